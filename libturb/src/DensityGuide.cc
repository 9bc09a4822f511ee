// Coarse-mean guiding of an up-res density (DensityGuide.h).
#include <turb/DensityGuide.h>

#include <turb/Error.h>
#include <turb/Measure.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>

#include <algorithm>
#include <cmath>

namespace turb {

DensityGuideStats guideDensity(ScalarField& fine, const ScalarField& coarse, int f, const DensityGuideSettings& s)
{
    if (f < 1) throw ValueError("density guide: ratio must be >= 1");
    if (fine.bbox() != refineDomain(coarse.bbox(), f))
        throw ValueError("density guide: the fine density must cover refineDomain(coarse box, f)");
    const int fz = domainFactors(coarse.bbox(), f).z(); // 1 for a 2D (one-layer) pair
    if (!(s.strength >= 0.0f && s.strength <= 1.0f)) throw ValueError("density guide: strength must lie in [0, 1]");
    if (s.passes < 1 || !(s.maxGain >= 1.0f) || !(s.threshold >= 0.0f))
        throw ValueError("density guide: passes >= 1, max gain >= 1 and threshold >= 0 required");
    DensityGuideStats st;
    for (float t : coarse.values()) st.guidedCells += t > s.threshold;
    st.errorBefore = st.errorAfter = coarseDensityError(fine, coarse, f, s.threshold);
    if (st.guidedCells == 0 || s.strength == 0.0f) return st;

    float peak = 0.0f;
    for (float t : coarse.values()) peak = std::max(peak, t);
    const auto guided = [&](size_t n) {
        const Coord c = fine.coordOf(n);
        return coarse(floorDiv(c.x(), f), floorDiv(c.y(), f), floorDiv(c.z(), fz)) > s.threshold;
    };
    // Mass inside and outside the guided cells, summed in a fixed order (deterministic at any thread count).
    const auto masses = [&] {
        std::pair<double, double> m{0.0, 0.0};
        for (size_t n = 0; n < fine.size(); ++n) (guided(n) ? m.first : m.second) += double(fine.data()[n]);
        return m;
    };
    const auto [insideBefore, outside] = masses();
    // A cell whose fine voxels hold less than this share of the wanted mean gets the rest added evenly: a gain
    // cannot create smoke where there is none.
    const float tiny = 1e-4f * peak;
    for (int pass = 0; pass < s.passes; ++pass) {
        const ScalarField down = boxDownsample(fine, f);
        ScalarField gain(coarse.bbox(), coarse.lattice(), 1.0f), add(coarse.bbox(), coarse.lattice(), 0.0f);
        for (size_t n = 0; n < coarse.size(); ++n) {
            const float t = coarse.data()[n];
            if (!(t > s.threshold)) continue;
            const float now = down.data()[n];
            const float want = now + s.strength * (t - now);
            if (now > tiny) {
                gain.data()[n] = std::clamp(want / now, 1.0f / s.maxGain, s.maxGain);
                add.data()[n] = std::max(0.0f, want - now * gain.data()[n]);
            } else {
                add.data()[n] = std::max(0.0f, want - now);
            }
        }
        // Smooth (trilinear) fields, so the correction shows no cell borders inside the target's smoke; voxels of
        // unguided cells are left exactly as they are (the trilinear fields would otherwise spill into them).
        const ScalarField G = upsample(gain, f), A = upsample(add, f);
        parallelFor(fine.size(), 1 << 14, [&](size_t b, size_t e) {
            for (size_t n = b; n < e; ++n) {
                if (!guided(n)) continue;
                const float v = fine.data()[n];
                const float w = v * G.data()[n] + A.data()[n];
                fine.data()[n] = w > v ? std::min(w, std::max(v, peak)) : std::max(0.0f, w);
            }
        });
    }
    // What the guide added inside comes first from smoke the detail carried outside the target's cells, so the
    // guide moves mass rather than making it: otherwise every frame's outflow across a sharp smoke border is
    // refilled inside while it also stays outside, and the mass grows without bound.
    const double added = masses().first - insideBefore;
    if (added > 0.0 && outside > 0.0) {
        const float keep = float(std::max(0.0, 1.0 - added / outside));
        parallelFor(fine.size(), 1 << 14, [&](size_t b, size_t e) {
            for (size_t n = b; n < e; ++n)
                if (!guided(n)) fine.data()[n] *= keep;
        });
    }
    st.errorAfter = coarseDensityError(fine, coarse, f, s.threshold);
    return st;
}

} // namespace turb
