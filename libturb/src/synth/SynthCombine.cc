// Motion-field synthesis, the parts around the engine: up(L), F = up(L) + omega H, density sources and
// look-back integration, the texture-match statistic, analytic coarse flows.
#include <turb/Synth.h>

#include <turb/Distance.h>
#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Projection.h>
#include <turb/Resample.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace turb {

namespace {

template<typename T>
Field<T> upsampleImpl(const Field<T>& coarse, int factor)
{
    const FineDomain d = fineDomain(coarse.bbox(), coarse.lattice(), factor);
    if (!d.twoD) return upsample(coarse, factor);
    // 2D: the same cell-centred trilinear rule in x and y, one layer in z.
    Field<T> fine(d.box, d.lattice);
    const CoordBBox b = d.box;
    const int k0 = coarse.bbox().min().z();
    parallelFor(size_t(b.dim().x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x)
            for (int y = b.min().y(); y <= b.max().y(); ++y) {
                const int i = b.min().x() + int(x);
                const Vec3d c((i + 0.5) / factor - 0.5, (y + 0.5) / factor - 0.5, double(k0));
                fine(i, y, k0) = sampleTrilinear(coarse, c);
            }
    });
    return fine;
}

} // namespace

VectorField upsampleCoarse(const VectorField& coarse, int factor)
{
    return upsampleImpl(coarse, factor); // fineDomain rejects factor < 1
}

ScalarField upsampleCoarse(const ScalarField& coarse, int factor)
{
    return upsampleImpl(coarse, factor); // fineDomain rejects factor < 1
}

ScalarField smokeDetailWeight(const ScalarField& density, float threshold, double margin, double falloff)
{
    if (!(threshold >= 0.0f)) throw ValueError("combine: the smoke threshold must be >= 0");
    if (!(margin >= 0.0)) throw ValueError("combine: the smoke margin must be >= 0 cells");
    if (!(falloff > 0.0)) throw ValueError("combine: the smoke falloff must be > 0 cells");
    ScalarField w = distanceToSmoke(density, threshold);
    for (float& v : w.values()) {
        const double t = (double(v) - margin) / falloff;
        v = t <= 0.0 ? 1.0f : t >= 1.0 ? 0.0f : float(0.5 * (1.0 + std::cos(M_PI * t)));
    }
    return w;
}

namespace {

// L's fastest speed; the voxels faster than 5% of it are the moving ones that omega's normalisations average over.
double fastestSpeed(const VectorField& coarse)
{
    double maxSpeed = 0.0;
    for (const Vec3f& v : coarse.values()) maxSpeed = std::max(maxSpeed, double(v.length()));
    return maxSpeed;
}

bool isMoving(const Vec3f& v, double maxSpeed) { return v.length() > 0.05 * maxSpeed; }

// The shape of omega on the coarse lattice, normalised to mean 1 over moving voxels, and faded outside the smoke.
ScalarField omegaShape(const VectorField& coarse, const CombineSettings& s, double maxSpeed)
{
    ScalarField shape(coarse.bbox(), coarse.lattice(), 1.0f);
    if (s.weighting != CombineSettings::Weighting::Constant) {
        if (s.weighting == CombineSettings::Weighting::KineticEnergy) {
            for (size_t n = 0; n < coarse.size(); ++n) shape.data()[n] = 0.5f * coarse.data()[n].lengthSqr();
        } else {
            const VectorField w = curl(coarse);
            for (size_t n = 0; n < coarse.size(); ++n) shape.data()[n] = w.data()[n].length();
        }
        double sum = 0.0;
        size_t cnt = 0;
        for (size_t n = 0; n < coarse.size(); ++n)
            if (isMoving(coarse.data()[n], maxSpeed)) {
                sum += shape.data()[n];
                ++cnt;
            }
        const double mean = cnt ? sum / double(cnt) : 0.0;
        const float inv = mean > 0.0 ? float(1.0 / mean) : 0.0f;
        for (float& v : shape.values()) v *= inv;
    }
    if (s.smoke) {
        if (s.smoke->bbox() != coarse.bbox())
            throw ValueError("combine: the smoke density does not cover L's box (" +
                             std::to_string(s.smoke->bbox().dim().x()) + " cells along x against " +
                             std::to_string(coarse.bbox().dim().x()) + ")");
        const ScalarField w = smokeDetailWeight(*s.smoke, s.smokeThreshold, s.smokeMargin, s.smokeFalloff);
        for (size_t n = 0; n < shape.size(); ++n) shape.data()[n] *= w.data()[n];
    }
    return shape;
}

// omega's overall factor: as given, or (relative) times L's rms speed over its moving voxels.
double omegaScale(const VectorField& coarse, const CombineSettings& s, double maxSpeed)
{
    double scale = s.omega;
    if (s.relative) {
        double s2 = 0.0;
        size_t cnt = 0;
        for (size_t n = 0; n < coarse.size(); ++n)
            if (isMoving(coarse.data()[n], maxSpeed)) {
                s2 += coarse.data()[n].lengthSqr();
                ++cnt;
            }
        scale *= cnt ? std::sqrt(s2 / double(cnt)) : 0.0;
    }
    return scale;
}

// The detail's coarse-cell means, spread trilinearly as up(L) is, are motion at L's scale: they would change the
// coarse flow (lf_err). Trilinear spreading does not keep a cell's mean exactly: each pass leaves about half of
// the means in the worst case (a wavelength of two coarse cells), so five passes leave a few percent
// (docs/synth.md: three left lf_err 0.047-0.072 on the Blender plume2 cache).
void removeCoarsePart(VectorField& D, int factor, int passes)
{
    for (int pass = 0; pass < passes; ++pass) {
        const VectorField coarsePart = upsampleImpl(boxDownsample(D, factor), factor);
        if (coarsePart.bbox() != D.bbox()) throw ValueError("combine: the detail's coarse part does not cover its box");
        parallelFor(D.size(), 4096, [&](size_t b, size_t e) {
            for (size_t n = b; n < e; ++n) D.data()[n] -= coarsePart.data()[n];
        });
    }
}

} // namespace

