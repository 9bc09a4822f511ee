// Fluidymation (Fluidymation): motion guides (Appendix A, extents), the (i, x, y, theta) field's pyramid
// operations, the time shift, each energy term against its optimum, determinism and bad input.
#include "TestUtil.h"

#include <scenes/Ink2D.h>

#include <turb/ChannelImage.h>
#include <turb/Error.h>
#include <turb/Fluidymation.h>
#include <turb/MotionGuides.h>
#include <turb/Parallel.h>
#include <turb/RotatedNnf.h>
#include <turb/Voting.h>

#include <cmath>
#include <random>

using namespace turb;

namespace {

constexpr double kPi = 3.14159265358979323846;

ChannelImage disc(int W, int H, double cx, double cy, double R)
{
    ChannelImage m(W, H, 1);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) m.at(x, y, 0) = std::hypot(x - cx, y - cy) <= R ? 1.0f : 0.0f;
    return m;
}

/// Uniform dilation about (cx, cy) whose rim (radius R) moves `speed` pixels per frame; 0 outside the disc.
ChannelImage dilation(const ChannelImage& mask, double cx, double cy, double R, double speed)
{
    ChannelImage f(mask.width(), mask.height(), 2);
    for (int y = 0; y < mask.height(); ++y)
        for (int x = 0; x < mask.width(); ++x)
            if (mask.at(x, y, 0) > 0.5f) {
                f.at(x, y, 0) = float((x - cx) * speed / R);
                f.at(x, y, 1) = float((y - cy) * speed / R);
            }
    return f;
}

/// A small moving exemplar or target: a disc growing 1 pixel a frame, a textured RGB.
struct Video
{
    std::vector<ChannelImage> rgb;
    MotionSequence motion;
};

Video growingDisc(int W, int H, int frames, double R0, double speed, unsigned seed, bool giveFlow = true)
{
    Video v;
    v.motion = MotionSequence(W, H);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    ChannelImage noise(W, H, 1);
    for (float& x : noise.data()) x = u(rng);
    noise = gaussianBlur(noise, 1.0);
    const double cx = (W - 1) / 2.0, cy = (H - 1) / 2.0;
    for (int i = 0; i < frames; ++i) {
        const double R = R0 + speed * i;
        const ChannelImage m = disc(W, H, cx, cy, R);
        const ChannelImage f = dilation(m, cx, cy, R, speed);
        v.motion.addFrame(m, giveFlow ? &f : nullptr);
        ChannelImage c(W, H, 3);
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const float in = m.at(x, y, 0), t = noise.at(x, y, 0);
                c.at(x, y, 0) = 0.9f - in * (0.6f + 0.6f * (t - 0.5f));
                c.at(x, y, 1) = 0.9f - in * (0.4f + 0.4f * float(x) / float(W));
                c.at(x, y, 2) = 0.85f - in * 0.2f;
            }
        v.rgb.push_back(c);
    }
    v.motion.finish();
    return v;
}

PatchRef ref(int i, int x, int y, int k = 0)
{
    return PatchRef{std::int16_t(i), std::int16_t(x), std::int16_t(y), std::uint8_t(k)};
}

FluidySettings tinySettings()
{
    FluidySettings s;
    s.boundaryBlur = 6.0; // b scaled to a 40-pixel image
    return s;
}

} // namespace

// ---------------------------------------------------------------------------------------------
// Motion guides (section 3.3, Appendix A)

TEST(MotionGuides, SignedDistanceIsExactAgainstBruteForce)
{
    std::mt19937 rng(3);
    std::bernoulli_distribution b(0.3);
    const int W = 23, H = 17;
    ChannelImage m(W, H, 1);
    for (float& v : m.data()) v = b(rng) ? 1.0f : 0.0f;
    const ChannelImage phi = signedDistance(m);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const bool in = m.at(x, y, 0) > 0.5f;
            double best = 1e9;
            for (int yy = 0; yy < H; ++yy)
                for (int xx = 0; xx < W; ++xx)
                    if ((m.at(xx, yy, 0) > 0.5f) != in) best = std::min(best, std::hypot(xx - x, yy - y));
            EXPECT_NEAR(phi.at(x, y, 0), in ? -(best - 0.5) : best - 0.5, 1e-4) << x << "," << y;
        }
}

