// The temporal terms: U_h(i-1) advected through the target (eq. 2's U^_h), and, beyond the paper, the blend that
// carries it into the patches it reaches so the turbulence moves with the flow instead of being re-pasted, and
// regenerates it from the fresh patches where the flow has stretched it.
#include "Stages.h"

#include <turb/Advect.h>
#include <turb/Measure.h>
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

namespace {

/// Gradient energy of H along d and the mean across d (one direction across in 2D), summed over `box` less one
/// voxel at its faces (central differences): the parts of `measure`'s anisotropy, for one patch.
struct StructureSums
{
    double along = 0.0, across = 0.0;
    double ratio() const { return across > 0.0 ? along / across : 1.0; }
};

template<class Value>
StructureSums structureSumsOf(const Value& value, const CoordBBox& box, const Vec3d& d, const FrameSetup& fs)
{
    const int axes = fs.flat ? 2 : 3;
    CoordBBox in = box;
    for (int a = 0; a < axes; ++a) {
        in.min()[a] += 1;
        in.max()[a] -= 1;
    }
    double along = 0.0, all = 0.0;
    for (auto it = in.begin(); it; ++it) {
        Vec3d g[3] = {Vec3d(0.0), Vec3d(0.0), Vec3d(0.0)}; // g[a] = dH/dx_a
        for (int a = 0; a < axes; ++a) {
            Coord lo = *it, hi = *it;
            lo[a] -= 1;
            hi[a] += 1;
            g[a] = 0.5 * (value(hi) - value(lo));
        }
        along += (g[0] * d.x() + g[1] * d.y() + g[2] * d.z()).lengthSqr();
        all += g[0].lengthSqr() + g[1].lengthSqr() + g[2].lengthSqr();
    }
    return {along, (all - along) / double(axes - 1)};
}

StructureSums structureSums(const VectorField& H, const CoordBBox& box, const Vec3d& d, const FrameSetup& fs)
{
    return structureSumsOf([&](const Coord& c) { return Vec3d(H[c]); }, box, d, fs);
}

/// The gain that keeps a patch blended at carried weight w at the energy its two parts had, interpolated by w: a
/// mix of two nearly unrelated fields has less energy than either (0.5 of it at w = 0.5).
float keptEnergyGain(const VectorField& fresh, const VectorField& carried, const CoordBBox& box, float w)
{
    double ef = 0.0, ea = 0.0, em = 0.0;
    for (auto it = box.begin(); it; ++it) {
        ef += double(fresh[*it].lengthSqr());
        ea += double(carried[*it].lengthSqr());
        em += double((fresh[*it] * (1.0f - w) + carried[*it] * w).lengthSqr());
    }
    return em > 0.0 ? float(std::sqrt(((1.0 - w) * ef + w * ea) / em)) : 1.0f;
}

/// Structure sums along d of the patch blended at carried weight w, times the gain k.
StructureSums blendedSums(const VectorField& fresh, const VectorField& carried, const CoordBBox& box, float w, float k,
    const Vec3d& d, const FrameSetup& fs)
{
    return structureSumsOf(
        [&](const Coord& c) { return Vec3d((fresh[c] * (1.0f - w) + carried[c] * w) * k); }, box, d, fs);
}

/// The target's mean flow direction over a patch (up(u_t)); zero where it is at rest.
Vec3d patchFlow(const VectorField& Ut, const CoordBBox& pb)
{
    Vec3d d(0.0);
    for (auto it = pb.begin(); it; ++it) d += Vec3d(Ut[*it]);
    return d.lengthSqr() > 0.0 ? d.unit() : Vec3d(0.0);
}

// Patch p's box, clipped to the output's fine box.
CoordBBox clippedPatchBox(const FrameSetup& fs, size_t p)
{
    CoordBBox pb = fs.layout.patchBox(fs.layout.patchCoord(p));
    pb.intersect(fs.fineBox);
    return pb;
}

// What regeneration compares, per active patch: the local flow direction and the structure sums, along and across
// it, of the pasted (fresh) and the carried detail; `pooled` is the ratio of all pasted detail together.
struct StretchSums
{
    std::vector<StructureSums> fresh, carried;
    std::vector<Vec3d> flow;
    double pooled = 1.0;
};

StretchSums stretchSums(const VectorField& detail, const VectorField& advected, const TargetAtOutput& t,
    const std::vector<size_t>& act, const PatchTracks& tracks, const FrameSetup& fs)
{
    StretchSums out;
    out.fresh.resize(act.size());
    out.carried.resize(act.size());
    out.flow.assign(act.size(), Vec3d(0.0));
    parallelFor(act.size(), 16, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        for (size_t i = b; i < e; ++i) {
            if (!tracks.tracked[act[i]]) continue;
            const CoordBBox pb = clippedPatchBox(fs, act[i]);
            out.flow[i] = patchFlow(t.Ut, pb);
            if (out.flow[i].lengthSqr() == 0.0) continue;
            out.fresh[i] = structureSums(detail, pb, out.flow[i], fs);
            out.carried[i] = structureSums(advected, pb, out.flow[i], fs);
        }
    });
    StructureSums all; // summed in patch order: the same at any thread count
    for (const StructureSums& f : out.fresh) all.along += f.along, all.across += f.across;
    out.pooled = all.ratio();
    return out;
}

