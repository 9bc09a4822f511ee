// The detail's energy inside the smoke, and the factor that calibrates it (DetailEnergy).
#include "Stages.h"
#include "Align.h"

#include <turb/Operators.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace turb::detail {

SmokeEnergy::SmokeEnergy(const ScalarField& d, float th) : density(d), threshold(th), voxels(0)
{
    for (float v : d.values()) voxels += v > th;
}

double SmokeEnergy::operator()(const VectorField& u, const VectorField* less) const
{
    if (voxels == 0) return 0.0;
    // Inside the smoke, where the turbulence is seen (and measured).
    const double sum = parallelSum(u.size(), 1 << 16, [&](size_t b, size_t e) {
        double acc = 0.0;
        for (size_t n = b; n < e; ++n)
            if (density.data()[n] > threshold)
                acc += double((less ? u.data()[n] - less->data()[n] : u.data()[n]).lengthSqr());
        return acc;
    });
    return sum / double(voxels);
}

double energyFactor(double reference, double now)
{
    // Bounded: a large factor would mean the pipeline lost the detail, not something to amplify.
    return now > 0.0 ? std::clamp(std::sqrt(reference / now), 1.0 / 3.0, 3.0) : 1.0;
}

std::vector<double> patchRms(
    const VectorField& detail, const ScalarField& density, float threshold, const PatchLayout& layout)
{
    std::vector<double> sum(layout.patchCount(), 0.0), cnt(layout.patchCount(), 0.0);
    // Serial, in a fixed order: the same sums at any thread count. The patch of each coordinate, once per axis.
    const CoordBBox b = detail.bbox();
    std::array<std::vector<int>, 3> patch;
    for (int a = 0; a < 3; ++a) {
        patch[size_t(a)].resize(size_t(b.dim()[a]));
        for (int i = 0; i < b.dim()[a]; ++i) {
            Coord c = b.min();
            c[a] += i;
            patch[size_t(a)][size_t(i)] = layout.patchOf(c)[a];
        }
    }
    size_t n = 0;
    for (int x = 0; x < b.dim().x(); ++x)
        for (int y = 0; y < b.dim().y(); ++y)
            for (int z = 0; z < b.dim().z(); ++z, ++n) {
                if (!(density.data()[n] > threshold)) continue;
                const Coord P(patch[0][size_t(x)], patch[1][size_t(y)], patch[2][size_t(z)]);
                if (P.x() < 0 || P.y() < 0 || P.z() < 0 || P.x() >= layout.count.x() || P.y() >= layout.count.y() ||
                    P.z() >= layout.count.z())
                    continue;
                const size_t p = layout.patchIndex(P);
                sum[p] += double(detail.data()[n].lengthSqr());
                cnt[p] += 1.0;
            }
    for (size_t p = 0; p < sum.size(); ++p) sum[p] = cnt[p] > 0.0 ? std::sqrt(sum[p] / cnt[p]) : 0.0;
    return sum;
}

