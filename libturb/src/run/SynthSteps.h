/// @file SynthSteps.h
/// @brief The steps of turb::run::runSynth that its files share (private to libturb/src/run): the coarse input, the
///        exemplars and the job's text settings (SynthInput.cc), and what the run says about its frames
///        (SynthReport.cc). The run itself is SynthRun.cc.
#pragma once

#include "RunHelpers.h"

#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>
#include <turb/run/Synth.h>

#include <scenes/Smoke.h>
#include <turb/Synth.h>
#include <turb/SynthSequence.h>
#include <turbio/Scan.h>
#include <turbio/Sequence.h>

#include <nlohmann/json.hpp>

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace turb::run::synth {

using detail::fmt;

/// Where the coarse frames come from: a cache, a built-in scene simulated on the fly, or an analytic flow.
/// Holds `job` by reference: the run's preflight sets the box its cache frames are read over.
class CoarseSource
{
public:
    /// Throws turb::ValueError unless exactly one input is given, or on bad --frames or resolutions; turb::IoError
    /// for a cache's missing frames.
    explicit CoarseSource(const SynthJob& job);
    ~CoarseSource();

    const std::vector<int>& frames() const { return mFrames; }
    const std::string& label() const { return mLabel; }
    /// The cache sequence, when the coarse motion comes from one.
    const std::optional<turbio::Sequence>& sequence() const { return mSeq; }

    /// Coarse frame `frame` (a scene is simulated up to it), cut to --slice-z's layer when given.
    turb::Frame read(int frame, turb::Progress* progress);
    /// Walls of a built-in scene: its closed faces.
    unsigned sceneWalls() const;
    /// Where a built-in scene's emitters are at frame `frame` (grown by one voxel); nullopt for other inputs.
    std::optional<turb::ScalarField> sceneEmitters(const turb::ScalarField& like, int frame) const;
    /// Obstacles of a built-in scene as a signed distance on the coarse lattice.
    std::optional<turb::ScalarField> sceneObstacles(const turb::VectorField& like) const;

private:
    void openScene(const SynthJob& a);
    void openFlow(const SynthJob& a);

    const SynthJob& mArgs;
    std::optional<turbio::Sequence> mSeq;
    std::vector<int> mFrames;
    std::string mLabel;
    std::optional<turb::scenes::SmokeSettings> mSceneSettings;
    std::unique_ptr<turb::scenes::SmokeSim> mSim;
    turb::VectorField mFlow;
};

/// The job's text settings into the library's (a.seq.synth: threads, --secondary, --iterations, --radius).
void fillSettings(SynthJob& a);
/// One exemplar from its description (SynthJob::exemplars).
turb::Exemplar loadExemplar(const std::string& spec, const SynthJob& a);
/// --walls as SynthSettings' wall bits.
unsigned parseWalls(const std::string& s);
/// The views the exemplars serve: one 2D view, one volume exemplar, or planar exemplars along local axes (--views,
/// --view-weights).
std::vector<turb::SynthView> synthViews(const SynthJob& a, const std::vector<turb::Exemplar>& ex, bool volume);
/// The obstacle: the scene's, or a level set named by --obstacle PATH[:GRID].
std::optional<turb::ScalarField> readObstacle(const SynthJob& a, CoarseSource& source, const turb::Frame& f0);

/// The run's fixed parts: the coarse input, its first frame, the exemplars as views, walls and obstacle.
struct SynthPlan
{
    std::vector<int> frames;
    turbio::FramePattern out;
    std::optional<turbio::SequenceScan> scan;
    turb::Frame first; ///< the first coarse frame, read to decide 2D or 3D and the views
    bool volume = false;
    std::vector<turb::SynthView> views;
    std::optional<turb::ScalarField> obstacle;
    std::vector<std::string> outputs, settings; ///< per frame: the file and the settings it records
    SkipPlan skips;                             ///< --skip-existing
};

/// The plan's lines: the input, the frames, the kind, the exemplars.
void logPlan(const SynthJob& a, const CoarseSource& source, const SynthPlan& p);
/// -v: every level's energy after each iteration.
void logLevels(const turb::DetailField& H, int fr);
/// The projection's outcome for the JSON line; one that stopped short is warned about and added to `unconverged`.
nlohmann::json projectionReport(
    const SynthJob& a, const turb::SynthFrameResult& r, int fr, FrameProgress& progress, std::vector<int>& unconverged);
/// The detail's divergence solve for the JSON line (null without one); one that stopped short is warned about and
/// listed, as a projection is.
nlohmann::json detailDivergenceReport(
    const SynthJob& a, const turb::SynthFrameResult& r, int fr, FrameProgress& progress, std::vector<int>& unconverged);
/// What the written frame records about how it was made.
void tagOutput(turb::Frame& outFrame, const SynthJob& a, const std::vector<turb::SynthView>& views);

/// What a written frame's record needs beside the job and the plan.
struct FrameOutcome
{
    const turb::Frame* coarse = nullptr; ///< the frame's L (its density decides the detail's region)
    const turb::SynthFrameResult* result = nullptr;
    const turb::DetailField* detail = nullptr; ///< H, the sequence's last
    nlohmann::json projection, divergence;     ///< projectionReport's and detailDivergenceReport's
    std::string outPath;
    double readSeconds = 0.0, writeSeconds = 0.0;
};
/// A frame's JSON line: the output, the synthesis's levels and energies, the detail's strength and region, the
/// steps' times, and --stats' and --preview's outcomes (made here, on `progress`).
nlohmann::json frameJson(const SynthJob& a, const SynthPlan& p, const FrameOutcome& o, int fr, FrameProgress& progress);
/// The farm log's line for the frame.
std::string frameLine(const SynthJob& a, const FrameOutcome& o, const nlohmann::json& extra);

} // namespace turb::run::synth
