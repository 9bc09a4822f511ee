// Shared building blocks: resampling, finite differences, advection, images.
#include "TestUtil.h"

#include <turb/Advect.h>
#include <turb/Error.h>
#include <turb/Image.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>
#include <turb/RgbaImage.h>
#include <turbio/ImageIO.h>

#include <cmath>
#include <fstream>

using namespace turb;

namespace {

VectorField linearField(const CoordBBox& box, const Lattice& lat)
{
    VectorField u(box, lat);
    for (size_t n = 0; n < u.size(); ++n) {
        const Vec3d x = lat.indexToWorld(Vec3d(u.coordOf(n).asVec3d()));
        u.data()[n] = Vec3f(float(2 * x.x() - x.y() + 1), float(0.5 * x.z()), float(x.x() + 3 * x.y() - x.z()));
    }
    return u;
}

} // namespace

TEST(Resample, UpsampleIsExactOnLinearFieldsAwayFromTheEdge)
{
    const Lattice coarseLat{0.5, {1.0, -2.0, 0.25}};
    const CoordBBox cb({0, 0, 0}, {5, 4, 6});
    const VectorField c = linearField(cb, coarseLat);
    const int f = 4;
    const VectorField fine = upsample(c, f);
    EXPECT_EQ(fine.bbox(), refineBox(cb, f));
    const Lattice fl = fine.lattice();
    EXPECT_NEAR(fl.voxelSize, 0.125, 1e-12);
    // Fine voxels whose sample position lies inside the coarse voxel-centre hull are exact.
    for (size_t n = 0; n < fine.size(); ++n) {
        const Coord I = fine.coordOf(n);
        const Vec3d xc = coarseLat.worldToIndex(fl.indexToWorld(I.asVec3d()));
        bool inside = true;
        for (int a = 0; a < 3; ++a) inside &= xc[a] >= cb.min()[a] && xc[a] <= cb.max()[a];
        if (!inside) continue;
        const Vec3d x = fl.indexToWorld(I.asVec3d());
        const Vec3f expect(float(2 * x.x() - x.y() + 1), float(0.5 * x.z()), float(x.x() + 3 * x.y() - x.z()));
        ASSERT_NEAR((fine.data()[n] - expect).length(), 0.0f, 1e-4f) << I;
    }
}

TEST(Resample, BoxDownsampleAveragesBlocksAndLatticesNest)
{
    const Lattice fineLat{0.25, {0.0, 0.0, 0.0}};
    ScalarField f(CoordBBox({0, 0, 0}, {7, 7, 7}), fineLat);
    for (size_t n = 0; n < f.size(); ++n) f.data()[n] = float(f.coordOf(n).x());
    const ScalarField c = boxDownsample(f, 4);
    EXPECT_EQ(c.bbox(), CoordBBox({0, 0, 0}, {1, 1, 1}));
    EXPECT_FLOAT_EQ(c(0, 1, 1), 1.5f); // mean of x = 0..3
    EXPECT_FLOAT_EQ(c(1, 0, 0), 5.5f); // mean of x = 4..7
    // The coarse voxel's centre is the centre of its 4^3 fine voxels.
    const Vec3d centre = c.lattice().indexToWorld(Vec3d(0.0));
    EXPECT_NEAR((centre - fineLat.indexToWorld(Vec3d(1.5))).length(), 0.0, 1e-12);
    EXPECT_TRUE(c.lattice().refined(4).approxEqual(fineLat));
}

TEST(Resample, SplitSumsBackExactlyAndLowPartHasNoBlockDetail)
{
    const Lattice lat{0.1, {0.0, 0.0, 0.0}};
    VectorField u(CoordBBox({0, 0, 0}, {15, 15, 15}), lat);
    for (size_t n = 0; n < u.size(); ++n) {
        const Coord c = u.coordOf(n);
        u.data()[n] = Vec3f(std::sin(2.3f * c.x()) + 0.1f * c.y(), std::cos(1.7f * c.z()), float((c.x() * 7 + c.y() * 3) % 5));
    }
    const FrequencySplit s = splitFrequencies(u, 4);
    // Exact up to one float rounding of the subtraction.
    for (size_t n = 0; n < u.size(); ++n)
        for (int a = 0; a < 3; ++a)
            ASSERT_NEAR(s.low.data()[n][a] + s.high.data()[n][a], u.data()[n][a],
                4e-7f * (std::abs(u.data()[n][a]) + std::abs(s.low.data()[n][a])));
    // Low part is the trilinear interpolant of 4x4x4 means: re-splitting it moves little energy.
    const FrequencySplit again = splitFrequencies(s.low, 4);
    double eHigh = 0, eLowHigh = 0;
    for (size_t n = 0; n < u.size(); ++n) {
        eHigh += s.high.data()[n].lengthSqr();
        eLowHigh += again.high.data()[n].lengthSqr();
    }
    EXPECT_LT(eLowHigh, 0.1 * eHigh);
}

