// A divergence-free random "turbulent" field for the transfer and seam tests.
#pragma once

#include <turb/Field.h>

#include <cmath>
#include <random>
#include <vector>

namespace testutil {

/// The curl of a vector potential built from random Fourier modes with wavelengths between `minWave` and
/// `maxWave` voxels (of the lattice it is sampled on).
struct Modes
{
    struct Mode
    {
        turb::Vec3d k, a;
        double phase;
    };
    std::vector<Mode> modes;
    Modes(int count, double minWave, double maxWave, unsigned seed, double voxel)
    {
        std::mt19937 rng(seed);
        std::uniform_real_distribution<double> u(-1.0, 1.0), len(minWave, maxWave), ph(0.0, 6.283185307);
        for (int i = 0; i < count; ++i) {
            turb::Vec3d dir(u(rng), u(rng), u(rng));
            dir.normalize();
            const double wave = len(rng) * voxel;
            Mode m{dir * (6.283185307 / wave), turb::Vec3d(u(rng), u(rng), u(rng)) * (wave / 6.283185307), ph(rng)};
            modes.push_back(m);
        }
    }
    // curl of sum a sin(k.x + phase) = sum (k x a) cos(k.x + phase)
    turb::Vec3f at(const turb::Vec3d& x) const
    {
        turb::Vec3d v(0.0);
        for (const auto& m : modes) v += m.k.cross(m.a) * std::cos(m.k.dot(x) + m.phase);
        return turb::Vec3f(float(v.x()), float(v.y()), float(v.z()));
    }
};

} // namespace testutil