VectorField combineMotion(const VectorField& coarse, const VectorField& detail, const CombineSettings& s,
    CentralDivergenceResult* diagnostics)
{
    if (coarse.empty() || detail.empty()) throw ValueError("combine: empty coarse or detail field");
    if (!(s.omega >= 0.0)) throw ValueError("combine: omega must be >= 0");
    const int factor = integerRatio(coarse.lattice().voxelSize, detail.lattice().voxelSize);
    VectorField F = upsampleCoarse(coarse, factor);
    if (F.bbox() != detail.bbox())
        throw ValueError("combine: the detail field does not cover the refined coarse box (was it made from this L?)");

    const double maxSpeed = fastestSpeed(coarse);
    const ScalarField shape = omegaShape(coarse, s, maxSpeed);
    const double scale = omegaScale(coarse, s, maxSpeed);
    const ScalarField omega = upsampleCoarse(shape, factor);
    VectorField D(F.bbox(), F.lattice());
    parallelFor(F.size(), 4096, [&](size_t b, size_t e) {
        for (size_t n = b; n < e; ++n) D.data()[n] = detail.data()[n] * float(scale * omega.data()[n]);
    });
    if (s.removeCoarsePart) removeCoarsePart(D, factor, 5);
    if (s.solenoidalDetail) {
        const CentralDivergenceResult r = removeCentralDivergence(D, s.solenoidalTolerance, s.solenoidalIterations);
        if (diagnostics) *diagnostics = r;
        // The gradient part taken out had coarse means of its own: one more pass takes most of what it put back
        // (lf_err 0.046 -> 0.029 on Blender plume2, frames 1-10) and returns a little divergence (div_rel 0.237 ->
        // 0.241, against up(L)'s 0.336; five passes would give back most of it: 0.102 against 0.082 on the plume).
        if (s.removeCoarsePart) removeCoarsePart(D, factor, 1);
    }
    parallelFor(F.size(), 4096, [&](size_t b, size_t e) {
        for (size_t n = b; n < e; ++n) F.data()[n] += D.data()[n];
    });
    return F;
}

LookbackDensity::LookbackDensity(const LookbackSettings& s) : mSettings(s)
{
    if (s.frames < 0) throw ValueError("look-back: frames must be >= 0");
}

