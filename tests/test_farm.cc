// Time chunks (turb/Farm.h): the split of a frame list and the overlap cross-fade, against analytic answers.
#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Metadata.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace turb;

TEST(FarmPlan, ChunksCoverEveryFrameWithExactOverlapsAndPreroll)
{
    for (size_t n : {12u, 30u, 31u, 1000u})
        for (int N : {1, 2, 3, 7})
            for (int O : {0, 1, 2, 4}) {
                if (n < size_t(N) * size_t(std::max(O, 1)) + size_t(O)) continue;
                const int P = 5;
                const auto c = planTimeChunks(n, N, P, O);
                ASSERT_EQ(c.size(), size_t(N));
                EXPECT_EQ(c.front().keepBegin, 0u);
                EXPECT_EQ(c.front().computeBegin, 0u); // chunk 0 is the sequential run's start: no pre-roll
                EXPECT_EQ(c.back().end, n);
                // Every frame is kept by one chunk, or by two on exactly the O overlap frames.
                std::vector<int> owners(n, 0);
                for (const auto& k : c)
                    for (size_t i = k.keepBegin; i < k.end; ++i) ++owners[i];
                size_t shared = 0;
                for (size_t i = 0; i < n; ++i) {
                    EXPECT_GE(owners[i], 1) << "frame " << i;
                    EXPECT_LE(owners[i], 2) << "frame " << i;
                    shared += owners[i] == 2;
                }
                EXPECT_EQ(shared, size_t(N - 1) * size_t(O));
                for (size_t k = 1; k < c.size(); ++k) {
                    EXPECT_EQ(c[k - 1].end - c[k].keepBegin, size_t(O));
                    EXPECT_EQ(c[k].keepBegin - c[k].computeBegin, std::min<size_t>(P, c[k].keepBegin));
                }
                // Nearly equal lengths: the chunks differ by at most one frame.
                size_t lo = n, hi = 0;
                for (const auto& k : c) {
                    lo = std::min(lo, k.end - k.keepBegin);
                    hi = std::max(hi, k.end - k.keepBegin);
                }
                EXPECT_LE(hi - lo, 1u);
            }
}

TEST(FarmPlan, RefusesChunksShorterThanTwoOverlaps)
{
    EXPECT_THROW(planTimeChunks(10, 4, 2, 3), ValueError);
    EXPECT_THROW(planTimeChunks(10, 0, 2, 1), ValueError);
    EXPECT_THROW(planTimeChunks(10, 2, -1, 1), ValueError);
    EXPECT_NO_THROW(planTimeChunks(10, 2, 2, 3));
}

TEST(FarmBlend, WeightsPreserveDetailEnergyAndDensityMass)
{
    for (int O : {1, 2, 4, 9}) {
        double prevB = 0.0;
        for (int j = 0; j < O; ++j) {
            const CrossFade w = crossFade(j, O);
            EXPECT_NEAR(w.detailA * w.detailA + w.detailB * w.detailB, 1.0, 1e-12);
            EXPECT_NEAR(w.densityA + w.densityB, 1.0, 1e-12);
            EXPECT_GT(w.detailB, prevB);
            EXPECT_GT(w.detailA, 0.0);
            prevB = w.detailB;
        }
        // Symmetric about the middle of the overlap.
        EXPECT_NEAR(crossFade(0, O).detailA, crossFade(O - 1, O).detailB, 1e-12);
    }
    EXPECT_THROW(crossFade(2, 2), ValueError);
}

namespace {

Frame noiseFrame(const CoordBBox& box, const Lattice& l, const VectorField& up, unsigned seed, float density)
{
    std::mt19937 rng(seed);
    std::normal_distribution<float> g(0.0f, 1.0f);
    Frame f;
    f.velocity = VectorField(box, l);
    f.density = ScalarField(box, l, density);
    for (size_t n = 0; n < f.velocity.size(); ++n) f.velocity.data()[n] = up.data()[n] + Vec3f(g(rng), g(rng), g(rng));
    f.metadata[meta::kState] = "state";
    f.metadata[meta::kRatio] = "4";
    return f;
}

} // namespace

