// Motion-field texture synthesis (Ma et al. 2009): exemplar preparation and the texture-optimisation engine.
//
// Layout of the engine, per pyramid level and iteration:
//   centres  a lattice of neighbourhood centres, `spacing` apart, jittered per iteration (Kwatra's
//            sparse subset X of Eq. 1);
//   search   per centre and view: the neighbourhood sampled in the local frame of L, projected to
//            the view's two components, matched by tree or k-coherence;
//   assign   every match's exemplar neighbourhood is splatted back (trilinear, robust weights) into
//            per-component sums; each voxel takes the weighted mean (Eq. 1 least squares, Eq. 2
//            across views), then the temporal and wall terms.
// Splatting scatters, so for determinism without atomics the centres are bucketed into slabs wider
// than twice the splat reach, and even slabs run in parallel before odd ones: every voxel receives its
// contributions in the same order at any thread count.
#include <turb/Synth.h>

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/PatchIndex.h>
#include <turb/Resample.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>

namespace turb {

namespace {

inline std::uint64_t splitmix(std::uint64_t x)
{
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}
inline std::uint64_t hash4(std::uint64_t a, std::uint64_t b, std::uint64_t c, std::uint64_t d)
{
    return splitmix(a ^ splitmix(b ^ splitmix(c ^ splitmix(d))));
}

inline int wrapi(int v, int n) { return ((v % n) + n) % n; }

/// A local frame: e[a] is local axis a in world coordinates.
struct Frame3
{
    Vec3f e[3] = {Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)};
    Vec3f toWorld(const Vec3f& h) const { return e[0] * h[0] + e[1] * h[1] + e[2] * h[2]; }
    Vec3f toLocal(const Vec3f& w) const { return Vec3f(e[0].dot(w), e[1].dot(w), e[2].dot(w)); }
};

/// Neighbourhood taps of one view at one radius, and the exemplar rows that can be their centres.
struct Neigh
{
    int radius = 0;
    std::vector<Vec3f> local;           // tap offset in the local frame (level voxels)
    std::vector<std::array<int, 3>> ex; // the same tap in exemplar pixels
    std::vector<Vec3f> coherence;       // k-coherence: neighbour offsets, local frame
    std::vector<std::array<int, 3>> coherenceEx;
    float reach = 0.0f;                       // largest |local|
    int lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0}; // valid centre box (inclusive)
    size_t rows = 0;
    PatchIndex index;
    std::vector<float> reduced; // rows x pcaDim (k-coherence)
    std::vector<int> similar;   // rows x k (k-coherence), nearest first, self excluded
    int k = 0;
};

struct ViewLevel
{
    Exemplar ex;
    Neigh neigh[2];                                   // [0] small radius, [1] large radius (2D only)
    double mean[3] = {0, 0, 0}, stdev[3] = {0, 0, 0}; // per channel
};

struct PreparedView
{
    SynthView view;
    int nc = 2;                    // channels
    int comps[3] = {0, 1, 2};      // local component of each channel
    int normal = -1;               // local axis dropped (planar views), -1 for volumetric
    std::vector<ViewLevel> levels; // coarsest first
};

} // namespace

struct SynthExemplars::Impl
{
    std::vector<SynthView> views;
    std::vector<PreparedView> prepared;
    int levels = 1;
    bool volume = false;
    bool kcoherence = false;
    int kSimilar = 0;
};

