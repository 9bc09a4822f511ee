// Motion-field texture synthesis (Ma et al. 2009): exemplars, 2D and 2D-to-3D synthesis, orientation, walls,
// determinism, temporal continuation, combination and look-back density. Small sizes: the whole suite
// runs in seconds.
#include "TestUtil.h"

#include <turb/Advect.h>
#include <turb/Distance.h>
#include <turb/Error.h>
#include <turb/Exemplar.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>
#include <turb/Synth.h>
#include <turb/SynthSequence.h>

#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>

using namespace turb;

namespace {

constexpr double kPi = 3.14159265358979323846;

Exemplar procedural(ProceduralPattern p, int size, int period)
{
    ProceduralExemplarSettings s;
    s.pattern = p;
    s.size = size;
    s.period = period;
    return proceduralExemplar(s);
}

VectorField uniformFlow(int n, int nz, double angleDeg, double speed = 1.0)
{
    AnalyticFlowSettings a;
    a.res = Coord(n, n, nz);
    a.angleDegrees = angleDeg;
    a.speed = speed;
    return analyticFlow(a);
}

DetailField synth2D(const Exemplar& ex, const VectorField& L, SynthSettings s, int factor = 4)
{
    SynthExemplars prepared({SynthView{ex, 2, 1.0f}}, s, false);
    SynthInput in;
    in.coarse = &L;
    in.factor = factor;
    return synthesizeDetail(prepared, in, s);
}

/// Discrete divergence of a planar exemplar with periodic central differences, relative to the rms
/// of its velocity gradient.
double relativeDivergence(const Exemplar& e)
{
    double d2 = 0.0, g2 = 0.0;
    for (int x = 0; x < e.nx; ++x)
        for (int y = 0; y < e.ny; ++y) {
            const float* xp = e.at((x + 1) % e.nx, y);
            const float* xm = e.at((x + e.nx - 1) % e.nx, y);
            const float* yp = e.at(x, (y + 1) % e.ny);
            const float* ym = e.at(x, (y + e.ny - 1) % e.ny);
            const double dudx = 0.5 * (xp[0] - xm[0]), dvdy = 0.5 * (yp[1] - ym[1]);
            const double dudy = 0.5 * (yp[0] - ym[0]), dvdx = 0.5 * (xp[1] - xm[1]);
            d2 += (dudx + dvdy) * (dudx + dvdy);
            g2 += dudx * dudx + dvdy * dvdy + dudy * dudy + dvdx * dvdx;
        }
    return std::sqrt(d2 / std::max(g2, 1e-30));
}

/// Principal direction (degrees in [0, 180)) and anisotropy (eigenvalue ratio) of sum v v^T.
struct Axis
{
    double degrees = 0.0, anisotropy = 0.0;
};
Axis principal(double xx, double xy, double yy)
{
    Axis a;
    double phi = 0.5 * std::atan2(2 * xy, xx - yy) * 180.0 / kPi;
    if (phi < 0) phi += 180.0;
    a.degrees = phi;
    const double tr = xx + yy, det = xx * yy - xy * xy;
    const double disc = std::sqrt(std::max(0.0, tr * tr / 4 - det));
    const double l1 = tr / 2 + disc, l2 = tr / 2 - disc;
    a.anisotropy = l2 > 0 ? l1 / l2 : 1e9;
    return a;
}
double angleDiff(double a, double b)
{
    double d = std::fmod(std::abs(a - b), 180.0);
    return std::min(d, 180.0 - d);
}

/// Orientation of the vectors and of the pattern (gradient structure tensor) of a 2D world field.
void orientation(const VectorField& f, Axis& vectors, Axis& pattern)
{
    const CoordBBox b = f.bbox();
    const int k = b.min().z();
    double vxx = 0, vxy = 0, vyy = 0, gxx = 0, gxy = 0, gyy = 0;
    for (int i = b.min().x() + 1; i < b.max().x(); ++i)
        for (int j = b.min().y() + 1; j < b.max().y(); ++j) {
            const Vec3f v = f(i, j, k);
            vxx += v[0] * v[0];
            vxy += v[0] * v[1];
            vyy += v[1] * v[1];
            for (int c = 0; c < 2; ++c) {
                const double gx = 0.5 * (f(i + 1, j, k)[c] - f(i - 1, j, k)[c]);
                const double gy = 0.5 * (f(i, j + 1, k)[c] - f(i, j - 1, k)[c]);
                gxx += gx * gx;
                gxy += gx * gy;
                gyy += gy * gy;
            }
        }
    vectors = principal(vxx, vxy, vyy);
    pattern = principal(gxx, gxy, gyy);
}

double rms(const VectorField& f)
{
    double s = 0.0;
    for (const Vec3f& v : f.values()) s += v.lengthSqr();
    return std::sqrt(s / double(std::max<size_t>(1, f.size())));
}

bool bitEqual(const VectorField& a, const VectorField& b)
{
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3f)) == 0;
}

/// A periodic, divergence-free random field of n^3 voxels (a few Fourier modes): its axis slices are
/// mutually consistent views of one 3D field, so three-view synthesis has a solution to find.
VectorField randomPeriodicField(int n, unsigned seed)
{
    VectorField f(CoordBBox(Coord(0), Coord(n - 1)), Lattice{});
    std::mt19937 rng(seed);
    std::normal_distribution<double> g;
    std::uniform_real_distribution<double> phase(0, 2 * kPi);
    struct Mode
    {
        Vec3d k, a;
        double ph;
    };
    std::vector<Mode> modes;
    while (modes.size() < 40) {
        const Vec3d k(std::round(2 * g(rng)), std::round(2 * g(rng)), std::round(2 * g(rng)));
        if (k.length() < 1.5 || k.length() > 3.5) continue;
        Vec3d a(g(rng), g(rng), g(rng));
        a -= k * (a.dot(k) / k.lengthSqr());
        modes.push_back({k, a, phase(rng)});
    }
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int l = 0; l < n; ++l) {
                Vec3d v(0.0);
                for (const auto& m : modes)
                    v += m.a * std::sin(2 * kPi * (m.k[0] * i + m.k[1] * j + m.k[2] * l) / n + m.ph);
                f(i, j, l) = Vec3f(float(v[0]), float(v[1]), float(v[2]));
            }
    return f;
}

} // namespace

// ---------------------------------------------------------------------------------------------
// Exemplars

