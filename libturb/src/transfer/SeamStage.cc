// Section 3.3 as the transfer uses it: the seam problem of this frame's pasted patches, handed to smoothSeams.
#include "Stages.h"

namespace turb::detail {

SeamStats smoothPatchSeams(VectorField& detail, const SeamInputs& in, const FrameSetup& fs, Progress* progress)
{
    const TransferSettings& s = *fs.s;
    SeamProblem problem;
    problem.sourceHigh = &in.src.split.high;
    problem.sourceScale = in.src.detailScale;
    problem.layout = fs.layout;
    problem.active = in.active;
    problem.offset = in.offsets;
    if (s.compensateTargetDivergence) {
        problem.base = &in.t.Ut;
        // The energy factor scales U_h after the solve, and a compensation of the target's divergence scaled with
        // it would overshoot (by 2x at the bound of 3 on first frames).
        problem.baseScale = float(1.0 / in.scaleEstimate);
    }
    if (s.removeCoarseDetail) problem.boxFactor = fs.f;
    if (!in.blendWeight.empty()) {
        problem.temporal = &in.advectedDetail;
        problem.temporalWeights = in.blendWeight;
    }
    if (s.solveFreshPatchesWhole) {
        problem.wholePatches.assign(fs.layout.patchCount(), 0);
        for (size_t p = 0; p < fs.layout.patchCount(); ++p)
            problem.wholePatches[p] = in.active[p] && (in.blendWeight.empty() || in.blendWeight[p] == 0.0f);
    }
    SeamSettings settings = s.seams;
    if (settings.boundaryPatch <= 0) settings.boundaryPatch = fs.B % 2 == 0 ? fs.B : fs.B + 1;
    return smoothSeams(detail, problem, settings, progress);
}

} // namespace turb::detail
