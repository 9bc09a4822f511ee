#include <turb/Parallel.h>
#include <turb/Progress.h>
#include <turb/Error.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <vector>

namespace turb {

void checkCancelled(const Progress* p)
{
    if (p && p->cancelled()) throw Cancelled();
}

void withThreads(int threads, const std::function<void()>& fn)
{
    if (threads <= 0) {
        fn();
        return;
    }
    tbb::task_arena arena(threads);
    arena.execute(fn);
}

void parallelFor(size_t n, size_t grain, const std::function<void(size_t, size_t)>& body)
{
    if (n == 0) return;
    if (grain == 0) grain = 1;
    const size_t chunks = (n + grain - 1) / grain;
    // simple_partitioner over whole chunks: the split points depend only on n and grain.
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, chunks, 1),
        [&](const tbb::blocked_range<size_t>& r) {
            for (size_t c = r.begin(); c != r.end(); ++c) {
                const size_t b = c * grain;
                body(b, std::min(n, b + grain));
            }
        },
        tbb::simple_partitioner());
}

double parallelSum(size_t n, size_t grain, const std::function<double(size_t, size_t)>& chunkSum)
{
    if (n == 0) return 0.0;
    if (grain == 0) grain = 1;
    const size_t chunks = (n + grain - 1) / grain;
    std::vector<double> partial(chunks, 0.0);
    parallelFor(chunks, 1, [&](size_t c0, size_t c1) {
        for (size_t c = c0; c < c1; ++c) {
            const size_t b = c * grain;
            partial[c] = chunkSum(b, std::min(n, b + grain));
        }
    });
    double s = 0.0;
    for (double p : partial) s += p;
    return s;
}

} // namespace turb
