// The temporal terms: U_h(i-1) advected through the target (eq. 2's U^_h), and, beyond the paper, the blend that
// carries it into the patches it reaches so the turbulence moves with the flow instead of being re-pasted.
#include "Stages.h"

#include <turb/Advect.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb::detail {

VectorField advectPreviousDetail(const CarriedState& c, const FrameSetup& fs)
{
    const TransferSettings& s = *fs.s;
    if (!c.havePrevious || !(s.beta > 0.0f || s.temporalBlend > 0.0f)) return VectorField();
    AdvectSettings a = inPlane();
    // BFECC: with temporal blending this detail is most of the next frame's, and first-order advection would blur
    // it a little more every frame.
    a.scheme = s.temporalBlend > 0.0f ? AdvectSettings::Scheme::BFECC : AdvectSettings::Scheme::SemiLagrangian;
    return cropped(advect(c.prevDetail, c.prevTargetVelocity, fs.elapsed, a), fs.fineBox);
}

std::vector<float> blendTemporal(VectorField& detail, const VectorField& advected, const LocalSearchResult& local,
    const PatchTracks& tracks, const FrameSetup& fs)
{
    // The blend's memory is in frames: over a gap of k frames the carried detail keeps lambda^k.
    const float lambda = advected.empty() ? 0.0f : float(std::pow(double(fs.s->temporalBlend), fs.frameGap));
    if (!(lambda > 0.0f)) return {};
    const PatchLayout& L = fs.layout;
    // Per-patch weights: lambda where the patch carried detail last frame; where smoke has just arrived, only as
    // much as the detail advected into it (its rms against the pasted detail's), so detail that flowed in keeps
    // moving instead of being replaced.
    std::vector<float> weight(L.patchCount(), 0.0f);
    parallelFor(local.activeList.size(), 16, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            const size_t p = local.activeList[i];
            if (tracks.tracked[p]) {
                weight[p] = lambda;
                continue;
            }
            CoordBBox pb = L.patchBox(L.patchCoord(p));
            pb.intersect(fs.fineBox);
            double ea = 0.0, ep = 0.0;
            for (auto it = pb.begin(); it; ++it) {
                ea += double(advected[*it].lengthSqr());
                ep += double(detail[*it].lengthSqr());
            }
            weight[p] = ep > 0.0 ? float(lambda * std::min(1.0, std::sqrt(ea / ep))) : lambda;
        }
    });
    parallelFor(detail.size(), 1 << 14, [&](size_t b, size_t e) {
        for (size_t n = b; n < e; ++n) {
            const float w = weight[L.patchIndex(L.patchOf(detail.coordOf(n)))];
            if (w > 0.0f) detail.data()[n] = detail.data()[n] * (1.0f - w) + advected.data()[n] * w;
        }
    });
    return weight;
}

} // namespace turb::detail
