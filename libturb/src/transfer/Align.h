// Private to the transfer stage: flow alignment (beyond the paper) and removal of U_h's coarse part.
#pragma once

#include <turb/Field.h>

#include <array>

namespace turb::detail {

/// One of the 24 rotations that map coordinate axes onto coordinate axes: component i of the
/// rotated vector is sign[i] * v[perm[i]]. Exact on grids (no resampling).
struct AxisRotation
{
    std::array<int, 3> perm{0, 1, 2};
    std::array<int, 3> sign{1, 1, 1};

    Vec3f apply(const Vec3f& v) const
    {
        return Vec3f(float(sign[0]) * v[perm[0]], float(sign[1]) * v[perm[1]], float(sign[2]) * v[perm[2]]);
    }
    bool isIdentity() const { return perm == std::array<int, 3>{0, 1, 2} && sign == std::array<int, 3>{1, 1, 1}; }
    int id() const; ///< 0..23, 0 = identity
    static AxisRotation fromId(int id);
};

/// The rotation (identity preferred on ties) whose image of `from` points most along `to`.
AxisRotation bestRotation(const Vec3d& from, const Vec3d& to);

/// Rotated copies of fields about the index origin; the lattice's voxel size is kept.
VectorField rotated(const VectorField& f, const AxisRotation& r);
ScalarField rotated(const ScalarField& f, const AxisRotation& r);

/// Mean velocity and RMS speed over voxels where `density` > threshold (same box and lattice).
void smokeFlowStats(const VectorField& u, const ScalarField& density, float threshold, Vec3d& mean, double& rms);

/// A coarse field c with boxDownsample(upsample(c)) = boxDownsample(detail) (Richardson iteration on the
/// coarse lattice), so detail - upsample(c) has zero box means up to `tolerance` while staying smooth.
VectorField coarsePart(const VectorField& detail, int factor, int iterations = 200, double tolerance = 1e-3);

} // namespace turb::detail
