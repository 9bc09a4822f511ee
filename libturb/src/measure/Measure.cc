#include <turb/Metadata.h>
#include <turb/Measure.h>

#include <turb/Distance.h>
#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace turb {

namespace {

using Mask = std::vector<unsigned char>;

// Sums of K quantities over x-slabs of `box`, combined in slab order (deterministic at any thread count).
template<size_t K, typename Fn>
std::array<double, K> slabSums(const CoordBBox& box, Fn fn)
{
    const size_t nx = size_t(box.dim().x());
    std::vector<std::array<double, K>> part(nx);
    parallelFor(nx, 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            part[x].fill(0.0);
            fn(box.min().x() + int(x), part[x]);
        }
    });
    std::array<double, K> total{};
    for (const auto& p : part)
        for (size_t k = 0; k < K; ++k) total[k] += p[k];
    return total;
}

// Trilinear sample at a continuous index position with VDB background semantics: taps outside the box
// are zero (so values fade to zero within one voxel outside the data instead of being extended).
template<typename T>
T sampleZeroOutside(const Field<T>& f, const Vec3d& p)
{
    int i0[3];
    double w[3];
    for (int a = 0; a < 3; ++a) {
        i0[a] = int(std::floor(p[a]));
        w[a] = p[a] - i0[a];
    }
    T sum = Field<T>::zeroValue();
    for (int c = 0; c < 8; ++c) {
        const int i = i0[0] + (c & 1), j = i0[1] + ((c >> 1) & 1), k = i0[2] + ((c >> 2) & 1);
        if (!f.contains(i, j, k)) continue;
        const double wt =
            ((c & 1) ? w[0] : 1 - w[0]) * (((c >> 1) & 1) ? w[1] : 1 - w[1]) * (((c >> 2) & 1) ? w[2] : 1 - w[2]);
        if (wt != 0.0) sum += f(i, j, k) * float(wt);
    }
    return sum;
}

bool nearInteger(double v, double tol = 1e-3) { return std::abs(v - std::round(v)) <= tol; }

// True when `to` voxels coincide with `from` voxels up to a whole-voxel shift, so that World alignment is
// a copy (a scale error of 1e-4 drifts by a hundredth of a voxel over a 128-voxel box).
bool nestsExactly(const Lattice& from, const Lattice& to)
{
    const Vec3d d = from.worldToIndex(to.indexToWorld(Vec3d(0.0)));
    return std::abs(to.voxelSize / from.voxelSize - 1.0) < 1e-4 && nearInteger(d.x()) && nearInteger(d.y()) &&
           nearInteger(d.z());
}

Mask thresholdMask(const ScalarField& density, const CoordBBox& box, float threshold)
{
    const ScalarField d = density.bbox() == box ? density : cropped(density, box);
    Mask m(d.size());
    for (size_t n = 0; n < d.size(); ++n) m[n] = d.data()[n] > threshold ? 1 : 0;
    return m;
}

size_t countMask(const Mask& m)
{
    size_t n = 0;
    for (unsigned char c : m) n += c;
    return n;
}

CoordBBox maskBBox(const CoordBBox& box, const Mask& m)
{
    CoordBBox b; // empty
    const Coord d = box.dim();
    for (size_t n = 0; n < m.size(); ++n)
        if (m[n]) {
            const int k = int(n % size_t(d.z()));
            const size_t r = n / size_t(d.z());
            b.expand(box.min() + Coord(int(r / size_t(d.y())), int(r % size_t(d.y())), k));
        }
    return b;
}

VectorField difference(const VectorField& a, const VectorField& b)
{
    VectorField out(a.bbox(), a.lattice());
    for (size_t n = 0; n < a.size(); ++n) out.data()[n] = a.data()[n] - b.data()[n];
    return out;
}

void requireVelocity(const Frame* f, const char* role)
{
    if (!f) throw ValueError(std::string("measure: no ") + role + " frame given");
    if (!f->hasVelocity())
        throw ValueError(
            std::string("measure: the ") + role + " frame " + std::to_string(f->number) + " has no velocity grid");
}

void requireDensity(const Frame& f, const char* role)
{
    if (!f.hasDensity())
        throw ValueError(std::string("measure: the ") + role + " frame " + std::to_string(f.number) +
                         " has no density grid; the smoke region (density > threshold) needs it");
}

int metadataInt(const Frame& f, const std::string& key, int fallback)
{
    auto it = f.metadata.find(key);
    if (it == f.metadata.end()) return fallback;
    char* end = nullptr;
    const long v = std::strtol(it->second.c_str(), &end, 10);
    return (end && end != it->second.c_str()) ? int(v) : fallback;
}

// "x,y,z" (or one number for all three axes).
Coord metadataCoord(const Frame& f, const std::string& key, const Coord& fallback)
{
    auto it = f.metadata.find(key);
    if (it == f.metadata.end()) return fallback;
    std::string t = it->second;
    for (char& ch : t)
        if (ch == ',') ch = ' ';
    std::istringstream is(t);
    int v[3];
    if (!(is >> v[0])) return fallback;
    if (!(is >> v[1] >> v[2])) v[1] = v[2] = v[0];
    return Coord(v[0], v[1], v[2]);
}

std::string fmt(double v)
{
    std::ostringstream os;
    os << v;
    return os.str();
}

// `q` advected through `velocity` over dt, wanted only on `region` and returned over `box`. Only the
// part of q that can reach `region` is advected: BFECC traces back, forward and back again (three
// travel distances) with one-voxel stencils, so a margin of 3 * travel + 4 voxels leaves the values in
// `region` as they would be from the whole box, at a fraction of the cost (smoke fills little of a domain).
VectorField advectOnto(const VectorField& q, const VectorField& velocity, double dt, const CoordBBox& region,
    const CoordBBox& box, const AdvectSettings& settings)
{
    if (region.empty()) return VectorField(box, q.lattice());
    double vmax = 0.0;
    for (const Vec3f& v : velocity.values()) vmax = std::max(vmax, double(v.length()));
    const int margin = 3 * int(std::ceil(vmax * std::abs(dt) / q.lattice().voxelSize)) + 4;
    CoordBBox work = region;
    work.expand(margin);
    work.intersect(q.bbox());
    AdvectSettings inPlane = settings;
    inPlane.inPlane = true; // a 2D output is advected in its plane, as the transfer advects it (same tcoh)
    return cropped(advect(cropped(q, work), velocity, dt, inPlane), box);
}