TEST(MotionGuides, AppendixAOnAnExpandingDiscGivesTheRadialSpeed)
{
    // A disc growing 1.5 pixels a frame, no flow given: the estimate must point outwards at 1.5 px/frame
    // on the rim and follow the harmonic (linear) field inside.
    const int W = 128, H = 128, F = 10;
    const double c = 63.5, speed = 1.5;
    MotionSequence seq(W, H);
    for (int i = 0; i < F; ++i) seq.addFrame(disc(W, H, c, c, 20.0 + speed * i));
    seq.finish();
    EXPECT_TRUE(seq.flowsEstimated());
    const int i = 5;
    const double R = 20.0 + speed * i;
    const ChannelImage f = seq.flow(i);
    const std::vector<char> rim = boundaryPixels(seq.mask(i));
    double radial = 0, tangential = 0, n = 0, radialHalf = 0, nHalf = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const double dx = x - c, dy = y - c, r = std::hypot(dx, dy);
            const double vr = (f.at(x, y, 0) * dx + f.at(x, y, 1) * dy) / r,
                         vt = (-f.at(x, y, 0) * dy + f.at(x, y, 1) * dx) / r;
            if (rim[size_t(y) * W + size_t(x)]) {
                radial += vr;
                tangential += std::abs(vt);
                n += 1;
            }
            if (std::abs(r - R / 2) < 1.0) {
                radialHalf += vr;
                nHalf += 1;
            }
        }
    EXPECT_NEAR(radial / n, speed, 0.1 * speed);
    EXPECT_LT(tangential / n, 0.1 * speed);
    EXPECT_NEAR(radialHalf / nHalf, speed / 2, 0.15 * speed); // v = speed r / R inside
    // Outside the mask the flow is zero.
    EXPECT_EQ(f.at(2, 2, 0), 0.0f);
    // The raw estimate of one frame (no temporal smoothing) points the same way.
    const ChannelImage raw = maskFlow(seq.mask(4), seq.mask(5), true);
    const int rx = int(c + 20.0 + speed * 4 - 0.5);
    EXPECT_GT(raw.at(rx, int(c), 0), 0.5);
}

TEST(MotionGuides, AppendixAOnTheInkExemplarFollowsItsTrueRimMotion)
{
    // The built-in ink knows its velocity: on the rim, Appendix A's estimate from the masks alone must
    // point the same way (it sees only the normal component, so the lengths agree less well).
    scenes::InkSettings is;
    is.width = 128;
    is.height = 96;
    is.frames = 12;
    const scenes::InkSequence ink = scenes::inkExemplar(is);
    MotionSequence est(is.width, is.height);
    for (const ChannelImage& m : ink.mask) est.addFrame(m);
    est.finish();
    double cosSum = 0.0, n = 0.0, lenEst = 0.0, lenTrue = 0.0;
    for (int i = 2; i < 10; ++i) {
        const ChannelImage f = est.flow(i);
        const std::vector<char> rim = boundaryPixels(ink.mask[size_t(i)]);
        for (size_t p = 0; p < rim.size(); ++p) {
            if (!rim[p]) continue;
            const float* a = f.pixel(p);
            const float* b = ink.flow[size_t(i)].pixel(p);
            const double la = std::hypot(a[0], a[1]), lb = std::hypot(b[0], b[1]);
            if (la < 1e-3 || lb < 0.3) continue;
            cosSum += (a[0] * b[0] + a[1] * b[1]) / (la * lb);
            lenEst += la;
            lenTrue += lb;
            n += 1.0;
        }
    }
    ASSERT_GT(n, 200.0);
    EXPECT_GT(cosSum / n, 0.8); // mean cosine of the angle between estimate and truth
    EXPECT_NEAR(lenEst / lenTrue, 1.0, 0.5);
}

