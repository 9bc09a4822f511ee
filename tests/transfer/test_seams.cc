// Seam smoothing (Sato et al., "Example-based Synthesis of Turbulence by Flow Field Style Transfer", section 3.3):
// the band's geometry, the E-step's solvers against the normal equations and against each other, and the EM stage on
// pasted patches (box rows, value rows, the divergence term, 2D).
#include "Modes.h"
#include "TestUtil.h"

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>
#include <turb/Seams.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace turb;
using testutil::Modes;

namespace {

// 24^3 of detail in 8^3 patches, each pasted from its own offset into one analytic source (real seams),
// with box rows on a 4^3 coarse lattice. Holds the source the problem points at, so it stays put.
struct PastedWithSeams
{
    VectorField source{CoordBBox({-16, -16, -16}, {47, 47, 47}), Lattice{}};
    VectorField pasted{CoordBBox({0, 0, 0}, {23, 23, 23}), Lattice{}};
    SeamProblem problem;
    explicit PastedWithSeams(unsigned seed)
    {
        const Modes fine(20, 3.0, 8.0, seed, 1.0);
        for (size_t n = 0; n < source.size(); ++n) source.data()[n] = fine.at(source.coordOf(n).asVec3d());
        SeamProblem& p = problem;
        p.sourceHigh = &source;
        p.layout = PatchLayout::covering(pasted.bbox(), 8);
        p.active.assign(p.layout.patchCount(), 1);
        p.offset.resize(p.layout.patchCount());
        for (size_t i = 0; i < p.offset.size(); ++i)
            p.offset[i] = Coord(int(i % 5) * 3 - 6, int(i % 3) * 4 - 4, int(i % 7) - 3);
        p.boxFactor = 4;
        for (size_t n = 0; n < pasted.size(); ++n) {
            const Coord c = pasted.coordOf(n);
            pasted.data()[n] = source[c + p.offset[p.layout.patchIndex(p.layout.patchOf(c))]];
        }
    }
    PastedWithSeams(const PastedWithSeams&) = delete;
    PastedWithSeams& operator=(const PastedWithSeams&) = delete;
};

// Every E-step stopped on its tolerance, before its iteration cap and in fewer than `maxIterations` iterations (each
// caller's bound is about twice the most its solves were measured to take, so a slower solve fails before the cap).
// `flat`: the layout is 2D, whose E-steps stop on cgTolerance2D.
void expectConverged(const SeamStats& st, const SeamSettings& s, int maxIterations, bool flat = false)
{
    EXPECT_FALSE(st.iterations.empty());
    for (size_t k = 0; k < st.iterations.size(); ++k) {
        EXPECT_LE(st.iterations[k].cgResidual, flat ? s.cgTolerance2D : s.cgTolerance) << "EM iteration " << k;
        EXPECT_LT(st.iterations[k].cgIterations, s.maxCgIterations) << "EM iteration " << k;
        EXPECT_LT(st.iterations[k].cgIterations, maxIterations) << "EM iteration " << k;
    }
}

// Every kind of row the E-step has: edges, divergence of a base field under the detail, box means, and value rows
// in patches that carry last frame's detail (weights 0 and 0.6).
struct EveryRow
{
    PastedWithSeams fx{24};
    VectorField base{fx.pasted.bbox(), Lattice{}};
    SeamProblem problem = fx.problem;
    SeamSettings settings;
    EveryRow()
    {
        for (size_t n = 0; n < base.size(); ++n) base.data()[n] = Vec3f(0.2f * float(base.coordOf(n).x()), 0.0f, 0.0f);
        problem.base = &base;
        problem.baseScale = 0.5f;
        problem.temporal = &fx.pasted;
        problem.temporalWeights.assign(problem.layout.patchCount(), 0.0f);
        for (size_t i = 0; i < problem.temporalWeights.size(); ++i) problem.temporalWeights[i] = (i % 3) ? 0.6f : 0.0f;
        settings.valueWeight = 5.0f;
    }
    SeamStats solve(VectorField& x, SeamSolver solver, int threads) const
    {
        SeamSettings s = settings;
        s.solver = solver;
        SeamStats st;
        withThreads(threads, [&] { st = smoothSeams(x, problem, s); });
        return st;
    }
};

} // namespace

