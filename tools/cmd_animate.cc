// vdbturb animate: animate a still picture of fluid from a video example (Okabe et al. 2009).
// Parses the options into a turb::run::AnimateJob and runs it (libturb/src/run/Animate*.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "StylizeCommon.h"

#include <turb/Animate.h>
#include <turb/run/Animate.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace vdbturb {

namespace {

using Refine = turb::run::AnimateRefine;
using HmMode = turb::run::AnimateHm;

// The command line's animate: the job, and the parser its frames' settings come from.
struct AnimateArgs : turb::run::AnimateJob
{
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
};

// Where "builtin:river" (scenes/animate/river_strokes.json) is looked for: PREFIX/share/vdbturb beside an installed
// binary (found from /proc/self/exe, so a moved prefix works); the binary in the build tree reads the source tree.
std::vector<std::string> builtinDataDirs()
{
    namespace fs = std::filesystem;
    std::vector<std::string> dirs;
    std::error_code ec;
    const fs::path exeDir = fs::read_symlink("/proc/self/exe", ec).parent_path();
    if (!ec && fs::equivalent(exeDir, VDBTURB_BUILD_BIN_DIR, ec)) {
        dirs.emplace_back(VDBTURB_SOURCE_DATA_DIR);
    } else if (!exeDir.empty()) {
        fs::path prefix = exeDir;
        for (const auto& part : fs::path(VDBTURB_INSTALL_BIN_DIR))
            if (!part.empty()) prefix = prefix.parent_path();
        dirs.push_back((prefix / VDBTURB_INSTALL_DATA_DIR).string());
    }
    return dirs;
}

int runAnimate(AnimateArgs& a)
{
    turb::run::AnimateJob job = a;
    if (a.strokes.rfind("builtin:", 0) == 0 || a.cloneStrokes.rfind("builtin:", 0) == 0)
        job.builtinDataDirs = builtinDataDirs();
    job.settingsText = commandSettingsText(*a.app, {});
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    turb::run::runAnimate(job);
    return kOk;
}

// The video example, the still and its flow design (a cache example is seen through --camera).
void addInputOptions(CLI::App* app, AnimateArgs& a)
{
    app->add_option("--example", a.example, "Video example: an image sequence with ####, or builtin:river[:WxHxN]");
    app->add_option("--example-cache", a.exampleCache, "Video example from a VDB cache seen through --camera");
    app->add_option("--frames", a.frames, "Example frames to use, e.g. 1-100 (empty: all on disk)")
        ->check(frameListCheck());
    stylize::addCameraOptions(app, a.camera);
    app->add_option(
        "--target", a.target, "The still to animate (its alpha is kept in the output), or builtin:river[:WxH]");
    app->add_option(
        "--target-alpha", a.targetAlpha, "Matte of the fluid (grey image, target size): only the fluid moves");
    app->add_option("--flow-strokes", a.strokes,
        "Flow design: orientation and speed strokes (JSON, scenes/animate/README.md), or builtin:river / builtin:plume "
        "(the designs installed in share/vdbturb/animate)");
    app->add_option(
        "--flow", a.flow, "Flow design: a dense flow image, R,G = x,y in pixels per frame (x right, y down)");
    setting(app->add_flag("--flow-y-up", a.flowYUp, "The --flow image's G channel points up"), "flow-y-up");
    addReadOptions(app, a.read);
    // Only --example-cache reads grids: its grid and frame-rate choices are settings here.
    for (const char* name : {"density-grid", "vel-grid", "fps"})
        setting(app->get_option(std::string("--") + name), name);
}

void addOutputOptions(CLI::App* app, AnimateArgs& a)
{
    app->add_option("--out", a.out, "Output frames, e.g. anim/still.####.exr (EXR: half, premultiplied) or .png");
    app->add_option("--start", a.start, "Frame number of the first output frame")->group(kGroupOutput);
    app->add_flag("--no-clobber", a.noClobber, "Never replace an existing output file")->group(kGroupOutput);
    app->add_flag("--skip-existing", a.skipExisting,
           "Skip the frames already written by the same settings (farm wrappers' retries; when some are missing the "
           "whole shot is made again, since each frame comes from the whole example); a frame written otherwise is "
           "refused (exit 1)")
        ->group(kGroupOutput);
    a.app = app;
    app->add_option("--sheet", a.sheet, "Write a contact sheet PNG: example, design and output frames")
        ->group(kGroupOutput);
    app->add_flag("--json", "One JSON line per frame and a summary with stage times on stdout");
    app->add_option(
        "--export-builtin", a.exportBuiltin, "Write the built-in river example and still into DIR and stop");
    setting(app->add_option(
                "--dump", a.dump, "Also write every stage's images into DIR (float EXR) and flow pictures (PNG)"),
        "dump");
    setting(app->add_flag(
                "--measure", a.measure, "Measure the output's flow against the design and its temporal statistics"),
        "measure");
}

// Histogram matching (section 5.6): the steerable pyramid's repetitions and the grid of cells.
void addHmSettings(CLI::App* app, AnimateArgs& a)
{
    turb::HistogramMatchSettings& hm = a.settings.hm;
    setting(app->add_option("--hm-rep,--hm.reps", hm.reps, "HM Rep: repetitions of the steerable matching (paper 3)")
                ->check(CLI::Range(1, 10)),
        "hm.reps");
    // Checked while parsing, so a bad grid is a usage error (exit 2) like every other option's bad value.
    const CLI::Validator gridCheck(
        [](std::string& v) -> std::string { return turb::run::hmGridProblem(v); }, "COLSxROWS|auto|off");
    setting(
        app->add_option("--hm-grid", a.hmGrid, "HM Grid: COLSxROWS, auto (cells of about hm.cellSize pixels) or off")
            ->check(gridCheck),
        "hm-grid");
    setting(app->add_option("--hm-cell,--hm.cellSize", hm.cellSize, "Cell size of the automatic HM grid in pixels")
                ->check(CLI::Range(16, 100000)),
        "hm.cellSize");
    setting(app->add_option("--hm-passes,--hm.pixelPasses", hm.pixelPasses, "Final pixel-domain matching passes")
                ->check(CLI::Range(1, 20)),
        "hm.pixelPasses");
    boolSetting(app, "--hm.blendPixels", hm.blendPixels,
        "Blend the cells' pixel-domain matches (false: each cell's statistics exact, seams can show)",
        "hm.blendPixels");
    boolSetting(app, "--hm.cellMoments", hm.cellMoments,
        "Finally solve one blended gain and offset per cell so every cell's mean and std are the target's (false: "
        "stop after the pixel passes)",
        "hm.cellMoments");
    setting(addEnum<turb::HmApply>(app, "--hm-apply,--hmApply", a.settings.hmApply,
                {{"per-frame", turb::HmApply::PerFrame}, {"sequence", turb::HmApply::Sequence}},
                "per-frame: match every frame (the paper); sequence: match the mean frame once, give every frame that "
                "correction and its own cell moments (keeps the moving detail on smooth stills such as smoke renders; "
                "a static speckle on textured ones; docs/animate.md)"),
        "hmApply");
    legacy(app->add_flag_function(
               "--hm-exact-cells", [&hm](std::int64_t) { hm.blendPixels = false; }, "hm.blendPixels = false"),
        "hm.blendPixels", "false");
}

// The method's knobs (Okabe et al.), under turb::AnimateSettings' field names; docs/animate.md has their measurements.
void addAnimateSettings(CLI::App* app, AnimateArgs& a)
{
    turb::AnimateSettings& s = a.settings;
    const auto knob = [app](const std::string& names, auto& v, const std::string& help, const std::string& key) {
        return setting(app->add_option(names, v, help), key);
    };
    setting(
        addEnum<Refine>(app, "--refine", a.refine, {{"auto", Refine::Auto}, {"on", Refine::On}, {"off", Refine::Off}},
            "Refine the design by the target's gradients: auto (strokes yes, --flow no), on, off"),
        "refine");
    setting(addEnum<turb::GradientOrientation>(app, "--orient,--refine.orient", s.refine.orient,
                {{"parallel", turb::GradientOrientation::Parallel},
                    {"perpendicular", turb::GradientOrientation::Perpendicular}},
                "Refined orientation: parallel to the image gradient (the paper) or perpendicular (along edges)"),
        "refine.orient");
    knob("--wf,--refine.wf", s.refine.wf, "w_f: blur of the refined orientation, Gaussian std in pixels (paper 12)",
        "refine.wf")
        ->check(finiteIn(0.1, 500.0));
    knob("--tau", s.tau, "Lifetime of a residual in frames (paper 16); the output has N - tau frames", "tau")
        ->check(CLI::Range(1, 10000));
    knob("--shutter,--average.shutter", s.average.shutter,
        "Sh: motion blur of the target along the flow for A', in frames", "average.shutter")
        ->check(finiteIn(0.0, 200.0));
    knob("--wa,--average.wa", s.average.wa, "w_a: Gaussian std in pixels after the motion blur for A'", "average.wa")
        ->check(finiteIn(0.0, 500.0));
    knob("--patch,--transfer.patchSize", s.transfer.patchSize, "Residual transfer patch size in pixels (paper 8-32)",
        "transfer.patchSize")
        ->check(CLI::Range(8, 64));
    knob("--search-downsample,--transfer.downsample", s.transfer.downsample, "Match flows downsampled by 1, 2 or 4",
        "transfer.downsample")
        ->check(CLI::IsMember({1, 2, 4}));
    knob("--variety,--transfer.variety", s.transfer.variety,
        "Residual transfer: candidates within this fraction of the patch's design speed of the best are equally good, "
        "and the one farthest from its neighbours' windows is taken (0: the nearest, the paper)",
        "transfer.variety")
        ->check(finiteIn(0.0, 1.0));
    knob("--transfer.candidates", s.transfer.candidates,
        "Residual transfer: random example windows costed per patch besides the 8 nearest (only with variety > 0)",
        "transfer.candidates")
        ->check(CLI::Range(1, 64));
    knob("--features,--analysis.features", s.analysis.features,
        "Lucas-Kanade features per example frame pair (paper 100)", "analysis.features")
        ->check(CLI::Range(1, 100000));
    knob("--lk-window,--analysis.window", s.analysis.window, "Lucas-Kanade window in pixels (paper 10)",
        "analysis.window")
        ->check(CLI::Range(3, 64));
    addHmSettings(app, a);
}

} // namespace