// Everything the metrics need of one (output, target) pair on the refined target lattice.
struct Aligned
{
    int f = 0;
    Lattice refined;
    CoordBBox box;
    Alignment alignment = Alignment::World;
    Vec3d offset{0.0};
    bool resampled = false;
    VectorField output; ///< U_out on the refined target lattice
    VectorField up;     ///< up_f(U_t)
    Mask mask;          ///< smoke region on the refined target lattice
};

Aligned alignPair(const Frame& out, const Frame& tgt, const MeasureSettings& s)
{
    Aligned a;
    a.f = resolutionRatio(tgt, out);
    a.refined = refinedLattice(tgt.velocity.lattice(), tgt.velocity.bbox(), a.f);
    a.box = refineDomain(tgt.velocity.bbox(), a.f);
    a.alignment = resolveAlignment(s.alignment, out.velocity, a.refined, a.box);
    a.offset = (out.velocity.lattice().origin - a.refined.origin) / out.velocity.lattice().voxelSize;
    a.resampled = a.alignment == Alignment::World && !nestsExactly(out.velocity.lattice(), a.refined);
    a.output = realign(out.velocity, a.refined, a.box, a.alignment);
    a.up = upsample(tgt.velocity, a.f);
    if (out.hasDensity()) {
        a.mask = thresholdMask(realign(out.density, a.refined, a.box, a.alignment), a.box, s.densityThreshold);
    } else {
        a.mask = thresholdMask(upsample(tgt.density, a.f), a.box, s.densityThreshold);
    }
    return a;
}

// A frame written trimmed to the smoke (meta::kVelocityMargin) holds the up-sampled target's velocity where nothing
// was written (an exact zero): read it so, or the edge of the written region would count as detail. Returns `out`
// itself when it was written whole, else `storage` filled in.
const Frame& fillUnwritten(const Frame& out, const Frame& tgt, const MeasureSettings& s, Frame& storage)
{
    if (!out.metadata.count(meta::kVelocityMargin) || !out.hasVelocity() || !tgt.hasVelocity()) return out;
    storage = out;
    const int f = resolutionRatio(tgt, out);
    const Lattice refined = refinedLattice(tgt.velocity.lattice(), tgt.velocity.bbox(), f);
    const CoordBBox box = refineDomain(tgt.velocity.bbox(), f);
    fillUnwrittenVelocity(
        storage.velocity, realign(upsample(tgt.velocity, f), out.velocity.lattice(), out.velocity.bbox(),
                              resolveAlignment(s.alignment, out.velocity, refined, box)));
    return storage;
}

} // namespace

const char* alignmentName(Alignment a)
{
    switch (a) {
    case Alignment::Auto: return "auto";
    case Alignment::World: return "world";
    case Alignment::Index: return "index";
    }
    return "?";
}

int resolutionRatio(const Frame& target, const Frame& output)
{
    return integerRatio(target.lattice().voxelSize, output.lattice().voxelSize);
}

template<typename T>
Field<T> realign(const Field<T>& field, const Lattice& lattice, const CoordBBox& box, Alignment a)
{
    if (a == Alignment::Auto) throw ValueError("realign: resolve Alignment::Auto first (resolveAlignment)");
    Field<T> out(box, lattice);
    if (field.empty() || box.empty()) return out;
    const Lattice& from = field.lattice();
    const Vec3d d = from.worldToIndex(lattice.indexToWorld(Vec3d(0.0))); // our voxel 0 in field's index space
    const double scale = lattice.voxelSize / from.voxelSize;
    const bool copy = a == Alignment::Index || nestsExactly(from, lattice);
    const Coord shift = a == Alignment::Index
                            ? Coord(0)
                            : Coord(int(std::lround(d.x())), int(std::lround(d.y())), int(std::lround(d.z())));
    forEachVoxel(box, [&](int i, int j, int k) {
        out(i, j, k) = copy ? field.valueOr(i + shift.x(), j + shift.y(), k + shift.z(), Field<T>::zeroValue())
                            : sampleZeroOutside(field, d + Vec3d(i, j, k) * scale);
    });
    return out;
}

template Field<float> realign(const Field<float>&, const Lattice&, const CoordBBox&, Alignment);
template Field<Vec3f> realign(const Field<Vec3f>&, const Lattice&, const CoordBBox&, Alignment);

namespace {

Alignment resolveAlignmentOf(Alignment requested, const Lattice& outLattice, const CoordBBox& outBox,
    const Lattice& refined, const CoordBBox& refinedBox)
{
    if (requested != Alignment::Auto) return requested;
    const Vec3d off = (outLattice.origin - refined.origin) / refined.voxelSize;
    const bool nests = off.length() < 1e-3;
    if (!nests && outBox == refinedBox) return Alignment::Index;
    // Two resolutions of one Blender domain put index 0 at the same world point (a shared corner, not nested
    // cells): the output's origin then sits (f - 1) / 2 fine voxels from the refined target's on every axis. Held
    // over their smoke, the boxes no longer tell this apart by their extent, the origins still do.
    const double k = 2.0 * off.x() + 1.0;
    if (!nests && k >= 2.5 && std::abs(k - std::round(k)) < 1e-3 && std::abs(off.x() - off.y()) < 1e-3 &&
        std::abs(off.x() - off.z()) < 1e-3)
        return Alignment::Index;
    return Alignment::World;
}

} // namespace

Alignment resolveAlignment(
    Alignment requested, const Field<Vec3f>& output, const Lattice& refined, const CoordBBox& refinedBox)
{
    return resolveAlignmentOf(requested, output.lattice(), output.bbox(), refined, refinedBox);
}

Alignment resolveAlignment(
    Alignment requested, const Field<float>& output, const Lattice& refined, const CoordBBox& refinedBox)
{
    return resolveAlignmentOf(requested, output.lattice(), output.bbox(), refined, refinedBox);
}

std::vector<unsigned char> smokeMask(const ScalarField& density, float threshold)
{
    return thresholdMask(density, density.bbox(), threshold);
}

CoordBBox smokeBBox(const ScalarField& density, float threshold)
{
    return maskBBox(density.bbox(), smokeMask(density, threshold));
}

std::optional<double> highFrequencyEnergy(const VectorField& u, const Mask& mask, int f)
{
    if (mask.size() != u.size()) throw ValueError("highFrequencyEnergy: mask and field sizes differ");
    const FrequencySplit split = splitFrequencies(u, f);
    const auto s = slabSums<2>(u.bbox(), [&](int i, std::array<double, 2>& acc) {
        for (int j = u.bbox().min().y(); j <= u.bbox().max().y(); ++j) {
            const size_t n0 = u.offset(i, j, u.bbox().min().z());
            for (int k = 0; k < u.dim().z(); ++k)
                if (mask[n0 + size_t(k)]) {
                    acc[0] += double(split.high.data()[n0 + size_t(k)].lengthSqr());
                    acc[1] += 1.0;
                }
        }
    });
    if (s[1] == 0.0) return std::nullopt;
    return s[0] / s[1];
}

