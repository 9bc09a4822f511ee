// Coarse-mean guiding of an up-res density (DensityGuide.h).
#include <turb/DensityGuide.h>

#include <turb/Error.h>
#include <turb/Measure.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace turb {

namespace {

// Every weight below is a function of the trilinear up(coarse), so the correction varies smoothly across the
// target's cell faces. An earlier guide switched per coarse cell (guided or not) and erased smoke outside the
// guided cells evenly: the output's silhouette became a staircase of whole cells (density_imprint 1.1-3.3 on
// the demo, pictures in docs/transfer.md). Per fine voxel: 0 below the threshold, rising over `ramp` to 1.
std::vector<float> guideWeights(const ScalarField& upT, float threshold, float ramp)
{
    std::vector<float> weight(upT.size());
    for (size_t n = 0; n < upT.size(); ++n) {
        const float over = upT.data()[n] - threshold;
        weight[n] = over <= 0.0f ? 0.0f : ramp > 0.0f ? std::min(1.0f, over / ramp) : 1.0f;
    }
    return weight;
}

double totalMass(const ScalarField& fine)
{
    double m = 0.0; // a fixed order: deterministic at any thread count
    for (float v : fine.values()) m += double(v);
    return m;
}

// One guiding pass: each guided cell's fine mean is pulled `strength` of the way to the target's by a bounded gain,
// and (allowAdd) what the gain cannot reach is added evenly; both spread trilinearly and applied by weight. A cell
// whose fine voxels hold less than `tiny` of the wanted mean gets it all added: a gain cannot create smoke where
// there is none.
void guidePass(ScalarField& fine, const ScalarField& coarse, int f, const DensityGuideSettings& s,
    const std::vector<float>& weight, float peak, float tiny, bool allowAdd)
{
    const ScalarField down = boxDownsample(fine, f);
    ScalarField gain(coarse.bbox(), coarse.lattice(), 1.0f), add(coarse.bbox(), coarse.lattice(), 0.0f);
    for (size_t n = 0; n < coarse.size(); ++n) {
        const float t = coarse.data()[n];
        if (!(t > s.threshold)) continue;
        const float now = down.data()[n];
        const float want = now + s.strength * (t - now);
        if (now > tiny) {
            gain.data()[n] = std::clamp(want / now, 1.0f / s.maxGain, s.maxGain);
            if (allowAdd) add.data()[n] = std::max(0.0f, want - now * gain.data()[n]);
        } else if (allowAdd) {
            add.data()[n] = std::max(0.0f, want - now);
        }
    }
    const ScalarField G = upsample(gain, f), A = upsample(add, f);
    parallelFor(fine.size(), 1 << 14, [&](size_t b, size_t e) {
        for (size_t n = b; n < e; ++n) {
            const float w = weight[n];
            if (w == 0.0f) continue;
            const float v = fine.data()[n];
            const float g = v * G.data()[n] + A.data()[n];
            fine.data()[n] = std::clamp(v + w * (g - v), 0.0f, peak);
        }
    });
}

// The guide moves mass rather than making it: what the passes added, or what exceeds the target's own mass if
// that is more (emission estimates and the detail's flux add smoke too), is taken back. Otherwise every frame's
// outflow across the smoke's border is refilled inside while it also stays outside, and the mass grows without
// bound. First layer: a voxel gives in proportion to its value times 1 - weight (all of it where the target has
// no smoke, smoothly less toward its smoke, so no cell face shows). Second layer, only for mass still beyond
// the target's (a target with a sharp edge, whose border cells the passes overfill through the gain's spill):
// in proportion to 1 - the trilinear up(indicator of the guided cells), which reaches into the border cells.
void takeBackAddedMass(ScalarField& fine, const ScalarField& coarse, int f, float threshold,
    const std::vector<float>& weight, double massBefore)
{
    double targetMass = 0.0;
    for (float t : coarse.values()) targetMass += double(t);
    targetMass *= double(fine.size()) / double(coarse.size()); // f^3 fine voxels a cell (f^2 in 2D)
    const double total = totalMass(fine);
    double owed = std::max(total - massBefore, total - targetMass);
    const double excess = std::max(0.0, total - targetMass); // only mass beyond the target's reaches into its cells
    ScalarField inside(coarse.bbox(), coarse.lattice(), 0.0f);
    for (size_t n = 0; n < coarse.size(); ++n) inside.data()[n] = coarse.data()[n] > threshold ? 1.0f : 0.0f;
    const ScalarField upInside = upsample(inside, f);
    for (int layer = 0; layer < 2 && owed > 0.0; ++layer) {
        const auto share = [&](size_t n) { return layer == 0 ? 1.0f - weight[n] : 1.0f - upInside.data()[n]; };
        double takeable = 0.0;
        for (size_t n = 0; n < fine.size(); ++n) takeable += double(share(n)) * double(fine.data()[n]);
        if (!(takeable > 0.0)) continue;
        const float r = float(std::min(1.0, owed / takeable));
        parallelFor(fine.size(), 1 << 14, [&](size_t b, size_t e) {
            for (size_t n = b; n < e; ++n) fine.data()[n] *= 1.0f - r * share(n);
        });
        owed -= double(r) * takeable;
        if (layer == 0) owed = std::min(owed, std::max(0.0, excess - double(r) * takeable));
    }
}

} // namespace

DensityGuideStats guideDensity(ScalarField& fine, const ScalarField& coarse, int f, const DensityGuideSettings& s)
{
    if (f < 1) throw ValueError("density guide: ratio must be >= 1");
    if (fine.bbox() != refineDomain(coarse.bbox(), f))
        throw ValueError("density guide: the fine density must cover refineDomain(coarse box, f)");
    if (!(s.strength >= 0.0f && s.strength <= 1.0f)) throw ValueError("density guide: strength must lie in [0, 1]");
    if (s.passes < 1 || !(s.maxGain >= 1.0f) || !(s.threshold >= 0.0f) || !(s.rampFactor >= 0.0f))
        throw ValueError("density guide: passes >= 1, max gain >= 1, threshold >= 0 and ramp >= 0 required");
    DensityGuideStats st;
    for (float t : coarse.values()) st.guidedCells += t > s.threshold;
    st.errorBefore = st.errorAfter = coarseDensityError(fine, coarse, f, s.threshold);
    if (st.guidedCells == 0 || s.strength == 0.0f) return st;

    float peak = 0.0f;
    for (float t : coarse.values()) peak = std::max(peak, t);
    const std::vector<float> weight = guideWeights(upsample(coarse, f), s.threshold, s.rampFactor * s.threshold);
    // Denser than the target's densest cell is taken as a pile-up, not detail: an inflow emitter sets the same
    // density at every resolution (Blender plume2 at frame 1: 0.999 at 128^3, 0.965 at 32^3).
    for (float& v : fine.values()) v = std::min(v, peak);
    const double massBefore = totalMass(fine);
    const float tiny = 1e-4f * peak;
    for (int p = 0; p < s.passes; ++p) guidePass(fine, coarse, f, s, weight, peak, tiny, true);
    takeBackAddedMass(fine, coarse, f, s.threshold, weight, massBefore);
    st.errorAfter = coarseDensityError(fine, coarse, f, s.threshold);
    return st;
}

} // namespace turb
