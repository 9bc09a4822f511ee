/// @file Preflight.h
/// @brief The checks every command runs before its first frame live in the entry points' layer
///        (turb/run/Preflight.h), where the Python module reaches them too; here only what needs the command line.
#pragma once

#include <turb/run/Preflight.h>

#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace vdbturb {

using turb::run::checkInput;
using turb::run::checkMemory;
using turb::run::checkOutputs;
using turb::run::frameMetadata;
using turb::run::LatticePolicy;
using turb::run::lockOutputFrames;
using turb::run::planSkips;
using turb::run::printSkipPlan;
using turb::run::releaseOutputLocks;
using turb::run::reportTiming;
using turb::run::sequentialSettings;
using turb::run::SkipPlan;
using turb::run::timingLines;
using turb::run::TimingSources;
using turb::run::timingSources;
using turb::run::upAxisOf;
using turb::run::writtenWithSettings;

/// The settings that make a command's frames, as "name=value;..." for vdbturb_settings: every option of `app` with
/// its value (defaults included), less those that do not change a frame (threads, progress, verbosity, frames,
/// paths, dry run, skip-existing, no-clobber), and each input as an absolute path. What --skip-existing compares.
std::string commandSettingsText(const CLI::App& app, const std::vector<std::string>& inputs);

} // namespace vdbturb
