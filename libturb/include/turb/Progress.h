/// @file Progress.h
/// @brief Injected progress reporting and cancellation (in the spirit of openvdb::util::NullInterrupter).
///
/// Stages call `update()` and `cancelled()`; they never print. The CLI turns reports into a progress bar
/// on a TTY or into plain log lines for farm logs. `cancelled()` may be called from worker threads.
#pragma once

#include <string>

namespace turb {

class Progress
{
public:
    virtual ~Progress() = default;
    /// A named step of the current frame begins (e.g. "global search").
    virtual void begin(const std::string& /*step*/) {}
    /// Fraction of the current step done, in [0, 1].
    virtual void update(double /*fraction*/) {}
    /// A diagnostic line the caller may log at verbose level.
    virtual void note(const std::string& /*text*/) {}
    /// True when the caller wants the stage to stop; stages then throw turb::Cancelled.
    virtual bool cancelled() const { return false; }
};

/// Throws Cancelled when `p` asks to stop. Null-safe.
void checkCancelled(const Progress* p);

} // namespace turb
