// Private to the transfer stage: descriptors and the two-level patch search of Sato et al. section 3.2.
#pragma once

#include <turb/Field.h>
#include <turb/PatchIndex.h>

#include <vector>

namespace turb::detail {

/// Weights shared by both levels. Velocities enter multiplied by a per-sequence scale k (coarse cells
/// per frame per world unit, or 1 / RMS speed when normalising), densities as 0/1 masks.
struct MatchWeights
{
    float alpha = 0.004f;
    float beta = 0.5f;
    float threshold = 0.01f;
};

/// Global patches (eq. 1): b x b x depth coarse cells x (3 velocity + 1 mask) channels, clamped at the box;
/// depth = b in 3D, 1 in 2D (b^2 patches on the one layer). b and depth odd.
void globalDescriptor(const VectorField& u, const ScalarField& d, const Coord& centre, int b, int depth, float k,
    const MatchWeights& w, float* out);
inline size_t globalDescriptorSize(int b, int depth) { return size_t(b) * size_t(b) * size_t(depth) * 4; }

/// FLANN index over the global patches of the downsampled source, at every coarse cell whose b^3
/// neighbourhood holds smoke.
class GlobalIndex
{
public:
    void build(const VectorField& us, const ScalarField& ds, int b, int depth, float k, const MatchWeights& w,
        int pcaComponents);
    bool empty() const { return mCells.empty(); }
    /// The coarse source cell whose global patch is nearest to the descriptor.
    Coord nearest(const float* descriptor) const;

private:
    PatchIndex mIndex;
    std::vector<Coord> mCells;
};

/// Local patches for the first (PCA) stage of the local search: the patch (extent (B, B, B), or (B, B, 1) in 2D)
/// sampled on every other voxel, channels = low-frequency velocity (3) + mask (1). The temporal term is left to
/// the exact re-scoring, because the previous detail does not exist everywhere.
void localDescriptor(const VectorField& U, const ScalarField& D, const Coord& corner, const Coord& patch, float k,
    const MatchWeights& w, float* out);
inline size_t localDescriptorSize(const Coord& patch)
{
    return size_t((patch.x() + 1) / 2) * size_t((patch.y() + 1) / 2) * size_t((patch.z() + 1) / 2) * 4;
}

/// PCA-reduced local descriptors of the source at every `stride`-th patch corner whose patch holds
/// smoke.
class LocalCandidates
{
public:
    /// Candidates are patches with at least `minSmoke` of their voxels in the smoke, or half the smokiest patch's
    /// count when that is less (and always at least one voxel).
    void build(const VectorField& Usl, const ScalarField& Ds, const Coord& patch, int stride, float k,
        const MatchWeights& w, int pcaComponents, double minSmoke = 0.0);
    const Pca& pca() const { return mPca; }
    int stride() const { return mStride; }
    /// Corners allowed for a patch (the whole patch inside the source box).
    const CoordBBox& cornerBox() const { return mCorners; }
    /// Reduced descriptor of the candidate at lattice corner `c` (a multiple of stride from the corner
    /// box's minimum), or nullptr when that patch holds no smoke.
    const float* reduced(const Coord& c) const;
    size_t count() const { return mCount; }
    /// The smoke voxels a candidate patch needed (see build).
    int minSmokeVoxels() const { return mMinSmoke; }

private:
    Pca mPca;
    int mStride = 2;
    Coord mPatch{8};
    CoordBBox mCorners;
    Coord mLattice{0};
    std::vector<int> mSlot;
    std::vector<float> mReduced;
    size_t mCount = 0;
    int mMinSmoke = 1;
};

} // namespace turb::detail