TEST(Resample, IntegerRatioRejectsBadRatios)
{
    EXPECT_EQ(integerRatio(0.125, 0.03125), 4);
    EXPECT_EQ(integerRatio(0.8, 0.1), 8);
    EXPECT_THROW(integerRatio(0.1, 0.03), ValueError);
    EXPECT_THROW(integerRatio(0.03125, 0.125), ValueError);
    EXPECT_TRUE(isIntegerRatio(0.125, 0.03125));
    EXPECT_TRUE(isIntegerRatio(0.1, 0.1 / 3.0));
    EXPECT_FALSE(isIntegerRatio(0.1, 0.04));
    EXPECT_EQ(nearestRatio(0.1, 0.04), 3); // 2.5 rounds half away from zero
    EXPECT_EQ(nearestRatio(0.1, 0.03), 3);
    EXPECT_EQ(nearestRatio(0.1, 0.08), 1);
    EXPECT_THROW(nearestRatio(0.03125, 0.125), ValueError);
}

TEST(Resample, ResamplingToAnotherVoxelSizeIsExactOnLinearFieldsAndNeverExtrapolates)
{
    const Lattice lat{0.04, {1.0, -2.0, 0.5}};
    const CoordBBox box({-3, 0, 2}, {20, 17, 25});
    const auto linear = [](const Vec3d& x) { return Vec3f(float(1.0 + 2.0 * x.x() - x.y()), float(0.5 * x.z()), float(x.x() + x.y() + x.z())); };
    VectorField u(box, lat);
    for (auto it = box.begin(); it; ++it) {
        const Coord c = *it;
        u(c.x(), c.y(), c.z()) = linear(lat.indexToWorld(c.asVec3d()));
    }
    const double voxel = 0.1 / 3.0; // a 0.1 target at ratio 2.5 brought to ratio 3
    const VectorField r = resampledToVoxel(u, voxel);
    EXPECT_DOUBLE_EQ(r.lattice().voxelSize, voxel);
    EXPECT_EQ(r.lattice().origin, lat.origin);
    // Every new centre lies inside the hull of the old centres, and the hull is covered to within a voxel.
    const Vec3d oldLo = lat.indexToWorld(box.min().asVec3d()), oldHi = lat.indexToWorld(box.max().asVec3d());
    const Vec3d newLo = r.lattice().indexToWorld(r.bbox().min().asVec3d()), newHi = r.lattice().indexToWorld(r.bbox().max().asVec3d());
    for (int a = 0; a < 3; ++a) {
        EXPECT_GE(newLo[a], oldLo[a] - 1e-9);
        EXPECT_LE(newHi[a], oldHi[a] + 1e-9);
        EXPECT_LT(newLo[a] - oldLo[a], voxel);
        EXPECT_LT(oldHi[a] - newHi[a], voxel);
    }
    double worst = 0.0;
    for (auto it = r.bbox().begin(); it; ++it) {
        const Coord c = *it;
        const Vec3f want = linear(r.lattice().indexToWorld(c.asVec3d()));
        worst = std::max(worst, double((r(c.x(), c.y(), c.z()) - want).length()));
    }
    EXPECT_LT(worst, 1e-4);
}

TEST(Operators, AnalyticDivergenceAndCurl)
{
    const Lattice lat{0.2, {0.0, 0.0, 0.0}};
    VectorField u(CoordBBox({0, 0, 0}, {9, 9, 9}), lat);
    VectorField w(u.bbox(), lat);
    for (size_t n = 0; n < u.size(); ++n) {
        const Vec3d x = lat.indexToWorld(u.coordOf(n).asVec3d());
        u.data()[n] = Vec3f(float(x.x()), float(x.y()), float(-2 * x.z())); // div 0
        w.data()[n] = Vec3f(float(-x.y()), float(x.x()), 0.0f);            // curl (0,0,2)
    }
    const ScalarField d = divergence(u);
    const VectorField c = curl(w);
    for (size_t n = 0; n < d.size(); ++n) {
        ASSERT_NEAR(d.data()[n], 0.0f, 1e-4f);
        ASSERT_NEAR((c.data()[n] - Vec3f(0, 0, 2)).length(), 0.0f, 1e-4f);
    }
}

