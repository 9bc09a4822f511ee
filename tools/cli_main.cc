// The vdbturb executable: the command line runs in runCommandLine (main.cc), which the Python module calls too.
#include "CommandLine.h"

#include <malloc.h>

int main(int argc, char** argv)
{
    // Image stages allocate and free many frame-sized buffers (a few MB each). Keep them in the heap
    // instead of mapping fresh pages for each one: measured 0.70 -> 0.52 CPU-s per 640x480 frame of
    // animate's histogram matching (docs/performance.md).
    mallopt(M_MMAP_THRESHOLD, 64 << 20);
    mallopt(M_TRIM_THRESHOLD, 256 << 20);
    return vdbturb::runCommandLine(std::vector<std::string>(argv + 1, argv + argc));
}
