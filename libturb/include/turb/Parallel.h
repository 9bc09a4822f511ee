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

} // namespace turb
