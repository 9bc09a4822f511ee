// The PatchMatch sweep shared by the forward field (PatchMatch.cc) and the reversed, uniform one
// (UniformNnf.cc). Internal: not installed.
#pragma once

#include <turb/Parallel.h>
#include <turb/PatchMatch.h>
#include <turb/Progress.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <vector>

namespace turb::detail {

inline std::uint64_t mix64(std::uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

/// A small counter-based generator: the stream depends only on the key it was built from.
struct Rng
{
    std::uint64_t state;
    explicit Rng(std::uint64_t key) : state(mix64(key)) {}
    std::uint64_t next() { return state = mix64(state); }
    /// Uniform integer in [0, n), n > 0.
    std::uint32_t below(std::uint32_t n) { return std::uint32_t((next() >> 32) * n >> 32); }
};

inline std::uint64_t key(std::uint64_t a, std::uint64_t b, std::uint64_t c, std::uint64_t d)
{
    return mix64(mix64(mix64(a ^ 0x51ed2701ull) ^ b) ^ (c * 0x2545F4914F6CDD1Dull)) ^ d;
}

/// The deterministic sweep skeleton shared by every PatchMatch here (2D, reversed, and the generalized
/// (i, x, y, theta) one of Fluidymation): `iterations` sweeps over a width x height grid of queries, in
/// fixed square tiles run in parallel. Sweep `first + it` visits each tile in scan order when even and in
/// reverse order when odd; `visit(q, x, y, sweep, step, neighbour)` updates match[q], where `step` (-1 or
/// +1) points to the neighbours already visited in this sweep and `neighbour(nx, ny)` returns their match:
/// from this sweep inside the tile, from the previous sweep's snapshot across tiles, so no result depends
/// on which thread ran which tile.
template<typename Match, typename Visit>
void tiledSweeps(int width, int height, int tileSize, int first, int iterations, std::vector<Match>& match,
    Progress* progress, const Visit& visit)
{
    const int T = std::max(8, tileSize);
    const int tilesX = (width + T - 1) / T, tilesY = (height + T - 1) / T;
    std::vector<Match> previous;
    for (int it = first; it < first + iterations; ++it) {
        checkCancelled(progress);
        previous = match; // neighbours in other tiles are read from here
        const bool forward = it % 2 == 0;
        const int step = forward ? -1 : 1; // the neighbours already visited lie this way
        parallelFor(size_t(tilesX) * size_t(tilesY), 1, [&](size_t t0, size_t t1) {
            for (size_t t = t0; t < t1; ++t) {
                const int x0 = int(t % size_t(tilesX)) * T, y0 = int(t / size_t(tilesX)) * T;
                const int x1 = std::min(width, x0 + T), y1 = std::min(height, y0 + T);
                const auto neighbour = [&](int nx, int ny) -> const Match& {
                    const size_t n = size_t(ny) * size_t(width) + size_t(nx);
                    return nx >= x0 && nx < x1 && ny >= y0 && ny < y1 ? match[n] : previous[n];
                };
                for (int yy = 0; yy < y1 - y0; ++yy) {
                    const int y = forward ? y0 + yy : y1 - 1 - yy;
                    for (int xx = 0; xx < x1 - x0; ++xx) {
                        const int x = forward ? x0 + xx : x1 - 1 - xx;
                        visit(size_t(y) * size_t(width) + size_t(x), x, y, it, step, neighbour);
                    }
                }
            }
        });
        if (progress) progress->update(double(it - first + 1) / iterations);
    }
}

/// Geometry and knobs of one search: queries live on a qW x qH grid, candidates on a dW x dH grid.
struct SearchConfig
{
    int qW = 0, qH = 0, dW = 0, dH = 0;
    int iterations = 4, tileSize = 64, randomCentres = 2;
    std::uint64_t seed = 1, salt = 0; // salt separates the streams of different calls (rounds, EM iterations)
};

/// For every active query q (label L = qLabels[q] >= 0) improves match[q] among candidates d with
/// ok(d, L), minimising dist(q, d, cutoff). `lists[L]` holds candidates for random draws (they must
/// satisfy ok). Queries whose label has no candidate get -1.
template<typename Ok, typename Dist>
void sweepSearch(const SearchConfig& cfg, const std::vector<char>& active, const Labels& qLabels,
    const std::vector<std::vector<std::int32_t>>& lists, const Ok& ok, const Dist& dist,
    std::vector<std::int32_t>& match, std::vector<float>& best, Progress* progress)
{
    const float inf = std::numeric_limits<float>::infinity();
    const size_t qN = size_t(cfg.qW) * size_t(cfg.qH);
    const auto listOf = [&](int L) -> const std::vector<std::int32_t>* {
        return L >= 0 && size_t(L) < lists.size() && !lists[size_t(L)].empty() ? &lists[size_t(L)] : nullptr;
    };
    parallelFor(qN, 4096, [&](size_t b, size_t e) {
        for (size_t q = b; q < e; ++q) {
            if (!active[q]) continue;
            const int L = qLabels[q];
            if (match[q] >= 0 && ok(match[q], L)) {
                best[q] = dist(std::int32_t(q), match[q], inf);
                continue;
            }
            const auto* list = listOf(L);
            if (!list) {
                match[q] = -1;
                best[q] = inf;
                continue;
            }
            Rng rng(key(cfg.seed, cfg.salt, q, 0x1717));
            match[q] = (*list)[rng.below(std::uint32_t(list->size()))];
            best[q] = dist(std::int32_t(q), match[q], inf);
        }
    });

    tiledSweeps(cfg.qW, cfg.qH, cfg.tileSize, 0, cfg.iterations, match, progress,
        [&](size_t q, int x, int y, int it, int step, const auto& neighbour) {
            if (!active[q] || match[q] < 0) return;
            const int L = qLabels[q];
            std::int32_t m = match[q];
            float b = best[q];
            const auto tryCandidate = [&](std::int32_t c) {
                if (c < 0 || c == m || !ok(c, L)) return;
                const float d = dist(std::int32_t(q), c, b);
                if (d < b || (d == b && c < m)) {
                    b = d;
                    m = c;
                }
            };
            // Propagation: a neighbour's match, shifted back by the offset to the neighbour.
            for (int axis = 0; axis < 2; ++axis) {
                const int nx = x + (axis == 0 ? step : 0), ny = y + (axis == 1 ? step : 0);
                if (nx < 0 || ny < 0 || nx >= cfg.qW || ny >= cfg.qH) continue;
                const size_t n = size_t(ny) * size_t(cfg.qW) + size_t(nx);
                if (!active[n]) continue;
                const std::int32_t nm = neighbour(nx, ny);
                if (nm < 0) continue;
                const int cx = nm % cfg.dW - (nx - x), cy = nm / cfg.dW - (ny - y);
                if (cx >= 0 && cy >= 0 && cx < cfg.dW && cy < cfg.dH) tryCandidate(cy * cfg.dW + cx);
            }
            // Random search in windows halving around the best so far.
            Rng rng(key(cfg.seed, cfg.salt, q, std::uint64_t(it) + 1));
            for (int w = std::max(cfg.dW, cfg.dH); w >= 1; w /= 2) {
                const int mx = m % cfg.dW, my = m / cfg.dW;
                const int cx = std::min(cfg.dW - 1, std::max(0, mx - w + int(rng.below(std::uint32_t(2 * w + 1)))));
                const int cy = std::min(cfg.dH - 1, std::max(0, my - w + int(rng.below(std::uint32_t(2 * w + 1)))));
                tryCandidate(cy * cfg.dW + cx);
            }
            if (const auto* list = listOf(L))
                for (int k = 0; k < cfg.randomCentres; ++k)
                    tryCandidate((*list)[rng.below(std::uint32_t(list->size()))]);
            match[q] = m;
            best[q] = b;
        });
}

} // namespace turb::detail
