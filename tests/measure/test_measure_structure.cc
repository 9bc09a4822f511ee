// The structure metrics (MeasureStructure.cc, declared in Measure.h): the detail's anisotropy along a direction and
// its direction-free isotropy, on plane-wave noise with and without a stretch; the patch lattice in its strength and
// the peak vorticity.
#include <turb/Error.h>
#include <turb/Measure.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

using namespace turb;

namespace {

// Smooth isotropic noise: a sum of random plane waves with wavelengths between 3 and 6 voxels (times `scale`),
// sampled at (x, y, z / zStretch): zStretch > 1 stretches every structure along z.
VectorField planeWaveNoise(const CoordBBox& box, unsigned seed, double zStretch, double scale = 1.0)
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
        waves.push_back({dir * (6.2831853 / (scale * len(rng))), Vec3d(u(rng), u(rng), u(rng)), ph(rng)});
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

TEST(MeasureStructure, DetailScaleOfASineIsItsDiscreteWavelengthOverTwoPi)
{
    // H = (0, sin(k x), 0) at voxel size h: central differences give k' = sin(k h) / h, so the scale is
    // h / sin(k h) exactly over whole periods (masked off the one-sided faces). 2D (one z layer) and 3D alike.
    for (const int depth : {1, 6})
        for (const int period : {8, 16}) {
            const double h = 0.05, k = 2.0 * M_PI / (period * h);
            const CoordBBox box({0, 0, 0}, {63, 9, depth - 1});
            VectorField H(box, Lattice{h, Vec3d(0.0)});
            std::vector<unsigned char> mask(H.size(), 0);
            for (size_t n = 0; n < H.size(); ++n) {
                const Coord c = H.coordOf(n);
                H.data()[n] = Vec3f(0.0f, float(std::sin(k * h * c.x())), 0.0f);
                mask[n] = c.x() >= 8 && c.x() < 8 + 3 * period;
            }
            const auto l = highBandScale(H, mask);
            ASSERT_TRUE(l);
            EXPECT_NEAR(*l, h / std::sin(k * h), 1e-5) << "period " << period << ", depth " << depth;
        }
    // Finer detail reads smaller: the same waves at half the wavelengths (6-12 voxels against 12-24) give about half
    // the scale; a little more, as central differences see less of the shorter waves' gradient (sin(kh)/kh 0.83-0.95).
    const CoordBBox box({0, 0, 0}, {47, 47, 47});
    const std::vector<unsigned char> all(size_t(48 * 48 * 48), 1);
    const VectorField coarse = planeWaveNoise(box, 7, 1.0, 4.0), fine = planeWaveNoise(box, 7, 1.0, 2.0);
    const auto a = highBandScale(coarse, all), b = highBandScale(fine, all);
    ASSERT_TRUE(a && b);
    EXPECT_GT(*b / *a, 0.5);
    EXPECT_LT(*b / *a, 0.6);
    EXPECT_FALSE(highBandScale(VectorField(box, Lattice{}), all)) << "no gradient: undefined";
    EXPECT_THROW(highBandScale(coarse, std::vector<unsigned char>(10, 1)), ValueError);
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

TEST(MeasureStructure, LatticeIsNearZeroForNoiseAndFindsAModulationWithThePatchPeriod)
{
    const CoordBBox box({0, 0, 0}, {47, 47, 47});
    const std::vector<unsigned char> all(size_t(48 * 48 * 48), 1);
    const VectorField iso = planeWaveNoise(box, 7, 1.0);
    // The same noise 40% stronger and weaker with the position in every 8-voxel patch, along each axis:
    // w = prod_a (1 + A cos(2 pi I_a / 8)). e = |curl H|^2 follows w^2 (w varies slowly against the noise), whose
    // fold along one axis has mean 1 + A^2/2 and variance 2 A^2 + A^4/8, so lattice ~ sqrt(0.323) / 1.08 = 0.53.
    const double A = 0.4, k = 6.2831853 / 8.0;
    VectorField modulated = iso;
    for (size_t n = 0; n < modulated.size(); ++n) {
        const Coord c = modulated.coordOf(n);
        const double w =
            (1.0 + A * std::cos(k * c.x())) * (1.0 + A * std::cos(k * c.y())) * (1.0 + A * std::cos(k * c.z()));
        modulated.data()[n] *= float(w);
    }
    const auto none = latticeImprint(iso, all, 4, 8), found = latticeImprint(modulated, all, 4, 8);
    ASSERT_TRUE(none && found);
    EXPECT_LT(*none, 0.05);
    EXPECT_NEAR(*found, 0.53, 0.12);
    // A lattice of another size does not see it; the shift of the box does not matter.
    EXPECT_LT(*latticeImprint(modulated, all, 4, 6), 0.15);
    VectorField shifted(CoordBBox({3, 5, 7}, {50, 52, 54}), Lattice{});
    for (size_t n = 0; n < shifted.size(); ++n) shifted.data()[n] = modulated.data()[n];
    EXPECT_NEAR(*latticeImprint(shifted, all, 4, 8), *found, 1e-3); // float sums in another order
    // 2D: the one-layer z axis is left out, and the x-y folds still find it.
    const CoordBBox flat({0, 0, 0}, {63, 63, 0});
    VectorField flatMod(flat, Lattice{});
    const VectorField flatNoise = planeWaveNoise(flat, 9, 1.0);
    for (size_t n = 0; n < flatMod.size(); ++n) {
        const Coord c = flatMod.coordOf(n);
        const Vec3f v = flatNoise.data()[n];
        flatMod.data()[n] =
            Vec3f(v.x(), v.y(), 0.0f) * float((1.0 + A * std::cos(k * c.x())) * (1.0 + A * std::cos(k * c.y())));
    }
    const std::vector<unsigned char> flatAll(flatMod.size(), 1);
    const auto f2 = latticeImprint(flatMod, flatAll, 4, 8);
    ASSERT_TRUE(f2);
    EXPECT_GT(*f2, 0.3);
    EXPECT_FALSE(latticeImprint(iso, std::vector<unsigned char>(all.size(), 0), 4, 8));
    EXPECT_THROW(latticeImprint(iso, all, 4, 2), ValueError);
}

TEST(MeasureStructure, VorticityPeakOfASolidBodyRotationIsTwiceItsAngularVelocity)
{
    // u = Omega x x with Omega = (0.5, 0, 2): curl u = 2 Omega everywhere, exact for central and one-sided
    // differences alike (u is linear), in world units (voxel 0.25).
    VectorField u(CoordBBox({0, 0, 0}, {15, 15, 15}), Lattice{0.25, {0.0, 0.0, 0.0}});
    const Vec3d omega(0.5, 0.0, 2.0);
    for (size_t n = 0; n < u.size(); ++n) {
        const Vec3d x = u.lattice().indexToWorld(u.coordOf(n).asVec3d());
        const Vec3d v = omega.cross(x);
        u.data()[n] = Vec3f(float(v.x()), float(v.y()), float(v.z()));
    }
    std::vector<unsigned char> mask(u.size(), 1);
    EXPECT_NEAR(*vorticityPeak(u, mask, kVortPeakQuantile), 2.0 * omega.length(), 1e-4);
    // A hot spot in 1 voxel of 4096 is left out by the 0.999 quantile and found by the maximum.
    u(8, 8, 8) += Vec3f(0.0f, 10.0f, 0.0f);
    EXPECT_NEAR(*vorticityPeak(u, mask, kVortPeakQuantile), 2.0 * omega.length(), 1e-4);
    EXPECT_GT(*vorticityPeak(u, mask, 1.0), 10.0);
    EXPECT_FALSE(vorticityPeak(u, std::vector<unsigned char>(mask.size(), 0), 0.5));
    EXPECT_THROW(vorticityPeak(u, mask, 1.5), ValueError);
}