Command animateCommand()
{
    auto args = std::make_shared<AnimateArgs>();
    Command c;
    c.name = "animate";
    c.help = "Animate a still picture of fluid from a video example (Okabe et al.): strokes or a flow design, residual "
             "transfer, histogram matching";
    c.setup = [args](CLI::App* app) {
        AnimateArgs& a = *args;
        addInputOptions(app, a);
        addOutputOptions(app, a);
        app->add_option("--clone-strokes", a.cloneStrokes,
            "Clone Brush: source strokes on the example and destination strokes on the still (JSON, pixels; "
            "scenes/animate/README.md): the example's residuals around each source are pasted around its destination");
        addEnum<HmMode>(app, "--hm", a.hm,
            {{"steerable", HmMode::Steerable}, {"laplacian", HmMode::Laplacian}, {"off", HmMode::Off}},
            "Histogram matching: steerable (Heeger-Bergen), laplacian (one pass, the fast preview) or off");
        addAnimateSettings(app, a);
        setting(addEnum<turb::GivenFlow>(app, "--analysis.givenFlow", a.settings.analysis.givenFlow,
                    {{"best", turb::GivenFlow::Best}, {"use", turb::GivenFlow::Use}, {"track", turb::GivenFlow::Track}},
                    "v of a cache example: best (its projected velocity or the tracked flow, whichever leaves the "
                    "smaller residuals), use (the velocity) or track (the paper's tracking)"),
            "analysis.givenFlow");
    };
    c.run = [args] { return runAnimate(*args); };
    return c;
}

} // namespace vdbturb
