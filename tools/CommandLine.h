/// @file CommandLine.h
/// @brief The whole command line as one call, for the vdbturb executable and for hosts that run commands in their
///        own process (the Python module, tools/python/vdbturb_module.cc).
#pragma once

#include <string>
#include <vector>

namespace turb {
struct FrameMeasures;
}

namespace vdbturb {

struct OutputHooks;

/// Runs one command line in this process as the vdbturb executable would (`words` without the program's name:
/// {"transfer", "--target", ...}): parsing, dispatch, messages, exit code. Without `hooks` it is the executable
/// (stdout, stderr, Ctrl-C handlers); with them a host's call (the Python module): output goes to the hooks and
/// the process's signal handlers are left alone. One command line at a time per process: the caller serialises.
int runCommandLine(const std::vector<std::string>& words, const OutputHooks* hooks = nullptr);

/// One option of a command as its parser declares it, for a host that builds command lines (the Python module).
struct OptionInfo
{
    std::vector<std::string> longNames;  ///< without "--": {"density-threshold", "densityThreshold"}
    std::vector<std::string> falseNames; ///< a flag's negations ("full-float" of --half,!--full-float)
    std::string positional;              ///< a positional's name ("pattern"), else empty
    bool flag = false;                   ///< takes no value
    bool multiple = false;               ///< takes several values
    std::string help, defaultValue;
};
/// The options of `command` ("transfer"); empty for no such command. Not while a command line runs.
std::vector<OptionInfo> commandOptions(const std::string& command);

/// One frame's numbers as measure's JSON line writes them (without "frame" and "seconds"), as JSON text.
std::string measureJsonText(const turb::FrameMeasures& m, bool spectra);

} // namespace vdbturb
