// vdbturb stylize --method fluidymation: its options (moving exemplars; the run is turb::run::runStylize).
#include "StylizeCommon.h"

namespace vdbturb::stylize {

void addFluidymationOptions(CLI::App* app, StylizeArgs& a)
{
    turb::run::FluidymationJob& f = a.fluidy;
    const std::string m = "[fluidymation] ";
    app->add_option(
        "--exemplar-mask", f.exemplarMask, m + "Binary masks of the exemplar frames (empty: the exemplar's alpha)");
    app->add_option("--target-mask", f.targetMask, m + "Binary target masks (#### sequence): the 2D target");
    // The rest is the second tier, turb::FluidySettings under its field names (Table 1's values are the defaults;
    // docs/fluidymation.md), and the flows and debugging pictures.
    addSettingsFromTo(app, static_cast<turb::run::StylizeJob&>(a), turb::run::stylizeSettings(), "exemplar-flow",
        "fluidy.reusePrevious", turb::run::stylizeOldSpellings());
}

} // namespace vdbturb::stylize