namespace {

// ---------------------------------------------------------------------------------------------
// Exemplar side

/// Plane axes (u, v) of a view looking along local axis a.
inline void planeAxes(int a, int& u, int& v)
{
    u = a == 0 ? 1 : 0;
    v = a == 2 ? 1 : 2;
}

size_t rowOf(const Neigh& N, const Exemplar& ex, int x, int y, int z)
{
    if (ex.periodic) return ex.linear(x, y, z);
    const size_t dy = size_t(N.hi[1] - N.lo[1] + 1), dz = size_t(N.hi[2] - N.lo[2] + 1);
    return (size_t(x - N.lo[0]) * dy + size_t(y - N.lo[1])) * dz + size_t(z - N.lo[2]);
}

std::array<int, 3> posOf(const Neigh& N, const Exemplar& ex, size_t row)
{
    if (ex.periodic) {
        const size_t yz = size_t(ex.ny) * size_t(ex.nz);
        return {int(row / yz), int((row / size_t(ex.nz)) % size_t(ex.ny)), int(row % size_t(ex.nz))};
    }
    const size_t dy = size_t(N.hi[1] - N.lo[1] + 1), dz = size_t(N.hi[2] - N.lo[2] + 1);
    return {N.lo[0] + int(row / (dy * dz)), N.lo[1] + int((row / dz) % dy), N.lo[2] + int(row % dz)};
}

/// Clamps or wraps an exemplar position into the valid centre box.
std::array<int, 3> validPos(const Neigh& N, const Exemplar& ex, std::array<int, 3> p)
{
    const int n[3] = {ex.nx, ex.ny, ex.nz};
    for (int a = 0; a < 3; ++a)
        p[size_t(a)] = ex.periodic ? wrapi(p[size_t(a)], n[a]) : std::clamp(p[size_t(a)], N.lo[a], N.hi[a]);
    return p;
}

/// The exemplar value at a centre plus a tap (wrapping when periodic; valid centres keep it inside).
inline const float* exValue(const Exemplar& ex, const std::array<int, 3>& c, const std::array<int, 3>& off)
{
    int x = c[0] + off[0], y = c[1] + off[1], z = c[2] + off[2];
    if (ex.periodic) {
        x = wrapi(x, ex.nx);
        y = wrapi(y, ex.ny);
        z = wrapi(z, ex.nz);
    }
    return ex.at(x, y, z);
}

void makeTaps(Neigh& N, const PreparedView& pv, int radius, int tapStep)
{
    N.radius = radius;
    N.local.clear();
    N.ex.clear();
    if (pv.normal >= 0) {
        int u, v;
        planeAxes(pv.normal, u, v);
        for (int i = -radius; i <= radius; ++i)
            for (int j = -radius; j <= radius; ++j) {
                Vec3f o(0.0f);
                o[u] = float(i);
                o[v] = float(j);
                N.local.push_back(o);
                N.ex.push_back({i, j, 0});
            }
        for (int i = -1; i <= 1; ++i)
            for (int j = -1; j <= 1; ++j) {
                Vec3f o(0.0f);
                o[u] = float(i);
                o[v] = float(j);
                N.coherence.push_back(o);
                N.coherenceEx.push_back({i, j, 0});
            }
    } else {
        const int r = (radius / tapStep) * tapStep;
        for (int i = -r; i <= r; i += tapStep)
            for (int j = -r; j <= r; j += tapStep)
                for (int k = -r; k <= r; k += tapStep) {
                    N.local.push_back(Vec3f(float(i), float(j), float(k)));
                    N.ex.push_back({i, j, k});
                }
        for (int i = -1; i <= 1; ++i)
            for (int j = -1; j <= 1; ++j)
                for (int k = -1; k <= 1; ++k) {
                    N.coherence.push_back(Vec3f(float(i), float(j), float(k)));
                    N.coherenceEx.push_back({i, j, k});
                }
    }
    N.reach = 0.0f;
    for (const auto& o : N.local) N.reach = std::max(N.reach, o.length());
}

/// Largest usable radius for an exemplar: the neighbourhood must fit (periodic) or leave at least
/// half of each axis as valid centres (non-periodic).
int clampRadius(const Exemplar& ex, int radius)
{
    int m = std::min(ex.nx, ex.ny);
    if (!ex.planar()) m = std::min(m, ex.nz);
    const int cap = ex.periodic ? (m - 1) / 2 : m / 4;
    return std::max(1, std::min(radius, cap));
}

void buildNeigh(Neigh& N, const PreparedView& pv, const Exemplar& ex, int radius, const SynthSettings& s, bool kcoh)
{
    makeTaps(N, pv, clampRadius(ex, radius), std::max(1, s.volumeTapStep));
    int ext[3] = {0, 0, 0};
    for (const auto& o : N.ex)
        for (int a = 0; a < 3; ++a) ext[a] = std::max(ext[a], std::abs(o[size_t(a)]));
    const int n[3] = {ex.nx, ex.ny, ex.nz};
    for (int a = 0; a < 3; ++a) {
        N.lo[a] = ex.periodic ? 0 : ext[a];
        N.hi[a] = ex.periodic ? n[a] - 1 : n[a] - 1 - ext[a];
        if (N.hi[a] < N.lo[a]) {
            std::ostringstream os;
            os << "synth: exemplar '" << ex.name << "' (" << ex.nx << "x" << ex.ny
               << (ex.planar() ? "" : "x" + std::to_string(ex.nz)) << ") is too small for a neighbourhood of radius "
               << N.radius << " at this pyramid level";
            throw ValueError(os.str());
        }
    }
    N.rows = size_t(N.hi[0] - N.lo[0] + 1) * size_t(N.hi[1] - N.lo[1] + 1) * size_t(N.hi[2] - N.lo[2] + 1);
    const size_t taps = N.local.size(), dim = taps * size_t(pv.nc);
    if (double(N.rows) * double(dim) * sizeof(float) > 3.0 * double(1u << 30)) {
        std::ostringstream os;
        os << "synth: exemplar '" << ex.name << "' needs " << N.rows << " neighbourhoods of " << dim
           << " values (over 3 GiB); use a smaller exemplar (a 32^3 or 64^3 crop)";
        throw ValueError(os.str());
    }
    std::vector<float> rows(N.rows * dim);
    parallelFor(N.rows, 256, [&](size_t b, size_t e) {
        for (size_t r = b; r < e; ++r) {
            const auto c = posOf(N, ex, r);
            float* d = &rows[r * dim];
            for (size_t t = 0; t < taps; ++t) {
                const float* v = exValue(ex, c, N.ex[t]);
                for (int ch = 0; ch < pv.nc; ++ch) d[t * size_t(pv.nc) + size_t(ch)] = v[ch];
            }
        }
    });
    PcaSettings pca;
    pca.components = std::max(1, s.pcaComponents);
    pca.maxSamples = 4000; // plenty for a covariance of a few hundred dimensions, and fast
    pca.exactMaxDim = std::numeric_limits<size_t>::max(); // 3D neighbourhoods reach ~1000 dimensions; exact stays fast
    if (kcoh) {
        // k-coherence needs the reduced rows and each row's k most similar rows (Tong et al. 2002).
        const std::vector<float> copy = rows;
        N.index.build(std::move(rows), dim, pca);
        const size_t k = N.index.pca().outputDim();
        N.reduced.assign(N.rows * k, 0.0f);
        N.index.pca().projectRows(copy.data(), N.rows, N.reduced.data());
        N.k = int(std::min<size_t>(size_t(std::max(1, s.kSimilar)), N.rows > 1 ? N.rows - 1 : 0));
        std::vector<int> idx;
        std::vector<float> d2;
        N.index.queryMany(copy.data(), N.rows, N.k + 1, idx, d2);
        N.similar.assign(N.rows * size_t(N.k), 0);
        for (size_t r = 0; r < N.rows; ++r) {
            int m = 0;
            for (int j = 0; j <= N.k && m < N.k; ++j) {
                const int o = idx[r * size_t(N.k + 1) + size_t(j)];
                if (o >= 0 && size_t(o) != r) N.similar[r * size_t(N.k) + size_t(m++)] = o;
            }
            for (; m < N.k; ++m) N.similar[r * size_t(N.k) + size_t(m)] = int(r);
        }
    } else {
        N.index.build(std::move(rows), dim, pca);
    }
}

// ---------------------------------------------------------------------------------------------
// Output side

/// The unit direction L has least of: the eigenvector of the smallest eigenvalue of sum L L^T, its sign chosen
/// so that its largest component is positive (deterministic). `fallback` when L is zero everywhere.
Vec3f leastPresentDirection(const VectorField& L, const Vec3f& fallback)
{
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    for (const Vec3f& v : L.values()) {
        const Eigen::Vector3d e(v[0], v[1], v[2]);
        M += e * e.transpose();
    }
    if (!(M.trace() > 0.0)) return fallback;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(M);
    Eigen::Vector3d d = es.eigenvectors().col(0); // eigenvalues ascending
    int big = 0;
    for (int a = 1; a < 3; ++a)
        if (std::abs(d[a]) > std::abs(d[big]) + 1e-9) big = a;
    if (d[big] < 0.0) d = -d;
    return Vec3f(float(d[0]), float(d[1]), float(d[2]));
}

/// Local frames from the coarse flow (sections 3.1, 3.3).
class FrameGuide
{
public:
    FrameGuide(const SynthInput& in, const OrientationSettings& o, bool twoD)
        : mL(in.coarse), mFollow(o.follow), mTwoD(twoD)
    {
        mFallback = Vec3f(float(o.fallback.x()), float(o.fallback.y()), float(o.fallback.z()));
        if (mTwoD) mFallback[2] = 0.0f;
        if (mFallback.length() < 1e-6f) mFallback = Vec3f(1, 0, 0);
        mFallback.normalize();
        mSecondary = Vec3f(float(o.secondary.x()), float(o.secondary.y()), float(o.secondary.z()));
        if (!mTwoD && o.autoSecondary) {
            mNormal = leastPresentDirection(*mL, Vec3f(0, 0, 1));
            mUseNormal = true;
        }
        if (mSecondary.length() < 1e-6f) mSecondary = Vec3f(0, 1, 0);
        mSecondary.normalize();
        if (!mFollow) return;
        // rms speed over moving voxels sets the scale below which e1 fades to the fallback direction.
        double s2 = 0.0, mx = 0.0;
        size_t n = 0;
        for (const Vec3f& v : mL->values()) mx = std::max(mx, double(v.length()));
        for (const Vec3f& v : mL->values()) {
            const double l = v.length();
            if (l > 1e-6 * mx) {
                s2 += l * l;
                ++n;
            }
        }
        const double rms = n ? std::sqrt(s2 / double(n)) : 0.0;
        mEps = float(std::max(1e-12, o.stillFraction * rms));
        if (!mTwoD && o.densitySecondary && in.coarseDensity && !in.coarseDensity->empty()) {
            // Density gradient, scaled so that its largest magnitude is 1: where the smoke is flat the
            // given secondary vector (weight 0.05) takes over smoothly.
            const ScalarField& rho = *in.coarseDensity;
            mGrad = VectorField(rho.bbox(), rho.lattice());
            const CoordBBox b = rho.bbox();
            float gmax = 0.0f;
            for (int i = b.min().x(); i <= b.max().x(); ++i)
                for (int j = b.min().y(); j <= b.max().y(); ++j)
                    for (int k = b.min().z(); k <= b.max().z(); ++k) {
                        const Vec3f g(centralDifferenceAt(rho, i, j, k, 0), centralDifferenceAt(rho, i, j, k, 1),
                            centralDifferenceAt(rho, i, j, k, 2));
                        mGrad(i, j, k) = g;
                        gmax = std::max(gmax, g.length());
                    }
            if (gmax > 0.0f) {
                for (Vec3f& g : mGrad.values()) g *= 1.0f / gmax;
                mUseGrad = true;
            }
        }
    }

    Frame3 at(const Vec3d& world) const
    {
        Frame3 f;
        if (!mFollow) return f;
        Vec3f p = sampleWorld(*mL, world);
        if (mTwoD) p[2] = 0.0f;
        p += mFallback * mEps;
        const float len = p.length();
        const Vec3f e1 = len > 0.0f ? p / len : mFallback;
        if (mTwoD) {
            f.e[0] = e1;
            f.e[1] = Vec3f(-e1[1], e1[0], 0.0f);
            f.e[2] = Vec3f(0, 0, 1);
            return f;
        }
        // With the direction n that L has least of, the secondary is n x e1: for a flow in a plane with normal n
        // this is 2D's frame (e2 = z x e1), continuous wherever L does not point along n.
        const Vec3f secondary = mUseNormal ? mNormal.cross(e1) : mSecondary;
        Vec3f s = secondary;
        if (mUseGrad) s = sampleWorld(mGrad, world) + secondary * 0.05f;
        Vec3f e2 = s - e1 * e1.dot(s);
        if (e2.length() < 1e-3f * std::max(1e-12f, s.length())) {
            // Degenerate: the axis least aligned with e1.
            int a = 0;
            for (int b = 1; b < 3; ++b)
                if (std::abs(e1[b]) < std::abs(e1[a])) a = b;
            Vec3f ax(0.0f);
            ax[a] = 1.0f;
            e2 = ax - e1 * e1.dot(ax);
        }
        e2.normalize();
        f.e[0] = e1;
        f.e[1] = e2;
        f.e[2] = e1.cross(e2);
        return f;
    }

private:
    const VectorField* mL;
    VectorField mGrad;
    bool mFollow, mTwoD, mUseGrad = false, mUseNormal = false;
    float mEps = 0.0f;
    Vec3f mFallback, mSecondary, mNormal{0.0f, 0.0f, 1.0f};
};

/// One pyramid level of the output: geometry and the local-frame detail H.
struct Level
{
    int n[3] = {1, 1, 1};
    int shrink = 1;
    bool flat = false;
    Vec3d fineMin{0.0};
    Lattice fineLat;
    std::vector<Vec3f> h;