TEST(MotionGuides, ExtentsAccumulateForwardAndBackward)
{
    // A square translating 1 pixel a frame with its flow given: a pixel inside it in every frame has
    // I+ext = i and I-ext = F - 1 - i; a pixel that enters late restarts its accumulation.
    const int W = 40, H = 20, F = 6;
    MotionSequence seq(W, H);
    for (int i = 0; i < F; ++i) {
        ChannelImage m(W, H, 1), f(W, H, 2);
        for (int y = 5; y < 15; ++y)
            for (int x = 5 + i; x < 25 + i; ++x) {
                m.at(x, y, 0) = 1.0f;
                f.at(x, y, 0) = 1.0f;
            }
        seq.addFrame(m, &f);
    }
    seq.finish();
    for (int i = 0; i < F; ++i) {
        const ChannelImage e = seq.extents(i);
        EXPECT_FLOAT_EQ(e.at(15, 10, 0), float(i));
        EXPECT_FLOAT_EQ(e.at(15, 10, 1), float(F - 1 - i));
    }
    // Pixel x = 27 enters at frame 3 (x < 25 + i): I+ext restarts there.
    EXPECT_FLOAT_EQ(seq.extents(3).at(27, 10, 0), 0.0f);
    EXPECT_FLOAT_EQ(seq.extents(5).at(27, 10, 0), 2.0f);
    EXPECT_FLOAT_EQ(seq.extents(1).at(27, 10, 0), 0.0f); // outside the mask
}

TEST(MotionGuides, MixingGivenAndMissingFlowsIsAnError)
{
    MotionSequence seq(8, 8);
    const ChannelImage m(8, 8, 1, 1.0f), f(8, 8, 2);
    seq.addFrame(m, &f);
    EXPECT_THROW(seq.addFrame(m), ValueError);
    EXPECT_THROW(seq.addFrame(ChannelImage(9, 8, 1)), ValueError);
}

// ---------------------------------------------------------------------------------------------
// The (i, x, y, theta) field

TEST(RotatedNnf, UpscalingAtThetaZeroIsPlainUpsampling)
{
    std::mt19937 rng(5);
    RotatedNnf coarse = emptyRotatedNnf(9, 7);
    for (PatchRef& p : coarse.match) p = ref(int(rng() % 5), int(10 + rng() % 20), int(10 + rng() % 20));
    coarse.match[3] = PatchRef{}; // no match stays no match
    const RotatedNnf fine = upscaleNnf(coarse, 18, 13);
    for (int y = 0; y < 13; ++y)
        for (int x = 0; x < 18; ++x) {
            const PatchRef& c = coarse.match[size_t(y / 2) * 9 + size_t(x / 2)];
            const PatchRef& f = fine.match[size_t(y) * 18 + size_t(x)];
            if (!c.valid()) {
                EXPECT_FALSE(f.valid());
                continue;
            }
            EXPECT_EQ(f.frame, c.frame);
            EXPECT_EQ(f.x, 2 * c.x + x % 2);
            EXPECT_EQ(f.y, 2 * c.y + y % 2);
            EXPECT_EQ(f.rotation, 0);
        }
    // At theta = pi the 2x2 block reads the source block mirrored: x_up = 2 x' + 1 - (x mod 2).
    coarse.match.assign(coarse.match.size(), ref(1, 12, 15, kRotations / 2));
    const RotatedNnf flipped = upscaleNnf(coarse, 18, 14);
    EXPECT_EQ(flipped.match[0].x, 25);
    EXPECT_EQ(flipped.match[1].x, 24);
    EXPECT_EQ(flipped.match[18].y, 30);
}

