/// @file Commands.h
/// @brief The table of subcommands. Each command fills a Settings struct from its options and calls one
///        library entry point; no algorithm code lives in tools/.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <turb/Error.h>
#include <turbio/Vdb.h>

#include "Validators.h"

#include <turb/run/Flags.h>
#include <turb/run/Output.h>
#include <turb/run/Settings.h>

namespace vdbturb {

using turb::run::checkOutputFormat;
using turb::run::flagFor;
using turb::run::kVelocityMarginAuto;
using turb::run::messageWithFlags;
using turb::run::readingAs;
using turb::run::resolveVelocityMargin;
using turb::run::upResWriteDefaults;
using turb::run::warnIfClippedAway;

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

/// Adds --style, --no-clobber, --half and --clipping for writing caches.
void addWriteOptions(CLI::App* app, turbio::WriteOptions& opt);
/// Adds --format auto|vdb|nanovdb and --nanovdb-quant float|fp16|fp8 for the commands that write NanoVDB too.
void addFormatOptions(CLI::App* app, turbio::WriteOptions& opt);
/// Adds --velocity-margin N|auto, --vel-voxel-scale N (Houdini's velocity voxel scale: `vel` on an N times coarser
/// lattice) and --no-velocity (no velocity grid) for an up-res's output.
void addVelocityWriteOptions(CLI::App* app, turbio::WriteOptions& opt);

/// A settings table's rows bound to one job's fields.
using BoundSettings = std::vector<std::pair<const turb::run::SettingRow*, turb::run::FieldRef>>;

/// Declares `rows` as second-tier options of `app` (setting()): each row's aliases and key as its long names
/// (--density-threshold,--densityThreshold), its range as a check, an enum by its choices' names, a bool as
/// KEY=true|false or a bare flag; then `old` as legacy() spellings that set the same fields.
void addSettingRows(CLI::App* app, const BoundSettings& rows, const std::vector<turb::run::OldSpelling>& old);

/// addSettingRows for `table`'s rows bound to `job`, from the row keyed `from` up to the one keyed `to` (not
/// included; empty: from the first, past the last): --help-all lists options in the order they are declared, so a
/// table whose rows another function's options sit among (animate's read options) is declared in parts. The table
/// and the job must outlive the parse.
template<typename Job>
void addSettings(CLI::App* app, Job& job, const turb::run::SettingsTable<Job>& table,
    const std::vector<turb::run::OldSpelling>& old = {}, const std::string& from = "", const std::string& to = "")
{
    BoundSettings rows;
    bool in = from.empty();
    for (const turb::run::Setting<Job>& s : table) {
        in = (in || s.key == from) && s.key != to;
        if (in) rows.emplace_back(&s, s.field(job));
    }
    if (rows.empty()) throw std::logic_error("no settings rows from '" + from + "' to '" + to + "'");
    addSettingRows(app, rows, old);
}

} // namespace vdbturb
