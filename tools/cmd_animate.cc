// vdbturb animate: animate a still picture of fluid from a video example (Okabe et al. 2009).
// Parses the options into a turb::run::AnimateJob and runs it (libturb/src/run/Animate*.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "StylizeCommon.h"

#include <turb/run/Animate.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace vdbturb {

namespace {

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
    // The table's first row: --help-all lists it before the read options.
    addSettings(app, static_cast<turb::run::AnimateJob&>(a), turb::run::animateSettings(), {}, "", "dump");
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
        // The rest of the table: dump and measure, then the method's knobs (turb::AnimateSettings' fields).
        addSettings(app, static_cast<turb::run::AnimateJob&>(a), turb::run::animateSettings(),
            turb::run::animateOldSpellings(), "dump");
    };
    c.run = [args] { return runAnimate(*args); };
    return c;
}

} // namespace vdbturb
