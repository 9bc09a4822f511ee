// The energy spectrum (Spectrum.h) of known fields: a single mode's peak, Parseval's identity.
#include <turb/Spectrum.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

using namespace turb;

TEST(Spectrum, SingleFourierModePeaksAtItsWavenumber)
{
    const double h = 0.1;
    // A non-cubic box: 32 x 24 x 20 voxels, padded to 32^3, so dk = 2 pi / 3.2.
    const CoordBBox box({0, 0, 0}, {31, 23, 19});
    const auto modeField = [&](int axis, int periods, int extent) {
        VectorField u(box, Lattice{h, {0.0, 0.0, 0.0}});
        for (size_t n = 0; n < u.size(); ++n) {
            const Coord c = u.coordOf(n);
            const double phase = 2.0 * M_PI * periods * (c[axis] + 0.5) / extent + 0.3;
            u.data()[n] = Vec3f(0.0f, float(std::sin(phase)), 0.5f); // a mean flow too: removed first
        }
        return u;
    };
    const auto peak = [](const Spectrum& s) {
        return size_t(std::max_element(s.energy.begin(), s.energy.end()) - s.energy.begin());
    };
    const Spectrum sx = energySpectrum(modeField(0, 5, 32), box);
    EXPECT_EQ(sx.fftSide, 32);
    EXPECT_NEAR(sx.dk, 2.0 * M_PI / 3.2, 1e-12);
    EXPECT_NEAR(sx.k[peak(sx)], 5 * sx.dk, 1e-9);
    // 5 periods over the 20-voxel z extent: k = 2 pi 5 / 2.0 = 8 dk.
    const Spectrum sz = energySpectrum(modeField(2, 5, 20), box);
    EXPECT_NEAR(sz.k[peak(sz)], 2.0 * M_PI * 5 / 2.0, 1e-9);
    // Energy: 1/2 mean sin^2 = 1/4, the window's loss divided out.
    EXPECT_NEAR(sx.meanEnergy, 0.25, 0.01);
}

TEST(Spectrum, ParsevalOnAPeriodicBandLimitedField)
{
    const int n = 24;
    const double h = 0.05;
    const CoordBBox box({0, 0, 0}, {n - 1, n - 1, n - 1});
    VectorField u(box, Lattice{h, {0.0, 0.0, 0.0}});
    double e = 0.0;
    for (size_t q = 0; q < u.size(); ++q) {
        const Vec3d x = u.coordOf(q).asVec3d() * (2.0 * M_PI / n);
        // Modes (3,4,0), (0,0,4), (0,7,-5): shells 5, 4 and 9.
        u.data()[q] = Vec3f(float(std::sin(3 * x.x() + 4 * x.y())), float(0.5 * std::cos(4 * x.z())),
            float(0.2 * std::sin(7 * x.y() - 5 * x.z())));
        e += 0.5 * double(u.data()[q].lengthSqr());
    }
    e /= double(u.size());
    SpectrumSettings s;
    s.window = SpectrumSettings::Window::None;
    const Spectrum sp = energySpectrum(u, box, s);
    double sum = 0.0;
    for (double v : sp.energy) sum += v * sp.dk;
    EXPECT_NEAR(sp.meanEnergy, e, 1e-5 * e);
    EXPECT_NEAR(sum, e, 1e-4 * e); // every mode lies inside the Nyquist sphere
    // Shell 4 holds the y component's 1/2 * 0.5^2 / 2, shell 5 the x component's 1/2 * 1/2.
    EXPECT_NEAR(sp.energy[3] * sp.dk, 0.0625, 1e-5);
    EXPECT_NEAR(sp.energy[4] * sp.dk, 0.25, 1e-5);
    EXPECT_NEAR(sp.energy[2] * sp.dk, 0.0, 1e-6);
    EXPECT_EQ(fftFriendlySize(97), 98);
    EXPECT_EQ(fftFriendlySize(121), 125);
}
