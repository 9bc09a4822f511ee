// Interface compression and level-set diffusion of a density (DensityShaping.h).
#include <turb/DensityShaping.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace turb {

namespace {

// Index arithmetic on a Field's dense box (z fastest), neighbours clamped to the box (constant extension).
struct Grid
{
    int nx, ny, nz;
    explicit Grid(const ScalarField& f) : nx(f.dim().x()), ny(f.dim().y()), nz(f.dim().z()) {}
    size_t at(int x, int y, int z) const
    {
        x = std::clamp(x, 0, nx - 1);
        y = std::clamp(y, 0, ny - 1);
        z = std::clamp(z, 0, nz - 1);
        return (size_t(x) * size_t(ny) + size_t(y)) * size_t(nz) + size_t(z);
    }
    int axes() const { return nz > 1 ? 3 : 2; } // one z layer: a 2D field
};

// [1 2 1]/4 along each axis, twice: the smoothed copy whose gradient gives the surface's direction.
ScalarField smoothed(const ScalarField& f, const Grid& g)
{
    ScalarField s = f, tmp = f;
    for (int pass = 0; pass < 2; ++pass)
        for (int a = 0; a < g.axes(); ++a) {
            tmp.values() = s.values();
            parallelFor(size_t(g.nx), 1, [&](size_t x0, size_t x1) {
                for (int x = int(x0); x < int(x1); ++x)
                    for (int y = 0; y < g.ny; ++y)
                        for (int z = 0; z < g.nz; ++z) {
                            std::array<int, 3> lo{x, y, z}, hi{x, y, z};
                            lo[size_t(a)] -= 1;
                            hi[size_t(a)] += 1;
                            s.data()[g.at(x, y, z)] =
                                0.25f * (tmp.data()[g.at(lo[0], lo[1], lo[2])] + 2.0f * tmp.data()[g.at(x, y, z)] +
                                            tmp.data()[g.at(hi[0], hi[1], hi[2])]);
                        }
            });
        }
    return s;
}

} // namespace

void compressInterface(ScalarField& density, float c, float peak)
{
    if (!(c >= 0.0f && c <= 1.0f)) throw ValueError("interface compression must lie in [0, 1]");
    if (!(peak > 0.0f)) throw ValueError("interface compression needs a peak density > 0");
    if (c == 0.0f || density.empty()) return;
    const Grid g(density);
    const ScalarField S = smoothed(density, g);
    const float* D = density.data();
    const float* s = S.data();
    const auto flux = [&](float d) {
        const float a = std::clamp(d / peak, 0.0f, 1.0f);
        return a * (1.0f - a) * peak;
    };
    // The flux through the face between voxel p and its +a neighbour q, toward increasing S: n_a from S's gradient
    // at the face (the difference across it, the mean of the central differences of p and q along it). Computed
    // alike from either side, so what leaves one voxel enters the other, bit for bit.
    const auto faceFlux = [&](int x, int y, int z, int a) -> float {
        std::array<int, 3> p{x, y, z}, q{x, y, z};
        q[size_t(a)] += 1;
        const size_t ip = g.at(p[0], p[1], p[2]), iq = g.at(q[0], q[1], q[2]);
        if (ip == iq) return 0.0f; // the box's face: nothing leaves
        const float carried = 0.5f * (flux(D[ip]) + flux(D[iq]));
        if (carried == 0.0f) return 0.0f; // air (most of the box) or the peak: no flux, no gradient needed
        double grad[3];
        for (int k = 0; k < 3; ++k) {
            if (k == a) {
                grad[k] = double(s[iq]) - double(s[ip]);
                continue;
            }
            if (k >= g.axes()) {
                grad[k] = 0.0;
                continue;
            }
            std::array<int, 3> pl = p, ph = p, ql = q, qh = q;
            pl[size_t(k)] -= 1;
            ph[size_t(k)] += 1;
            ql[size_t(k)] -= 1;
            qh[size_t(k)] += 1;
            grad[k] = 0.25 * (double(s[g.at(ph[0], ph[1], ph[2])]) - double(s[g.at(pl[0], pl[1], pl[2])]) +
                                 double(s[g.at(qh[0], qh[1], qh[2])]) - double(s[g.at(ql[0], ql[1], ql[2])]));
        }
        const double len = std::sqrt(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2]);
        if (!(len > 1e-6 * double(peak))) return 0.0f;
        return c * float(grad[a] / len) * carried;
    };
    ScalarField out = density;
    parallelFor(size_t(g.nx), 1, [&](size_t x0, size_t x1) {
        for (int x = int(x0); x < int(x1); ++x)
            for (int y = 0; y < g.ny; ++y)
                for (int z = 0; z < g.nz; ++z) {
                    float change = 0.0f;
                    const std::array<int, 3> p{x, y, z};
                    for (int a = 0; a < g.axes(); ++a) {
                        std::array<int, 3> m = p;
                        m[size_t(a)] -= 1;
                        change -= faceFlux(x, y, z, a);                                // out through the +a face
                        if (p[size_t(a)] > 0) change += faceFlux(m[0], m[1], m[2], a); // in through the -a face
                    }
                    float& v = out.data()[g.at(x, y, z)];
                    v = std::max(0.0f, v + change);
                }
    });
    density = std::move(out);
}

