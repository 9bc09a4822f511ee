#include <turb/Budget.h>

namespace turb {

// Fitted on this machine (docs/reliability.md): plume 128^3 source, target 64^3 / 32^3 / 16^3 (ratios 2, 4, 8)
// measured 766 / 398 / 235 MB peak RSS; the formula gives 842 / 488 / 311 MB.
double transferPeakBytes(double targetVoxels, int ratio, double sourceVoxels)
{
    return 50e6 + 40.0 * sourceVoxels + 675.0 * targetVoxels * double(ratio) * double(ratio);
}

int largestTransferRatio(double bytes, double targetVoxels, double sourceVoxels)
{
    int best = 0;
    for (int f = 2; f <= 1024 && transferPeakBytes(targetVoxels, f, sourceVoxels) <= bytes; ++f) best = f;
    return best;
}

// Fitted on plume 32^3, 2 frames, at factors 2 and 4 (95 and 408 MB measured; 127 and 611 MB estimated) and
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