TEST(SeamBand, GeometryMatchesTheAnalyticCount)
{
    const CoordBBox box({0, 0, 0}, {31, 31, 31});
    const PatchLayout layout = PatchLayout::covering(box, 8);
    ASSERT_EQ(layout.count, Coord(4, 4, 4));
    // Every patch active: per axis 12 of 32 positions lie within 2 of an inner border.
    std::vector<uint8_t> all(layout.patchCount(), 1);
    auto band = seamBand(box, layout, all, 2);
    EXPECT_EQ(std::count(band.begin(), band.end(), uint8_t(1)), 32 * 32 * 32 - 20 * 20 * 20);
    // One interior active patch: its own shell (8^3 - 4^3) plus a 2-voxel slab in each face neighbour.
    std::vector<uint8_t> one(layout.patchCount(), 0);
    one[layout.patchIndex(Coord(1, 1, 1))] = 1;
    band = seamBand(box, layout, one, 2);
    EXPECT_EQ(std::count(band.begin(), band.end(), uint8_t(1)), (512 - 64) + 6 * 2 * 8 * 8);
    // No active patch, no band.
    std::vector<uint8_t> none(layout.patchCount(), 0);
    band = seamBand(box, layout, none, 2);
    EXPECT_EQ(std::count(band.begin(), band.end(), uint8_t(1)), 0);
}

TEST(SeamBand, TwoDGeometryMatchesTheAnalyticCount)
{
    // A 2D box (one layer, at z = 5): patches are 8 x 8 x 1 and there are no borders along z.
    const CoordBBox box({0, 0, 5}, {31, 31, 5});
    const PatchLayout layout = PatchLayout::covering(box, 8);
    ASSERT_TRUE(layout.flat);
    ASSERT_EQ(layout.count, Coord(4, 4, 1));
    EXPECT_EQ(layout.patchBox(Coord(1, 2, 0)), CoordBBox({8, 16, 5}, {15, 23, 5}));
    EXPECT_EQ(layout.patchOf(Coord(9, 17, 5)), Coord(1, 2, 0));
    // Every patch active: per axis 12 of 32 positions lie within 2 of an inner border, in x and y only.
    std::vector<uint8_t> all(layout.patchCount(), 1);
    auto band = seamBand(box, layout, all, 2);
    EXPECT_EQ(std::count(band.begin(), band.end(), uint8_t(1)), 32 * 32 - 20 * 20);
    // One interior active patch: its own ring (8^2 - 4^2) plus a 2-voxel strip in each of its 4 edge neighbours.
    std::vector<uint8_t> one(layout.patchCount(), 0);
    one[layout.patchIndex(Coord(1, 1, 0))] = 1;
    band = seamBand(box, layout, one, 2);
    EXPECT_EQ(std::count(band.begin(), band.end(), uint8_t(1)), (64 - 16) + 4 * 2 * 8);
    // Band width 1 around a corner patch (0, 0): only its two inner sides have borders.
    std::vector<uint8_t> corner(layout.patchCount(), 0);
    corner[layout.patchIndex(Coord(0, 0, 0))] = 1;
    band = seamBand(box, layout, corner, 1);
    // Own: the last column and row (15 voxels); neighbours (1,0) and (0,1): one 8-voxel strip each.
    EXPECT_EQ(std::count(band.begin(), band.end(), uint8_t(1)), 15 + 2 * 8);
}

class SeamSolve : public ::testing::Test
{
protected:
    // A 24^3 field with a random discontinuous pasted pattern and targets from a smooth random field.
    void SetUp() override
    {
        box = CoordBBox({0, 0, 0}, {23, 23, 23});
        X = VectorField(box, Lattice{});
        std::mt19937 rng(5);
        std::normal_distribution<float> g;
        for (auto& v : X.values()) v = Vec3f(g(rng), g(rng), g(rng));
        const Modes smooth(12, 6.0, 20.0, 9, 1.0);
        targets.assign(3 * X.size(), Vec3f(0.0f));
        for (size_t n = 0; n < X.size(); ++n) {
            const Vec3d x = X.coordOf(n).asVec3d();
            for (int a = 0; a < 3; ++a) {
                Vec3d y = x;
                y[a] += 1.0;
                // A target with divergence: gradient of the smooth field plus a compressive part.
                targets[n * 3 + size_t(a)] = smooth.at(y) - smooth.at(x) +
                                             Vec3f(a == 0 ? 0.3f : 0.0f, a == 1 ? 0.3f : 0.0f, a == 2 ? 0.3f : 0.0f);
            }
        }
        const PatchLayout layout = PatchLayout::covering(box, 8);
        omega = seamBand(box, layout, std::vector<uint8_t>(layout.patchCount(), 1), 2);
    }
    void expectNormalEquations(SeamSolver solver) const;
    CoordBBox box;
    VectorField X;
    std::vector<Vec3f> targets;
    std::vector<uint8_t> omega;
};