// The structure goal: the frame's blended detail (patch interiors, summed along and across goal.d) is brought within
// the tolerance of the source's anisotropy by regenerating more tracked patches: first at the regeneration weight,
// then, where that is not enough, at its square (two frames' worth). Each step takes the patches in the order of
// their pull on the frame ratio, and only those that move it closer. Regenerating falls back on the freshly pasted
// detail, the paper's own answer, so the goal is reached only as far as the fresh patches allow. Sequential over a
// sorted list: the same at any thread count. Returns the patches whose weight it lowered.
int regenerateTowardsGoal(const VectorField& fresh, const VectorField& carried, const std::vector<size_t>& act,
    const PatchTracks& tracks, const FrameSetup& fs, const StructureGoal& goal, float regenerated,
    std::vector<uint8_t>& regen, std::vector<float>& weight, double& estimate)
{
    const auto sumsAt = [&](size_t i, float w, bool keepEnergy) {
        const CoordBBox pb = clippedPatchBox(fs, act[i]);
        return blendedSums(
            fresh, carried, pb, w, keepEnergy ? keptEnergyGain(fresh, carried, pb, w) : 1.0f, goal.d, fs);
    };
    std::vector<StructureSums> now(act.size()), alt(act.size());
    parallelFor(act.size(), 16, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        for (size_t i = b; i < e; ++i) now[i] = sumsAt(i, weight[act[i]], regen[i]);
    });
    StructureSums frame; // in patch order
    for (const StructureSums& n : now) frame.along += n.along, frame.across += n.across;
    const double lo = goal.aim * (1.0 - goal.tolerance), hi = goal.aim * (1.0 + goal.tolerance);
    const bool raise = frame.ratio() < lo;
    const auto reached = [&] { return raise ? frame.ratio() >= lo : frame.ratio() <= hi; };
    std::vector<uint8_t> changed(act.size(), 0);
    for (const float w : {regenerated, regenerated * regenerated}) {
        if (reached()) break;
        std::vector<size_t> order;
        for (size_t i = 0; i < act.size(); ++i)
            if (tracks.tracked[act[i]] && weight[act[i]] > w) order.push_back(i);
        parallelFor(order.size(), 16, [&](size_t b, size_t e) {
            checkCancelled(fs.progress);
            for (size_t k = b; k < e; ++k) alt[order[k]] = sumsAt(order[k], w, true);
        });
        // A patch's pull on the frame ratio R = along / across: dR ~ (d along - R d across) / across.
        const double r0 = frame.ratio();
        std::vector<double> pull(act.size(), 0.0);
        for (size_t i : order) {
            const double dp = (alt[i].along - now[i].along) - r0 * (alt[i].across - now[i].across);
            pull[i] = raise ? dp : -dp;
        }
        std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return pull[a] != pull[b] ? pull[a] > pull[b] : a < b; });
        for (size_t i : order) {
            if (reached() || !(pull[i] > 0.0)) break;
            StructureSums next = frame;
            next.along += alt[i].along - now[i].along;
            next.across += alt[i].across - now[i].across;
            if (raise ? next.ratio() <= frame.ratio() : next.ratio() >= frame.ratio()) continue;
            frame = next;
            now[i] = alt[i];
            regen[i] = 1;
            changed[i] = 1;
            weight[act[i]] = w;
        }
    }
    estimate = frame.ratio();
    return int(std::count(changed.begin(), changed.end(), uint8_t(1)));
}

} // namespace

