/// @file Parallel.h
/// @brief The one place where stages get their threads.
///
/// Every stage runs its loops inside `withThreads(n, ...)`, an isolated TBB arena of n threads.
/// Loops split work into chunks whose boundaries do not depend on the thread count, and any reduction
/// combines chunk results in a fixed order, so results are bit-identical at any thread count.
#pragma once

#include <cstddef>
#include <functional>

namespace turb {

/// Runs `fn` with at most `threads` worker threads (0 = all hardware threads).
void withThreads(int threads, const std::function<void()>& fn);

/// Calls body(begin, end) over [0, n) in chunks of `grain`, in parallel. Chunk boundaries depend only
/// on n and grain.
void parallelFor(size_t n, size_t grain, const std::function<void(size_t, size_t)>& body);

/// Deterministic parallel sum of f(i) over [0, n): chunk partial sums are added in index order.
double parallelSum(size_t n, size_t grain, const std::function<double(size_t, size_t)>& chunkSum);

/// Runs body(i, j, k) over every voxel of `box` (an openvdb CoordBBox), in parallel over x slabs: each
/// voxel is visited by one thread, so bodies that write only their own voxel are deterministic.
template<typename Box, typename Fn>
void forEachVoxel(const Box& box, Fn&& body)
{
    if (box.empty()) return;
    parallelFor(size_t(box.dim().x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int i = box.min().x() + int(x);
            for (int j = box.min().y(); j <= box.max().y(); ++j)
                for (int k = box.min().z(); k <= box.max().z(); ++k) body(i, j, k);
        }
    });
}

} // namespace turb