TEST_F(SeamSolve, CgSolutionSatisfiesTheNormalEquations)
{
    for (SeamSolver solver : {SeamSolver::Cgnr, SeamSolver::EigenLscg}) expectNormalEquations(solver);
}

// Both E-step solvers, at a tolerance of 1e-7, stop with the normal equations satisfied.
void SeamSolve::expectNormalEquations(SeamSolver solver) const
{
    SCOPED_TRACE(solver == SeamSolver::Cgnr ? "CGNR" : "Eigen LSCG");
    VectorField x = X;
    const double before = seamEnergy(x, omega, targets, 10.0f);
    const SeamIteration it = solveSeamEStep(x, omega, targets, 10.0f, 2000, 1e-7, solver);
    EXPECT_LE(it.cgResidual, 1e-7);
    EXPECT_LT(it.cgIterations, 200) << "measured: 107 (CGNR), 97 (Eigen)";
    EXPECT_LT(it.energy, before);
    EXPECT_NEAR(it.energy, seamEnergy(x, omega, targets, 10.0f), 1e-6 * before);
    // Values outside Ω are untouched.
    for (size_t n = 0; n < x.size(); ++n)
        if (!omega[n]) ASSERT_EQ(x.data()[n], X.data()[n]);
    // At the minimum the directional derivative along any perturbation of Ω vanishes:
    // (E(x + e d) - E(x - e d)) / 2e = 2 d.(A^T A x - A^T b) ~ 0, compared with the energy's scale.
    std::mt19937 rng(1);
    std::normal_distribution<float> g;
    for (int trial = 0; trial < 3; ++trial) {
        VectorField d(box, Lattice{});
        for (size_t n = 0; n < d.size(); ++n)
            if (omega[n]) d.data()[n] = Vec3f(g(rng), g(rng), g(rng));
        const float eps = 1e-2f;
        VectorField p = x, m = x;
        for (size_t n = 0; n < x.size(); ++n) {
            p.data()[n] += d.data()[n] * eps;
            m.data()[n] -= d.data()[n] * eps;
        }
        const double ep = seamEnergy(p, omega, targets, 10.0f), em = seamEnergy(m, omega, targets, 10.0f);
        const double slope = (ep - em) / (2 * eps), curvature = (ep + em - 2 * it.energy) / (eps * eps);
        // A non-minimum would have |slope| comparable to sqrt(curvature * E).
        EXPECT_LT(std::abs(slope), 1e-3 * std::sqrt(curvature * before)) << "trial " << trial;
        EXPECT_GT(curvature, 0.0);
    }
}

TEST_F(SeamSolve, RaisingGammaLowersDivergence)
{
    double previous = 1e300;
    for (float gamma : {0.0f, 1.0f, 10.0f, 100.0f}) {
        VectorField x = X;
        const SeamIteration it = solveSeamEStep(x, omega, targets, gamma, 2000, 1e-6);
        EXPECT_LE(it.cgResidual, 1e-6) << "gamma " << gamma;
        EXPECT_LT(it.cgIterations, 400) << "gamma " << gamma << " (measured: 48 at 0, 224 at 100)";
        const ScalarField div = divergence(x);
        double s = 0;
        for (size_t n = 0; n < div.size(); ++n)
            if (omega[n]) s += double(div.data()[n]) * div.data()[n];
        EXPECT_LT(s, previous) << "gamma " << gamma;
        previous = s;
    }
}

