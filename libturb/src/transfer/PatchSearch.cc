#include "PatchSearch.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb::detail {

void globalDescriptor(const VectorField& u, const ScalarField& d, const Coord& centre, int b, int depth, float k,
    const MatchWeights& w, float* out)
{
    const int r = b / 2, rz = depth / 2;
    const float sa = std::sqrt(w.alpha);
    size_t n = 0;
    for (int x = -r; x <= r; ++x)
        for (int y = -r; y <= r; ++y)
            for (int z = -rz; z <= rz; ++z) {
                const Coord c = centre + Coord(x, y, z);
                const Vec3f v = u.clamped(c.x(), c.y(), c.z()) * k;
                out[n++] = v.x();
                out[n++] = v.y();
                out[n++] = v.z();
                out[n++] = d.clamped(c.x(), c.y(), c.z()) > w.threshold ? sa : 0.0f;
            }
}

void GlobalIndex::build(
    const VectorField& us, const ScalarField& ds, int b, int depth, float k, const MatchWeights& w, int pcaComponents)
{
    mCells.clear();
    if (us.bbox() != ds.bbox()) throw ValueError("GlobalIndex: the coarse velocity and density cover different boxes");
    const int r = b / 2, rz = depth / 2;
    // Candidate centres: cells with smoke within the patch radius, the smoke mask dilated by (r, r, rz) one axis at a
    // time (a box's dilation is separable).
    std::vector<uint8_t> smoke(ds.size()), next(ds.size());
    for (size_t n = 0; n < ds.size(); ++n) smoke[n] = ds.data()[n] > w.threshold;
    const Coord cells = ds.bbox().dim();
    const size_t stride[3] = {size_t(cells.y()) * size_t(cells.z()), size_t(cells.z()), 1};
    for (int a = 0; a < 3; ++a) {
        const int reach = a == 2 ? rz : r;
        if (reach <= 0) continue;
        parallelFor(size_t(cells.x()), 1, [&](size_t x0, size_t x1) {
            for (size_t i = x0; i < x1; ++i)
                for (int j = 0; j < cells.y(); ++j)
                    for (int k = 0; k < cells.z(); ++k) {
                        const int p = a == 0 ? int(i) : (a == 1 ? j : k);
                        const size_t o = i * stride[0] + size_t(j) * stride[1] + size_t(k);
                        uint8_t any = 0;
                        for (int d = std::max(-reach, -p); d <= std::min(reach, cells[a] - 1 - p) && !any; ++d)
                            any = smoke[size_t(std::ptrdiff_t(o) + std::ptrdiff_t(d) * std::ptrdiff_t(stride[a]))];
                        next[o] = any;
                    }
        });
        std::swap(smoke, next);
    }
    for (size_t n = 0; n < ds.size(); ++n)
        if (smoke[n]) mCells.push_back(ds.coordOf(n));
    if (mCells.empty()) return;
    // Fit the PCA on an even sample, then project the cells in fixed chunks: at ratio 2 a descriptor has 2916
    // floats, and holding all of them for a 64^3 source would take gigabytes.
    const size_t dim = globalDescriptorSize(b, depth);
    PcaSettings ps{pcaComponents};
    ps.maxSamples = kGlobalPatchPcaSamples;
    const size_t sample = std::min(mCells.size(), ps.maxSamples);
    const double step = double(mCells.size()) / double(sample);
    Pca pca;
    {
        std::vector<float> rows(sample * dim);
        parallelFor(sample, 64, [&](size_t s, size_t e) {
            for (size_t i = s; i < e; ++i)
                globalDescriptor(us, ds, mCells[size_t(i * step)], b, depth, k, w, &rows[i * dim]);
        });
        pca.fit(rows.data(), sample, dim, ps);
    }
    const size_t rk = pca.outputDim(), chunk = 4096;
    std::vector<float> reduced(mCells.size() * rk), rows;
    for (size_t c0 = 0; c0 < mCells.size(); c0 += chunk) {
        const size_t c1 = std::min(mCells.size(), c0 + chunk);
        rows.resize((c1 - c0) * dim);
        parallelFor(c1 - c0, 64, [&](size_t s, size_t e) {
            for (size_t i = s; i < e; ++i) globalDescriptor(us, ds, mCells[c0 + i], b, depth, k, w, &rows[i * dim]);
        });
        pca.projectRows(rows.data(), c1 - c0, &reduced[c0 * rk]);
    }
    mIndex.buildReduced(std::move(reduced), pca);
}

