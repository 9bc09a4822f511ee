// The structure metrics of Measure.h: the detail's anisotropy along the flow, its isotropy, the patch lattice in its
// strength, and the peak vorticity. Kept apart from Measure.cc: most need their own frequency split.
#include <turb/Measure.h>

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

namespace turb {

namespace {

using Mask = std::vector<unsigned char>;

// The bodies below take the detail H = splitFrequencies(u, f).high: detailStructure splits once for all three.

// N sums of per-voxel terms over the masked voxels of H's box: terms(i, j, k, sums) adds to them. Summed per x slab
// and then in slab order: deterministic at any thread count.
template<size_t N, class Terms>
std::array<double, N> maskedSums(const VectorField& H, const Mask& mask, const Terms& terms)
{
    const CoordBBox& b = H.bbox();
    std::vector<std::array<double, N>> part(size_t(b.dim().x()), std::array<double, N>{});
    parallelFor(part.size(), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int i = b.min().x() + int(x);
            for (int j = b.min().y(); j <= b.max().y(); ++j)
                for (int k = b.min().z(); k <= b.max().z(); ++k)
                    if (mask[H.offset(i, j, k)]) terms(i, j, k, part[x]);
        }
    });
    std::array<double, N> sum{};
    for (const auto& p : part)
        for (size_t a = 0; a < N; ++a) sum[a] += p[a];
    return sum;
}

std::optional<double> anisotropyOf(const VectorField& H, const Mask& mask, const Vec3d& direction)
{
    if (!(direction.length() > 0.0)) return std::nullopt;
    const Vec3d d = direction / direction.length();
    // along, all, voxels
    const auto sums = maskedSums<3>(H, mask, [&](int i, int j, int k, std::array<double, 3>& s) {
        const Jacobian J = jacobianAt(H, i, j, k);
        const Vec3f along = J.d[0] * float(d.x()) + J.d[1] * float(d.y()) + J.d[2] * float(d.z());
        s[0] += double(along.lengthSqr());
        s[1] += double(J.frobeniusSq());
        s[2] += 1.0;
    });
    // Two directions across the flow in 3D, one in 2D (a flat field has no z derivatives).
    const double across = isFlat(H.bbox()) ? sums[1] - sums[0] : 0.5 * (sums[1] - sums[0]);
    if (sums[2] == 0.0 || !(across > 0.0)) return std::nullopt;
    return sums[0] / across;
}

std::optional<double> scaleOf(const VectorField& H, const Mask& mask)
{
    // mean |H|^2 and mean |grad H|^2, as sums over the same voxels
    const auto sums = maskedSums<2>(H, mask, [&](int i, int j, int k, std::array<double, 2>& s) {
        s[0] += double(H(i, j, k).lengthSqr());
        s[1] += double(jacobianAt(H, i, j, k).frobeniusSq());
    });
    if (!(sums[1] > 0.0)) return std::nullopt;
    return std::sqrt(sums[0] / sums[1]);
}

std::optional<double> isotropyOf(const VectorField& H, const Mask& mask, int block)
{
    const CoordBBox& b = H.bbox();
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
                if (!mask[H.offset(c.x(), c.y(), c.z())]) continue;
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

std::optional<double> latticeOf(const VectorField& H, const Mask& mask, int patch)
{
    const CoordBBox& b = H.bbox();
    // Folds at the periods P-1, P, P+1 along each axis: bins[period][axis][residue] = {sum e, count}.
    const int periods[3] = {patch - 1, patch, patch + 1};
    const size_t stride = size_t(patch + 1) * 2;
    const size_t perSlab = 9 * stride;
    std::vector<double> part(size_t(b.dim().x()) * perSlab, 0.0);
    parallelFor(size_t(b.dim().x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            double* acc = part.data() + x * perSlab;
            const int i = b.min().x() + int(x);
            for (int j = b.min().y(); j <= b.max().y(); ++j)
                for (int k = b.min().z(); k <= b.max().z(); ++k) {
                    if (!mask[H.offset(i, j, k)]) continue;
                    const double e = double(jacobianAt(H, i, j, k).curl().lengthSqr());
                    const Coord c(i, j, k);
                    for (int p = 0; p < 3; ++p)
                        for (int a = 0; a < 3; ++a) {
                            // The residue from the box's corner: a cyclic shift of the patch origin's residues,
                            // which leaves their variance unchanged.
                            const int r = (c[a] - b.min()[a]) % periods[p];
                            double* bin = acc + (size_t(p) * 3 + size_t(a)) * stride + size_t(r) * 2;
                            bin[0] += e;
                            bin[1] += 1.0;
                        }
                }
        }
    });
    std::vector<double> sum(perSlab, 0.0);
    for (size_t x = 0; x < size_t(b.dim().x()); ++x)
        for (size_t n = 0; n < perSlab; ++n) sum[n] += part[x * perSlab + n];
    double total = 0.0, count = 0.0;
    for (int r = 0; r < periods[1]; ++r) {
        total += sum[stride + size_t(r) * 2];
        count += sum[stride + size_t(r) * 2 + 1];
    }
    if (count == 0.0 || !(total > 0.0)) return std::nullopt;
    const double mean = total / count;
    // V_P: variance over residues of the bin means, over mean^2, averaged over the axes that hold two periods.
    double V[3] = {0.0, 0.0, 0.0};
    int axes = 0;
    for (int a = 0; a < 3; ++a) {
        if (b.dim()[a] < 2 * periods[2]) continue;
        ++axes;
        for (int p = 0; p < 3; ++p) {
            std::vector<double> m;
            for (int r = 0; r < periods[p]; ++r) {
                const double* bin = sum.data() + (size_t(p) * 3 + size_t(a)) * stride + size_t(r) * 2;
                if (bin[1] > 0.0) m.push_back(bin[0] / bin[1]);
            }
            if (m.size() < 2) continue;
            double mm = 0.0, var = 0.0;
            for (double v : m) mm += v;
            mm /= double(m.size());
            for (double v : m) var += (v - mm) * (v - mm);
            V[p] += var / double(m.size()) / (mean * mean);
        }
    }
    if (axes == 0) return std::nullopt;
    for (double& v : V) v /= double(axes);
    return std::sqrt(std::max(0.0, V[1] - 0.5 * (V[0] + V[2])));
}

