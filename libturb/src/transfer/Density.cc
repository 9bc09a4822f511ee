// The output density: advected at output resolution (or looked back), the target's emission, the coarse guide.
#include "Stages.h"

#include <turb/Advect.h>
#include <turb/DensityGuide.h>
#include <turb/DensityShaping.h>

#include <algorithm>

namespace turb::detail {

namespace {

// Adds the target's emission (fine, same box as `d`) where it emits, but never beyond the target's own density
// there (`targetFine`) unless `d` already holds more. Inflow emitters in Blender and Houdini set (or take the
// maximum of) density inside the emitter rather than adding without limit; the estimate max(0, d_t - advect(d_t))
// cannot tell the two apart, and summed onto a high-resolution density that keeps more smoke at the emitter than
// the coarse advection predicts, it piles up there frame after frame.
void addBoundedEmission(ScalarField& d, const ScalarField& emissionFine, const ScalarField& targetFine)
{
    for (size_t n = 0; n < d.size(); ++n) {
        const float e = emissionFine.data()[n];
        if (!(e > 0.0f)) continue;
        float& v = d.data()[n];
        v = std::min(v + e, std::max(v, targetFine.data()[n]));
    }
}

// Issue 42's fur: the advected density's edge sharpened across and evened out along its surface (3D only: the 2D
// pair's structure goal steers its detail, and these steps were measured on 3D pairs only).
void shapeEdge(ScalarField& d, const ScalarField& targetFine, const FrameSetup& fs)
{
    const TransferSettings& s = *fs.s;
    if (fs.flat) return;
    if (s.interfaceCompression > 0.0f) {
        float peak = 0.0f;
        for (float v : targetFine.values()) peak = std::max(peak, v);
        if (peak > 0.0f) compressInterface(d, s.interfaceCompression, peak);
    }
    if (s.levelSetDiffusion > 0.0f) diffuseAlongLevelSets(d, s.levelSetDiffusion, s.levelSetDiffusionPasses);
}

} // namespace

DensityStep advanceDensity(const Frame& target, const TargetAtOutput& t, const CarriedState& c, const FrameSetup& fs)
{
    const TransferSettings& s = *fs.s;
    const int f = fs.f;
    DensityStep out;
    ScalarField& d = out.density;
    AdvectSettings scheme = inPlane();
    scheme.scheme = s.densityScheme;
    if (s.densityMode == DensityMode::Advect) {
        if (!c.havePrevious) {
            d = t.Dt;
        } else {
            d = cropped(advect(c.prevDensity, c.prevVelocity, fs.elapsed, scheme), fs.fineBox);
            addBoundedEmission(d, upsample(t.emission, f), t.Dt);
            shapeEdge(d, t.Dt, fs);
        }
    } else if (c.history.empty()) {
        d = t.Dt;
    } else {
        // Ma et al.'s supplement, pseudocode 4: start from the target's density m frames back and advect it through
        // the output velocities since, injecting the target's emission on the way.
        d = cropped(upsample(c.history.front().targetDensity, f), fs.fineBox);
        for (size_t j = 0; j < c.history.size(); ++j) {
            d = advect(d, c.history[j].velocity, c.history[j].elapsed, scheme);
            const bool last = j + 1 == c.history.size();
            const ScalarField& em = last ? t.emission : c.history[j + 1].emission;
            addBoundedEmission(d, cropped(upsample(em, f), fs.fineBox),
                last ? t.Dt : cropped(upsample(c.history[j + 1].targetDensity, f), fs.fineBox));
        }
    }
    DensityGuideSettings g = s.densityGuide;
    g.threshold = s.densityThreshold;
    const DensityGuideStats gs = guideDensity(d, target.density, f, g);
    out.errorBefore = gs.errorBefore;
    out.errorAfter = gs.errorAfter;
    return out;
}

std::vector<uint8_t> activePatches(const FrameSetup& fs, const ScalarField& Dt, const ScalarField& density)
{
    const float th = fs.s->densityThreshold;
    std::vector<uint8_t> active(fs.layout.patchCount(), 0);
    for (size_t n = 0; n < Dt.size(); ++n)
        if (Dt.data()[n] > th || density.data()[n] > th)
            active[fs.layout.patchIndex(fs.layout.patchOf(Dt.coordOf(n)))] = 1;
    return active;
}

} // namespace turb::detail
