// Small helpers the entry points' sources share (private to libturb/src/run).
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace turb::run::detail {

/// One number in printf's format `f`, for messages.
inline std::string fmt(const char* f, double v)
{
    char b[64];
    std::snprintf(b, sizeof(b), f, v);
    return b;
}

/// Seconds since `t0`.
inline double secondsSince(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace turb::run::detail
