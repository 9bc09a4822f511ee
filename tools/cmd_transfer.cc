// vdbturb transfer: turbulence style transfer (Sato et al. 2018) from a high-res source onto a low-res target.
// Parses the options into a turb::run::TransferJob and runs it (libturb/src/run/Transfer.cc).
#include "Commands.h"
#include "Console.h"

#include <turb/Farm.h>
#include <turb/Transfer.h>
#include <turb/run/Transfer.h>

#include <memory>
#include <utility>
#include <vector>

namespace vdbturb {

namespace {

using turb::run::kKindTwins;
using turb::run::TransferJob;

// The command line's transfer: the job, and the options whose being given matters.
struct TransferArgs : TransferJob
{
    const CLI::Option* sourceCropMargin = nullptr; ///< given or not: its default depends on the ratio
    const CLI::Option* velocityMargin = nullptr;   ///< given or not: --style blender ignores it, saying so if given
    /// kKindTwins' options as parsed (3D, 2D): one given for the other kind of cache gets a warning.
    std::vector<std::pair<const CLI::Option*, const CLI::Option*>> kindTwins;
};

int runTransfer(TransferArgs& a)
{
    TransferJob job = a;
    job.sourceCropMarginGiven = a.sourceCropMargin && a.sourceCropMargin->count() > 0;
    job.velocityMarginGiven = a.velocityMargin && a.velocityMargin->count() > 0;
    for (const auto& [threeD, twoD] : a.kindTwins)
        job.kindTwinsGiven.emplace_back(threeD->count() > 0, twoD->count() > 0);
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    turb::run::runTransfer(job);
    return kOk;
}

} // namespace

namespace {

// A numeric setting: the option, in the second tier under `key`.
template<typename T>
CLI::Option* num(CLI::App* app, const std::string& names, T& v, const std::string& help, const std::string& key)
{
    return setting(app->add_option(names, v, help), key);
}

// Matching (Sato et al. section 3.2): patch sizes, descriptor, candidates and the energy's weights.
void addSearchSettings(CLI::App* app, turb::TransferSettings& s)
{
    num(app, "--alpha", s.alpha, "Weight of the density-mask term in matching (paper 0.004)", "alpha")
        ->check(finiteIn(0.0));
    num(app, "--beta", s.beta, "Weight of the temporal term: previous detail advected (paper 0.5)", "beta")
        ->check(finiteIn(0.0));
    num(app, "--density-threshold,--densityThreshold", s.densityThreshold, "D_th: smoke where density > this",
        "densityThreshold")
        ->check(finiteIn(0.0));
    num(app, "--patch,--localPatch", s.localPatch, "B: local patch edge in output voxels", "localPatch")
        ->check(CLI::Range(2, 64));
    num(app, "--global-patch,--globalPatch", s.globalPatch,
        "b: global patch edge in target voxels, odd (0 = 2*ceil(B/f)+1)", "globalPatch");
    num(app, "--pca,--pcaComponents", s.pcaComponents, "PCA dimensions of patch descriptors", "pcaComponents")
        ->check(CLI::Range(1, 256));
    num(app, "--stride,--localStride", s.localStride, "Spacing of candidate source patches in the local search",
        "localStride")
        ->check(CLI::Range(1, 16));
    num(app, "--candidates,--refineCandidates", s.refineCandidates, "Local candidates re-scored at full resolution",
        "refineCandidates")
        ->check(CLI::Range(1, 4096));
}

// Seam smoothing (section 3.3): the band, the boundary patches, EM and CG.
void addSeamSettings(CLI::App* app, turb::SeamSettings& seams)
{
    num(app, "--gamma,--seams.gamma", seams.gamma, "Weight of divergence in seam smoothing (paper 10)", "seams.gamma")
        ->check(finiteIn(0.0));
    num(app, "--seams.bandWidth", seams.bandWidth, "Seam band: voxels on each side of a patch border (3D)",
        "seams.bandWidth")
        ->check(CLI::Range(1, 32));
    num(app, "--seams.bandWidth2D", seams.bandWidth2D, "Seam band on 2D caches", "seams.bandWidth2D")
        ->check(CLI::Range(1, 32));
    legacy(app->add_option_function<int>(
                  "--band", [&seams](int v) { seams.bandWidth = seams.bandWidth2D = v; }, "Both seam band widths")
               ->check(CLI::Range(1, 32)),
        "seams.bandWidth,seams.bandWidth2D");
    num(app, "--boundary-patch,--seams.boundaryPatch", seams.boundaryPatch, "C: boundary patch edge, even (0 = B)",
        "seams.boundaryPatch");
    num(app, "--em-iterations,--seams.maxEmIterations", seams.maxEmIterations, "Seam EM iterations at most",
        "seams.maxEmIterations")
        ->check(CLI::Range(1, 50));
    num(app, "--em-tolerance,--seams.emTolerance", seams.emTolerance,
        "Stop EM when E_b changes by less than this fraction", "seams.emTolerance");
    num(app, "--cg-iterations,--seams.maxCgIterations", seams.maxCgIterations, "CG iterations per E-step at most",
        "seams.maxCgIterations")
        ->check(CLI::Range(1, 100000));
    num(app, "--seams.cgTolerance", seams.cgTolerance, "CG relative residual (3D)", "seams.cgTolerance")
        ->check(finiteIn(1e-12, 1.0));
    num(app, "--seams.cgTolerance2D", seams.cgTolerance2D, "CG relative residual on 2D caches", "seams.cgTolerance2D")
        ->check(finiteIn(1e-12, 1.0));
    legacy(app->add_option_function<double>(
                  "--cg-tolerance", [&seams](double v) { seams.cgTolerance = seams.cgTolerance2D = v; },
                  "Both CG tolerances")
               ->check(finiteIn(1e-12, 1.0)),
        "seams.cgTolerance,seams.cgTolerance2D");
    num(app, "--value-weight,--seams.valueWeight", seams.valueWeight,
        "Weight of seam-solve rows keeping carried detail at its value (0 = the paper's energy)", "seams.valueWeight")
        ->check(finiteIn(0.0));
    num(app, "--box-weight,--seams.boxWeight", seams.boxWeight,
        "Weight of the seam-solve rows holding U_h's coarse-cell means (0 = free; coarseTolerance bounds them)",
        "seams.boxWeight")
        ->check(finiteIn(0.0));
    setting(addEnum<turb::SeamSolver>(app, "--seam-solver,--seams.solver", seams.solver,
                {{"cgnr", turb::SeamSolver::Cgnr}, {"eigen", turb::SeamSolver::EigenLscg}},
                "Seam E-step solver: cgnr (matrix-free, parallel) or eigen (Eigen's LeastSquaresConjugateGradient)"),
        "seams.solver");
    num(app, "--box-keep,--seams.boxKeep", seams.boxKeep,
        "Fraction of each coarse cell's mean of U_h the seam solve keeps (1: leaves the coarse motion; 0: pulls it to "
        "0)",
        "seams.boxKeep")
        ->check(finiteIn(0.0, 1.0));
    boolSetting(
        app, "--seams.enabled", seams.enabled, "Seam smoothing (false: paste patches as they are)", "seams.enabled");
    legacy(app->add_flag_function(
               "--no-seams", [&seams](int64_t) { seams.enabled = false; }, "seams.enabled = false"),
        "seams.enabled", "false");
}

// Beyond the paper: what U_h keeps of its coarse part, how patches follow the source, resampling.
// The detail's strength and shape (docs/look.md's departures from the paper) and its energy (section 3.4).
void addDetailStrengthSettings(CLI::App* app, turb::TransferSettings& s)
{
    num(app, "--even-patches,--evenPatches", s.evenPatches,
        "How far to even out the detail's strength over the position in the patch (variance-preserving seams; 0 = "
        "off, the paper)",
        "evenPatches")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--local-energy,--localEnergy", s.localEnergy,
        "How far each patch's detail strength moves toward the source detail pasted into it, the frame's total kept "
        "(0 = one factor per frame)",
        "localEnergy")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--vorticity-limit,--vorticityLimit", s.vorticityLimit,
        "Scale the detail down where the vorticity exceeds this times the source's 0.999 quantile (0 = off)",
        "vorticityLimit")
        ->check(finiteIn(0.0));
    num(app, "--repeat-radius,--repeatRadius", s.repeatRadius,
        "Patches within this many patches never take overlapping source patches (0 = off, the paper)", "repeatRadius")
        ->check(CLI::Range(0, 4));
    num(app, "--repeatTolerance", s.repeatTolerance,
        "Avoid a repeat with a candidate whose E_h is within (1 + this) of the best", "repeatTolerance")
        ->check(finiteIn(0.0));
    boolSetting(app, "--trackGlobalPatches", s.trackGlobalPatches,
        "Follow last frame's global patch (false: global search every frame)", "trackGlobalPatches");
    legacy(app->add_flag_function(
               "--no-tracking", [&s](int64_t) { s.trackGlobalPatches = false; }, "trackGlobalPatches = false"),
        "trackGlobalPatches", "false");
    const std::vector<std::pair<std::string, turb::DetailEnergy>> energies{{"source", turb::DetailEnergy::Source},
        {"pasted", turb::DetailEnergy::Pasted}, {"none", turb::DetailEnergy::None},
        {"distribution", turb::DetailEnergy::Distribution}};
    // Defined before the two settings, so that one of them given as well wins on its own kind of cache.
    legacy(addEnum<turb::DetailEnergy>(
               app, "--detail-energy", s.detailEnergy, energies, "Both detail energies (3D and 2D caches)")
               // addEnum's transform has already turned the name into the enum's number.
               ->each([&s](const std::string& v) { s.detailEnergy2D = static_cast<turb::DetailEnergy>(std::stoi(v)); }),
        "detailEnergy,detailEnergy2D");
    setting(addEnum<turb::DetailEnergy>(app, "--detailEnergy", s.detailEnergy, energies,
                "U_h's energy per smoke voxel on 3D caches: source (the source's high-frequency energy), pasted "
                "(the pasted patches' energy), none (as made), or distribution (|U_h| remapped rank for rank onto "
                "the source detail's magnitudes, then the source's energy)"),
        "detailEnergy");
    setting(addEnum<turb::DetailEnergy>(app, "--detailEnergy2D,--detail-energy-2d", s.detailEnergy2D, energies,
                "The same on 2D (one z layer) caches"),
        "detailEnergy2D");
    boolSetting(app, "--compensateTargetDivergence", s.compensateTargetDivergence,
        "The seam gamma term penalises div(up(u_t) + U_h) (false: div(U_h), the paper)", "compensateTargetDivergence");
    legacy(app->add_flag_function(
               "--no-target-divergence", [&s](int64_t) { s.compensateTargetDivergence = false; },
               "compensateTargetDivergence = false"),
        "compensateTargetDivergence", "false");
}

