/// @file Field.h
/// @brief Dense fields on a uniform lattice: the working representation of every stage.
///
/// Caches arrive as sparse VDB grids, but patch search, FFTs and the seam solve all want random access
/// over a box. Frames are small enough (a 128x128x192 velocity is 38 MB) that a dense box over the
/// domain is both simpler and faster. Values are stored z-fastest, matching openvdb::tools::Dense's
/// LayoutZYX, so the IO layer can copy to and from VDB trees without reordering.
///
/// @code
/// turb::Lattice lat{0.125, {0, 0, 0}};
/// turb::ScalarField rho(openvdb::CoordBBox({0, 0, 0}, {31, 31, 31}), lat);
/// rho(3, 4, 5) = 1.0f;
/// @endcode
#pragma once

#include <openvdb/math/Coord.h>
#include <openvdb/math/Vec3.h>

#include <cmath>
#include <cstddef>
#include <vector>

namespace turb {

using Coord = openvdb::math::Coord;
using CoordBBox = openvdb::math::CoordBBox;
using Vec3f = openvdb::math::Vec3<float>;
using Vec3d = openvdb::math::Vec3<double>;

/// Where an index lattice sits in world space: a uniform voxel size, and the world position of the
/// centre of voxel (0,0,0). Only uniform-scale-plus-translation transforms are supported.
struct Lattice
{
    double voxelSize = 1.0; ///< edge length of a voxel in world units, > 0
    Vec3d origin{0.0};      ///< world position of the centre of voxel (0,0,0)

    Vec3d indexToWorld(const Vec3d& ijk) const { return origin + ijk * voxelSize; }
    Vec3d worldToIndex(const Vec3d& xyz) const { return (xyz - origin) / voxelSize; }

    /// The lattice of voxels `factor` times smaller whose blocks of factor^3 voxels tile this
    /// lattice's voxels exactly: fine voxel I lies in coarse voxel floor(I / factor).
    Lattice refined(int factor) const
    {
        Lattice l;
        l.voxelSize = voxelSize / factor;
        l.origin = origin + Vec3d(-0.5 * voxelSize + 0.5 * l.voxelSize);
        return l;
    }
    /// Inverse of refined().
    Lattice coarsened(int factor) const
    {
        Lattice l;
        l.voxelSize = voxelSize * factor;
        l.origin = origin + Vec3d(0.5 * l.voxelSize - 0.5 * voxelSize);
        return l;
    }
    bool approxEqual(const Lattice& o, double relTol = 1e-6) const
    {
        const double tol = relTol * voxelSize;
        return std::abs(voxelSize - o.voxelSize) <= tol && (origin - o.origin).length() <= tol * 10;
    }
};

/// A dense box of values over an inclusive index bounding box, placed in world space by a Lattice.
template<typename T>
class Field
{
public:
    using ValueType = T;

    Field() = default;
    Field(const CoordBBox& box, const Lattice& lattice, const T& fill = zeroValue()) : mBox(box), mLattice(lattice)
    {
        const Coord d = box.empty() ? Coord(0) : box.dim();
        mDim = d;
        mValues.assign(size_t(d.x()) * size_t(d.y()) * size_t(d.z()), fill);
    }

    static T zeroValue() { return T(0); }

    const CoordBBox& bbox() const { return mBox; }
    const Coord& dim() const { return mDim; }
    const Lattice& lattice() const { return mLattice; }
    void setLattice(const Lattice& l) { mLattice = l; }
    bool empty() const { return mValues.empty(); }
    size_t size() const { return mValues.size(); }

    /// Linear offset of (i,j,k); z is the fastest-varying index.
    size_t offset(int i, int j, int k) const
    {
        return (size_t(i - mBox.min().x()) * size_t(mDim.y()) + size_t(j - mBox.min().y())) * size_t(mDim.z()) +
               size_t(k - mBox.min().z());
    }
    Coord coordOf(size_t n) const
    {
        const int k = int(n % size_t(mDim.z()));
        const size_t r = n / size_t(mDim.z());
        const int j = int(r % size_t(mDim.y()));
        const int i = int(r / size_t(mDim.y()));
        return mBox.min() + Coord(i, j, k);
    }
    bool contains(int i, int j, int k) const { return mBox.isInside(Coord(i, j, k)); }
    bool contains(const Coord& c) const { return mBox.isInside(c); }

    T& operator()(int i, int j, int k) { return mValues[offset(i, j, k)]; }
    const T& operator()(int i, int j, int k) const { return mValues[offset(i, j, k)]; }
    T& operator[](const Coord& c) { return mValues[offset(c.x(), c.y(), c.z())]; }
    const T& operator[](const Coord& c) const { return mValues[offset(c.x(), c.y(), c.z())]; }