ScalarField LookbackDensity::step(
    const VectorField& motion, const ScalarField& sources, const ScalarField& coarseOnly, double dt, Progress* progress)
{
    if (motion.empty() || sources.empty()) throw ValueError("look-back: empty motion or sources");
    if (motion.bbox() != sources.bbox()) throw ValueError("look-back: motion and sources cover different boxes");
    const auto addSources = [](ScalarField& d, const ScalarField& src) {
        for (size_t n = 0; n < d.size(); ++n) d.data()[n] += src.data()[n];
    };
    const int m = mSettings.frames;
    if (m == 0) {
        // Pseudocode 3, with each frame's sources added after its advection (they are estimated as
        // what advection alone leaves unexplained).
        mNaive = mNaive.empty() ? ScalarField(sources.bbox(), sources.lattice())
                                : advect(mNaive, motion, dt, mSettings.advect);
        addSources(mNaive, sources);
        return mNaive;
    }
    if (coarseOnly.empty() || coarseOnly.bbox() != motion.bbox())
        throw ValueError("look-back: the coarse-only density must cover the motion's box");
    mMotion.push_back(motion);
    mSources.push_back(sources);
    mDt.push_back(dt);
    mCoarse.push_back(coarseOnly);
    while (int(mMotion.size()) > m) {
        mMotion.pop_front();
        mSources.pop_front();
        mDt.pop_front();
    }
    while (int(mCoarse.size()) > m + 1) mCoarse.pop_front();
    // D_i from O_{i-m} (empty before the sequence has m frames), through F_{i-m+1..i}.
    const bool full = int(mCoarse.size()) == m + 1;
    ScalarField d = full ? mCoarse.front() : ScalarField(sources.bbox(), sources.lattice());
    for (size_t j = 0; j < mMotion.size(); ++j) {
        checkCancelled(progress);
        if (progress) progress->update(double(j) / double(mMotion.size()));
        if (j > 0 || full) d = advect(d, mMotion[j], mDt[j], mSettings.advect); // each step over its own time
        addSources(d, mSources[j]);
    }
    return d;
}

namespace {

// Every neighbourhood of the exemplar (each valid centre, all of them where it wraps), one row of
// (2r+1)^2 * 2 values each: the texture-match statistic compares against them all, brute force (exact and small).
struct ExemplarNeighbourhoods
{
    std::vector<float> rows;
    size_t count = 0;
    int dim = 0;
};

ExemplarNeighbourhoods exemplarNeighbourhoods(const Exemplar& ex, int r)
{
    ExemplarNeighbourhoods out;
    out.dim = (2 * r + 1) * (2 * r + 1) * 2;
    const auto exVal = [&](int x, int y, int c) {
        if (ex.periodic) {
            x = ((x % ex.nx) + ex.nx) % ex.nx;
            y = ((y % ex.ny) + ex.ny) % ex.ny;
        }
        return ex.at(x, y)[c];
    };
    const int lo = ex.periodic ? 0 : r;
    for (int x = lo; x < (ex.periodic ? ex.nx : ex.nx - r); ++x)
        for (int y = lo; y < (ex.periodic ? ex.ny : ex.ny - r); ++y) {
            for (int i = -r; i <= r; ++i)
                for (int j = -r; j <= r; ++j)
                    for (int c = 0; c < 2; ++c) out.rows.push_back(exVal(x + i, y + j, c));
            ++out.count;
        }
    if (out.count == 0) throw ValueError("texture match: exemplar smaller than the neighbourhood");
    return out;
}

// The centres of the compared output neighbourhoods: every `stride`-th voxel of the slices perpendicular to `axis`
// whose whole neighbourhood lies inside box `b` (u, v: the slices' in-plane axes).
std::vector<Coord> sliceCentres(const CoordBBox& b, const TextureMatchSettings& s, int u, int v)
{
    const int r = s.radius;
    const Coord d = b.dim();
    if (d[u] < 2 * r + 1 || d[v] < 2 * r + 1)
        throw ValueError("texture match: field slices smaller than the neighbourhood");
    std::vector<Coord> centres;
    const int stride = std::max(1, s.stride);
    for (int w = b.min()[s.axis]; w <= b.max()[s.axis]; w += (d[s.axis] > 1 ? stride : 1))
        for (int a = b.min()[u] + r; a <= b.max()[u] - r; a += stride)
            for (int c = b.min()[v] + r; c <= b.max()[v] - r; c += stride) {
                Coord p;
                p[s.axis] = w;
                p[u] = a;
                p[v] = c;
                centres.push_back(p);
            }
    return centres;
}

// The field's vectors at random voxels (seeded): the baseline a texture-less field of the same values gives.
std::vector<Vec3f> shuffledValues(const VectorField& local, std::uint64_t seed)
{
    std::vector<Vec3f> shuffled(local.values());
    std::mt19937_64 rng(seed);
    for (size_t i = shuffled.size(); i > 1; --i) {
        std::uniform_int_distribution<size_t> pick(0, i - 1);
        std::swap(shuffled[i - 1], shuffled[pick(rng)]);
    }
    return shuffled;
}

// The mean over `centres` of each output neighbourhood's squared distance per channel to its nearest exemplar
// neighbourhood, with the field's vectors taken from `vals` (the field's own or shuffled).
double meanNearestDistance(const ExemplarNeighbourhoods& exn, const VectorField& local, const std::vector<Vec3f>& vals,
    const std::vector<Coord>& centres, int r, int u, int v)
{
    const int dim = exn.dim;
    const auto nearest = [&](const Coord& p) {
        std::vector<float> q(static_cast<size_t>(dim));
        size_t k = 0;
        for (int i = -r; i <= r; ++i)
            for (int j = -r; j <= r; ++j) {
                Coord c = p;
                c[u] += i;
                c[v] += j;
                const Vec3f val = vals[local.offset(c.x(), c.y(), c.z())];
                q[k++] = val[u];
                q[k++] = val[v];
            }
        double best = std::numeric_limits<double>::max();
        for (size_t e = 0; e < exn.count; ++e) {
            const float* row = &exn.rows[e * size_t(dim)];
            double s2 = 0.0;
            for (int t = 0; t < dim && s2 < best; ++t) {
                const double z = double(q[size_t(t)]) - row[t];
                s2 += z * z;
            }
            best = std::min(best, s2);
        }
        return best / dim;
    };
    const double sum = parallelSum(centres.size(), 16, [&](size_t b0, size_t e0) {
        double acc = 0.0;
        for (size_t i = b0; i < e0; ++i) acc += nearest(centres[i]);
        return acc;
    });
    return centres.empty() ? 0.0 : sum / double(centres.size());
}

} // namespace

