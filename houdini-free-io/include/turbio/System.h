/// @file System.h
/// @brief Facts about the process and machine, for benchmark reports and logs.
#pragma once

#include <string>

namespace turbio {

/// Peak resident set size of this process in bytes (VmHWM), or -1 if unknown.
long long peakRssBytes();

/// CPU model name and the number of hardware threads, e.g. "Intel Xeon ... (2 threads)".
std::string machineDescription();

} // namespace turbio