TEST(FarmBlend, IndependentDetailsKeepTheirEnergyAndTheCoarseMotionIsExact)
{
    const Lattice l{0.1, {0.0, 0.0, 0.0}};
    const CoordBBox box({0, 0, 0}, {31, 31, 31});
    VectorField up(box, l);
    for (size_t n = 0; n < up.size(); ++n) {
        const Coord c = up.coordOf(n);
        up.data()[n] = Vec3f(float(c.x()) * 0.3f, 2.0f, -float(c.z()) * 0.1f);
    }
    const Frame a = noiseFrame(box, l, up, 1, 0.2f), b = noiseFrame(box, l, up, 2, 0.6f);
    const CrossFade w = crossFade(1, 3); // t = 1/2: where a linear fade loses most (half the energy)
    BlendStats st;
    const Frame out = blendOverlap(a, b, up, w, 0.01f, &st);
    EXPECT_EQ(st.smokeVoxels, box.volume());
    EXPECT_LT(std::abs(st.correlation), 0.02);
    // Independent unit-variance details: the blend's detail has unit variance too (32^3 * 3 samples: ~0.5% noise).
    EXPECT_NEAR(st.energyOut / (0.5 * st.energyA + 0.5 * st.energyB), 1.0, 0.02);
    EXPECT_NEAR(st.energyOut / 3.0, 1.0, 0.02);
    // Density: linear, mass-preserving.
    for (size_t n = 0; n < out.density.size(); ++n) ASSERT_NEAR(out.density.data()[n], 0.4f, 1e-6f);
    // The detail is w_a H_a + w_b H_b on top of up(u_t), times a factor that is 1 for uncorrelated details (here
    // the samples' own correlation, ~1/sqrt(3 * 32^3), leaves it within 1%).
    EXPECT_NEAR(st.energyScale, 1.0, 0.01);
    const float s = float(st.energyScale);
    for (size_t n = 0; n < out.velocity.size(); n += 97) {
        const Vec3f h = s * float(w.detailA) * (a.velocity.data()[n] - up.data()[n]) +
                        s * float(w.detailB) * (b.velocity.data()[n] - up.data()[n]);
        EXPECT_NEAR((out.velocity.data()[n] - up.data()[n] - h).length(), 0.0f, 1e-5f);
    }
    // b's resume state is not the blend's: it must not be resumable.
    EXPECT_EQ(out.metadata.count(meta::kState), 0u);
    EXPECT_EQ(out.metadata.at(meta::kRatio), "4");
}

TEST(FarmBlend, CorrelatedDetailsAreScaledBackToTheInterpolatedEnergy)
{
    const Lattice l{0.1, {0.0, 0.0, 0.0}};
    const CoordBBox box({0, 0, 0}, {15, 15, 15});
    const VectorField up(box, l, Vec3f(1.0f, 0.0f, 0.5f));
    const Frame a = noiseFrame(box, l, up, 3, 0.5f);
    // The same detail in both chunks (rho = 1): w_a + w_b = 1.41 would raise its energy by 2x at t = 1/2; the blend
    // must give the detail back unchanged.
    const CrossFade w = crossFade(0, 1);
    BlendStats st;
    const Frame out = blendOverlap(a, a, up, w, 0.01f, &st);
    EXPECT_NEAR(st.correlation, 1.0, 1e-9);
    EXPECT_NEAR(st.energyScale, 1.0 / (w.detailA + w.detailB), 1e-6);
    EXPECT_NEAR(st.energyOut / st.energyA, 1.0, 1e-5);
    for (size_t n = 0; n < out.velocity.size(); n += 31)
        EXPECT_NEAR((out.velocity.data()[n] - a.velocity.data()[n]).length(), 0.0f, 1e-5f);
    // Half correlated: b = (a's detail + independent detail) / sqrt(2), rho = 1/sqrt(2).
    const Frame c = noiseFrame(box, l, up, 4, 0.5f);
    Frame b = c;
    for (size_t n = 0; n < b.velocity.size(); ++n)
        b.velocity.data()[n] =
            up.data()[n] +
            (a.velocity.data()[n] - up.data()[n] + c.velocity.data()[n] - up.data()[n]) * float(M_SQRT1_2);
    blendOverlap(a, b, up, w, 0.01f, &st);
    EXPECT_NEAR(st.correlation, M_SQRT1_2, 0.02);
    EXPECT_NEAR(st.energyOut / (0.5 * st.energyA + 0.5 * st.energyB), 1.0, 1e-5);
}

TEST(FarmBlend, RefusesFramesOfDifferentBoxes)
{
    const Lattice l{0.1, {0.0, 0.0, 0.0}};
    const CoordBBox box({0, 0, 0}, {7, 7, 7}), other({0, 0, 0}, {7, 7, 8});
    const VectorField up(box, l), up2(other, l);
    const Frame a = noiseFrame(box, l, up, 1, 0.2f), b = noiseFrame(other, l, up2, 2, 0.2f);
    EXPECT_THROW(blendOverlap(a, b, up, crossFade(0, 1), 0.01f), ValueError);
}