void applyPatchGain(VectorField& detail, const std::vector<float>& gain, const PatchLayout& layout)
{
    // Trilinear between patch centres is separable: each axis's lower patch and weight, once per coordinate.
    const CoordBBox b = detail.bbox();
    const Coord e = layout.extent();
    std::array<std::vector<int>, 3> lower;
    std::array<std::vector<float>, 3> weight;
    for (int a = 0; a < 3; ++a) {
        const int n = b.dim()[a];
        lower[size_t(a)].resize(size_t(n));
        weight[size_t(a)].resize(size_t(n));
        for (int i = 0; i < n; ++i) {
            const double u = (double(b.min()[a] + i - layout.origin[a]) + 0.5) / double(e[a]) - 0.5;
            const int i0 = int(std::floor(u));
            lower[size_t(a)][size_t(i)] = i0;
            weight[size_t(a)][size_t(i)] = float(u - i0);
        }
    }
    // The gains with one clamped layer around them, so the eight reads below need no bounds: index p + 1.
    const Coord c = layout.count, g2 = c + Coord(2);
    std::vector<float> padded(size_t(g2.x()) * size_t(g2.y()) * size_t(g2.z()));
    for (int x = 0; x < g2.x(); ++x)
        for (int y = 0; y < g2.y(); ++y)
            for (int z = 0; z < g2.z(); ++z)
                padded[(size_t(x) * size_t(g2.y()) + size_t(y)) * size_t(g2.z()) + size_t(z)] =
                    gain[layout.patchIndex(Coord(std::clamp(x - 1, 0, c.x() - 1), std::clamp(y - 1, 0, c.y() - 1),
                        std::clamp(z - 1, 0, c.z() - 1)))];
    for (int a = 0; a < 3; ++a)
        for (int& i0 : lower[size_t(a)]) i0 = std::clamp(i0 + 1, 0, g2[a] - 2); // a corner pair inside the padding
    const auto at = [&](int x, int y, int z) {
        return padded[(size_t(x) * size_t(g2.y()) + size_t(y)) * size_t(g2.z()) + size_t(z)];
    };
    const int ny = b.dim().y(), nz = b.dim().z();
    parallelFor(size_t(b.dim().x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int px = lower[0][x];
            const float wx = weight[0][x];
            for (int y = 0; y < ny; ++y) {
                const int py = lower[1][size_t(y)];
                const float wy = weight[1][size_t(y)];
                Vec3f* row = &detail.data()[(x * size_t(ny) + size_t(y)) * size_t(nz)];
                for (int z = 0; z < nz; ++z) {
                    const int pz = lower[2][size_t(z)];
                    const float wz = weight[2][size_t(z)];
                    float g = 0.0f;
                    for (int corner = 0; corner < 8; ++corner) {
                        const int bx = corner & 1, by = (corner >> 1) & 1, bz = (corner >> 2) & 1;
                        g += (bx ? wx : 1.0f - wx) * (by ? wy : 1.0f - wy) * (bz ? wz : 1.0f - wz) *
                             at(px + bx, py + by, pz + bz);
                    }
                    row[z] *= g;
                }
            }
        }
    });
}

void matchPatchStrength(VectorField& detail, const std::vector<double>& pastedRms, const SmokeEnergy& smoke,
    const PatchLayout& layout, float strength)
{
    const std::vector<double> now = patchRms(detail, smoke.density, smoke.threshold, layout);
    std::vector<float> gain(now.size(), 1.0f);
    for (size_t p = 0; p < now.size(); ++p)
        if (now[p] > 0.0 && pastedRms[p] > 0.0)
            gain[p] = float(std::clamp(std::pow(pastedRms[p] / now[p], double(strength)), 1.0 / 3.0, 3.0));
    const double before = smoke(detail);
    applyPatchGain(detail, gain, layout);
    const double after = smoke(detail);
    if (after > 0.0)
        for (auto& v : detail.values()) v *= float(std::sqrt(before / after));
}

void keepCoarseMeans(VectorField& detail, const VectorField& before, int f)
{
    VectorField change(detail.bbox(), detail.lattice());
    for (size_t n = 0; n < change.size(); ++n) change.data()[n] = detail.data()[n] - before.data()[n];
    const VectorField c = cropped(upsample(coarsePart(change, f), f), detail.bbox());
    for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] -= c.data()[n];
}