    size_t size() const { return size_t(n[0]) * size_t(n[1]) * size_t(n[2]); }
    size_t idx(int x, int y, int z) const { return (size_t(x) * size_t(n[1]) + size_t(y)) * size_t(n[2]) + size_t(z); }
    Vec3d world(double x, double y, double z) const
    {
        const double s = shrink;
        Vec3d fi(fineMin.x() + (x + 0.5) * s - 0.5, fineMin.y() + (y + 0.5) * s - 0.5,
            flat ? fineMin.z() : fineMin.z() + (z + 0.5) * s - 0.5);
        return fineLat.indexToWorld(fi);
    }
    double voxel() const { return fineLat.voxelSize * shrink; }

    Vec3f sample(float x, float y, float z) const
    {
        x = std::min(std::max(x, 0.0f), float(n[0] - 1));
        y = std::min(std::max(y, 0.0f), float(n[1] - 1));
        const int x0 = int(x), y0 = int(y);
        const int x1 = std::min(x0 + 1, n[0] - 1), y1 = std::min(y0 + 1, n[1] - 1);
        const float wx = x - float(x0), wy = y - float(y0);
        if (flat) {
            const Vec3f a = h[idx(x0, y0, 0)] * (1 - wy) + h[idx(x0, y1, 0)] * wy;
            const Vec3f b = h[idx(x1, y0, 0)] * (1 - wy) + h[idx(x1, y1, 0)] * wy;
            return a * (1 - wx) + b * wx;
        }
        z = std::min(std::max(z, 0.0f), float(n[2] - 1));
        const int z0 = int(z), z1 = std::min(z0 + 1, n[2] - 1);
        const float wz = z - float(z0);
        const auto lerpZ = [&](int xi, int yi) { return h[idx(xi, yi, z0)] * (1 - wz) + h[idx(xi, yi, z1)] * wz; };
        const Vec3f a = lerpZ(x0, y0) * (1 - wy) + lerpZ(x0, y1) * wy;
        const Vec3f b = lerpZ(x1, y0) * (1 - wy) + lerpZ(x1, y1) * wy;
        return a * (1 - wx) + b * wx;
    }
};

/// Adds `w * value[c]` to local components comps[c] at a continuous position (trilinear; corners
/// outside the level are dropped, not clamped, so values do not pile up on the faces).
inline void splat(const Level& L, float* acc, const Vec3f& pos, const int* comps, const float* value, int nc, float w)
{
    const float fx = std::floor(pos[0]), fy = std::floor(pos[1]);
    const int x0 = int(fx), y0 = int(fy);
    const float wx = pos[0] - fx, wy = pos[1] - fy;
    float wv[3];
    for (int c = 0; c < nc; ++c) wv[c] = w * value[c];
    // A flat (2D) level has one z layer: z0 = 0 with full weight.
    const float fz = L.flat ? 0.0f : std::floor(pos[2]);
    const int z0 = int(fz);
    const float wz = L.flat ? 0.0f : pos[2] - fz;
    if (!L.flat && x0 >= 0 && y0 >= 0 && z0 >= 0 && x0 + 1 < L.n[0] && y0 + 1 < L.n[1] && z0 + 1 < L.n[2]) {
        // Interior fast path: all eight corners exist.
        const size_t sx = size_t(L.n[1]) * size_t(L.n[2]) * 6, sy = size_t(L.n[2]) * 6, sz = 6;
        float* base = acc + L.idx(x0, y0, z0) * 6;
        const float w8[8] = {(1 - wx) * (1 - wy) * (1 - wz), (1 - wx) * (1 - wy) * wz, (1 - wx) * wy * (1 - wz),
            (1 - wx) * wy * wz, wx * (1 - wy) * (1 - wz), wx * (1 - wy) * wz, wx * wy * (1 - wz), wx * wy * wz};
        const size_t off[8] = {0, sz, sy, sy + sz, sx, sx + sz, sx + sy, sx + sy + sz};
        for (int k = 0; k < 8; ++k) {
            float* o = base + off[k];
            const float a = w8[k];
            for (int c = 0; c < nc; ++c) {
                o[comps[c]] += a * wv[c];
                o[3 + comps[c]] += a * w;
            }
        }
        return;
    }
    for (int cx = 0; cx < 2; ++cx) {
        const int x = x0 + cx;
        if (x < 0 || x >= L.n[0]) continue;
        const float ax = cx ? wx : 1 - wx;
        for (int cy = 0; cy < 2; ++cy) {
            const int y = y0 + cy;
            if (y < 0 || y >= L.n[1]) continue;
            const float axy = ax * (cy ? wy : 1 - wy);
            for (int cz = 0; cz < (L.flat ? 1 : 2); ++cz) {
                const int z = z0 + cz;
                if (z < 0 || z >= L.n[2]) continue;
                const float a = axy * (cz ? wz : 1 - wz);
                float* o = acc + L.idx(x, y, z) * 6;
                for (int c = 0; c < nc; ++c) {
                    o[comps[c]] += a * wv[c];
                    o[3 + comps[c]] += a * w;
                }
            }
        }
    }
}

struct Constraint
{
    size_t voxel;
    Vec3f normalLocal;
    float lambda;
};

struct Centre
{
    int p[3];
    Frame3 f;
};

struct Match
{
    int row = -1;
    float weight = 0.0f;
};

/// Everything one synthesis run needs besides the level data.
struct Engine
{
    const SynthExemplars::Impl& ex;
    const SynthSettings& s;
    const FrameGuide& frames;
    bool kcoh;
    Progress* progress;

    // k-coherence source maps: per view, exemplar pixel (linear index) per voxel, -1 = none.
    std::vector<std::vector<int>> source;

    int spacingFor(int radius, bool flat) const
    {
        if (s.spacing > 0) return s.spacing;
        return flat ? std::max(1, (2 * radius + 1) / 4) : 3;
    }

    /// Planar views in 3D see a plane; their neighbourhoods are extruded along the view normal with a
    /// tent reaching the neighbouring centre planes (layers within spacing/2), so that a centre
    /// lattice sparse along the normal still covers every voxel with every view. Returns the tent's
    /// half-width: layers -(ext-1)..(ext-1) get weight 1 - |layer|/ext.
    int extrusion(const PreparedView& pv, const Level& L, int spacing) const
    {
        return (pv.normal >= 0 && !L.flat) ? spacing / 2 + 1 : 1;
    }

