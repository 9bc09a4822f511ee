/// @file Animate.h
/// @brief `vdbturb animate` as a library call (turb::run, the entry points' layer): a still picture of fluid
///        animated from a video example (Okabe et al. 2009), from files to files.
///
/// @code
/// turb::run::AnimateJob job;
/// job.example = "river/river.####.png";          // or exampleCache through job.camera, or "builtin:river"
/// job.target = "still.png";
/// job.strokes = "river_strokes.json";            // the flow design, or job.flow (a dense flow image)
/// job.out = "anim/still.####.exr";
/// turb::run::AnimateRun done = turb::run::runAnimate(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// The run reads and checks the whole example and the still before it writes anything; every output frame comes
/// from the whole example (the design, eq. 8's statistics), so the example's frames are part of the settings each
/// frame records, and --skip-existing remakes the whole shot when a frame is missing.
#pragma once

#include <turb/Animate.h>
#include <turb/run/CacheCamera.h>
#include <turbio/Vdb.h>

#include <string>
#include <vector>

namespace turb::run {

/// Whether the flow design is refined by the target's gradients (section 5.1).
enum class AnimateRefine {
    Auto, ///< a stroke design is refined, a dense flow image is not
    On,
    Off
};

/// Histogram matching (section 5.6).
enum class AnimateHm {
    Steerable, ///< Heeger-Bergen on a steerable pyramid (the paper)
    Laplacian, ///< one pass on a Laplacian pyramid: the fast preview
    Off
};

/// An animate run: the CLI's options as plain values (same names, same defaults).
struct AnimateJob
{
    /// The video example, one of: `example`, an image pattern (####) or "builtin:river[:WxHxN]"; `exampleCache`, a
    /// VDB cache pattern seen through `camera`.
    std::string example, exampleCache;
    std::string frames;      ///< the example frames to use ("1-100"); empty: every frame on disk
    CacheCamera camera;      ///< how `exampleCache` is seen
    std::string target;      ///< the still to animate (its alpha is kept in the output), or "builtin:river[:WxH]"
    std::string targetAlpha; ///< the fluid's matte (grey image, the target's size): only the fluid moves; empty: all
    /// The flow design, one of: `strokes`, a stroke file (JSON) or "builtin:NAME" (a design in builtinDataDirs);
    /// `flow`, a dense flow image, R,G = x,y in pixels per frame (x right, y down).
    std::string strokes, flow;
    bool flowYUp = false; ///< the `flow` image's G channel points up
    /// The Clone Brush's stroke pairs (section 5.3; turbio/Strokes.h's JSON: sources in example pixels, destinations
    /// in target pixels), or "builtin:NAME" (DIR/animate/NAME_clone.json in builtinDataDirs); empty: none.
    std::string cloneStrokes;
    /// Where "builtin:NAME" designs are looked for, in order: DIR/animate/NAME_strokes.json (the CLI passes the
    /// source tree's scenes/ or the installed share/vdbturb).
    std::vector<std::string> builtinDataDirs;
    AnimateRefine refine = AnimateRefine::Auto; ///< sets settings.refineFlow
    AnimateHm hm = AnimateHm::Steerable;        ///< sets settings.histogramMatch and settings.hm.pyramid
    std::string hmGrid = "auto"; ///< "COLSxROWS" cells (hmGridProblem), "auto" (by settings.hm.cellSize) or "off"
    std::string out;             ///< output frames: an image pattern with #### (.exr, .png, .tif)
    int start = 1;               ///< the frame number of the first output frame
    std::string dump;  ///< also write every stage's images into this folder (float EXR) and flow pictures (PNG)
    std::string sheet; ///< write a contact sheet PNG here: example, design and output frames
    /// Write the built-in river example and still into this folder and stop (example and target may then only be
    /// built-ins or empty).
    std::string exportBuiltin;
    bool noClobber = false;    ///< never replace an existing output file
    bool measure = false;      ///< measure the output's flow against the design, and its temporal statistics
    bool skipExisting = false; ///< skip the frames written by the same settings; a missing one remakes the shot
    /// The settings each frame records and --skip-existing compares ("name=value;...": the CLI's
    /// commandSettingsText); the run adds the example's frames to it.
    std::string settingsText;
    turbio::ReadOptions read; ///< how `exampleCache` is read
    /// The method's knobs (turb::validate's ranges); the run sets refineFlow, histogramMatch and hm's pyramid and
    /// grid from refine, hm and hmGrid.
    turb::AnimateSettings settings;
    bool dryRun = false; ///< check and plan (printData), write nothing
    int threads = 0;     ///< 0 = all cores
};

/// What a run did.
struct AnimateRun
{
    int framesWritten = 0;
    int framesSkipped = 0; ///< left as --skip-existing found them
};

/// Runs `job`. Throws turb::ValueError (bad settings, naming the first out of range), UsageError (a missing or
/// unknown --out, or one without a frame token), turb::IoError (a missing, damaged or mismatched input, naming the
/// file), turb::TransientError (a frame locked by another process) and turb::Cancelled (the reporter's progress
/// asked to stop). Frames written before a throw stay.
AnimateRun runAnimate(const AnimateJob& job);

/// What is wrong with `grid` as AnimateJob::hmGrid ("" when nothing): "auto", "off" or COLSxROWS of whole numbers
/// >= 1. The CLI checks it while parsing.
std::string hmGridProblem(const std::string& grid);

} // namespace turb::run