void addDetailSettings(CLI::App* app, turb::TransferSettings& s)
{
    num(app, "--coarse-tolerance,--coarseTolerance", s.coarseTolerance,
        "lf_err bound: U_h's coarse-cell means are reduced only down to this fraction of the target's (0 = exactly)",
        "coarseTolerance")
        ->check(finiteIn(0.0, 1.0));
    boolSetting(app, "--removeCoarseDetail", s.removeCoarseDetail, "Reduce U_h's coarse part (false lets lf_err grow)",
        "removeCoarseDetail");
    legacy(app->add_flag_function(
               "--keep-coarse-detail", [&s](int64_t) { s.removeCoarseDetail = false; }, "removeCoarseDetail = false"),
        "removeCoarseDetail", "false");
    num(app, "--coherence", s.coherence,
        "Take a neighbour's continued source patch within this fraction of the best E_h (0 = off, the paper)",
        "coherence")
        ->check(finiteIn(0.0));
    setting(app->add_flag("--whole-fresh-patches,--solveFreshPatchesWhole", s.solveFreshPatchesWhole,
                "Solve every voxel of patches without carried detail, not only the seam band"),
        "solveFreshPatchesWhole");
    boolSetting(app, "--resampleSource", s.resampleSource,
        "Resample a source at a non-integer ratio trilinearly to the nearest integer one (false: refuse it)",
        "resampleSource");
    legacy(app->add_flag_function(
               "--no-resample-source", [&s](int64_t) { s.resampleSource = false; }, "resampleSource = false"),
        "resampleSource", "false");
    boolSetting(app, "--followSourceFlow", s.followSourceFlow,
        "Patches follow the source's flow from frame to frame (false: re-paste where last frame found them)",
        "followSourceFlow");
    legacy(app->add_flag_function(
               "--no-follow-source", [&s](int64_t) { s.followSourceFlow = false; }, "followSourceFlow = false"),
        "followSourceFlow", "false");
    num(app, "--follow-tolerance,--followTolerance", s.followTolerance,
        "Keep a patch's continuation while its E_h is within (1 + this) of the best", "followTolerance")
        ->check(finiteIn(0.0));
    num(app, "--source-smoke,--sourceSmoke", s.sourceSmoke,
        "Fraction of a source patch's voxels that must hold smoke for it to be a candidate (0 = any, the paper)",
        "sourceSmoke")
        ->check(finiteIn(0.0, 1.0));
    addDetailStrengthSettings(app, s);
}