    std::vector<Centre> centres(const Level& L, int spacing, std::uint64_t salt, int& slabAxis) const
    {
        int jit[3];
        for (int a = 0; a < 3; ++a)
            jit[a] = int(hash4(s.seed, salt, std::uint64_t(a), 0x51ab) % std::uint64_t(spacing));
        slabAxis = 0;
        for (int a = 1; a < 3; ++a)
            if (L.n[a] > L.n[slabAxis]) slabAxis = a;
        std::vector<int> pos[3];
        for (int a = 0; a < 3; ++a) {
            if (a == 2 && L.flat) {
                pos[a] = {0};
                continue;
            }
            const int j = std::min(jit[a], L.n[a] - 1);
            for (int p = j; p < L.n[a]; p += spacing) pos[a].push_back(p);
        }
        // Slab axis outermost, so slabs are contiguous runs of the list.
        int o[3] = {slabAxis, (slabAxis + 1) % 3, (slabAxis + 2) % 3};
        std::vector<Centre> c;
        c.reserve(pos[0].size() * pos[1].size() * pos[2].size());
        for (int a : pos[o[0]])
            for (int b : pos[o[1]])
                for (int d : pos[o[2]]) {
                    Centre ce;
                    ce.p[o[0]] = a;
                    ce.p[o[1]] = b;
                    ce.p[o[2]] = d;
                    c.push_back(ce);
                }
        parallelFor(c.size(), 1024, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) c[i].f = frames.at(L.world(c[i].p[0], c[i].p[1], c[i].p[2]));
        });
        return c;
    }

    /// Runs `fn(centreIndex)` over the centres slab by slab: even slabs in parallel, then odd ones.
    template<typename Fn>
    void bySlabs(const std::vector<Centre>& c, int slabAxis, float reach, Fn&& fn) const
    {
        const int width = std::max(4, 2 * int(std::ceil(reach)) + 3);
        std::vector<size_t> start; // first centre of each slab
        int current = -1;
        for (size_t i = 0; i < c.size(); ++i) {
            const int slab = c[i].p[slabAxis] / width;
            while (current < slab) {
                start.push_back(i);
                ++current;
            }
        }
        start.push_back(c.size());
        const size_t slabs = start.size() - 1;
        for (size_t phase = 0; phase < 2; ++phase) {
            const size_t count = (slabs + 1 - phase) / 2;
            parallelFor(count, 1, [&](size_t b, size_t e) {
                for (size_t k = b; k < e; ++k) {
                    const size_t sl = 2 * k + phase;
                    for (size_t i = start[sl]; i < start[sl + 1]; ++i) fn(i);
                }
            });
        }
    }

    /// Kwatra's objective of one iteration's centres and matches: at the search, after the weighted average
    /// (the M-step proper), and after everything that follows it (moment match, temporal and wall terms).
    struct Descent
    {
        double before = 0.0, averaged = 0.0, updated = 0.0;
    };

    /// One iteration's centres (jittered lattice, slab axis outermost) and, per centre and view, the matched
    /// exemplar row, its weight and its squared neighbourhood distance.
    struct Matches
    {
        int spacing = 1, slabAxis = 0;
        std::vector<Centre> cs;
        std::vector<Match> match; ///< centre-major: match[ci * views + v]
        std::vector<double> dist; ///< the same layout; 0 for random matches
    };

    /// The search (Kwatra's E-step): per centre and view the nearest exemplar neighbourhood (tree or k-coherence),
    /// or a random one for the initialisation, weighted by the robust weight.
    Matches search(const Level& L, int level, int which, bool useTree, bool randomMatches, std::uint64_t salt) const
    {
        const size_t nv = ex.prepared.size();
        int radius = 0;
        for (const auto& pv : ex.prepared) radius = std::max(radius, pv.levels[size_t(level)].neigh[which].radius);
        Matches m;
        m.spacing = spacingFor(radius, L.flat);
        m.cs = centres(L, m.spacing, salt, m.slabAxis);
        const size_t nc = m.cs.size();
        m.match.resize(nc * nv);
        m.dist.assign(nc * nv, 0.0);
        const double r = std::clamp(s.robustExponent, 0.01, 2.0);
        parallelFor(nc, 32, [&](size_t b, size_t e) {
            std::vector<float> d, red, exd;
            std::vector<int> cand;
            for (size_t ci = b; ci < e; ++ci) {
                const Centre& c = m.cs[ci];
                for (size_t v = 0; v < nv; ++v) {
                    const PreparedView& pv = ex.prepared[v];
                    const ViewLevel& vl = pv.levels[size_t(level)];
                    const Neigh& N = vl.neigh[which];
                    Match& mt = m.match[ci * nv + v];
                    if (randomMatches) {
                        mt.row = int(hash4(s.seed, salt, ci, v) % std::uint64_t(N.rows));
                        mt.weight = pv.view.weight;
                        continue;
                    }
                    gather(L, c, pv, N, d);
                    const Pca& pca = N.index.pca();
                    red.resize(pca.outputDim());
                    pca.project(d.data(), red.data());
                    int row = -1;
                    if (useTree) {
                        float d2;
                        N.index.queryReduced(red.data(), 1, &row, &d2);
                    } else {
                        row = kcoherenceSearch(L, c, vl, N, v, red, cand);
                    }
                    mt.row = row;
                    const double s2 = distanceTo(vl, N, pv.nc, row, d);
                    m.dist[ci * nv + v] = s2;
                    // Kwatra's robust weight |x_p - z_p|^(r - 2); the floor keeps exact matches finite.
                    mt.weight = float(pv.view.weight * std::pow(s2 + 1e-4, 0.5 * (r - 2.0)));
                }
            }
        });
        return m;
    }

    /// Kwatra's objective for these centres and matches with `h` as the level's detail: the weighted mean of the
    /// neighbourhood distances (weights fixed). L.h is swapped with `h` for the evaluation and back.
    double objective(Level& L, int level, int which, const Matches& m, std::vector<Vec3f>& h) const
    {
        const size_t nv = ex.prepared.size();
        std::swap(L.h, h);
        const double sums = parallelSum(m.cs.size(), 32, [&](size_t b, size_t e) {
            std::vector<float> d;
            double acc = 0.0;
            for (size_t ci = b; ci < e; ++ci)
                for (size_t v = 0; v < nv; ++v) {
                    const PreparedView& pv = ex.prepared[v];
                    const Neigh& N = pv.levels[size_t(level)].neigh[which];
                    const Match& mt = m.match[ci * nv + v];
                    gather(L, m.cs[ci], pv, N, d);
                    acc += double(mt.weight) * distanceTo(pv.levels[size_t(level)], N, pv.nc, mt.row, d);
                }
            return acc;
        });
        std::swap(L.h, h);
        double w = 0.0;
        for (const Match& mt : m.match) w += mt.weight;
        return w > 0.0 ? sums / w : 0.0;
    }

    /// How far a centre's splat reaches, in level voxels: the widest neighbourhood plus its extrusion, plus one.
    float splatReach(const Level& L, int level, int which, int spacing) const
    {
        float reach = 0.0f;
        for (const auto& pv : ex.prepared)
            reach = std::max(reach, pv.levels[size_t(level)].neigh[which].reach + float(extrusion(pv, L, spacing)));
        return reach + 1.0f;
    }

    /// The assignment's sums: every match's exemplar neighbourhood splatted onto the level (per voxel, three
    /// weighted component sums and their three weights), slab by slab.
    std::vector<float> splatMatches(const Level& L, int level, int which, const Matches& m, float reach) const
    {
        const size_t nv = ex.prepared.size();
        std::vector<float> acc(L.size() * 6, 0.0f);
        bySlabs(m.cs, m.slabAxis, reach, [&](size_t ci) {
            const Centre& c = m.cs[ci];
            const Vec3f p(float(c.p[0]), float(c.p[1]), float(c.p[2]));
            for (size_t v = 0; v < nv; ++v) {
                const PreparedView& pv = ex.prepared[v];
                const ViewLevel& vl = pv.levels[size_t(level)];
                const Neigh& N = vl.neigh[which];
                const Match& mt = m.match[ci * nv + v];
                const auto pos = posOf(N, vl.ex, size_t(mt.row));
                const int ext = extrusion(pv, L, m.spacing);
                const Vec3f nrm = pv.normal >= 0 ? c.f.e[pv.normal] : Vec3f(0.0f);
                for (size_t t = 0; t < N.local.size(); ++t) {
                    const float* z = exValue(vl.ex, pos, N.ex[t]);
                    const Vec3f base = p + c.f.toWorld(N.local[t]);
                    for (int layer = -(ext - 1); layer <= ext - 1; ++layer) {
                        const float tent = 1.0f - float(std::abs(layer)) / float(ext);
                        const Vec3f at = base + nrm * float(layer);
                        splat(L, acc.data(), at, pv.comps, z, pv.nc, mt.weight * tent);
                    }
                }
            }
        });
        return acc;
    }

    /// Least-squares value per component (Eq. 1 / Eq. 2) from the splatted sums; components no view reached keep
    /// the level's.
    static std::vector<Vec3f> weightedAverage(const Level& L, const std::vector<float>& acc)
    {
        std::vector<Vec3f> avg(L.h);
        parallelFor(L.size(), 4096, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) {
                const float* o = &acc[i * 6];
                for (int c = 0; c < 3; ++c)
                    if (o[3 + c] > 0.0f) avg[i][c] = o[c] / o[3 + c];
            }
        });
        return avg;
    }

    /// Temporal coherence (O(x) of Eq. 1) and the wall term E_n (Eq. 3), both closed form, applied to `avg`.
    void temporalAndWallTerms(const Level& L, const std::vector<float>& acc, const std::vector<Vec3f>* advected,
        const std::vector<Constraint>& constraints, std::vector<Vec3f>& avg) const
    {
        if (advected) {
            const float eta = float(std::max(0.0, s.temporalWeight));
            parallelFor(L.size(), 4096, [&](size_t b, size_t e) {
                for (size_t i = b; i < e; ++i) {
                    const float* o = &acc[i * 6];
                    for (int c = 0; c < 3; ++c)
                        if (o[3 + c] > 0.0f) avg[i][c] = (avg[i][c] + eta * (*advected)[i][c]) / (1.0f + eta);
                }
            });
        }
        for (const Constraint& k : constraints) {
            Vec3f& x = avg[k.voxel];
            x -= k.normalLocal * (k.normalLocal.dot(x) * (k.lambda / (1.0f + k.lambda)));
        }
    }

    /// One search + assignment iteration. `which`: 0 small radius, 1 large. `randomMatches`: the
    /// initialisation (random exemplar neighbourhoods blended by the assignment, section 3.4).
    /// Returns the mean squared neighbourhood distance per channel before the assignment; fills `trace`
    /// when given (two more neighbourhood passes).
    double iterate(Level& L, int level, int which, bool useTree, bool randomMatches, std::uint64_t salt,
        const std::vector<Vec3f>* advected, const std::vector<Constraint>& constraints, Descent* trace = nullptr)
    {
        Matches m = search(L, level, which, useTree, randomMatches, salt);
        double energy = 0.0;
        for (double x : m.dist) energy += x;
        energy /= double(std::max<size_t>(1, m.dist.size()));
        if (trace && !randomMatches) {
            double w = 0.0, wd = 0.0;
            for (size_t i = 0; i < m.match.size(); ++i) {
                w += m.match[i].weight;
                wd += double(m.match[i].weight) * m.dist[i];
            }
            trace->before = w > 0.0 ? wd / w : 0.0;
        }

        const float reach = splatReach(L, level, which, m.spacing);
        const std::vector<float> acc = splatMatches(L, level, which, m, reach);
        std::vector<Vec3f> avg = weightedAverage(L, acc);
        if (trace && !randomMatches) trace->averaged = objective(L, level, which, m, avg);
        if (kcoh) discreteAssign(L, level, which, m.cs, m.slabAxis, reach, m.match, m.spacing, avg);
        if (s.matchVariance) matchMoments(L, level, acc, avg);
        temporalAndWallTerms(L, acc, advected, constraints, avg);
        if (trace && !randomMatches) trace->updated = objective(L, level, which, m, avg);
        L.h.swap(avg);
        return energy;
    }

    /// The neighbourhood of view `pv` around centre `c` on L, as the search sees it (taps in c's frame).
    void gather(const Level& L, const Centre& c, const PreparedView& pv, const Neigh& N, std::vector<float>& d) const
    {
        d.resize(N.local.size() * size_t(pv.nc));
        for (size_t t = 0; t < N.local.size(); ++t) {
            const Vec3f off = c.f.toWorld(N.local[t]);
            const Vec3f h = L.sample(float(c.p[0]) + off[0], float(c.p[1]) + off[1], float(c.p[2]) + off[2]);
            for (int ch = 0; ch < pv.nc; ++ch) d[t * size_t(pv.nc) + size_t(ch)] = h[pv.comps[ch]];
        }
    }

    /// Mean squared difference per value between a gathered neighbourhood and exemplar row `row`.
    static double distanceTo(const ViewLevel& vl, const Neigh& N, int nc, int row, const std::vector<float>& d)
    {
        const auto pos = posOf(N, vl.ex, size_t(row));
        double s2 = 0.0;
        for (size_t t = 0; t < N.ex.size(); ++t) {
            const float* z = exValue(vl.ex, pos, N.ex[t]);
            for (int ch = 0; ch < nc; ++ch) {
                const double q = double(d[t * size_t(nc) + size_t(ch)]) - z[ch];
                s2 += q * q;
            }
        }
        return s2 / double(std::max<size_t>(1, d.size()));
    }

    /// Components that two or more views share are averages of views that do not fully agree, and
    /// lose variance (Kopf et al. 2007 restore it by histogram matching). Here each shared component
    /// gets the weighted mean and standard deviation of the exemplar channels that feed it.
    void matchMoments(const Level& L, int level, const std::vector<float>& acc, std::vector<Vec3f>& avg) const
    {
        for (int c = 0; c < 3; ++c) {
            double tw = 0.0, tm = 0.0, tv = 0.0;
            int views = 0;
            for (const auto& pv : ex.prepared)
                for (int ch = 0; ch < pv.nc; ++ch)
                    if (pv.comps[ch] == c) {
                        const ViewLevel& vl = pv.levels[size_t(level)];
                        tw += pv.view.weight;
                        tm += pv.view.weight * vl.mean[ch];
                        tv += pv.view.weight * vl.stdev[ch] * vl.stdev[ch];
                        ++views;
                    }
            if (views < 2 || tw <= 0.0) continue;
            tm /= tw;
            const double tsd = std::sqrt(tv / tw);
            const size_t n = L.size();
            const double cnt = parallelSum(n, 8192, [&](size_t b, size_t e) {
                double k = 0.0;
                for (size_t i = b; i < e; ++i) k += acc[i * 6 + 3 + size_t(c)] > 0.0f ? 1.0 : 0.0;
                return k;
            });
            if (cnt < 2.0) continue;
            const double sum = parallelSum(n, 8192, [&](size_t b, size_t e) {
                double k = 0.0;
                for (size_t i = b; i < e; ++i)
                    if (acc[i * 6 + 3 + size_t(c)] > 0.0f) k += avg[i][c];
                return k;
            });
            const double mean = sum / cnt;
            const double var = parallelSum(n, 8192, [&](size_t b, size_t e) {
                double k = 0.0;
                for (size_t i = b; i < e; ++i)
                    if (acc[i * 6 + 3 + size_t(c)] > 0.0f) k += (avg[i][c] - mean) * (avg[i][c] - mean);
                return k;
            }) / cnt;
            if (!(var > 0.0)) continue;
            const float gain = float(tsd / std::sqrt(var));
            parallelFor(n, 8192, [&](size_t b, size_t e) {
                for (size_t i = b; i < e; ++i)
                    if (acc[i * 6 + 3 + size_t(c)] > 0.0f) avg[i][c] = float(tm + (avg[i][c] - mean) * gain);
            });
        }
    }

    int kcoherenceSearch(const Level& L, const Centre& c, const ViewLevel& vl, const Neigh& N, size_t v,
        const std::vector<float>& red, std::vector<int>& cand) const
    {
        cand.clear();
        const std::vector<int>& S = source[v];
        for (size_t o = 0; o < N.coherence.size(); ++o) {
            const Vec3f off = c.f.toWorld(N.coherence[o]);
            const int q[3] = {int(std::lround(c.p[0] + off[0])), int(std::lround(c.p[1] + off[1])),
                L.flat ? 0 : int(std::lround(c.p[2] + off[2]))};
            if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= L.n[0] || q[1] >= L.n[1] || q[2] >= L.n[2]) continue;
            const int src = S[L.idx(q[0], q[1], q[2])];
            if (src < 0) continue;
            const size_t yz = size_t(vl.ex.ny) * size_t(vl.ex.nz);
            std::array<int, 3> p = {int(size_t(src) / yz), int((size_t(src) / size_t(vl.ex.nz)) % size_t(vl.ex.ny)),
                int(size_t(src) % size_t(vl.ex.nz))};
            for (int a = 0; a < 3; ++a) p[size_t(a)] -= N.coherenceEx[o][size_t(a)];
            p = validPos(N, vl.ex, p);
            const int row = int(rowOf(N, vl.ex, p[0], p[1], p[2]));
            cand.push_back(row);
            for (int j = 0; j < N.k; ++j) cand.push_back(N.similar[size_t(row) * size_t(N.k) + size_t(j)]);
        }
        if (cand.empty()) cand.push_back(0);
        const size_t k = N.index.pca().outputDim();
        int best = cand[0];
        float bestD = std::numeric_limits<float>::max();
        for (size_t i = 0; i < cand.size(); ++i) {
            const int row = cand[i];
            if (std::find(cand.begin(), cand.begin() + long(i), row) != cand.begin() + long(i)) continue;
            const float* q = &N.reduced[size_t(row) * k];
            float d = 0.0f;
            for (size_t j = 0; j < k; ++j) {
                const float t = red[j] - q[j];
                d += t * t;
            }
            if (d < bestD) {
                bestD = d;
                best = row;
            }
        }
        return best;
    }

    /// k-coherence assignment (Pseudocode 2): each voxel takes, per view, the candidate exemplar pixel
    /// closest to the least-squares average, among the pixels its covering neighbourhoods propose.
    void discreteAssign(const Level& L, int level, int which, const std::vector<Centre>& cs, int slabAxis, float reach,
        const std::vector<Match>& match, int spacing, std::vector<Vec3f>& avg)
    {
        const size_t nv = ex.prepared.size();
        std::vector<std::vector<int>> best(nv, std::vector<int>(L.size(), -1));
        std::vector<std::vector<float>> err(nv, std::vector<float>(L.size(), std::numeric_limits<float>::max()));
        bySlabs(cs, slabAxis, reach, [&](size_t ci) {
            const Centre& c = cs[ci];
            for (size_t v = 0; v < nv; ++v) {
                const PreparedView& pv = ex.prepared[v];
                const ViewLevel& vl = pv.levels[size_t(level)];
                const Neigh& N = vl.neigh[which];
                const auto pos = posOf(N, vl.ex, size_t(match[ci * nv + v].row));
                const int ext = extrusion(pv, L, spacing);
                const Vec3f nrm = pv.normal >= 0 ? c.f.e[pv.normal] : Vec3f(0.0f);
                for (size_t t = 0; t < N.local.size(); ++t) {
                    const Vec3f base = Vec3f(float(c.p[0]), float(c.p[1]), float(c.p[2])) + c.f.toWorld(N.local[t]);
                    std::array<int, 3> px = {pos[0] + N.ex[t][0], pos[1] + N.ex[t][1], pos[2] + N.ex[t][2]};
                    if (vl.ex.periodic) px = {wrapi(px[0], vl.ex.nx), wrapi(px[1], vl.ex.ny), wrapi(px[2], vl.ex.nz)};
                    const float* z = vl.ex.at(px[0], px[1], px[2]);
                    const int lin = int(vl.ex.linear(px[0], px[1], px[2]));
                    for (int layer = -(ext - 1); layer <= ext - 1; ++layer) {
                        const Vec3f at = base + nrm * float(layer);
                        const int q[3] = {
                            int(std::lround(at[0])), int(std::lround(at[1])), L.flat ? 0 : int(std::lround(at[2]))};
                        if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= L.n[0] || q[1] >= L.n[1] || q[2] >= L.n[2])
                            continue;
                        const size_t qi = L.idx(q[0], q[1], q[2]);
                        float e2 = 0.0f;
                        for (int ch = 0; ch < pv.nc; ++ch) {
                            const float t2 = z[ch] - avg[qi][pv.comps[ch]];
                            e2 += t2 * t2;
                        }
                        if (e2 < err[v][qi]) {
                            err[v][qi] = e2;
                            best[v][qi] = lin;
                        }
                    }
                }
            }
        });
        parallelFor(L.size(), 4096, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) {
                float sum[3] = {0, 0, 0}, w[3] = {0, 0, 0};
                for (size_t v = 0; v < nv; ++v) {
                    const int lin = best[v][i];
                    if (lin < 0) continue;
                    source[v][i] = lin;
                    const PreparedView& pv = ex.prepared[v];
                    const float* z = &pv.levels[size_t(level)].ex.values[size_t(lin) * size_t(pv.nc)];
                    for (int ch = 0; ch < pv.nc; ++ch) {
                        sum[pv.comps[ch]] += pv.view.weight * z[ch];
                        w[pv.comps[ch]] += pv.view.weight;
                    }
                }
                for (int c = 0; c < 3; ++c)
                    if (w[c] > 0.0f) avg[i][c] = sum[c] / w[c];
            }
        });
    }
};