TEST_F(SeamSolve, EigenLeastSquaresReachesTheCgnrEnergy)
{
    // The same system assembled as a sparse matrix and solved by Eigen's LeastSquaresConjugateGradient: at the
    // transfer's defaults (relative residual 1e-3, at most 100 iterations) both converge, to the same E_b.
    const SeamSettings defaults;
    VectorField cgnr = X, eigen = X;
    const SeamIteration a =
        solveSeamEStep(cgnr, omega, targets, 10.0f, defaults.maxCgIterations, defaults.cgTolerance, SeamSolver::Cgnr);
    const SeamIteration b = solveSeamEStep(
        eigen, omega, targets, 10.0f, defaults.maxCgIterations, defaults.cgTolerance, SeamSolver::EigenLscg);
    for (const SeamIteration& it : {a, b}) {
        EXPECT_LE(it.cgResidual, defaults.cgTolerance);
        EXPECT_LT(it.cgIterations, 60) << "measured: 37 (CGNR), 34 (Eigen)";
    }
    EXPECT_NEAR(b.energy, a.energy, 0.01 * a.energy);
    EXPECT_NEAR(b.energy, seamEnergy(eigen, omega, targets, 10.0f), 1e-6 * b.energy);
    for (size_t n = 0; n < X.size(); ++n)
        if (!omega[n]) ASSERT_EQ(eigen.data()[n], X.data()[n]) << "values outside Ω are untouched";
}

TEST(SeamSmoothing, LeavesAFieldWithoutSeamsAlone)
{
    // Every patch pasted from the same offset is one continuous copy of the source: the M-step must find
    // that continuation and the E-step must keep it (no divergence or box terms here).
    const CoordBBox box({0, 0, 0}, {31, 31, 31});
    const Modes fine(20, 3.0, 8.0, 12, 1.0);
    VectorField source(CoordBBox({-8, -8, -8}, {47, 47, 47}), Lattice{});
    for (size_t n = 0; n < source.size(); ++n) source.data()[n] = fine.at(source.coordOf(n).asVec3d());
    const Coord off(5, -3, 2);
    VectorField detail(box, Lattice{});
    for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] = source[detail.coordOf(n) + off];
    const VectorField before = detail;
    SeamProblem p;
    p.sourceHigh = &source;
    p.layout = PatchLayout::covering(box, 8);
    p.active.assign(p.layout.patchCount(), 1);
    p.offset.assign(p.layout.patchCount(), off);
    SeamSettings s;
    s.gamma = 0.0f;
    const SeamStats st = smoothSeams(detail, p, s);
    expectConverged(st, s, 40); // measured 19-20
    EXPECT_GT(st.bandVoxels, 0u);
    EXPECT_LT(st.initialEnergy, 1e-6);
    double change = 0, energy = 0;
    for (size_t n = 0; n < detail.size(); ++n) {
        change += (detail.data()[n] - before.data()[n]).lengthSqr();
        energy += before.data()[n].lengthSqr();
    }
    EXPECT_LT(change, 1e-8 * energy);
}

TEST(SeamSmoothing, BoxRowsHoldTheCoarseMeansOrClearThem)
{
    // Patches pasted from different offsets: the seam solve moves detail across borders. Its box rows hold
    // each coarse cell's mean where it came in (keep 1) or pull it to zero (keep 0); without them the
    // means drift.
    const PastedWithSeams fx(22);
    SeamProblem p = fx.problem;
    const VectorField& pasted = fx.pasted;
    const VectorField before = boxDownsample(pasted, 4);
    const auto rms = [](const VectorField& a, const VectorField* b) {
        double e = 0;
        for (size_t n = 0; n < a.size(); ++n) e += (a.data()[n] - (b ? b->data()[n] : Vec3f(0.0f))).lengthSqr();
        return std::sqrt(e / double(a.size()));
    };
    const auto means = [&](float weight, float keep) {
        VectorField detail = pasted;
        SeamSettings s;
        s.boxWeight = weight;
        s.boxKeep = keep;
        s.maxCgIterations = 400;
        s.cgTolerance = 1e-6;
        expectConverged(smoothSeams(detail, p, s), s, 200); // measured 54-105
        return boxDownsample(detail, 4);
    };
    const double scale = rms(before, nullptr);
    const double drift = rms(means(0.0f, 1.0f), &before) / scale;
    EXPECT_GT(drift, 0.2) << "without box rows the solve must move the means for this test to mean anything";
    EXPECT_LT(rms(means(10.0f, 1.0f), &before) / scale, 0.25 * drift);
    // Rows are soft (weight 10 against the gradient and divergence rows): most of each mean goes.
    EXPECT_LT(rms(means(10.0f, 0.0f), nullptr) / scale, 0.35);
}

