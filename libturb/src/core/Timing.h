// Private to libturb: the step timer the streaming stages report their per-step seconds with.
#pragma once

#include <chrono>

namespace turb::detail {

using Clock = std::chrono::steady_clock;

/// Seconds since `t`, restarting it: one call per timed step.
inline double lap(Clock::time_point& t)
{
    const Clock::time_point now = Clock::now();
    const double s = std::chrono::duration<double>(now - t).count();
    t = now;
    return s;
}

} // namespace turb::detail
