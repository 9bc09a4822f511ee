// vdbturb preview: pictures of caches (density render, speed/vorticity slices, LIC) and contact sheets.
// Parses the options into a turb::run::PreviewJob and runs it (libturb/src/run/Preview.cc).
#include "Commands.h"
#include "Console.h"

#include <turb/run/Preview.h>

#include <memory>

namespace vdbturb {

namespace {

using PreviewArgs = turb::run::PreviewJob;

int runCommand(const PreviewArgs& a)
{
    turb::run::PreviewJob job = a;
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    turb::run::runPreview(job);
    return kOk;
}

CLI::Validator modesCheck()
{
    return CLI::Validator(
        [](std::string& v) {
            try {
                turb::run::parsePreviewModes(v);
            } catch (const turb::ValueError& e) {
                return std::string(e.what());
            }
            return std::string();
        },
        "MODES");
}

} // namespace

Command previewCommand()
{
    auto args = std::make_shared<PreviewArgs>();
    Command c;
    c.globals = kVerbosity | kThreads | kDryRun;
    c.name = "preview";
    c.help = "Pictures of caches (PNG, EXR, TIFF, JPEG): lit density, speed/vorticity slices, LIC, and labelled "
             "contact sheets (a 2D cache, one z layer, is shown in its x-y plane)";
    c.setup = [args](CLI::App* app) {
        PreviewArgs& a = *args;
        app->add_option("caches", a.inputs,
               "Caches as [LABEL=]PATTERN (####, %04d, $F4 or one real file); several go side by side in --sheet")
            ->required();
        app->add_option("--mode", a.modes,
               "Comma list of density (lit ray march), speed, vorticity (slices), lic (flow texture), all")
            ->check(modesCheck());
        app->add_option(
               "--frames", a.frames, "Frames, e.g. 10,30,60 or 1-60 (default: all; a sheet: three spread frames)")
            ->check(frameListCheck());
        addEnum<turb::View>(app, "--view", a.view, turb::run::previewViews(),
            "Camera: front (along +y), side (along +x), top (down -z), for a z-up cache");
        app->add_option("--up", a.up,
               "World axis drawn upward: auto (vdbturb_up_axis metadata, else y for Houdini's files, else z), y, z")
            ->check(CLI::IsMember({"auto", "y", "z"}));
        app->add_option("--width", a.width, "Width of each picture in pixels")->check(CLI::Range(16, 8192));
        app->add_flag("--json", "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.read);
        app->add_option("--out", a.out, "One picture per frame, e.g. pics/plume.####.png (.exr: linear half float)")
            ->group(kGroupOutput);
        app->add_option("--sheet", a.sheet, "Write one contact sheet: rows = frames, columns = caches x modes")
            ->group(kGroupOutput);
        app->add_option("--title", a.title, "Title of the contact sheet (default: the labels)")->group(kGroupOutput);
        // The second tier: the slice, the density render's light and the colour ranges (docs/scenes.md).
        addSettings(app, a, turb::run::previewSettings());
    };
    c.run = [args] { return runCommand(*args); };
    return c;
}

} // namespace vdbturb
