/// @file Commands.h
/// @brief The table of subcommands. Each command fills a Settings struct from its options and calls one
///        library entry point; no algorithm code lives in tools/.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

#include <turb/Error.h>
#include <turbio/Vdb.h>

#include "Validators.h"

#include <turb/run/Flags.h>

namespace vdbturb {

using turb::run::flagFor;
using turb::run::messageWithFlags;

struct Command
{
    std::string name;
    std::string help;
    std::function<void(CLI::App*)> setup; ///< declares the options
    std::function<int()> run;             ///< returns an exit code
    unsigned globals = 7;                 ///< which shared options apply (Console.h GlobalOption bits)
};

Command infoCommand();
Command simCommand();
Command previewCommand();
Command transferCommand();
Command resampleCommand();
Command convertCommand();
Command measureCommand();
Command synthCommand();
Command stylizeCommand();
Command animateCommand();
Command farmCommand();

/// All commands, in the order `vdbturb --help` lists them.
std::vector<Command> allCommands();

/// Adds --density-grid, --vel-grid, --vel-units, --dt, --fps for reading caches; with a `prefix` ("target"),
/// --target-density-grid and so on.
void addReadOptions(CLI::App* app, turbio::ReadOptions& opt, const std::string& prefix = "");

/// Runs `read`, a read with the ReadOptions that addReadOptions declared with `prefix`, and qualifies the settings
/// a turb::Error it throws names with that prefix, so that its message names this command's flags.
template<typename Read>
auto readingAs(const std::string& prefix, Read&& read) -> decltype(read())
{
    try {
        return read();
    } catch (turb::Error& e) {
        e.qualifySettings(prefix);
        throw;
    }
}

/// Warns (once per run, through `warned`) when `options.densityTolerance` (--clipping) is at or above every density
/// value of a frame that holds smoke: its density grid would be written empty.
void warnIfClippedAway(
    const turb::Frame& frame, const turbio::WriteOptions& options, const std::string& path, bool& warned);

/// Adds --style, --no-clobber, --half and --clipping for writing caches.
void addWriteOptions(CLI::App* app, turbio::WriteOptions& opt);
/// Adds --format auto|vdb|nanovdb and --nanovdb-quant float|fp16|fp8 for the commands that write NanoVDB too.
void addFormatOptions(CLI::App* app, turbio::WriteOptions& opt);
/// Refuses (UsageError, exit 2) output options that contradict each other for the output pattern `out`: --format
/// against the name's extension (.vdb / .nvdb), --nanovdb-quant for OpenVDB output, and for NanoVDB output the Blender
/// style and `resumeFlag` ("--resume", "--skip-existing"; "" when not given), which need metadata NanoVDB cannot hold.
void checkOutputFormat(const turbio::WriteOptions& w, const std::string& out, const std::string& resumeFlag = "");
/// --velocity-margin auto: one target voxel, resolved to the ratio once it is known (resolveVelocityMargin).
constexpr int kVelocityMarginAuto = -2;
/// What an up-res (transfer, farm join) writes by default: 16-bit floats and velocity within one target voxel of
/// the smoke, as Blender and Houdini caches are written (docs/io.md, Size). --full-float and --velocity-margin -1
/// give the whole frame in 32-bit floats.
turbio::WriteOptions upResWriteDefaults();
/// Adds --velocity-margin N|auto, --vel-voxel-scale N (Houdini's velocity voxel scale: `vel` on an N times coarser
/// lattice) and --no-velocity (no velocity grid) for an up-res's output.
void addVelocityWriteOptions(CLI::App* app, turbio::WriteOptions& opt);
/// --velocity-margin auto becomes `ratio` output voxels (one target voxel); other values are kept.
inline void resolveVelocityMargin(turbio::WriteOptions& w, int ratio)
{
    if (w.velocityMargin == kVelocityMarginAuto) w.velocityMargin = ratio;
}

} // namespace vdbturb
