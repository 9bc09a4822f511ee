// preview's second tier as a settings table (turb/run/Settings.h): the slice, the density render's light and the
// colour ranges (docs/scenes.md), in the order --help-all lists them.
#include "SettingsRows.h"

#include <turb/run/Preview.h>

namespace turb::run {

const SettingsTable<PreviewJob>& previewSettings()
{
    using detail::add;
    static const SettingsTable<PreviewJob> table = [] {
        SettingsTable<PreviewJob> t;
        add(t, "slice", "", "Slice position for speed/vorticity/lic, fraction along the view axis", TURB_FIELD(slice),
            0.0, 1.0);
        add(t, "exposure", "", "Density render exposure, fixed for all frames", TURB_FIELD(exposure), 0.0).lowOpen =
            true;
        add(t, "extinction", "", "Optical depth per unit density per world unit", TURB_FIELD(extinction), 0.0).lowOpen =
            true;
        add(t, "match-density", "",
            "Draw each cache's density scaled to the first cache's peak (on the last row's frame, fixed for the run; "
            "Blender's noise up-res writes about f times its base's density), labelled with the scale",
            TURB_FIELD(matchDensity))
            .flag = true;
        // 0, the default, is "from the picture" (a percentile): only a positive value may be given.
        add(t, "speed-max", "", "Speed at the top of the colour map (0: the last frame's 99.5th percentile)",
            TURB_FIELD(speedMax), 0.0)
            .lowOpen = true;
        add(t, "vorticity-max", "", "Vorticity at the top of the colour map (0: each cache's 99th percentile)",
            TURB_FIELD(vorticityMax), 0.0)
            .lowOpen = true;
        return t;
    }();
    return table;
}

} // namespace turb::run
