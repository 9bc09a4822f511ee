// Previews: analytic checks of the density render, slices and LIC.
#include "TestUtil.h"

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Render.h>

#include <cmath>
#include <cstring>

using namespace turb;

namespace {

const Lattice kLat{1.0 / 32.0, {0.0, 0.0, 0.0}};

/// A ball of density 1 with a one-voxel linear edge centred on radius r (voxels).
ScalarField ball(const CoordBBox& box, const Vec3d& centre, double r)
{
    ScalarField d(box, kLat);
    for (size_t q = 0; q < d.size(); ++q) {
        const double dist = (d.coordOf(q).asVec3d() - centre).length();
        d.data()[q] = float(std::min(1.0, std::max(0.0, r + 0.5 - dist)));
    }
    return d;
}

float diff(const Rgb& a, const Rgb& b)
{
    return std::max({std::abs(a.x() - b.x()), std::abs(a.y() - b.y()), std::abs(a.z() - b.z())});
}

struct Disc
{
    double area = 0, cx = 0, cy = 0;
    double radius() const { return std::sqrt(area / M_PI); }
};

/// Pixels brighter than `threshold` (red channel).
Disc discOf(const Image& img, float threshold)
{
    Disc d;
    for (int y = 0; y < img.height(); ++y)
        for (int x = 0; x < img.width(); ++x)
            if (img.at(x, y).x() > threshold) {
                d.area += 1;
                d.cx += x + 0.5;
                d.cy += y + 0.5;
            }
    if (d.area > 0) {
        d.cx /= d.area;
        d.cy /= d.area;
    }
    return d;
}

} // namespace

TEST(Render, EmptyVolumeRendersTheBackground)
{
    const ScalarField empty(CoordBBox({0, 0, 0}, {15, 11, 23}), kLat);
    DensityRenderSettings s;
    s.background = Rgb(0.1f, 0.2f, 0.3f);
    for (View v : {View::Front, View::Side, View::Top}) {
        s.view = v;
        const Image img = renderDensity(empty, s);
        ASSERT_FALSE(img.empty());
        for (const auto& p : img.pixels()) ASSERT_EQ(p, s.background);
    }
}

TEST(Render, SphereRendersADiscOfItsRadiusWhereItIs)
{
    // 40 x 32 x 48 voxels, ball of radius 9 voxels centred above the middle: every view shows a disc
    // of radius 9 voxels = 36 pixels at 4 pixels per voxel, centred where the ball projects.
    const CoordBBox box({0, 0, 0}, {39, 31, 47});
    const Vec3d c(22.0, 15.5, 30.0);
    const double r = 9.0;
    const ScalarField d = ball(box, c, r);
    // Uniform unit emission on a black background makes a pixel tone(opacity), so the disc of
    // opacity > 1/2 is where the optical depth exceeds ln 2. Through a sharp ball of optical depth
    // 1 per voxel that is b < sqrt(R^2 - 0.12) = R - 0.007 voxels: the sphere's radius. The ball's
    // one-voxel edge ramp and trilinear reconstruction blur the edge by up to a voxel, which bounds
    // the tolerance (measured: +0.48 voxel).
    DensityRenderSettings s;
    s.extinction = 32.0f; // 1 per voxel
    s.light = Rgb(0.0f);
    s.ambient = Rgb(1.0f);
    s.albedo = 1.0f;
    s.background = Rgb(0.0f);
    const float halfOpacity = std::pow(1.0f - std::exp(-0.5f), 1.0f / 2.2f);
    const double ppv = 4.0;
    struct Expect
    {
        View view;
        int width;
        double cx, cy; // pixels
    };
    const Expect cases[] = {
        {View::Front, 160, (c.x() + 0.5) * ppv, (47.5 - c.z()) * ppv}, // x right, z up
        {View::Side, 128, (31.5 - c.y()) * ppv, (47.5 - c.z()) * ppv}, // -y right, z up
        {View::Top, 160, (c.x() + 0.5) * ppv, (31.5 - c.y()) * ppv},   // x right, y up
    };
    for (const auto& e : cases) {
        s.view = e.view;
        s.width = e.width;
        const Image img = renderDensity(d, s);
        EXPECT_NEAR(img.width() / ppv, double(box.dim()[e.view == View::Side ? 1 : 0]), 1e-9);
        const Disc disc = discOf(img, halfOpacity);
        EXPECT_NEAR(disc.radius(), r * ppv, 0.75 * ppv) << int(e.view);
        EXPECT_NEAR(disc.cx, e.cx, 0.5 * ppv) << int(e.view);
        EXPECT_NEAR(disc.cy, e.cy, 0.5 * ppv) << int(e.view);
    }
}

