// Exact Euclidean distance transforms (Felzenszwalb & Huttenlocher 2012).
#include <turb/Distance.h>

#include <turb/Parallel.h>

#include <cmath>

namespace turb {

void squaredDistance1D(const double* f, int n, double* d, int* v, double* z)
{
    const double far = kNoSiteSquaredDistance;
    const auto meet = [&](int q, int p) { // where the parabolas rooted at q and p intersect
        return ((f[q] + double(q) * q) - (f[p] + double(p) * p)) / (2.0 * q - 2.0 * p);
    };
    int k = 0;
    v[0] = 0;
    z[0] = -far;
    z[1] = far;
    for (int q = 1; q < n; ++q) {
        double s = meet(q, v[k]);
        while (s <= z[k] && k > 0) {
            --k;
            s = meet(q, v[k]);
        }
        if (s <= z[k]) { // k == 0: the new parabola lies below the first everywhere left of it
            v[0] = q;
            z[0] = -far;
            z[1] = far;
            continue;
        }
        ++k;
        v[k] = q;
        z[k] = s;
        z[k + 1] = far;
    }
    k = 0;
    for (int q = 0; q < n; ++q) {
        while (z[k + 1] < q) ++k;
        d[q] = double(q - v[k]) * double(q - v[k]) + f[v[k]];
    }
}

ScalarField distanceToSmoke(const ScalarField& density, float threshold)
{
    ScalarField out(density.bbox(), density.lattice());
    if (density.empty()) return out;
    const Coord dim = density.bbox().dim();
    const size_t nx = size_t(dim.x()), ny = size_t(dim.y()), nz = size_t(dim.z());
    std::vector<double> g(density.size());
    for (size_t n = 0; n < g.size(); ++n) g[n] = density.data()[n] > threshold ? 0.0 : kNoSiteSquaredDistance;
    // One pass along an axis: lines of `len` samples `stride` apart, starting at each of `starts`.
    const auto pass = [&](size_t lines, size_t len, size_t stride, auto start) {
        parallelFor(lines, 16, [&](size_t l0, size_t l1) {
            std::vector<double> f(len), d(len), z(len + 1);
            std::vector<int> v(len);
            for (size_t l = l0; l < l1; ++l) {
                const size_t s = start(l);
                for (size_t q = 0; q < len; ++q) f[q] = g[s + q * stride];
                squaredDistance1D(f.data(), int(len), d.data(), v.data(), z.data());
                for (size_t q = 0; q < len; ++q) g[s + q * stride] = d[q];
            }
        });
    };
    // Offsets are (i * ny + j) * nz + k (Field::offset).
    pass(nx * ny, nz, 1, [&](size_t l) { return l * nz; });
    pass(nx * nz, ny, nz, [&](size_t l) { return (l / nz) * ny * nz + l % nz; });
    pass(ny * nz, nx, ny * nz, [&](size_t l) { return l; });
    for (size_t n = 0; n < g.size(); ++n) out.data()[n] = float(std::sqrt(g[n]));
    return out;
}

} // namespace turb