void checkMask(const VectorField& u, const Mask& mask, const char* who)
{
    if (mask.size() != u.size()) throw ValueError(std::string(who) + ": mask and field sizes differ");
}

void checkPatch(int patch, const char* who)
{
    if (patch < 3) throw ValueError(std::string(who) + ": patch size must be >= 3, got " + std::to_string(patch));
}

} // namespace

std::optional<double> detailAnisotropy(const VectorField& u, const Mask& mask, int f, const Vec3d& direction)
{
    checkMask(u, mask, "detailAnisotropy");
    return anisotropyOf(splitFrequencies(u, f).high, mask, direction);
}

std::optional<double> highBandScale(const VectorField& H, const Mask& mask)
{
    checkMask(H, mask, "highBandScale");
    return scaleOf(H, mask);
}

std::optional<double> highBandAnisotropy(const VectorField& H, const Mask& mask, const Vec3d& direction)
{
    checkMask(H, mask, "highBandAnisotropy");
    return anisotropyOf(H, mask, direction);
}

std::optional<double> detailIsotropy(const VectorField& u, const Mask& mask, int f, int block)
{
    checkMask(u, mask, "detailIsotropy");
    if (block < 2) throw ValueError("detailIsotropy: block must be >= 2");
    return isotropyOf(splitFrequencies(u, f).high, mask, block);
}

std::optional<double> latticeImprint(const VectorField& u, const Mask& mask, int f, int patch)
{
    checkMask(u, mask, "latticeImprint");
    checkPatch(patch, "latticeImprint");
    return latticeOf(splitFrequencies(u, f).high, mask, patch);
}

DetailStructure detailStructure(const VectorField& u, const Mask& mask, int f, const Vec3d& direction, int patch)
{
    checkMask(u, mask, "detailStructure");
    if (patch != 0) checkPatch(patch, "detailStructure");
    const VectorField H = splitFrequencies(u, f).high;
    DetailStructure d;
    d.aniso = anisotropyOf(H, mask, direction);
    d.isotropy = isotropyOf(H, mask, 8);
    d.scale = scaleOf(H, mask);
    if (patch != 0) d.lattice = latticeOf(H, mask, patch);
    return d;
}

std::optional<double> vorticityPeak(const VectorField& u, const std::vector<unsigned char>& mask, double quantile)
{
    checkMask(u, mask, "vorticityPeak");
    if (!(quantile >= 0.0 && quantile <= 1.0)) throw ValueError("vorticityPeak: quantile must lie in [0, 1]");
    const CoordBBox& b = u.bbox();
    std::vector<float> w;
    for (int i = b.min().x(); i <= b.max().x(); ++i)
        for (int j = b.min().y(); j <= b.max().y(); ++j)
            for (int k = b.min().z(); k <= b.max().z(); ++k)
                if (mask[u.offset(i, j, k)]) w.push_back(jacobianAt(u, i, j, k).curl().length());
    if (w.empty()) return std::nullopt;
    const size_t n = std::min(w.size() - 1, size_t(quantile * double(w.size() - 1) + 0.5));
    std::nth_element(w.begin(), w.begin() + std::ptrdiff_t(n), w.end());
    return double(w[n]);
}

} // namespace turb
