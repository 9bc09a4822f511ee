// U_h's coarse part: the smooth field with U_h's coarse-cell means. Left in, it changes the target's coarse motion
// (lf_err); taken out exactly, it costs temporal coherence, since advected detail moves some energy into the means.
// It is reduced to a tolerance, once before the seam solve and once after the energy factor.
#include "Stages.h"

#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb::detail {

namespace {

// The fraction of a coarse part measuring `lf` (lf_err's ratio) that stays within `tolerance`; an infinite lf
// (a target at rest under the detail) keeps none.
double keptFraction(double lf, double tolerance)
{
    if (!std::isfinite(lf)) return 0.0;
    return lf > tolerance ? tolerance / lf : 1.0;
}

// |U_h| voxel by voxel onto the source's magnitudes, rank for rank over the smoke: a monotone map, so the order
// of the detail's magnitudes (where it is strong) is kept and only their distribution changes. Directions are kept.
void matchMagnitudes(VectorField& detail, const SmokeEnergy& smoke, const std::vector<float>& source)
{
    std::vector<float> m;
    m.reserve(smoke.voxels);
    for (size_t n = 0; n < detail.size(); ++n)
        if (smoke.density.data()[n] > smoke.threshold) m.push_back(detail.data()[n].length());
    const std::vector<float> out = rankTable(std::move(m), kMagnitudeRanks);
    if (out.empty() || source.size() != out.size()) return;
    const int K = int(out.size()) - 1;
    parallelFor(detail.size(), 1 << 14, [&](size_t b, size_t e) {
        for (size_t n = b; n < e; ++n) {
            Vec3f& v = detail.data()[n];
            const float len = v.length();
            if (!(len > 0.0f)) continue;
            float target;
            if (len >= out[size_t(K)]) {
                target = source[size_t(K)]; // beyond the smoke's largest (air): the source's largest
            } else {
                const size_t hi = size_t(std::upper_bound(out.begin(), out.end(), len) - out.begin());
                if (hi == 0) { // below the smoke's smallest (air): scaled as the smallest is
                    target = source[0] * (out[0] > 0.0f ? len / out[0] : 1.0f);
                } else {
                    const size_t lo = hi - 1;
                    const float w = out[hi] > out[lo] ? (len - out[lo]) / (out[hi] - out[lo]) : 0.0f;
                    target = source[lo] + w * (source[hi] - source[lo]);
                }
            }
            v *= target / len;
        }
    });
}

} // namespace

std::vector<float> rankTable(std::vector<float> values, int ranks)
{
    if (values.empty() || ranks < 1) return {};
    std::sort(values.begin(), values.end());
    std::vector<float> table(size_t(ranks) + 1);
    const double last = double(values.size() - 1);
    for (int k = 0; k <= ranks; ++k) {
        const double r = last * k / ranks;
        const size_t i = size_t(r);
        const double w = r - double(i);
        table[size_t(k)] = i + 1 < values.size() ? float(values[i] * (1.0 - w) + values[i + 1] * w) : values[i];
    }
    return table;
}

double reduceCoarsePartBeforeSeams(VectorField& detail, const TargetAtOutput& t, const Frame& target,
    const SmokeEnergy& smoke, double referenceEnergy, const FrameSetup& fs)
{
    const TransferSettings& s = *fs.s;
    // Taking out a trilinear field adds divergence, which the solve's gamma term then removes while its box rows
    // hold the means. Both this tolerance and the solve's target-divergence term need the energy factor this frame
    // will get: estimated here from the detail without its coarse part.
    VectorField coarse;
    if (s.removeCoarseDetail) coarse = upsample(coarsePart(detail, fs.f), fs.f);
    double estimate = 1.0;
    if (fs.detailEnergy() != DetailEnergy::None && referenceEnergy > 0.0)
        estimate = energyFactor(referenceEnergy, smoke(detail, coarse.empty() ? nullptr : &coarse));
    if (!coarse.empty()) {
        const double lf = estimate * coarseRatio(coarse, t.Ut, target.density, s.densityThreshold, fs.f);
        const float remove = float(1.0 - keptFraction(lf, s.coarseTolerance));
        for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] -= coarse.data()[n] * remove;
    }
    return estimate;
}

void calibrateDetail(VectorField& detail, const TargetAtOutput& t, const Frame& target, const SmokeEnergy& smoke,
    double referenceEnergy, const std::vector<float>& sourceMagnitudes, const FrameSetup& fs, TransferStats& st)
{
    const TransferSettings& s = *fs.s;
    const int f = fs.f;
    // A voxel-by-voxel gain puts box means back into the detail, so the magnitudes are matched before the coarse
    // part is measured and bounded.
    if (!sourceMagnitudes.empty()) matchMagnitudes(detail, smoke, sourceMagnitudes);
    VectorField coarse;
    if (s.removeCoarseDetail) {
        coarse = upsample(coarsePart(detail, f), f);
        for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] -= coarse.data()[n];
    }
    if (fs.detailEnergy() != DetailEnergy::None && referenceEnergy > 0.0) {
        st.energyScale = energyFactor(referenceEnergy, smoke(detail));
        for (auto& v : detail.values()) v *= float(st.energyScale);
    }
    if (!coarse.empty()) {
        // Put back as much of the coarse part as the tolerance allows, measured as lf_err measures it: the coarse
        // part's box means against the up-sampled target's, over the target's smoke cells. A target at rest there
        // leaves no relative budget: the coarse part goes entirely.
        const double lf = st.energyScale * coarseRatio(coarse, t.Ut, target.density, s.densityThreshold, f);
        st.coarseKept = keptFraction(lf, s.coarseTolerance);
        st.lfErr = st.coarseKept > 0.0 ? lf * st.coarseKept : 0.0;
        const float k = float(st.coarseKept * st.energyScale);
        if (k > 0.0f)
            for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] += coarse.data()[n] * k;
    } else {
        st.coarseKept = 1.0;
        const double lf = coarseRatio(detail, t.Ut, target.density, s.densityThreshold, f);
        st.lfErr = std::isfinite(lf) ? lf : 0.0;
    }
}

} // namespace turb::detail