std::optional<double> relativeDivergence(const VectorField& u, const Mask& mask)
{
    if (mask.size() != u.size()) throw ValueError("relativeDivergence: mask and field sizes differ");
    const auto s = slabSums<2>(u.bbox(), [&](int i, std::array<double, 2>& acc) {
        for (int j = u.bbox().min().y(); j <= u.bbox().max().y(); ++j)
            for (int k = u.bbox().min().z(); k <= u.bbox().max().z(); ++k)
                if (mask[u.offset(i, j, k)]) {
                    const Jacobian J = jacobianAt(u, i, j, k);
                    const double dv = J.divergence();
                    acc[0] += dv * dv;
                    acc[1] += J.frobeniusSq();
                }
    });
    if (!(s[1] > 0.0)) return std::nullopt;
    return std::sqrt(s[0] / s[1]); // the voxel counts of the two rms cancel
}

std::optional<double> blockRatio(const VectorField& u, const Mask& mask, int patch, const Coord& origin)
{
    if (mask.size() != u.size()) throw ValueError("blockRatio: mask and field sizes differ");
    if (patch < 2) throw ValueError("blockRatio: patch size must be >= 2, got " + std::to_string(patch));
    const CoordBBox b = u.bbox();
    const auto onSeam = [&](int plane, int axis) { return ((plane - origin[axis]) % patch + patch) % patch == 0; };
    // acc: seam sum, seam count, other sum, other count
    const auto s = slabSums<4>(b, [&](int i, std::array<double, 4>& acc) {
        for (int j = b.min().y(); j <= b.max().y(); ++j)
            for (int k = b.min().z(); k <= b.max().z(); ++k) {
                if (!mask[u.offset(i, j, k)]) continue;
                const Coord I(i, j, k);
                for (int a = 0; a < 3; ++a) {
                    Coord J = I;
                    J[a] += 1;
                    if (J[a] > b.max()[a] || !mask[u.offset(J.x(), J.y(), J.z())]) continue;
                    const double d = (u[J] - u[I]).length();
                    const int slot = onSeam(J[a], a) ? 0 : 2;
                    acc[size_t(slot)] += d;
                    acc[size_t(slot) + 1] += 1.0;
                }
            }
    });
    if (s[1] == 0.0 || s[3] == 0.0 || s[2] == 0.0) return std::nullopt;
    return (s[0] / s[1]) / (s[2] / s[3]);
}

DensityMeasures densityMeasures(
    const ScalarField& output, const ScalarField& outputOnRefined, const ScalarField& target, int f, float threshold)
{
    if (f < 1) throw ValueError("densityMeasures: ratio must be >= 1");
    if (outputOnRefined.bbox() != refineDomain(target.bbox(), f))
        throw ValueError("densityMeasures: the refined output must cover refineDomain(target box, f)");
    DensityMeasures d;
    const auto massOf = [](const ScalarField& q) {
        const double v = q.lattice().voxelSize;
        double sum = 0.0;
        for (float x : q.values()) sum += double(x);
        return sum * v * v * (isFlat(q.bbox()) ? 1.0 : v); // a 2D field's mass is per unit depth
    };
    const auto peakOf = [](const ScalarField& q) {
        float p = 0.0f;
        for (float x : q.values()) p = std::max(p, x);
        return double(p);
    };
    const double mt = massOf(target), pt = peakOf(target);
    d.peak = peakOf(output);
    if (mt > 0.0) d.massRatio = massOf(output) / mt;
    if (pt > 0.0) d.peakRatio = *d.peak / pt;
    if (pt > threshold) d.coarseErr = coarseDensityError(outputOnRefined, target, f, threshold);
    d.imprint = densityImprint(outputOnRefined, f, threshold);
    return d;
}

namespace {

// One pass over the density's edge for densityFray and edgeCrispness: sums of |grad D|^2 across n, |grad D|^2,
// (grad D . n)^2 and |grad L|^2.
std::array<double, 4> densityEdgeSums(const ScalarField& D, int f, float threshold)
{
    const ScalarField low = cropped(upsample(boxDownsample(D, f), f), D.bbox());
    const CoordBBox& b = D.bbox();
    const bool flat = isFlat(b);
    return slabSums<4>(b, [&](int i, std::array<double, 4>& acc) {
        for (int j = b.min().y(); j <= b.max().y(); ++j)
            for (int k = b.min().z(); k <= b.max().z(); ++k) {
                const size_t n = D.offset(i, j, k);
                if (!(std::max(D.data()[n], low.data()[n]) > threshold)) continue;
                Vec3d g(0.0), gl(0.0); // one layer: the z components stay 0
                for (int a = 0; a < (flat ? 2 : 3); ++a) {
                    g[a] = double(centralDifferenceAt(D, i, j, k, a));
                    gl[a] = double(centralDifferenceAt(low, i, j, k, a));
                }
                const double ll = gl.lengthSqr();
                if (!(ll > 0.0)) continue;
                const double along = g.dot(gl);
                acc[0] += g.lengthSqr() - along * along / ll; // |grad D| across the smooth surface's normal
                acc[1] += g.lengthSqr();
                acc[2] += along * along / ll; // |grad D| along it
                acc[3] += ll;
            }
    });
}

} // namespace

DensityEdge densityEdge(const ScalarField& D, int f, float threshold)
{
    DensityEdge e;
    if (f < 2 || D.empty()) return e;
    const auto s = densityEdgeSums(D, f, threshold);
    if (s[1] > 0.0) e.fray = s[0] / s[1];
    if (s[3] > 0.0) e.crispness = s[2] / s[3];
    return e;
}

std::optional<double> densityFray(const ScalarField& D, int f, float threshold)
{
    return densityEdge(D, f, threshold).fray;
}

std::optional<double> edgeCrispness(const ScalarField& D, int f, float threshold)
{
    return densityEdge(D, f, threshold).crispness;
}