// Temporal coherence, alignment, the output density and the source's velocity extension.
void addTimeSettings(CLI::App* app, TransferArgs& a)
{
    turb::TransferSettings& s = a.settings;
    num(app, "--temporal-blend,--temporalBlend", s.temporalBlend,
        "Weight of last frame's detail advected through the target (0 = the paper)", "temporalBlend")
        ->check(finiteIn(0.0, 0.999));
    num(app, "--regenerate", s.regenerate,
        "Regenerate carried detail stretched below this fraction of the fresh patches' anisotropy (0 = off)",
        "regenerate")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--regenerateBlend", s.regenerateBlend, "Carried weight per frame in a regenerated patch (3D)",
        "regenerateBlend")
        ->check(finiteIn(0.0, 0.999));
    num(app, "--regenerateBlend2D", s.regenerateBlend2D, "The same on 2D caches", "regenerateBlend2D")
        ->check(finiteIn(0.0, 0.999));
    num(app, "--structureTolerance", s.structureTolerance,
        "Regenerate more patches while the detail's anisotropy is this fraction off the source's, and redo a frame "
        "that finishes 3x this off (3D; 0 = off)",
        "structureTolerance")
        ->check(finiteIn(0.0, 0.99));
    num(app, "--structureTolerance2D", s.structureTolerance2D, "The same on 2D caches", "structureTolerance2D")
        ->check(finiteIn(0.0, 0.99));
    legacy(app->add_option_function<float>(
                  "--regenerate-blend", [&s](float v) { s.regenerateBlend = s.regenerateBlend2D = v; },
                  "Both regeneration blends")
               ->check(finiteIn(0.0, 0.999)),
        "regenerateBlend,regenerateBlend2D");
    setting(addEnum<turb::FlowAlignment>(app, "--align,--alignment", s.alignment,
                {{"none", turb::FlowAlignment::None}, {"normalize", turb::FlowAlignment::Normalize},
                    {"rotate", turb::FlowAlignment::Rotate}, {"both", turb::FlowAlignment::Both}},
                "Match after aligning flows: none (the paper), normalize, rotate, both"),
        "alignment");
    num(app, "--lookback,--lookBackFrames", s.lookBackFrames, "m for --density lookback", "lookBackFrames")
        ->check(CLI::Range(1, 100));
    setting(
        addEnum<turb::AdvectSettings::Scheme>(app, "--density-scheme,--densityScheme", s.densityScheme,
            {{"bfecc", turb::AdvectSettings::Scheme::BFECC}, {"maccormack", turb::AdvectSettings::Scheme::MacCormack},
                {"semi-lagrangian", turb::AdvectSettings::Scheme::SemiLagrangian}},
            "Advection scheme of the output density"),
        "densityScheme");
    num(app, "--density-guide,--densityGuide.strength", s.densityGuide.strength,
        "Fraction of the way the output density's coarse means move onto the target's per frame (0 = off)",
        "densityGuide.strength")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--interface-compression,--interfaceCompression", s.interfaceCompression,
        "Sharpen the output density's edge: interface compression in voxels per frame (0 = off; docs/look.md: 0.5)",
        "interfaceCompression")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--level-set-diffusion,--levelSetDiffusion", s.levelSetDiffusion,
        "Even out hairs along the output density's surface: diffusion along its level sets per pass (0 = off; "
        "docs/look.md: 0.15)",
        "levelSetDiffusion")
        ->check(finiteIn(0.0, 1.0 / 6.0));
    num(app, "--level-set-diffusion-passes,--levelSetDiffusionPasses", s.levelSetDiffusionPasses,
        "Passes of the level-set diffusion per frame", "levelSetDiffusionPasses")
        ->check(CLI::Range(0, 20));
    num(app, "--extend-velocity,--sourceRead.extendVelocity", a.sourceRead.extendVelocity,
        "Continue the source's velocity this many voxels past its active region (Blender clips it to the smoke; 0 = "
        "off)",
        "sourceRead.extendVelocity")
        ->check(CLI::Range(0, 64));
}

