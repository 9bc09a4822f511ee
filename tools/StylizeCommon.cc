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
    setting(
        app->add_option("--camera-pos", c.position, "Perspective camera position X,Y,Z (world units)"), "camera-pos");
    setting(app->add_option("--look-at", c.lookAt, "Perspective camera target X,Y,Z (world units)"), "look-at");
    setting(app->add_option("--camera-up", c.up, "Perspective camera up direction"), "camera-up");
    setting(
        app->add_option("--fov", c.fov, "Perspective horizontal field of view in degrees")->check(finiteIn(1.0, 170.0)),
        "fov");
    setting(
        app->add_option("--height", c.height, "Perspective image height (0: the width)")->check(CLI::Range(0, 16384)),
        "height");
    setting(
        app->add_option("--extinction", c.extinction, "Cache opacity: optical depth per unit density per world unit")
            ->check(finitePositive()),
        "extinction");
    setting(app->add_option("--step", c.step, "Cache ray-march step in voxels")->check(finiteIn(0.05, 1.0)), "step");
}

} // namespace vdbturb::stylize
