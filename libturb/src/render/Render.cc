// Previews: density ray march with one shadowed light, colour-mapped slices, LIC.
#include <turb/Render.h>

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb {

namespace {

/// How a View maps index axes to the picture.
struct ViewAxes
{
    int depth, right, up;
    int depthSign, rightSign; // +1: along +axis
};

ViewAxes axesOf(View v)
{
    switch (v) {
    case View::Front: return {1, 0, 2, +1, +1};
    case View::Side: return {0, 1, 2, +1, -1};
    case View::Top: return {2, 0, 1, -1, +1};
    }
    return {1, 0, 2, +1, +1};
}

/// The image raster of a view: pixel centres mapped to continuous index coordinates.
struct Raster
{
    ViewAxes ax;
    CoordBBox box;
    int width = 0, height = 0;

    Raster(const CoordBBox& b, View v, int requestedWidth) : ax(axesOf(v)), box(b)
    {
        if (b.empty()) throw ValueError("render: empty field");
        const int dr = b.dim()[ax.right], du = b.dim()[ax.up];
        width = requestedWidth > 0 ? requestedWidth : std::max(64, 4 * dr);
        height = std::max(1, int(std::lround(double(width) * du / dr)));
    }
    /// Index coordinate along the right axis of pixel column px (voxel edges span the image).
    double rightAt(int px) const
    {
        const double lo = box.min()[ax.right] - 0.5, hi = box.max()[ax.right] + 0.5;
        const double t = (px + 0.5) / width;
        return ax.rightSign > 0 ? lo + t * (hi - lo) : hi - t * (hi - lo);
    }
    /// Index coordinate along the up axis of pixel row py (row 0 at the top).
    double upAt(int py) const
    {
        const double lo = box.min()[ax.up] - 0.5, hi = box.max()[ax.up] + 0.5;
        return hi - (py + 0.5) / height * (hi - lo);
    }
    Vec3d point(int px, int py, double depth) const
    {
        Vec3d p;
        p[ax.right] = rightAt(px);
        p[ax.up] = upAt(py);
        p[ax.depth] = depth;
        return p;
    }
    double depthAtFraction(double f) const
    {
        f = std::min(1.0, std::max(0.0, f));
        return box.min()[ax.depth] + f * (box.max()[ax.depth] - box.min()[ax.depth]);
    }
};

/// Shadow volume: transmittance from each voxel centre toward the light, by sweeping slices away from
/// the light along its dominant axis. Each voxel looks one slice back toward the light (bilinear in that
/// slice), so the cost is one pass over the volume whatever the direction.
ScalarField lightTransmittance(const ScalarField& rho, const Vec3d& toLight, double sigma)
{
    const CoordBBox& b = rho.bbox();
    Vec3d L = toLight;
    const double len = L.length();
    if (!(len > 0.0)) throw ValueError("renderDensity: toLight must be a nonzero direction");
    L /= len;
    int a = 0;
    for (int k = 1; k < 3; ++k)
        if (std::abs(L[k]) > std::abs(L[a])) a = k;
    const int u = (a + 1) % 3, v = (a + 2) % 3;
    const int dir = L[a] > 0 ? 1 : -1; // the light lies toward +a when dir = 1
    // One slice toward the light moves (du, dv) voxels sideways and ds world units along the ray.
    const double du = L[u] / std::abs(L[a]), dv = L[v] / std::abs(L[a]);
    const double ds = rho.lattice().voxelSize / std::abs(L[a]);

    ScalarField T(b, rho.lattice(), 1.0f);
    const int first = dir > 0 ? b.max()[a] : b.min()[a];
    const int last = dir > 0 ? b.min()[a] : b.max()[a];
    for (int s = first;; s -= dir) {
        const int up = s + dir; // the slice toward the light
        const bool haveUp = up >= b.min()[a] && up <= b.max()[a];
        parallelFor(size_t(b.dim()[u]), 4, [&](size_t r0, size_t r1) {
            for (size_t r = r0; r < r1; ++r) {
                const int iu = b.min()[u] + int(r);
                for (int iv = b.min()[v]; iv <= b.max()[v]; ++iv) {
                    Coord c;
                    c[a] = s;
                    c[u] = iu;
                    c[v] = iv;
                    float tUp = 1.0f, rhoUp = 0.0f;
                    if (haveUp) {
                        const double pu = iu + du, pv = iv + dv;
                        // Beyond the sides of the box the light ray leaves the smoke: fully lit.
                        if (pu >= b.min()[u] - 0.5 && pu <= b.max()[u] + 0.5 && pv >= b.min()[v] - 0.5 &&
                            pv <= b.max()[v] + 0.5) {
                            const double cu = std::min(std::max(pu, double(b.min()[u])), double(b.max()[u]));
                            const double cv = std::min(std::max(pv, double(b.min()[v])), double(b.max()[v]));
                            const int u0 = int(std::floor(cu)), v0 = int(std::floor(cv));
                            const int u1 = std::min(u0 + 1, b.max()[u]), v1 = std::min(v0 + 1, b.max()[v]);
                            const float fu = float(cu - u0), fv = float(cv - v0);
                            const auto at = [&](const ScalarField& f, int iu2, int iv2) {
                                Coord q;
                                q[a] = up;
                                q[u] = iu2;
                                q[v] = iv2;
                                return f[q];
                            };
                            const auto bil = [&](const ScalarField& f) {
                                return (1 - fu) * ((1 - fv) * at(f, u0, v0) + fv * at(f, u0, v1)) +
                                       fu * ((1 - fv) * at(f, u1, v0) + fv * at(f, u1, v1));
                            };
                            tUp = bil(T);
                            rhoUp = bil(rho);
                        }
                    }
                    const double tau = sigma * ds * 0.5 * (double(std::max(0.0f, rho[c])) + std::max(0.0f, rhoUp));
                    T[c] = tUp * float(std::exp(-tau));
                }
            }
        });
        if (s == last) break;
    }
    return T;
}

float toneCurve(float x) { return std::pow(1.0f - std::exp(-std::max(0.0f, x)), 1.0f / 2.2f); }

std::uint64_t hash64(std::uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

} // namespace

double pixelsPerUnit(const CoordBBox& box, double voxelSize, View view, int width)
{
    const Raster r(box, view, width);
    return r.width / (box.dim()[r.ax.right] * voxelSize);
}

Image renderDensity(const ScalarField& density, const DensityRenderSettings& s)
{
    if (!(s.extinction > 0.0f) || !(s.exposure > 0.0f))
        throw ValueError("renderDensity: extinction and exposure must be > 0");
    if (!(s.stepVoxels > 0.0f && s.stepVoxels <= 1.0f))
        throw ValueError("renderDensity: stepVoxels must lie in (0, 1]");
    CameraSettings cam;
    cam.view = s.view;
    cam.width = s.width;
    const CameraRays rays(s.camera ? *s.camera : cam, density.bbox(), density.lattice());
    const ScalarField T = lightTransmittance(density, s.toLight, s.extinction);

    Image img(rays.width(), rays.height());
    parallelFor(size_t(rays.height()), 1, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy) {
            const int py = int(yy);
            for (int px = 0; px < rays.width(); ++px) {
                Rgb radiance(0.0f);
                const float view = marchRay(density, rays.ray(px, py), s.stepVoxels, s.extinction,
                    [&](const Vec3d& p, float alpha, float transmittance) {
                        const float lit = sampleTrilinear(T, p);
                        const Rgb in = s.ambient + s.light * lit;
                        radiance += in * (transmittance * alpha * s.albedo);
                    });
                const Rgb c(toneCurve(radiance.x() * s.exposure), toneCurve(radiance.y() * s.exposure),
                    toneCurve(radiance.z() * s.exposure));
                img.at(px, py) = c + s.background * view;
            }
        }
    });
    return img;
}