TEST(Exemplar, ProceduralPatternsAreUnitRmsDivergenceFreeAndTile)
{
    for (auto p : {ProceduralPattern::Circles, ProceduralPattern::Swirls, ProceduralPattern::Squares,
             ProceduralPattern::Hearts, ProceduralPattern::Stripes, ProceduralPattern::Sinusoids}) {
        SCOPED_TRACE(proceduralPatternName(p));
        const Exemplar e = procedural(p, 64, 16);
        EXPECT_EQ(e.nx, 64);
        EXPECT_TRUE(e.periodic);
        EXPECT_NEAR(exemplarRms(e), 1.0, 1e-5);
        // Derived from a stream function: the discrete divergence is a small fraction of the gradient.
        EXPECT_LT(relativeDivergence(e), 0.1);
        // Tiling: the jump across the wrap-around is no larger than jumps inside.
        double wrap = 0.0, inside = 0.0;
        for (int y = 0; y < e.ny; ++y)
            for (int c = 0; c < 2; ++c) {
                wrap = std::max(wrap, double(std::abs(e.at(0, y)[c] - e.at(e.nx - 1, y)[c])));
                for (int x = 0; x + 1 < e.nx; ++x)
                    inside = std::max(inside, double(std::abs(e.at(x + 1, y)[c] - e.at(x, y)[c])));
            }
        EXPECT_LE(wrap, inside + 1e-6);
    }
    EXPECT_THROW(procedural(ProceduralPattern::Hearts, 60, 16), ValueError); // not a multiple of the period
    EXPECT_THROW(parseProceduralPattern("spirals"), ValueError);
}

TEST(Exemplar, GrayBitmapCurlCirclesTheBlob)
{
    // A Gaussian blob: the curl of its intensity turns around the centre, and the discrete divergence
    // of the curl vanishes (the two central differences commute).
    const int n = 32;
    Image img(n, n);
    for (int x = 0; x < n; ++x)
        for (int r = 0; r < n; ++r) {
            const double y = n - 1 - r; // exemplar y is up
            const double d2 = (x - 15.5) * (x - 15.5) + (y - 15.5) * (y - 15.5);
            img.at(x, r) = Rgb(float(std::exp(-d2 / 40.0)));
        }
    const Exemplar e = exemplarFromGrayImage(img, 10.0);
    double radial = 0.0, tangential = 0.0, maxDiv = 0.0;
    for (int x = 2; x < n - 2; ++x)
        for (int y = 2; y < n - 2; ++y) {
            const float* v = e.at(x, y);
            const double rx = x - 15.5, ry = y - 15.5;
            radial += std::abs(v[0] * rx + v[1] * ry);
            tangential += std::abs(-v[0] * ry + v[1] * rx);
            const double div =
                0.5 * (e.at(x + 1, y)[0] - e.at(x - 1, y)[0]) + 0.5 * (e.at(x, y + 1)[1] - e.at(x, y - 1)[1]);
            maxDiv = std::max(maxDiv, std::abs(div));
        }
    EXPECT_LT(radial, 0.02 * tangential); // central differences of a sampled Gaussian are radial to ~0.5%
    EXPECT_LT(maxDiv, 1e-5);
    // Intensity falls outward, so v = (dI/dy, -dI/dx) turns counter-clockwise: up at the right of the centre.
    EXPECT_GT(e.at(20, 16)[1], 0.0f);
}

TEST(Exemplar, VectorImageChannelsAndScale)
{
    Image img(3, 2, Rgb(0.5f));
    img.at(0, 0) = Rgb(1.0f, 0.5f, 0.0f); // top-left
    img.at(2, 1) = Rgb(0.5f, 0.0f, 0.0f); // bottom-right
    const Exemplar e = exemplarFromVectorImage(img, 3.0);
    EXPECT_NEAR(e.at(0, 1)[0], 3.0f, 1e-6); // top row is y = 1
    EXPECT_NEAR(e.at(0, 1)[1], 0.0f, 1e-6);
    EXPECT_NEAR(e.at(2, 0)[1], -3.0f, 1e-6);
    EXPECT_NEAR(e.at(1, 0)[0], 0.0f, 1e-6);
}

TEST(Exemplar, SlicesFollowTheViewConvention)
{
    VectorField f(CoordBBox(Coord(0), Coord(3, 4, 5)), Lattice{});
    for (size_t n = 0; n < f.size(); ++n) {
        const Coord c = f.coordOf(n);
        f.data()[n] = Vec3f(float(c.x()), float(100 + c.y()), float(200 + c.z()));
    }
    const Exemplar ex = exemplarFromSlice(f, 0, 2); // plane (y, z)
    EXPECT_EQ(ex.nx, 5);
    EXPECT_EQ(ex.ny, 6);
    EXPECT_EQ(ex.at(3, 4)[0], 103.0f);
    EXPECT_EQ(ex.at(3, 4)[1], 204.0f);
    const Exemplar ey = exemplarFromSlice(f, 1, 1); // plane (x, z)
    EXPECT_EQ(ey.at(2, 5)[0], 2.0f);
    EXPECT_EQ(ey.at(2, 5)[1], 205.0f);
    EXPECT_THROW(exemplarFromSlice(f, 2, 9), ValueError);
    const Exemplar big = rescaledExemplar(procedural(ProceduralPattern::Swirls, 32, 16), 2.0);
    EXPECT_EQ(big.nx, 64);
}

// ---------------------------------------------------------------------------------------------
// Synthesis

TEST(Synth, TwoDReproducesExemplarNeighbourhoods)
{
    const Exemplar ex = procedural(ProceduralPattern::Circles, 32, 16);
    const VectorField L = uniformFlow(16, 1, 0.0);
    SynthSettings s;
    const DetailField H = synth2D(ex, L, s);
    ASSERT_EQ(H.local.bbox().dim(), Coord(64, 64, 1));
    TextureMatchSettings ts;
    const TextureMatch m = textureMatch(ex, H.local, ts);
    // The output's nearest-neighbour distance to the exemplar is small next to a shuffled field's.
    EXPECT_LT(m.ratio(), 0.3) << m.distance << " vs shuffled " << m.shuffled;
    for (int c = 0; c < 2; ++c) EXPECT_NEAR(m.fieldRms[c], m.exemplarRms[c], 0.2 * m.exemplarRms[c]);
    // Energy falls over the iterations of the finest level.
    const auto& e = H.levels.back().energy;
    ASSERT_GE(e.size(), 2u);
    EXPECT_LT(e.back(), e.front());

    // k-coherence (section 3.7) also reproduces the neighbourhoods.
    s.search = SearchMethod::KCoherence;
    const DetailField K = synth2D(ex, L, s);
    EXPECT_LT(textureMatch(ex, K.local, ts).ratio(), 0.4);
}

