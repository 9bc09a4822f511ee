/// @file Error.h
/// @brief The one exception hierarchy of vdbturb.
///
/// Broken preconditions and unreadable inputs throw; solver outcomes (non-convergence, a frame with no
/// smoke) are returned as values in the stage's result struct instead.
#pragma once

#include <stdexcept>
#include <string>

namespace turb {

/// Base of everything vdbturb throws.
class Error : public std::runtime_error
{
public:
    using std::runtime_error::runtime_error;
};

/// A file could not be found, read, parsed or written. The message names the file (and grid).
class IoError : public Error
{
public:
    using Error::Error;
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
