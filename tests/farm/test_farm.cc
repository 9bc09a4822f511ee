// Time chunks and space tiles (turb/Farm.h): the split of a frame list and the overlap cross-fade, the split of a box
// and the tiles' join, against analytic answers.
#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Metadata.h>
#include <turb/Resample.h>

#include <gtest/gtest.h>

#include <algorithm>
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
    // Two chunks have one overlap between them: it may be most of the shot (the long overlaps the seam needs).
    const auto two = planTimeChunks(30, 2, 0, 25);
    EXPECT_EQ(two[0].end - two[1].keepBegin, 25u);
    EXPECT_GE(two[1].keepBegin, 1u);
    EXPECT_THROW(planTimeChunks(30, 3, 0, 12), ValueError); // the middle chunk's two overlaps would meet
    EXPECT_THROW(planTimeChunks(30, 2, 0, 29), ValueError); // chunk 0 would keep no frame of its own
    const auto one = planTimeChunks(12, 1, 4, 20);          // one chunk: no overlap, no pre-roll
    ASSERT_EQ(one.size(), 1u);
    EXPECT_EQ(one[0].computeBegin, 0u);
    EXPECT_EQ(one[0].end, 12u);
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

// ---------------------------------------------------------------------------------------------
// Space tiles

TEST(FarmTiles, CoresPartitionTheBoxAndTheHalosStayInsideIt)
{
    const CoordBBox box(Coord(-5, 3, 0), Coord(40, 30, 17));
    for (const Coord n : {Coord(1), Coord(2, 1, 1), Coord(2, 2, 1), Coord(3, 2, 2)})
        for (int halo : {1, 4}) {
            const TilePlan p = planSpaceTiles(box, n, halo);
            ASSERT_EQ(p.tiles.size(), size_t(n.x() * n.y() * n.z()));
            std::vector<int> owners(size_t(box.volume()), 0);
            for (const SpaceTile& t : p.tiles) {
                EXPECT_TRUE(box.isInside(t.core));
                EXPECT_TRUE(box.isInside(t.held));
                EXPECT_TRUE(t.held.isInside(t.core));
                for (int a = 0; a < 3; ++a) {
                    // The halo reaches toward a neighbour only, and exactly `halo` voxels.
                    EXPECT_EQ(t.core.min()[a] - t.held.min()[a], t.core.min()[a] > box.min()[a] ? halo : 0);
                    EXPECT_EQ(t.held.max()[a] - t.core.max()[a], t.core.max()[a] < box.max()[a] ? halo : 0);
                }
                for (auto it = t.core.beginXYZ(); it; ++it) {
                    const Coord c = *it - box.min();
                    ++owners[size_t((c.x() * box.dim().y() + c.y()) * box.dim().z() + c.z())];
                }
            }
            for (int o : owners) ASSERT_EQ(o, 1);
        }
    // Borders on absolute multiples of the alignment.
    const TilePlan aligned = planSpaceTiles(box, Coord(3, 1, 1), 2, 4);
    for (const SpaceTile& t : aligned.tiles)
        if (t.core.min().x() > box.min().x()) EXPECT_EQ(t.core.min().x() % 4, 0);
    EXPECT_THROW(planSpaceTiles(box, Coord(0, 1, 1), 2), ValueError);
    EXPECT_THROW(planSpaceTiles(box, Coord(20, 1, 1), 4), ValueError); // tiles of 2-3 voxels, halo 4
    EXPECT_THROW(planSpaceTiles(CoordBBox(Coord(0), Coord(31, 31, 0)), Coord(1, 1, 2), 2), ValueError); // 2D in z
    EXPECT_NO_THROW(planSpaceTiles(CoordBBox(Coord(0), Coord(31, 31, 0)), Coord(2, 2, 1), 2));
}

TEST(FarmTiles, WeightsAreAPartitionOfUnityWithLinearRampsAcrossTheBorders)
{
    const CoordBBox box(Coord(0), Coord(15, 11, 7));
    const TilePlan p = planSpaceTiles(box, Coord(2, 2, 1), 3);
    const int f = 4, ramp = 8;
    const CoordBBox fine = refineDomain(box, f);
    for (auto it = fine.beginXYZ(); it; ++it) {
        double sum = 0.0;
        for (size_t k = 0; k < p.tiles.size(); ++k) {
            const double w = p.weight(k, *it, f, ramp);
            EXPECT_GE(w, 0.0);
            EXPECT_LE(w, 1.0);
            if (w > 0.0) EXPECT_TRUE(refineDomain(p.tiles[k].held, f).isInside(*it));
            sum += w;
        }
        ASSERT_NEAR(sum, 1.0, 1e-12);
    }
    // Tile 0's core is x 0..7, y 0..5: its border planes are x = 32 and y = 24 in output voxels. Along x at y = 0
    // (deep in its core in y), the weight falls linearly over x = 28..36: (36 - (x + 0.5)) / 8.
    for (int x = 24; x < 40; ++x)
        EXPECT_NEAR(p.weight(0, Coord(x, 0, 0), f, ramp), std::clamp((36.0 - (x + 0.5)) / 8.0, 0.0, 1.0), 1e-12);
    EXPECT_DOUBLE_EQ(p.weight(0, Coord(31, 23, 0), f, ramp), (36.0 - 31.5) / 8.0 * (28.0 - 23.5) / 8.0);
}

