/// @file System.h
/// @brief Facts about the process and machine, for benchmark reports and logs.
#pragma once

#include <string>

namespace turbio {

/// Peak resident set size of this process in bytes (VmHWM), or -1 if unknown.
long long peakRssBytes();

/// Memory this process may use in bytes: the smaller of physical RAM and the cgroup limit (a farm job's
/// memory.max), or -1 if unknown. The budget dry runs and preflight checks compare estimates against.
long long usableMemoryBytes();

/// Human form of a byte count: "512 MB", "3.2 GB".
std::string formatBytes(double bytes);

/// CPU time this process has used so far (user + system, all threads), seconds. On a shared machine it
/// is the time a run needs, where the wall clock also counts other processes' load.
double cpuSeconds();

/// CPU model name and the number of hardware threads, e.g. "Intel Xeon ... (2 threads)".
std::string machineDescription();

} // namespace turbio
