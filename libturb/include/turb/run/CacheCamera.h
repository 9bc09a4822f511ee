/// @file CacheCamera.h
/// @brief The camera a VDB cache is seen through by the image-space entry points (turb::run): `vdbturb stylize
///        --cache` takes its target, `vdbturb animate --example-cache` its video example through it.
#pragma once

#include <turb/CameraBridge.h>

#include <string>

namespace turb::run {

/// An axis view of the cache's whole box, or a placed perspective camera.
enum class CameraKind { Front, Side, Top, Perspective };

/// The camera and its ray march as the command line gives them (--camera, --camera-pos, ...).
struct CacheCamera
{
    CameraKind kind = CameraKind::Front; ///< front (along +y), side (along +x), top (down -z) or perspective
    std::string position, lookAt;        ///< perspective only, required there: "X,Y,Z" in world units
    std::string up = "0,0,1";            ///< perspective: the up direction "X,Y,Z"
    double fov = 40.0;                   ///< perspective: horizontal field of view in degrees, (1, 170]
    int width = 0;                       ///< image width in pixels; 0: 4 pixels per voxel (perspective 512)
    int height = 0;                      ///< perspective image height in pixels; 0: the width
    float extinction = 6.0f;             ///< opacity: optical depth per unit density per world unit, > 0
    float step = 0.5f;                   ///< ray-march step in voxels, (0, 1]
};

/// The bridge's camera and ray march for `camera`. Throws turb::ValueError when a perspective camera lacks its
/// position or target, or one of its vectors is not three comma-separated numbers.
turb::BridgeSettings bridgeSettings(const CacheCamera& camera);

/// "front", "side", "top" or "perspective".
std::string cameraName(CameraKind kind);

} // namespace turb::run
