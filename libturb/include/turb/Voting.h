/// @file Voting.h
/// @brief The M-step of patch-based synthesis (Kwatra et al. 2005; Wexler et al. 2007): every target
///        pixel becomes the mean of what the overlapping matched source patches put there.
///
/// For target pixel q, each centre q' with q inside its patch and a match p' = NNF(q') votes the source
/// pixel p' + (q - q'). Gathering (each pixel reads its own votes) makes the result independent of the
/// thread count. Pixels with no vote get `empty`.
///
/// @code
/// turb::vote(exemplar, nnf, 2, 0, 4, target, turb::VoteSettings{});  // RGBA channels 0..3
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/PatchMatch.h>

namespace turb {

struct VoteSettings
{
    float empty = 0.0f; ///< value of pixels no patch covers
};

/// Writes channels [firstTarget, firstTarget + count) of `target` from channels [firstSource, ...) of
/// `source`, by uniform-weight voting through `nnf` (target-sized, patch half-size `radius`). Returns
/// the number of votes per target pixel (0 = uncovered). Throws ValueError on size or channel mismatch.
std::vector<int> vote(const ChannelImage& source, const Nnf& nnf, int radius, int firstSource, int firstTarget, int count,
    ChannelImage& target, const VoteSettings& settings = {});

} // namespace turb