StructureGoal structureGoal(const TargetAtOutput& t, const SourceBands& bands, const FrameSetup& fs)
{
    const TransferSettings& s = *fs.s;
    StructureGoal g;
    const float tolerance = fs.flat ? s.structureTolerance2D : s.structureTolerance;
    if (!(tolerance > 0.0f) || !(s.regenerate > 0.0f) || bands.Ds.size() != bands.split.high.size()) return g;
    Vec3d mean(0.0);
    for (size_t n = 0; n < t.Ut.size(); ++n)
        if (t.Dt.data()[n] > s.densityThreshold) mean += Vec3d(t.Ut.data()[n]);
    if (!(mean.length() > 0.0)) return g;
    const std::optional<double> a = highBandAnisotropy(bands.split.high, smokeMask(bands.Ds, s.densityThreshold), mean);
    if (!a || !(*a > 0.0)) return g;
    g.d = mean.unit();
    g.source = g.aim = *a;
    g.tolerance = tolerance;
    return g;
}

std::optional<double> finishedAnisotropy(const VectorField& detail, const TargetAtOutput& t, const ScalarField& density,
    const StructureGoal& goal, const FrameSetup& fs)
{
    if (detail.bbox() != t.Ut.bbox() || density.bbox() != detail.bbox()) return std::nullopt;
    VectorField U = t.Ut;
    for (size_t n = 0; n < U.size(); ++n) U.data()[n] += detail.data()[n];
    return detailAnisotropy(U, smokeMask(density, fs.s->densityThreshold), fs.f, goal.d);
}

namespace {

// Per-patch carried weights: lambda where the patch carried detail last frame (or `regenerated` where the flow has
// stretched it: regen[i] set); where smoke has just arrived, only as much as the detail advected into it (its rms
// against the pasted detail's), so detail that flowed in keeps moving instead of being replaced.
void carriedWeights(const VectorField& detail, const VectorField& advected, const std::vector<size_t>& act,
    const PatchTracks& tracks, const StretchSums& sums, float lambda, float regenerated, const FrameSetup& fs,
    std::vector<float>& weight, std::vector<uint8_t>& regen)
{
    const TransferSettings& s = *fs.s;
    parallelFor(act.size(), 16, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        for (size_t i = b; i < e; ++i) {
            const size_t p = act[i];
            if (tracks.tracked[p]) {
                const bool stretched =
                    s.regenerate > 0.0f && sums.flow[i].lengthSqr() > 0.0 &&
                    sums.carried[i].ratio() < double(s.regenerate) * std::min(sums.pooled, sums.fresh[i].ratio());
                regen[i] = stretched;
                weight[p] = stretched ? regenerated : lambda;
                continue;
            }
            double ea = 0.0, ep = 0.0;
            const CoordBBox pb = clippedPatchBox(fs, p);
            for (auto it = pb.begin(); it; ++it) {
                ea += double(advected[*it].lengthSqr());
                ep += double(detail[*it].lengthSqr());
            }
            weight[p] = ep > 0.0 ? float(lambda * std::min(1.0, std::sqrt(ea / ep))) : lambda;
        }
    });
}

