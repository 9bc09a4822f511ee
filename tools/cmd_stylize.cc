// vdbturb stylize: appearance transfer onto fluid motion (LazyFluids, Jamriška et al. 2015; --method fluidymation).
// Parses the options into a turb::run::StylizeJob and runs it (libturb/src/run/Stylize*.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "StylizeCommon.h"

#include <turb/run/Stylize.h>

#include <memory>
#include <string>
#include <vector>

namespace vdbturb {

namespace {

using namespace stylize;
using turb::run::StylizeJob;
using turb::run::StylizeMethod;

// The options given on the command line (or in a settings file) that the chosen method does not read, warned once.
void warnUnread(const std::vector<const CLI::Option*>& options, const std::string& whose, const std::string& method)
{
    std::string given;
    for (const CLI::Option* o : options)
        if (o->count() > 0) given += (given.empty() ? "" : ", ") + o->get_name();
    if (!given.empty())
        logWarning("stylize: " + given + " set " + whose + " synthesis; " + method + " does not read " +
                   (given.find(',') == std::string::npos ? "it" : "them"));
}

int runStylize(StylizeArgs& a)
{
    if (a.method == StylizeMethod::Fluidymation) warnUnread(a.lazyFluidsOnly, "LazyFluids'", "--method fluidymation");
    else warnUnread(a.fluidymationOnly, "Fluidymation's", "--method lazyfluids (the default)");
    turb::run::StylizeJob job = a;
    job.settingsText = commandSettingsText(*a.app, {});
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    turb::run::runStylize(job);
    return kOk;
}

// The exemplar, the target (2D masks and flows, a cache through a camera, or a built-in scene) and the frames.
void addInputOptions(CLI::App* app, StylizeArgs& a)
{
    app->add_option("--exemplar", a.exemplar,
           "Exemplar: a picture, a #### sequence (a video), builtin:fire[:N]; fluidymation: its frames or "
           "builtin:ink[:WxH[xN]]")
        ->required();
    app->add_option(
        "--exemplar-alpha", a.exemplarAlpha, "Grayscale mask (or #### sequence) giving the exemplar's alpha");
    app->add_option(
        "--flow", a.flow, "2D target motion per frame: R,G in pixels per frame (x right, y down), or 1-layer VDBs");
    app->add_option("--alpha", a.alpha, "2D target alpha masks per frame (grayscale images)");
    app->add_option(
        "--cache", a.cache, "3D target: a cache seen through --camera (alpha = opacity, motion = projected velocity)");
    addCameraOptions(app, a.camera);
    app->add_option("--scene", a.scene, "Built-in 2D target: rotate, swirl, rise, fill, grow or stroke")
        ->check(CLI::IsMember({"rotate", "swirl", "rise", "fill", "grow", "stroke"}));
    app->add_option(
           "--frames", a.frames, "Frames, e.g. 1-150; a scene: a count N or a list (empty: all on disk; scene 1)")
        ->check(frameListCheck());
    addSettingsFromTo(app, static_cast<StylizeJob&>(a), turb::run::stylizeSettings(), "scene-size", "flow-y-up");
    addReadOptions(app, a.read);
    // Only a --cache target reads grids: its grid and frame-rate choices are settings here.
    for (const char* name : {"density-grid", "vel-grid", "fps"})
        setting(app->get_option(std::string("--") + name), name);
}

void addOutputOptions(CLI::App* app, StylizeArgs& a)
{
    app->add_option(
        "--out", a.out, "Output RGBA frames, e.g. styl/fire.####.exr (EXR: half, premultiplied; PNG: straight)");
    app->add_option(
           "--preview", a.preview, "Write a PNG per frame into DIR: target | motion (LIC) | stylized | exemplar")
        ->group(kGroupOutput);
    app->add_flag("--no-clobber", a.noClobber, "Never replace an existing output file")->group(kGroupOutput);
    app->add_flag("--skip-existing", a.skipExisting,
           "Skip the frames already written by the same settings (farm wrappers' retries; the frames before the last "
           "one to write are made again, not written); a frame written otherwise is refused (exit 1)")
        ->group(kGroupOutput);
    a.app = app;
    app->add_flag("--json", "One JSON line per frame and a summary on stdout");
    addSettingsFromTo(app, static_cast<StylizeJob&>(a), turb::run::stylizeSettings(), "write-target", "write-target");
}

} // namespace

Command stylizeCommand()
{
    auto args = std::make_shared<StylizeArgs>();
    Command c;
    c.name = "stylize";
    c.help =
        "Appearance transfer onto fluid motion: an exemplar's look on 2D flows or on a VDB cache seen through a camera "
        "(LazyFluids; --method fluidymation: a moving exemplar's look and dynamics)";
    c.setup = [args](CLI::App* app) {
        StylizeArgs& a = *args;
        addEnum<StylizeMethod>(app, "--method", a.method,
            {{"lazyfluids", StylizeMethod::LazyFluids}, {"fluidymation", StylizeMethod::Fluidymation}},
            "lazyfluids: a still or video RGBA exemplar; fluidymation: a moving exemplar's look and dynamics");
        addInputOptions(app, a);
        addOutputOptions(app, a);
        const size_t before = app->get_options().size();
        // LazyFluids' knobs (Jamriška et al. 2015; docs/stylize.md).
        addSettingsFromTo(app, static_cast<StylizeJob&>(a), turb::run::stylizeSettings(), "nnf", "seed");
        const std::vector<CLI::Option*> all = app->get_options();
        for (size_t i = before; i < all.size(); ++i)
            if (!all[i]->check_lname("seed")) a.lazyFluidsOnly.push_back(all[i]); // fluidymation reads the seed
        addFluidymationOptions(app, a);
        const std::vector<CLI::Option*> more = app->get_options();
        for (size_t i = all.size(); i < more.size(); ++i) a.fluidymationOnly.push_back(more[i]);
    };
    c.run = [args] { return runStylize(*args); };
    return c;
}

} // namespace vdbturb