TEST(Advect, ConstantVelocityTranslatesABlob)
{
    const Lattice lat{0.1, {0.0, 0.0, 0.0}};
    const CoordBBox box({0, 0, 0}, {31, 31, 31});
    ScalarField rho(box, lat);
    for (size_t n = 0; n < rho.size(); ++n) {
        const Vec3d x = rho.coordOf(n).asVec3d() - Vec3d(10.0, 12.0, 14.0);
        rho.data()[n] = float(std::exp(-x.lengthSqr() / 8.0));
    }
    // Velocity on a coarser lattice, as the target velocity is when advecting high-res detail.
    VectorField vel(CoordBBox({-1, -1, -1}, {9, 9, 9}), Lattice{0.4, {0.15, 0.15, 0.15}}, Vec3f(1.0f, 0.5f, 0.0f));
    const double dt = 0.5; // 5 voxels in x, 2.5 in y
    const auto centroid = [](const ScalarField& f) {
        Vec3d c(0.0);
        double m = 0;
        for (size_t n = 0; n < f.size(); ++n) {
            c += f.coordOf(n).asVec3d() * double(f.data()[n]);
            m += f.data()[n];
        }
        return std::make_pair(c / m, m);
    };
    const auto [c0, m0] = centroid(rho);
    ScalarField out1, out2;
    withThreads(1, [&] { out1 = advect(rho, vel, dt); });
    withThreads(2, [&] { out2 = advect(rho, vel, dt); });
    const auto [c1, m1] = centroid(out1);
    EXPECT_NEAR(c1.x() - c0.x(), 5.0, 0.1);
    EXPECT_NEAR(c1.y() - c0.y(), 2.5, 0.1);
    EXPECT_NEAR(c1.z() - c0.z(), 0.0, 0.05);
    EXPECT_NEAR(m1 / m0, 1.0, 0.02);
    EXPECT_EQ(out1.values(), out2.values()) << "advection must not depend on the thread count";
}

TEST(Image, CaptionsAreLabelsDrawnByTheIoLayer)
{
    Image a(40, 30, Rgb(0.2f)), b(20, 30, Rgb(0.8f));
    EXPECT_EQ(a.drawText(2, 2, "Ab1", Rgb(1.0f)), Image::textWidth("Ab1"));
    EXPECT_EQ(Image::textWidth("Ab1", 2), 36);
    ASSERT_EQ(a.texts().size(), 1u);
    EXPECT_EQ(a.at(3, 4), Rgb(0.2f)) << "libturb keeps captions as labels, not pixels";
    // Drawn with OpenImageIO's render_text: ink (anti-aliased, so compared with a tolerance) inside the
    // caption's box, none far from it, and the background untouched elsewhere.
    const Image drawn = turbio::withTextDrawn(a);
    EXPECT_TRUE(drawn.texts().empty());
    float inkInside = 0.0f, inkOutside = 0.0f;
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            const float ink = drawn.at(x, y).x() - 0.2f;
            ASSERT_GE(ink, -1e-5f);
            const bool inBox = x >= 1 && x <= 2 + Image::textWidth("Ab1") && y >= 1 && y <= 2 + 7 + 3;
            (inBox ? inkInside : inkOutside) += ink;
        }
    EXPECT_GT(inkInside, 8.0f) << "three glyphs of about 20 inked pixels each";
    EXPECT_LT(inkOutside, 0.05f * inkInside);

    // Captions move with blit and scale with upscaled.
    Image big(100, 100);
    big.blit(a, 10, 20);
    ASSERT_EQ(big.texts().size(), 1u);
    EXPECT_EQ(big.texts()[0].x, 12);
    EXPECT_EQ(big.texts()[0].y, 22);
    EXPECT_EQ(a.upscaled(3).texts()[0].scale, 3);

    const Image sheet = contactSheet({{{&a, "target"}, {&b, "source"}}}, {"f1"}, "title", 1);
    EXPECT_GT(sheet.width(), 60);
    EXPECT_GT(sheet.height(), 30);

    // A caption longer than its cell wraps inside the cell's column: the neighbour's column below the
    // pictures stays background, and the sheet grows taller instead.
    const Image wrapped = turbio::withTextDrawn(contactSheet({{{&b, "alpha 0.004 vorticity 0-403/s"}, {&b, ""}}}, {}, "", 1));
    const Image single = contactSheet({{{&b, "a"}, {&b, ""}}}, {}, "", 1);
    EXPECT_GT(wrapped.height(), single.height());
    const int pad = 6, secondX = pad + (b.width() + pad);
    for (int y = 30 + pad; y < wrapped.height(); ++y)
        for (int x = secondX - pad / 2 + 1; x < wrapped.width(); ++x)
            ASSERT_NEAR((wrapped.at(x, y) - Rgb(0.12f)).length(), 0.0f, 0.02f) << x << "," << y;
}