// detail = (1 - w) detail + w advected, per patch weight w. A regenerated patch mixes two nearly unrelated fields
// at comparable weights, and such a mix has less energy than either; the frame's one energy factor would then lift
// every other patch to make up for it (hf 1.27 against 1.25 without this on the analytic pair's second frame). The
// patch keeps the energy its two parts had, interpolated by the weight (keptEnergyGain).
void mixCarriedDetail(VectorField& detail, const VectorField& advected, const std::vector<size_t>& act,
    const std::vector<uint8_t>& regen, const std::vector<float>& weight, const FrameSetup& fs)
{
    const PatchLayout& L = fs.layout;
    std::vector<uint8_t> done(L.patchCount(), 0);
    parallelFor(act.size(), 16, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        for (size_t i = b; i < e; ++i) {
            if (!regen[i]) continue;
            const size_t p = act[i];
            const float w = weight[p];
            const CoordBBox pb = clippedPatchBox(fs, p);
            const float k = keptEnergyGain(detail, advected, pb, w);
            for (auto it = pb.begin(); it; ++it) detail[*it] = (detail[*it] * (1.0f - w) + advected[*it] * w) * k;
            done[p] = 1;
        }
    });
    parallelFor(detail.size(), 1 << 14, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        for (size_t n = b; n < e; ++n) {
            const size_t p = L.patchIndex(L.patchOf(detail.coordOf(n)));
            const float w = weight[p];
            if (w > 0.0f && !done[p]) detail.data()[n] = detail.data()[n] * (1.0f - w) + advected.data()[n] * w;
        }
    });
}

} // namespace

TemporalBlend blendTemporal(VectorField& detail, const TargetAtOutput& t, const VectorField& advected,
    const LocalSearchResult& local, const PatchTracks& tracks, const FrameSetup& fs, const StructureGoal& goal)
{
    const TransferSettings& s = *fs.s;
    TemporalBlend out;
    // The blend's memory is in frames: over a gap of k frames the carried detail keeps lambda^k.
    const float lambda = advected.empty() ? 0.0f : float(std::pow(double(s.temporalBlend), fs.frameGap));
    if (!(lambda > 0.0f)) return out;
    const std::vector<size_t>& act = local.activeList;

    // Regeneration: carried detail that the flow has stretched (its structure ratio along/across the local flow
    // below `regenerate` times the fresh detail's) is replaced faster. The fresh reference is the smaller of the
    // patch's own pasted detail and all pasted detail pooled: where the source's patches are themselves streaky
    // (a young source's jets), regenerating would only trade one streak for another.
    StretchSums sums;
    if (s.regenerate > 0.0f) {
        sums = stretchSums(detail, advected, t, act, tracks, fs);
    } else {
        sums.fresh.resize(act.size());
        sums.carried.resize(act.size());
        sums.flow.assign(act.size(), Vec3d(0.0));
    }
    const float blendOfRegenerated = fs.flat ? s.regenerateBlend2D : s.regenerateBlend;
    const float regenerated = float(std::pow(double(std::min(blendOfRegenerated, s.temporalBlend)), fs.frameGap));

    out.weight.assign(fs.layout.patchCount(), 0.0f);
    std::vector<uint8_t> regen(act.size(), 0);
    carriedWeights(detail, advected, act, tracks, sums, lambda, regenerated, fs, out.weight, regen);
    if (goal.tolerance > 0.0 && regenerated < lambda)
        out.regeneratedForStructure = regenerateTowardsGoal(
            detail, advected, act, tracks, fs, goal, regenerated, regen, out.weight, out.estimate);
    out.regenerated = int(std::count(regen.begin(), regen.end(), uint8_t(1)));
    mixCarriedDetail(detail, advected, act, regen, out.weight, fs);
    return out;
}

} // namespace turb::detail