// The second tier: every solver and experimental knob of turb::TransferSettings under its field's name, beside the
// spelling scripts used before (their measured effects are in docs/transfer.md).
void addTransferSettings(CLI::App* app, TransferArgs& a)
{
    addSearchSettings(app, a.settings);
    addSeamSettings(app, a.settings.seams);
    addDetailSettings(app, a.settings);
    addTimeSettings(app, a);
}

} // namespace

Command transferCommand()
{
    auto args = std::make_shared<TransferArgs>();
    Command c;
    c.name = "transfer";
    c.help = "Turbulence style transfer: add a high-res source's detail to a low-res target's motion (3D, or 2D: "
             "one-z-layer caches)";
    c.setup = [args](CLI::App* app) {
        TransferArgs& a = *args;
        app->add_option("--target", a.target, "Low-res target cache (velocity + density): pattern or one file")
            ->required();
        app->add_option("--source", a.source, "High-res source cache whose turbulence is transferred")->required();
        app->add_option("--out", a.out, "Output pattern, e.g. up/turb.####.vdb (directories are created)")->required();
        app->add_option("--frames", a.frames, "Target frames, e.g. 1001-1100x2 (default: all on disk)")
            ->check(frameListCheck());
        app->add_option("--source-frames", a.sourceFrames, "Restrict the source to these frames")
            ->check(frameListCheck());
        app->add_option("--source-offset", a.sourceOffset, "Source frame = target frame + offset");
        addEnum<turbio::SourceWrap>(app, "--source-wrap", a.wrap,
            {{"loop", turbio::SourceWrap::Loop}, {"pingpong", turbio::SourceWrap::PingPong},
                {"clamp", turbio::SourceWrap::Clamp}, {"error", turbio::SourceWrap::Error}},
            "When the source runs out");
        addEnum<turb::DensityMode>(app, "--density", a.settings.densityMode,
            {{"advect", turb::DensityMode::Advect}, {"lookback", turb::DensityMode::LookBack}},
            "Output density: advected, or looked back m frames (Ma et al.'s supplement)");
        app->add_option("--preroll", a.preroll,
               "Run up to N cache frames before the first requested one without writing them, so the detail and "
               "density are established as in a longer run")
            ->check(finiteIn(0.0));
        app->add_flag("--resume,--skip-existing", a.resume,
            "Skip frames already written (refused unless the last was made with these settings) and continue from the "
            "state saved in it; --skip-existing is the farm wrappers' name for it");
        app->add_flag("--json", "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.targetRead, "target");
        addReadOptions(app, a.sourceRead, "source");
        a.sourceCropMargin =
            app->get_option("--source-crop-margin")
                ->description("Source voxels kept around the source's smoke (default: 8 target voxels)");
        app->add_option("--tile-box", a.tileBox,
               "Hold only this box of the target, X0,Y0,Z0,X1,Y1,Z1 (inclusive voxel indices): a space tile and its "
               "halo, as farm plan --tiles writes it. The output covers its refined box")
            ->check(parsedBy([](const std::string& t) { turb::parseTileBox(t); }, "X0,Y0,Z0,X1,Y1,Z1"))
            ->group(kGroupInput);
        addWriteOptions(app, a.write);
        addFormatOptions(app, a.write);
        addVelocityWriteOptions(app, a.write);
        a.velocityMargin = app->get_option("--velocity-margin");
        addTransferSettings(app, a);
        for (const turb::run::KindTwin& k : kKindTwins)
            a.kindTwins.emplace_back(app->get_option(k.option3D), app->get_option(k.option2D));
    };
    c.run = [args] { return runTransfer(*args); };
    return c;
}

} // namespace vdbturb