TEST(RotatedNnf, DownscalingInvertsUpscalingForQuarterTurns)
{
    std::mt19937 rng(9);
    RotatedNnf coarse = emptyRotatedNnf(8, 6);
    for (PatchRef& p : coarse.match)
        p = ref(int(rng() % 4), int(20 + rng() % 30), int(20 + rng() % 30), int(rng() % 4) * (kRotations / 4));
    const RotatedNnf back = downscaleNnf(upscaleNnf(upscaleNnf(coarse, 16, 12), 32, 24), 2, 8, 6);
    for (size_t q = 0; q < coarse.match.size(); ++q) EXPECT_EQ(back.match[q], coarse.match[q]) << q;
    // The mode wins: three of four fine pixels agree.
    RotatedNnf fine = emptyRotatedNnf(2, 2);
    fine.match = {ref(0, 10, 10), ref(0, 11, 10), ref(2, 40, 40), ref(0, 11, 11)};
    const RotatedNnf m = downscaleNnf(fine, 1, 1, 1);
    EXPECT_EQ(m.match[0], ref(0, 5, 5));
}

TEST(RotatedNnf, VotingRotatedPatchesOfAnIsotropicImageKeepsIt)
{
    // A radial ramp about the source centre: every rotation about it reads the same values.
    ChannelImage src(31, 31, 1);
    for (int y = 0; y < 31; ++y)
        for (int x = 0; x < 31; ++x) src.at(x, y, 0) = float(std::hypot(x - 15, y - 15));
    RotatedNnf nnf = emptyRotatedNnf(11, 11);
    for (int y = 0; y < 11; ++y)
        for (int x = 0; x < 11; ++x) nnf.match[size_t(y) * 11 + size_t(x)] = ref(0, 10 + x, 10 + y);
    ChannelImage a(11, 11, 1), b(11, 11, 1);
    voteRotated({&src}, nnf, 2, 0, 0, 1, a);
    EXPECT_NEAR(a.at(5, 5, 0), 0.0f, 1e-5); // centre on the source centre, theta 0: exact
    for (PatchRef& p : nnf.match) p.rotation = 16;
    nnf.match[5 * 11 + 5] = ref(0, 15, 15, 16);
    voteRotated({&src}, nnf, 2, 0, 0, 1, b);
    EXPECT_GT(b.at(0, 0, 0), 0.0f);
}

// ---------------------------------------------------------------------------------------------
// Energy pieces

TEST(Fluidymation, PyramidLevelCountIsFloorLog2OfDminOverN)
{
    EXPECT_EQ(fluidyLevels(400, 120, 900, 900, 5), 4); // the genie: 120 / 5 = 24
    EXPECT_EQ(fluidyLevels(225, 94, 700, 300, 5), 4);  // the jump: 94 / 5 = 18.8
    EXPECT_EQ(fluidyLevels(200, 200, 500, 600, 5), 5); // the sunflower: 200 / 5 = 40
    EXPECT_EQ(fluidyLevels(40, 40, 40, 40, 5), 3);
    EXPECT_EQ(fluidyLevels(9, 9, 9, 9, 5), 1); // never fewer than one level
    // The coarsest level's short side lies in [2n, 4n).
    const int L = fluidyLevels(400, 120, 900, 900, 5);
    EXPECT_GE(120 >> (L - 1), 10);
    EXPECT_LT(120 >> (L - 1), 20);
}

