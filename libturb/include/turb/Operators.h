/// @file Operators.h
/// @brief Sampling and finite differences on dense fields, in world units.
///
/// Central differences inside the box, one-sided at its faces. These are the discrete operators the
/// quality metrics (`div_rel`) are defined with; solvers use their own consistent (staggered) stencils.
#pragma once

#include <turb/Field.h>

#include <algorithm>
#include <cmath>

namespace turb {

/// Trilinear interpolation at a continuous index position, clamped to the box (constant extension).
template<typename T>
inline T sampleTrilinear(const Field<T>& f, const Vec3d& ijk)
{
    const CoordBBox& b = f.bbox();
    double p[3];
    int i0[3], i1[3];
    double w[3];
    for (int a = 0; a < 3; ++a) {
        p[a] = std::min(std::max(ijk[a], double(b.min()[a])), double(b.max()[a]));
        i0[a] = int(std::floor(p[a]));
        w[a] = p[a] - i0[a];
        i1[a] = std::min(i0[a] + 1, b.max()[a]);
    }
    const auto v = [&](int x, int y, int z) { return f(x, y, z); };
    const T c00 = v(i0[0], i0[1], i0[2]) * float(1 - w[2]) + v(i0[0], i0[1], i1[2]) * float(w[2]);
    const T c01 = v(i0[0], i1[1], i0[2]) * float(1 - w[2]) + v(i0[0], i1[1], i1[2]) * float(w[2]);
    const T c10 = v(i1[0], i0[1], i0[2]) * float(1 - w[2]) + v(i1[0], i0[1], i1[2]) * float(w[2]);
    const T c11 = v(i1[0], i1[1], i0[2]) * float(1 - w[2]) + v(i1[0], i1[1], i1[2]) * float(w[2]);
    const T c0 = c00 * float(1 - w[1]) + c01 * float(w[1]);
    const T c1 = c10 * float(1 - w[1]) + c11 * float(w[1]);
    return c0 * float(1 - w[0]) + c1 * float(w[0]);
}

/// Trilinear sample at a world position.
template<typename T>
inline T sampleWorld(const Field<T>& f, const Vec3d& xyz)
{
    return sampleTrilinear(f, f.lattice().worldToIndex(xyz));
}

/// Velocity-gradient tensor at a voxel: J[a][b] = d u_a / d x_b (world units).
struct Jacobian
{
    Vec3f d[3]; ///< d[b] = d u / d x_b
    float divergence() const { return d[0][0] + d[1][1] + d[2][2]; }
    Vec3f curl() const { return Vec3f(d[1][2] - d[2][1], d[2][0] - d[0][2], d[0][1] - d[1][0]); }
    float frobeniusSq() const { return d[0].lengthSqr() + d[1].lengthSqr() + d[2].lengthSqr(); }
};

/// (f(c + e_a) - f(c - e_a)) / 2 in index units, one-sided on the box faces (0 on a one-voxel axis).
template<typename T>
inline T centralDifferenceAt(const Field<T>& f, int i, int j, int k, int axis)
{
    const CoordBBox& b = f.bbox();
    const int c[3] = {i, j, k};
    int lo[3] = {i, j, k}, hi[3] = {i, j, k};
    lo[axis] = std::max(c[axis] - 1, b.min()[axis]);
    hi[axis] = std::min(c[axis] + 1, b.max()[axis]);
    const int span = hi[axis] - lo[axis];
    return span > 0 ? (f(hi[0], hi[1], hi[2]) - f(lo[0], lo[1], lo[2])) * (1.0f / float(span)) : Field<T>::zeroValue();
}

/// Central differences (one-sided on the box faces), in world units.
inline Jacobian jacobianAt(const VectorField& u, int i, int j, int k)
{
    Jacobian J;
    const float inv = float(1.0 / u.lattice().voxelSize);
    for (int a = 0; a < 3; ++a) J.d[a] = centralDifferenceAt(u, i, j, k, a) * inv;
    return J;
}

/// Divergence with central differences.
ScalarField divergence(const VectorField& u);
/// Curl (vorticity) with central differences.
VectorField curl(const VectorField& u);
/// |u| per voxel.
ScalarField magnitude(const VectorField& u);

} // namespace turb
