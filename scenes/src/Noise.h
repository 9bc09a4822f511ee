#pragma once
// Seeded hashing and 2D value noise for the built-in scenes: pure functions of (seed, position), so a scene is
// the same at any thread count. Internal to turb_scenes.

#include <cmath>
#include <cstdint>

namespace turb::scenes::detail {

/// SplitMix64's finaliser (Steele, Lea and Flood, "Fast splittable pseudorandom number generators").
inline std::uint64_t splitmix(std::uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

/// Smooth value noise in [0, 1) at pixel (x, y), lattice period `cell` pixels (> 0), smoothstep-interpolated.
inline double valueNoise2D(double x, double y, double cell, std::uint64_t seed)
{
    const double fx = x / cell, fy = y / cell;
    const long ix = long(std::floor(fx)), iy = long(std::floor(fy));
    const double tx = fx - ix, ty = fy - iy;
    const auto v = [&](long a, long b) {
        return double(
                   splitmix(seed ^ splitmix(std::uint64_t(a) * 73856093ull ^ std::uint64_t(b) * 19349663ull)) >> 11) /
               9007199254740992.0;
    };
    const auto s = [](double t) { return t * t * (3.0 - 2.0 * t); };
    const double a = v(ix, iy) + (v(ix + 1, iy) - v(ix, iy)) * s(tx);
    const double b = v(ix, iy + 1) + (v(ix + 1, iy + 1) - v(ix, iy + 1)) * s(tx);
    return a + (b - a) * s(ty);
}

} // namespace turb::scenes::detail
