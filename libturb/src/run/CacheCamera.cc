// The camera a cache is seen through by stylize and animate (turb/run/CacheCamera.h).
#include <turb/run/CacheCamera.h>

#include "StylizeParts.h"

#include <turb/Error.h>

namespace turb::run {

namespace {

turb::Vec3d parseVec(const std::string& s, const std::string& what)
{
    const auto v = detail::parseNumbers(s, 3, what);
    return turb::Vec3d(v[0], v[1], v[2]);
}

} // namespace

std::string cameraName(CameraKind k)
{
    switch (k) {
    case CameraKind::Side: return "side";
    case CameraKind::Top: return "top";
    case CameraKind::Perspective: return "perspective";
    default: return "front";
    }
}

turb::BridgeSettings bridgeSettings(const CacheCamera& a)
{
    turb::BridgeSettings b;
    turb::CameraSettings& c = b.camera;
    if (a.kind == CameraKind::Perspective) {
        if (a.position.empty() || a.lookAt.empty())
            throw turb::ValueError("--camera perspective needs --camera-pos X,Y,Z and --look-at X,Y,Z");
        c.perspective = true;
        c.position = parseVec(a.position, "--camera-pos");
        c.lookAt = parseVec(a.lookAt, "--look-at");
        c.up = parseVec(a.up, "--camera-up");
        c.fovDegrees = a.fov;
    } else {
        c.view = a.kind == CameraKind::Side  ? turb::View::Side
                 : a.kind == CameraKind::Top ? turb::View::Top
                                             : turb::View::Front;
    }
    c.width = a.width;
    c.height = a.height;
    b.extinction = a.extinction;
    b.stepVoxels = a.step;
    return b;
}

} // namespace turb::run