TEST(Image, RoundTripsThroughPngExrTiffAndJpeg)
{
    testutil::TempDir dir;
    Image grad(17, 9);
    for (int y = 0; y < 9; ++y)
        for (int x = 0; x < 17; ++x) grad.at(x, y) = Rgb(x / 16.0f, y / 8.0f, 0.5f);
    for (const char* name : {"g.png", "g.exr", "g.tif"}) {
        turbio::writeImage(dir / name, grad);
        const RgbaImage back = turbio::readImage(dir / name);
        ASSERT_EQ(back.width(), 17) << name;
        ASSERT_EQ(back.height(), 9) << name;
        const bool exr = std::string(name) == "g.exr";
        for (size_t i = 0; i < grad.pixels().size(); ++i)
            for (int c = 0; c < 3; ++c) {
                // The EXR holds the picture decoded to linear (sRGB curve): compare after re-encoding.
                float v = back.pixels()[i][c];
                if (exr) v = v <= 0.0031308f ? v * 12.92f : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
                ASSERT_NEAR(v, grad.pixels()[i][c], exr ? 2e-3f : 1.0f / 255.0f) << name;
            }
    }
    EXPECT_EQ(turbio::readImage(dir / "g.exr").colorSpace, "Linear");

    // Data images: straight alpha survives PNG, TIFF and the premultiplied EXR; a float EXR keeps values
    // outside [0, 1] (motion in pixels).
    RgbaImage rgba(5, 4);
    for (size_t i = 0; i < rgba.size(); ++i) rgba.pixels()[i] = Rgba(0.8f, 0.4f * float(i % 3), 0.1f, float(i) / 19.0f);
    for (const char* name : {"a.png", "a.tif", "a.exr"}) {
        turbio::writeImage(dir / name, rgba);
        turbio::ImageFileInfo info;
        const RgbaImage back = turbio::readImage(dir / name, &info);
        EXPECT_TRUE(info.hasAlpha) << name;
        EXPECT_EQ(info.associatedAlpha, std::string(name) == "a.exr") << name;
        for (size_t i = 1; i < rgba.size(); ++i) // pixel 0 has alpha 0: its colour is not kept by EXR
            ASSERT_NEAR((back.pixels()[i] - rgba.pixels()[i]).length(), 0.0f, std::string(name) == "a.png" ? 4e-3f : 2e-3f)
                << name << " pixel " << i;
    }
    RgbaImage flow(3, 2, Rgba(-12.5f, 3.25f, 0.0f, 1.0f));
    turbio::ImageWriteOptions fo;
    fo.bits = turbio::PixelBits::Float;
    fo.alpha = false;
    turbio::writeImage(dir / "flow.exr", flow, fo);
    EXPECT_EQ(turbio::readImage(dir / "flow.exr").at(2, 1), Rgba(-12.5f, 3.25f, 0.0f, 1.0f));
    turbio::writeImage(dir / "g.jpg", grad);
    EXPECT_EQ(turbio::inspectImage(dir / "g.jpg").channels, 3);

    // Errors name the file; nothing is left behind by a refused write.
    EXPECT_THROW(turbio::readImage(dir / "missing.png"), turb::IoError);
    { std::ofstream(dir / "junk.png") << "not a png"; }
    try {
        turbio::readImage(dir / "junk.png");
        ADD_FAILURE() << "junk accepted";
    } catch (const turb::IoError& e) {
        EXPECT_NE(std::string(e.what()).find("junk.png"), std::string::npos) << e.what();
    }
    EXPECT_THROW(turbio::writeImage(dir / "x.bmpx", grad), turb::ValueError);
    EXPECT_THROW(turbio::writeImage(dir / "h.png", rgba, turbio::ImageWriteOptions{false, turbio::PixelBits::Half}), turb::IoError);
    turbio::ImageWriteOptions keep;
    keep.noClobber = true;
    EXPECT_THROW(turbio::writeImage(dir / "g.png", grad, keep), turb::IoError);
    EXPECT_EQ(testutil::countEntries(dir.path()), 9u) << "no temporary files may remain";
}