/// Soft wall constraints of one level: voxels near walls or obstacles, their normal in the local
/// frame, and lambda from a Gaussian of the distance in level voxels (section 3.6).
std::vector<Constraint> makeConstraints(
    const Level& L, const FrameGuide& frames, const BoundarySettings& b, const ScalarField* obstacle)
{
    std::vector<Constraint> out;
    if (b.lambda <= 0.0 || (b.walls == 0 && !obstacle)) return out;
    const double sigma = std::max(1e-3, b.width);
    const double cutoff = 4.0 * sigma;
    for (int x = 0; x < L.n[0]; ++x)
        for (int y = 0; y < L.n[1]; ++y)
            for (int z = 0; z < L.n[2]; ++z) {
                const int c[3] = {x, y, z};
                Frame3 f;
                bool haveFrame = false;
                const auto add = [&](const Vec3f& nWorld, double dist) {
                    if (dist > cutoff) return;
                    if (!haveFrame) {
                        f = frames.at(L.world(x, y, z));
                        haveFrame = true;
                    }
                    Constraint k;
                    k.voxel = L.idx(x, y, z);
                    k.normalLocal = f.toLocal(nWorld);
                    k.lambda = float(b.lambda * std::exp(-0.5 * dist * dist / (sigma * sigma)));
                    out.push_back(k);
                };
                for (int a = 0; a < 3; ++a) {
                    if (a == 2 && L.flat) continue;
                    Vec3f n(0.0f);
                    n[a] = 1.0f;
                    // The wall lies on the domain face, half a voxel beyond the outermost centre.
                    if (b.walls & (1u << (2 * a))) add(n, c[a] + 0.5);
                    if (b.walls & (1u << (2 * a + 1))) add(n, L.n[a] - 1 - c[a] + 0.5);
                }
                if (obstacle && !obstacle->empty()) {
                    const Vec3d w = L.world(x, y, z);
                    const double sd = sampleWorld(*obstacle, w);
                    const double dist = std::max(0.0, sd) / L.voxel();
                    if (dist <= cutoff) {
                        const double h = obstacle->lattice().voxelSize;
                        Vec3f g;
                        for (int a = 0; a < 3; ++a) {
                            Vec3d dp(0.0);
                            dp[a] = h;
                            g[a] = float(sampleWorld(*obstacle, w + dp) - sampleWorld(*obstacle, w - dp));
                        }
                        if (L.flat) g[2] = 0.0f;
                        if (g.length() > 0.0f) add(g / g.length(), dist);
                    }
                }
            }
    return out;
}