Image renderSlice(const ScalarField& f, const SliceSettings& s)
{
    const Raster r(f.bbox(), s.view, s.width);
    const double depth = r.depthAtFraction(s.position);
    std::vector<float> values(size_t(r.width) * size_t(r.height));
    parallelFor(size_t(r.height), 4, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < r.width; ++x)
                values[y * size_t(r.width) + size_t(x)] = sampleTrilinear(f, r.point(x, int(y), depth));
    });
    float lo = s.minValue, hi = s.maxValue;
    if (hi <= lo) {
        hi = lo;
        for (float v : values) hi = std::max(hi, v);
    }
    const float inv = hi > lo ? 1.0f / (hi - lo) : 0.0f;
    Image img(r.width, r.height);
    for (size_t q = 0; q < values.size(); ++q) img.pixels()[q] = colormap(s.map, (values[q] - lo) * inv);
    return img;
}

Image renderLic(const VectorField& u, const LicSettings& s)
{
    if (!(s.length >= 1.0f)) throw ValueError("renderLic: length must be >= 1 pixel");
    const Raster r(u.bbox(), s.view, s.width);
    const double depth = r.depthAtFraction(s.position);
    const int W = r.width, H = r.height;
    // In-plane velocity per pixel, in picture directions (x right, y down).
    std::vector<Vec3f> flow(size_t(W) * size_t(H));
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < W; ++x) {
                const Vec3f v = sampleTrilinear(u, r.point(x, int(y), depth));
                flow[y * size_t(W) + size_t(x)] = Vec3f(v[r.ax.right] * float(r.ax.rightSign), -v[r.ax.up], 0.0f);
            }
    });
    float vmax = 0.0f;
    for (const auto& v : flow) vmax = std::max(vmax, v.length());
    const float zero = 1e-4f * vmax;
    std::vector<float> noise(flow.size());
    for (size_t q = 0; q < noise.size(); ++q)
        noise[q] = float(double(hash64(s.seed * 0x2545F4914F6CDD1Dull + q) >> 11) / 9007199254740992.0);

    const auto flowAt = [&](double x, double y) -> Vec3f {
        const int ix = int(std::floor(x)), iy = int(std::floor(y));
        if (ix < 0 || iy < 0 || ix >= W || iy >= H) return Vec3f(0.0f);
        return flow[size_t(iy) * size_t(W) + size_t(ix)];
    };
    const int L = int(std::lround(s.length));
    const float speedTop = s.maxSpeed > 0.0f ? s.maxSpeed : vmax;
    Image img(W, H);
    parallelFor(size_t(H), 2, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy) {
            const int py = int(yy);
            for (int px = 0; px < W; ++px) {
                const size_t q = size_t(py) * size_t(W) + size_t(px);
                const float speed = flow[q].length();
                float intensity;
                if (speed <= zero) {
                    intensity = 0.5f + (noise[q] - 0.5f) * 0.35f; // still air: faint raw noise
                } else {
                    double sum = noise[q], wsum = 1.0, w2 = 1.0;
                    for (int dir = -1; dir <= 1; dir += 2) {
                        double x = px + 0.5, y = py + 0.5;
                        for (int n = 1; n <= L; ++n) {
                            // Midpoint step of one pixel along the normalised flow.
                            Vec3f v = flowAt(x, y);
                            if (v.length() <= zero) break;
                            v.normalize();
                            Vec3f m = flowAt(x + 0.5 * dir * v.x(), y + 0.5 * dir * v.y());
                            if (m.length() <= zero) break;
                            m.normalize();
                            x += dir * m.x();
                            y += dir * m.y();
                            const int ix = int(std::floor(x)), iy = int(std::floor(y));
                            if (ix < 0 || iy < 0 || ix >= W || iy >= H) break;
                            const double w = 0.5 * (1.0 + std::cos(M_PI * n / (L + 1)));
                            sum += w * noise[size_t(iy) * size_t(W) + size_t(ix)];
                            wsum += w;
                            w2 += w * w;
                        }
                    }
                    // Averaging n noise samples shrinks their spread by sqrt(n): stretch it back.
                    const double nEff = wsum * wsum / w2;
                    intensity = float(0.5 + (sum / wsum - 0.5) * std::min(4.0, 0.9 * std::sqrt(nEff)));
                }
                intensity = std::min(1.0f, std::max(0.0f, intensity));
                Rgb c(intensity);
                if (s.colourBySpeed) {
                    const float t = speedTop > 0.0f ? std::min(1.0f, speed / speedTop) : 0.0f;
                    c = colormap(Colormap::Magma, 0.2f + 0.8f * t) * (0.25f + 0.95f * intensity);
                    for (int k = 0; k < 3; ++k) c[k] = std::min(1.0f, c[k]);
                }
                img.at(px, py) = c;
            }
        }
    });
    return img;
}

} // namespace turb