Coord GlobalIndex::nearest(const float* descriptor) const
{
    int idx = -1;
    float d2 = 0.0f;
    mIndex.query(descriptor, 1, &idx, &d2);
    return idx >= 0 ? mCells[size_t(idx)] : Coord(0);
}

void localDescriptor(const VectorField& U, const ScalarField& D, const Coord& corner, const Coord& patch, float k,
    const MatchWeights& w, float* out)
{
    const float sa = std::sqrt(w.alpha);
    size_t n = 0;
    // Samples at odd offsets 1, 3, 5, ... sit symmetrically inside an even-sized patch (offset 0 of a 2D patch's
    // one layer).
    for (int x = 1 % patch.x(); x < patch.x(); x += 2)
        for (int y = 1 % patch.y(); y < patch.y(); y += 2)
            for (int z = 1 % patch.z(); z < patch.z(); z += 2) {
                const Coord c = corner + Coord(x, y, z);
                const Vec3f v = U.clamped(c.x(), c.y(), c.z()) * k;
                out[n++] = v.x();
                out[n++] = v.y();
                out[n++] = v.z();
                out[n++] = D.clamped(c.x(), c.y(), c.z()) > w.threshold ? sa : 0.0f;
            }
}

namespace {

// The smoke mask's summed-area table over `box`: the smoke voxels of any patch-sized box in O(1).
class SmokeCounts
{
public:
    SmokeCounts(const ScalarField& Ds, const CoordBBox& box, float threshold)
        : mBox(box), mD(box.dim()), mSum(size_t(mD.x() + 1) * size_t(mD.y() + 1) * size_t(mD.z() + 1), 0)
    {
        for (int x = 1; x <= mD.x(); ++x)
            for (int y = 1; y <= mD.y(); ++y)
                for (int z = 1; z <= mD.z(); ++z) {
                    const int m = Ds(box.min().x() + x - 1, box.min().y() + y - 1, box.min().z() + z - 1) > threshold;
                    mSum[at(x, y, z)] = m + mSum[at(x - 1, y, z)] + mSum[at(x, y - 1, z)] + mSum[at(x, y, z - 1)] -
                                        mSum[at(x - 1, y - 1, z)] - mSum[at(x - 1, y, z - 1)] -
                                        mSum[at(x, y - 1, z - 1)] + mSum[at(x - 1, y - 1, z - 1)];
                }
    }
    // The smoke voxels of the patch with corner `lo`.
    int in(const Coord& lo, const Coord& patch) const
    {
        const int x0 = lo.x() - mBox.min().x(), y0 = lo.y() - mBox.min().y(), z0 = lo.z() - mBox.min().z();
        const int x1 = x0 + patch.x(), y1 = y0 + patch.y(), z1 = z0 + patch.z();
        return mSum[at(x1, y1, z1)] - mSum[at(x0, y1, z1)] - mSum[at(x1, y0, z1)] - mSum[at(x1, y1, z0)] +
               mSum[at(x0, y0, z1)] + mSum[at(x0, y1, z0)] + mSum[at(x1, y0, z0)] - mSum[at(x0, y0, z0)];
    }

private:
    size_t at(int x, int y, int z) const
    {
        return (size_t(x) * size_t(mD.y() + 1) + size_t(y)) * size_t(mD.z() + 1) + size_t(z);
    }
    CoordBBox mBox;
    Coord mD;
    std::vector<int> mSum;
};

// The candidates' reduced descriptors, one row of pca.outputDim() each. The PCA is fitted on an even subset; then
// everything is projected in fixed chunks (memory stays bounded).
std::vector<float> reducedDescriptors(const VectorField& Usl, const ScalarField& Ds, const std::vector<Coord>& corners,
    const Coord& patch, float k, const MatchWeights& w, int pcaComponents, Pca& pca)
{
    const size_t count = corners.size();
    const size_t dim = localDescriptorSize(patch);
    {
        const size_t sample = std::min<size_t>(count, 12000);
        std::vector<float> rows(sample * dim);
        const double step = double(count) / double(sample);
        parallelFor(sample, 256, [&](size_t s, size_t e) {
            for (size_t i = s; i < e; ++i)
                localDescriptor(Usl, Ds, corners[size_t(i * step)], patch, k, w, &rows[i * dim]);
        });
        pca.fit(rows.data(), sample, dim, PcaSettings{pcaComponents, sample});
    }
    const size_t rk = pca.outputDim();
    std::vector<float> reduced(count * rk, 0.0f);
    const size_t chunk = 4096;
    std::vector<float> rows;
    for (size_t b = 0; b < count; b += chunk) {
        const size_t e = std::min(count, b + chunk);
        rows.resize((e - b) * dim);
        parallelFor(e - b, 256, [&](size_t s, size_t t) {
            for (size_t i = s; i < t; ++i) localDescriptor(Usl, Ds, corners[b + i], patch, k, w, &rows[i * dim]);
        });
        pca.projectRows(rows.data(), e - b, &reduced[b * rk]);
    }
    return reduced;
}

} // namespace