TEST(Fluidymation, DirTermIsZeroForParallelAndAntiparallelFlowsAndGrowsTowardPerpendicular)
{
    const float clamp = 10.0f;
    for (double a : {0.0, 0.7, -2.0}) {
        EXPECT_NEAR(dirCost(a, 0.4, a + 0.4, clamp), 0.0f, 1e-6);
        EXPECT_NEAR(dirCost(a, 0.4 + kPi, a + 0.4, clamp), 0.0f, 1e-5); // antiparallel
        EXPECT_FLOAT_EQ(dirCost(a, 0.4 + kPi / 2, a + 0.4, clamp), clamp);
        float previous = -1.0f;
        for (int k = 0; k <= 16; ++k) {
            const float d = dirCost(a, 0.4 + k * kPi / 32, a + 0.4, clamp);
            EXPECT_GE(d, previous);
            previous = d;
        }
    }
    EXPECT_NEAR(dirCost(0.0, kPi / 4, 0.0, clamp), 1.0f, 1e-5); // |tan 45 degrees|
}

TEST(Fluidymation, TemporalModulationRelaxesWhereDistancesDisagree)
{
    // Our reading of section 3.4: full temporal weight where the source and target distances agree,
    // none where they differ by m_u or more (the paper prints the smoothstep the other way round).
    EXPECT_EQ(temporalModulation(0.0, 2.0, 20.0), 1.0);
    EXPECT_EQ(temporalModulation(2.0, 2.0, 20.0), 1.0);
    EXPECT_EQ(temporalModulation(20.0, 2.0, 20.0), 0.0);
    EXPECT_EQ(temporalModulation(50.0, 2.0, 20.0), 0.0);
    EXPECT_NEAR(temporalModulation(11.0, 2.0, 20.0), 0.5, 1e-12);
    double previous = 2.0;
    for (double v = 0.0; v <= 25.0; v += 0.5) {
        const double m = temporalModulation(v, 2.0, 20.0);
        EXPECT_LE(m, previous);
        previous = m;
    }
}

TEST(Fluidymation, TimeShiftMatchesKnownSpeeds)
{
    // One source pixel over 20 frames moving 2 px/frame: S+ext(k) = 2k, S-ext(k) = 2 (19 - k).
    const int F = 20;
    std::vector<float> e(2 * F);
    for (int k = 0; k < F; ++k) {
        e[size_t(2 * k)] = 2.0f * k;
        e[size_t(2 * k + 1)] = 2.0f * (F - 1 - k);
    }
    EXPECT_EQ(bestTimeShift(e.data(), e.data() + 1, 2, F, 4, 6.0, false), 3);   // target 3x faster
    EXPECT_EQ(bestTimeShift(e.data(), e.data() + 1, 2, F, 4, 1.0, false), 0);   // ties keep the smaller shift
    EXPECT_EQ(bestTimeShift(e.data(), e.data() + 1, 2, F, 4, 0.0, false), 0);   // a still target stays
    EXPECT_EQ(bestTimeShift(e.data(), e.data() + 1, 2, F, 10, 8.0, true), -4);  // opposite flows go back in time
    EXPECT_EQ(bestTimeShift(e.data(), e.data() + 1, 2, F, 17, 40.0, false), 2); // the end of the exemplar clamps
    // A slower source (0.5 px/frame) needs a longer shift for the same target motion.
    for (int k = 0; k < F; ++k) e[size_t(2 * k)] = 0.5f * k;
    EXPECT_EQ(bestTimeShift(e.data(), e.data() + 1, 2, F, 2, 2.0, false), 4);
}

