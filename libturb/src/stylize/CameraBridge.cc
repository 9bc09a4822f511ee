#include <turb/CameraBridge.h>

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Warp.h>

#include <cmath>

namespace turb {

CameraView viewThroughCamera(const Frame& frame, const BridgeSettings& s)
{
    if (!frame.hasDensity())
        throw ValueError("camera bridge: the frame has no density (alpha is its rendered opacity)");
    if (!frame.hasVelocity()) throw ValueError("camera bridge: the frame has no velocity (motion is its projection)");
    if (!(frame.dt > 0.0)) throw ValueError("camera bridge: the frame's time per frame (dt) is unknown; give it");
    if (!(s.extinction > 0.0f)) throw ValueError("camera bridge: extinction must be > 0");
    if (!(s.stepVoxels > 0.0f && s.stepVoxels <= 1.0f))
        throw ValueError("camera bridge: the step must lie in (0, 1] voxels");
    const ScalarField& rho = frame.density;
    const CameraRays rays(s.camera, rho.bbox(), rho.lattice());
    const int W = rays.width(), H = rays.height();
    CameraView v{ChannelImage(W, H, 1), ChannelImage(W, H, 2), 0.0};
    parallelFor(size_t(H), 1, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy) {
            const int py = int(yy);
            for (int px = 0; px < W; ++px) {
                double wsum = 0.0, mx = 0.0, my = 0.0;
                const float left = marchRay(rho, rays.ray(px, py), s.stepVoxels, s.extinction,
                    [&](const Vec3d& p, float alpha, float transmittance) {
                        const Vec3d x = rho.lattice().indexToWorld(p);
                        const Vec3f u = sampleWorld(frame.velocity, x);
                        double ax, ay, bx, by;
                        if (!rays.project(x, ax, ay) || !rays.project(x + Vec3d(u) * frame.dt, bx, by)) return;
                        const double w = double(transmittance) * alpha;
                        wsum += w;
                        mx += w * (bx - ax);
                        my += w * (by - ay);
                    });
                v.alpha.at(px, py, 0) = 1.0f - left;
                if (wsum > 0.0) {
                    v.motion.at(px, py, 0) = float(mx / wsum);
                    v.motion.at(px, py, 1) = float(my / wsum);
                }
            }
        }
    });
    double sum = 0.0;
    long long n = 0;
    for (size_t i = 0; i < v.alpha.pixelCount(); ++i)
        if (v.alpha.pixel(i)[0] >= 0.05f) {
            sum += std::hypot(double(v.motion.pixel(i)[0]), double(v.motion.pixel(i)[1]));
            ++n;
        }
    v.meanSpeed = n ? sum / double(n) : 0.0;
    return v;
}

double meanAbsDifference(const ChannelImage& a, const ChannelImage& b)
{
    if (!a.sameSize(b) || a.channels() != 1 || b.channels() != 1)
        throw ValueError("meanAbsDifference: two 1-channel images of one size");
    double s = 0.0;
    for (size_t i = 0; i < a.pixelCount(); ++i) s += std::abs(double(a.pixel(i)[0]) - double(b.pixel(i)[0]));
    return a.pixelCount() ? s / double(a.pixelCount()) : 0.0;
}

AdvectionCheck checkAdvection(const ChannelImage& alpha, const ChannelImage& motion, const ChannelImage& nextAlpha)
{
    AdvectionCheck c;
    c.advected = meanAbsDifference(forwardWarp(alpha, motion).image, nextAlpha);
    c.still = meanAbsDifference(alpha, nextAlpha);
    return c;
}

} // namespace turb
