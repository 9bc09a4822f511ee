// Private to the transfer stage: flow alignment (beyond the paper) and removal of U_h's coarse part.
#pragma once

#include <turb/Reorient.h>

#include <array>

namespace turb::detail {

using turb::AxisRotation;

/// The rotation (identity preferred on ties) whose image of `from` points most along `to`.
AxisRotation bestRotation(const Vec3d& from, const Vec3d& to);

/// Mean velocity and RMS speed over voxels where `density` > threshold (same box and lattice).
void smokeFlowStats(const VectorField& u, const ScalarField& density, float threshold, Vec3d& mean, double& rms);

/// A coarse field c with boxDownsample(upsample(c)) = boxDownsample(detail) (Richardson iteration on the
/// coarse lattice), so detail - upsample(c) has zero box means up to `tolerance` while staying smooth.
VectorField coarsePart(const VectorField& detail, int factor, int iterations = 200, double tolerance = 1e-3);

/// lf_err's ratio for a detail field on the refined target lattice: rms of its box means over the target
/// cells with density > threshold, against the same of `up` (the up-sampled target velocity, same box);
/// +infinity when the target is at rest there and the detail is not.
double coarseRatio(
    const VectorField& detail, const VectorField& up, const ScalarField& targetDensity, float threshold, int factor);

} // namespace turb::detail
