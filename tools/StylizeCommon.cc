// The command line stylize's methods and animate share (StylizeCommon.h).
#include "StylizeCommon.h"

#include "Console.h"

namespace vdbturb::stylize {

using turb::run::CameraKind;

void addCameraOptions(CLI::App* app, turb::run::CacheCamera& c)
{
    addEnum<CameraKind>(app, "--camera", c.kind,
        {{"front", CameraKind::Front}, {"side", CameraKind::Side}, {"top", CameraKind::Top},
            {"perspective", CameraKind::Perspective}},
        "Cache camera: front (along +y), side (along +x), top (down -z), or perspective")
        ->group(kGroupInput);
    app->add_option("--width", c.width, "Cache camera image width (0: 4 pixels per voxel; perspective 512)")
        ->check(CLI::Range(16, 16384))
        ->group(kGroupInput);
    // The second tier (turb::run::cacheCameraSettings()): the perspective camera's placement, the height, the march.
    addSettings(app, c, turb::run::cacheCameraSettings());
}

} // namespace vdbturb::stylize
