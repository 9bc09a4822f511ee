/// @file Budget.h
/// @brief Peak memory and output size of a `transfer` or `synth` run, estimated from the lattices alone, for
///        dry runs and the checks before a run's first frame (a 25x ratio must be refused, not die in
///        std::bad_alloc an hour later).
///
/// The constants are fitted to peak RSS measured on this project's caches (docs/reliability.md, "Memory
/// estimates"); they err on the high side by up to about 1.3x. They do not depend on thread count.
///
/// @code
/// double need = turb::transferPeakBytes(32 * 32 * 32, 4, 128 * 128 * 128); // about 0.61 GB
/// @endcode
#pragma once

namespace turb {

/// Peak bytes of `transfer` at resolution ratio `ratio` (>= 1) over a target domain of `targetVoxels` voxels, with
/// a source of `sourceVoxels` voxels as matched (after resampling to the ratio, when it was not an integer):
/// 200 MB + 664 B x sourceVoxels / ratio + 30 B x targetVoxels x ratio^3 (voxels of the held boxes: the smoke and its
/// margin). The source term (patch descriptors and search structures) dominates on this project's caches; the last is
/// the output's dense fields.
double transferPeakBytes(double targetVoxels, int ratio, double sourceVoxels);

/// Seconds per frame of `transfer` on two cores, for the same held boxes as transferPeakBytes: a linear model
/// c0 + c1 x output voxels (targetVoxels x ratio^3) + c2 x sourceVoxels, fitted to per-frame times of Blender and
/// built-in pairs at ratios 2-8 (docs/performance.md, "Time estimate", states the fit's error). A guide for plans
/// and farm requests, not a promise: the smoke's share of the box and the machine move it.
double transferSecondsPerFrame(double targetVoxels, int ratio, double sourceVoxels);

/// Peak bytes of `synth` over a coarse domain of `coarseVoxels` at up-sampling `factor`, for a run of `frames`
/// frames with look-back density over `lookback` frames (0 = none): 50 MB + (200 B + 18 B x min(frames,
/// lookback)) per output voxel (coarseVoxels x factor^3); the look-back keeps that many velocity frames.
double synthPeakBytes(double coarseVoxels, int factor, int frames, int lookback);

/// The largest factor >= 1 whose synthPeakBytes fits in `bytes`; 0 when none does.
int largestSynthFactor(double bytes, double coarseVoxels, int frames, int lookback);

} // namespace turb