/// Throws unless every view's exemplar is well formed and usable; returns the smallest exemplar's larger side.
int checkExemplarViews(const std::vector<SynthView>& views)
{
    int smallest = std::numeric_limits<int>::max();
    for (const auto& v : views) {
        const Exemplar& e = v.exemplar;
        if (e.count() == 0 || e.values.size() != e.count() * size_t(e.channels))
            throw ValueError("synth: exemplar '" + e.name + "' is empty or malformed");
        if (!(v.weight > 0.0f)) throw ValueError("synth: view weights must be > 0");
        if (e.planar() && (v.normal < 0 || v.normal > 2)) throw ValueError("synth: a view normal must be 0, 1 or 2");
        for (float x : e.values)
            if (!std::isfinite(x)) throw ValueError("synth: exemplar '" + e.name + "' holds NaN or Inf");
        smallest = std::min(smallest, std::max(e.nx, e.ny));
    }
    return smallest;
}

/// The pyramid's depth. Paper: 3 levels, 2 when the input is <= 16^2; never so many that the coarsest exemplar
/// drops below 8 pixels.
int pyramidLevels(const std::vector<SynthView>& views, const SynthSettings& s, int smallest)
{
    int levels = s.levels > 0 ? s.levels : (smallest <= 16 ? 2 : 3);
    for (const auto& v : views) {
        int m2 = std::min(v.exemplar.nx, v.exemplar.ny);
        if (!v.exemplar.planar()) m2 = std::min(m2, v.exemplar.nz);
        int fit = 1;
        while ((m2 >> fit) >= 8) ++fit;
        levels = std::max(1, std::min(levels, fit));
    }
    return levels;
}

/// One view's exemplar pyramid (coarsest first) with each level's per-channel mean and standard deviation.
void prepareView(PreparedView& pv, const SynthView& view, int levels)
{
    pv.view = view;
    if (view.exemplar.planar()) {
        pv.nc = 2;
        pv.normal = view.normal;
        planeAxes(pv.normal, pv.comps[0], pv.comps[1]);
    } else {
        pv.nc = 3;
        pv.normal = -1;
    }
    pv.levels.resize(size_t(levels));
    pv.levels[size_t(levels - 1)].ex = view.exemplar;
    for (int l = levels - 2; l >= 0; --l) {
        // Halving with the pixel-centre-aligned resampler is the 2x2(x2) box mean.
        pv.levels[size_t(l)].ex = rescaledExemplar(pv.levels[size_t(l + 1)].ex, 0.5);
    }
    for (ViewLevel& vl : pv.levels) {
        const size_t n = vl.ex.count();
        for (int ch = 0; ch < pv.nc; ++ch) {
            double sum = 0.0, sq = 0.0;
            for (size_t k = 0; k < n; ++k) sum += vl.ex.values[k * size_t(pv.nc) + size_t(ch)];
            vl.mean[ch] = sum / double(n);
            for (size_t k = 0; k < n; ++k) {
                const double d = vl.ex.values[k * size_t(pv.nc) + size_t(ch)] - vl.mean[ch];
                sq += d * d;
            }
            vl.stdev[ch] = std::sqrt(sq / double(n));
        }
    }
}

/// Indexes every (view, level, radius) neighbourhood set; the tasks are independent, so they are built in parallel.
void indexNeighbourhoods(std::vector<PreparedView>& prepared, int levels, const SynthSettings& s, bool volume,
    bool kcoherence, Progress* progress)
{
    struct Task
    {
        size_t view;
        int level, which, radius;
    };
    std::vector<Task> tasks;
    for (size_t i = 0; i < prepared.size(); ++i)
        for (int l = 0; l < levels; ++l) {
            tasks.push_back({i, l, 0, s.smallRadius});
            if (!volume && s.largeIterations > 0) tasks.push_back({i, l, 1, s.largeRadius});
        }
    withThreads(s.threads, [&] {
        parallelFor(tasks.size(), 1, [&](size_t b, size_t e) {
            for (size_t t = b; t < e; ++t) {
                checkCancelled(progress);
                PreparedView& pv = prepared[tasks[t].view];
                ViewLevel& vl = pv.levels[size_t(tasks[t].level)];
                buildNeigh(vl.neigh[tasks[t].which], pv, vl.ex, tasks[t].radius, s, kcoherence);
            }
        });
    });
}

} // namespace

// ---------------------------------------------------------------------------------------------

SynthExemplars::SynthExemplars(std::vector<SynthView> views, const SynthSettings& s, bool volume, Progress* progress)
    : mImpl(std::make_unique<Impl>())
{
    Impl& m = *mImpl;
    if (views.empty()) throw ValueError("synth: no exemplar views");
    m.volume = volume;
    m.kcoherence = s.search == SearchMethod::KCoherence;
    m.kSimilar = s.kSimilar;
    if (!volume) {
        if (views.size() != 1) throw ValueError("synth: a 2D synthesis takes exactly one exemplar");
        if (!views[0].exemplar.planar())
            throw ValueError("synth: a 2D synthesis needs a planar exemplar, not a volume");
        views[0].normal = 2;
    }
    const int levels = pyramidLevels(views, s, checkExemplarViews(views));
    m.levels = levels;
    m.views = views;
    m.prepared.resize(views.size());
    for (size_t i = 0; i < views.size(); ++i) prepareView(m.prepared[i], views[i], levels);
    indexNeighbourhoods(m.prepared, levels, s, volume, m.kcoherence, progress);
}

