// transfer's second tier as a settings table (turb/run/Settings.h): TransferSettings' solver and experimental knobs
// under their fields' names, in the order --help-all lists them.
#include "SettingsRows.h"

#include <turb/run/Transfer.h>

namespace turb::run {

namespace {

using detail::add;
using Table = SettingsTable<TransferJob>;

const std::vector<Choice> kEnergies{{"source", int(DetailEnergy::Source)}, {"pasted", int(DetailEnergy::Pasted)},
    {"none", int(DetailEnergy::None)}, {"distribution", int(DetailEnergy::Distribution)}};

// Matching (Sato et al. section 3.2): patch sizes, descriptor, candidates and the energy's weights.
void addSearch(Table& t)
{
    add(t, "alpha", "", "Weight of the density-mask term in matching (paper 0.004)", TURB_FIELD(settings.alpha), 0.0);
    add(t, "beta", "", "Weight of the temporal term: previous detail advected (paper 0.5)", TURB_FIELD(settings.beta),
        0.0);
    add(t, "densityThreshold", "density-threshold", "D_th: smoke where density > this",
        TURB_FIELD(settings.densityThreshold), 0.0);
    add(t, "localPatch", "patch", "B: local patch edge in output voxels", TURB_FIELD(settings.localPatch), 2, 64);
    add(t, "globalPatch", "global-patch", "b: global patch edge in target voxels, odd (0 = 2*ceil(B/f)+1)",
        TURB_FIELD(settings.globalPatch));
    add(t, "pcaComponents", "pca", "PCA dimensions of patch descriptors", TURB_FIELD(settings.pcaComponents), 1, 256);
    add(t, "localStride", "stride", "Spacing of candidate source patches in the local search",
        TURB_FIELD(settings.localStride), 1, 16);
    add(t, "refineCandidates", "candidates", "Local candidates re-scored at full resolution",
        TURB_FIELD(settings.refineCandidates), 1, 4096);
}

// Seam smoothing (section 3.3): the band, the boundary patches, EM and CG.
void addSeams(Table& t)
{
    add(t, "seams.gamma", "gamma", "Weight of divergence in seam smoothing (paper 10)",
        TURB_FIELD(settings.seams.gamma), 0.0);
    add(t, "seams.bandWidth", "", "Seam band: voxels on each side of a patch border (3D)",
        TURB_FIELD(settings.seams.bandWidth), 1, 32);
    add(t, "seams.bandWidth2D", "", "Seam band on 2D caches", TURB_FIELD(settings.seams.bandWidth2D), 1, 32);
    add(t, "seams.boundaryPatch", "boundary-patch", "C: boundary patch edge, even (0 = B)",
        TURB_FIELD(settings.seams.boundaryPatch));
    add(t, "seams.maxEmIterations", "em-iterations", "Seam EM iterations at most",
        TURB_FIELD(settings.seams.maxEmIterations), 1, 50);
    add(t, "seams.emTolerance", "em-tolerance", "Stop EM when E_b changes by less than this fraction",
        TURB_FIELD(settings.seams.emTolerance));
    add(t, "seams.maxCgIterations", "cg-iterations", "CG iterations per E-step at most",
        TURB_FIELD(settings.seams.maxCgIterations), 1, 100000);
    add(t, "seams.cgTolerance", "", "CG relative residual (3D)", TURB_FIELD(settings.seams.cgTolerance), 1e-12, 1.0);
    add(t, "seams.cgTolerance2D", "", "CG relative residual on 2D caches", TURB_FIELD(settings.seams.cgTolerance2D),
        1e-12, 1.0);
    add(t, "seams.valueWeight", "value-weight",
        "Weight of seam-solve rows keeping carried detail at its value (0 = the paper's energy)",
        TURB_FIELD(settings.seams.valueWeight), 0.0);
    add(t, "seams.boxWeight", "box-weight",
        "Weight of the seam-solve rows holding U_h's coarse-cell means (0 = free; coarseTolerance bounds them)",
        TURB_FIELD(settings.seams.boxWeight), 0.0);
    add(t, "seams.solver", "seam-solver",
        "Seam E-step solver: cgnr (matrix-free, parallel) or eigen (Eigen's LeastSquaresConjugateGradient)",
        TURB_FIELD(settings.seams.solver))
        .choices = {{"cgnr", int(SeamSolver::Cgnr)}, {"eigen", int(SeamSolver::EigenLscg)}};
    add(t, "seams.boxKeep", "box-keep",
        "Fraction of each coarse cell's mean of U_h the seam solve keeps (1: leaves the coarse motion; 0: pulls it to "
        "0)",
        TURB_FIELD(settings.seams.boxKeep), 0.0, 1.0);
    add(t, "seams.enabled", "", "Seam smoothing (false: paste patches as they are)",
        TURB_FIELD(settings.seams.enabled));
}

// Beyond the paper: what U_h keeps of its coarse part, how patches follow the source, resampling.
void addDetail(Table& t)
{
    add(t, "coarseTolerance", "coarse-tolerance",
        "lf_err bound: U_h's coarse-cell means are reduced only down to this fraction of the target's (0 = exactly)",
        TURB_FIELD(settings.coarseTolerance), 0.0, 1.0);
    add(t, "removeCoarseDetail", "", "Reduce U_h's coarse part (false lets lf_err grow)",
        TURB_FIELD(settings.removeCoarseDetail));
    add(t, "coherence", "",
        "Take a neighbour's continued source patch within this fraction of the best E_h (0 = off, the paper)",
        TURB_FIELD(settings.coherence), 0.0);
    add(t, "solveFreshPatchesWhole", "whole-fresh-patches",
        "Solve every voxel of patches without carried detail, not only the seam band",
        TURB_FIELD(settings.solveFreshPatchesWhole))
        .flag = true;
    add(t, "resampleSource", "",
        "Resample a source at a non-integer ratio trilinearly to the nearest integer one (false: refuse it)",
        TURB_FIELD(settings.resampleSource));
    add(t, "followSourceFlow", "",
        "Patches follow the source's flow from frame to frame (false: re-paste where last frame found them)",
        TURB_FIELD(settings.followSourceFlow));
    add(t, "followTolerance", "follow-tolerance",
        "Keep a patch's continuation while its E_h is within (1 + this) of the best",
        TURB_FIELD(settings.followTolerance), 0.0);
    add(t, "sourceSmoke", "source-smoke",
        "Fraction of a source patch's voxels that must hold smoke for it to be a candidate (0 = any, the paper)",
        TURB_FIELD(settings.sourceSmoke), 0.0, 1.0);
}

// The detail's strength and shape (docs/look.md's departures from the paper) and its energy (section 3.4).
void addDetailStrength(Table& t)
{
    add(t, "evenPatches", "even-patches",
        "How far to even out the detail's strength over the position in the patch (variance-preserving seams; 0 = "
        "off, the paper)",
        TURB_FIELD(settings.evenPatches), 0.0, 1.0);
    add(t, "localEnergy", "local-energy",
        "How far each patch's detail strength moves toward the source detail pasted into it, the frame's total kept "
        "(0 = one factor per frame)",
        TURB_FIELD(settings.localEnergy), 0.0, 1.0);
    add(t, "vorticityLimit", "vorticity-limit",
        "Scale the detail down where the vorticity exceeds this times the source's 0.999 quantile (0 = off)",
        TURB_FIELD(settings.vorticityLimit), 0.0);
    add(t, "repeatRadius", "repeat-radius",
        "Patches within this many patches never take overlapping source patches (0 = off, the paper)",
        TURB_FIELD(settings.repeatRadius), 0, 4);
    add(t, "repeatTolerance", "", "Avoid a repeat with a candidate whose E_h is within (1 + this) of the best",
        TURB_FIELD(settings.repeatTolerance), 0.0);
    add(t, "trackGlobalPatches", "", "Follow last frame's global patch (false: global search every frame)",
        TURB_FIELD(settings.trackGlobalPatches));
    add(t, "detailEnergy", "",
        "U_h's energy per smoke voxel on 3D caches: source (the source's high-frequency energy), pasted (the pasted "
        "patches' energy), none (as made), or distribution (|U_h| remapped rank for rank onto the source detail's "
        "magnitudes, then the source's energy)",
        TURB_FIELD(settings.detailEnergy))
        .choices = kEnergies;
    add(t, "detailEnergy2D", "detail-energy-2d", "The same on 2D (one z layer) caches",
        TURB_FIELD(settings.detailEnergy2D))
        .choices = kEnergies;
    add(t, "compensateTargetDivergence", "",
        "The seam gamma term penalises div(up(u_t) + U_h) (false: div(U_h), the paper)",
        TURB_FIELD(settings.compensateTargetDivergence));
}

// Temporal coherence and regeneration of stretched detail.
void addTime(Table& t)
{
    add(t, "temporalBlend", "temporal-blend",
        "Weight of last frame's detail advected through the target (0 = the paper)", TURB_FIELD(settings.temporalBlend),
        0.0, 0.999);
    add(t, "regenerate", "",
        "Regenerate carried detail stretched below this fraction of the fresh patches' anisotropy (0 = off)",
        TURB_FIELD(settings.regenerate), 0.0, 1.0);
    add(t, "regenerateBlend", "", "Carried weight per frame in a regenerated patch (3D)",
        TURB_FIELD(settings.regenerateBlend), 0.0, 0.999);
    add(t, "regenerateBlend2D", "", "The same on 2D caches", TURB_FIELD(settings.regenerateBlend2D), 0.0, 0.999);
    add(t, "structureTolerance", "",
        "Regenerate more patches while the detail's anisotropy is this fraction off the source's, and redo a frame "
        "that finishes 3x this off (3D; 0 = off)",
        TURB_FIELD(settings.structureTolerance), 0.0, 0.99);
    add(t, "structureTolerance2D", "", "The same on 2D caches", TURB_FIELD(settings.structureTolerance2D), 0.0, 0.99);
    add(t, "alignment", "align", "Match after aligning flows: none (the paper), normalize, rotate, both",
        TURB_FIELD(settings.alignment))
        .choices = {{"none", int(FlowAlignment::None)}, {"normalize", int(FlowAlignment::Normalize)},
        {"rotate", int(FlowAlignment::Rotate)}, {"both", int(FlowAlignment::Both)}};
    add(t, "lookBackFrames", "lookback", "m for --density lookback", TURB_FIELD(settings.lookBackFrames), 1, 100);
}

// The output density and the source's velocity extension.
void addDensity(Table& t)
{
    add(t, "densityScheme", "density-scheme", "Advection scheme of the output density",
        TURB_FIELD(settings.densityScheme))
        .choices = {{"bfecc", int(AdvectSettings::Scheme::BFECC)},
        {"maccormack", int(AdvectSettings::Scheme::MacCormack)},
        {"semi-lagrangian", int(AdvectSettings::Scheme::SemiLagrangian)}};
    add(t, "densityGuide.strength", "density-guide",
        "Fraction of the way the output density's coarse means move onto the target's per frame (0 = off)",
        TURB_FIELD(settings.densityGuide.strength), 0.0, 1.0);
    add(t, "interfaceCompression", "interface-compression",
        "Sharpen the output density's edge: interface compression in voxels per frame (0 = off; docs/look.md: 0.5)",
        TURB_FIELD(settings.interfaceCompression), 0.0, 1.0);
    add(t, "levelSetDiffusion", "level-set-diffusion",
        "Even out hairs along the output density's surface: diffusion along its level sets per pass (0 = off; "
        "docs/look.md: 0.15)",
        TURB_FIELD(settings.levelSetDiffusion), 0.0, 1.0 / 6.0);
    add(t, "levelSetDiffusionPasses", "level-set-diffusion-passes", "Passes of the level-set diffusion per frame",
        TURB_FIELD(settings.levelSetDiffusionPasses), 0, 20);
    add(t, "sourceRead.extendVelocity", "extend-velocity",
        "Continue the source's velocity this many voxels past its active region (Blender clips it to the smoke; 0 = "
        "off)",
        TURB_FIELD(sourceRead.extendVelocity), 0, 64);
}

} // namespace

const SettingsTable<TransferJob>& transferSettings()
{
    static const Table table =
        detail::tableOf<TransferJob>({addSearch, addSeams, addDetail, addDetailStrength, addTime, addDensity});
    return table;
}

const std::vector<OldSpelling>& transferOldSpellings()
{
    static const std::vector<OldSpelling> spellings{
        {"band", "seams.bandWidth,seams.bandWidth2D", "", "Both seam band widths"},
        {"cg-tolerance", "seams.cgTolerance,seams.cgTolerance2D", "", "Both CG tolerances"},
        {"no-seams", "seams.enabled", "false", ""}, {"no-tracking", "trackGlobalPatches", "false", ""},
        {"detail-energy", "detailEnergy,detailEnergy2D", "", "Both detail energies (3D and 2D caches)"},
        {"no-target-divergence", "compensateTargetDivergence", "false", ""},
        {"keep-coarse-detail", "removeCoarseDetail", "false", ""},
        {"no-resample-source", "resampleSource", "false", ""}, {"no-follow-source", "followSourceFlow", "false", ""},
        {"regenerate-blend", "regenerateBlend,regenerateBlend2D", "", "Both regeneration blends"}};
    return spellings;
}

} // namespace turb::run