TEST(SeamSmoothing, DivergenceTermCancelsTheScaledBaseAndReachesWholePatches)
{
    // A base field of constant divergence 0.2 under pasted, divergence-free detail. The gamma term makes
    // div(baseScale * base + X) small in Ω: the solve cancels the base scaled as asked (the detail is
    // scaled by 1 / baseScale afterwards in the transfer), and whole patches take part everywhere.
    const PastedWithSeams fx(23);
    VectorField base(fx.pasted.bbox(), Lattice{});
    for (size_t n = 0; n < base.size(); ++n) base.data()[n] = Vec3f(0.2f * float(base.coordOf(n).x()), 0.0f, 0.0f);
    const std::vector<uint8_t> band = seamBand(fx.pasted.bbox(), fx.problem.layout, fx.problem.active, 2);
    // rms of div(scale * base + x) over the band (or everywhere).
    const auto rmsDiv = [&](const VectorField& x, float scale, bool bandOnly) {
        VectorField u = x;
        for (size_t n = 0; n < u.size(); ++n) u.data()[n] += base.data()[n] * scale;
        const ScalarField div = divergence(u);
        double e = 0;
        size_t count = 0;
        for (size_t n = 0; n < div.size(); ++n)
            if (!bandOnly || band[n]) {
                e += double(div.data()[n]) * div.data()[n];
                ++count;
            }
        return std::sqrt(e / double(count));
    };
    const auto solved = [&](float scale, bool whole, SeamStats* stats = nullptr) {
        SeamProblem p = fx.problem;
        p.boxFactor = 0;
        p.base = &base;
        p.baseScale = scale;
        if (whole) p.wholePatches.assign(p.layout.patchCount(), 1);
        VectorField x = fx.pasted;
        SeamSettings s;
        s.gamma = 100.0f;
        s.maxCgIterations = 1500; // whole patches at gamma 100 need about 950 CGNR iterations for 1e-6
        s.cgTolerance = 1e-6;
        const SeamStats st = smoothSeams(x, p, s);
        expectConverged(st, s, whole ? 1500 : 600); // measured 238-307 in the band, 668-953 with whole patches
        if (stats) *stats = st;
        return x;
    };
    const VectorField one = solved(1.0f, false), half = solved(0.5f, false);
    EXPECT_LT(rmsDiv(one, 1.0f, true), 0.3 * rmsDiv(one, 0.5f, true));
    EXPECT_LT(rmsDiv(half, 0.5f, true), 0.3 * rmsDiv(half, 1.0f, true));

    // Whole patches: every voxel is an unknown, and the divergence falls everywhere, not only in the band.
    SeamStats inBand, inWhole;
    const VectorField banded = solved(1.0f, false, &inBand), whole = solved(1.0f, true, &inWhole);
    EXPECT_EQ(inWhole.bandVoxels, fx.pasted.size());
    EXPECT_EQ(inBand.bandVoxels, size_t(std::count(band.begin(), band.end(), uint8_t(1))));
    EXPECT_LT(inBand.bandVoxels, fx.pasted.size());
    EXPECT_LT(rmsDiv(whole, 1.0f, false), 0.5 * rmsDiv(banded, 1.0f, false));
    SeamProblem bad = fx.problem;
    bad.wholePatches.assign(3, 1);
    VectorField x = fx.pasted;
    EXPECT_THROW(smoothSeams(x, bad, SeamSettings{}), ValueError) << "one flag per patch is required";
}

