// Reversed NNF retrieval with uniform patch usage (LazyFluids section 4.1 and 4.2).
#include <turb/UniformNnf.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include "Search.h"

#include <algorithm>
#include <limits>
#include <string>

namespace turb {

namespace {

struct Claim
{
    float distance;
    std::int32_t source, target;
    bool operator<(const Claim& o) const
    {
        if (distance != o.distance) return distance < o.distance;
        if (source != o.source) return source < o.source;
        return target < o.target;
    }
};

/// Per-segment bookkeeping of eq. 5.
struct Budget
{
    long long K = 0, R = 0;
};

int maxLabel(const Labels& a, const Labels& b)
{
    int m = -1;
    for (auto v : a) m = std::max(m, int(v));
    for (auto v : b) m = std::max(m, int(v));
    return m;
}

// Eq. 5 per segment L: each of its |S_L| source patches serves K = |T_L| / |S_L| targets, R = |T_L| mod |S_L| of
// them one more. A segment with targets but no source patch cannot be served.
std::vector<Budget> segmentBudgets(const Labels& sourceLabels, const Labels& targetLabels)
{
    const int nl = maxLabel(sourceLabels, targetLabels) + 1;
    std::vector<long long> nS(size_t(std::max(0, nl)), 0), nT(nS.size(), 0);
    for (auto v : sourceLabels)
        if (v >= 0) ++nS[size_t(v)];
    for (auto v : targetLabels)
        if (v >= 0) ++nT[size_t(v)];
    std::vector<Budget> budget(nS.size());
    for (size_t L = 0; L < nS.size(); ++L) {
        if (nT[L] > 0 && nS[L] == 0)
            throw ValueError("uniform NNF: segment " + std::to_string(L) + " has " + std::to_string(nT[L]) +
                             " target patches but no source patch");
        if (nS[L] > 0) budget[L] = Budget{nT[L] / nS[L], nT[L] % nS[L]};
    }
    return budget;
}

// A sweep's collisions resolved: each target keeps its closest claim (ties: the lower source index), sorted by
// distance, so the closest are assigned first.
std::vector<Claim> winningClaims(const std::vector<char>& active, const std::vector<std::int32_t>& claim,
    const std::vector<float>& claimDist, size_t targetPixels)
{
    std::vector<std::int32_t> winner(targetPixels, -1);
    for (size_t p = 0; p < active.size(); ++p) {
        if (!active[p] || claim[p] < 0) continue;
        std::int32_t& w = winner[size_t(claim[p])];
        if (w < 0 || claimDist[p] < claimDist[size_t(w)] ||
            (claimDist[p] == claimDist[size_t(w)] && std::int32_t(p) < w))
            w = std::int32_t(p);
    }
    std::vector<Claim> claims;
    for (size_t q = 0; q < winner.size(); ++q)
        if (winner[q] >= 0) claims.push_back(Claim{claimDist[size_t(winner[q])], winner[q], std::int32_t(q)});
    std::sort(claims.begin(), claims.end());
    return claims;
}

/// The state of one uniformNnf call: eq. 5's budgets (R counts down as patches take their K + 1-th target), the
/// NNF built so far and how many targets are left.
struct Assignment
{
    const Labels& sourceLabels;
    std::vector<Budget> budget;
    UniformNnf out;
    std::vector<std::int32_t> assigned; // target -> source, -1 = unassigned
    long long unassigned = 0;

    /// Source patch p may serve another target: fewer than K so far, or K with one of the R extra uses left.
    bool usable(size_t p) const
    {
        const int L = sourceLabels[p];
        if (L < 0) return false;
        const Budget& b = budget[size_t(L)];
        return out.counts[p] < b.K || (out.counts[p] == b.K && b.R > 0);
    }