TEST(Synth, RotatingTheCoarseFlowRotatesPatternAndVectors)
{
    // Stripes: vectors along the exemplar's x, pattern varying along its y. With x following L, the
    // vectors must lie along L and the pattern vary across it, whatever L's direction.
    const Exemplar ex = procedural(ProceduralPattern::Stripes, 32, 16);
    for (double angle : {0.0, 60.0, 135.0}) {
        SCOPED_TRACE(angle);
        const DetailField H = synth2D(ex, uniformFlow(16, 1, angle), SynthSettings{});
        Axis vec, pat;
        orientation(H.world, vec, pat);
        EXPECT_LT(angleDiff(vec.degrees, angle), 5.0);
        EXPECT_LT(angleDiff(pat.degrees, angle + 90.0), 5.0);
        EXPECT_GT(vec.anisotropy, 10.0);
        EXPECT_GT(pat.anisotropy, 3.0);
    }
    // Without orientation the output stays in the exemplar's axes.
    SynthSettings fixed;
    fixed.orientation.follow = false;
    const DetailField H = synth2D(ex, uniformFlow(16, 1, 60.0), fixed);
    Axis vec, pat;
    orientation(H.world, vec, pat);
    EXPECT_LT(angleDiff(vec.degrees, 0.0), 5.0);
}

TEST(Synth, ThreeViewsMatchEachViewsStatistics)
{
    // Three axis views cut from one periodic 3D field: each view of the 3D output (its slices and
    // their two in-plane components) must resemble its exemplar.
    const VectorField src = randomPeriodicField(32, 3);
    std::vector<SynthView> views;
    for (int a = 0; a < 3; ++a) {
        Exemplar e = exemplarFromSlice(src, a, 0);
        e.periodic = true;
        normalizeExemplar(e);
        views.push_back({e, a, 1.0f});
    }
    SynthSettings s;
    s.orientation.follow = false; // the local frame is the world frame: views are the axis views
    const VectorField L = uniformFlow(8, 8, 0.0);
    SynthInput in;
    in.coarse = &L;
    in.factor = 4;
    TextureMatchSettings ts;
    ts.stride = 3;
    double equalRatio[3];
    {
        SynthExemplars prepared(views, s, true);
        const DetailField H = synthesizeDetail(prepared, in, s);
        for (int a = 0; a < 3; ++a) {
            SCOPED_TRACE(a);
            ts.axis = a;
            const TextureMatch m = textureMatch(views[size_t(a)].exemplar, H.local, ts);
            equalRatio[a] = m.ratio();
            EXPECT_LT(m.ratio(), 0.5) << m.distance << " vs shuffled " << m.shuffled;
            for (int c = 0; c < 2; ++c) EXPECT_NEAR(m.fieldRms[c], m.exemplarRms[c], 0.25 * m.exemplarRms[c]);
        }
    }
    // Per-view weights: a dominant view is reproduced much more closely.
    views[2].weight = 10.0f;
    SynthExemplars prepared(views, s, true);
    const DetailField H = synthesizeDetail(prepared, in, s);
    ts.axis = 2;
    EXPECT_LT(textureMatch(views[2].exemplar, H.local, ts).ratio(), 0.5 * equalRatio[2]);
}

TEST(Synth, VolumetricExemplarGives3DOutputWithItsSpread)
{
    // A 3D exemplar (9^3 footprint, 5^3 taps): a periodic Taylor-Green vortex field. The output keeps
    // the exemplar's spread and its slices resemble the exemplar's slices.
    const int n = 16;
    const double k = 2 * kPi / 8.0;
    VectorField src(CoordBBox(Coord(0), Coord(n - 1)), Lattice{});
    for (size_t q = 0; q < src.size(); ++q) {
        const Coord c = src.coordOf(q);
        const double x = k * (c.x() + 0.5), y = k * (c.y() + 0.5), z = k * (c.z() + 0.5);
        src.data()[q] = Vec3f(
            float(std::sin(x) * std::cos(y) * std::cos(z)), float(-std::cos(x) * std::sin(y) * std::cos(z)), 0.0f);
    }
    Exemplar e = exemplarFromVolume(src);
    e.periodic = true;
    normalizeExemplar(e);
    SynthSettings s;
    s.orientation.follow = false;
    const VectorField L = uniformFlow(6, 6, 0.0);
    SynthInput in;
    in.coarse = &L;
    in.factor = 4;
    const DetailField H = synthesizeDetail(SynthExemplars({SynthView{e, -1, 1.0f}}, s, true), in, s);
    ASSERT_EQ(H.local.bbox().dim(), Coord(24, 24, 24));
    Exemplar slice = exemplarFromSlice(src, 2, 1);
    slice.periodic = true;
    for (float& v : slice.values) v *= float(1.0 / exemplarRms(exemplarFromVolume(src))); // e's normalisation
    TextureMatchSettings ts;
    ts.stride = 3;
    const TextureMatch m = textureMatch(slice, H.local, ts);
    EXPECT_LT(m.ratio(), 0.4) << m.distance << " vs shuffled " << m.shuffled;
    double ex2[3] = {0, 0, 0}, out2[3] = {0, 0, 0};
    for (size_t q = 0; q < e.count(); ++q)
        for (int c = 0; c < 3; ++c) ex2[c] += double(e.values[q * 3 + size_t(c)]) * e.values[q * 3 + size_t(c)];
    for (const Vec3f& v : H.local.values())
        for (int c = 0; c < 3; ++c) out2[c] += double(v[c]) * v[c];
    for (int c = 0; c < 2; ++c) {
        const double want = std::sqrt(ex2[c] / double(e.count()));
        EXPECT_NEAR(std::sqrt(out2[c] / double(H.local.size())), want, 0.25 * want);
    }
}

