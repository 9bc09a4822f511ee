// synth's second tier as a settings table (turb/run/Settings.h): the coarse motion's and exemplars' shape, the
// texture optimisation and F's combination, under the keys settings files used, in the order --help-all lists them.
#include "SettingsRows.h"

#include <turb/run/Flags.h>
#include <turb/run/Synth.h>

#include <cmath>

namespace turb::run {

namespace {

using detail::add;
using Table = SettingsTable<SynthJob>;

// Where the coarse motion comes from beyond the everyday --target/--scene/--flow, and the exemplars' shape.
void addInput(Table& t)
{
    add(t, "scene-res", "", "Scene cells NXxNYxNZ along x, y, z (z is up), as sim --res", TURB_FIELD(sceneRes));
    add(t, "scene-seed", "", "Scene emitter noise seed", TURB_FIELD(sceneSeed));
    add(t, "flow-res", "", "Analytic flow cells NXxNYxNZ along x, y, z; NZ = 1 is 2D", TURB_FIELD(flowRes));
    add(t, "flow-speed", "", "Analytic flow speed, world units/s (the domain is 4 units wide)", TURB_FIELD(flowSpeed));
    add(t, "flow-angle", "", "Uniform flow direction in the xy plane, degrees from +x", TURB_FIELD(flowAngle));
    // Its default, -1 (3D), is no value to give: a layer is >= 0.
    add(t, "slice-z", "", "Synthesise in 2D on coarse layer K of a 3D input", TURB_FIELD(sliceZ), 0);
    add(t, "exemplar-scale", "", "Texture scale: features this many times larger", TURB_FIELD(exemplarScale), 0.0)
        .lowOpen = true;
    add(t, "volume-crop", "", "vdb3 exemplars: use the central N^3 voxels", TURB_FIELD(volumeCrop), 8, 128);
    add(t, "periodic", "", "Picture/VDB exemplars tile seamlessly (procedurals always do)", TURB_FIELD(periodic)).flag =
        true;
    add(t, "views", "",
        "3D: local axis each exemplar looks along, e.g. 0,1,2 (0 = along L; one exemplar for all views by default)",
        TURB_FIELD(views));
    add(t, "view-weights", "", "3D: relative weight per view, e.g. 1,1,4", TURB_FIELD(viewWeights));
    add(t, "obstacle", "", "Obstacle signed distance: FILE.vdb[:GRID] in world units (grid 'surface')",
        TURB_FIELD(obstacle));
}

// The texture optimisation (Ma et al. sections 3.2-3.4, 3.7): pyramid, neighbourhoods, search, orientation.
void addSynthesis(Table& t)
{
    add(t, "synth.search", "search", "Neighbourhood search: tree (the paper) or k-coherence (section 3.7)",
        TURB_FIELD(seq.synth.search))
        .choices = {{"tree", int(SearchMethod::Tree)}, {"kcoherence", int(SearchMethod::KCoherence)}};
    add(t, "synth.kSimilar", "k", "k-coherence: similar neighbourhoods per exemplar pixel",
        TURB_FIELD(seq.synth.kSimilar), 1, 64);
    add(t, "synth.treeIterationsPerLevel", "tree-iterations",
        "k-coherence: iterations per level that still search the tree (0 = pure k-coherence)",
        TURB_FIELD(seq.synth.treeIterationsPerLevel), 0, 100);
    add(t, "synth.levels", "levels", "Pyramid levels (0 = the paper's: 3, or 2 for exemplars <= 16^2)",
        TURB_FIELD(seq.synth.levels), 0, 8);
    add(t, "iterations", "", "Iterations per level: LARGE,SMALL in 2D, SMALL in 3D (paper 3-5)",
        TURB_FIELD(iterations));
    add(t, "radius", "", "Neighbourhood radii LARGE,SMALL (8,4 = 17^2 and 9^2)", TURB_FIELD(radius));
    add(t, "synth.spacing", "spacing", "Distance between neighbourhood centres (0 = auto)",
        TURB_FIELD(seq.synth.spacing), 0, 16);
    add(t, "synth.volumeTapStep", "tap-step",
        "vdb3 exemplars: a tap every N voxels over the 9^3 footprint (1 = all 729)",
        TURB_FIELD(seq.synth.volumeTapStep), 1, 4);
    add(t, "synth.pcaComponents", "pca", "PCA dimensions for the tree search", TURB_FIELD(seq.synth.pcaComponents), 1,
        256);
    add(t, "synth.robustExponent", "robust", "Robust exponent r of Kwatra's weights (2 = least squares)",
        TURB_FIELD(seq.synth.robustExponent), 0.01, 2.0);
    add(t, "synth.matchVariance", "", "3D: views keep their mean and spread (false: the paper's plain average)",
        TURB_FIELD(seq.synth.matchVariance));
    add(t, "synth.orientation.follow", "", "Neighbourhoods and vectors follow L's local frame (false: world axes)",
        TURB_FIELD(seq.synth.orientation.follow));
    add(t, "secondary", "",
        "3D second local axis: density (its gradient, else the direction L has least of) or a fixed vector X,Y,Z",
        TURB_FIELD(secondary));
    add(t, "synth.seed", "seed", "Random seed: the same seed gives the same output", TURB_FIELD(seq.synth.seed));
    add(t, "synth.continueIterations", "continue-iterations", "Later frames: iterations from the advected detail",
        TURB_FIELD(seq.synth.continueIterations), 1, 100);
    add(t, "synth.temporalWeight", "temporal-weight", "Later frames: pull toward the advected detail",
        TURB_FIELD(seq.synth.temporalWeight), 0.0);
    add(t, "synth.boundary.lambda", "wall-lambda",
        "Wall term weight: normal detail shrinks by 1/(1+lambda) on the wall", TURB_FIELD(seq.synth.boundary.lambda),
        0.0);
    add(t, "synth.boundary.width", "wall-width", "Gaussian width of the wall term in voxels of each level",
        TURB_FIELD(seq.synth.boundary.width), 0.0)
        .lowOpen = true;
    add(t, "synth.facePadding", "face-padding",
        "Coarse cells synthesised beyond each open box face and cut off, so faces show no seams (0 = the paper)",
        TURB_FIELD(seq.synth.facePadding), 0, 16);
    add(t, "synth.traceDescent", "trace-descent",
        "JSON: Kwatra's objective at every step of every iteration (levels[].descent; slower)",
        TURB_FIELD(seq.synth.traceDescent))
        .flag = true;
}

// The detail's margins in coarse cells: a message in their words, as the command line has always given (CLI11's
// number ranges let NaN through and print their infinite bound in full). 1e6 is the row's hi.
Setting<SynthJob>& coarseCells(Setting<SynthJob>& row, bool zeroOk)
{
    row.hi = 1e6;
    row.lowOpen = !zeroOk;
    row.typeName = zeroOk ? "CELLS>=0" : "CELLS>0";
    row.validate = [zeroOk](const std::string& text) -> std::string {
        double v = 0.0;
        if (!parseNumber(text, v) || !std::isfinite(v) || v > 1e6 || (zeroOk ? v < 0.0 : v <= 0.0))
            return std::string("must be a number of coarse cells ") + (zeroOk ? ">= 0" : "> 0") + " (up to 1e6)";
        return {};
    };
    return row;
}

// F = up(L) + omega H' (section 3.5): the detail's coarse part and divergence, omega's shape and where it goes.
void addCombine(Table& t)
{
    add(t, "combine.removeCoarsePart", "",
        "Take the detail's coarse part out, so the coarse motion stays L's (false: the paper's F)",
        TURB_FIELD(seq.combine.removeCoarsePart));
    add(t, "combine.solenoidalDetail", "",
        "Take the detail's central-difference divergence out, so F's div_rel stays at or below L's (false: the paper)",
        TURB_FIELD(seq.combine.solenoidalDetail));
    add(t, "combine.solenoidalTolerance", "", "Relative rms divergence left in the detail by that solve",
        TURB_FIELD(seq.combine.solenoidalTolerance), 1e-9, 0.999);
    add(t, "combine.solenoidalIterations", "", "Conjugate-gradient cap of that solve",
        TURB_FIELD(seq.combine.solenoidalIterations), 1, 100000);
    add(t, "combine.relative", "", "omega is relative to L's rms speed (false: velocity units)",
        TURB_FIELD(seq.combine.relative));
    Setting<SynthJob>& weighting = add(t, "combine.weighting", "omega-mode",
        "Shape of omega: constant, energy (|L|^2), vorticity (|curl L|)", TURB_FIELD(seq.combine.weighting));
    for (const WeightingName& n : kWeightingNames) weighting.choices.push_back({n.name, int(n.weighting)});
    coarseCells(add(t, "combine.smokeMargin", "detail-margin",
                    "Coarse cells of full detail around the smoke; the detail then fades out",
                    TURB_FIELD(seq.combine.smokeMargin), 0.0),
        true);
    coarseCells(add(t, "combine.smokeFalloff", "detail-falloff",
                    "Coarse cells over which the detail fades to zero beyond the margin",
                    TURB_FIELD(seq.combine.smokeFalloff), 0.0),
        false);
    add(t, "detailNearSmoke", "", "Detail near the smoke only, when L has density (false: the whole box, the paper)",
        TURB_FIELD(seq.detailNearSmoke));
}

// The projection, the output velocity, the density and the pictures.
void addOutput(Table& t)
{
    add(t, "projectIterations", "project-iterations", "Conjugate-gradient cap of --project",
        TURB_FIELD(seq.projectIterations), 1, 100000);
    add(t, "detailOnly", "", "Write F - up(L), what the synthesis added (false: F)", TURB_FIELD(seq.detailOnly));
    add(t, "lookback", "", "Density: frames of look-back integration m (paper 10-20; 0 = naive)",
        TURB_FIELD(seq.lookback), 0, 200);
    add(t, "density", "", "Carry a fine density (false: velocity only)", TURB_FIELD(seq.density));
    add(t, "preview-format", "", "Picture format of --preview: png, exr (linear half), tif", TURB_FIELD(previewFormat))
        .oneOf = {"png", "exr", "tif"};
    add(t, "preview-width", "", "Width of each preview panel in pixels", TURB_FIELD(previewWidth), 32, 4096);
    // Its default, "" (by the cache's kind), is no value to give.
    add(t, "preview-view", "", "Preview slice: top, front, side (top in 2D, front in 3D)", TURB_FIELD(previewView))
        .oneOf = {"top", "front", "side"};
    add(t, "stats", "",
        "Texture statistics per frame: nearest-neighbour distance to each exemplar against a shuffled field",
        TURB_FIELD(stats))
        .flag = true;
}

} // namespace

const SettingsTable<SynthJob>& synthSettings()
{
    static const Table table = detail::tableOf<SynthJob>({addInput, addSynthesis, addCombine, addOutput});
    return table;
}

const std::vector<OldSpelling>& synthOldSpellings()
{
    // --output combined|detail (detailOnly) maps its words to the bool, which an OldSpelling cannot say: cmd_synth.cc
    // declares it.
    static const std::vector<OldSpelling> spellings{{"no-variance-match", "synth.matchVariance", "false", ""},
        {"no-orient", "synth.orientation.follow", "false", ""},
        {"keep-coarse", "combine.removeCoarsePart", "false", ""},
        {"keep-divergence", "combine.solenoidalDetail", "false", ""},
        {"omega-absolute", "combine.relative", "false", ""}, {"detail-everywhere", "detailNearSmoke", "false", ""},
        {"no-density", "density", "false", ""}};
    return spellings;
}

} // namespace turb::run