std::vector<std::optional<double>> detailProfile(
    const VectorField& u, const std::vector<unsigned char>& mask, int f, int upAxis, int bands)
{
    if (mask.size() != u.size()) throw ValueError("detailProfile: mask and field sizes differ");
    if (upAxis < 0 || upAxis > 2) throw ValueError("detailProfile: the up axis must be 0, 1 or 2");
    if (bands < 1) throw ValueError("detailProfile: at least one band");
    const CoordBBox mb = maskBBox(u.bbox(), mask);
    if (mb.empty()) return {};
    const FrequencySplit split = splitFrequencies(u, f);
    const int lo = mb.min()[upAxis], extent = mb.max()[upAxis] - lo + 1;
    std::vector<double> sum(size_t(bands), 0.0), count(size_t(bands), 0.0);
    // Serial: a fixed order of additions keeps the result the same at any thread count.
    for (size_t n = 0; n < mask.size(); ++n) {
        if (!mask[n]) continue;
        const int h = u.coordOf(n)[upAxis] - lo;
        const size_t band = size_t(std::min(bands - 1, int(int64_t(h) * bands / extent)));
        sum[band] += double(split.high.data()[n].lengthSqr());
        count[band] += 1.0;
    }
    double all = 0.0, voxels = 0.0;
    for (int b = 0; b < bands; ++b) {
        all += sum[size_t(b)];
        voxels += count[size_t(b)];
    }
    if (!(all > 0.0)) return {};
    const double rmsAll = std::sqrt(all / voxels);
    std::vector<std::optional<double>> out(static_cast<size_t>(bands));
    for (size_t b = 0; b < size_t(bands); ++b)
        if (count[b] >= 0.01 * voxels) out[b] = std::sqrt(sum[b] / count[b]) / rmsAll;
    return out;
}

std::optional<double> detailProfileRatio(
    const std::vector<std::optional<double>>& output, const std::vector<std::optional<double>>& source)
{
    std::optional<double> worst;
    for (size_t b = 0; b < std::min(output.size(), source.size()); ++b) {
        if (!output[b] || !source[b] || !(*output[b] > 0.0) || !(*source[b] > 0.0)) continue;
        const double r = *output[b] / *source[b];
        worst = std::max(worst.value_or(0.0), std::max(r, 1.0 / r));
    }
    return worst;
}

std::optional<double> densityImprint(const ScalarField& fine, int f, float threshold)
{
    if (f < 2) return std::nullopt;
    const CoordBBox b = fine.bbox();
    // acc: coarse-face sum, count, other sum, count
    const auto s = slabSums<4>(b, [&](int i, std::array<double, 4>& acc) {
        for (int j = b.min().y(); j <= b.max().y(); ++j)
            for (int k = b.min().z(); k <= b.max().z(); ++k) {
                const Coord I(i, j, k);
                const float v = fine[I];
                for (int a = 0; a < 3; ++a) {
                    Coord J = I;
                    J[a] += 1;
                    if (J[a] > b.max()[a]) continue;
                    const float w = fine[J];
                    if (!(std::max(v, w) > threshold)) continue;
                    const size_t slot = floorDiv(J[a], f) != floorDiv(I[a], f) ? 0 : 2;
                    acc[slot] += std::abs(double(w) - double(v));
                    acc[slot + 1] += 1.0;
                }
            }
    });
    if (s[1] == 0.0 || s[3] == 0.0 || !(s[0] > 0.0) || !(s[2] > 0.0)) return std::nullopt;
    return (s[0] / s[1]) / (s[2] / s[3]);
}

double coarseDensityError(const ScalarField& fine, const ScalarField& coarse, int f, float threshold)
{
    if (f < 1) throw ValueError("coarse density error: ratio must be >= 1");
    if (fine.bbox() != refineDomain(coarse.bbox(), f))
        throw ValueError("coarse density error: the fine density must cover refineDomain(coarse box, f)");
    const ScalarField down = boxDownsample(fine, f);
    double err = 0.0, ref = 0.0;
    for (size_t n = 0; n < coarse.size(); ++n) {
        const float t = coarse.data()[n];
        if (!(t > threshold)) continue;
        const double d = double(down.data()[n]) - double(t);
        err += d * d;
        ref += double(t) * double(t);
    }
    return ref > 0.0 ? std::sqrt(err / ref) : 0.0;
}

// air_detail: U_h's rms over coarse cells more than kAirCells from the smoke cells, over its rms in the smoke
// cells, both where `covered` (the output's own box on the refined lattice) is 1. `uh` lies on the refined target
// lattice: fine voxel I in coarse cell floor(I / f) (a 2D target's one layer keeps its index).
static std::optional<double> airDetail(
    const VectorField& uh, const ScalarField& covered, const VectorField& coarse, const Mask& coarseMask, int f)
{
    const CoordBBox cb = coarse.bbox();
    ScalarField smoke(cb, coarse.lattice(), 0.0f);
    for (size_t n = 0; n < smoke.size(); ++n) smoke.data()[n] = coarseMask[n] ? 1.0f : 0.0f;
    const ScalarField dist = distanceToSmoke(smoke, 0.5f);
    const bool flat = cb.dim().z() == 1;
    const CoordBBox fb = uh.bbox();
    const auto sums = slabSums<4>(fb, [&](int i, std::array<double, 4>& acc) {
        for (int j = fb.min().y(); j <= fb.max().y(); ++j)
            for (int k = fb.min().z(); k <= fb.max().z(); ++k) {
                const Coord c(floorDiv(i, f), floorDiv(j, f), flat ? cb.min().z() : floorDiv(k, f));
                if (!cb.isInside(c) || covered(i, j, k) < 0.5f) continue;
                const float d = dist[c];
                const double e = double(uh(i, j, k).lengthSqr());
                if (d == 0.0f) {
                    acc[0] += e;
                    acc[1] += 1.0;
                } else if (d > kAirCells) {
                    acc[2] += e;
                    acc[3] += 1.0;
                }
            }
    });
    if (!(sums[0] > 0.0) || sums[3] == 0.0) return std::nullopt;
    return std::sqrt((sums[2] / sums[3]) / (sums[0] / sums[1]));
}

