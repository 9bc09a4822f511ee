/// @file Error.h
/// @brief The one exception hierarchy of vdbturb.
///
/// Broken preconditions and unreadable inputs throw; solver outcomes (non-convergence, a frame with no
/// smoke) are returned as values in the stage's result struct instead.
///
/// The contract with programs that take settings from their users: the library and the IO layer name
/// *settings*, the program names its own *flags*. A message says what is wrong in the library's words (the
/// file, the grid, the frame) and never names a command-line flag; an error that a setting fixes (or that a
/// setting caused) lists that setting in settings(), by its field name in the struct the call took
/// ("velocityGrid" of turbio::ReadOptions, "noClobber" of turbio::WriteOptions). A command line (tools/) turns
/// those into its flags when it prints the error ("Use --target-vel-grid NAME").
#pragma once

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace turb {

/// Base of everything vdbturb throws.
class Error : public std::runtime_error
{
public:
    /// `message`: what is wrong; `settings`: the fields of the caller's settings struct that fix it, most direct
    /// first (empty when none does).
    explicit Error(const std::string& message, std::vector<std::string> settings = {})
        : std::runtime_error(message), mSettings(std::move(settings))
    {}

    /// The settings that fix (or caused) the error: field names such as "densityGrid"; qualified as
    /// "target.densityGrid" after qualifySettings("target").
    const std::vector<std::string>& settings() const noexcept { return mSettings; }

    /// Prefixes each setting with `owner` and a dot, for a caller that passes several structs of one type (a
    /// target's and a source's ReadOptions) and catches to say which one the error concerns, then rethrows
    /// with `throw;` (which keeps the error's type). A setting already qualified is left as it is.
    void qualifySettings(const std::string& owner)
    {
        if (owner.empty()) return;
        for (auto& s : mSettings)
            if (s.find('.') == std::string::npos) s = owner + "." + s;
    }

private:
    std::vector<std::string> mSettings;
};

/// A file could not be found, read, parsed or written. The message names the file (and grid).
class IoError : public Error
{
public:
    using Error::Error;
};

/// A failure of the machine rather than of the input, which a retry (on another node, with more disk) may fix:
/// the disk full, a file-size limit (ulimit -f) or quota reached, memory exhausted. Commands exit 75
/// (EX_TEMPFAIL) on it, the code farm wrappers requeue on.
class TransientError : public IoError
{
public:
    using IoError::IoError;
};

/// An argument or an input value is invalid (NaN voxels, a non-integer ratio, mismatched transforms...).
class ValueError : public Error
{
public:
    using Error::Error;
};

/// The injected Progress asked the stage to stop.
class Cancelled : public Error
{
public:
    Cancelled() : Error("interrupted") {}
};

} // namespace turb
