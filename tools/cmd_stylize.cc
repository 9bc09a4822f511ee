// vdbturb stylize: appearance transfer onto fluid motion (LazyFluids, Jamriška et al. 2015; --method fluidymation).
// Parses the options into a turb::run::StylizeJob and runs it (libturb/src/run/Stylize*.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "StylizeCommon.h"

#include <turb/Stylize.h>
#include <turb/run/Stylize.h>

#include <memory>
#include <string>
#include <vector>

namespace vdbturb {

namespace {

using namespace stylize;
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
    setting(app->add_option("--scene-size", a.sceneSize, "Built-in target size WxH"), "scene-size");
    setting(app->add_option("--scene-speed", a.sceneSpeed,
                "Built-in target: radians per frame at the centre (rise: widths per frame)"),
        "scene-speed");
    setting(
        app->add_flag("--flow-y-up", a.flowYUp, "The flow images' G channel points up (Nuke, Houdini)"), "flow-y-up");
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
    setting(app->add_option("--write-target", a.writeTarget,
                "Write the target per frame into DIR: alpha.####.png, motion.####.exr"),
        "write-target");
}

// LazyFluids' knobs (Jamriška et al. 2015), under turb::StylizeSettings' field names; their measured effects are in
// docs/stylize.md.
void addLazyFluidsSettings(CLI::App* app, turb::StylizeSettings& s)
{
    const auto knob = [app](const std::string& names, auto& v, const std::string& help, const std::string& key) {
        return setting(app->add_option(names, v, help), key);
    };
    setting(addEnum<turb::NnfMode>(app, "--nnf", s.nnf,
                {{"uniform", turb::NnfMode::Uniform}, {"standard", turb::NnfMode::Standard}},
                "uniform: reversed NNF, uniform patch usage (the paper); standard: nearest neighbours (the wash-out "
                "ablation)"),
        "nnf");
    knob("--patch,--patchSize", s.patchSize, "Patch size in pixels, odd (paper 5)", "patchSize")
        ->check(CLI::Range(3, 15));
    knob("--lambda", s.lambda, "Temporal coherence lambda (paper 0.2; 0 = independent frames)", "lambda")
        ->check(finiteIn(0.0));
    knob("--eta", s.eta, "Weight of the blurred-alpha guide (paper 3)", "eta")->check(finiteIn(0.0));
    knob("--blur-radius,--blurRadius", s.blurRadius, "r: Gaussian standard deviation (pixels) of the guide alpha",
        "blurRadius")
        ->check(finitePositive());
    knob("--lower", s.lower, "l: boundary segment where the blurred alpha lies in (l, u)", "lower")
        ->check(finiteIn(0.0, 1.0));
    knob("--upper", s.upper, "u: interior segment where the blurred alpha >= u", "upper")->check(finiteIn(0.0, 1.0));
    knob("--levels", s.levels, "Pyramid levels (0 = short sides >= 32 px, at most 5)", "levels")
        ->check(CLI::Range(0, 8));
    knob("--iterations", s.iterations, "EM iterations on each coarser level", "iterations")->check(CLI::Range(1, 50));
    knob("--fine-iterations,--fineIterations", s.fineIterations, "EM iterations on the finest level", "fineIterations")
        ->check(CLI::Range(1, 50));
    knob("--sweeps", s.sweeps, "PatchMatch sweeps per retrieval round", "sweeps")->check(CLI::Range(1, 32));
    setting(app->add_flag("--rotations", s.rotations, "Also use the exemplar rotated by 90, 180 and 270 degrees"),
        "rotations");
    knob("--motion-blur,--motionBlur", s.motionBlur, "Blur along F^t by this fraction of a frame's motion (0 = none)",
        "motionBlur")
        ->check(finiteIn(0.0));
    knob("--vote-weight,--voteWeight", s.voteWeight,
        "Beyond the paper: votes weighted by exp(-D / (w x the 75th percentile of D)) (Wexler 2007; 0 = the paper's "
        "plain average)",
        "voteWeight")
        ->check(finiteIn(0.0));
    boolSetting(app, "--startFromPrevious", s.startFromPrevious,
        "Beyond the paper: later frames start every level from the previous output advected (false: coarse to fine, "
        "the paper)",
        "startFromPrevious");
    knob("--preroll", s.preroll,
        "Beyond the paper: a first frame is synthesised again N times as a held frame under the temporal term, so the "
        "look does not step between frames 1 and 5 (0 = the paper's first frame)",
        "preroll")
        ->check(CLI::Range(0, 100));
    knob("--seed", s.seed, "Random seed: the same seed gives the same frames at any --threads", "seed");
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
        addLazyFluidsSettings(app, a.settings);
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
