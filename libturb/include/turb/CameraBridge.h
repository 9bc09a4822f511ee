/// @file CameraBridge.h
/// @brief A 3D smoke cache seen through a camera as a 2D target for the image-space methods
///        (stylize; seeds 004 and 001): per pixel the rendered opacity and the mean projected motion.
///
/// Beyond LazyFluids, which is 2D only. Along each pixel's ray (Camera.h's marchRay, the ray march of
/// `vdbturb preview`), sample i has opacity a_i = 1 - exp(-sigma rho_i ds) behind transmittance T_i:
/// - alpha = 1 - prod(1 - a_i) = 1 - exp(-sigma * integral rho ds), the rendered opacity;
/// - motion = sum(w_i m_i) / sum(w_i) with w_i = T_i a_i (each sample's share of the opacity), where
///   m_i is the image motion of the sample point over one frame: the projection of x_i + u(x_i) dt
///   minus that of x_i, in pixels per frame (x right, y down). For axis views this is the projected
///   velocity times dt times pixels per unit; perspective cameras use the exact difference.
/// Pixels whose rays meet no smoke get alpha 0 and motion 0.
///
/// @code
/// turb::BridgeSettings b;                        // front axis view, sigma = 6 as in preview
/// b.camera.width = 512;
/// turb::CameraView v = turb::viewThroughCamera(frame, b);  // v.alpha: 1 channel, v.motion: 2 channels
/// @endcode
#pragma once

#include <turb/Camera.h>
#include <turb/ChannelImage.h>
#include <turb/Frame.h>

namespace turb {

struct BridgeSettings
{
    CameraSettings camera;   ///< which camera; axis front view by default
    float extinction = 6.0f; ///< sigma: optical depth per unit density per world unit (preview's default), > 0
    float stepVoxels = 0.5f; ///< ray-march step in voxels, (0, 1]
};

struct CameraView
{
    ChannelImage alpha;     ///< 1 channel, opacity in [0, 1]
    ChannelImage motion;    ///< 2 channels, opacity-weighted mean image motion, pixels per frame
    double meanSpeed = 0.0; ///< mean |motion| where alpha >= 0.05 (pixels per frame), for reports
};

/// Renders `frame` (density and velocity on one lattice; dt > 0) through the camera. Throws
/// ValueError when the density or velocity is missing, dt <= 0, or a setting is out of range.
CameraView viewThroughCamera(const Frame& frame, const BridgeSettings& settings);

/// Mean |a - b| of two 1-channel images of one size (for the advection check of the bridge).
double meanAbsDifference(const ChannelImage& a, const ChannelImage& b);

/// Does the motion move the alpha? Compares alpha(t+1) with alpha(t) forward-warped by F^t (Warp.h)
/// and with alpha(t) left in place. A motion field that describes the alpha's motion gives
/// advected < still.
struct AdvectionCheck
{
    double advected = 0.0; ///< mean |warp(alpha_t, F^t) - alpha_{t+1}|
    double still = 0.0;    ///< mean |alpha_t - alpha_{t+1}|
};
AdvectionCheck checkAdvection(const ChannelImage& alpha, const ChannelImage& motion, const ChannelImage& nextAlpha);

} // namespace turb