TEST(Fluidymation, EachTermIsSmallestAtItsOwnOptimum)
{
    // The target is the exemplar itself: at q = (x, y) the patch p = (j, x, y, 0) has identical shape,
    // flow and extents, so D^bound = D^dir = D^ext = 0 there and each grows away from it.
    Video ex = growingDisc(40, 40, 11, 8.0, 1.0, 1), tg = growingDisc(40, 40, 11, 8.0, 1.0, 1);
    FluidySettings s = tinySettings();
    Fluidymator f(s, ex.rgb, ex.motion, tg.motion);
    f.next();
    const FluidyFrame second = f.next();
    const int j = 1;
    // A rim pixel to the right of the centre (moving along +x), and a deep one.
    const int x = 28, y = 20;
    const FluidyTerms here = f.terms(ref(j, x, y), x, y);
    EXPECT_NEAR(here.bound, 0.0, 1e-9);
    EXPECT_NEAR(here.ext, 0.0, 1e-9);
    EXPECT_NEAR(here.dir, 0.0, 1e-3);
    EXPECT_FALSE(here.swapped);
    // D^bound grows with the offset across the boundary.
    double previous = -1.0;
    for (int d = 0; d <= 4; ++d) {
        const double b = f.terms(ref(j, x - d, y), x, y).bound;
        EXPECT_GT(b, previous);
        previous = b;
    }
    // D^dir grows as the patch turns away from alignment (up to 45 degrees; nearer 90 the patch's
    // pixels, whose radial directions differ by tens of degrees, straddle the clamp), is largest near
    // perpendicular, and is small again at pi.
    previous = -1.0;
    for (int k = 0; k <= kRotations / 8; k += 2) {
        const double d = f.terms(ref(j, x, y, k), x, y).dir;
        EXPECT_GT(d, previous);
        previous = d;
    }
    const double perpendicular = f.terms(ref(j, x, y, kRotations / 4), x, y).dir;
    EXPECT_GT(perpendicular, 5.0 * f.terms(ref(j, x, y, kRotations / 16), x, y).dir);
    const FluidyTerms flipped = f.terms(ref(j, x, y, kRotations / 2), x, y);
    EXPECT_LT(flipped.dir, 0.05 * perpendicular);
    EXPECT_TRUE(flipped.swapped); // opposite flows swap T+ext and T-ext
    // D^ext grows with the distance in time from the target's own frame (a pixel inside every frame).
    previous = -1.0;
    for (int i = j; i < 11; i += 3) {
        const double e = f.terms(ref(i, 22, 21), 22, 21).ext;
        EXPECT_GT(e, previous);
        previous = e;
    }
    // D^temp: the previous frame's patch shifted in time beats a patch from elsewhere.
    const FluidyTerms own = f.terms(second.nnf.match[size_t(y) * 40 + size_t(x)], x, y);
    const FluidyTerms far = f.terms(ref(10, 6, 6), x, y);
    EXPECT_LT(own.temp, far.temp);
    EXPECT_LT(own.tex, far.tex);
    // Omega: a patch no target cuboid covers costs nothing; the used ones cost something, and the mean
    // over the matched patches is of the order of w^uni (uniform usage costs w^uni).
    double unused = 1e9;
    for (int i = 0; i <= 6; ++i)
        for (int side : {-1, 1}) // just outside the exemplar's rim in each frame: a patch centre
            unused = std::min(unused, f.terms(ref(i, int(std::lround(19.5 + side * (8.0 + i + 1.0))), 20), x, y).uni);
    EXPECT_EQ(unused, 0.0);
    EXPECT_GT(own.uni, 0.0);
    EXPECT_GT(second.stats.energy.uni, 0.2 * s.wUni);
    EXPECT_LT(second.stats.energy.uni, 5.0 * s.wUni);
}

TEST(Fluidymation, WeightsSetToZeroRemoveTheirTerms)
{
    Video ex = growingDisc(40, 40, 11, 8.0, 1.0, 1), tg = growingDisc(40, 40, 11, 7.0, 1.2, 2);
    FluidySettings s = tinySettings();
    s.wBound = s.wExt = s.wDir = s.wTemp = s.wUni = 0.0f;
    Fluidymator f(s, ex.rgb, ex.motion, tg.motion);
    f.next();
    const FluidyFrame out = f.next();
    const FluidyTerms& e = out.stats.energy;
    EXPECT_EQ(e.bound + e.ext + e.dir + e.temp + e.uni, 0.0);
    EXPECT_GT(e.tex, 0.0);
}