namespace {

// A frame with smooth but distinct values everywhere on `box` (velocity, density, temperature).
Frame wholeFrame(const CoordBBox& box, const Lattice& l)
{
    Frame f;
    f.number = 7;
    f.velocity = VectorField(box, l);
    f.density = ScalarField(box, l);
    f.temperature = ScalarField(box, l);
    for (size_t n = 0; n < f.velocity.size(); ++n) {
        const Coord c = f.velocity.coordOf(n);
        f.velocity.data()[n] = Vec3f(std::sin(0.3f * c.x()), std::cos(0.2f * c.y() + c.z()), 0.1f * c.z());
        f.density.data()[n] = 0.5f + 0.4f * std::sin(0.1f * (c.x() + 2 * c.y()));
        f.temperature->data()[n] = float(c.x() + c.y());
    }
    f.metadata[meta::kPatchSize] = "8";
    f.metadata[meta::kState] = "tile state";
    return f;
}

std::vector<Frame> tileFrames(const Frame& whole, const TilePlan& p, int f)
{
    std::vector<Frame> out;
    for (const SpaceTile& t : p.tiles) {
        const CoordBBox b = refineDomain(t.held, f);
        Frame tf = mapFields(whole, [&](const auto& field) { return cropped(field, b); });
        out.push_back(tf);
    }
    return out;
}

} // namespace

TEST(FarmTiles, JoinOfTilesThatAgreeIsTheWholeFrame)
{
    const CoordBBox box(Coord(2, 0, 1), Coord(17, 11, 9));
    const TilePlan p = planSpaceTiles(box, Coord(2, 2, 1), 3);
    const int f = 2, ramp = 6;
    const Lattice l{0.05, Vec3d(0.0)};
    const Frame whole = wholeFrame(refineDomain(box, f), l);
    TileJoinStats st;
    const Frame joined = joinTiles(tileFrames(whole, p, f), p, f, ramp, 0.01f, VectorField(), &st);
    ASSERT_EQ(joined.velocity.bbox(), whole.velocity.bbox());
    for (size_t n = 0; n < whole.velocity.size(); ++n) {
        ASSERT_NEAR((joined.velocity.data()[n] - whole.velocity.data()[n]).length(), 0.0, 1e-6);
        ASSERT_NEAR(joined.density.data()[n], whole.density.data()[n], 1e-6);
        ASSERT_NEAR(joined.temperature->data()[n], whole.temperature->data()[n], 1e-5);
    }
    EXPECT_GT(st.seamVoxels, 0u);
    EXPECT_NEAR(st.disagreement, 0.0, 1e-6);
    EXPECT_EQ(joined.metadata.count(meta::kState), 0u); // the resume state is a tile's own
    EXPECT_EQ(joined.metadata.at(meta::kPatchSize), "8");
    EXPECT_EQ(formatTileBorders(tileBorders(p, f)), "x:20;y:12");
}

TEST(FarmTiles, TilesThatDisagreeInCoarseMotionAreFadedLinearlyAcrossTheBorder)
{
    const CoordBBox box(Coord(0), Coord(15, 3, 3));
    const TilePlan p = planSpaceTiles(box, Coord(2, 1, 1), 4);
    const int f = 2, ramp = 8;
    const Lattice l{0.1, Vec3d(0.0)};
    std::vector<Frame> tiles = tileFrames(wholeFrame(refineDomain(box, f), l), p, f);
    tiles[0].velocity.fill(Vec3f(1.0f, 0.0f, 0.0f));
    tiles[1].velocity.fill(Vec3f(0.0f, 1.0f, 0.0f));
    TileJoinStats st;
    const Frame j = joinTiles(tiles, p, f, ramp, 0.01f, VectorField(), &st);
    // The border is at x = 16; tile 0 weighs (20 - (x + 0.5)) / 8 over x = 12..19.
    for (int x = 0; x < 32; ++x) {
        const float w0 = float(std::clamp((20.0 - (x + 0.5)) / 8.0, 0.0, 1.0));
        EXPECT_NEAR(j.velocity(x, 1, 2).x(), w0, 1e-6) << x;
        EXPECT_NEAR(j.velocity(x, 1, 2).y(), 1.0f - w0, 1e-6) << x;
    }
    EXPECT_GT(st.disagreement, 0.3);
    EXPECT_EQ(st.seamVoxels, size_t(8 * 8 * 8)); // the ramp's 8 slices of the 8x8 cross-section
    // With up(u_t): details constant over each coarse cell are all coarse motion, which is blended linearly too (the
    // joined coarse means are the tiles' interpolated: lf_err as the tiles').
    const VectorField up(j.velocity.bbox(), l, Vec3f(0.0f));
    const Frame withUp = joinTiles(tiles, p, f, ramp, 0.01f, up);
    for (int x = 0; x < 32; ++x) {
        const float w0 = float(std::clamp((20.0 - (x + 0.5)) / 8.0, 0.0, 1.0));
        EXPECT_NEAR(withUp.velocity(x, 1, 2).x(), w0, 1e-6) << x;
        EXPECT_NEAR(withUp.velocity(x, 1, 2).y(), 1.0f - w0, 1e-6) << x;
    }
}