std::vector<std::pair<std::string, std::optional<double>>> FrameMeasures::scalars() const
{
    return {{"lf_err", lfErr}, {"hf_ratio", hfRatio}, {"hf_energy", hfEnergy}, {"hf_energy_source", hfEnergySource},
        {"div_rel", divRel}, {"div_rel_source", divRelSource}, {"block", block}, {"tile_block", tileBlock},
        {"tile_div_rel", tileDivRel}, {"tile_hf_ratio", tileHfRatio}, {"tcoh", tcoh}, {"tcoh_source", tcohSource},
        {"mass_ratio", massRatio}, {"peak_density", peakDensity}, {"peak_ratio", peakRatio},
        {"density_err", densityErr}, {"density_imprint", densityImprint}, {"density_fray", densityFray},
        {"density_fray_source", densityFraySource}, {"density_fray_ratio", densityFrayRatio},
        {"edge_crispness", edgeCrispness}, {"edge_crispness_source", edgeCrispnessSource},
        {"detail_profile_ratio", detailProfileRatio}, {"aniso", aniso},
        {"aniso_source", anisoSource}, {"aniso_ratio", anisoRatio}, {"detail_scale", detailScale},
        {"detail_scale_source", detailScaleSource}, {"detail_scale_ratio", detailScaleRatio}, {"isotropy", isotropy},
        {"isotropy_source", isotropySource}, {"lattice", lattice}, {"lattice_source", latticeSource},
        {"vort_peak", vortPeak}, {"vort_peak_source", vortPeakSource}, {"vort_peak_ratio", vortPeakRatio},
        {"air_detail", airDetail}};
}

std::optional<double> lowFrequencyError(const VectorField& detail, const VectorField& up, const Mask& coarseMask, int f)
{
    if (detail.bbox() != up.bbox()) throw ValueError("lowFrequencyError: the detail and up(U_t) cover different boxes");
    const VectorField dn = boxDownsample(detail, f);
    const VectorField nn = boxDownsample(up, f);
    if (coarseMask.size() != dn.size()) throw ValueError("lowFrequencyError: the mask does not cover the coarse box");
    const CoordBBox cb = dn.bbox();
    const auto sums = slabSums<2>(cb, [&](int i, std::array<double, 2>& acc) {
        for (int j = cb.min().y(); j <= cb.max().y(); ++j)
            for (int k = cb.min().z(); k <= cb.max().z(); ++k)
                if (coarseMask[dn.offset(i, j, k)]) {
                    acc[0] += double(dn(i, j, k).lengthSqr());
                    acc[1] += double(nn(i, j, k).lengthSqr());
                }
    });
    if (!(sums[1] > 0.0)) return std::nullopt;
    return std::sqrt(sums[0] / sums[1]);
}