void LocalCandidates::build(const VectorField& Usl, const ScalarField& Ds, const Coord& patch, int stride, float k,
    const MatchWeights& w, int pcaComponents, double minSmoke)
{
    mPatch = patch;
    mStride = std::max(1, stride);
    const CoordBBox box = Usl.bbox();
    mCorners = CoordBBox(box.min(), box.max() - (patch - Coord(1)));
    // The stride lattice sits on absolute multiples of the stride, as the output's patches sit on multiples of B:
    // the candidates are then the same whichever box the source is held over (its smoke and a margin, or the whole
    // domain). An axis too short for that (a 2D source's one layer) keeps the box's own start.
    for (int a = 0; a < 3; ++a) {
        const int aligned = floorDiv(mCorners.min()[a] + mStride - 1, mStride) * mStride;
        if (aligned <= mCorners.max()[a]) mCorners.min()[a] = aligned;
    }
    mReduced.clear();
    mSlot.clear();
    mCount = 0;
    if (mCorners.empty()) throw ValueError("the source is smaller than one local patch");
    const Coord extent = mCorners.dim();
    mLattice = Coord((extent.x() + mStride - 1) / mStride, (extent.y() + mStride - 1) / mStride,
        (extent.z() + mStride - 1) / mStride);
    const size_t cells = size_t(mLattice.x()) * size_t(mLattice.y()) * size_t(mLattice.z());

    // Which candidate patches hold smoke: a prefix-sum over the mask answers each box in O(1).
    const SmokeCounts smoke(Ds, box, w.threshold);
    // The smoke a candidate needs: `minSmoke` of its voxels, relaxed to half the smokiest patch's share when the
    // source holds no patch that full (thin shells of smoke on a plume's first frames).
    int most = 0;
    for (int x = 0; x < mLattice.x(); ++x)
        for (int y = 0; y < mLattice.y(); ++y)
            for (int z = 0; z < mLattice.z(); ++z)
                most = std::max(most, smoke.in(mCorners.min() + Coord(x * mStride, y * mStride, z * mStride), patch));
    mMinSmoke = std::max(
        1, int(std::ceil(std::min(minSmoke * double(patch.x()) * double(patch.y()) * double(patch.z()), 0.5 * most))));
    mSlot.assign(cells, -1);
    std::vector<Coord> corners;
    for (int x = 0; x < mLattice.x(); ++x)
        for (int y = 0; y < mLattice.y(); ++y)
            for (int z = 0; z < mLattice.z(); ++z) {
                const Coord c = mCorners.min() + Coord(x * mStride, y * mStride, z * mStride);
                if (smoke.in(c, patch) < mMinSmoke) continue;
                mSlot[(size_t(x) * size_t(mLattice.y()) + size_t(y)) * size_t(mLattice.z()) + size_t(z)] =
                    int(corners.size());
                corners.push_back(c);
            }
    mCount = corners.size();
    if (mCount == 0) return;
    mReduced = reducedDescriptors(Usl, Ds, corners, patch, k, w, pcaComponents, mPca);
}

const float* LocalCandidates::reduced(const Coord& c) const
{
    const Coord rel = c - mCorners.min();
    if (rel.x() < 0 || rel.y() < 0 || rel.z() < 0) return nullptr;
    if (rel.x() % mStride || rel.y() % mStride || rel.z() % mStride) return nullptr;
    const Coord l(rel.x() / mStride, rel.y() / mStride, rel.z() / mStride);
    if (l.x() >= mLattice.x() || l.y() >= mLattice.y() || l.z() >= mLattice.z()) return nullptr;
    const int slot =
        mSlot[(size_t(l.x()) * size_t(mLattice.y()) + size_t(l.y())) * size_t(mLattice.z()) + size_t(l.z())];
    return slot < 0 ? nullptr : &mReduced[size_t(slot) * mPca.outputDim()];
}

} // namespace turb::detail
