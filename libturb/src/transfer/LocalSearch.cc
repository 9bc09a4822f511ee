// Eq. 2: the local search for B^3 fine patches (B^2 in 2D) inside each patch's global region: PCA-reduced candidates on
// the stride lattice, the best few re-scored with the full-resolution E_h (with the beta term on U^_h).
#include "Stages.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <turb/Operators.h>

#include <algorithm>
#include <cmath>

namespace turb::detail {

namespace {

// E_h over a patch (eq. 2), the source read through `at(field, k)` for the patch's k-th voxel offset: by index at
// an integer corner, trilinearly at a sub-voxel one. One body, so the two cannot drift apart.
template<typename SourceAt>
double patchEnergy(const PatchEnergy& pe, const Coord& tCorner, bool temporal, const SourceAt& at)
{
    const FrameSetup& fs = pe.fs;
    const TransferSettings& s = *fs.s;
    const Coord& P = fs.patch;
    double e = 0.0;
    for (int x = 0; x < P.x(); ++x)
        for (int y = 0; y < P.y(); ++y)
            for (int z = 0; z < P.z(); ++z) {
                const Coord k(x, y, z), tv = tCorner + k;
                if (!fs.fineBox.isInside(tv)) continue;
                const Vec3f du = pe.t.Ut[tv] * pe.src.kt - at(pe.src.split.low, k) * pe.src.ks;
                const float dm = float(pe.t.Dt[tv] > s.densityThreshold) - float(at(pe.src.Ds, k) > s.densityThreshold);
                e += double(du.lengthSqr()) + double(s.alpha) * double(dm * dm);
                if (temporal) {
                    const Vec3f dh = pe.advectedDetail[tv] * pe.src.kt - at(pe.src.split.high, k) * pe.src.ks;
                    e += double(s.beta) * double(dh.lengthSqr());
                }
            }
    return e;
}

} // namespace

double PatchEnergy::operator()(const Coord& tCorner, const Coord& sCorner, bool temporal) const
{
    return patchEnergy(*this, tCorner, temporal, [&](const auto& field, const Coord& k) { return field[sCorner + k]; });
}

double PatchEnergy::at(const Coord& tCorner, const Vec3d& sCorner, bool temporal) const
{
    const Coord base(int(std::floor(sCorner.x())), int(std::floor(sCorner.y())), int(std::floor(sCorner.z())));
    if (base.asVec3d() == sCorner) return (*this)(tCorner, base, temporal);
    return patchEnergy(*this, tCorner, temporal,
        [&](const auto& field, const Coord& k) { return sampleTrilinear(field, sCorner + k.asVec3d()); });
}

double LocalSearchResult::meanEnergy() const
{
    double sum = 0.0;
    for (size_t p : activeList) sum += energy[p];
    return activeList.empty() ? 0.0 : sum / double(activeList.size());
}

namespace {

// Voxels of the patch (extent P) at `corner` (rounded) whose density exceeds the threshold; outside the box counts
// none.
int smokeVoxels(const ScalarField& D, const Vec3d& corner, const Coord& P, float threshold)
{
    const Coord c(int(std::lround(corner.x())), int(std::lround(corner.y())), int(std::lround(corner.z())));
    int n = 0;
    for (int x = 0; x < P.x(); ++x)
        for (int y = 0; y < P.y(); ++y)
            for (int z = 0; z < P.z(); ++z) n += D.valueOr(c.x() + x, c.y() + y, c.z() + z, 0.0f) > threshold;
    return n;
}

// The PCA distances of the candidates within `radius` of a patch's region centre on the stride lattice (widened
// when the region holds no smoke-bearing candidate, e.g. at the edge of the source's smoke; the whole lattice as a
// last resort for tiny sources).
void regionCandidates(const LocalCandidates& cands, const Coord& centre, const Coord& half, int radius, int grow,
    const std::vector<float>& red, std::vector<std::pair<float, Coord>>& best)
{
    const size_t rk = cands.pca().outputDim();
    const CoordBBox& corners = cands.cornerBox();
    const int stride = cands.stride();
    const auto consider = [&](const Coord& c) {
        if (const float* r = cands.reduced(c)) {
            float d2 = 0.0f;
            for (size_t k = 0; k < rk; ++k) d2 += (r[k] - red[k]) * (r[k] - red[k]);
            best.emplace_back(d2, c);
        }
    };
    for (int g = 0; g < 4 && best.empty(); ++g) {
        const int rad = radius + g * grow;
        // A 2D patch's region is its one layer: no radius along z.
        const Coord r(rad, rad, half.z() > 0 ? rad : 0);
        const Coord lo = centre - half - r, hi = centre - half + r;
        Coord c0, c1;
        for (int a = 0; a < 3; ++a) {
            const int base = corners.min()[a];
            const int l = std::max(lo[a], base), h = std::min(hi[a], corners.max()[a]);
            c0[a] = base + ((l - base + stride - 1) / stride) * stride;
            c1[a] = h;
        }
        for (int x = c0.x(); x <= c1.x(); x += stride)
            for (int y = c0.y(); y <= c1.y(); y += stride)
                for (int z = c0.z(); z <= c1.z(); z += stride) consider(Coord(x, y, z));
    }
    if (!best.empty()) return;
    for (int x = corners.min().x(); x <= corners.max().x(); x += stride)
        for (int y = corners.min().y(); y <= corners.max().y(); y += stride)
            for (int z = corners.min().z(); z <= corners.max().z(); z += stride) consider(Coord(x, y, z));
}

} // namespace

LocalSearchResult localSearch(const PatchEnergy& energy, const std::vector<uint8_t>& active,
    const GlobalSearchResult& global, const PatchTracks& tracks, const MatchWeights& w)
{
    const FrameSetup& fs = energy.fs;
    const TransferSettings& s = *fs.s;
    const int B = fs.B;
    LocalCandidates cands;
    cands.build(
        energy.src.split.low, energy.src.Ds, fs.patch, s.localStride, energy.src.ks, w, s.pcaComponents, s.sourceSmoke);
    if (cands.count() == 0) throw ValueError("the source has no local patch holding smoke");
    const int radius = std::max(0, (fs.globalPatch * fs.f - B) / 2);
    const size_t rk = cands.pca().outputDim(), ldim = localDescriptorSize(fs.patch);
    LocalSearchResult out;
    out.corners = cands.cornerBox();
    out.chosen.assign(fs.layout.patchCount(), Coord(0));
    out.chosenExact.assign(fs.layout.patchCount(), Vec3d(0.0));
    std::vector<uint8_t> followed(fs.layout.patchCount(), 0);
    out.energy.assign(fs.layout.patchCount(), 0.0);
    for (size_t p = 0; p < active.size(); ++p)
        if (active[p]) out.activeList.push_back(p);
    const bool haveAdvected = !energy.advectedDetail.empty();
    // Every re-scored candidate of every patch, best first, for the repeat rule below.
    const bool noRepeats = s.repeatRadius > 0;
    std::vector<std::vector<std::pair<double, Coord>>> ranked(noRepeats ? fs.layout.patchCount() : 0);
    parallelFor(out.activeList.size(), 8, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        std::vector<float> desc(ldim), red(rk);
        std::vector<std::pair<float, Coord>> best;
        for (size_t i = b; i < e; ++i) {
            const size_t p = out.activeList[i];
            const Coord tCorner = fs.layout.patchBox(fs.layout.patchCoord(p)).min();
            localDescriptor(energy.t.Ut, energy.t.Dt, tCorner, fs.patch, energy.src.kt, w, desc.data());
            cands.pca().project(desc.data(), red.data());
            best.clear();
            regionCandidates(cands, global.regionCentre[p], fs.half, radius, fs.globalPatch * fs.f, red, best);
            const size_t m = std::min(best.size(), size_t(s.refineCandidates));
            std::partial_sort(best.begin(), best.begin() + long(m), best.end(), [](const auto& a, const auto& c) {
                if (a.first != c.first) return a.first < c.first;
                return a.second < c.second;
            });
            best.resize(m);
            // Keep last frame's match in the running: the cheapest way to stay coherent.
            if (tracks.tracked[p] && out.corners.isInside(tracks.match[p])) best.emplace_back(0.0f, tracks.match[p]);
            const bool temporal = haveAdvected && tracks.tracked[p];
            double bestE = -1.0;
            Coord bestC = best.empty() ? out.corners.min() : best.front().second;
            for (const auto& cand : best) {
                const double en = energy(tCorner, cand.second, temporal);
                if (noRepeats) ranked[p].emplace_back(en, cand.second);
                if (bestE < 0.0 || en < bestE || (en == bestE && cand.second < bestC)) {
                    bestE = en;
                    bestC = cand.second;
                }
            }
            if (noRepeats) std::sort(ranked[p].begin(), ranked[p].end());
            out.chosen[p] = bestC;
            out.chosenExact[p] = bestC.asVec3d();
            out.energy[p] = std::max(0.0, bestE);
            // The continuation in the source's flow wins while it matches nearly as well as the best found.
            if (!tracks.following.empty() && tracks.following[p] &&
                smokeVoxels(energy.src.Ds, tracks.follow[p], fs.patch, s.densityThreshold) >= cands.minSmokeVoxels()) {
                const double ef = energy.at(tCorner, tracks.follow[p], temporal);
                if (ef <= (1.0 + double(s.followTolerance)) * out.energy[p]) {
                    const Vec3d& c = tracks.follow[p];
                    out.chosenExact[p] = c;
                    out.chosen[p] = Coord(int(std::lround(c.x())), int(std::lround(c.y())), int(std::lround(c.z())));
                    out.energy[p] = ef;
                    followed[p] = 1;
                }
            }
        }
    });
    out.followed = int(std::count(followed.begin(), followed.end(), uint8_t(1)));
    if (noRepeats) {
        // Patches that carried detail keep their choice (and are the others' constraints): their match continues
        // last frame's, and re-choosing it for variety cost the plume2 pair its anisotropy (aniso_ratio up to 1.49).
        std::vector<uint8_t> fixed = followed;
        for (size_t p = 0; p < fixed.size(); ++p) fixed[p] |= tracks.tracked[p];
        out.repeatsAvoided = avoidRepeats(out, ranked, fixed, fs);
    }
    return out;
}

