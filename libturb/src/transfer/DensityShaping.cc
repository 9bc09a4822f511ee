// Interface compression and level-set diffusion of a density (DensityShaping.h).
#include <turb/DensityShaping.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <vector>

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
    // The same indices without the clamp, for voxels whose neighbours all lie in the box (inner()): most of them.
    size_t stride(int a) const { return a == 0 ? size_t(ny) * size_t(nz) : a == 1 ? size_t(nz) : 1; }
    bool inner(int x, int y, int z) const
    {
        return x > 0 && x < nx - 1 && y > 0 && y < ny - 1 && (nz == 1 || (z > 0 && z < nz - 1));
    }
};

// A box of index coordinates (inclusive) inside the field's dense box: where a pass can change anything.
struct Region
{
    std::array<int, 3> lo{0, 0, 0}, hi{-1, -1, -1};
    bool empty() const { return hi[0] < lo[0]; }
    // Grown by r voxels along each axis of the field, clamped to its box.
    Region grown(int r, const Grid& g) const
    {
        Region o = *this;
        if (empty()) return o;
        const int n[3] = {g.nx, g.ny, g.nz};
        for (int a = 0; a < 3; ++a) {
            o.lo[size_t(a)] = std::max(0, lo[size_t(a)] - r);
            o.hi[size_t(a)] = std::min(n[a] - 1, hi[size_t(a)] + r);
        }
        return o;
    }
};

// The box of the non-zero voxels. Shaping leaves air with air all around as it is (zero in, zero out), and the
// held box around a frame's smoke is mostly air: passes confined to this box, grown by their reach, give the same
// values as passes over the whole box, in a fraction of the time.
Region smokeRegion(const ScalarField& f, const Grid& g)
{
    std::vector<Region> perX(size_t(g.nx));
    parallelFor(size_t(g.nx), 1, [&](size_t x0, size_t x1) {
        for (int x = int(x0); x < int(x1); ++x) {
            Region& r = perX[size_t(x)];
            for (int y = 0; y < g.ny; ++y) {
                const float* row = f.data() + g.at(x, y, 0);
                for (int z = 0; z < g.nz; ++z)
                    if (row[z] != 0.0f) {
                        if (r.empty()) r.lo = r.hi = {x, y, z};
                        r.lo = {std::min(r.lo[0], x), std::min(r.lo[1], y), std::min(r.lo[2], z)};
                        r.hi = {std::max(r.hi[0], x), std::max(r.hi[1], y), std::max(r.hi[2], z)};
                    }
            }
        }
    });
    Region all;
    for (const Region& r : perX) {
        if (r.empty()) continue;
        if (all.empty()) {
            all = r;
            continue;
        }
        for (size_t a = 0; a < 3; ++a) {
            all.lo[a] = std::min(all.lo[a], r.lo[a]);
            all.hi[a] = std::max(all.hi[a], r.hi[a]);
        }
    }
    return all;
}

// Runs body(x, y, z) over `r`, parallel over x.
template<typename Body>
void forEachIn(const Region& r, const Body& body)
{
    if (r.empty()) return;
    parallelFor(size_t(r.hi[0] - r.lo[0] + 1), 1, [&](size_t x0, size_t x1) {
        for (int x = r.lo[0] + int(x0); x < r.lo[0] + int(x1); ++x)
            for (int y = r.lo[1]; y <= r.hi[1]; ++y)
                for (int z = r.lo[2]; z <= r.hi[2]; ++z) body(x, y, z);
    });
}

// [1 2 1]/4 along each axis, twice: the smoothed copy whose gradient gives the surface's direction. Non-zero only
// within `smoke` (f's non-zero box) grown by 2, where it is computed; zero elsewhere, as f is.
ScalarField smoothed(const ScalarField& f, const Grid& g, const Region& smoke)
{
    ScalarField s = f, tmp = f;
    const Region r = smoke.grown(2, g);
    for (int pass = 0; pass < 2; ++pass)
        for (int a = 0; a < g.axes(); ++a) {
            tmp.values() = s.values();
            const size_t st = g.stride(a);
            const int n = a == 0 ? g.nx : a == 1 ? g.ny : g.nz;
            forEachIn(r, [&](int x, int y, int z) {
                const int along = a == 0 ? x : a == 1 ? y : z;
                if (along > 0 && along < n - 1) {
                    const size_t i = g.at(x, y, z);
                    s.data()[i] = 0.25f * (tmp.data()[i - st] + 2.0f * tmp.data()[i] + tmp.data()[i + st]);
                    return;
                }
                std::array<int, 3> lo{x, y, z}, hi{x, y, z};
                lo[size_t(a)] -= 1;
                hi[size_t(a)] += 1;
                s.data()[g.at(x, y, z)] =
                    0.25f * (tmp.data()[g.at(lo[0], lo[1], lo[2])] + 2.0f * tmp.data()[g.at(x, y, z)] +
                                tmp.data()[g.at(hi[0], hi[1], hi[2])]);
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
    const Region smoke = smokeRegion(density, g);
    const ScalarField S = smoothed(density, g, smoke);
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
        const bool inner = g.inner(p[0], p[1], p[2]) && g.inner(q[0], q[1], q[2]);
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
            if (inner) {
                const size_t st = g.stride(k);
                grad[k] = 0.25 * (double(s[ip + st]) - double(s[ip - st]) + double(s[iq + st]) - double(s[iq - st]));
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
    // A face carries flux only beside smoke: voxels beyond one of it keep their value.
    ScalarField out = density;
    forEachIn(smoke.grown(1, g), [&](int x, int y, int z) {
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
        // Air with air all around (most of the box) has nothing to diffuse: one voxel beyond the smoke at most.
        const Region smoke = smokeRegion(density, g);
        const ScalarField S = smoothed(density, g, smoke);
        ScalarField out = density;
        const float* D = density.data();
        const Region r = smoke.grown(1, g);
        parallelFor(r.empty() ? 0 : size_t(r.hi[0] - r.lo[0] + 1), 1, [&](size_t x0, size_t x1) {
            for (int x = r.lo[0] + int(x0); x < r.lo[0] + int(x1); ++x)
                for (int y = r.lo[1]; y <= r.hi[1]; ++y)
                    for (int z = r.lo[2]; z <= r.hi[2]; ++z) {
                        const std::array<int, 3> p{x, y, z};
                        const size_t i0 = g.at(x, y, z);
                        const bool inner = g.inner(x, y, z);
                        const auto val = [&](const float* f, int da, int a, int db, int b) {
                            if (inner)
                                return double(f[size_t(
                                    ptrdiff_t(i0) + da * ptrdiff_t(g.stride(a)) + db * ptrdiff_t(g.stride(b)))]);
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
