/// @file Flags.h
/// @brief The command line's words for the library's settings (turb::run, the entry points' layer).
///
/// The library names settings by their field (`velocityGrid` of ReadOptions, turb::Error::settings); the entry points
/// speak to people in the command line's words, so that the CLI, the Python module and the add-on give one message.
#pragma once

#include <turb/Error.h>

#include <string>

namespace turb::run {

/// The flag that sets `setting`, a turbio::ReadOptions or WriteOptions field as turb::Error::settings and
/// turbio::ReadReport name it ("velocityGrid" -> "--vel-grid"). A read option takes the prefix the command declared
/// it with: the setting's qualifier ("target.velocityGrid" -> "--target-vel-grid"), else `readPrefix`.
/// "" for a setting no flag sets.
std::string flagFor(const std::string& setting, const std::string& readPrefix = "");

/// `e`'s message as the command line prints it: followed by the flags of the settings it names ("...; the file
/// has: #0 'density' float fog volume. Use --vel-grid NAME, or '#N' for the N-th grid listed here.").
std::string messageWithFlags(const turb::Error& e);

/// Reads the whole of `s` as a number, as the command line reads numbers (NaN and inf included); false when it is
/// not one.
bool parseNumber(const std::string& s, double& v);

} // namespace turb::run