TEST(Synth, NormalComponentVanishesAtWallsAndObstacles)
{
    const Exemplar ex = procedural(ProceduralPattern::Circles, 32, 16);
    const VectorField L = uniformFlow(16, 1, 45.0);
    SynthSettings s;
    s.boundary.walls = (1u << 0) | (1u << 3); // x-min and y-max
    const DetailField H = synth2D(ex, L, s);
    const CoordBBox b = H.world.bbox();
    const int k = b.min().z();
    double xn = 0.0, yn = 0.0, tangential = 0.0;
    for (int j = b.min().y(); j <= b.max().y(); ++j) {
        xn += H.world(b.min().x(), j, k)[0] * H.world(b.min().x(), j, k)[0];
        tangential += H.world(b.min().x(), j, k)[1] * H.world(b.min().x(), j, k)[1];
    }
    for (int i = b.min().x(); i <= b.max().x(); ++i)
        yn += H.world(i, b.max().y(), k)[1] * H.world(i, b.max().y(), k)[1];
    const double n = b.dim().y();
    const double overall = rms(H.world);
    EXPECT_LT(std::sqrt(xn / n), 0.05 * overall);
    EXPECT_LT(std::sqrt(yn / n), 0.05 * overall);
    EXPECT_GT(std::sqrt(tangential / n), 0.2 * overall); // only the normal component is constrained

    // Without walls the same column carries normal motion (so the check above can fail).
    const DetailField free = synth2D(ex, L, SynthSettings{});
    double xf = 0.0;
    for (int j = b.min().y(); j <= b.max().y(); ++j)
        xf += free.world(b.min().x(), j, k)[0] * free.world(b.min().x(), j, k)[0];
    EXPECT_GT(std::sqrt(xf / n), 0.3 * rms(free.world));

    // An obstacle: a disk given by its signed distance, in world units.
    ScalarField sdf(L.bbox(), L.lattice());
    for (size_t q = 0; q < sdf.size(); ++q) {
        const Coord c = sdf.coordOf(q);
        sdf.data()[q] = float(std::hypot(c.x() - 7.5, c.y() - 7.5) - 3.0);
    }
    SynthExemplars prepared({SynthView{ex, 2, 1.0f}}, SynthSettings{}, false);
    SynthInput in;
    in.coarse = &L;
    in.factor = 4;
    in.obstacle = &sdf;
    const DetailField O = synthesizeDetail(prepared, in, SynthSettings{});
    double normal2 = 0.0, all2 = 0.0;
    int count = 0;
    for (int i = b.min().x(); i <= b.max().x(); ++i)
        for (int j = b.min().y(); j <= b.max().y(); ++j) {
            const Vec3d w = O.world.lattice().indexToWorld(Vec3d(i, j, k));
            const Vec3d r(w.x() - 7.5, w.y() - 7.5, 0.0);
            const double dist = r.length() - 3.0;
            if (std::abs(dist) > 0.125) continue; // within half a fine voxel of the surface
            const Vec3f v = O.world(i, j, k);
            const double vn = (v[0] * r.x() + v[1] * r.y()) / r.length();
            normal2 += vn * vn;
            all2 += v.lengthSqr();
            ++count;
        }
    ASSERT_GT(count, 10);
    EXPECT_LT(std::sqrt(normal2 / count), 0.1 * rms(O.world));
}

TEST(Synth, SameSeedSameOutputAtAnyThreadCount)
{
    const Exemplar ex = procedural(ProceduralPattern::Hearts, 32, 16);
    const VectorField L2 =
        analyticFlow(AnalyticFlowSettings{AnalyticFlowSettings::Kind::Vortex, Coord(12, 12, 1), 1.0, 1.0, 0.0});
    for (auto method : {SearchMethod::Tree, SearchMethod::KCoherence}) {
        SynthSettings s;
        s.search = method;
        s.boundary.walls = 1u;
        s.threads = 1;
        const DetailField a = synth2D(ex, L2, s);
        s.threads = 2;
        const DetailField b = synth2D(ex, L2, s);
        EXPECT_TRUE(bitEqual(a.world, b.world));
        s.seed = 2;
        const DetailField c = synth2D(ex, L2, s);
        EXPECT_FALSE(bitEqual(a.world, c.world));
    }
    // 3D, three views, density-gradient secondary axis.
    const VectorField L3 =
        analyticFlow(AnalyticFlowSettings{AnalyticFlowSettings::Kind::Vortex, Coord(6, 6, 6), 1.0, 1.0, 0.0});
    ScalarField rho(L3.bbox(), L3.lattice());
    for (size_t q = 0; q < rho.size(); ++q) rho.data()[q] = float(rho.coordOf(q).y()) * 0.1f;
    std::vector<SynthView> views;
    for (int a = 0; a < 3; ++a) views.push_back({ex, a, 1.0f});
    SynthInput in;
    in.coarse = &L3;
    in.coarseDensity = &rho;
    in.factor = 4;
    SynthSettings s;
    s.threads = 1;
    const DetailField a = synthesizeDetail(SynthExemplars(views, s, true), in, s);
    s.threads = 2;
    const DetailField b = synthesizeDetail(SynthExemplars(views, s, true), in, s);
    EXPECT_TRUE(bitEqual(a.world, b.world));
    EXPECT_GT(rms(a.world), 0.3);
}

TEST(Synth, LaterFramesFollowTheAdvectedDetail)
{
    const Exemplar ex = procedural(ProceduralPattern::Swirls, 32, 16);
    const VectorField L = uniformFlow(16, 1, 30.0, 1.0);
    SynthSettings s;
    SynthExemplars prepared({SynthView{ex, 2, 1.0f}}, s, false);
    SynthInput in;
    in.coarse = &L;
    in.factor = 4;
    const DetailField h1 = synthesizeDetail(prepared, in, s);
    in.previous = &h1;
    in.dt = 1.5; // 6 fine voxels
    const DetailField h2 = synthesizeDetail(prepared, in, s);
    EXPECT_TRUE(h2.fromPrevious);
    const VectorField moved = advect(h1.world, L, 1.5);
    const auto relDiff = [&](const VectorField& h) {
        double d = 0.0, n = 0.0;
        const CoordBBox b = h.bbox();
        // Skip the inflow border, where advection brings in nothing.
        for (int i = b.min().x() + 12; i <= b.max().x() - 2; ++i)
            for (int j = b.min().y() + 12; j <= b.max().y() - 2; ++j) {
                d += (h(i, j, 0) - moved(i, j, 0)).lengthSqr();
                n += h(i, j, 0).lengthSqr();
            }
        return std::sqrt(d / n);
    };
    SynthSettings other = s;
    other.seed = 9;
    SynthInput fresh = in;
    fresh.previous = nullptr;
    const DetailField h3 = synthesizeDetail(prepared, fresh, other);
    EXPECT_LT(relDiff(h2.world), 0.6);
    EXPECT_GT(relDiff(h3.world), 1.0);
    // And it still looks like the exemplar.
    EXPECT_LT(textureMatch(ex, h2.local, TextureMatchSettings{}).ratio(), 0.4);
}

