/// @file Voting.h
/// @brief The M-step of patch-based synthesis (Kwatra et al. 2005; Wexler et al. 2007): every target
///        pixel becomes the mean of what the overlapping matched source patches put there.
///
/// For target pixel q, each centre q' with q inside its patch and a match p' = NNF(q') votes the source
/// pixel p' + (q - q'). Gathering (each pixel reads its own votes) makes the result independent of the
/// thread count. Pixels with no vote get `empty`.
///
/// `voteRotated` is the same for the (i, x, y, theta) fields of Fluidymation (RotatedNnf.h).
///
/// @code
/// turb::vote(exemplar, nnf, 2, 0, 4, target, turb::VoteSettings{});  // RGBA channels 0..3
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/PatchMatch.h>
#include <turb/RotatedNnf.h>

namespace turb {

struct VoteSettings
{
    float empty = 0.0f;         ///< value of pixels no patch covers
    float distanceScale = 0.0f; ///< > 0: weight votes by exp(-distance / distanceScale) (Wexler 2007); 0: uniform
};

/// Writes channels [firstTarget, firstTarget + count) of `target` from channels [firstSource, ...) of
/// `source`, by uniform-weight voting through `nnf` (target-sized, patch half-size `radius`). Returns
/// the number of votes per target pixel (0 = uncovered). Throws ValueError on size or channel mismatch.
std::vector<int> vote(const ChannelImage& source, const Nnf& nnf, int radius, int firstSource, int firstTarget,
    int count, ChannelImage& target, const VoteSettings& settings = {});

/// Voting of rotated patches from a video (Fluidymation): target pixel q gathers, from every
/// centre q' = q - d with a match (i, x, y, theta), the source frame i sampled bilinearly at
/// (x, y) + R_{-theta} d (RotatedNnf.h), and takes the mean. `frames[i]` is source frame i; channels
/// [firstSource, firstSource + count) go to [firstTarget, ...) of `target`. Returns the votes per target
/// pixel. Throws ValueError on size or channel mismatch or a match naming a missing frame.
std::vector<int> voteRotated(const std::vector<const ChannelImage*>& frames, const RotatedNnf& nnf, int radius,
    int firstSource, int firstTarget, int count, ChannelImage& target, const VoteSettings& settings = {});

} // namespace turb
