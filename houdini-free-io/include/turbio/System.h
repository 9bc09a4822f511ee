/// @file System.h
/// @brief Facts about the process and machine, for benchmark reports and logs.
#pragma once

#include <string>

namespace turbio {

/// Peak resident set size of this process in bytes (VmHWM), or -1 if unknown.
long long peakRssBytes();

/// The memory this process may use, and what sets it.
struct MemoryLimit
{
    long long bytes = -1; ///< -1 if unknown
    /// What the bytes are, for messages: "this machine's memory", "MemAvailable (what other processes leave
    /// free)", "the cgroup's memory.max (/sys/fs/cgroup/...)", "RLIMIT_AS (ulimit -v)", "RLIMIT_DATA (ulimit -d)".
    std::string source;
    /// "25.3 GB (MemAvailable: what other processes leave free)".
    std::string describe() const;
};

/// The smallest of: physical RAM; MemAvailable (/proc/meminfo: other jobs hold the rest); the memory cgroup's
/// limit, cgroup v2 memory.max or v1 memory.limit_in_bytes, of this process's own cgroup and its ancestors (Slurm's
/// --mem, a container's limit); RLIMIT_AS and RLIMIT_DATA (a wrapper's ulimit -v / -d: address space, which
/// exceeds resident memory by the allocator's and thread pools' reservations). What dry runs and preflight
/// checks compare estimates against, and what an out-of-memory failure names.
MemoryLimit memoryLimit();

/// memoryLimit().bytes: -1 if unknown.
long long usableMemoryBytes();

/// Physical memory of this machine in bytes, or -1 if unknown.
long long machineMemoryBytes();

namespace detail {
/// The smallest memory limit of the cgroup that `procSelfCgroup` (the text of /proc/self/cgroup) names, and of its
/// ancestors, under the cgroup mount `root` ("/sys/fs/cgroup"): v2 memory.max, v1 memory/memory.limit_in_bytes.
/// memoryLimit()'s cgroup part, apart for tests.
MemoryLimit cgroupMemoryLimit(const std::string& procSelfCgroup, const std::string& root);
} // namespace detail

/// Human form of a byte count: "512 MB", "3.2 GB".
std::string formatBytes(double bytes);

/// CPU time this process has used so far (user + system, all threads), seconds. On a shared machine it
/// is the time a run needs, where the wall clock also counts other processes' load.
double cpuSeconds();

/// CPU model name and the number of hardware threads, e.g. "Intel Xeon ... (2 threads)".
std::string machineDescription();

} // namespace turbio