TEST(SeamSmoothing, ValueRowsKeepCarriedDetailNearItsValue)
{
    // Patches pasted from different offsets (real seams), all carrying last frame's detail with weight
    // 0.9: the larger the value weight, the less the solve changes the detail, and a huge weight leaves
    // it where it was.
    const PastedWithSeams fx(21);
    SeamProblem p = fx.problem;
    const VectorField& pasted = fx.pasted;
    p.temporal = &pasted;
    // Relative change of the detail over the voxels of patches with weight w (w < 0: all).
    const auto relChange = [&](const VectorField& detail, float w) {
        double change = 0, energy = 0;
        for (size_t n = 0; n < detail.size(); ++n) {
            if (w >= 0.0f && p.temporalWeights[p.layout.patchIndex(p.layout.patchOf(detail.coordOf(n)))] != w) continue;
            change += (detail.data()[n] - pasted.data()[n]).lengthSqr();
            energy += pasted.data()[n].lengthSqr();
        }
        return std::sqrt(change / energy);
    };
    const auto solved = [&](float mu, double tolerance = 1e-6) {
        VectorField detail = pasted;
        SeamSettings s;
        s.valueWeight = mu;
        s.maxCgIterations = 400;
        s.cgTolerance = tolerance;
        expectConverged(smoothSeams(detail, p, s), s, 250); // measured 18-113
        return detail;
    };
    p.temporalWeights.assign(p.layout.patchCount(), 0.9f);
    // At mu = 5 the float CGNR stalls at a relative residual of 1.5e-6 (Eigen's double LSCG reaches 1e-6 in 23).
    const double free = relChange(solved(0.0f), -1.0f), held = relChange(solved(5.0f, 1e-5), -1.0f);
    EXPECT_GT(free, 0.05) << "the seams must need smoothing for this test to mean anything";
    EXPECT_LT(held, 0.8 * free);
    // Weights per patch: with a huge value weight, patches weighted 0.9 stay put while patches weighted 0
    // are still smoothed as freely as without value rows.
    for (size_t i = 0; i < p.temporalWeights.size(); ++i) p.temporalWeights[i] = (i % 2) ? 0.0f : 0.9f;
    const VectorField mixed = solved(1e6f);
    EXPECT_LT(relChange(mixed, 0.9f), 1e-3);
    EXPECT_GT(relChange(mixed, 0.0f), 0.5 * free);
    p.temporalWeights.pop_back();
    VectorField bad = pasted;
    EXPECT_THROW(smoothSeams(bad, p, SeamSettings{}), ValueError) << "one weight per patch is required";
}

TEST(SeamSmoothing, TwoDSolveSmoothsSeamsAndKeepsTheFieldFlat)
{
    // Two halves pasted from different parts of a smooth 2D field: the seam solve on the 2D band must lower the
    // seam energy, write nothing along z, and touch only the band.
    const CoordBBox box({0, 0, 0}, {31, 31, 0});
    const Lattice lat{1.0, Vec3d(0.0)};
    VectorField src(CoordBBox({0, 0, 0}, {95, 95, 0}), lat);
    for (size_t n = 0; n < src.size(); ++n) {
        const Vec3d x = src.coordOf(n).asVec3d();
        src.data()[n] = Vec3f(float(std::sin(0.7 * x.y())), float(std::cos(0.6 * x.x())), 0.0f);
    }
    const PatchLayout layout = PatchLayout::covering(box, 8);
    SeamProblem problem;
    problem.sourceHigh = &src;
    problem.layout = layout;
    problem.active.assign(layout.patchCount(), 1);
    problem.offset.assign(layout.patchCount(), Coord(0));
    VectorField X(box, lat);
    for (size_t p = 0; p < layout.patchCount(); ++p) {
        const Coord P = layout.patchCoord(p);
        problem.offset[p] = Coord(13 * P.x() + 7 * P.y(), 11 * P.y() + 3 * P.x(), 0);
        const CoordBBox pb = layout.patchBox(P);
        for (auto it = pb.begin(); it; ++it) X[*it] = src[*it + problem.offset[p]];
    }
    const std::vector<uint8_t> band = seamBand(box, layout, problem.active, 2);
    SeamSettings settings;
    settings.gamma = 1.0f;
    settings.bandWidth2D = 2; // the band above
    settings.cgTolerance = 1e-9; // the 3D tolerance does not apply here: the solves stop on cgTolerance2D (1e-3)
    settings.cgTolerance2D = 1e-3;
    // Both solvers (the explicit matrix has no z stencil here), to the same E_b.
    std::vector<double> energies;
    for (SeamSolver solver : {SeamSolver::Cgnr, SeamSolver::EigenLscg}) {
        SCOPED_TRACE(solver == SeamSolver::Cgnr ? "CGNR" : "Eigen LSCG");
        settings.solver = solver;
        VectorField Y = X;
        const SeamStats st = smoothSeams(Y, problem, settings);
        ASSERT_FALSE(st.iterations.empty());
        expectConverged(st, settings, 40, /*flat=*/true); // measured 16-19
        EXPECT_GT(st.boundaryPatches, 0u);
        EXPECT_LT(st.iterations.back().energy, st.initialEnergy);
        EXPECT_EQ(st.bandVoxels, size_t(std::count(band.begin(), band.end(), uint8_t(1))));
        for (size_t n = 0; n < X.size(); ++n) {
            EXPECT_EQ(Y.data()[n].z(), 0.0f);
            if (!band[n]) EXPECT_EQ(Y.data()[n], X.data()[n]);
        }
        energies.push_back(st.iterations.back().energy);
    }
    EXPECT_NEAR(energies[1], energies[0], 0.01 * energies[0]);
}

