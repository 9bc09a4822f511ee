/// @file PatchMatch.h
/// @brief Nearest-neighbour fields between the patches of two images: the shared patch space
///        (weighted multi-channel distance, segment labels) and masked PatchMatch (Barnes et al. 2009)
///        run in parallel over tiles (Barnes et al. 2010), deterministic for a seed at any thread count.
///
/// A patch is the (2r+1)^2 square centred on a pixel. Every pixel carries a segment label: patches
/// match only between centres of equal label, and a label < 0 means "no patch here" (outside the mask,
/// or too close to the border for a whole patch). The distance between source centre p and target
/// centre q is
///     D(p, q) = sum over offsets o, channels c of  W_c(q + o) * (S_c(p + o) - T_c(q + o))^2,
/// with per-target-pixel channel weights W (the guide weights of LazyFluids eq. 9, where the temporal
/// weight lambda_q varies per pixel).
///
/// Determinism: tiles have a fixed size; inside a tile pixels are visited in scan order, and a
/// neighbour in another tile is read from the previous sweep's field, so no result depends on which
/// thread ran which tile. Random numbers are hashed from (seed, sweep, pixel).
///
/// @code
/// turb::PatchSpace space{&source, &target, &weights, 2};
/// turb::Nnf nnf = turb::emptyNnf(target.width(), target.height());
/// turb::patchMatch(space, sourceLabels, targetLabels, turb::PatchMatchSettings{}, nnf);
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/Progress.h>

#include <cstdint>
#include <vector>

namespace turb {

/// Segment label per pixel (row-major, as ChannelImage): >= 0 a patch centre of that segment, < 0 none.
using Labels = std::vector<std::int8_t>;

/// The two images whose patches are compared, and how.
struct PatchSpace
{
    const ChannelImage* source = nullptr;  ///< S: C channels
    const ChannelImage* target = nullptr;  ///< T: C channels, any size
    const ChannelImage* weights = nullptr; ///< W: target-sized, C channels, >= 0 (per-pixel channel weights)
    int radius = 2;                        ///< patch half-size r: patches are (2r+1)^2, r >= 1

    /// D(p, q) for source pixel index p and target pixel index q (both must be whole-patch centres).
    /// Stops early and returns a value > cutoff once the sum exceeds `cutoff`.
    float distance(std::int32_t p, std::int32_t q, float cutoff) const
    {
        const int C = source->channels(), sW = source->width(), tW = target->width();
        const int px = p % sW, py = p / sW, qx = q % tW, qy = q / tW;
        const int n = (2 * radius + 1) * C;
        float acc = 0.0f;
        for (int dy = -radius; dy <= radius; ++dy) {
            const float* s = source->pixel(px - radius, py + dy);
            const float* t = target->pixel(qx - radius, qy + dy);
            const float* w = weights->pixel(qx - radius, qy + dy);
            // Four partial sums let the compiler vectorise without reassociating one long sum.
            float a[4] = {0.0f, 0.0f, 0.0f, 0.0f};
            int i = 0;
            for (; i + 4 <= n; i += 4)
                for (int k = 0; k < 4; ++k) {
                    const float d = s[i + k] - t[i + k];
                    a[k] += w[i + k] * d * d;
                }
            for (; i < n; ++i) {
                const float d = s[i] - t[i];
                a[0] += w[i] * d * d;
            }
            acc += (a[0] + a[1]) + (a[2] + a[3]);
            if (acc > cutoff) return acc;
        }
        return acc;
    }
};

/// Throws ValueError unless the images are set, non-empty, with equal channel counts and weights of
/// the target's size and channels.
void validatePatchSpace(const PatchSpace& space);

/// The labels of an image's whole-patch centres: `segment` (row-major, < 0 = none) with every pixel
/// closer than `radius` to the border set to -1.
Labels centreLabels(const std::vector<std::int8_t>& segment, int width, int height, int radius);

/// Nearest-neighbour field over the target: for each target pixel the matched source pixel index
/// (y * sourceWidth + x), or -1, and the distance.
struct Nnf
{
    int width = 0, height = 0;
    std::vector<std::int32_t> source;
    std::vector<float> distance;
};

/// A field of the given size with no matches.
Nnf emptyNnf(int width, int height);

struct PatchMatchSettings
{
    int iterations = 4; ///< sweeps of propagation + random search, >= 1
    int tileSize = 64;  ///< tile edge in pixels for the parallel sweeps (fixed: results do not depend on threads), >= 8
    int randomCentres = 2;  ///< extra candidates per pixel and sweep drawn uniformly from the segment's centres, >= 0
    std::uint64_t seed = 1; ///< same seed, same field
};

/// Masked PatchMatch, target -> source: every target centre (label >= 0) gets the source centre of its
/// label with the smallest D found. Entries of `nnf` that already hold a valid match of the right label
/// are the starting guess; others start at random. A target label with no source centre stays -1.
/// Throws ValueError on an invalid space or label sizes; Cancelled when `progress` asks.
void patchMatch(const PatchSpace& space, const Labels& sourceLabels, const Labels& targetLabels,
    const PatchMatchSettings& settings, Nnf& nnf, Progress* progress = nullptr);

/// The exact nearest neighbours by exhaustive search (tests and small images only: O(|S| |T| r^2 C)).
Nnf bruteForceNnf(const PatchSpace& space, const Labels& sourceLabels, const Labels& targetLabels);

} // namespace turb