double evenPatchStrength(
    VectorField& detail, const ScalarField& density, float threshold, const PatchLayout& layout, float strength)
{
    const int B = layout.size;
    const int axes = layout.flat ? 2 : 3;
    double worst = 0.0;
    for (int pass = 0; pass < 2; ++pass) {
        // Mean |U_h|^2 over the smoke by the voxel's position in its patch, along each axis: the detail's variance,
        // which a variance-preserving blend keeps even. Serial sums in a fixed order: the same result at any thread
        // count. (Evening |curl U_h|^2, the lattice number's own statistic, put block over 1.05 on the paper's pair.)
        std::vector<std::vector<double>> sum(size_t(axes), std::vector<double>(size_t(B), 0.0)),
            cnt(size_t(axes), std::vector<double>(size_t(B), 0.0));
        double all = 0.0, voxels = 0.0;
        const CoordBBox box = detail.bbox();
        const auto residue = [&](int a, int i) { return size_t(((box.min()[a] + i - layout.origin[a]) % B + B) % B); };
        size_t n = 0;
        for (int x = 0; x < box.dim().x(); ++x)
            for (int y = 0; y < box.dim().y(); ++y)
                for (int z = 0; z < box.dim().z(); ++z, ++n) {
                    if (!(density.data()[n] > threshold)) continue;
                    const double e = double(detail.data()[n].lengthSqr());
                    const size_t r[3] = {residue(0, x), residue(1, y), residue(2, z)};
                    for (int a = 0; a < axes; ++a) {
                        sum[size_t(a)][r[a]] += e;
                        cnt[size_t(a)][r[a]] += 1.0;
                    }
                    all += e;
                    voxels += 1.0;
                }
        if (!(all > 0.0)) return worst;
        const double mean = all / voxels;
        std::vector<std::vector<float>> gain(size_t(axes), std::vector<float>(size_t(B), 1.0f));
        double dev = 0.0;
        for (int a = 0; a < axes; ++a) {
            std::vector<double> g(size_t(B), 1.0);
            for (int r = 0; r < B; ++r) {
                const double m =
                    cnt[size_t(a)][size_t(r)] > 0.0 ? sum[size_t(a)][size_t(r)] / cnt[size_t(a)][size_t(r)] : mean;
                g[size_t(r)] = m > 0.0 ? std::clamp(std::sqrt(mean / m), 0.5, 2.0) : 1.0;
                dev = std::max(dev, std::abs(std::log(g[size_t(r)])));
                g[size_t(r)] = std::pow(g[size_t(r)], double(strength));
            }
            // A circular 1-2-1 smoothing: the gain has no step where one patch meets the next.
            for (int r = 0; r < B; ++r)
                gain[size_t(a)][size_t(r)] =
                    float(0.25 * g[size_t((r + B - 1) % B)] + 0.5 * g[size_t(r)] + 0.25 * g[size_t((r + 1) % B)]);
        }
        // Only a clear lattice is evened (a shot's first frames: 1.3-1.4 on the Blender pairs at frame 1): the
        // 2-10% modulation of later frames is left, since scaling it every frame put block at 1.06 from frame 7 of
        // the farm test's pair, while 1.01 without.
        if (pass == 0) worst = std::exp(dev);
        if (pass == 0 && worst < kEvenPatchesFrom) return worst;
        parallelFor(detail.size(), 1 << 14, [&](size_t lo, size_t hi) {
            for (size_t n = lo; n < hi; ++n) {
                const Coord c = detail.coordOf(n);
                float g = 1.0f;
                for (int a = 0; a < axes; ++a) g *= gain[size_t(a)][size_t(((c[a] - layout.origin[a]) % B + B) % B)];
                detail.data()[n] *= g;
            }
        });
    }
    return worst;
}

size_t limitVorticity(VectorField& detail, const VectorField& Ut, const ScalarField& density, float threshold, double cap)
{
    if (!(cap > 0.0)) return 0;
    const CoordBBox b = detail.bbox();
    size_t over = 0;
    for (int pass = 0; pass < 1; ++pass) {
        VectorField u(b, detail.lattice());
        parallelFor(u.size(), 1 << 14, [&](size_t lo, size_t hi) {
            for (size_t n = lo; n < hi; ++n) u.data()[n] = Ut.data()[n] + detail.data()[n];
        });
        const VectorField w = curl(u);
        // The hot voxels are few (tens in a frame of the Blender pairs), so the gain is made around them only.
        std::vector<std::pair<size_t, float>> hot;
        for (size_t n = 0; n < w.size(); ++n) {
            const double m = double(w.data()[n].length());
            if (density.data()[n] > threshold && m > cap) hot.emplace_back(n, float(cap / m));
        }
        if (pass == 0) over = hot.size();
        if (hot.empty()) break;
        // The smallest gain of the 3^3 neighbourhood, then a 3^3 mean: the whole hot spot is scaled, smoothly, so no
        // new gradient (and vorticity) is made at its edge. Away from hot voxels both are exactly 1.
        ScalarField least(b, detail.lattice(), 1.0f);
        const auto around = [&](const Coord& c, int r, const auto& fn) {
            for (int di = -r; di <= r; ++di)
                for (int dj = -r; dj <= r; ++dj)
                    for (int dk = -r; dk <= r; ++dk)
                        if (b.isInside(c + Coord(di, dj, dk))) fn(c + Coord(di, dj, dk));
        };
        for (const auto& h : hot) {
            const float g = h.second; // a named copy: clang-14 does not capture structured bindings
            around(detail.coordOf(h.first), 1, [&](const Coord& q) { least[q] = std::min(least[q], g); });
        }
        std::vector<uint8_t> done(detail.size(), 0);
        for (const auto& [n, g] : hot)
            around(detail.coordOf(n), 2, [&](const Coord& q) {
                const size_t k = detail.offset(q.x(), q.y(), q.z());
                if (done[k]) return;
                done[k] = 1;
                float sum = 0.0f;
                int count = 0;
                around(q, 1, [&](const Coord& r) {
                    sum += least[r];
                    ++count;
                });
                detail.data()[k] *= sum / float(count);
            });
    }
    return over;
}

} // namespace turb::detail