TEST(SeamSmoothing, EigenLeastSquaresMatchesCgnrWithEveryKindOfRow)
{
    // The explicit matrix must hold the rows the matrix-free solve applies: with edge, divergence (and base), box and
    // value rows, each EM iteration of the two solvers converges and reaches the same E_b.
    const EveryRow er;
    VectorField a = er.fx.pasted, b = er.fx.pasted;
    const SeamStats sa = er.solve(a, SeamSolver::Cgnr, 2), sb = er.solve(b, SeamSolver::EigenLscg, 2);
    ASSERT_EQ(sa.iterations.size(), sb.iterations.size());
    ASSERT_FALSE(sa.iterations.empty());
    for (size_t k = 0; k < sa.iterations.size(); ++k) {
        for (const SeamIteration& it : {sa.iterations[k], sb.iterations[k]}) {
            EXPECT_LE(it.cgResidual, er.settings.cgTolerance) << "EM iteration " << k;
            EXPECT_LT(it.cgIterations, 50) << "EM iteration " << k << " (measured: 23-28)";
        }
        EXPECT_NEAR(sb.iterations[k].energy, sa.iterations[k].energy, 0.01 * sa.iterations[k].energy)
            << "EM iteration " << k;
    }
    EXPECT_LT(sb.iterations.back().energy, 0.5 * sb.initialEnergy);
    double diff = 0, norm = 0;
    for (size_t n = 0; n < a.size(); ++n) {
        diff += (a.data()[n] - b.data()[n]).lengthSqr();
        norm += (a.data()[n] - er.fx.pasted.data()[n]).lengthSqr();
    }
    EXPECT_LT(std::sqrt(diff / norm), 0.01) << "the two solutions differ by more than 1% of the change they make";
}

TEST(SeamSmoothing, BothSolversAreIdenticalAtOneAndTwoThreads)
{
    const EveryRow er;
    for (SeamSolver solver : {SeamSolver::Cgnr, SeamSolver::EigenLscg}) {
        VectorField one = er.fx.pasted, two = er.fx.pasted;
        const SeamStats s1 = er.solve(one, solver, 1), s2 = er.solve(two, solver, 2);
        const char* name = solver == SeamSolver::Cgnr ? "CGNR" : "Eigen";
        SCOPED_TRACE(name);
        expectConverged(s1, er.settings, 50); // measured 23-28, as in EigenLeastSquaresMatchesCgnrWithEveryKindOfRow
        EXPECT_EQ(one.values(), two.values()) << name;
        ASSERT_EQ(s1.iterations.size(), s2.iterations.size()) << name;
        for (size_t k = 0; k < s1.iterations.size(); ++k) {
            EXPECT_EQ(s1.iterations[k].cgIterations, s2.iterations[k].cgIterations) << name;
            EXPECT_EQ(s1.iterations[k].cgResidual, s2.iterations[k].cgResidual) << name;
            EXPECT_EQ(s1.iterations[k].energy, s2.iterations[k].energy) << name;
        }
    }
}
