/// @file StylizeCommon.h
/// @brief The command line of `vdbturb stylize` that both methods share, and the cache camera's options, which
///        `vdbturb animate` takes too. The runs are the library's (turb/run/Stylize.h, turb/run/Animate.h).
#pragma once

#include "Commands.h"

#include <turb/run/CacheCamera.h>
#include <turb/run/Stylize.h>

#include <vector>

namespace vdbturb::stylize {

/// The command line's stylize: the job, and what the CLI needs to fill in the rest.
struct StylizeArgs : turb::run::StylizeJob
{
    const CLI::App* app = nullptr;                    ///< for the settings its frames record (--skip-existing)
    std::vector<const CLI::Option*> lazyFluidsOnly;   ///< options --method fluidymation does not read (it warns)
    std::vector<const CLI::Option*> fluidymationOnly; ///< options --method lazyfluids does not read (it warns)
};

/// --camera and --width (everyday); the perspective camera's placement, the height and the ray march (settings).
void addCameraOptions(CLI::App* app, turb::run::CacheCamera& c);

/// `--method fluidymation`'s options (cmd_stylize_fluidymation.cc).
void addFluidymationOptions(CLI::App* app, StylizeArgs& a);

} // namespace vdbturb::stylize