TEST(Fluidymation, DeterministicAtOneAndTwoThreadsAndFollowsTheFlow)
{
    Video ex = growingDisc(48, 40, 11, 8.0, 1.0, 1), tg = growingDisc(44, 44, 4, 9.0, 1.5, 2);
    FluidySettings s = tinySettings();
    std::vector<FluidyFrame> runs[2];
    for (int t = 0; t < 2; ++t)
        withThreads(t + 1, [&] {
            Fluidymator f(s, ex.rgb, ex.motion, tg.motion);
            for (int j = 0; j < 4; ++j) runs[t].push_back(f.next());
        });
    for (int j = 0; j < 4; ++j) {
        ASSERT_EQ(runs[0][size_t(j)].image.size(), runs[1][size_t(j)].image.size());
        for (size_t p = 0; p < runs[0][size_t(j)].image.size(); ++p)
            ASSERT_EQ(runs[0][size_t(j)].image.pixels()[p], runs[1][size_t(j)].image.pixels()[p]);
        for (size_t p = 0; p < runs[0][size_t(j)].nnf.match.size(); ++p)
            ASSERT_EQ(runs[0][size_t(j)].nnf.match[p], runs[1][size_t(j)].nnf.match[p]);
    }
    // Both discs move radially: the rotated source flow lines up with the target's (random: 0.64).
    const FluidyStats& st = runs[0][3].stats;
    EXPECT_GT(st.movingPixels, 100);
    ASSERT_TRUE(st.meanAbsSin.has_value());
    EXPECT_LT(*st.meanAbsSin, 0.3);
    EXPECT_GT(st.reusedFraction, 0.0);            // the previous frame's field was reused
    EXPECT_TRUE(st.stationaryChange.has_value()); // measured from frame 2 on
    // The output alpha covers the target mask.
    const ChannelImage m = tg.motion.mask(3);
    double inside = 0, n = 0;
    for (size_t p = 0; p < m.pixelCount(); ++p)
        if (m.pixel(p)[0] > 0.5f) {
            inside += runs[0][3].image.pixels()[p][3];
            n += 1;
        }
    EXPECT_GT(inside / n, 0.7);
}

TEST(Fluidymation, BadInputsAreValueErrors)
{
    Video ex = growingDisc(40, 40, 11, 8.0, 1.0, 1), tg = growingDisc(40, 40, 3, 8.0, 1.0, 2);
    FluidySettings s = tinySettings();
    // An exemplar shorter than 2r + 1 frames.
    Video shortEx = growingDisc(40, 40, 10, 8.0, 1.0, 1);
    EXPECT_THROW(Fluidymator(s, shortEx.rgb, shortEx.motion, tg.motion), ValueError);
    s.cuboidFrames = 4;
    EXPECT_NO_THROW(Fluidymator(s, shortEx.rgb, shortEx.motion, tg.motion));
    s.cuboidFrames = 5;
    // Mask and frame counts that differ.
    std::vector<ChannelImage> fewer(ex.rgb.begin(), ex.rgb.end() - 1);
    EXPECT_THROW(Fluidymator(s, fewer, ex.motion, tg.motion), ValueError);
    // A target empty in every frame.
    MotionSequence empty(40, 40);
    for (int i = 0; i < 3; ++i) empty.addFrame(ChannelImage(40, 40, 1));
    empty.finish();
    EXPECT_THROW(Fluidymator(s, ex.rgb, ex.motion, empty), ValueError);
    // Settings out of range.
    FluidySettings bad = s;
    bad.wDir = -1.0f;
    EXPECT_THROW(validate(bad), ValueError);
    bad = s;
    bad.patchSize = 4;
    EXPECT_THROW(validate(bad), ValueError);
    bad = s;
    bad.mUpper = bad.mLower;
    EXPECT_THROW(validate(bad), ValueError);
    // Past the last frame.
    Fluidymator f(s, ex.rgb, ex.motion, tg.motion);
    for (int j = 0; j < 3; ++j) f.next();
    EXPECT_THROW(f.next(), ValueError);
}
