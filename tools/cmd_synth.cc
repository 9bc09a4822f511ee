// vdbturb synth: motion-field texture synthesis (Ma et al. 2009) over a coarse flow.
// Parses the options into a turb::run::SynthJob and runs it (libturb/src/run/SynthRun.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"

#include <turb/run/Synth.h>

#include <cmath>
#include <memory>

namespace vdbturb {

namespace {

// The command line's synth: the job, and the parser whose options its frames record.
struct SynthArgs : turb::run::SynthJob
{
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
};

int runSynthCommand(const SynthArgs& a)
{
    turb::run::SynthJob job = a;
    job.settingsText =
        commandSettingsText(*a.app, a.target.empty() ? std::vector<std::string>{} : std::vector<std::string>{a.target});
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    const turb::run::SynthRun done = turb::run::runSynth(job);
    if (!done.strictFailure.empty()) return reportFailure(done.strictFailure, kFailed);
    return kOk;
}

const std::vector<std::pair<std::string, turb::CombineSettings::Weighting>> kWeightings = [] {
    std::vector<std::pair<std::string, turb::CombineSettings::Weighting>> w;
    for (const turb::run::WeightingName& n : turb::run::kWeightingNames) w.emplace_back(n.name, n.weighting);
    return w;
}();

// A second-tier setting of the command: the option under `key`.
template<typename T>
CLI::Option* knob(CLI::App* app, const std::string& names, T& v, const std::string& help, const std::string& key)
{
    return setting(app->add_option(names, v, help), key);
}

// Where the coarse motion comes from beyond the everyday --target/--scene/--flow, and the exemplars' shape.
void addInputSettings(CLI::App* app, SynthArgs& a)
{
    knob(app, "--scene-res", a.sceneRes, "Scene cells NXxNYxNZ along x, y, z (z is up), as sim --res", "scene-res");
    knob(app, "--scene-seed", a.sceneSeed, "Scene emitter noise seed", "scene-seed");
    knob(app, "--flow-res", a.flowRes, "Analytic flow cells NXxNYxNZ along x, y, z; NZ = 1 is 2D", "flow-res");
    knob(app, "--flow-speed", a.flowSpeed, "Analytic flow speed, world units/s (the domain is 4 units wide)",
        "flow-speed");
    knob(app, "--flow-angle", a.flowAngle, "Uniform flow direction in the xy plane, degrees from +x", "flow-angle");
    knob(app, "--slice-z", a.sliceZ, "Synthesise in 2D on coarse layer K of a 3D input", "slice-z")
        ->check(finiteIn(0.0));
    knob(app, "--exemplar-scale", a.exemplarScale, "Texture scale: features this many times larger", "exemplar-scale")
        ->check(finitePositive());
    knob(app, "--volume-crop", a.volumeCrop, "vdb3 exemplars: use the central N^3 voxels", "volume-crop")
        ->check(CLI::Range(8, 128));
    setting(app->add_flag("--periodic", a.periodic, "Picture/VDB exemplars tile seamlessly (procedurals always do)"),
        "periodic");
    knob(app, "--views", a.views,
        "3D: local axis each exemplar looks along, e.g. 0,1,2 (0 = along L; one exemplar for all views by default)",
        "views");
    knob(app, "--view-weights", a.viewWeights, "3D: relative weight per view, e.g. 1,1,4", "view-weights");
    knob(app, "--obstacle", a.obstacle, "Obstacle signed distance: FILE.vdb[:GRID] in world units (grid 'surface')",
        "obstacle");
}

// The texture optimisation (Ma et al. sections 3.2-3.4, 3.7): pyramid, neighbourhoods, search, orientation.
void addSynthesisSettings(CLI::App* app, SynthArgs& a)
{
    turb::SynthSettings& s = a.seq.synth;
    setting(addEnum<turb::SearchMethod>(app, "--search,--synth.search", s.search,
                {{"tree", turb::SearchMethod::Tree}, {"kcoherence", turb::SearchMethod::KCoherence}},
                "Neighbourhood search: tree (the paper) or k-coherence (section 3.7)"),
        "synth.search");
    knob(app, "--k,--synth.kSimilar", s.kSimilar, "k-coherence: similar neighbourhoods per exemplar pixel",
        "synth.kSimilar")
        ->check(CLI::Range(1, 64));
    knob(app, "--tree-iterations,--synth.treeIterationsPerLevel", s.treeIterationsPerLevel,
        "k-coherence: iterations per level that still search the tree (0 = pure k-coherence)",
        "synth.treeIterationsPerLevel")
        ->check(CLI::Range(0, 100));
    knob(app, "--levels,--synth.levels", s.levels, "Pyramid levels (0 = the paper's: 3, or 2 for exemplars <= 16^2)",
        "synth.levels")
        ->check(CLI::Range(0, 8));
    knob(app, "--iterations", a.iterations, "Iterations per level: LARGE,SMALL in 2D, SMALL in 3D (paper 3-5)",
        "iterations");
    knob(app, "--radius", a.radius, "Neighbourhood radii LARGE,SMALL (8,4 = 17^2 and 9^2)", "radius");
    knob(app, "--spacing,--synth.spacing", s.spacing, "Distance between neighbourhood centres (0 = auto)",
        "synth.spacing")
        ->check(CLI::Range(0, 16));
    knob(app, "--tap-step,--synth.volumeTapStep", s.volumeTapStep,
        "vdb3 exemplars: a tap every N voxels over the 9^3 footprint (1 = all 729)", "synth.volumeTapStep")
        ->check(CLI::Range(1, 4));
    knob(app, "--pca,--synth.pcaComponents", s.pcaComponents, "PCA dimensions for the tree search",
        "synth.pcaComponents")
        ->check(CLI::Range(1, 256));
    knob(app, "--robust,--synth.robustExponent", s.robustExponent,
        "Robust exponent r of Kwatra's weights (2 = least squares)", "synth.robustExponent")
        ->check(finiteIn(0.01, 2.0));
    boolSetting(app, "--synth.matchVariance", s.matchVariance,
        "3D: views keep their mean and spread (false: the paper's plain average)", "synth.matchVariance");
    legacy(app->add_flag_function(
               "--no-variance-match", [&s](int64_t) { s.matchVariance = false; }, ""),
        "synth.matchVariance", "false");
    boolSetting(app, "--synth.orientation.follow", s.orientation.follow,
        "Neighbourhoods and vectors follow L's local frame (false: world axes)", "synth.orientation.follow");
    legacy(app->add_flag_function(
               "--no-orient", [&s](int64_t) { s.orientation.follow = false; }, ""),
        "synth.orientation.follow", "false");
    knob(app, "--secondary", a.secondary,
        "3D second local axis: density (its gradient, else the direction L has least of) or a fixed vector X,Y,Z",
        "secondary");
    knob(app, "--seed,--synth.seed", s.seed, "Random seed: the same seed gives the same output", "synth.seed");
    knob(app, "--continue-iterations,--synth.continueIterations", s.continueIterations,
        "Later frames: iterations from the advected detail", "synth.continueIterations")
        ->check(CLI::Range(1, 100));
    knob(app, "--temporal-weight,--synth.temporalWeight", s.temporalWeight,
        "Later frames: pull toward the advected detail", "synth.temporalWeight")
        ->check(finiteIn(0.0));
    knob(app, "--wall-lambda,--synth.boundary.lambda", s.boundary.lambda,
        "Wall term weight: normal detail shrinks by 1/(1+lambda) on the wall", "synth.boundary.lambda")
        ->check(finiteIn(0.0));
    knob(app, "--wall-width,--synth.boundary.width", s.boundary.width,
        "Gaussian width of the wall term in voxels of each level", "synth.boundary.width")
        ->check(finitePositive());
    knob(app, "--face-padding,--synth.facePadding", s.facePadding,
        "Coarse cells synthesised beyond each open box face and cut off, so faces show no seams (0 = the paper)",
        "synth.facePadding")
        ->check(CLI::Range(0, 16));
    setting(app->add_flag("--trace-descent,--synth.traceDescent", s.traceDescent,
                "JSON: Kwatra's objective at every step of every iteration (levels[].descent; slower)"),
        "synth.traceDescent");
}

// CLI11's number ranges let NaN through and print their infinite bound in full.
CLI::Validator coarseCells(bool zeroOk)
{
    return CLI::Validator(
        [zeroOk](std::string& text) -> std::string {
            double v = 0.0;
            if (!parseNumber(text, v) || !std::isfinite(v) || v > 1e6 || (zeroOk ? v < 0.0 : v <= 0.0))
                return std::string("must be a number of coarse cells ") + (zeroOk ? ">= 0" : "> 0") + " (up to 1e6)";
            return {};
        },
        zeroOk ? "CELLS>=0" : "CELLS>0");
}

// F = up(L) + omega H' (section 3.5), the projection, the density and the pictures.
void addCombineSettings(CLI::App* app, SynthArgs& a)
{
    turb::SynthSequenceSettings& q = a.seq;
    turb::CombineSettings& c = q.combine;
    boolSetting(app, "--combine.removeCoarsePart", c.removeCoarsePart,
        "Take the detail's coarse part out, so the coarse motion stays L's (false: the paper's F)",
        "combine.removeCoarsePart");
    legacy(app->add_flag_function(
               "--keep-coarse", [&c](int64_t) { c.removeCoarsePart = false; }, ""),
        "combine.removeCoarsePart", "false");
    boolSetting(app, "--combine.solenoidalDetail", c.solenoidalDetail,
        "Take the detail's central-difference divergence out, so F's div_rel stays at or below L's (false: the paper)",
        "combine.solenoidalDetail");
    legacy(app->add_flag_function(
               "--keep-divergence", [&c](int64_t) { c.solenoidalDetail = false; }, ""),
        "combine.solenoidalDetail", "false");
    knob(app, "--combine.solenoidalTolerance", c.solenoidalTolerance,
        "Relative rms divergence left in the detail by that solve", "combine.solenoidalTolerance")
        ->check(finiteIn(1e-9, 0.999));
    knob(app, "--combine.solenoidalIterations", c.solenoidalIterations, "Conjugate-gradient cap of that solve",
        "combine.solenoidalIterations")
        ->check(CLI::Range(1, 100000));
    boolSetting(app, "--combine.relative", c.relative, "omega is relative to L's rms speed (false: velocity units)",
        "combine.relative");
    legacy(app->add_flag_function(
               "--omega-absolute", [&c](int64_t) { c.relative = false; }, ""),
        "combine.relative", "false");
    setting(addEnum<turb::CombineSettings::Weighting>(app, "--omega-mode,--combine.weighting", c.weighting, kWeightings,
                "Shape of omega: constant, energy (|L|^2), vorticity (|curl L|)"),
        "combine.weighting");
    knob(app, "--detail-margin,--combine.smokeMargin", c.smokeMargin,
        "Coarse cells of full detail around the smoke; the detail then fades out", "combine.smokeMargin")
        ->check(coarseCells(true));
    knob(app, "--detail-falloff,--combine.smokeFalloff", c.smokeFalloff,
        "Coarse cells over which the detail fades to zero beyond the margin", "combine.smokeFalloff")
        ->check(coarseCells(false));
    boolSetting(app, "--detailNearSmoke", q.detailNearSmoke,
        "Detail near the smoke only, when L has density (false: the whole box, the paper)", "detailNearSmoke");
    legacy(app->add_flag_function(
               "--detail-everywhere", [&q](int64_t) { q.detailNearSmoke = false; }, ""),
        "detailNearSmoke", "false");
    knob(app, "--project-iterations,--projectIterations", q.projectIterations, "Conjugate-gradient cap of --project",
        "projectIterations")
        ->check(CLI::Range(1, 100000));
    boolSetting(
        app, "--detailOnly", q.detailOnly, "Write F - up(L), what the synthesis added (false: F)", "detailOnly");
    legacy(app->add_option_function<std::string>(
                  "--output", [&q](const std::string& v) { q.detailOnly = v == "detail"; }, "combined or detail")
               ->check(CLI::IsMember({"combined", "detail"})),
        "detailOnly");
    knob(app, "--lookback", q.lookback, "Density: frames of look-back integration m (paper 10-20; 0 = naive)",
        "lookback")
        ->check(CLI::Range(0, 200));
    boolSetting(app, "--density", q.density, "Carry a fine density (false: velocity only)", "density");
    legacy(app->add_flag_function(
               "--no-density", [&q](int64_t) { q.density = false; }, ""),
        "density", "false");
    knob(app, "--preview-format", a.previewFormat, "Picture format of --preview: png, exr (linear half), tif",
        "preview-format")
        ->check(CLI::IsMember({"png", "exr", "tif"}));
    knob(app, "--preview-width", a.previewWidth, "Width of each preview panel in pixels", "preview-width")
        ->check(CLI::Range(32, 4096));
    knob(app, "--preview-view", a.previewView, "Preview slice: top, front, side (top in 2D, front in 3D)",
        "preview-view")
        ->check(CLI::IsMember({"top", "front", "side"}));
    setting(app->add_flag("--stats", a.stats,
                "Texture statistics per frame: nearest-neighbour distance to each exemplar against a shuffled field"),
        "stats");
}

} // namespace

Command synthCommand()
{
    auto args = std::make_shared<SynthArgs>();
    Command c;
    c.name = "synth";
    c.help = "Motion-field texture synthesis: detail motion from small exemplars, oriented along a coarse flow";
    c.setup = [args](CLI::App* app) {
        SynthArgs& a = *args;
        app->add_option("--target", a.target, "Coarse motion L: a VDB cache (pattern or one file); density optional");
        app->add_option("--scene", a.scene,
            "Coarse motion from a built-in scene simulated on the fly (plume, swirl, obstacle, wind)");
        app->add_option("--flow", a.flow, "Coarse motion from an analytic flow (no density)")
            ->check(CLI::IsMember({"uniform", "vortex", "shear"}));
        app->add_option(
               "--frames", a.frames, "Cache: frames to use (default all). Scene/flow: a count N or a list (default 1)")
            ->check(frameListCheck());
        app->add_option("--factor", a.seq.factor, "Up-res factor: output voxel = coarse voxel / factor")
            ->check(CLI::Range(1, 32));
        app->add_option("--exemplar", a.exemplars,
            "Exemplar, repeatable (one per view): circles|swirls|squares|hearts|stripes|sinusoids[:PERIOD[:SIZE]] "
            "(default "
            "circles:16), rg:PICTURE[:SCALE], gray:PICTURE[:SCALE], vdb:FILE.vdb[:AXIS:INDEX], vdb3:FILE.vdb "
            "(docs/synth.md)");
        app->add_option("--omega", a.seq.combine.omega, "Detail strength: times rms|L|")->check(finiteIn(0.0));
        app->add_option(
            "--walls", a.walls, "Walls: x-,x+,y-,y+,z-,z+, all or none (default: a scene's closed faces, else none)");
        app->add_flag(
            "--project", a.seq.project, "Make F divergence-free (Helmholtz-Hodge projection); walls are closed faces");
        app->add_flag("--strict", a.strict,
            "Exit 1 when a projection or the detail's divergence solve does not converge (always a warning naming the "
            "frame)");
        app->add_option(
            "--preview", a.preview, "Write a picture per frame into DIR: LIC of exemplar, up(L), H', F, and density");
        app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.read);
        app->add_option("--out", a.out, "Output pattern (directories are created)")->group(kGroupOutput);
        addWriteOptions(app, a.write);
        app->add_flag("--skip-existing", a.skipExisting,
               "Skip the frames already written by the same settings (farm wrappers' retries; the frames before the "
               "last one to write are made again, not written); a frame written otherwise is refused (exit 1)")
            ->group(kGroupOutput);
        a.app = app;
        addInputSettings(app, a);
        addSynthesisSettings(app, a);
        addCombineSettings(app, a);
    };
    c.run = [args] { return runSynthCommand(*args); };
    return c;
}

} // namespace vdbturb
