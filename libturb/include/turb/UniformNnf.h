/// @file UniformNnf.h
/// @brief The reversed nearest-neighbour field with uniform patch usage (LazyFluids,
///        section 4.1, after Rosenberger et al. 2009): the core of `vdbturb stylize`.
///
/// Per segment L with |X_L| target and |Z_L| source centres, K = floor(|X_L| / |Z_L|) and
/// R = |X_L| mod |Z_L|. Every source patch p keeps a counter c_p. Rounds repeat until every target
/// centre is assigned:
/// 1. every usable source patch (c_p < K, or c_p = K while R > 0) searches for its nearest
///    *unassigned* target patch of its segment (PatchMatch in the reverse direction, source -> target);
/// 2. when several claim one target, the smallest distance keeps it;
/// 3. the surviving claims, sorted by increasing distance, are assigned greedily: c_p < K assigns and
///    increments c_p; c_p = K with R > 0 assigns, increments c_p and decrements R.
/// So every count ends at K or K + 1, exactly R counts at K + 1 (eq. 5), and no match crosses segments.
/// When few pairs remain (unassigned targets x usable sources <= exhaustiveBudget) the last round
/// compares all of them exactly and assigns greedily by distance, which ends the rounds.
///
/// @code
/// turb::UniformNnfSettings us;                  // 2 PatchMatch sweeps per round
/// turb::UniformNnf u = turb::uniformNnf(space, sourceLabels, targetLabels, us);
/// // u.nnf.source[q]: the exemplar patch used at target centre q; u.counts[p]: uses of exemplar patch p
/// @endcode
#pragma once

#include <turb/PatchMatch.h>

#include <cstdint>
#include <vector>

namespace turb {

struct UniformNnfSettings
{
    int sweepsPerRound = 2;          ///< PatchMatch sweeps of the reverse search in each round, >= 1
    int tileSize = 64;               ///< tile edge of the parallel sweeps, >= 8
    int randomTargets = 4;           ///< candidates per source and sweep drawn from the unassigned targets, >= 0
    double exhaustiveBudget = 2.0e5; ///< pair count at or below which a round is solved exactly, >= 0
    std::uint64_t seed = 1;          ///< same seed, same field
};

/// Usage of one segment's source patches after the assignment.
struct SegmentUsage
{
    int label = 0;
    long long sources = 0, targets = 0; ///< |Z_L| and |X_L| (whole-patch centres)
    long long K = 0, R = 0;             ///< quotient and remainder of eq. 5
    long long minCount = 0, maxCount = 0;
    long long countsAtKPlusOne = 0; ///< how many counts are K + 1 (== R when the constraint holds)
    double coverage = 0.0;          ///< fraction of source patches used at least once
};

struct UniformNnf
{
    Nnf nnf;                          ///< target centre -> source centre
    std::vector<std::int32_t> counts; ///< per source pixel: uses (0 where not a centre)
    int rounds = 0;                   ///< retrieval rounds until every target was assigned
    int exhaustiveRounds = 0;         ///< of which solved by exhaustive comparison
    std::vector<SegmentUsage> usage;  ///< one per segment label that has target centres
};

/// Runs the reversed retrieval. Throws ValueError on an invalid space, or when a segment has target
/// centres but no source centre (the exemplar lacks that segment); Cancelled when `progress` asks.
UniformNnf uniformNnf(const PatchSpace& space, const Labels& sourceLabels, const Labels& targetLabels,
    const UniformNnfSettings& settings = {}, Progress* progress = nullptr);

/// Per-segment usage of any field (also the standard, non-uniform one): counts, K, R, coverage.
std::vector<SegmentUsage> patchUsage(const Nnf& nnf, const Labels& sourceLabels, const Labels& targetLabels,
    std::vector<std::int32_t>* counts = nullptr);

} // namespace turb
