/// @file Distance.h
/// @brief Exact Euclidean distance transforms (Felzenszwalb & Huttenlocher 2012, "Distance Transforms of
///        Sampled Functions"): the 1D lower envelope of parabolas, applied along each axis in turn.
///
/// Used where a region needs a margin measured in voxels: synth's detail that stays near the smoke, the
/// measure of detail in still air, and stylize's signed distances of masks (MotionGuides.h).
#pragma once

#include <turb/Field.h>

#include <vector>

namespace turb {

/// Squared distance at which a sample counts as "no site in reach" (larger than any box's diagonal squared).
constexpr double kNoSiteSquaredDistance = 1e20;

/// The 1D squared-distance transform of the sampled function f (length n >= 1): d[q] = min_p (q - p)^2 + f[p].
/// f[p] = 0 at sites and kNoSiteSquaredDistance elsewhere gives squared distances to the nearest site.
/// v (n ints) and z (n + 1 doubles) are scratch. Exact; O(n).
void squaredDistance1D(const double* f, int n, double* d, int* v, double* z);

/// Euclidean distance in voxels from the centre of every voxel of `density`'s box to the centre of the nearest
/// voxel with density > threshold (0 inside the smoke). Same box and lattice as `density`. Voxels of a box with
/// no smoke get sqrt(kNoSiteSquaredDistance). Exact, separable along x, y, z; deterministic at any thread count.
ScalarField distanceToSmoke(const ScalarField& density, float threshold);

} // namespace turb