    /// The value at (i,j,k), or `outside` when the voxel is not in the box (VDB background semantics).
    T valueOr(int i, int j, int k, const T& outside) const { return contains(i, j, k) ? (*this)(i, j, k) : outside; }
    /// The value at the voxel of the box nearest to (i,j,k) (constant extension).
    const T& clamped(int i, int j, int k) const { return (*this)(clampi(i, 0), clampi(j, 1), clampi(k, 2)); }

    T* data() { return mValues.data(); }
    const T* data() const { return mValues.data(); }
    std::vector<T>& values() { return mValues; }
    const std::vector<T>& values() const { return mValues; }

    void fill(const T& v) { std::fill(mValues.begin(), mValues.end(), v); }

private:
    int clampi(int v, int axis) const
    {
        const int lo = mBox.min()[axis], hi = mBox.max()[axis];
        return v < lo ? lo : (v > hi ? hi : v);
    }

    CoordBBox mBox;
    Coord mDim{0};
    Lattice mLattice;
    std::vector<T> mValues;
};

template<>
inline Vec3f Field<Vec3f>::zeroValue()
{
    return Vec3f(0.0f);
}

using ScalarField = Field<float>;
using VectorField = Field<Vec3f>;

/// Floor division that rounds toward minus infinity (index arithmetic across coarse/fine lattices).
inline int floorDiv(int a, int b) { return (a >= 0) ? a / b : -((-a + b - 1) / b); }

/// The coarse box covering every fine voxel of `fine` when a coarse voxel holds factor^3 fine ones.
inline CoordBBox coarsenBox(const CoordBBox& fine, int factor)
{
    return CoordBBox(
        Coord(floorDiv(fine.min().x(), factor), floorDiv(fine.min().y(), factor), floorDiv(fine.min().z(), factor)),
        Coord(floorDiv(fine.max().x(), factor), floorDiv(fine.max().y(), factor), floorDiv(fine.max().z(), factor)));
}

/// The fine box tiled exactly by the coarse box.
inline CoordBBox refineBox(const CoordBBox& coarse, int factor)
{
    const Coord& a = coarse.min();
    const Coord& b = coarse.max();
    return CoordBBox(Coord(a.x() * factor, a.y() * factor, a.z() * factor),
        Coord(b.x() * factor + factor - 1, b.y() * factor + factor - 1, b.z() * factor + factor - 1));
}

/// A 2D field: one voxel thick in z, the way Houdini and Blender write 2D simulations. Refining or coarsening a
/// flat field's box (refineDomain, coarsenDomain, upsample, boxDownsample) keeps its one layer at the same z index.
inline bool isFlat(const CoordBBox& box) { return !box.empty() && box.dim().z() == 1; }

/// The per-axis factors refineDomain and coarsenDomain apply: (f, f, 1) for a flat box, (f, f, f) otherwise.
inline Coord domainFactors(const CoordBBox& box, int factor)
{
    return isFlat(box) ? Coord(factor, factor, 1) : Coord(factor);
}

/// refineBox, except that a flat (2D) box keeps its one z layer at the same index.
inline CoordBBox refineDomain(const CoordBBox& coarse, int factor)
{
    CoordBBox b = refineBox(coarse, factor);
    if (isFlat(coarse))
        b = CoordBBox(
            Coord(b.min().x(), b.min().y(), coarse.min().z()), Coord(b.max().x(), b.max().y(), coarse.max().z()));
    return b;
}

/// coarsenBox, except that a flat (2D) box keeps its one z layer at the same index.
inline CoordBBox coarsenDomain(const CoordBBox& fine, int factor)
{
    CoordBBox b = coarsenBox(fine, factor);
    if (isFlat(fine))
        b = CoordBBox(Coord(b.min().x(), b.min().y(), fine.min().z()), Coord(b.max().x(), b.max().y(), fine.max().z()));
    return b;
}

/// `l` (a refinement or coarsening of `from`) with its z origin moved, for a flat (2D) box, so that the box's one
/// layer keeps its index and its world height (synth's 2D convention, FineDomain); other boxes keep `l`.
inline Lattice keepFlatLayer(Lattice l, const Lattice& from, const CoordBBox& box)
{
    if (isFlat(box)) {
        const int k0 = box.min().z();
        Vec3d o = l.origin;
        o[2] = from.origin.z() + k0 * from.voxelSize - k0 * l.voxelSize;
        l.origin = o;
    }
    return l;
}

/// The lattice of refineDomain(box, factor): lattice.refined(factor), its flat layer kept (keepFlatLayer).
inline Lattice refinedLattice(const Lattice& coarse, const CoordBBox& box, int factor)
{
    return keepFlatLayer(coarse.refined(factor), coarse, box);
}

/// The lattice of coarsenDomain(box, factor); the inverse of refinedLattice.
inline Lattice coarsenedLattice(const Lattice& fine, const CoordBBox& box, int factor)
{
    return keepFlatLayer(fine.coarsened(factor), fine, box);
}

} // namespace turb