TEST(Render, ExposureIsFixedNotNormalisedPerFrame)
{
    // Adding smoke elsewhere must not change how the first puff looks (no per-frame normalisation),
    // and a thinner puff must look thinner.
    const CoordBBox box({0, 0, 0}, {31, 15, 31});
    const ScalarField a = ball(box, Vec3d(8, 8, 8), 4);
    ScalarField b = a, thin = a;
    const ScalarField other = ball(box, Vec3d(24, 8, 24), 4);
    for (size_t q = 0; q < b.size(); ++q) {
        b.data()[q] += 3.0f * other.data()[q];
        thin.data()[q] *= 0.2f;
    }
    DensityRenderSettings s;
    s.toLight = Vec3d(0.0, -1.0, 0.0); // lit from the camera side: the puffs do not shadow each other
    const Image ia = renderDensity(a, s), ib = renderDensity(b, s), it = renderDensity(thin, s);
    const int px = int(8.5 * 4), py = int((31.5 - 8) * 4);
    EXPECT_EQ(ia.at(px, py), ib.at(px, py));
    EXPECT_GT(diff(ia.at(px, py), s.background), diff(it.at(px, py), s.background) + 0.05f);
}

TEST(Render, DensityRenderIsBitIdenticalAtOneAndTwoThreads)
{
    const ScalarField d = ball(CoordBBox({0, 0, 0}, {23, 23, 35}), Vec3d(11, 12, 15), 7);
    Image a, b;
    withThreads(1, [&] { a = renderDensity(d); });
    withThreads(2, [&] { b = renderDensity(d); });
    ASSERT_EQ(a.pixels().size(), b.pixels().size());
    EXPECT_EQ(0, std::memcmp(a.pixels().data(), b.pixels().data(), a.pixels().size() * sizeof(Rgb)));
}

TEST(Render, SliceMapsValuesToTheColourMapLeftToRight)
{
    // f = x index: a front-view slice runs from the map's first colour at the left to its last.
    ScalarField f(CoordBBox({0, 0, 0}, {15, 7, 7}), kLat);
    for (size_t q = 0; q < f.size(); ++q) f.data()[q] = float(f.coordOf(q).x());
    SliceSettings s;
    s.minValue = 0.0f;
    s.maxValue = 15.0f;
    s.width = 64;
    const Image img = renderSlice(f, s);
    EXPECT_EQ(img.height(), 32);
    const float eps = 0.02f;
    EXPECT_LT(diff(img.at(0, 10), colormap(Colormap::Viridis, 0.0f)), eps);
    EXPECT_LT(diff(img.at(63, 10), colormap(Colormap::Viridis, 1.0f)), eps);
    EXPECT_LT(diff(img.at(32, 3), colormap(Colormap::Viridis, (32.0f / 4.0f - 0.5f) / 15.0f)), eps);
}

TEST(Render, LicStreaksFollowTheFlow)
{
    // Uniform flow along +x: the texture is smooth along rows and noisy across them; along +z the
    // other way round. Where the flow is zero, un-integrated noise with reduced contrast remains.
    const CoordBBox box({0, 0, 0}, {31, 3, 31});
    for (int axis : {0, 2}) {
        VectorField u(box, kLat);
        for (auto& v : u.values()) {
            v = Vec3f(0.0f);
            v[axis] = 1.0f;
        }
        LicSettings s;
        s.colourBySpeed = false;
        s.width = 128;
        const Image img = renderLic(u, s);
        double along = 0, across = 0;
        for (int y = 1; y < img.height() - 1; ++y)
            for (int x = 1; x < img.width() - 1; ++x) {
                const float c = img.at(x, y).x();
                const float h = std::abs(img.at(x + 1, y).x() - c), v = std::abs(img.at(x, y + 1).x() - c);
                along += axis == 0 ? h : v;
                across += axis == 0 ? v : h;
            }
        EXPECT_LT(along, 0.4 * across) << axis;
    }
    const VectorField still(box, kLat);
    LicSettings s;
    s.colourBySpeed = false;
    const Image img = renderLic(still, s);
    float lo = 1, hi = 0;
    for (const auto& p : img.pixels()) {
        lo = std::min(lo, p.x());
        hi = std::max(hi, p.x());
    }
    EXPECT_GE(lo, 0.5f - 0.18f);
    EXPECT_LE(hi, 0.5f + 0.18f);
    EXPECT_GT(hi - lo, 0.2f);
}

TEST(Render, RejectsBadSettings)
{
    const ScalarField d(CoordBBox({0, 0, 0}, {3, 3, 3}), kLat);
    DensityRenderSettings s;
    s.toLight = Vec3d(0.0);
    EXPECT_THROW(renderDensity(d, s), ValueError);
    EXPECT_THROW(renderDensity(ScalarField(), DensityRenderSettings{}), ValueError);
}