void diffuseAlongLevelSets(ScalarField& density, float k, int passes)
{
    if (!(k >= 0.0f && k <= 1.0f / 6.0f)) throw ValueError("level-set diffusion must lie in [0, 1/6]");
    if (passes < 0) throw ValueError("level-set diffusion passes must be >= 0");
    if (k == 0.0f || density.empty()) return;
    const Grid g(density);
    const int axes = g.axes();
    for (int pass = 0; pass < passes; ++pass) {
        const ScalarField S = smoothed(density, g);
        ScalarField out = density;
        const float* D = density.data();
        parallelFor(size_t(g.nx), 1, [&](size_t x0, size_t x1) {
            for (int x = int(x0); x < int(x1); ++x)
                for (int y = 0; y < g.ny; ++y)
                    for (int z = 0; z < g.nz; ++z) {
                        const std::array<int, 3> p{x, y, z};
                        const auto val = [&](const float* f, int da, int a, int db, int b) {
                            std::array<int, 3> q = p;
                            q[size_t(a)] += da;
                            q[size_t(b)] += db;
                            return double(f[g.at(q[0], q[1], q[2])]);
                        };
                        const double d0 = D[g.at(x, y, z)];
                        // Air with air all around (most of the box) has nothing to diffuse.
                        bool any = d0 != 0.0;
                        for (int a = 0; a < axes && !any; ++a)
                            any = val(D, 1, a, 0, a) != 0.0 || val(D, -1, a, 0, a) != 0.0;
                        if (!any) continue;
                        double n[3] = {0.0, 0.0, 0.0};
                        for (int a = 0; a < axes; ++a)
                            n[a] = 0.5 * (val(S.data(), 1, a, 0, a) - val(S.data(), -1, a, 0, a));
                        const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
                        if (!(len > 1e-6)) continue; // no surface here: nothing to even out along
                        for (double& v : n) v /= len;
                        double lap = 0.0, nHn = 0.0;
                        for (int a = 0; a < axes; ++a) {
                            const double haa = val(D, 1, a, 0, a) + val(D, -1, a, 0, a) - 2.0 * d0;
                            lap += haa;
                            nHn += n[a] * n[a] * haa;
                            for (int b = a + 1; b < axes; ++b) {
                                const double hab = 0.25 * (val(D, 1, a, 1, b) - val(D, 1, a, -1, b) -
                                                              val(D, -1, a, 1, b) + val(D, -1, a, -1, b));
                                nHn += 2.0 * n[a] * n[b] * hab;
                            }
                        }
                        out.data()[g.at(x, y, z)] = float(std::max(0.0, d0 + double(k) * (lap - nHn)));
                    }
        });
        density = std::move(out);
    }
}

} // namespace turb