SynthExemplars::~SynthExemplars() = default;
SynthExemplars::SynthExemplars(SynthExemplars&&) noexcept = default;
SynthExemplars& SynthExemplars::operator=(SynthExemplars&&) noexcept = default;

int SynthExemplars::levels() const { return mImpl->levels; }
bool SynthExemplars::volume() const { return mImpl->volume; }
const std::vector<SynthView>& SynthExemplars::views() const { return mImpl->views; }
std::vector<double> SynthExemplars::explainedVariance() const
{
    std::vector<double> out;
    for (const auto& pv : mImpl->prepared) out.push_back(pv.levels.back().neigh[0].index.pca().explainedVariance());
    return out;
}

FineDomain fineDomain(const CoordBBox& cb, const Lattice& coarseLattice, int factor)
{
    if (factor < 1) throw ValueError("synth: the up-res factor must be >= 1");
    FineDomain d;
    d.twoD = cb.dim().z() == 1;
    d.lattice = coarseLattice.refined(factor);
    d.box = refineBox(cb, factor);
    if (d.twoD) {
        // Keep one voxel in z, at the height of the coarse slice.
        const int k0 = cb.min().z();
        d.box = CoordBBox(Coord(d.box.min().x(), d.box.min().y(), k0), Coord(d.box.max().x(), d.box.max().y(), k0));
        Vec3d o = d.lattice.origin;
        o[2] = coarseLattice.origin.z() + k0 * coarseLattice.voxelSize - k0 * d.lattice.voxelSize;
        d.lattice.origin = o;
    }
    return d;
}

namespace {

/// `f` on `box` (a superset of its own), each voxel outside taking the value of the nearest face voxel.
template<typename T>
Field<T> extendedByFaces(const Field<T>& f, const CoordBBox& box)
{
    Field<T> out(box, f.lattice());
    const CoordBBox& b = f.bbox();
    parallelFor(size_t(box.dim().x()), 1, [&](size_t i0, size_t i1) {
        for (size_t di = i0; di < i1; ++di) {
            const int i = std::clamp(box.min().x() + int(di), b.min().x(), b.max().x());
            for (int j = box.min().y(); j <= box.max().y(); ++j)
                for (int k = box.min().z(); k <= box.max().z(); ++k)
                    out(box.min().x() + int(di), j, k) =
                        f(i, std::clamp(j, b.min().y(), b.max().y()), std::clamp(k, b.min().z(), b.max().z()));
        }
    });
    return out;
}

DetailField synthesizeOnBox(
    const SynthExemplars& exemplars, const SynthInput& in, const SynthSettings& s, Progress* progress);

} // namespace

DetailField synthesizeDetail(
    const SynthExemplars& exemplars, const SynthInput& in, const SynthSettings& s, Progress* progress)
{
    if (s.facePadding < 0) throw ValueError("synth: face padding must be >= 0 cells");
    for (const Vec3d* v : {&s.orientation.secondary, &s.orientation.fallback})
        if (!std::isfinite(float(v->x())) || !std::isfinite(float(v->y())) || !std::isfinite(float(v->z())))
            throw ValueError("synth: the secondary and fallback directions must be finite");
    if (!in.coarse || in.coarse->empty() || s.facePadding == 0) return synthesizeOnBox(exemplars, in, s, progress);
    if (in.coarseDensity && !in.coarseDensity->empty() && in.coarseDensity->bbox() != in.coarse->bbox())
        throw ValueError("synth: the coarse density and velocity must cover the same box");
    const CoordBBox box = in.coarse->bbox();
    const bool flat = box.dim().z() == 1; // as fineDomain: a 2D synthesis stays one layer
    CoordBBox grown = box;
    for (int a = 0; a < (flat ? 2 : 3); ++a) {
        if (!(s.boundary.walls & (1u << (2 * a)))) grown.min()[a] -= s.facePadding;
        if (!(s.boundary.walls & (1u << (2 * a + 1)))) grown.max()[a] += s.facePadding;
    }
    if (grown == box) return synthesizeOnBox(exemplars, in, s, progress);

    const VectorField coarse = extendedByFaces(*in.coarse, grown);
    ScalarField density;
    SynthInput grownIn = in;
    grownIn.coarse = &coarse;
    if (in.coarseDensity && !in.coarseDensity->empty()) {
        density = extendedByFaces(*in.coarseDensity, grown);
        grownIn.coarseDensity = &density;
    }
    DetailField previous;
    if (in.previous && !in.previous->padded.empty()) {
        previous.world = in.previous->padded;
        grownIn.previous = &previous;
    }
    DetailField d = synthesizeOnBox(exemplars, grownIn, s, progress);
    const CoordBBox fine = fineDomain(*in.coarse, in.factor).box;
    DetailField out;
    out.world = cropped(d.world, fine);
    out.local = cropped(d.local, fine);
    out.levels = std::move(d.levels);
    out.fromPrevious = d.fromPrevious;
    out.padded = std::move(d.world);
    return out;
}

