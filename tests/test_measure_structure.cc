// The structure metrics (MeasureStructure.cc, declared in Measure.h): the detail's anisotropy along a direction and
// its direction-free isotropy, on plane-wave noise with and without a stretch.
#include <turb/Measure.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

using namespace turb;

namespace {

// Smooth isotropic noise: a sum of random plane waves with wavelengths between 3 and 6 voxels, sampled at
// (x, y, z / zStretch): zStretch > 1 stretches every structure along z.
VectorField planeWaveNoise(const CoordBBox& box, unsigned seed, double zStretch)
{
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0), len(3.0, 6.0), ph(0.0, 6.2831853);
    struct Wave
    {
        Vec3d k, a;
        double phase;
    };
    std::vector<Wave> waves;
    for (int i = 0; i < 60; ++i) {
        Vec3d dir(u(rng), u(rng), u(rng));
        dir.normalize();
        waves.push_back({dir * (6.2831853 / len(rng)), Vec3d(u(rng), u(rng), u(rng)), ph(rng)});
    }
    VectorField f(box, Lattice{});
    for (size_t n = 0; n < f.size(); ++n) {
        const Coord c = f.coordOf(n);
        const Vec3d x(c.x(), c.y(), c.z() / zStretch);
        Vec3d v(0.0);
        for (const Wave& w : waves) v += w.a * std::sin(w.k.dot(x) + w.phase);
        f.data()[n] = Vec3f(float(v.x()), float(v.y()), float(v.z()));
    }
    return f;
}

} // namespace

TEST(MeasureStructure, IsotropicNoiseIsNearOneAndStretchedNoiseFarBelow)
{
    const CoordBBox box({0, 0, 0}, {47, 47, 47});
    const std::vector<unsigned char> all(size_t(48 * 48 * 48), 1);
    const Vec3d up(0.0, 0.0, 1.0), side(1.0, 0.0, 0.0);
    const VectorField iso = planeWaveNoise(box, 3, 1.0), streaks = planeWaveNoise(box, 3, 4.0);
    const auto aIso = detailAnisotropy(iso, all, 4, up), aSide = detailAnisotropy(iso, all, 4, side);
    const auto aStreaks = detailAnisotropy(streaks, all, 4, up);
    ASSERT_TRUE(aIso && aSide && aStreaks);
    EXPECT_NEAR(*aIso, 1.0, 0.2);
    EXPECT_NEAR(*aSide, 1.0, 0.2);
    EXPECT_LT(*aStreaks, 0.25) << "4x stretch along the flow";
    // Across the stretch the structure is squashed relative to the rest: above 1 when looking along x.
    EXPECT_GT(*detailAnisotropy(streaks, all, 4, side), 1.0);
    EXPECT_FALSE(detailAnisotropy(iso, all, 4, Vec3d(0.0)));
}

TEST(MeasureStructure, IsotropyIsHighForNoiseAndLowForStreaksAlongAnyAxis)
{
    const CoordBBox box({0, 0, 0}, {47, 47, 47});
    const std::vector<unsigned char> all(size_t(48 * 48 * 48), 1);
    const VectorField iso = planeWaveNoise(box, 5, 1.0), alongZ = planeWaveNoise(box, 5, 4.0);
    // The same streaks turned to run along x: a direction-free measure must see them too.
    VectorField alongX(box, Lattice{});
    for (size_t n = 0; n < alongX.size(); ++n) {
        const Coord c = alongX.coordOf(n);
        const Vec3f v = alongZ(c.z(), c.y(), c.x());
        alongX.data()[n] = Vec3f(v.z(), v.y(), v.x());
    }
    const auto a = detailIsotropy(iso, all, 4), b = detailIsotropy(alongZ, all, 4), c = detailIsotropy(alongX, all, 4);
    ASSERT_TRUE(a && b && c);
    EXPECT_GT(*a, 0.4);
    EXPECT_LT(*b, 0.5 * *a);
    EXPECT_NEAR(*c, *b, 0.02);
    // Tiles need half their voxels in the mask.
    EXPECT_FALSE(detailIsotropy(iso, std::vector<unsigned char>(all.size(), 0), 4));
}
