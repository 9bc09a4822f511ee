#include <turbio/System.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

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

namespace {

// A number of bytes in a cgroup limit file; -1 for "max", a missing file or text that is not a number.
long long limitFile(const std::string& path)
{
    std::ifstream in(path);
    std::string text;
    if (!(in >> text) || text == "max") return -1;
    try {
        const long long v = std::stoll(text);
        return v > 0 ? v : -1;
    } catch (...) {
        return -1;
    }
}

// The limit files of the memory cgroup `procSelfCgroup` (/proc/self/cgroup's text) names, under the cgroup mount
// `root`: cgroup v2's unified path ("0::/PATH") or v1's memory controller ("N:...memory...:/PATH"), each with its
// ancestors, then the mount's own (inside a container the cgroup's files are at the root).
std::vector<std::string> cgroupLimitFiles(const std::string& procSelfCgroup, const std::string& root)
{
    std::vector<std::string> files;
    std::istringstream in(procSelfCgroup);
    std::string line;
    while (std::getline(in, line)) {
        const size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
        if (b == std::string::npos) continue;
        const std::string controllers = line.substr(a + 1, b - a - 1);
        std::string path = line.substr(b + 1);
        std::string dir, file;
        if (controllers.empty()) {
            dir = root;
            file = "memory.max";
        } else if (("," + controllers + ",").find(",memory,") != std::string::npos) {
            dir = root + "/memory";
            file = "memory.limit_in_bytes";
        } else {
            continue;
        }
        // A limit on any ancestor holds too (Slurm sets it on the job, the process sits in a step below it).
        for (;;) {
            files.push_back(dir + (path == "/" ? std::string() : path) + "/" + file);
            if (path.empty() || path == "/") break;
            const size_t slash = path.rfind('/');
            path = slash == 0 || slash == std::string::npos ? "/" : path.substr(0, slash);
        }
    }
    files.push_back(root + "/memory.max");
    files.push_back(root + "/memory/memory.limit_in_bytes");
    return files;
}

// Keeps the smaller of `m` and (bytes, source); bytes <= 0 means no limit.
void keepSmaller(MemoryLimit& m, long long bytes, const std::string& source)
{
    if (bytes > 0 && (m.bytes < 0 || bytes < m.bytes)) {
        m.bytes = bytes;
        m.source = source;
    }
}

} // namespace

long long machineMemoryBytes()
{
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    return pages > 0 && page > 0 ? (long long)pages * page : -1;
}

namespace detail {

MemoryLimit cgroupMemoryLimit(const std::string& procSelfCgroup, const std::string& root)
{
    MemoryLimit m;
    for (const std::string& f : cgroupLimitFiles(procSelfCgroup, root))
        keepSmaller(m, limitFile(f), "the cgroup's " + f.substr(f.rfind('/') + 1) + ", " + f);
    return m;
}

} // namespace detail

std::string MemoryLimit::describe() const
{
    return bytes < 0 ? std::string("unknown") : formatBytes(double(bytes)) + " (" + source + ")";
}

MemoryLimit memoryLimit()
{
    MemoryLimit m;
    const auto consider = [&m](long long bytes, const std::string& source) { keepSmaller(m, bytes, source); };
    consider(machineMemoryBytes(), "this machine's memory");
    {
        std::ifstream in("/proc/meminfo");
        std::string key;
        long long kb = 0;
        std::string unit;
        while (in >> key >> kb >> unit)
            if (key == "MemAvailable:") consider(kb * 1024, "MemAvailable: what other processes leave free");
    }
    {
        std::ifstream in("/proc/self/cgroup");
        std::stringstream text;
        text << in.rdbuf();
        const MemoryLimit group = detail::cgroupMemoryLimit(text.str(), "/sys/fs/cgroup");
        consider(group.bytes, group.source);
    }
    // An address-space limit also counts what is mapped and not resident (libraries, thread stacks, malloc's
    // arenas): what is mapped so far beyond the resident set is not there for the run's data.
    long long mappedNotResident = 0;
    {
        std::ifstream in("/proc/self/status");
        std::string line;
        long long size = -1, rss = -1;
        while (std::getline(in, line)) {
            if (line.rfind("VmSize:", 0) == 0) size = std::stoll(line.substr(7)) * 1024;
            if (line.rfind("VmRSS:", 0) == 0) rss = std::stoll(line.substr(6)) * 1024;
        }
        if (size > 0 && rss > 0 && size > rss) mappedNotResident = size - rss;
    }
    for (const auto& [resource, name] : {std::pair<int, const char*>{RLIMIT_AS, "RLIMIT_AS, ulimit -v"},
             std::pair<int, const char*>{RLIMIT_DATA, "RLIMIT_DATA, ulimit -d"}}) {
        rlimit rl{};
        if (::getrlimit(resource, &rl) != 0 || rl.rlim_cur == RLIM_INFINITY) continue;
        if (resource == RLIMIT_AS && mappedNotResident > 0)
            consider((long long)rl.rlim_cur - mappedNotResident,
                std::string(name) + ", less " + formatBytes(double(mappedNotResident)) + " mapped and not resident");
        else consider((long long)rl.rlim_cur, name);
    }
    return m;
}

long long usableMemoryBytes() { return memoryLimit().bytes; }

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
