/// @file Reorient.h
/// @brief Exact grid reorientations and box down-sampling of whole frames: proxies for tests and
///        look-development (a box-downsampled cache is the target whose detail a transfer must recover;
///        a source turned on its side tests flow alignment).
///
/// @code
/// turb::Frame proxy = turb::downsampleFrame(hiRes, 4);                       // mean over 4^3 blocks
/// turb::Frame sideways = turb::reorientFrame(f, turb::AxisRotation::quarterTurns(1, 1)); // 90 deg about y
/// @endcode
#pragma once

#include <turb/Frame.h>

#include <array>

namespace turb {

/// One of the 24 rotations mapping coordinate axes onto coordinate axes: component i of the rotated
/// vector is sign[i] * v[perm[i]]. Exact on grids: voxels move, nothing is resampled.
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
    /// `turns` quarter turns (right-handed) about coordinate axis `axis` (0 = x, 1 = y, 2 = z).
    static AxisRotation quarterTurns(int axis, int turns);
};

/// Rotated copies of fields about the index origin; the lattice's voxel size is kept.
VectorField rotated(const VectorField& f, const AxisRotation& r);
ScalarField rotated(const ScalarField& f, const AxisRotation& r);

/// Every field of the frame rotated (vectors too). The lattice keeps its voxel size and origin.
Frame reorientFrame(const Frame& f, const AxisRotation& r);

/// Every field averaged over factor^3 blocks onto the coarsened lattice (turb::boxDownsample).
Frame downsampleFrame(const Frame& f, int factor);

} // namespace turb