// ---------------------------------------------------------------------------------------------
// Combination and density

TEST(Combine, OmegaConstantRelativeAndEnergyWeighted)
{
    const VectorField L =
        analyticFlow(AnalyticFlowSettings{AnalyticFlowSettings::Kind::Shear, Coord(8, 8, 1), 1.0, 2.0, 0.0});
    const VectorField up = upsampleCoarse(L, 4);
    VectorField H(up.bbox(), up.lattice(), Vec3f(0.0f, 1.0f, 0.0f));
    double rmsL = 0.0;
    size_t moving = 0;
    for (const Vec3f& v : L.values())
        if (v.length() > 0.05 * 2.0) { // moving: above 5% of the top speed
            rmsL += v.lengthSqr();
            ++moving;
        }
    rmsL = std::sqrt(rmsL / double(moving));

    CombineSettings c;
    c.omega = 0.5;
    c.removeCoarsePart = false; // the paper's F = up(L) + omega H' (a constant H is all coarse part)
    c.solenoidalDetail = false; // (and has divergence where it meets the box's faces)
    const VectorField F = combineMotion(L, H, c);
    for (size_t n = 0; n < F.size(); n += 7) {
        EXPECT_NEAR(F.data()[n][0], up.data()[n][0], 1e-6);
        EXPECT_NEAR(F.data()[n][1], 0.5 * rmsL, 1e-5);
    }
    c.relative = false;
    EXPECT_NEAR(combineMotion(L, H, c).data()[5][1], 0.5f, 1e-6);

    // Energy weighting: omega follows |L|^2, so it is 0 where the shear flow is still (the middle)
    // and largest at the edges.
    c.weighting = CombineSettings::Weighting::KineticEnergy;
    const VectorField E = combineMotion(L, H, c);
    const CoordBBox b = E.bbox();
    EXPECT_GT(E(10, b.max().y(), 0)[1], 1.5 * 0.5);
    EXPECT_LT(std::abs(E(10, 16, 0)[1]), 0.1);
}

TEST(Combine, TheDetailsCoarsePartIsTakenOutByDefault)
{
    // The detail must not change L's coarse motion. A constant detail is all coarse part and goes
    // entirely; one alternating voxel by voxel has zero cell means and stays; a smooth one (a wavelength of two
    // coarse cells) loses most of its cell means.
    const VectorField L =
        analyticFlow(AnalyticFlowSettings{AnalyticFlowSettings::Kind::Shear, Coord(8, 8, 1), 1.0, 2.0, 0.0});
    const VectorField up = upsampleCoarse(L, 4);
    const auto field = [&](const std::function<Vec3f(const Coord&)>& f) {
        VectorField H(up.bbox(), up.lattice());
        for (size_t n = 0; n < H.size(); ++n) H.data()[n] = f(H.coordOf(n));
        return H;
    };
    const VectorField flat = field([](const Coord&) { return Vec3f(0.0f, 1.0f, 0.0f); });
    const VectorField alternating = field([](const Coord& c) { return Vec3f(0.0f, (c.x() & 1) ? 1.0f : -1.0f, 0.0f); });
    const VectorField smooth =
        field([](const Coord& c) { return Vec3f(0.0f, float(std::sin(2.0 * M_PI * c.x() / 8.0)), 0.0f); });
    CombineSettings c;
    c.relative = false;
    c.omega = 1.0;
    c.solenoidalDetail = false; // the coarse part alone (these fields' divergence is the test below's)
    ASSERT_TRUE(c.removeCoarsePart);
    const VectorField Ff = combineMotion(L, flat, c), Fa = combineMotion(L, alternating, c),
                      Fs = combineMotion(L, smooth, c);
    for (size_t n = 0; n < up.size(); ++n) {
        ASSERT_NEAR(Ff.data()[n][1], up.data()[n][1], 1e-5);
        ASSERT_NEAR(Fa.data()[n][1] - up.data()[n][1], alternating.data()[n][1], 1e-5);
    }
    // lf_err's numerator: the cell means of F - up(L).
    const auto cellMeans = [&](const VectorField& F) {
        VectorField D = F;
        for (size_t n = 0; n < D.size(); ++n) D.data()[n] -= up.data()[n];
        double s2 = 0.0;
        const VectorField means = boxDownsample(D, 4);
        for (const Vec3f& v : means.values()) s2 += v.lengthSqr();
        return std::sqrt(s2);
    };
    double before = 0.0;
    const VectorField smoothMeans = boxDownsample(smooth, 4);
    for (const Vec3f& v : smoothMeans.values()) before += v.lengthSqr();
    before = std::sqrt(before);
    ASSERT_GT(before, 0.1);
    // The worst case: each pass leaves about half of this mode's means (0.46 measured), five passes a few percent.
    EXPECT_LT(cellMeans(Fs), 0.05 * before);
    c.removeCoarsePart = false;
    EXPECT_NEAR(cellMeans(combineMotion(L, smooth, c)), before, 1e-4);
}

TEST(Lookback, OnlyTheLastMFramesOfSourcesRemain)
{
    // With no motion, each frame adds its sources: naive integration keeps all of them, look-back
    // over m frames keeps m frames' worth on top of the coarse-only density O_{i-m}.
    const CoordBBox box(Coord(0), Coord(7, 7, 3));
    const VectorField still(box, Lattice{});
    const ScalarField src(box, Lattice{}, 0.25f);
    const ScalarField coarseOnly(box, Lattice{}, 0.0f);
    LookbackDensity naive(LookbackSettings{0, {}});
    LookbackDensity windowed(LookbackSettings{3, {}});
    for (int i = 1; i <= 6; ++i) {
        const ScalarField dn = naive.step(still, src, coarseOnly, 1.0);
        const ScalarField dw = windowed.step(still, src, coarseOnly, 1.0);
        EXPECT_NEAR(dn(3, 3, 1), 0.25 * i, 1e-5);
        EXPECT_NEAR(dw(3, 3, 1), 0.25 * std::min(i, 3), 1e-5);
    }
    // Sources: what advection does not explain.
    const VectorField right(box, Lattice{}, Vec3f(1.0f, 0.0f, 0.0f));
    ScalarField a(box, Lattice{}), b(box, Lattice{});
    a(2, 3, 1) = 1.0f;
    b(3, 3, 1) = 1.0f; // moved one voxel
    b(6, 6, 2) = 0.5f; // appeared
    const ScalarField s = estimateSources(&a, b, right, 1.0);
    EXPECT_NEAR(s(3, 3, 1), 0.0f, 1e-4);
    EXPECT_NEAR(s(6, 6, 2), 0.5f, 1e-4);
}

