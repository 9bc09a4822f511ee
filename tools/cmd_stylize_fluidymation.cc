// vdbturb stylize --method fluidymation: its options (moving exemplars; the run is turb::run::runStylize).
#include "Console.h"
#include "StylizeCommon.h"

namespace vdbturb::stylize {

void addFluidymationOptions(CLI::App* app, StylizeArgs& a)
{
    turb::run::FluidymationJob& f = a.fluidy;
    turb::FluidySettings& s = f.settings;
    const std::string m = "[fluidymation] ";
    app->add_option(
        "--exemplar-mask", f.exemplarMask, m + "Binary masks of the exemplar frames (empty: the exemplar's alpha)");
    app->add_option("--target-mask", f.targetMask, m + "Binary target masks (#### sequence): the 2D target");
    const auto knob = [app, &m](const std::string& names, auto& v, const std::string& help, const std::string& key) {
        return setting(app->add_option(names, v, m + help), key);
    };
    knob("--exemplar-flow", f.exemplarFlow, "Exemplar flows, R,G in pixels per frame (empty: estimated from the masks)",
        "exemplar-flow");
    knob("--target-flow", f.targetFlow, "Target flows, R,G in pixels per frame (empty: estimated from the masks)",
        "target-flow");
    knob("--mask-threshold", f.maskThreshold, "Target alpha / rendered opacity at or above this is inside the mask",
        "mask-threshold")
        ->check(finiteIn(0.001, 1.0));
    setting(app->add_flag("--estimate-flow", f.estimateFlow,
                m + "Estimate the target's flow from its masks even when one is given"),
        "estimate-flow");
    knob("--out-rot", f.outRot, "Write T^rot per frame: float EXR/TIFF, R = theta (radians), G, B = cos, sin",
        "out-rot");
    knob("--debug-nnf", f.debugNnf,
        "Write the NNF per frame into DIR: nnf.####.exr (R = frame, G = x, B = y), nnf_theta, nnf_vis", "debug-nnf");
    // turb::FluidySettings under its field names (Table 1's values are the defaults; docs/fluidymation.md).
    knob("--n,--fluidy.patchSize", s.patchSize, "Patch size n", "fluidy.patchSize")->check(CLI::Range(3, 15));
    knob("--b,--fluidy.boundaryBlur", s.boundaryBlur, "Boundary blur radius b in pixels (sigma = b/3)",
        "fluidy.boundaryBlur")
        ->check(finiteIn(0.1, 1000.0));
    knob("--r,--fluidy.cuboidFrames", s.cuboidFrames,
        "Occurrence cuboid half-length r in frames (the exemplar needs 2r+1)", "fluidy.cuboidFrames")
        ->check(CLI::Range(0, 50));
    knob("--w-bound,--fluidy.wBound", s.wBound, "w^bound (0 = ablation)", "fluidy.wBound")->check(finiteIn(0.0));
    knob("--w-ext,--fluidy.wExt", s.wExt, "w^ext", "fluidy.wExt")->check(finiteIn(0.0));
    knob("--w-dir,--fluidy.wDir", s.wDir, "w^dir", "fluidy.wDir")->check(finiteIn(0.0));
    knob("--w-temp,--fluidy.wTemp", s.wTemp, "w^temp", "fluidy.wTemp")->check(finiteIn(0.0));
    knob("--w-uni,--fluidy.wUni", s.wUni, "w^uni", "fluidy.wUni")->check(finiteIn(0.0));
    knob("--m-lower,--fluidy.mLower", s.mLower, "m_l as a fraction of the target's larger side", "fluidy.mLower")
        ->check(finiteIn(0.0, 10.0));
    knob("--m-upper,--fluidy.mUpper", s.mUpper, "m_u as a fraction of the target's larger side", "fluidy.mUpper")
        ->check(finiteIn(0.0, 10.0));
    knob("--dir-clamp,--fluidy.dirClamp", s.dirClamp, "Clamp of |tan| in D^dir", "fluidy.dirClamp")
        ->check(finitePositive());
    knob("--extent-scale,--fluidy.extentScale", s.extentScale,
        "The exemplar's D^ext unit in pixels (0 = its 95th percentile)", "fluidy.extentScale")
        ->check(finiteIn(0.0));
    knob("--target-extent-scale,--fluidy.targetExtentScale", s.targetExtentScale,
        "The target's D^ext unit in pixels (0 = its own 95th percentile)", "fluidy.targetExtentScale")
        ->check(finiteIn(0.0));
    knob("--fluidy-levels,--fluidy.levels", s.levels, "Pyramid levels (0 = floor(log2(d_min / n)))", "fluidy.levels")
        ->check(CLI::Range(0, 8));
    knob(
        "--fluidy-iterations,--fluidy.iterations", s.iterations, "EM iterations on coarser levels", "fluidy.iterations")
        ->check(CLI::Range(1, 50));
    knob("--fluidy-fine-iterations,--fluidy.fineIterations", s.fineIterations, "EM iterations on the finest level",
        "fluidy.fineIterations")
        ->check(CLI::Range(1, 50));
    knob("--fluidy-sweeps,--fluidy.sweeps", s.sweeps, "PatchMatch sweeps per E-step on coarser levels", "fluidy.sweeps")
        ->check(CLI::Range(1, 32));
    knob("--fluidy-fine-sweeps,--fluidy.fineSweeps", s.fineSweeps, "PatchMatch sweeps per E-step on the finest level",
        "fluidy.fineSweeps")
        ->check(CLI::Range(1, 32));
    boolSetting(app, "--fluidy.reusePrevious", s.reusePrevious,
        m + "Start each frame from the previous one's NNF (false: random)", "fluidy.reusePrevious");
    legacy(app->add_flag_function(
               "--no-reuse", [&s](int64_t) { s.reusePrevious = false; }, "fluidy.reusePrevious = false"),
        "fluidy.reusePrevious", "false");
}

} // namespace vdbturb::stylize