namespace {

/// Throws ValueError on a missing or non-finite L, a dimension the views were not prepared for, a density on another
/// box, or a continuation without dt.
void checkSynthInput(const SynthExemplars::Impl& ex, const SynthInput& in, const FineDomain& dom)
{
    if (dom.twoD == ex.volume)
        throw ValueError(dom.twoD
                             ? "synth: the coarse motion is 2D (one voxel thick) but the views were prepared for 3D"
                             : "synth: the coarse motion is 3D but the views were prepared for a 2D synthesis");
    if (in.coarseDensity && !in.coarseDensity->empty() && in.coarseDensity->bbox() != in.coarse->bbox())
        throw ValueError("synth: the coarse density and velocity must cover the same box");
    const bool continuing = in.previous && !in.previous->world.empty();
    if (continuing && !(in.dt > 0.0)) throw ValueError("synth: continuing from a previous frame needs dt > 0");
}

/// Pyramid level `level` of `levels` over the fine domain (the last level is the fine lattice), with H = 0.
Level emptyLevel(int level, int levels, const FineDomain& dom)
{
    const Coord N = dom.box.dim();
    Level L;
    L.shrink = 1 << (levels - 1 - level);
    L.flat = dom.twoD;
    for (int a = 0; a < 3; ++a) L.n[a] = (a == 2 && L.flat) ? 1 : std::max(1, (N[a] + L.shrink - 1) / L.shrink);
    L.fineMin = Vec3d(dom.box.min().x(), dom.box.min().y(), dom.box.min().z());
    L.fineLat = dom.lattice;
    L.h.assign(L.size(), Vec3f(0.0f));
    return L;
}

/// H of the coarser level `L` upsampled onto `next` (cell-centred trilinear).
void upsampleDetail(const Level& L, Level& next)
{
    parallelFor(size_t(next.n[0]), 1, [&](size_t b, size_t e) {
        for (size_t x = b; x < e; ++x)
            for (int y = 0; y < next.n[1]; ++y)
                for (int z = 0; z < next.n[2]; ++z)
                    next.h[next.idx(int(x), y, z)] = L.sample(float((x + 0.5) / 2 - 0.5), float((y + 0.5) / 2 - 0.5),
                        next.flat ? 0.0f : float((z + 0.5) / 2 - 0.5));
    });
}

/// Pure k-coherence's source maps carried from level `level - 1` (on L) to `level` (on next): each voxel takes its
/// parent's exemplar pixel, doubled and offset by the voxel's parity in the view's plane.
void upsampleSources(Engine& eng, const Level& L, const Level& next, int level)
{
    const SynthExemplars::Impl& ex = eng.ex;
    std::vector<std::vector<int>> up(ex.prepared.size(), std::vector<int>(next.size(), -1));
    for (size_t v = 0; v < ex.prepared.size(); ++v) {
        const Exemplar& ec = ex.prepared[v].levels[size_t(level - 1)].ex;
        const Exemplar& ef = ex.prepared[v].levels[size_t(level)].ex;
        int u = 0, w = 1, t = 2;
        if (ex.prepared[v].normal >= 0) planeAxes(ex.prepared[v].normal, u, w);
        for (int x = 0; x < next.n[0]; ++x)
            for (int y = 0; y < next.n[1]; ++y)
                for (int z = 0; z < next.n[2]; ++z) {
                    const int src = eng.source[v][L.idx(
                        std::min(x / 2, L.n[0] - 1), std::min(y / 2, L.n[1] - 1), std::min(z / 2, L.n[2] - 1))];
                    if (src < 0) continue;
                    const size_t yz = size_t(ec.ny) * size_t(ec.nz);
                    const int c[3] = {x, y, z};
                    int px = 2 * int(size_t(src) / yz) + (c[u] & 1);
                    int py = 2 * int((size_t(src) / size_t(ec.nz)) % size_t(ec.ny)) + (c[w] & 1);
                    int pz = ec.planar() ? 0 : 2 * int(size_t(src) % size_t(ec.nz)) + (c[t] & 1);
                    px = ef.periodic ? wrapi(px, ef.nx) : std::min(px, ef.nx - 1);
                    py = ef.periodic ? wrapi(py, ef.ny) : std::min(py, ef.ny - 1);
                    pz = ef.periodic ? wrapi(pz, ef.nz) : std::min(pz, ef.nz - 1);
                    up[v][next.idx(x, y, z)] = int(ef.linear(px, py, pz));
                }
    }
    eng.source.swap(up);
}

/// Counts the run's iterations for the progress bar and asks for cancellation after each.
struct IterationTicker
{
    Progress* progress = nullptr;
    int total = 1;
    int done = 0;
    void operator()()
    {
        ++done;
        if (progress) progress->update(double(done) / double(std::max(1, total)));
        checkCancelled(progress);
    }
};

/// Appends one iteration's numbers to a level's statistics.
void recordIteration(SynthLevelStats& st, int radius, bool tree, double energy, const Engine::Descent& d, bool trace)
{
    st.radius.push_back(radius);
    st.tree.push_back(tree);
    st.energy.push_back(energy);
    if (trace) st.descent.push_back({d.before, d.averaged, d.updated});
}

/// One pyramid level's iterations (section 3.3): the random initialisation on the coarsest level, then for 2D views
/// the large-radius iterations, then the small-radius ones.
SynthLevelStats synthesizeLevel(
    Engine& eng, Level& L, int level, const std::vector<Constraint>& cons, IterationTicker& tick)
{
    const SynthExemplars::Impl& ex = eng.ex;
    const SynthSettings& s = eng.s;
    SynthLevelStats st;
    st.level = level;
    st.dim = Coord(L.n[0], L.n[1], L.n[2]);
    int it = 0;
    if (level == 0) {
        eng.iterate(
            L, level, ex.volume || s.largeIterations <= 0 ? 0 : 1, true, true, hash4(0, 0, 0, 0xabc), nullptr, cons);
        tick();
    }
    const auto run = [&](int which, int count) {
        for (int i = 0; i < count; ++i, ++it) {
            const bool tree = !eng.kcoh || it < s.treeIterationsPerLevel;
            Engine::Descent d;
            const double e = eng.iterate(L, level, which, tree, false,
                hash4(1, std::uint64_t(level), std::uint64_t(it), 0), nullptr, cons, s.traceDescent ? &d : nullptr);
            int radius = 0;
            for (const auto& pv : ex.prepared) radius = std::max(radius, pv.levels[size_t(level)].neigh[which].radius);
            recordIteration(st, radius, tree, e, d, s.traceDescent);
            tick();
        }
    };
    if (!ex.volume) run(1, std::max(0, s.largeIterations));
    run(0, std::max(0, s.smallIterations));
    return st;
}

/// The whole pyramid from a zero start, coarsest level first; returns the finest level.
Level synthesizePyramid(Engine& eng, const SynthInput& in, const FineDomain& dom, IterationTicker& tick,
    std::vector<SynthLevelStats>& levels)
{
    const SynthExemplars::Impl& ex = eng.ex;
    const int nL = ex.levels;
    Level L;
    for (int level = 0; level < nL; ++level) {
        Level next = emptyLevel(level, nL, dom);
        if (level > 0) {
            // Upsample H (cell-centred trilinear) and, for pure k-coherence, the source maps.
            upsampleDetail(L, next);
            if (eng.kcoh) upsampleSources(eng, L, next, level);
        } else {
            eng.source.assign(ex.prepared.size(), std::vector<int>(next.size(), -1));
        }
        L = std::move(next);
        const std::vector<Constraint> cons = makeConstraints(L, eng.frames, eng.s.boundary, in.obstacle);
        levels.push_back(synthesizeLevel(eng, L, level, cons, tick));
    }
    return L;
}

/// Section 3.4: the finest level started from the previous detail advected through L and expressed in the new
/// frames, then refined (the advected detail is the temporal term's target).
SynthLevelStats continueFromPrevious(
    Engine& eng, Level& L, const SynthInput& in, const FineDomain& dom, IterationTicker& tick)
{
    const SynthExemplars::Impl& ex = eng.ex;
    const SynthSettings& s = eng.s;
    const int nL = ex.levels;
    L = emptyLevel(nL - 1, nL, dom);
    eng.source.assign(ex.prepared.size(), std::vector<int>(L.size(), -1));
    VectorField prev = in.previous->world;
    const VectorField moved = advect(prev, *in.coarse, in.dt, s.advect);
    std::vector<Vec3f> adv(L.size(), Vec3f(0.0f));
    parallelFor(size_t(L.n[0]), 1, [&](size_t b, size_t e) {
        for (size_t x = b; x < e; ++x)
            for (int y = 0; y < L.n[1]; ++y)
                for (int z = 0; z < L.n[2]; ++z) {
                    const Coord c = dom.box.min() + Coord(int(x), y, z);
                    const Vec3f w = moved.valueOr(c.x(), c.y(), c.z(), Vec3f(0.0f));
                    adv[L.idx(int(x), y, z)] = eng.frames.at(L.world(double(x), y, z)).toLocal(w);
                }
    });
    L.h = adv;
    const std::vector<Constraint> cons = makeConstraints(L, eng.frames, s.boundary, in.obstacle);
    SynthLevelStats st;
    st.level = nL - 1;
    st.dim = Coord(L.n[0], L.n[1], L.n[2]);
    for (int it = 0; it < std::max(1, s.continueIterations); ++it) {
        // k-coherence has no source map yet on a continued frame: its first iteration searches the tree.
        const bool tree = !eng.kcoh || it < std::max(1, s.treeIterationsPerLevel);
        Engine::Descent d;
        const double e = eng.iterate(
            L, nL - 1, 0, tree, false, hash4(2, std::uint64_t(it), 0, 0), &adv, cons, s.traceDescent ? &d : nullptr);
        int radius = 0;
        for (const auto& pv : ex.prepared) radius = std::max(radius, pv.levels.back().neigh[0].radius);
        recordIteration(st, radius, tree, e, d, s.traceDescent);
        tick();
    }
    return st;
}

/// Post-process coordinate transformation (section 3.1): H' = R H, with H kept as `local`.
void detailToWorld(const Level& L, const FineDomain& dom, const FrameGuide& frames, DetailField& out)
{
    out.local = VectorField(dom.box, dom.lattice);
    out.world = VectorField(dom.box, dom.lattice);
    parallelFor(size_t(L.n[0]), 1, [&](size_t b, size_t e) {
        for (size_t x = b; x < e; ++x)
            for (int y = 0; y < L.n[1]; ++y)
                for (int z = 0; z < L.n[2]; ++z) {
                    const Vec3f h = L.h[L.idx(int(x), y, z)];
                    const Coord c = dom.box.min() + Coord(int(x), y, z);
                    out.local[c] = h;
                    out.world[c] = frames.at(L.world(double(x), y, z)).toWorld(h);
                }
    });
}

DetailField synthesizeOnBox(
    const SynthExemplars& exemplars, const SynthInput& in, const SynthSettings& s, Progress* progress)
{
    if (!in.coarse || in.coarse->empty()) throw ValueError("synth: no coarse motion L");
    for (const Vec3f& v : in.coarse->values())
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
            throw ValueError("synth: the coarse motion holds NaN or Inf");
    const SynthExemplars::Impl& ex = exemplars.impl();
    const FineDomain dom = fineDomain(*in.coarse, in.factor);
    checkSynthInput(ex, in, dom);
    const bool continuing = in.previous && !in.previous->world.empty();

    DetailField out;
    withThreads(s.threads, [&] {
        const FrameGuide frames(in, s.orientation, dom.twoD);
        Engine eng{ex, s, frames, ex.kcoherence, progress, {}};
        const int itersPerLevel = (!ex.volume ? std::max(0, s.largeIterations) : 0) + std::max(0, s.smallIterations);
        IterationTicker tick{progress, continuing ? std::max(1, s.continueIterations) : itersPerLevel * ex.levels + 1};
        Level L;
        if (!continuing) {
            if (progress) progress->begin("synthesis");
            L = synthesizePyramid(eng, in, dom, tick, out.levels);
        } else {
            if (progress) progress->begin("advect + refine");
            out.fromPrevious = true;
            out.levels.push_back(continueFromPrevious(eng, L, in, dom, tick));
        }
        detailToWorld(L, dom, frames, out);
    });
    return out;
}

} // namespace

} // namespace turb