TEST(Lookback, EachStepAdvectsOverItsOwnFrameGap)
{
    // Frames processed 1, 2, 4 (a gap of two): a voxel of smoke injected at frame 1 and carried at one voxel per
    // frame must sit 3 voxels on at frame 4, in the windowed (look-back) mode as in the naive one.
    const CoordBBox box(Coord(0), Coord(11, 3, 3));
    const VectorField right(box, Lattice{}, Vec3f(1.0f, 0.0f, 0.0f));
    ScalarField puff(box, Lattice{}), none(box, Lattice{});
    puff(2, 1, 1) = 1.0f;
    for (int m : {0, 3}) {
        LookbackDensity d(LookbackSettings{m, {}});
        d.step(right, puff, none, 1.0);
        d.step(right, none, none, 1.0);
        const ScalarField at4 = d.step(right, none, none, 2.0);
        EXPECT_NEAR(at4(5, 1, 1), 1.0f, 1e-4) << "m " << m;
        EXPECT_NEAR(at4(4, 1, 1), 0.0f, 1e-4) << "m " << m;
    }
}

namespace {

/// rms |curl H| in the `band` voxels inside each face of H's box, over its rms in the interior (voxels at
/// least `inner` from every face); faces in order x-, x+, y-, y+, z-, z+ (z only for a 3D box).
std::vector<double> faceBandVorticity(const VectorField& h, int band, int inner)
{
    const VectorField w = curl(h);
    const CoordBBox b = w.bbox();
    const bool flat = b.dim().z() == 1;
    const int faces = flat ? 4 : 6;
    std::vector<double> e(size_t(faces) + 1, 0.0), n(size_t(faces) + 1, 0.0);
    for (size_t q = 0; q < w.size(); ++q) {
        const Coord c = w.coordOf(q);
        const double v = w.data()[q].lengthSqr();
        int nearest = 1 << 20;
        for (int a = 0; a < (flat ? 2 : 3); ++a) {
            const int lo = c[a] - b.min()[a], hi = b.max()[a] - c[a];
            nearest = std::min({nearest, lo, hi});
            if (lo < band) e[size_t(2 * a)] += v, n[size_t(2 * a)] += 1;
            if (hi < band) e[size_t(2 * a + 1)] += v, n[size_t(2 * a + 1)] += 1;
        }
        if (nearest >= inner) e[size_t(faces)] += v, n[size_t(faces)] += 1;
    }
    const double interior = std::sqrt(e[size_t(faces)] / n[size_t(faces)]);
    std::vector<double> r;
    for (int f = 0; f < faces; ++f) r.push_back(std::sqrt(e[size_t(f)] / n[size_t(f)]) / interior);
    return r;
}

} // namespace

TEST(Synth, FacesLookLikeTheInterior)
{
    // Straight lines along the box faces. A face voxel is covered by fewer neighbourhoods than an
    // interior one, so its average cancels less. Synthesising a margin around the box and cutting it off gives
    // the face bands the interior's vorticity; without it, some face band is off by more than 25%.
    const Exemplar ex = procedural(ProceduralPattern::Swirls, 64, 16);
    const VectorField L = uniformFlow(16, 16, 20.0, 1.0);
    std::vector<SynthView> views;
    for (int a = 0; a < 3; ++a) views.push_back({ex, a, 1.0f});
    const auto run = [&](int padding) {
        SynthSettings s;
        s.facePadding = padding;
        const SynthExemplars prepared(views, s, true);
        SynthInput in;
        in.coarse = &L;
        in.factor = 4;
        const DetailField h1 = synthesizeDetail(prepared, in, s);
        in.previous = &h1;
        in.dt = 0.25;
        const DetailField h2 = synthesizeDetail(prepared, in, s);
        EXPECT_EQ(h2.world.bbox(), h1.world.bbox());
        return std::make_pair(faceBandVorticity(h1.world, 3, 8), faceBandVorticity(h2.world, 3, 8));
    };
    const auto worst = [](const std::vector<double>& r) {
        double w = 0.0;
        for (double v : r) w = std::max(w, std::abs(std::log(v)));
        return std::exp(w);
    };
    const auto bare = run(0);
    const auto padded = run(2);
    for (const auto* r : {&bare.first, &bare.second, &padded.first, &padded.second}) {
        std::string line;
        for (double v : *r) line += " " + std::to_string(v);
        std::printf("face band / interior vorticity:%s\n", line.c_str());
    }
    EXPECT_GT(std::max(worst(bare.first), worst(bare.second)), 1.25);
    EXPECT_LT(worst(padded.first), 1.25);
    EXPECT_LT(worst(padded.second), 1.25);
}

TEST(Synth, DistanceToSmokeIsExactEuclidean)
{
    ScalarField rho(CoordBBox(Coord(-3, 0, 2), Coord(9, 7, 12)), Lattice{});
    const Coord a(0, 1, 4), b(7, 6, 11);
    rho[a] = 1.0f;
    rho[b] = 0.5f;
    const ScalarField d = distanceToSmoke(rho, 0.1f);
    double worst = 0.0;
    for (size_t n = 0; n < d.size(); ++n) {
        const Coord c = d.coordOf(n);
        const double da = (c - a).asVec3d().length(), db = (c - b).asVec3d().length();
        worst = std::max(worst, std::abs(double(d.data()[n]) - std::min(da, db)));
    }
    EXPECT_LT(worst, 1e-5);
    // Nothing above the threshold: every voxel is out of reach.
    const ScalarField none = distanceToSmoke(rho, 2.0f);
    for (float v : none.values()) EXPECT_GT(v, 1e9f);
}

