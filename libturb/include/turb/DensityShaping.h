/// @file DensityShaping.h
/// @brief Shaping a high-resolution density's edge after advection: an interface compression that keeps the edge
///        sharp, and a diffusion along the density's level sets that removes hair without blurring the edge.
///
/// Density advected through detail velocity frays into hairs and streaks along its surface (measure's
/// `density_fray`), while the edge across the surface stays soft (`edge_crispness`). Diffusing the whole density
/// trades one for the other (semi-Lagrangian advection on issue 42's paper pair: fray 0.486 -> 0.367, crispness
/// 4.31 -> 2.91). These two steps act on the two directions separately:
/// - compressInterface: the artificial compression term of OpenFOAM's interFoam (Weller 2008), a conservative flux
///   c n a(1 - a) peak across every voxel face toward increasing density (n the direction of the gradient of a
///   smoothed copy S of the density, a = D / peak), which steepens the rise across the surface;
/// - diffuseAlongLevelSets: D += k (lap D - n.Hess(D).n), the Laplacian less its part along n: diffusion within the
///   level sets of S only, which evens out hairs and leaves a plane edge as it is.
/// Measured on the Blender plume2 pair (30 frames, c = 0.5, k = 0.15, 3 passes): fray 0.285 -> 0.154 and
/// crispness 2.39 -> 2.52 together (docs/look.md). S is D smoothed by [1 2 1]/4 twice along each axis. Both run in
/// parallel over x slabs, each voxel's result from its neighbours alone: the same output at any thread count.
///
/// @code
/// turb::compressInterface(density, 0.5f, targetPeak);
/// turb::diffuseAlongLevelSets(density, 0.15f, 3);
/// @endcode
#pragma once

#include <turb/Field.h>

namespace turb {

/// One step of interface compression of `density` (any box; 2D when one voxel thick in z), in place. `c` is the
/// compression speed in voxels per call, in [0, 1] (0: no change); `peak` (> 0, density units) is the density at
/// which the flux vanishes again (the target's peak). Mass is kept to rounding (face fluxes); values below 0 after
/// the step are set to 0, and the central face flux may carry a little past `peak` (1.8e-5 of it after 5 steps at
/// c = 0.5 on a tanh edge 3 voxels wide: DensityShaping.InterfaceCompressionSteepensAnEdgeAndKeepsTheMass). Throws
/// ValueError for c outside [0, 1] or peak <= 0.
void compressInterface(ScalarField& density, float c, float peak);

/// `passes` explicit steps of diffusion along the level sets of the smoothed density, in place; `k` in [0, 1/6]
/// (stable for the explicit step), `passes` >= 0. Values stay >= 0. Not exactly conservative (the non-divergence
/// form); transfer's density guide restores the coarse means afterwards (mass_ratio 1.00 on the plume2 pair). Throws
/// ValueError for k outside [0, 1/6] or passes < 0.
void diffuseAlongLevelSets(ScalarField& density, float k, int passes);

} // namespace turb