int avoidRepeats(LocalSearchResult& out, const std::vector<std::vector<std::pair<double, Coord>>>& ranked,
    const std::vector<uint8_t>& fixed, const FrameSetup& fs)
{
    // Beyond the paper: where the source offers few patches like the target's (a shot's first frames, an emitter
    // the source's floor matches best), the search gives many patches the same source patch, and the repeats show
    // as a regular lattice of equal blobs (issue 42: 336 patches from 3 source patches at frame 1 of the paper's
    // pair) or a band of one detail along an emitter. So patches within repeatRadius of each other do not take
    // source patches overlapping by more than half along every axis; a copy continued across a seam (source
    // corners as far apart as the patches') is no repeat. Patches are decided in index order, the `fixed` ones (those
    // following the source's flow or carrying detail) first and unchanged, so the choice is the same at any thread
    // count; a patch whose every candidate within repeatTolerance of its best repeats a neighbour's keeps its best.
    const TransferSettings& s = *fs.s;
    const PatchLayout& L = fs.layout;
    const int R = s.repeatRadius;
    const Coord half(std::max(1, fs.patch.x() / 2), std::max(1, fs.patch.y() / 2), std::max(1, fs.patch.z() / 2));
    std::vector<uint8_t> decided(L.patchCount(), 0);
    for (size_t p : out.activeList) decided[p] = fixed[p];
    const auto repeats = [&](size_t p, const Coord& c) {
        const Coord P = L.patchCoord(p);
        for (int dx = -R; dx <= R; ++dx)
            for (int dy = -R; dy <= R; ++dy)
                for (int dz = L.flat ? 0 : -R; dz <= (L.flat ? 0 : R); ++dz) {
                    const Coord Q = P + Coord(dx, dy, dz);
                    if ((dx == 0 && dy == 0 && dz == 0) || Q.x() < 0 || Q.y() < 0 || Q.z() < 0 ||
                        Q.x() >= L.count.x() || Q.y() >= L.count.y() || Q.z() >= L.count.z())
                        continue;
                    const size_t q = L.patchIndex(Q);
                    if (!decided[q]) continue;
                    const Coord d = c - out.chosen[q];
                    if (std::abs(d.x()) < half.x() && std::abs(d.y()) < half.y() && std::abs(d.z()) < half.z())
                        return true;
                }
        return false;
    };
    int changed = 0;
    for (size_t p : out.activeList) {
        if (fixed[p]) continue;
        const auto& r = ranked[p];
        if (!r.empty() && repeats(p, out.chosen[p])) {
            const double limit = (1.0 + double(s.repeatTolerance)) * std::max(0.0, r.front().first);
            for (const auto& [en, c] : r) {
                if (en > limit) break;
                if (!repeats(p, c)) {
                    out.chosen[p] = c;
                    out.chosenExact[p] = c.asVec3d();
                    out.energy[p] = std::max(0.0, en);
                    ++changed;
                    break;
                }
            }
        }
        decided[p] = 1;
    }
    return changed;
}

} // namespace turb::detail