namespace {

// The source frames as measured: at a non-integer ratio, resampled to the nearest integer one as the transfer
// resamples them, so hf_ratio compares the output with the detail the transfer actually had.
struct MeasuredSources
{
    const Frame* source = nullptr;   ///< in.source or `resampled`
    const Frame* previous = nullptr; ///< in.previousSource or `previousResampled`
    bool wasResampled = false;
    Frame resampled, previousResampled;
};

void measuredSources(const MeasureInput& in, const Frame& T, MeasuredSources& out)
{
    out.source = in.source;
    out.previous = in.previousSource;
    if (!out.source) return;
    const double tv = T.lattice().voxelSize, sv = out.source->lattice().voxelSize;
    const int n = nearestRatio(tv, sv);
    if (isIntegerRatio(tv, sv)) return;
    out.wasResampled = true;
    out.resampled = resampledToVoxel(*out.source, tv / n);
    out.source = &out.resampled;
    if (out.previous) {
        out.previousResampled = resampledToVoxel(*out.previous, tv / n);
        out.previous = &out.previousResampled;
    }
}

void recordAlignment(const Aligned& a, const Frame& T, FrameMeasures& m)
{
    m.ratio = a.f;
    m.alignment = a.alignment;
    m.alignmentOffset = a.offset;
    m.resampled = a.resampled;
    m.targetNyquist = M_PI / T.lattice().voxelSize;
    if (a.resampled)
        m.notes.push_back("output resampled trilinearly onto the refined target lattice (offset " + fmt(a.offset.x()) +
                          "," + fmt(a.offset.y()) + "," + fmt(a.offset.z()) + " voxels)");
}

// lf_err on the coarse cells with smoke, and air_detail.
void coarseMeasures(
    const Aligned& a, const VectorField& uh, const Mask& coarseMask, const Frame& O, const Frame& T, FrameMeasures& m)
{
    m.smokeCells = countMask(coarseMask);
    m.lfErr = lowFrequencyError(uh, a.up, coarseMask, a.f);
    if (m.smokeCells == 0) m.notes.push_back("lf_err: the target has no smoke");
    else if (!m.lfErr) m.notes.push_back("lf_err: the target does not move");
    if (m.smokeCells > 0) {
        // Only where the output holds values: beyond the box it was read on, U_h would be -up(U_t).
        const ScalarField covered =
            realign(ScalarField(O.velocity.bbox(), O.velocity.lattice(), 1.0f), a.refined, a.box, a.alignment);
        m.airDetail = airDetail(uh, covered, T.velocity, coarseMask, a.f);
    }
    if (m.smokeCells > 0 && !m.airDetail) m.notes.push_back("air_detail: no still air or no detail in the smoke");
}

// The output density's numbers against the target's, on the refined target lattice (`onRefined`): mass, peak,
// density_err, imprint, and fray and crispness from one pass over its edge.
void outputDensityNumbers(const ScalarField& D, const ScalarField& onRefined, const ScalarField& Dt, int f,
    float threshold, FrameMeasures& m)
{
    const DensityMeasures dm = densityMeasures(D, onRefined, Dt, f, threshold);
    m.massRatio = dm.massRatio;
    m.peakDensity = dm.peak;
    m.peakRatio = dm.peakRatio;
    m.densityErr = dm.coarseErr;
    m.densityImprint = dm.imprint;
    const DensityEdge e = densityEdge(onRefined, f, threshold);
    m.densityFray = e.fray;
    m.edgeCrispness = e.crispness;
}

// The source density's fray and crispness at its own ratio, and the fray ratio.
void sourceDensityNumbers(const ScalarField& Ds, int ratio, float threshold, FrameMeasures& m)
{
    const DensityEdge e = densityEdge(Ds, ratio, threshold);
    m.densityFraySource = e.fray;
    m.edgeCrispnessSource = e.crispness;
    if (m.densityFray && m.densityFraySource && *m.densityFraySource > 0.0)
        m.densityFrayRatio = *m.densityFray / *m.densityFraySource;
}

// Intrinsic numbers of the output on its own lattice (no alignment can blur them) and its density against the
// target's. Returns the output's smoke region on its own lattice.
Mask outputMeasures(const Frame& O, const Frame& T, const Aligned& a, const MeasureSettings& s, FrameMeasures& m)
{
    Mask ownMask;
    if (O.hasDensity()) ownMask = thresholdMask(O.density, O.velocity.bbox(), s.densityThreshold);
    else {
        ownMask = thresholdMask(realign(upsample(T.density, a.f), O.velocity.lattice(), O.velocity.bbox(), a.alignment),
            O.velocity.bbox(), s.densityThreshold);
        m.notes.push_back("the output has no density: its smoke region is the upsampled target's");
    }
    m.smokeVoxels = countMask(ownMask);
    if (O.hasDensity()) {
        outputDensityNumbers(O.density, realign(O.density, a.refined, a.box, a.alignment),
            T.density.bbox() == T.velocity.bbox() ? T.density : cropped(T.density, T.velocity.bbox()), a.f,
            s.densityThreshold, m);
    }
    m.hfEnergy = highFrequencyEnergy(O.velocity, ownMask, a.f);
    m.divRel = relativeDivergence(O.velocity, ownMask);
    if (m.smokeVoxels == 0) m.notes.push_back("the output has no smoke");
    return ownMask;
}

// The source's own hf energy and divergence, and hf_ratio. Returns the source's smoke region (empty without one).
Mask sourceMeasures(const MeasuredSources& sources, const Frame& T, const MeasureSettings& s, FrameMeasures& m)
{
    Mask srcMask;
    if (!sources.source) {
        m.notes.push_back("hf_ratio, div_rel_source: no source given");
        return srcMask;
    }
    const Frame& S = *sources.source;
    m.sourceRatio = integerRatio(T.lattice().voxelSize, S.lattice().voxelSize);
    if (sources.wasResampled)
        m.notes.push_back("source resampled trilinearly to the integer ratio " + std::to_string(m.sourceRatio));
    srcMask = thresholdMask(S.density, S.velocity.bbox(), s.densityThreshold);
    m.hfEnergySource = highFrequencyEnergy(S.velocity, srcMask, m.sourceRatio);
    m.divRelSource = relativeDivergence(S.velocity, srcMask);
    sourceDensityNumbers(S.density, m.sourceRatio, s.densityThreshold, m);
    if (m.hfEnergy && m.hfEnergySource && *m.hfEnergySource > 0.0) m.hfRatio = *m.hfEnergy / *m.hfEnergySource;
    else m.notes.push_back("hf_ratio: the source has no smoke or no high-frequency energy");
    return srcMask;
}

// aniso, isotropy, lattice (with a patch size, from blockMeasure) and vort_peak of the output, and of the source
// (aniso along the same direction, lattice on the same patch size: its chance level).
void structureMeasures(const Frame& O, const Frame& T, const Frame* src, const Aligned& a, const Mask& ownMask,
    const Mask& srcMask, const Mask& coarseMask, int upAxis, FrameMeasures& m)
{
    m.detailProfile = detailProfile(O.velocity, ownMask, a.f, upAxis);
    if (src) {
        m.detailProfileSource = detailProfile(src->velocity, srcMask, m.sourceRatio, upAxis);
        m.detailProfileRatio = detailProfileRatio(m.detailProfile, m.detailProfileSource);
    }
    // d: the target's mean flow over its smoke cells; the source's detail is measured along the same d.
    Vec3d mean(0.0);
    for (size_t n = 0; n < T.velocity.size(); ++n)
        if (coarseMask[n]) {
            const Vec3f& v = T.velocity.data()[n];
            mean += Vec3d(v.x(), v.y(), v.z());
        }
    const int patch = m.patchSize >= 3 ? m.patchSize : 0;
    const DetailStructure out = detailStructure(O.velocity, ownMask, a.f, mean, patch);
    m.aniso = out.aniso;
    m.isotropy = out.isotropy;
    m.lattice = out.lattice;
    m.detailScale = out.scale;
    if (!m.aniso) m.notes.push_back("aniso: no smoke, no mean flow or no detail gradient");
    if (patch && !m.lattice)
        m.notes.push_back("lattice: no detail in the smoke, or the box is shorter than two patches");
    m.vortPeak = vorticityPeak(O.velocity, ownMask, kVortPeakQuantile);
    if (src) {
        const DetailStructure source = detailStructure(src->velocity, srcMask, m.sourceRatio, mean, patch);
        m.anisoSource = source.aniso;
        m.isotropySource = source.isotropy;
        m.latticeSource = source.lattice;
        m.detailScaleSource = source.scale;
        if (m.detailScale && m.detailScaleSource && *m.detailScaleSource > 0.0)
            m.detailScaleRatio = *m.detailScale / *m.detailScaleSource;
        if (m.aniso && m.anisoSource && *m.anisoSource > 0.0) m.anisoRatio = *m.aniso / *m.anisoSource;
        m.vortPeakSource = vorticityPeak(src->velocity, srcMask, kVortPeakQuantile);
        if (m.vortPeak && m.vortPeakSource && *m.vortPeakSource > 0.0)
            m.vortPeakRatio = *m.vortPeak / *m.vortPeakSource;
    }
}

// block: seams at the patch grid of the output's maker.
void blockMeasure(const Frame& O, const Aligned& a, const VectorField& uh, const MeasureSettings& s, FrameMeasures& m)
{
    m.patchSize = s.patchSize > 0 ? s.patchSize : metadataInt(O, turb::meta::kPatchSize, 0);
    m.patchOrigin = s.patchOrigin ? *s.patchOrigin : metadataCoord(O, turb::meta::kPatchOrigin, Coord(0));
    if (m.patchSize >= 2) {
        // U_h lives on the refined target lattice: move the origin there when whole voxels apart.
        Coord origin = m.patchOrigin;
        if (a.alignment == Alignment::World && !a.resampled)
            for (int ax = 0; ax < 3; ++ax) origin[ax] += int(std::lround(a.offset[ax]));
        m.block = blockRatio(uh, a.mask, m.patchSize, origin);
        if (!m.block) m.notes.push_back("block: no detail differences inside the smoke region");
    } else {
        m.patchSize = 0;
        m.notes.push_back("block: no patch size (option, or metadata vdbturb_patch_size)");
    }
}

// tile_block, tile_div_rel and tile_hf_ratio: block, div_rel and hf_ratio over the smoke near the border planes of a
// tiled run (farm join's metadata, or the settings for an untiled run measured at the same planes).
void tileMeasures(const Frame& O, const Aligned& a, const VectorField& uh, const Mask& ownMask,
    const MeasureSettings& s, FrameMeasures& m)
{
    std::vector<TileBorder> borders = s.tileBorders;
    if (borders.empty()) {
        const auto it = O.metadata.find(turb::meta::kTileBorders);
        if (it == O.metadata.end() || it->second.empty()) return;
        borders = parseTileBorders(it->second);
    }
    const int width = s.tileBorderWidth > 0 ? s.tileBorderWidth : 2 * (m.patchSize >= 2 ? m.patchSize : 8);
    // Planes are output voxel indices; U_h and a.mask live on the refined target lattice, whole voxels apart.
    Coord shift(0);
    if (a.alignment == Alignment::World && !a.resampled)
        for (int ax = 0; ax < 3; ++ax) shift[ax] = int(std::lround(a.offset[ax]));
    const auto near = [&](const Coord& c, const Coord& sh) {
        for (const TileBorder& b : borders)
            if (std::abs(double(c[b.axis] - sh[b.axis]) + 0.5 - double(b.plane)) <= double(width)) return true;
        return false;
    };
    Mask onRefined(a.mask.size(), 0), onOwn(ownMask.size(), 0);
    for (size_t n = 0; n < a.mask.size(); ++n) onRefined[n] = a.mask[n] && near(uh.coordOf(n), shift) ? 1 : 0;
    for (size_t n = 0; n < ownMask.size(); ++n) onOwn[n] = ownMask[n] && near(O.velocity.coordOf(n), Coord(0)) ? 1 : 0;
    m.tileVoxels = countMask(onOwn);
    if (m.patchSize >= 2) {
        Coord origin = m.patchOrigin;
        for (int ax = 0; ax < 3; ++ax) origin[ax] += shift[ax];
        m.tileBlock = blockRatio(uh, onRefined, m.patchSize, origin);
    }
    m.tileDivRel = relativeDivergence(O.velocity, onOwn);
    const std::optional<double> hf = highFrequencyEnergy(O.velocity, onOwn, a.f);
    if (hf && m.hfEnergySource && *m.hfEnergySource > 0.0) m.tileHfRatio = *hf / *m.hfEnergySource;
    if (m.tileVoxels == 0) m.notes.push_back("tile_block, tile_div_rel: no smoke near the tile borders");
}

// rms(a - b) / rms(a) over the voxels of `box` where `mask` (one byte per voxel of a's box) is 1; nullopt when a
// is zero there.
std::optional<double> relativeChange(const VectorField& a, const VectorField& b, const Mask& mask, const CoordBBox& box)
{
    const auto sums = slabSums<2>(box, [&](int i, std::array<double, 2>& acc) {
        for (int j = box.min().y(); j <= box.max().y(); ++j)
            for (int k = box.min().z(); k <= box.max().z(); ++k) {
                const size_t n = a.offset(i, j, k);
                if (!mask[n]) continue;
                acc[0] += double((a.data()[n] - b.data()[n]).lengthSqr());
                acc[1] += double(a.data()[n].lengthSqr());
            }
    });
    if (!(sums[1] > 0.0)) return std::nullopt;
    return std::sqrt(sums[0] / sums[1]);
}

// tcoh: the previous frame's detail carried by the previous target velocity.
void temporalCoherence(const MeasureInput& in, const Frame& T, const Aligned& a, const VectorField& uh,
    const MeasureSettings& s, FrameMeasures& m)
{
    requireVelocity(in.previousOutput, "previous output");
    requireVelocity(in.previousTarget, "previous target");
    const Frame& Tp = *in.previousTarget;
    Frame previousFilled;
    const Frame& Op = fillUnwritten(*in.previousOutput, Tp, s, previousFilled);
    // The real time between the two frames: frames measured two apart are two frames' time apart.
    const int gap = T.number - Tp.number;
    const double dt = (s.dt > 0.0 ? s.dt : Tp.dt) * gap;
    if (gap <= 0) m.notes.push_back("tcoh: the previous frame is not earlier than this one");
    else if (!(dt > 0.0)) m.notes.push_back("tcoh: unknown time step");
    else if (!Tp.lattice().approxEqual(T.lattice()) || resolutionRatio(Tp, Op) != a.f)
        m.notes.push_back("tcoh: the previous frame is on another lattice");
    else {
        const Aligned ap = [&] {
            MeasureSettings sp = s;
            sp.alignment = a.alignment; // one alignment for both frames
            return alignPair(Op, Tp, sp);
        }();
        const VectorField uhPrev = difference(ap.output, ap.up);
        const VectorField moved = advectOnto(uhPrev, Tp.velocity, dt, maskBBox(a.box, a.mask), a.box, s.advect);
        m.dt = dt;
        m.tcoh = relativeChange(uh, moved, a.mask, a.box);
        if (!m.tcoh) m.notes.push_back("tcoh: no detail in the smoke region");
    }
}

// The source's own coherence: its detail above the target's Nyquist, carried by its own low band.
void sourceCoherence(const MeasuredSources& sources, const Mask& srcMask, const MeasureSettings& s, FrameMeasures& m)
{
    const Frame& S = *sources.source;
    const Frame& Sp = *sources.previous;
    requireVelocity(&Sp, "previous source");
    const double dt = (s.dt > 0.0 ? s.dt : Sp.dt) * (S.number - Sp.number);
    if (dt > 0.0 && Sp.lattice().approxEqual(S.lattice())) {
        const FrequencySplit now = splitFrequencies(S.velocity, m.sourceRatio);
        const FrequencySplit before = splitFrequencies(Sp.velocity, m.sourceRatio);
        const VectorField moved = advectOnto(
            before.high, before.coarse, dt, maskBBox(S.velocity.bbox(), srcMask), S.velocity.bbox(), s.advect);
        m.tcohSource = relativeChange(now.high, moved, srcMask, S.velocity.bbox());
    } else {
        m.notes.push_back("tcoh_source: unknown time step or the previous source is on another lattice");
    }
}

// The density numbers of an output without velocity (Blender's noise up-res writes density_noise alone): the
// target's density gives the ratio and the refined lattice.
FrameMeasures measureDensityOnly(const MeasureInput& in, const MeasureSettings& s)
{
    const Frame& O = *in.output;
    const Frame& T = *in.target;
    FrameMeasures m;
    m.frame = O.number;
    m.notes.push_back("the output has no velocity: density numbers only");
    withThreads(s.threads, [&] {
        const ScalarField& Dt = T.density;
        const int f = integerRatio(Dt.lattice().voxelSize, O.density.lattice().voxelSize);
        const Lattice refined = refinedLattice(Dt.lattice(), Dt.bbox(), f);
        const CoordBBox box = refineDomain(Dt.bbox(), f);
        const Alignment al = resolveAlignment(s.alignment, O.density, refined, box);
        m.ratio = f;
        m.alignment = al;
        m.alignmentOffset = (O.density.lattice().origin - refined.origin) / O.density.lattice().voxelSize;
        m.resampled = al == Alignment::World && !nestsExactly(O.density.lattice(), refined);
        m.targetNyquist = M_PI / Dt.lattice().voxelSize;
        m.smokeVoxels = countMask(thresholdMask(O.density, O.density.bbox(), s.densityThreshold));
        m.smokeCells = countMask(thresholdMask(Dt, Dt.bbox(), s.densityThreshold));
        outputDensityNumbers(O.density, realign(O.density, refined, box, al), Dt, f, s.densityThreshold, m);
        MeasuredSources sources;
        measuredSources(in, T, sources);
        if (sources.source) {
            const Frame& S = *sources.source;
            m.sourceRatio = integerRatio(Dt.lattice().voxelSize, S.density.lattice().voxelSize);
            sourceDensityNumbers(S.density, m.sourceRatio, s.densityThreshold, m);
        }
    });
    return m;
}

// Throws unless the frames of a velocity measurement are there, with their grids, and agree on 2D or 3D.
void checkVelocityInputs(const MeasureInput& in, const MeasureSettings& s)
{
    requireVelocity(in.output, "output");
    requireVelocity(in.target, "target");
    requireDensity(*in.target, "target");
    if (in.source) {
        requireVelocity(in.source, "source");
        requireDensity(*in.source, "source");
        // A slice against a volume: every source figure (hf_ratio, aniso_ratio, ...) would be meaningless.
        const CoordBBox &ob = in.output->velocity.bbox(), &sb = in.source->velocity.bbox();
        if (!ob.empty() && !sb.empty() && isFlat(ob) != isFlat(sb))
            throw ValueError(isFlat(ob) ? "the output is 2D (one z layer) but the source is 3D: give the 2D source"
                                        : "the output is 3D but the source is 2D (one z layer)");
    }
    if (!(s.densityThreshold >= 0.0f)) throw ValueError("measure: density threshold must be >= 0");
}

// The velocity over the smoke's bounding box as stored: no mask inside the box (a mask would add the step at the
// smoke's edge to every spectrum; Blender already clips velocity to the smoke).
void spectraMeasures(const Frame& O, const Frame& T, const Frame* src, const Mask& ownMask, const Mask& coarseMask,
    const Mask& srcMask, const MeasureSettings& s, FrameMeasures& m)
{
    const auto spectrumOf = [&](const VectorField& u, const Mask& mask) {
        return energySpectrum(u, maskBBox(u.bbox(), mask), s.spectrum);
    };
    m.spectrumOutput = spectrumOf(O.velocity, ownMask);
    m.spectrumTarget = spectrumOf(T.velocity, coarseMask);
    if (src) m.spectrumSource = spectrumOf(src->velocity, srcMask);
}

// Every measure of an output with velocity, stage by stage, each stage a cancellation point.
void measureStages(const MeasureInput& in, const Frame& O, const Frame& T, const MeasuredSources& sources,
    const MeasureSettings& s, Progress* progress, FrameMeasures& m)
{
    const Frame* src = sources.source;
    if (progress) progress->begin("align");
    const Aligned a = alignPair(O, T, s);
    recordAlignment(a, T, m);
    checkCancelled(progress);

    if (progress) progress->begin("lf_err");
    const VectorField uh = difference(a.output, a.up);
    const Mask coarseMask = thresholdMask(T.density, T.velocity.bbox(), s.densityThreshold);
    coarseMeasures(a, uh, coarseMask, O, T, m);
    checkCancelled(progress);

    if (progress) progress->begin("hf energy, divergence");
    const Mask ownMask = outputMeasures(O, T, a, s, m);
    checkCancelled(progress);
    const Mask srcMask = sourceMeasures(sources, T, s, m);
    checkCancelled(progress);

    blockMeasure(O, a, uh, s, m);
    tileMeasures(O, a, uh, ownMask, s, m);
    if (s.structure) {
        if (progress) progress->begin("structure");
        structureMeasures(O, T, src, a, ownMask, srcMask, coarseMask, s.upAxis, m);
        checkCancelled(progress);
    }
    if (in.previousOutput && in.previousTarget) {
        if (progress) progress->begin("tcoh");
        temporalCoherence(in, T, a, uh, s, m);
    } else {
        m.notes.push_back("tcoh: no previous frame");
    }
    checkCancelled(progress);
    if (src && sources.previous && !srcMask.empty()) sourceCoherence(sources, srcMask, s, m);
    checkCancelled(progress);

    if (s.spectra) {
        if (progress) progress->begin("spectra");
        spectraMeasures(O, T, src, ownMask, coarseMask, srcMask, s, m);
    }
}

} // namespace

