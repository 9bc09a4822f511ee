// Advection of dense 3D fields over their own box, without a VDB round trip (Advect.cc dispatches here).
#pragma once

#include <turb/Advect.h>

namespace turb::detail {

/// q advected by `velocity` over `dt` with s.scheme and s.clamp: first-order backtraces from each voxel centre (the
/// velocity sampled trilinearly there, in world space), trilinear taps of q, zero outside q's box; the number of
/// substeps from the CFL number as OpenVDB's VolumeAdvection takes it (the largest |velocity|, 3 voxels a substep).
ScalarField advectDense(const ScalarField& q, const VectorField& velocity, double dt, const AdvectSettings& s);
VectorField advectDense(const VectorField& q, const VectorField& velocity, double dt, const AdvectSettings& s);

} // namespace turb::detail
