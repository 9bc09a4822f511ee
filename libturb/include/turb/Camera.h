/// @file Camera.h
/// @brief Cameras that look at a field's box, and the front-to-back ray march the density preview and
///        the camera bridge (CameraBridge.h) share.
///
/// Two kinds of camera:
/// - **axis** (orthographic) views framing the whole box, as `vdbturb preview` renders them, with +z up:
///   Front looks along +y (x right), Side along +x (-y right), Top down along -z (x right, +y up);
///   the image keeps the box's world aspect ratio;
/// - **perspective** pinhole cameras at a world position looking at a point, with a horizontal field
///   of view; `up` fixes the roll.
/// Pixel (px, py) has its centre at continuous image position (px, py), x right, y down (ChannelImage's
/// convention), so the difference of two projected positions is a motion in pixels.
///
/// @code
/// turb::CameraSettings cam;            // front view, 4 pixels per voxel
/// turb::CameraRays rays(cam, density.bbox(), density.lattice());
/// turb::Ray ray = rays.ray(10, 20);
/// float opacity = 1.0f - turb::marchRay(density, ray, 0.5, 6.0f, [](const turb::Vec3d&, float, float) {});
/// @endcode
#pragma once

#include <turb/Field.h>
#include <turb/Operators.h>

#include <algorithm>
#include <cmath>

namespace turb {

enum class View {
    Front, ///< along +y: x right, z up
    Side,  ///< along +x: -y right, z up
    Top    ///< along -z: x right, y up
};

struct CameraSettings
{
    bool perspective = false;        ///< false: an axis view of the whole box; true: a pinhole camera
    View view = View::Front;         ///< axis views: the direction
    Vec3d position{0.0, -10.0, 2.0}; ///< perspective: camera position, world units
    Vec3d lookAt{0.0, 0.0, 2.0};     ///< perspective: the point at the image centre, world units (!= position)
    Vec3d up{0.0, 0.0, 1.0};         ///< perspective: world direction shown as up (not parallel to the view)
    double fovDegrees = 40.0;        ///< perspective: horizontal field of view, (0, 170)
    int width = 0;                   ///< pixels; 0 = 4 per voxel (axis views, at least 64) or 512 (perspective)
    int height = 0;                  ///< perspective: pixels, 0 = width; axis views: from the box's aspect
};

/// A ray in index space: points origin + t * direction, with `direction` of unit length (t in voxels),
/// inside the box for t in [t0, t1] (t0 > t1: the ray misses the box).
struct Ray
{
    Vec3d origin{0.0}, direction{0.0, 1.0, 0.0};
    double t0 = 0.0, t1 = -1.0;
};

/// The rays of a camera through a box of voxels placed by a Lattice.
class CameraRays
{
public:
    /// Throws ValueError on an empty box or invalid camera settings.
    CameraRays(const CameraSettings& camera, const CoordBBox& box, const Lattice& lattice);

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    bool perspective() const { return mCam.perspective; }
    /// The ray through the centre of pixel (px, py).
    Ray ray(int px, int py) const;
    /// Continuous image position of a world point (x right, y down); false when it is behind a
    /// perspective camera.
    bool project(const Vec3d& world, double& px, double& py) const;
    /// Axis views: pixels per world unit.
    double pixelsPerUnit() const { return mPixelsPerUnit; }

private:
    CameraSettings mCam;
    CoordBBox mBox;
    Lattice mLattice;
    int mWidth = 0, mHeight = 0;
    // Axis views
    int mDepth = 1, mRight = 0, mUp = 2, mDepthSign = 1, mRightSign = 1;
    double mPixelsPerUnit = 1.0;
    // Perspective: orthonormal basis and the half-extents of the image plane at distance 1
    Vec3d mForward, mRightDir, mUpDir;
    double mTanX = 0.0, mTanY = 0.0;
};

/// Emission-absorption march along `ray` from front to back with samples every `stepVoxels` (the
/// step is shrunk so whole steps fill [t0, t1]), trilinear density, sample opacity
/// alpha = 1 - exp(-extinction * rho * ds) with ds in world units. For every sample with rho > 0,
/// calls visit(p, alpha, T) with p in index space and T the transmittance in front of the sample.
/// Stops once T < 1e-4. Returns the transmittance left, so the opacity is 1 - the result.
template<typename Visit>
float marchRay(const ScalarField& rho, const Ray& ray, double stepVoxels, float extinction, Visit&& visit)
{
    if (!(ray.t1 > ray.t0)) return 1.0f;
    const int steps = std::max(1, int(std::ceil((ray.t1 - ray.t0) / stepVoxels)));
    const double step = (ray.t1 - ray.t0) / steps;
    const double dsWorld = step * rho.lattice().voxelSize;
    float view = 1.0f;
    for (int n = 0; n < steps && view > 1e-4f; ++n) {
        const Vec3d p = ray.origin + ray.direction * (ray.t0 + (n + 0.5) * step);
        const float r = sampleTrilinear(rho, p);
        if (r <= 0.0f) continue;
        const float alpha = 1.0f - std::exp(-float(extinction * r * dsWorld));
        visit(p, alpha, view);
        view *= 1.0f - alpha;
    }
    return view;
}

} // namespace turb
