/// @file ResidualTransfer.h
/// @brief Automatic transfer of the example's residuals onto the target (Okabe et al. 2009,
///        section 5.2): patches of the target's flow are matched to windows of the example's flow, and
///        the residuals under the matched windows are pasted in the Lapped Textures manner.
///
/// - **Matching.** Target patches of `patchSize` pixels lie on a grid of stride patchSize/2 covering the
///   image; every window of the example's flow is a candidate. The cost is |s - e|^2 over the two flow
///   channels of the patch (s: target, e: example). The search runs on PCA-reduced descriptors in a FLANN
///   k-d tree (PatchIndex.h), optionally on flows downsampled 2x or 4x (box means; patches shrink with
///   them, positions scale back up). Candidate windows are every pixel position at the search
///   resolution.
/// - **Variety** (beyond the paper). A nearly uniform design matches many example windows equally well, and
///   the nearest one is then often the same window for a whole region: its residuals tile the target with
///   the patch stride, a regular grid of repeated detail (the paper's "flat residuals", which it mends by
///   hand with the Clone Brush). So besides the 8 nearest windows, `candidates` windows drawn at random (seeded
///   by the patch: deterministic) are costed; those whose rms flow difference is within `variety` x the patch's
///   rms design speed of the best count as equally good, and,
///   patch by patch in grid order, the one farthest from the windows already chosen by the patches within
///   two strides is taken (the nearest on ties). variety 0 is the paper's nearest match.
/// - **Lapped pasting.** Patches are sorted by their cost (most similar first; ties by position) and
///   pasted in that order *under* what is already there: a patch's alpha mask is 1 in its core and ramps
///   linearly to 0 over `feather` of its size at edges that lie inside the image, and pixel x takes
///   weight m(x) (1 - coverage(x)) from it, coverage += that. Patches whose pixels are all covered are
///   skipped. The most similar patch therefore owns its core, and seams are blended across the ramps.
///   Weights are finally divided by the coverage, so they sum to 1 wherever anything was pasted.
/// - **The same matches for every frame**: the result is a TransferMap (per target pixel, up to 4
///   example pixels and weights) applied to each residual R_i, so the transferred residuals R'_i are
///   coherent in time.
/// - A target matte (optional) restricts the patches to those touching the fluid (matte > 0); pixels no
///   patch reaches get no residual.
///
/// @code
/// turb::ResidualTransferSettings s;                 // 16 px patches, search at 2x downsampling
/// turb::TransferMap map = turb::matchResiduals(exampleFlow, targetFlow, s, nullptr, &progress);
/// turb::ChannelImage r = map.apply(example.residuals[i]);   // R'_i on the target
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/Progress.h>

#include <cstdint>
#include <vector>

namespace turb {

struct ResidualTransferSettings
{
    int patchSize = 16;     ///< target patch edge in pixels (paper 8..32), 8..64
    int downsample = 2;     ///< search on flows reduced by 1, 2 or 4 (paper 2 or 4)
    int pcaComponents = 16; ///< PCA dimensions of the descriptors, >= 1
    double feather = 0.25;  ///< alpha ramp width as a fraction of the patch edge, [0, 0.5]
    int candidates = 32;    ///< random example windows costed per patch besides the 8 nearest (variety > 0), 1..64
    double variety = 0.1;   ///< "equally good" slack, fraction of the patch's rms design speed, [0, 1]; 0 = nearest
};

/// Throws ValueError naming the first setting out of range.
void validate(const ResidualTransferSettings& s);

struct ResidualTransferStats
{
    int patches = 0;       ///< target patches considered (touching the matte)
    int pasted = 0;        ///< patches that added weight somewhere
    double meanCost = 0.0; ///< mean |s - e|^2 per pixel (pixels^2 / frame^2) over pasted patches
    double maxCost = 0.0;  ///< the worst pasted patch's cost per pixel
    double covered = 0.0;  ///< fraction of target pixels that received residuals
    int distinct = 0;      ///< distinct example windows among the patches matched
    double cloned = 0.0;   ///< fraction of target pixels the Clone Brush (CloneBrush.h) gave weight
};

/// Which example pixels make each target pixel of the transferred residuals.
class TransferMap
{
public:
    static constexpr int kTaps = 4;

    TransferMap() = default;
    TransferMap(int targetWidth, int targetHeight, int exampleWidth, int exampleHeight);

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    int exampleWidth() const { return mExWidth; }
    int exampleHeight() const { return mExHeight; }

    /// Tap k of target pixel i: example pixel index (y * exampleWidth + x) and weight (0 = unused).
    std::uint32_t source(size_t i, int k) const { return mSource[i * kTaps + size_t(k)]; }
    float weight(size_t i, int k) const { return mWeight[i * kTaps + size_t(k)]; }
    /// Adds a tap; when all kTaps are in use, the lightest is replaced if `w` is heavier.
    void addTap(size_t i, std::uint32_t source, float w);
    /// Divides each pixel's weights by their sum (pixels without taps stay empty).
    void normalise();
    /// Removes every tap of target pixel i.
    void clearTaps(size_t i);

    /// R' = the map applied to an example-sized image (any channel count). Throws ValueError when the
    /// image is not the example's size.
    ChannelImage apply(const ChannelImage& exampleImage) const;

    ResidualTransferStats stats;

private:
    int mWidth = 0, mHeight = 0, mExWidth = 0, mExHeight = 0;
    std::vector<std::uint32_t> mSource;
    std::vector<float> mWeight;
};

/// Matches the target flow's patches to the example flow's windows and lays the patches out (see the
/// file comment). Both flows have 2 channels (pixels per frame); `targetMatte` (1 channel, target size)
/// may be null. Throws ValueError when a flow has the wrong shape, the example is smaller than a patch
/// at the search resolution, or settings are out of range; Cancelled when `progress` asks.
TransferMap matchResiduals(const ChannelImage& exampleFlow, const ChannelImage& targetFlow,
    const ResidualTransferSettings& settings, const ChannelImage* targetMatte = nullptr, Progress* progress = nullptr);

} // namespace turb
