// Resampling between lattices (Resample.h): up- and downsampling, the frequency split, integer and non-integer ratios.
#include <turb/Error.h>
#include <turb/Resample.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

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
        u.data()[n] =
            Vec3f(std::sin(2.3f * c.x()) + 0.1f * c.y(), std::cos(1.7f * c.z()), float((c.x() * 7 + c.y() * 3) % 5));
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
    const auto linear = [](const Vec3d& x) {
        return Vec3f(float(1.0 + 2.0 * x.x() - x.y()), float(0.5 * x.z()), float(x.x() + x.y() + x.z()));
    };
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
    const Vec3d newLo = r.lattice().indexToWorld(r.bbox().min().asVec3d()),
                newHi = r.lattice().indexToWorld(r.bbox().max().asVec3d());
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