FrameMeasures measureFrame(const MeasureInput& in, const MeasureSettings& s, Progress* progress)
{
    if (!in.output) throw ValueError("measure: no output frame given");
    if (!in.output->hasVelocity()) {
        if (!in.output->hasDensity())
            throw ValueError("measure: the output frame " + std::to_string(in.output->number) +
                             " has neither a velocity nor a density grid");
        if (!in.target) throw ValueError("measure: no target frame given");
        requireDensity(*in.target, "target");
        if (in.source) requireDensity(*in.source, "source");
        return measureDensityOnly(in, s);
    }
    checkVelocityInputs(in, s);
    const Frame& T = *in.target;
    Frame filled;
    const Frame& O = fillUnwritten(*in.output, T, s, filled);
    MeasuredSources sources;
    measuredSources(in, T, sources);

    FrameMeasures m;
    m.frame = O.number;
    withThreads(s.threads, [&] { measureStages(in, O, T, sources, s, progress, m); });
    return m;
}

std::map<std::string, MetricStats> summarize(const std::vector<FrameMeasures>& frames)
{
    std::map<std::string, std::vector<double>> values;
    for (const auto& f : frames)
        for (const auto& [name, v] : f.scalars())
            if (v) values[name].push_back(*v);
    std::map<std::string, MetricStats> out;
    for (auto& [name, v] : values) {
        MetricStats st;
        st.count = int(v.size());
        std::sort(v.begin(), v.end());
        double sum = 0.0;
        for (double x : v) sum += x;
        st.mean = sum / double(v.size());
        st.min = v.front();
        st.max = v.back();
        const size_t h = v.size() / 2;
        st.median = v.size() % 2 ? v[h] : 0.5 * (v[h - 1] + v[h]);
        out[name] = st;
    }
    return out;
}

} // namespace turb
