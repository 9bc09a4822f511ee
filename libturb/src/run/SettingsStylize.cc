// stylize's second tier as a settings table (turb/run/Settings.h): the cache camera, the built-in target, and each
// method's knobs under turb::StylizeSettings' and turb::FluidySettings' field names, in the order --help-all lists
// them.
#include "SettingsRows.h"

#include <turb/run/Stylize.h>

namespace turb::run {

namespace {

using detail::add;
using Table = SettingsTable<StylizeJob>;

// The built-in target and what the run writes beside its frames.
void addTarget(Table& t)
{
    detail::addPart(t, cacheCameraSettings(), [](StylizeJob& job) -> CacheCamera& { return job.camera; });
    add(t, "scene-size", "", "Built-in target size WxH", TURB_FIELD(sceneSize));
    add(t, "scene-speed", "", "Built-in target: radians per frame at the centre (rise: widths per frame)",
        TURB_FIELD(sceneSpeed));
    add(t, "flow-y-up", "", "The flow images' G channel points up (Nuke, Houdini)", TURB_FIELD(flowYUp)).flag = true;
    add(t, "write-target", "", "Write the target per frame into DIR: alpha.####.png, motion.####.exr",
        TURB_FIELD(writeTarget));
}

// LazyFluids' knobs (Jamriška et al. 2015); their measured effects are in docs/stylize.md.
void addLazyFluids(Table& t)
{
    add(t, "nnf", "",
        "uniform: reversed NNF, uniform patch usage (the paper); standard: nearest neighbours (the wash-out ablation)",
        TURB_FIELD(settings.nnf))
        .choices = {{"uniform", int(NnfMode::Uniform)}, {"standard", int(NnfMode::Standard)}};
    add(t, "patchSize", "patch", "Patch size in pixels, odd (paper 5)", TURB_FIELD(settings.patchSize), 3, 15);
    add(t, "lambda", "", "Temporal coherence lambda (paper 0.2; 0 = independent frames)", TURB_FIELD(settings.lambda),
        0.0);
    add(t, "eta", "", "Weight of the blurred-alpha guide (paper 3)", TURB_FIELD(settings.eta), 0.0);
    add(t, "blurRadius", "blur-radius", "r: Gaussian standard deviation (pixels) of the guide alpha",
        TURB_FIELD(settings.blurRadius), 0.0)
        .lowOpen = true;
    add(t, "lower", "", "l: boundary segment where the blurred alpha lies in (l, u)", TURB_FIELD(settings.lower), 0.0,
        1.0);
    add(t, "upper", "", "u: interior segment where the blurred alpha >= u", TURB_FIELD(settings.upper), 0.0, 1.0);
    add(t, "levels", "", "Pyramid levels (0 = short sides >= 32 px, at most 5)", TURB_FIELD(settings.levels), 0, 8);
    add(t, "iterations", "", "EM iterations on each coarser level", TURB_FIELD(settings.iterations), 1, 50);
    add(t, "fineIterations", "fine-iterations", "EM iterations on the finest level",
        TURB_FIELD(settings.fineIterations), 1, 50);
    add(t, "sweeps", "", "PatchMatch sweeps per retrieval round", TURB_FIELD(settings.sweeps), 1, 32);
    add(t, "rotations", "", "Also use the exemplar rotated by 90, 180 and 270 degrees", TURB_FIELD(settings.rotations))
        .flag = true;
    add(t, "motionBlur", "motion-blur", "Blur along F^t by this fraction of a frame's motion (0 = none)",
        TURB_FIELD(settings.motionBlur), 0.0);
    add(t, "voteWeight", "vote-weight",
        "Beyond the paper: votes weighted by exp(-D / (w x the 75th percentile of D)) (Wexler 2007; 0 = the paper's "
        "plain average)",
        TURB_FIELD(settings.voteWeight), 0.0);
    add(t, "startFromPrevious", "",
        "Beyond the paper: later frames start every level from the previous output advected (false: coarse to fine, "
        "the paper)",
        TURB_FIELD(settings.startFromPrevious));
    add(t, "preroll", "",
        "Beyond the paper: a first frame is synthesised again N times as a held frame under the temporal term, so the "
        "look does not step between frames 1 and 5 (0 = the paper's first frame)",
        TURB_FIELD(settings.preroll), 0, 100);
    // Both methods read the seed.
    add(t, "seed", "", "Random seed: the same seed gives the same frames at any --threads", TURB_FIELD(settings.seed));
}

// Fluidymation's inputs beyond LazyFluids' and its knobs (Table 1's values are the defaults; docs/fluidymation.md).
void addFluidymationInputs(Table& t)
{
    add(t, "exemplar-flow", "",
        "[fluidymation] Exemplar flows, R,G in pixels per frame (empty: estimated from the masks)",
        TURB_FIELD(fluidy.exemplarFlow));
    add(t, "target-flow", "", "[fluidymation] Target flows, R,G in pixels per frame (empty: estimated from the masks)",
        TURB_FIELD(fluidy.targetFlow));
    add(t, "mask-threshold", "", "[fluidymation] Target alpha / rendered opacity at or above this is inside the mask",
        TURB_FIELD(fluidy.maskThreshold), 0.001, 1.0);
    add(t, "estimate-flow", "", "[fluidymation] Estimate the target's flow from its masks even when one is given",
        TURB_FIELD(fluidy.estimateFlow))
        .flag = true;
    add(t, "out-rot", "", "[fluidymation] Write T^rot per frame: float EXR/TIFF, R = theta (radians), G, B = cos, sin",
        TURB_FIELD(fluidy.outRot));
    add(t, "debug-nnf", "",
        "[fluidymation] Write the NNF per frame into DIR: nnf.####.exr (R = frame, G = x, B = y), nnf_theta, nnf_vis",
        TURB_FIELD(fluidy.debugNnf));
}

void addFluidymation(Table& t)
{
    add(t, "fluidy.patchSize", "n", "[fluidymation] Patch size n", TURB_FIELD(fluidy.settings.patchSize), 3, 15);
    add(t, "fluidy.boundaryBlur", "b", "[fluidymation] Boundary blur radius b in pixels (sigma = b/3)",
        TURB_FIELD(fluidy.settings.boundaryBlur), 0.1, 1000.0);
    add(t, "fluidy.cuboidFrames", "r",
        "[fluidymation] Occurrence cuboid half-length r in frames (the exemplar needs 2r+1)",
        TURB_FIELD(fluidy.settings.cuboidFrames), 0, 50);
    add(t, "fluidy.wBound", "w-bound", "[fluidymation] w^bound (0 = ablation)", TURB_FIELD(fluidy.settings.wBound),
        0.0);
    add(t, "fluidy.wExt", "w-ext", "[fluidymation] w^ext", TURB_FIELD(fluidy.settings.wExt), 0.0);
    add(t, "fluidy.wDir", "w-dir", "[fluidymation] w^dir", TURB_FIELD(fluidy.settings.wDir), 0.0);
    add(t, "fluidy.wTemp", "w-temp", "[fluidymation] w^temp", TURB_FIELD(fluidy.settings.wTemp), 0.0);
    add(t, "fluidy.wUni", "w-uni", "[fluidymation] w^uni", TURB_FIELD(fluidy.settings.wUni), 0.0);
    add(t, "fluidy.mLower", "m-lower", "[fluidymation] m_l as a fraction of the target's larger side",
        TURB_FIELD(fluidy.settings.mLower), 0.0, 10.0);
    add(t, "fluidy.mUpper", "m-upper", "[fluidymation] m_u as a fraction of the target's larger side",
        TURB_FIELD(fluidy.settings.mUpper), 0.0, 10.0);
    add(t, "fluidy.dirClamp", "dir-clamp", "[fluidymation] Clamp of |tan| in D^dir",
        TURB_FIELD(fluidy.settings.dirClamp), 0.0)
        .lowOpen = true;
    add(t, "fluidy.extentScale", "extent-scale",
        "[fluidymation] The exemplar's D^ext unit in pixels (0 = its 95th percentile)",
        TURB_FIELD(fluidy.settings.extentScale), 0.0);
    add(t, "fluidy.targetExtentScale", "target-extent-scale",
        "[fluidymation] The target's D^ext unit in pixels (0 = its own 95th percentile)",
        TURB_FIELD(fluidy.settings.targetExtentScale), 0.0);
    add(t, "fluidy.levels", "fluidy-levels", "[fluidymation] Pyramid levels (0 = floor(log2(d_min / n)))",
        TURB_FIELD(fluidy.settings.levels), 0, 8);
    add(t, "fluidy.iterations", "fluidy-iterations", "[fluidymation] EM iterations on coarser levels",
        TURB_FIELD(fluidy.settings.iterations), 1, 50);
    add(t, "fluidy.fineIterations", "fluidy-fine-iterations", "[fluidymation] EM iterations on the finest level",
        TURB_FIELD(fluidy.settings.fineIterations), 1, 50);
    add(t, "fluidy.sweeps", "fluidy-sweeps", "[fluidymation] PatchMatch sweeps per E-step on coarser levels",
        TURB_FIELD(fluidy.settings.sweeps), 1, 32);
    add(t, "fluidy.fineSweeps", "fluidy-fine-sweeps", "[fluidymation] PatchMatch sweeps per E-step on the finest level",
        TURB_FIELD(fluidy.settings.fineSweeps), 1, 32);
    add(t, "fluidy.reusePrevious", "", "[fluidymation] Start each frame from the previous one's NNF (false: random)",
        TURB_FIELD(fluidy.settings.reusePrevious));
}

} // namespace

const SettingsTable<StylizeJob>& stylizeSettings()
{
    static const Table table =
        detail::tableOf<StylizeJob>({addTarget, addLazyFluids, addFluidymationInputs, addFluidymation});
    return table;
}

const std::vector<OldSpelling>& stylizeOldSpellings()
{
    static const std::vector<OldSpelling> spellings{{"no-reuse", "fluidy.reusePrevious", "false", ""}};
    return spellings;
}

} // namespace turb::run
