/// @file Stylize.h
/// @brief `vdbturb stylize` as a library call (turb::run, the entry points' layer): an exemplar's look on fluid
///        motion, from files to files. Two methods: LazyFluids (Jamriška et al. 2015; a still or video RGBA exemplar)
///        and Fluidymation (a moving exemplar's look and dynamics).
///
/// @code
/// turb::run::StylizeJob job;
/// job.exemplar = "builtin:fire";
/// job.cache = "smoke/fluid_####.vdb"; // the target: a cache through job.camera, 2D flows and masks, or a scene
/// job.camera.kind = turb::run::CameraKind::Side;
/// job.out = "styl/fire.####.exr";
/// turb::run::runStylize(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// The run reads and checks every target and exemplar frame before it writes anything, then makes the frames in
/// order (each follows the one before it: the temporal term, the previous NNF), writes each with the settings
/// --skip-existing compares, and takes a lock on each frame it writes.
#pragma once

#include <turb/Fluidymation.h>
#include <turb/Stylize.h>
#include <turb/run/CacheCamera.h>
#include <turbio/Vdb.h>

#include <string>

namespace turb::run {

enum class StylizeMethod {
    LazyFluids,  ///< a still or video RGBA exemplar (turb::Stylizer)
    Fluidymation ///< a moving exemplar with masks and flows (turb::Fluidymator)
};

/// What only StylizeMethod::Fluidymation reads.
struct FluidymationJob
{
    std::string exemplarMask;   ///< the exemplar frames' binary masks (frame pattern); empty: the exemplar's alpha
    std::string exemplarFlow;   ///< the exemplar's flows (R,G pixels per frame, x right, y down); empty: estimated
    std::string targetMask;     ///< a 2D target: binary masks (frame pattern); or StylizeJob::cache / scene
    std::string targetFlow;     ///< the 2D target's flows (needs targetMask); empty: estimated from the masks
    std::string outRot;         ///< write T^rot per frame (float EXR/TIFF pattern: R = theta radians, G, B = cos, sin)
    std::string debugNnf;       ///< write the NNF per frame into this folder (nnf, nnf_theta, nnf_vis)
    float maskThreshold = 0.5f; ///< a target alpha or rendered opacity >= this is inside the mask, [0.001, 1]
    bool estimateFlow = false;  ///< ignore given target flows: estimate them from the masks (Appendix A)
    turb::FluidySettings settings;    ///< the method's knobs; its seed is StylizeJob::settings.seed
    turb::MotionGuideSettings guides; ///< how the masks' motion guides are made
};

/// A stylize run: the CLI's options as plain values (same names, same defaults).
struct StylizeJob
{
    StylizeMethod method = StylizeMethod::LazyFluids;
    /// A picture, a frame pattern (a video exemplar), "builtin:fire[:N]" (LazyFluids) or "builtin:ink[:WxH[xN]]"
    /// (Fluidymation). Required.
    std::string exemplar;
    std::string exemplarAlpha; ///< LazyFluids: a grey mask (or pattern) giving the exemplar's alpha; empty: its own
    /// The target, one of: `flow` and `alpha` (LazyFluids' 2D target: per-frame motion, R,G pixels per frame or
    /// 1-layer VDBs, and grey masks; Fluidymation takes FluidymationJob::targetMask/targetFlow instead), `cache` (a
    /// VDB cache seen through `camera`), or `scene` (rotate, swirl, rise, fill, grow or stroke).
    std::string flow, alpha, cache, scene;
    std::string sceneSize = "256x256"; ///< a scene's size, "WxH" (or "N": square)
    double sceneSpeed = 0.02;          ///< a scene's radians per frame at the centre (rise: widths per frame)
    /// Frame list ("1-150"); empty: every frame on disk (a scene: 1). A scene takes a count N for frames 1..N.
    std::string frames;
    CacheCamera camera;        ///< how a `cache` target is seen
    bool flowYUp = false;      ///< the flow images' G channel points up (Nuke, Houdini)
    std::string out;           ///< output RGBA frames (.png, .exr or .tif pattern with ####; one file for one frame)
    std::string preview;       ///< write a preview sheet PNG per frame into this folder; empty: none
    std::string writeTarget;   ///< LazyFluids: write the target per frame into this folder (alpha PNG, motion EXR)
    bool noClobber = false;    ///< never replace an existing output file
    bool skipExisting = false; ///< skip frames written by the same settings (they are made again, not written)
    /// The settings each frame records and --skip-existing compares ("name=value;...": the CLI's
    /// commandSettingsText); the run adds the shot's frames to it.
    std::string settingsText;
    turbio::ReadOptions read;       ///< how a `cache` target (and a VDB flow) is read
    turb::StylizeSettings settings; ///< LazyFluids' knobs (and the seed both methods use)
    FluidymationJob fluidy;
    bool dryRun = false; ///< check and plan (printData), write nothing
    int threads = 0;     ///< 0 = all cores
};

/// What a run did.
struct StylizeRun
{
    int framesWritten = 0;
    int framesSkipped = 0; ///< left as --skip-existing found them
};

/// Runs `job`. Throws turb::ValueError (bad settings, a method's failure on a frame, naming its files),
/// UsageError (a missing or unknown --out, an --out without a frame token for several frames), turb::IoError (a
/// missing, damaged or mismatched input, naming the file), turb::TransientError (a frame locked by another process)
/// and turb::Cancelled (the reporter's progress asked to stop). Frames written before a throw stay.
StylizeRun runStylize(const StylizeJob& job);

} // namespace turb::run
