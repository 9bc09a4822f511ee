#include <turb/Camera.h>

#include <turb/Error.h>

#include <cmath>
#include <limits>

namespace turb {

CameraRays::CameraRays(const CameraSettings& camera, const CoordBBox& box, const Lattice& lattice)
    : mCam(camera), mBox(box), mLattice(lattice)
{
    if (box.empty()) throw ValueError("camera: empty field");
    if (camera.width < 0 || camera.height < 0) throw ValueError("camera: width and height must be >= 0");
    if (!camera.perspective) {
        switch (camera.view) {
        case View::Front:
            mDepth = 1;
            mRight = 0;
            mUp = 2;
            mDepthSign = 1;
            mRightSign = 1;
            break;
        case View::Side:
            mDepth = 0;
            mRight = 1;
            mUp = 2;
            mDepthSign = 1;
            mRightSign = -1;
            break;
        case View::Top:
            mDepth = 2;
            mRight = 0;
            mUp = 1;
            mDepthSign = -1;
            mRightSign = 1;
            break;
        }
        const int dr = box.dim()[mRight], du = box.dim()[mUp];
        mWidth = camera.width > 0 ? camera.width : std::max(64, 4 * dr);
        mHeight = std::max(1, int(std::lround(double(mWidth) * du / dr)));
        mPixelsPerUnit = mWidth / (dr * lattice.voxelSize);
        return;
    }
    if (!(camera.fovDegrees > 0.0 && camera.fovDegrees < 170.0))
        throw ValueError("camera: field of view must lie in (0, 170) degrees");
    Vec3d f = camera.lookAt - camera.position;
    if (!(f.length() > 0.0)) throw ValueError("camera: position and look-at point must differ");
    f.normalize();
    Vec3d r = f.cross(camera.up);
    if (!(r.length() > 1e-9)) throw ValueError("camera: the up direction is parallel to the view direction");
    r.normalize();
    mForward = f;
    mRightDir = r;
    mUpDir = r.cross(f);
    mWidth = camera.width > 0 ? camera.width : 512;
    mHeight = camera.height > 0 ? camera.height : mWidth;
    mTanX = std::tan(0.5 * camera.fovDegrees * M_PI / 180.0);
    mTanY = mTanX * mHeight / mWidth;
}

Ray CameraRays::ray(int px, int py) const
{
    Ray ray;
    const double lo[3] = {mBox.min().x() - 0.5, mBox.min().y() - 0.5, mBox.min().z() - 0.5};
    const double hi[3] = {mBox.max().x() + 0.5, mBox.max().y() + 0.5, mBox.max().z() + 0.5};
    if (!mCam.perspective) {
        // As preview's raster: voxel edges span the image; the ray crosses the whole box along depth.
        const double tx = (px + 0.5) / mWidth, ty = (py + 0.5) / mHeight;
        ray.origin[mRight] =
            mRightSign > 0 ? lo[mRight] + tx * (hi[mRight] - lo[mRight]) : hi[mRight] - tx * (hi[mRight] - lo[mRight]);
        ray.origin[mUp] = hi[mUp] - ty * (hi[mUp] - lo[mUp]);
        ray.origin[mDepth] = mDepthSign > 0 ? lo[mDepth] : hi[mDepth];
        ray.direction = Vec3d(0.0);
        ray.direction[mDepth] = mDepthSign;
        ray.t0 = 0.0;
        ray.t1 = hi[mDepth] - lo[mDepth];
        return ray;
    }
    const double nx = (px + 0.5) / mWidth * 2.0 - 1.0, ny = 1.0 - (py + 0.5) / mHeight * 2.0;
    Vec3d d = mForward + mRightDir * (nx * mTanX) + mUpDir * (ny * mTanY);
    d.normalize();
    ray.origin = mLattice.worldToIndex(mCam.position);
    ray.direction = d; // index space is world space scaled by 1/voxel: directions are unchanged
    // Slab intersection with the box.
    double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        if (std::abs(d[a]) < 1e-12) {
            if (ray.origin[a] < lo[a] || ray.origin[a] > hi[a]) t0 = t1 + 1.0;
            continue;
        }
        double ta = (lo[a] - ray.origin[a]) / d[a], tb = (hi[a] - ray.origin[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    ray.t0 = t0;
    ray.t1 = t1;
    return ray;
}

bool CameraRays::project(const Vec3d& world, double& px, double& py) const
{
    if (!mCam.perspective) {
        const Vec3d i = mLattice.worldToIndex(world);
        const double lo[3] = {mBox.min().x() - 0.5, mBox.min().y() - 0.5, mBox.min().z() - 0.5};
        const double hi[3] = {mBox.max().x() + 0.5, mBox.max().y() + 0.5, mBox.max().z() + 0.5};
        const double tx = (i[mRight] - lo[mRight]) / (hi[mRight] - lo[mRight]);
        px = (mRightSign > 0 ? tx : 1.0 - tx) * mWidth - 0.5;
        py = (hi[mUp] - i[mUp]) / (hi[mUp] - lo[mUp]) * mHeight - 0.5;
        return true;
    }
    const Vec3d rel = world - mCam.position;
    const double z = rel.dot(mForward);
    if (!(z > 1e-9)) return false;
    const double nx = rel.dot(mRightDir) / (z * mTanX), ny = rel.dot(mUpDir) / (z * mTanY);
    px = (nx + 1.0) * 0.5 * mWidth - 0.5;
    py = (1.0 - ny) * 0.5 * mHeight - 0.5;
    return true;
}

} // namespace turb