TEST(FarmTiles, JoinRefusesTilesThatDoNotCoverTheirWeightsOrDisagreeInFields)
{
    const CoordBBox box(Coord(0), Coord(15, 3, 3));
    const TilePlan p = planSpaceTiles(box, Coord(2, 1, 1), 4);
    const int f = 2;
    const Lattice l{0.1, Vec3d(0.0)};
    const Frame whole = wholeFrame(refineDomain(box, f), l);
    std::vector<Frame> tiles = tileFrames(whole, p, f);
    EXPECT_NO_THROW(joinTiles(tiles, p, f, 8, 0.01f, VectorField()));
    EXPECT_THROW(joinTiles(tiles, p, f, 17, 0.01f, VectorField()), ValueError); // ramp over twice the halo (16)
    EXPECT_THROW(joinTiles(tiles, p, f, 0, 0.01f, VectorField()), ValueError);
    std::vector<Frame> small = tiles;
    small[1] = mapFields(whole, [&](const auto& field) { return cropped(field, refineDomain(p.tiles[1].core, f)); });
    EXPECT_THROW(joinTiles(small, p, f, 8, 0.01f, VectorField()), ValueError); // the ramp reaches past its box
    std::vector<Frame> noTemp = tiles;
    noTemp[1].temperature.reset();
    EXPECT_THROW(joinTiles(noTemp, p, f, 8, 0.01f, VectorField()), ValueError);
    EXPECT_THROW(
        joinTiles(std::vector<Frame>(tiles.begin(), tiles.begin() + 1), p, f, 8, 0.01f, VectorField()), ValueError);
}

TEST(FarmTiles, BordersRoundTripThroughTheirText)
{
    const std::vector<TileBorder> b = parseTileBorders("y:64;x:32,96");
    ASSERT_EQ(b.size(), 3u);
    EXPECT_EQ(formatTileBorders(b), "x:32,96;y:64");
    EXPECT_TRUE(parseTileBorders("").empty());
    for (const char* bad : {"x32", "w:3", "x:a", "x:3,", "x:"}) EXPECT_THROW(parseTileBorders(bad), ValueError) << bad;
}

TEST(FarmTiles, IndependentDetailsKeepTheirEnergyAcrossTheRampAndAgreeingOnesAreExact)
{
    const CoordBBox box(Coord(0), Coord(15, 3, 3));
    const TilePlan p = planSpaceTiles(box, Coord(2, 1, 1), 4);
    const int f = 2, ramp = 16;
    const Lattice l{0.1, Vec3d(0.0)};
    const Frame whole = wholeFrame(refineDomain(box, f), l);
    VectorField up(whole.velocity.bbox(), l);
    for (size_t n = 0; n < up.size(); ++n) up.data()[n] = Vec3f(0.5f, -0.25f, 2.0f);
    // Tiles that agree (the same frame cropped): the join is that frame, whatever the weights.
    TileJoinStats same;
    const Frame agreed = joinTiles(tileFrames(whole, p, f), p, f, ramp, 0.01f, up, &same);
    for (size_t n = 0; n < whole.velocity.size(); ++n)
        ASSERT_NEAR((agreed.velocity.data()[n] - whole.velocity.data()[n]).length(), 0.0, 1e-5);
    EXPECT_NEAR(same.correlation, 1.0, 1e-9);
    EXPECT_NEAR(same.disagreement, 0.0, 1e-5);

    // Independent unit-variance details: every voxel of the ramp keeps the tiles' energy on average over the
    // cross-section (a linear fade would keep lambda^2 + (1 - lambda)^2 of it: 1/2 mid-ramp).
    std::vector<Frame> tiles = tileFrames(whole, p, f);
    std::mt19937 rng(3);
    std::normal_distribution<float> g(0.0f, 1.0f);
    for (Frame& t : tiles)
        for (size_t n = 0; n < t.velocity.size(); ++n)
            t.velocity.data()[n] = up[t.velocity.coordOf(n)] + Vec3f(g(rng), g(rng), g(rng));
    TileJoinStats st;
    const Frame j = joinTiles(tiles, p, f, ramp, 0.01f, up, &st);
    EXPECT_LT(std::abs(st.correlation), 0.05);
    for (int x = 8; x < 24; ++x) { // the ramp: x = 8..23 around the border at 16
        double e = 0.0;
        int count = 0;
        for (int y = 0; y < 8; ++y)
            for (int z = 0; z < 8; ++z, ++count) e += (j.velocity(x, y, z) - up(x, y, z)).lengthSqr() / 3.0;
        EXPECT_NEAR(e / count, 1.0, 0.3) << "x " << x; // 64 voxels x 3 components: sd about 0.1
    }
    EXPECT_GT(st.disagreement, 0.5);
}