TEST(Combine, TheDetailsDivergenceIsTakenOutByDefault)
{
    // F = up(L) + omega H' keeps L's divergence: the detail's central-difference divergence (what div_rel counts) goes,
    // its cell means stay small, and its curl stays. H' is detail-like (wavelengths of 3-4 fine voxels, under a coarse
    // cell's 4) with divergence and rotation, fading out before the box faces, on a uniform L (no divergence of its
    // own).
    const VectorField L = uniformFlow(8, 8, 0.0, 1.0);
    const VectorField up = upsampleCoarse(L, 4);
    VectorField H(up.bbox(), up.lattice());
    const Vec3d centre = up.bbox().getCenter();
    for (size_t n = 0; n < H.size(); ++n) {
        const Vec3d x = H.coordOf(n).asVec3d() - centre;
        const float g = float(std::exp(-x.lengthSqr() / 60.0));
        H.data()[n] = Vec3f(float(std::sin(1.9 * x.y()) + 0.5 * std::sin(2.1 * x.x())), float(std::cos(1.7 * x.z())),
                          float(std::sin(1.6 * x.x()) + 0.4 * std::cos(2.3 * x.z()))) *
                      g;
    }
    // rms central divergence of F - up(L) over the box's interior, and rms of its curl
    const auto stats = [&](const VectorField& F) {
        VectorField D = F;
        for (size_t n = 0; n < D.size(); ++n) D.data()[n] -= up.data()[n];
        double div = 0.0, curl = 0.0;
        size_t m = 0;
        const CoordBBox in(D.bbox().min().offsetBy(1), D.bbox().max().offsetBy(-1));
        for (auto it = in.begin(); it; ++it) {
            const Jacobian J = jacobianAt(D, (*it).x(), (*it).y(), (*it).z());
            div += double(J.divergence()) * double(J.divergence());
            curl += double(J.curl().lengthSqr());
            ++m;
        }
        return std::make_pair(std::sqrt(div / double(m)), std::sqrt(curl / double(m)));
    };
    CombineSettings c;
    c.relative = false;
    c.omega = 1.0;
    ASSERT_TRUE(c.solenoidalDetail);
    CentralDivergenceResult r;
    const VectorField F = combineMotion(L, H, c, &r);
    c.solenoidalDetail = false;
    const VectorField F0 = combineMotion(L, H, c);
    const auto [div, curl] = stats(F);
    const auto [div0, curl0] = stats(F0);
    EXPECT_TRUE(r.converged);
    EXPECT_LT(r.divRmsAfter, c.solenoidalTolerance * r.divRmsBefore * 1.01);
    // The coarse pass after the solve gives a little divergence back (measured: 0.0092 against 0.30); the curl stays
    // (0.889 against 0.889).
    EXPECT_LT(div, 0.05 * div0);
    EXPECT_GT(curl, 0.9 * curl0);
    // lf_err's numerator, the cell means of F - up(L), against H''s own.
    const VectorField meansUp = boxDownsample(up, 4);
    const auto means = [&](const VectorField& G) {
        const VectorField m = boxDownsample(G, 4);
        double m2 = 0.0;
        for (size_t n = 0; n < m.size(); ++n) m2 += (m.data()[n] - meansUp.data()[n]).lengthSqr();
        return std::sqrt(m2);
    };
    double d2 = 0.0;
    for (const Vec3f& v : boxDownsample(H, 4).values()) d2 += v.lengthSqr();
    // Measured: 0.054 of H''s 0.73 (0.011 without the solve: the gradient part taken out had cell means of its own,
    // and one pass takes most of them out again).
    EXPECT_LT(means(F), 0.1 * std::sqrt(d2));
}

TEST(Combine, DetailStaysNearTheSmokeWhenGivenItsDensity)
{
    // Smoke in coarse cells x <= 1 of a 12-cell-wide box. Margin 2, falloff 2: full detail to x = 3, half at
    // x = 4, none from x = 5 on.
    const VectorField L = uniformFlow(12, 4, 0.0, 1.0);
    ScalarField rho(L.bbox(), L.lattice());
    for (size_t n = 0; n < rho.size(); ++n) rho.data()[n] = rho.coordOf(n).x() <= 1 ? 1.0f : 0.0f;
    const ScalarField w = smokeDetailWeight(rho, 0.01f, 2.0, 2.0);
    EXPECT_EQ(w(3, 1, 1), 1.0f);
    EXPECT_NEAR(w(4, 1, 1), 0.5f, 1e-6);
    EXPECT_EQ(w(6, 1, 1), 0.0f);
    EXPECT_THROW(smokeDetailWeight(rho, 0.01f, -1.0, 2.0), ValueError);
    EXPECT_THROW(smokeDetailWeight(rho, 0.01f, 2.0, 0.0), ValueError);

    const int f = 4;
    const VectorField up = upsampleCoarse(L, f);
    VectorField H(up.bbox(), up.lattice(), Vec3f(0.0f, 1.0f, 0.0f));
    CombineSettings cs;
    cs.removeCoarsePart = false;
    cs.solenoidalDetail = false; // the weight alone
    cs.relative = false;
    cs.omega = 1.0;
    cs.smoke = &rho;
    const VectorField F = combineMotion(L, H, cs);
    const auto detailAt = [&](int coarseX) { return double(F(coarseX * f + 1, 5, 5).y()); };
    EXPECT_NEAR(detailAt(0), 1.0, 1e-6);
    EXPECT_NEAR(detailAt(2), 1.0, 1e-6);
    EXPECT_EQ(detailAt(8), 0.0);
    EXPECT_EQ(detailAt(11), 0.0);
    cs.smoke = nullptr; // the paper: everywhere
    EXPECT_NEAR(double(combineMotion(L, H, cs)(8 * f + 1, 5, 5).y()), 1.0, 1e-6);
}

namespace {

// The 3D vortex case: a 12x12x6 vortex in the xy plane, circles seen from all three axes, z weighted 10.
struct VortexCase
{
    Exemplar ex = procedural(ProceduralPattern::Circles, 64, 16);
    VectorField L =
        analyticFlow(AnalyticFlowSettings{AnalyticFlowSettings::Kind::Vortex, Coord(12, 12, 6), 1.0, 1.0, 0.0});
    std::vector<SynthView> views;
    VortexCase()
    {
        for (int a = 0; a < 3; ++a) views.push_back({ex, a, a == 2 ? 10.0f : 1.0f});
    }
};

} // namespace

