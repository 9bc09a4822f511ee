#include <turb/Budget.h>

namespace turb {

// Fitted on this machine (docs/reliability.md, "Memory estimates"): the Blender plume's 128^3 source against
// targets at ratios 2, 4 and 8 measured 766, 398 and 235 MB peak RSS: the source term goes as 1/ratio.
namespace {
// transferSecondsPerFrame's fit (bench/time_model.sh, 2026-12-07, 100 frames of four Blender pairs at ratios 2 and 4
// on the 2-core VM): totals within 0.91-1.24x, single frames within 2.25x.
constexpr double kTimeFixed = 0.0104;
constexpr double kTimePerOutputVoxel = 4.09e-7;
constexpr double kTimePerSourceVoxel = 6.89e-7;
} // namespace

double transferPeakBytes(double targetVoxels, int ratio, double sourceVoxels)
{
    const double f = double(ratio);
    // 200 MB fixed: refitted when cropped reads made the voxel terms small (box32: 278 MB measured).
    return 200e6 + 664.0 * sourceVoxels / f + 30.0 * targetVoxels * f * f * f;
}

// Per-frame times (--json seconds) against the frames' held boxes; see docs/performance.md, Time estimate.
double transferSecondsPerFrame(double targetVoxels, int ratio, double sourceVoxels)
{
    const double f = double(ratio);
    return kTimeFixed + kTimePerOutputVoxel * targetVoxels * f * f * f + kTimePerSourceVoxel * sourceVoxels;
}

// Fitted on plume 32^3, 2 frames, at factors 2 and 4 (95 and 408 MB measured; 112 and 545 MB estimated) and
// the bench's synth3d (64x64x16 at factor 4, 30 frames: 1741 MB measured, 1.8 GB estimated).
double synthPeakBytes(double coarseVoxels, int factor, int frames, int lookback)
{
    const double f = double(factor);
    const int history = lookback > 0 ? (frames < lookback ? frames : lookback) : 0;
    return 50e6 + (200.0 + 18.0 * history) * coarseVoxels * f * f * f;
}

int largestSynthFactor(double bytes, double coarseVoxels, int frames, int lookback)
{
    int best = 0;
    for (int f = 1; f <= 1024 && synthPeakBytes(coarseVoxels, f, frames, lookback) <= bytes; ++f) best = f;
    return best;
}

} // namespace turb
