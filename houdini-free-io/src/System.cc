#include <turbio/System.h>

#include <cstdio>
#include <fstream>

#include <sys/resource.h>
#include <thread>
#include <unistd.h>

namespace turbio {

long long peakRssBytes()
{
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("VmHWM:", 0) == 0) return std::stoll(line.substr(6)) * 1024;
    return -1;
}

long long usableMemoryBytes()
{
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    long long mem = (pages > 0 && page > 0) ? (long long)pages * page : -1;
    // cgroup v2, then v1: a container or a Slurm job may get less than the machine has.
    for (const char* path : {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
        std::ifstream in(path);
        std::string text;
        if (!(in >> text) || text == "max") continue;
        try {
            const long long limit = std::stoll(text);
            if (limit > 0 && (mem < 0 || limit < mem)) mem = limit;
        } catch (...) {}
    }
    return mem;
}

std::string formatBytes(double bytes)
{
    char b[32];
    if (bytes >= 1e9) std::snprintf(b, sizeof(b), "%.1f GB", bytes / 1e9);
    else if (bytes >= 1e6) std::snprintf(b, sizeof(b), "%.0f MB", bytes / 1e6);
    else if (bytes >= 1e3) std::snprintf(b, sizeof(b), "%.0f kB", bytes / 1e3);
    else std::snprintf(b, sizeof(b), "%.0f B", bytes);
    return b;
}

double cpuSeconds()
{
    rusage u{};
    if (getrusage(RUSAGE_SELF, &u) != 0) return -1.0;
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

std::string machineDescription()
{
    std::ifstream in("/proc/cpuinfo");
    std::string line, model = "unknown CPU";
    while (std::getline(in, line))
        if (line.rfind("model name", 0) == 0) {
            const size_t colon = line.find(':');
            if (colon != std::string::npos) model = line.substr(colon + 2);
            break;
        }
    return model + " (" + std::to_string(std::thread::hardware_concurrency()) + " threads)";
}

} // namespace turbio
