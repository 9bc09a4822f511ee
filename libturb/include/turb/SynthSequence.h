/// @file SynthSequence.h
/// @brief A motion-field synthesis run frame after frame (Ma et al., "Motion Field Texture Synthesis", sections
///        3.4-3.5 and supplement A), shaped like TurbulenceTransfer: the caller reads frames and writes results,
///        the sequence keeps what the next frame continues from (the detail H, the look-back density's history).
///
/// One call per frame: H' synthesised (continued from the previous frame's H advected through L when there is
/// one), F = up(L) + omega H' (detail near the smoke by default), optionally projected divergence-free, and a fine
/// density carried through F with the coarse density's sources.
///
/// @code
/// turb::SynthExemplars ex(views, settings.synth, volume);
/// turb::SynthSequence seq(ex, settings);
/// for (...) { turb::SynthFrameResult r = seq.next(input, &progress); write(r.frame); }
/// @endcode
#pragma once

#include <turb/Frame.h>
#include <turb/Projection.h>
#include <turb/Synth.h>

#include <optional>
#include <utility>
#include <vector>

namespace turb {

/// What a synth sequence does around one frame's synthesis.
struct SynthSequenceSettings
{
    SynthSettings synth;          ///< the texture synthesis; synth.boundary.walls also close the projection's faces
    CombineSettings combine;      ///< F = up(L) + omega H' (section 3.5); its `smoke` is set per frame (below)
    int factor = 4;               ///< output voxel = coarse voxel / factor, >= 1
    bool detailNearSmoke = true;  ///< beyond the paper: omega only near a frame's smoke when it has density
    bool project = false;         ///< Helmholtz-Hodge projection of F (section 3.5; walls and obstacle closed)
    int projectIterations = 2000; ///< the projection's conjugate-gradient cap, >= 1
    bool density = true;          ///< carry a fine density through F when the frame has a coarse one
    int lookback = 12;            ///< m of LookbackDensity (supplement A); 0 = the naive scheme
    bool detailOnly = false;      ///< the output velocity is F - up(L) (what the synthesis added), not F
};

/// One frame of coarse input. Fields are borrowed for the call.
struct SynthFrameInput
{
    const VectorField* coarse = nullptr; ///< L, world units per time unit (required)
    const ScalarField* coarseDensity =
        nullptr;                           ///< optional, on L's lattice: the secondary axis, the smoke, the sources
    const ScalarField* obstacle = nullptr; ///< optional signed distance (world units, < 0 inside), any lattice
    const ScalarField* emitters = nullptr; ///< optional: where a scene's emitters are, on the density's box
    int frame = 0;                         ///< frame number; a gap to the previous call is advected over
    double dt = 0.0;                       ///< time per frame, > 0
    double timeUnit = 1.0;                 ///< seconds per time unit of `coarse` and dt (Frame::timeUnit)
};

/// Where one frame's time went, seconds.
struct SynthTimings
{
    double synthesis = 0.0; ///< synthesizeDetail: the detail H
    double combine = 0.0;   ///< combineMotion and, with SynthSequenceSettings::project, the projection
    double density = 0.0;   ///< the density carried through F (look-back, sources)
    /// (name, seconds) in report order; the names are the JSON keys of `steps_s`.
    std::vector<std::pair<const char*, double>> named() const
    {
        return {{"synthesis", synthesis}, {"combine", combine}, {"density", density}};
    }
};

struct SynthFrameResult
{
    Frame frame;        ///< number, dt, velocity (F, or F - up(L) with detailOnly), density when made
    VectorField motion; ///< F on the fine box
    std::optional<ProjectionResult> projection; ///< with SynthSequenceSettings::project
    /// with CombineSettings::solenoidalDetail: the solve that took the detail's divergence out
    std::optional<CentralDivergenceResult> detailDivergence;
    bool smokeless = false; ///< the frame's density holds no smoke, so no detail was placed (detailNearSmoke)
    std::optional<double>
        densityMass; ///< sum of the fine density times the voxel volume; none when no density was made
    SynthTimings seconds;
};

class SynthSequence
{
public:
    /// `exemplars` must outlive the sequence.
    SynthSequence(const SynthExemplars& exemplars, const SynthSequenceSettings& settings);

    /// The next frame. A call after a gap (frame numbers two apart) advects over the real time between the two;
    /// the look-back density restarts after a gap. Throws ValueError on a missing L or a non-positive dt, and what
    /// synthesizeDetail, combineMotion and project throw; Cancelled when `progress` asks.
    SynthFrameResult next(const SynthFrameInput& in, Progress* progress = nullptr);

    /// The last frame's detail H (levels, energies, local and world fields), which the next frame continues from.
    /// Throws ValueError before the first frame.
    const DetailField& lastDetail() const;

private:
    const SynthExemplars& mExemplars;
    SynthSequenceSettings mSettings;
    LookbackDensity mLookback;
    std::optional<DetailField> mPrevious;
    int mPreviousFrame = 0;
    ScalarField mPreviousDensity;
};

} // namespace turb