TEST(Synth, ThreeDFramesDoNotFlipAcrossAVortex)
{
    // With a fixed secondary axis (+y), the local frame turns 180 degrees where a vortex in the
    // xy plane crosses y = centre, so circles turning one way in the exemplar turn the other way on one side: the
    // skewness of curl_z changes sign across the plane. The secondary n x e1, with n the direction L has least of
    // (here z), keeps the frame continuous, and the sense of rotation the same on both sides.
    const VortexCase vc;
    const VectorField& L = vc.L;
    const std::vector<SynthView>& views = vc.views;
    const auto skewness = [&](bool autoSecondary) {
        SynthSettings s;
        s.orientation.autoSecondary = autoSecondary;
        SynthInput in;
        in.coarse = &L;
        in.factor = 4;
        const DetailField H = synthesizeDetail(SynthExemplars(views, s, true), in, s);
        const VectorField w = curl(H.world);
        const CoordBBox b = w.bbox();
        const double cy = 0.5 * (b.min().y() + b.max().y());
        std::array<std::array<double, 4>, 2> m{};
        for (size_t q = 0; q < w.size(); ++q) {
            const Coord c = w.coordOf(q);
            if (std::abs(c.y() - cy) < 2.0) continue;
            const double v = w.data()[q].z();
            auto& a = m[c.y() < cy ? 0 : 1];
            a[0] += 1.0, a[1] += v, a[2] += v * v, a[3] += v * v * v;
        }
        std::array<double, 2> out{};
        for (int h = 0; h < 2; ++h) {
            const double n = m[size_t(h)][0], mu = m[size_t(h)][1] / n, m2 = m[size_t(h)][2] / n,
                         m3 = m[size_t(h)][3] / n;
            out[size_t(h)] = (m3 - 3.0 * mu * m2 + 2.0 * mu * mu * mu) / std::pow(m2 - mu * mu, 1.5);
        }
        std::printf("curl_z skewness below / above y = centre (%s): %.3f %.3f\n", autoSecondary ? "auto" : "+y", out[0],
            out[1]);
        return out;
    };
    const auto fixedAxis = skewness(false);
    const auto chosen = skewness(true);
    EXPECT_LT(fixedAxis[0] * fixedAxis[1], 0.0); // the flip the issue found
    // One sense of rotation on both sides, the unflipped side's (2D's frame: e2 = z x e1 for a flow in the xy plane).
    EXPECT_GT(chosen[0], 0.8);
    EXPECT_GT(chosen[1], 0.8);
    EXPECT_GT(fixedAxis[0], 0.8);
}

TEST(Synth, EachThreeDIterationDescendsOnItsOwnCentres)
{
    // The reported 3D energy is not monotone across iterations. Measured with traceDescent: on
    // its own centres and matches every iteration lowers Kwatra's objective (the weighted average, the M-step,
    // always; the moment match gives part of it back); the next iteration jitters the centres to new positions,
    // whose neighbourhoods start higher. This holds that every iteration descends on its own centres.
    const VortexCase vc;
    const VectorField& L = vc.L;
    const std::vector<SynthView>& views = vc.views;
    SynthSettings s;
    s.traceDescent = true;
    SynthInput in;
    in.coarse = &L;
    in.factor = 4;
    const DetailField H = synthesizeDetail(SynthExemplars(views, s, true), in, s);
    int iterations = 0;
    for (const SynthLevelStats& st : H.levels)
        for (const auto& d : st.descent) {
            ++iterations;
            EXPECT_LT(d[1], 0.97 * d[0]) << "level " << st.level
                                         << ": the weighted average did not lower the objective";
            EXPECT_LT(d[2], d[0]) << "level " << st.level << ": the iteration ended above where it started";
        }
    EXPECT_GE(iterations, 8);
    // Without the trace nothing is filled (and nothing is paid for).
    s.traceDescent = false;
    const DetailField plain = synthesizeDetail(SynthExemplars(views, s, true), in, s);
    for (const SynthLevelStats& st : plain.levels) EXPECT_TRUE(st.descent.empty());
    EXPECT_TRUE(bitEqual(plain.world, H.world)); // tracing does not change the result
}

TEST(SynthSequence, IsTheStagesComposedAndContinuesOverTheRealTimeBetweenFrames)
{
    // The streaming class must be exactly the paper's stages run in order (synthesise H', F = up(L) + omega H',
    // continue the next frame from H advected by L over the time since the last frame processed).
    const Exemplar ex = procedural(ProceduralPattern::Swirls, 24, 8);
    const VectorField L = uniformFlow(12, 1, 30.0, 2.0);
    SynthSequenceSettings ss;
    ss.synth.seed = 3;
    ss.factor = 2;
    ss.density = false;
    const SynthExemplars prepared({SynthView{ex, 2, 1.0f}}, ss.synth, false);
    SynthSequence seq(prepared, ss);
    EXPECT_THROW(seq.lastDetail(), ValueError);
    SynthFrameInput in;
    in.coarse = &L;
    in.dt = 0.25;
    in.frame = 1;
    const SynthFrameResult r1 = seq.next(in);
    const DetailField H1 = seq.lastDetail();

    SynthInput si;
    si.coarse = &L;
    si.factor = 2;
    si.dt = 0.25;
    const DetailField h1 = synthesizeDetail(prepared, si, ss.synth);
    const VectorField f1 = combineMotion(L, h1.world, ss.combine);
    ASSERT_EQ(r1.frame.velocity.size(), f1.size());
    EXPECT_EQ(0, std::memcmp(r1.frame.velocity.data(), f1.data(), f1.size() * sizeof(Vec3f)));
    EXPECT_EQ(r1.frame.number, 1);
    EXPECT_FALSE(r1.projection);
    EXPECT_FALSE(r1.densityMass.has_value());

    // Frame 3 after frame 1: continued over two frames' time, as synthesizeDetail with dt = 0.5 from H1.
    in.frame = 3;
    const SynthFrameResult r3 = seq.next(in);
    si.previous = &H1;
    si.dt = 0.5;
    const DetailField h3 = synthesizeDetail(prepared, si, ss.synth);
    const VectorField f3 = combineMotion(L, h3.world, ss.combine);
    EXPECT_TRUE(seq.lastDetail().fromPrevious);
    EXPECT_EQ(0, std::memcmp(r3.frame.velocity.data(), f3.data(), f3.size() * sizeof(Vec3f)));
    // Had it advected by one frame's time, the result would differ.
    si.dt = 0.25;
    const VectorField wrong = combineMotion(L, synthesizeDetail(prepared, si, ss.synth).world, ss.combine);
    EXPECT_NE(0, std::memcmp(r3.frame.velocity.data(), wrong.data(), wrong.size() * sizeof(Vec3f)));

    SynthFrameInput bad = in;
    bad.dt = 0.0;
    EXPECT_THROW(seq.next(bad), ValueError);
}