TextureMatch textureMatch(const Exemplar& ex, const VectorField& local, const TextureMatchSettings& s)
{
    if (!ex.planar()) throw ValueError("texture match: the exemplar must be planar");
    if (s.axis < 0 || s.axis > 2) throw ValueError("texture match: axis must be 0, 1 or 2");
    const int r = s.radius;
    const int u = s.axis == 0 ? 1 : 0, v = s.axis == 2 ? 1 : 2;
    TextureMatch out;
    const ExemplarNeighbourhoods exn = exemplarNeighbourhoods(ex, r);
    double e2[2] = {0, 0};
    for (size_t n = 0; n < ex.count(); ++n)
        for (int c = 0; c < 2; ++c) e2[c] += double(ex.values[n * 2 + size_t(c)]) * ex.values[n * 2 + size_t(c)];
    for (int c = 0; c < 2; ++c) out.exemplarRms[c] = std::sqrt(e2[c] / double(ex.count()));

    // Output neighbourhoods: in-plane components (u, v) of slices perpendicular to `axis`.
    const std::vector<Coord> centres = sliceCentres(local.bbox(), s, u, v);
    const std::vector<Vec3f> shuffled = shuffledValues(local, s.seed);
    out.samples = int(centres.size());
    out.distance = meanNearestDistance(exn, local, local.values(), centres, r, u, v);
    out.shuffled = meanNearestDistance(exn, local, shuffled, centres, r, u, v);
    double f2[2] = {0, 0};
    for (const Vec3f& val : local.values()) {
        f2[0] += double(val[u]) * val[u];
        f2[1] += double(val[v]) * val[v];
    }
    for (int c = 0; c < 2; ++c) out.fieldRms[c] = std::sqrt(f2[c] / double(std::max<size_t>(1, local.size())));
    return out;
}

VectorField analyticFlow(const AnalyticFlowSettings& s)
{
    if (s.res.x() < 1 || s.res.y() < 1 || s.res.z() < 1) throw ValueError("analytic flow: empty resolution");
    if (!(s.voxelSize > 0.0)) throw ValueError("analytic flow: voxel size must be > 0");
    Lattice lat;
    lat.voxelSize = s.voxelSize;
    VectorField f(CoordBBox(Coord(0), s.res - Coord(1)), lat);
    const double cx = 0.5 * (s.res.x() - 1), cy = 0.5 * (s.res.y() - 1);
    const double half = 0.5 * std::min(s.res.x(), s.res.y());
    const double a = s.angleDegrees * 3.14159265358979323846 / 180.0;
    for (int i = 0; i < s.res.x(); ++i)
        for (int j = 0; j < s.res.y(); ++j)
            for (int k = 0; k < s.res.z(); ++k) {
                Vec3f v(0.0f);
                switch (s.kind) {
                case AnalyticFlowSettings::Kind::Uniform:
                    v = Vec3f(float(s.speed * std::cos(a)), float(s.speed * std::sin(a)), 0.0f);
                    break;
                case AnalyticFlowSettings::Kind::Vortex:
                    v = Vec3f(float(-(j - cy) / half * s.speed), float((i - cx) / half * s.speed), 0.0f);
                    break;
                case AnalyticFlowSettings::Kind::Shear:
                    v = Vec3f(float(s.speed * (2.0 * j / std::max(1, s.res.y() - 1) - 1.0)), 0.0f, 0.0f);
                    break;
                }
                f(i, j, k) = v;
            }
    return f;
}

} // namespace turb
