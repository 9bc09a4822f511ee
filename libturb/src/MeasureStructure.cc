// The structure metrics of Measure.h: the detail's anisotropy along the flow and its style distance to the source.
// Kept apart from Measure.cc: they need their own frequency split and, for the style distance, a patch index.
#include <turb/Measure.h>

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>

namespace turb {

std::optional<double> detailAnisotropy(
    const VectorField& u, const std::vector<unsigned char>& mask, int f, const Vec3d& direction)
{
    if (mask.size() != u.size()) throw ValueError("detailAnisotropy: mask and field sizes differ");
    if (!(direction.length() > 0.0)) return std::nullopt;
    const Vec3d d = direction / direction.length();
    const VectorField H = splitFrequencies(u, f).high;
    const CoordBBox& b = u.bbox();
    // Per x-slab sums, added in slab order: deterministic at any thread count.
    std::vector<std::array<double, 3>> part(size_t(b.dim().x()), {0.0, 0.0, 0.0});
    parallelFor(part.size(), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int i = b.min().x() + int(x);
            for (int j = b.min().y(); j <= b.max().y(); ++j)
                for (int k = b.min().z(); k <= b.max().z(); ++k) {
                    if (!mask[u.offset(i, j, k)]) continue;
                    const Jacobian J = jacobianAt(H, i, j, k);
                    const Vec3f along = J.d[0] * float(d.x()) + J.d[1] * float(d.y()) + J.d[2] * float(d.z());
                    part[x][0] += double(along.lengthSqr());
                    part[x][1] += double(J.frobeniusSq());
                    part[x][2] += 1.0;
                }
        }
    });
    double along = 0.0, all = 0.0, n = 0.0;
    for (const auto& p : part) {
        along += p[0];
        all += p[1];
        n += p[2];
    }
    // Two directions across the flow in 3D, one in 2D (a flat field has no z derivatives).
    const double across = isFlat(b) ? all - along : 0.5 * (all - along);
    if (n == 0.0 || !(across > 0.0)) return std::nullopt;
    return along / across;
}

std::optional<double> detailIsotropy(const VectorField& u, const std::vector<unsigned char>& mask, int f, int block)
{
    if (mask.size() != u.size()) throw ValueError("detailIsotropy: mask and field sizes differ");
    if (block < 2) throw ValueError("detailIsotropy: block must be >= 2");
    const VectorField H = splitFrequencies(u, f).high;
    const CoordBBox& b = u.bbox();
    const Coord n(
        (b.dim().x() + block - 1) / block, (b.dim().y() + block - 1) / block, (b.dim().z() + block - 1) / block);
    const bool flat = isFlat(b);
    const size_t tiles = size_t(n.x()) * size_t(n.y()) * size_t(n.z());
    std::vector<std::array<double, 2>> part(tiles, {0.0, 0.0}); // weight * isotropy, weight
    parallelFor(tiles, 16, [&](size_t t0, size_t t1) {
        for (size_t t = t0; t < t1; ++t) {
            const Coord T(int(t / (size_t(n.y()) * size_t(n.z()))), int((t / size_t(n.z())) % size_t(n.y())),
                int(t % size_t(n.z())));
            CoordBBox tile(b.min() + Coord(T.x() * block, T.y() * block, T.z() * block),
                b.min() + Coord(T.x() * block + block - 1, T.y() * block + block - 1, T.z() * block + block - 1));
            tile.intersect(b);
            Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
            size_t in = 0;
            for (auto it = tile.begin(); it; ++it) {
                const Coord c = *it;
                if (!mask[u.offset(c.x(), c.y(), c.z())]) continue;
                ++in;
                const Jacobian J = jacobianAt(H, c.x(), c.y(), c.z());
                for (int comp = 0; comp < 3; ++comp) {
                    const Eigen::Vector3d g(J.d[0][comp], J.d[1][comp], J.d[2][comp]);
                    S += g * g.transpose();
                }
            }
            if (2 * in < tile.volume()) continue;
            const double trace = S.trace();
            if (!(trace > 0.0)) continue;
            if (flat) {
                // 2D: gradients lie in the x-y plane; its 2x2 tensor's eigenvalue ratio (the z row is zero).
                Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(S.topLeftCorner<2, 2>(), Eigen::EigenvaluesOnly);
                const Eigen::Vector2d ev = eig.eigenvalues(); // ascending
                part[t] = {trace * std::max(0.0, ev(0)) / ev(1), trace};
                continue;
            }
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(S, Eigen::EigenvaluesOnly);
            const Eigen::Vector3d ev = eig.eigenvalues(); // ascending
            part[t] = {trace * std::max(0.0, ev(0)) / ev(2), trace};
        }
    });
    double num = 0.0, den = 0.0;
    for (const auto& p : part) {
        num += p[0];
        den += p[1];
    }
    if (!(den > 0.0)) return std::nullopt;
    return num / den;
}

} // namespace turb
