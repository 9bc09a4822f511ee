/// @file Render.h
/// @brief Pictures of smoke for people: a lit density render, colour-mapped slices, and a
///        line-integral-convolution (LIC) picture of the flow in a slice. All return turb::Image.
///
/// Views are orthographic along an axis, with +z up (the built-in scenes' and Blender's convention):
/// Front looks along +y (x to the right), Side along +x (-y to the right), Top down along -z (x to the
/// right, +y up). Images keep the field's world aspect ratio; `width` is in pixels, so caches of one
/// domain at different resolutions give images of the same size (contact sheets line up).
///
/// Nothing is normalised per frame: the density render's extinction, light and exposure, and the
/// colour ranges of slices, are settings, so a sequence rendered with fixed settings does not flicker.
///
/// @code
/// turb::DensityRenderSettings r;            // front view, one warm key light, fixed exposure
/// turb::Image img = turb::renderDensity(frame.density, r);
/// turb::SliceSettings s;  s.maxValue = 3.0f; // speed 0..3 world units/s
/// turb::Image speed = turb::renderSlice(turb::magnitude(frame.velocity), s);
/// turb::Image lic = turb::renderLic(frame.velocity, turb::LicSettings{});
/// @endcode
#pragma once

#include <turb/Camera.h>
#include <turb/Field.h>
#include <turb/Image.h>

#include <cstdint>
#include <optional>

namespace turb {

struct DensityRenderSettings
{
    View view = View::Front;              ///< camera direction
    int width = 0;                        ///< image width in pixels; 0 = 4 pixels per voxel (at least 64)
    float extinction = 6.0f;              ///< optical depth per unit density per world unit (> 0); fixed across frames
    float albedo = 0.85f;                 ///< fraction of extinguished light scattered toward the camera, [0, 1]
    Vec3d toLight{-1.0, 0.5, 1.2};        ///< direction from the smoke toward the one light: upper left, behind
    Rgb light{1.6f, 1.45f, 1.25f};        ///< light radiance (warm key light), linear
    Rgb ambient{0.12f, 0.14f, 0.19f};     ///< unshadowed sky fill, linear
    float exposure = 1.0f;                ///< linear scale before the tone curve 1 - exp(-x); fixed across frames, > 0
    Rgb background{0.07f, 0.075f, 0.09f}; ///< display value where the view ray meets no smoke
    float stepVoxels = 0.5f;              ///< ray-march step in voxels, (0, 1]
    std::optional<CameraSettings> camera; ///< any camera (e.g. perspective) instead of `view` and `width`
};

/// Emission–absorption ray march (Camera.h's marchRay) of a density field with single scattering from
/// one directional light (shadowed through the smoke) plus ambient light. An empty field renders
/// `background` exactly.
Image renderDensity(const ScalarField& density, const DensityRenderSettings& s = {});

struct SliceSettings
{
    View view = View::Front;          ///< the slice is perpendicular to the view direction
    double position = 0.5;            ///< slice position along the view axis, as a fraction of the box, [0, 1]
    int width = 0;                    ///< image width in pixels; 0 = 4 pixels per voxel (at least 64)
    Colormap map = Colormap::Viridis; ///< perceptual colour map
    float minValue = 0.0f;            ///< value shown as the map's first colour
    float maxValue = 0.0f;            ///< value shown as the map's last colour; <= minValue = the slice's own max
};

/// A slice of a scalar field (bilinear between voxel centres), colour-mapped.
Image renderSlice(const ScalarField& f, const SliceSettings& s = {});

struct LicSettings
{
    View view = View::Front;   ///< the slice is perpendicular to the view direction; in-plane flow is shown
    double position = 0.5;     ///< slice position along the view axis, fraction of the box, [0, 1]
    int width = 0;             ///< image width in pixels; 0 = 4 pixels per voxel (at least 64)
    float length = 12.0f;      ///< streamline half-length of the convolution kernel, in pixels, >= 1
    std::uint64_t seed = 1;    ///< white-noise texture seed
    bool colourBySpeed = true; ///< tint the LIC texture with the in-plane speed (magma map)
    float maxSpeed = 0.0f;     ///< speed at the map's top; <= 0 = the slice's own max
};

/// Line integral convolution (Cabral & Leedom 1993) of the in-plane velocity of a slice: a white-noise
/// texture smeared along streamlines. As in Ma et al., where the flow is zero the noise is left
/// un-integrated with reduced contrast.
Image renderLic(const VectorField& u, const LicSettings& s = {});

/// Pixels per world unit that renderDensity / renderSlice / renderLic use for a field and width.
double pixelsPerUnit(const CoordBBox& box, double voxelSize, View view, int width);

} // namespace turb
