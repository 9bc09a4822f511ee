/// @file StylizeCommon.h
/// @brief The command line of `vdbturb stylize` that both methods share, and the cache camera's options, which
///        `vdbturb animate` takes too. The runs are the library's (turb/run/Stylize.h, turb/run/Animate.h).
#pragma once

#include "Commands.h"

#include <turb/run/CacheCamera.h>
#include <turb/run/Stylize.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace vdbturb::stylize {

/// The command line's stylize: the job, and what the CLI needs to fill in the rest.
struct StylizeArgs : turb::run::StylizeJob
{
    const CLI::App* app = nullptr;                    ///< for the settings its frames record (--skip-existing)
    std::vector<const CLI::Option*> lazyFluidsOnly;   ///< options --method fluidymation does not read (it warns)
    std::vector<const CLI::Option*> fluidymationOnly; ///< options --method lazyfluids does not read (it warns)
};

/// --camera and --width (everyday); the perspective camera's placement, the height and the ray march (settings:
/// turb::run::cacheCameraSettings()).
void addCameraOptions(CLI::App* app, turb::run::CacheCamera& c);

/// addSettings for the rows of `table` from the key `first` through the key `last`, and `old`, spellings of those rows:
/// stylize's settings sit among its everyday options in --help-all (the built-in target's beside --scene).
template<typename Job>
void addSettingsFromTo(CLI::App* app, Job& job, const turb::run::SettingsTable<Job>& table, const std::string& first,
    const std::string& last, const std::vector<turb::run::OldSpelling>& old = {})
{
    BoundSettings rows;
    for (const turb::run::Setting<Job>& s : table)
        if (!rows.empty() || s.key == first) {
            rows.emplace_back(&s, s.field(job));
            if (s.key == last) break;
        }
    if (rows.empty() || rows.back().first->key != last)
        throw std::logic_error("no settings from " + first + " to " + last);
    addSettingRows(app, rows, old);
}

/// `--method fluidymation`'s options (cmd_stylize_fluidymation.cc).
void addFluidymationOptions(CLI::App* app, StylizeArgs& a);

} // namespace vdbturb::stylize
