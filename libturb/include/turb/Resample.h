/// @file Resample.h
/// @brief Moving fields between a coarse lattice and its f-times finer refinement, and the frequency
///        split of Sato et al. 2018 (section 3.1) built on them.
///
/// Both operators are the ones docs/measure.md defines the metrics with:
/// - upsample: cell-centred trilinear. Fine voxel I sits at coarse coordinate (I + 1/2)/f - 1/2; values
///   beyond the coarse box are extended constantly from the edge.
/// - boxDownsample: the mean over each coarse voxel's f^3 fine voxels; fine voxels outside the fine box
///   count as zero (sparse-grid background).
/// - A 2D field (one voxel thick in z, isFlat) stays 2D: both act in x and y only, and its one layer keeps its z
///   index (refineDomain, coarsenDomain; world height as refinedLattice places it).
///
/// @code
/// turb::VectorField low = turb::upsample(turb::boxDownsample(u, 4), 4); // U_sl
/// turb::FrequencySplit s = turb::splitFrequencies(u, 4);                // s.low + s.high == u
/// @endcode
#pragma once

#include <turb/Field.h>
#include <turb/Frame.h>

namespace turb {

/// Cell-centred trilinear upsampling by an integer factor >= 1; the result covers refineDomain(bbox).
template<typename T>
Field<T> upsample(const Field<T>& coarse, int factor);

/// Mean over factor^3 blocks (factor^2 for a 2D field); the result covers coarsenDomain(fine.bbox()).
template<typename T>
Field<T> boxDownsample(const Field<T>& fine, int factor);

/// U = low + high with low = upsample(boxDownsample(U)), restricted to U's box.
struct FrequencySplit
{
    VectorField coarse; ///< u_s: boxDownsample(U), on the coarse lattice
    VectorField low;    ///< U_sl: upsample(coarse), on U's box
    VectorField high;   ///< U_sh = U - U_sl
};
FrequencySplit splitFrequencies(const VectorField& fine, int factor);

/// A copy of `f` restricted (or zero-extended) to `box`.
template<typename T>
Field<T> cropped(const Field<T>& f, const CoordBBox& box);

/// The central part of `box`: at most `n` voxels along each axis, centred (the lower side takes the odd voxel).
CoordBBox centralBox(const CoordBBox& box, int n);

/// Layer `k` of a 3D frame as a 2D frame, one voxel thick: density as it is, velocity in the layer's plane (its z
/// component set to 0). Number, dt and metadata are kept; temperature and flame are not. Throws ValueError when `k` is
/// outside the frame's z range.
Frame zLayer(const Frame& frame, int k);

/// A velocity written only near the smoke (the IO layer's velocity margin, meta::kVelocityMargin) is the
/// up-sampled target's wherever it was not written, and reads there as an exact zero: sets each exactly zero voxel
/// of `velocity` to `up` at the same index (zero where `up`'s box does not reach). Used by transfer's restore,
/// measure and the farm's join, so all three read a trimmed frame as the file means it.
void fillUnwrittenVelocity(VectorField& velocity, const VectorField& up);

/// The integer ratio coarse/fine of two voxel sizes; throws ValueError naming both when the ratio is
/// below 1 or not within `tol` of an integer.
int integerRatio(double coarseVoxel, double fineVoxel, double tol = 1e-3);

/// Whether coarse/fine is within `tol` (relative) of an integer.
bool isIntegerRatio(double coarseVoxel, double fineVoxel, double tol = 1e-3);

/// coarse/fine rounded to the nearest integer; throws ValueError when the ratio is below 1.
int nearestRatio(double coarseVoxel, double fineVoxel, double tol = 1e-3);

/// `f` sampled trilinearly onto the lattice of voxel size `voxelSize` that keeps voxel (0,0,0)'s centre
/// where f's is. The box holds every new voxel centre inside the hull of f's voxel centres, so no value
/// is extrapolated. Used to bring a source at a non-integer ratio to the nearest integer one.
template<typename T>
Field<T> resampledToVoxel(const Field<T>& f, double voxelSize);

/// Every field of `frame` resampled by resampledToVoxel; number, dt and metadata are kept.
Frame resampledToVoxel(const Frame& frame, double voxelSize);

} // namespace turb
