// The cache camera's second tier as a settings table (turb/run/Settings.h): stylize --cache and animate
// --example-cache see a VDB cache through it. --camera and --width stay everyday options.
#include "SettingsRows.h"

#include <turb/run/CacheCamera.h>

namespace turb::run {

const SettingsTable<CacheCamera>& cacheCameraSettings()
{
    using detail::add;
    static const SettingsTable<CacheCamera> table = [] {
        SettingsTable<CacheCamera> t;
        add(t, "camera-pos", "", "Perspective camera position X,Y,Z (world units)", TURB_FIELD(position));
        add(t, "look-at", "", "Perspective camera target X,Y,Z (world units)", TURB_FIELD(lookAt));
        add(t, "camera-up", "", "Perspective camera up direction", TURB_FIELD(up));
        add(t, "fov", "", "Perspective horizontal field of view in degrees", TURB_FIELD(fov), 1.0, 170.0);
        add(t, "height", "", "Perspective image height (0: the width)", TURB_FIELD(height), 0, 16384);
        add(t, "extinction", "", "Cache opacity: optical depth per unit density per world unit", TURB_FIELD(extinction),
            0.0)
            .lowOpen = true;
        add(t, "step", "", "Cache ray-march step in voxels", TURB_FIELD(step), 0.05, 1.0);
        return t;
    }();
    return table;
}

} // namespace turb::run