    /// Takes a claim unless its target is taken or its source's budget is spent.
    bool assign(const Claim& c)
    {
        const int L = sourceLabels[size_t(c.source)];
        Budget& b = budget[size_t(L)];
        if (assigned[size_t(c.target)] >= 0) return false;
        const long long n = out.counts[size_t(c.source)];
        if (n == b.K && b.R > 0) --b.R; // one of the R patches used K + 1 times
        else if (n >= b.K) return false;
        ++out.counts[size_t(c.source)];
        assigned[size_t(c.target)] = c.source;
        out.nnf.source[size_t(c.target)] = c.source;
        out.nnf.distance[size_t(c.target)] = c.distance;
        --unassigned;
        return true;
    }
};

// The tail: compare every remaining pair and assign greedily by distance. Capacity left equals the targets left
// (eq. 5), so this round assigns them all.
void assignExhaustively(Assignment& a, const PatchSpace& space, const std::vector<char>& active,
    const std::vector<std::vector<std::int32_t>>& lists, Progress* progress)
{
    std::vector<Claim> claims;
    for (size_t p = 0; p < active.size(); ++p) {
        if (!active[p]) continue;
        checkCancelled(progress);
        for (std::int32_t q : lists[size_t(a.sourceLabels[p])])
            claims.push_back(
                Claim{space.distance(std::int32_t(p), q, std::numeric_limits<float>::infinity()), std::int32_t(p), q});
    }
    std::sort(claims.begin(), claims.end());
    for (const Claim& c : claims) a.assign(c);
    ++a.out.exhaustiveRounds;
    ++a.out.rounds;
    if (a.unassigned > 0) throw Error("uniform NNF: exhaustive round left targets unassigned (internal error)");
}

detail::SearchConfig sweepConfig(const ChannelImage& S, const ChannelImage& T, const UniformNnfSettings& settings)
{
    detail::SearchConfig cfg;
    cfg.qW = S.width();
    cfg.qH = S.height();
    cfg.dW = T.width();
    cfg.dH = T.height();
    cfg.iterations = settings.sweepsPerRound;
    cfg.tileSize = settings.tileSize;
    cfg.seed = settings.seed;
    return cfg;
}

} // namespace

std::vector<SegmentUsage> patchUsage(
    const Nnf& nnf, const Labels& sourceLabels, const Labels& targetLabels, std::vector<std::int32_t>* countsOut)
{
    std::vector<std::int32_t> counts(sourceLabels.size(), 0);
    for (size_t q = 0; q < nnf.source.size(); ++q)
        if (targetLabels[q] >= 0 && nnf.source[q] >= 0) ++counts[size_t(nnf.source[q])];
    const int nl = maxLabel(sourceLabels, targetLabels) + 1;
    std::vector<SegmentUsage> usage;
    for (int L = 0; L < nl; ++L) {
        SegmentUsage u;
        u.label = L;
        for (auto v : targetLabels) u.targets += v == L;
        if (u.targets == 0) continue;
        long long used = 0;
        u.minCount = std::numeric_limits<long long>::max();
        for (size_t p = 0; p < sourceLabels.size(); ++p) {
            if (sourceLabels[p] != L) continue;
            ++u.sources;
            u.minCount = std::min<long long>(u.minCount, counts[p]);
            u.maxCount = std::max<long long>(u.maxCount, counts[p]);
            used += counts[p] > 0;
        }
        if (u.sources == 0) u.minCount = 0;
        u.K = u.sources ? u.targets / u.sources : 0;
        u.R = u.sources ? u.targets % u.sources : 0;
        for (size_t p = 0; p < sourceLabels.size(); ++p)
            u.countsAtKPlusOne += sourceLabels[p] == L && counts[p] == u.K + 1;
        u.coverage = u.sources ? double(used) / double(u.sources) : 0.0;
        usage.push_back(u);
    }
    if (countsOut) *countsOut = std::move(counts);
    return usage;
}

UniformNnf uniformNnf(const PatchSpace& space, const Labels& sourceLabels, const Labels& targetLabels,
    const UniformNnfSettings& settings, Progress* progress)
{
    validatePatchSpace(space);
    const ChannelImage& S = *space.source;
    const ChannelImage& T = *space.target;
    if (sourceLabels.size() != S.pixelCount() || targetLabels.size() != T.pixelCount())
        throw ValueError("uniform NNF: labels must have one entry per pixel");
    if (settings.sweepsPerRound < 1 || settings.randomTargets < 0 || !(settings.exhaustiveBudget >= 0.0))
        throw ValueError("uniform NNF: sweepsPerRound must be >= 1, randomTargets and exhaustiveBudget >= 0");

    Assignment a{sourceLabels, segmentBudgets(sourceLabels, targetLabels), {}, {}, 0};
    a.out.nnf = emptyNnf(T.width(), T.height());
    a.out.counts.assign(S.pixelCount(), 0);
    a.assigned.assign(T.pixelCount(), -1);
    std::vector<std::int32_t> claim(S.pixelCount(), -1); // source -> claimed target
    std::vector<float> claimDist(S.pixelCount(), std::numeric_limits<float>::infinity());
    for (auto v : targetLabels) a.unassigned += v >= 0;

    detail::SearchConfig cfg = sweepConfig(S, T, settings);
    const auto ok = [&](std::int32_t q, int L) { return targetLabels[size_t(q)] == L && a.assigned[size_t(q)] < 0; };
    const auto dist = [&](std::int32_t p, std::int32_t q, float cutoff) { return space.distance(p, q, cutoff); };

    const long long total = a.unassigned;
    int randomTargets = settings.randomTargets;
    std::vector<char> active(S.pixelCount());
    std::vector<std::vector<std::int32_t>> lists;
    while (a.unassigned > 0) {
        checkCancelled(progress);
        lists.assign(a.budget.size(), {});
        for (size_t q = 0; q < T.pixelCount(); ++q)
            if (targetLabels[q] >= 0 && a.assigned[q] < 0) lists[size_t(targetLabels[q])].push_back(std::int32_t(q));
        long long nUsable = 0;
        for (size_t p = 0; p < active.size(); ++p) nUsable += (active[p] = a.usable(p));

        if (double(a.unassigned) * double(nUsable) <= settings.exhaustiveBudget) {
            assignExhaustively(a, space, active, lists, progress);
            break;
        }

        cfg.salt = std::uint64_t(a.out.rounds);
        cfg.randomCentres = randomTargets;
        detail::sweepSearch(cfg, active, sourceLabels, lists, ok, dist, claim, claimDist, nullptr);

        const std::vector<Claim> claims = winningClaims(active, claim, claimDist, T.pixelCount());
        const long long before = a.unassigned;
        for (const Claim& c : claims) a.assign(c);
        ++a.out.rounds;
        // Few new assignments (many sources crowding few targets): widen the random draws.
        if (before - a.unassigned < std::max<long long>(1, before / 50))
            randomTargets = std::min(64, std::max(1, randomTargets * 2));
        if (progress) progress->update(double(total - a.unassigned) / double(std::max<long long>(1, total)));
    }
    a.out.usage = patchUsage(a.out.nnf, sourceLabels, targetLabels);
    return std::move(a.out);
}

} // namespace turb
