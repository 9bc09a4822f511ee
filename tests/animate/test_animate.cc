// animate (Okabe et al. 2009): decomposition, flow design, residual transfer, synthesis and
// histogram matching against analytic answers.
#include "TestUtil.h"

#include <turb/Animate.h>
#include <turb/AnimateQuality.h>
#include <turb/CloneBrush.h>
#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/SteerablePyramid.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>

using namespace turb;

namespace {

/// Band-limited waves translated by (sx, sy) pixels per frame: frame t is exactly the texture moved by
/// t (sx, sy), at any sub-pixel shift. Three channels mix the waves differently.
struct Waves
{
    struct Wave
    {
        double kx, ky, phase, amp[3];
    };
    std::vector<Wave> waves;
    explicit Waves(unsigned seed, int count = 40, double minLambda = 5.0, double maxLambda = 24.0)
    {
        std::mt19937 rng(seed);
        std::uniform_real_distribution<double> u(0.0, 1.0);
        for (int i = 0; i < count; ++i) {
            const double lambda = minLambda + (maxLambda - minLambda) * u(rng), a = 2.0 * M_PI * u(rng),
                         k = 2.0 * M_PI / lambda;
            waves.push_back({k * std::cos(a), k * std::sin(a), 2.0 * M_PI * u(rng),
                {0.05 + 0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng)}});
        }
    }
    ChannelImage frame(int W, int H, double dx, double dy) const
    {
        ChannelImage img(W, H, 3);
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                float* p = img.pixel(x, y);
                p[0] = 0.5f;
                p[1] = 0.4f;
                p[2] = 0.3f;
                for (const Wave& w : waves) {
                    const double v = std::cos(w.kx * (x - dx) + w.ky * (y - dy) + w.phase);
                    for (int c = 0; c < 3; ++c) p[c] += float(w.amp[c] * v);
                }
            }
        return img;
    }
};

std::vector<ChannelImage> translatedNoise(int W, int H, int N, double sx, double sy, unsigned seed = 7)
{
    const Waves waves(seed);
    std::vector<ChannelImage> frames;
    for (int t = 0; t < N; ++t) frames.push_back(waves.frame(W, H, sx * t, sy * t));
    return frames;
}

double rms(const ChannelImage& a)
{
    double s = 0.0;
    for (float v : a.data()) s += double(v) * v;
    return std::sqrt(s / double(a.data().size()));
}

FlowStroke stroke(StrokeKind kind, std::vector<StrokePoint> pts, double speed = 0.0)
{
    FlowStroke s;
    s.kind = kind;
    s.points = std::move(pts);
    s.speed = speed;
    return s;
}

} // namespace

// ---------------------------------------------------------------------------------------------
// Decomposition (section 4)

TEST(AnimateAnalysis, Eq4ReconstructsTheExampleExactly)
{
    // Translating waves plus blobs that appear and vanish: residuals that no flow explains.
    std::vector<ChannelImage> frames = translatedNoise(64, 48, 12, 1.25, 0.5);
    std::mt19937 rng(3);
    for (ChannelImage& f : frames)
        for (int b = 0; b < 3; ++b) {
            const int cx = int(rng() % 64), cy = int(rng() % 48);
            for (int y = 0; y < 48; ++y)
                for (int x = 0; x < 64; ++x)
                    f.at(x, y, b) += 0.3f * float(std::exp(-((x - cx) * (x - cx) + (y - cy) * (y - cy)) / 8.0));
        }
    const std::vector<ChannelImage> original = frames;
    const ExampleDecomposition ex = decomposeExample(frames, AnalysisSettings{});
    ASSERT_EQ(ex.frames(), 12);
    const std::vector<ChannelImage> back = reconstructExample(ex);
    ASSERT_EQ(back.size(), original.size());
    double err = 0.0, norm = 0.0;
    for (size_t i = 0; i < back.size(); ++i)
        for (size_t q = 0; q < back[i].data().size(); ++q) {
            err += std::pow(double(back[i].data()[q]) - original[i].data()[q], 2.0);
            norm += std::pow(double(original[i].data()[q]) - ex.average.data()[q], 2.0);
        }
    EXPECT_LE(std::sqrt(err / norm), 1e-4) << "eq. 4 relative to the differences D";
    std::cout << "[ measured ] eq. 4 relative error " << std::sqrt(err / norm) << std::endl;

    // Eq. 4 literally (W^i(D_0) + sum W^{i-k-1}(R_k)) for i = 5 equals the incremental form.
    const int i = 5;
    ChannelImage lit = ex.first;
    for (int n = 0; n < i; ++n) lit = warpByFlow(lit, ex.flow);
    for (int k = 0; k < i; ++k) {
        ChannelImage r = ex.residuals[size_t(k)];
        for (int n = 0; n < i - k - 1; ++n) r = warpByFlow(r, ex.flow);
        for (size_t q = 0; q < lit.data().size(); ++q) lit.data()[q] += r.data()[q];
    }
    double e5 = 0.0;
    for (size_t q = 0; q < lit.data().size(); ++q)
        e5 = std::max(e5, std::abs(double(lit.data()[q]) + ex.average.data()[q] - original[size_t(i)].data()[q]));
    EXPECT_LT(e5, 1e-5);
}

TEST(AnimateAnalysis, TranslatedNoiseGivesItsShiftAndSmallResiduals)
{
    const double sx = 1.5, sy = -0.5;
    const ExampleDecomposition ex = decomposeExample(translatedNoise(96, 80, 24, sx, sy), AnalysisSettings{});
    EXPECT_GE(ex.stats.pairsUsed, 20);
    EXPECT_GE(ex.stats.tracksPerPair, 30.0);
    std::vector<double> err;
    for (int y = 10; y < 70; ++y)
        for (int x = 10; x < 86; ++x) err.push_back(std::hypot(ex.flow.at(x, y, 0) - sx, ex.flow.at(x, y, 1) - sy));
    std::sort(err.begin(), err.end());
    EXPECT_LT(err[err.size() / 2], 0.05) << "median flow error";
    EXPECT_LT(err[size_t(0.95 * double(err.size()))], 0.1) << "95th percentile flow error";
    // The residuals are what the flow does not explain: far below the frame differences.
    EXPECT_LT(ex.stats.rmsResidual, 0.2 * ex.stats.rmsDifference)
        << ex.stats.rmsResidual << " vs " << ex.stats.rmsDifference;
    std::cout << "[ measured ] flow error median " << err[err.size() / 2] << " px, 95th percentile "
              << err[size_t(0.95 * double(err.size()))] << " px; rms residual / rms difference "
              << ex.stats.rmsResidual / ex.stats.rmsDifference << std::endl;
}

TEST(AnimateAnalysis, TracksOfTranslatedNoiseCarryItsShift)
{
    // The tracks behind the mean flow, one by one: every pair tracked, each displacement the shift.
    const double sx = 1.5, sy = -0.5;
    const std::vector<ChannelImage> frames = translatedNoise(96, 80, 12, sx, sy);
    const std::vector<FlowTrack> tracks = trackFlow(frames, AnalysisSettings{});
    // estimateMeanFlow hands out the same tracks from its one tracking pass.
    std::vector<FlowTrack> fromMeanFlow;
    estimateMeanFlow(frames, AnalysisSettings{}, nullptr, nullptr, &fromMeanFlow);
    ASSERT_EQ(fromMeanFlow.size(), tracks.size());
    for (size_t i = 0; i < tracks.size(); ++i) {
        EXPECT_EQ(fromMeanFlow[i].pair, tracks[i].pair);
        EXPECT_EQ(fromMeanFlow[i].x, tracks[i].x);
        EXPECT_EQ(fromMeanFlow[i].dx, tracks[i].dx);
    }
    std::vector<int> perPair(11, 0);
    std::vector<double> err;
    for (const FlowTrack& t : tracks) {
        ASSERT_GE(t.pair, 0);
        ASSERT_LT(t.pair, 11);
        ++perPair[size_t(t.pair)];
        err.push_back(std::hypot(t.dx - sx, t.dy - sy));
    }
    for (int n : perPair) EXPECT_GE(n, 30);
    std::sort(err.begin(), err.end());
    // Single tracks scatter more than their average over pairs (the mean flow's 0.01 px).
    EXPECT_LT(err[err.size() / 2], 0.2) << "median track error";
    // Against a design equal to the shift: angle 0, ratio 1; against one twice as fast and turned by 90 degrees:
    // ratio 0.5, angle 90.
    ChannelImage same(96, 80, 2), other(96, 80, 2);
    for (size_t i = 0; i < same.pixelCount(); ++i) {
        same.pixel(i)[0] = float(sx);
        same.pixel(i)[1] = float(sy);
        other.pixel(i)[0] = float(2 * sy);
        other.pixel(i)[1] = float(-2 * sx);
    }
    const FlowAgreement a = compareTracks(tracks, same), b = compareTracks(tracks, other);
    EXPECT_LT(a.medianAngleDeg, 5.0);
    EXPECT_NEAR(a.medianSpeedRatio, 1.0, 0.03);
    EXPECT_NEAR(b.medianAngleDeg, 90.0, 5.0);
    EXPECT_NEAR(b.medianSpeedRatio, 0.5, 0.02);
    EXPECT_GT(a.pixels, 0.7) << "tracks off the 8-pixel border";
    // The matte and the minimum design speed choose the tracks compared.
    ChannelImage left(96, 80, 1);
    for (int y = 0; y < 80; ++y)
        for (int x = 0; x < 48; ++x) left.at(x, y, 0) = 1.0f;
    const FlowAgreement c = compareTracks(tracks, same, &left);
    EXPECT_GT(c.pixels, 0.2);
    EXPECT_LT(c.pixels, 0.6 * a.pixels);
    const FlowAgreement none = compareTracks(tracks, same, nullptr, 10.0);
    EXPECT_EQ(none.pixels, 0.0);
    EXPECT_TRUE(std::isnan(none.medianAngleDeg) && std::isnan(none.medianSpeedRatio)) << "no figure, not a perfect one";
    EXPECT_THROW(compareTracks(tracks, ChannelImage(96, 80, 3)), ValueError);
}

TEST(AnimateAnalysis, RefusesShortOrMixedExamples)
{
    std::vector<ChannelImage> one{ChannelImage(16, 16, 3)};
    EXPECT_THROW(decomposeExample(one, AnalysisSettings{}), ValueError);
    std::vector<ChannelImage> mixed{ChannelImage(16, 16, 3), ChannelImage(16, 17, 3)};
    EXPECT_THROW(decomposeExample(mixed, AnalysisSettings{}), ValueError);
}

// ---------------------------------------------------------------------------------------------
// Flow design (3.1, 5.1)

TEST(AnimateDesign, TwoStrokesInterpolateToTheAnalyticField)
{
    // Two horizontal speed strokes, speed 1 at y = 10 and 3 at y = 50: phi = r with its linear part
    // reproduces the linear field s = 1 + (y - 10) / 20 exactly, everywhere.
    // Two vertical orientation strokes, down at x = 10 and up at x = 70: the raw y component is
    // 1 - (x - 10) / 30, so the normalised orientation is (0, +1) left of x = 40 and (0, -1) right of it.
    const int W = 80, H = 60;
    std::vector<FlowStroke> s;
    s.push_back(stroke(StrokeKind::Orientation, {{10, 5}, {10, 55}}));
    s.push_back(stroke(StrokeKind::Orientation, {{70, 55}, {70, 5}}));
    s.push_back(stroke(StrokeKind::Speed, {{5, 10}, {75, 10}}, 1.0));
    s.push_back(stroke(StrokeKind::Speed, {{5, 50}, {75, 50}}, 3.0));
    const RoughFlow r = interpolateStrokes(s, W, H, StrokeSettings{});
    double maxErr = 0.0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) maxErr = std::max(maxErr, std::abs(r.speed.at(x, y, 0) - (1.0 + (y - 10) / 20.0)));
    EXPECT_LT(maxErr, 1e-4);
    for (int y = 0; y < H; y += 7)
        for (int x : {0, 12, 30, 38, 42, 55, 79}) {
            EXPECT_NEAR(r.orientation.at(x, y, 0), 0.0, 1e-4) << x << "," << y;
            EXPECT_NEAR(r.orientation.at(x, y, 1), x < 40 ? 1.0 : -1.0, 1e-4) << x << "," << y;
        }
}

TEST(AnimateDesign, LocalStrokesAreLayersWithTheirMatte)
{
    const int W = 80, H = 60;
    std::vector<FlowStroke> s;
    s.push_back(stroke(StrokeKind::Orientation, {{5, 30}, {75, 30}}));
    s.push_back(stroke(StrokeKind::Speed, {{5, 30}, {75, 30}}, 2.0));
    FlowStroke local = stroke(StrokeKind::Speed, {{40, 5}, {40, 55}}, 6.0);
    local.local = true;
    local.size = 10.0;
    local.alpha = 0.5;
    s.push_back(local);
    FlowStroke turn = stroke(StrokeKind::Orientation, {{20, 50}, {20, 10}}); // up, full strength
    turn.local = true;
    turn.size = 8.0;
    s.push_back(turn);
    const RoughFlow r = interpolateStrokes(s, W, H, StrokeSettings{});
    EXPECT_NEAR(r.speed.at(40, 30, 0), 0.5 * 6.0 + 0.5 * 2.0, 1e-4) << "on the stroke: alpha blend";
    EXPECT_NEAR(r.speed.at(43, 30, 0), 4.0, 1e-4) << "inside size/2";
    EXPECT_NEAR(r.speed.at(51, 30, 0), 2.0, 1e-4) << "beyond the brush size";
    EXPECT_GT(r.speed.at(47, 30, 0), 2.0);
    EXPECT_LT(r.speed.at(47, 30, 0), 4.0);
    EXPECT_NEAR(r.orientation.at(20, 30, 1), -1.0, 1e-4);
    EXPECT_NEAR(r.orientation.at(60, 30, 0), 1.0, 1e-4);
}

TEST(AnimateDesign, StrokeErrorsNameTheStroke)
{
    std::vector<FlowStroke> s{stroke(StrokeKind::Orientation, {{5, 5}, {95, 5}})};
    try {
        validateStrokes(s, 64, 64);
        FAIL() << "a stroke outside the image must be refused";
    } catch (const ValueError& e) {
        EXPECT_NE(std::string(e.what()).find("stroke 0"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("outside"), std::string::npos) << e.what();
    }
    EXPECT_THROW(validateStrokes({stroke(StrokeKind::Speed, {{5, 5}, {9, 5}}, 1.0)}, 64, 64), ValueError)
        << "no orientation stroke";
    EXPECT_THROW(validateStrokes({stroke(StrokeKind::Orientation, {{5, 5}, {5, 5}})}, 64, 64), ValueError)
        << "no direction";
}

TEST(AnimateDesign, RefinementFollowsTheGradientAndFallsBackWhereItVanishes)
{
    const int W = 64, H = 48;
    ChannelImage ramp(W, H, 3);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            for (int c = 0; c < 3; ++c) ramp.at(x, y, c) = 0.01f * float(x); // gradient along +x
    RoughFlow rough;
    rough.orientation = ChannelImage(W, H, 2);
    rough.speed = ChannelImage(W, H, 1, 2.0f);
    const double n = std::hypot(-1.0, 0.5);
    for (size_t i = 0; i < rough.orientation.pixelCount(); ++i) {
        rough.orientation.pixel(i)[0] = float(-1.0 / n);
        rough.orientation.pixel(i)[1] = float(0.5 / n);
    }
    RefineSettings rs;
    rs.gradientFloor = 0.0; // follow the gradient wherever it exists
    rs.wf = 3.0;            // local: the borders (no gradient there) stay out of the centre
    const RefinedFlow par = refineFlow(ramp, rough, rs);
    // Parallel to G = (+x), signed to agree with Phi_o = (-1, 0.5): Psi_o = (-1, 0); Psi_s = (Psi_o . Phi_o) Phi_s.
    EXPECT_NEAR(par.orientation.at(30, 20, 0), -1.0, 1e-3);
    EXPECT_NEAR(par.orientation.at(30, 20, 1), 0.0, 1e-3);
    EXPECT_NEAR(par.speed.at(30, 20, 0), 2.0 / n, 1e-3);
    rs.orient = GradientOrientation::Perpendicular;
    const RefinedFlow perp = refineFlow(ramp, rough, rs);
    EXPECT_NEAR(perp.orientation.at(30, 20, 0), 0.0, 1e-3);
    EXPECT_NEAR(perp.orientation.at(30, 20, 1), 1.0, 1e-3);
    EXPECT_NEAR(perp.speed.at(30, 20, 0), 2.0 * 0.5 / n, 1e-3);
    // A flat image has no gradient: the design is kept as it is.
    const RefinedFlow flat = refineFlow(ChannelImage(W, H, 3, 0.5f), rough, RefineSettings{});
    EXPECT_NEAR(flat.flow.at(30, 20, 0), -2.0 / n, 1e-4);
    EXPECT_NEAR(flat.flow.at(30, 20, 1), 1.0 / n, 1e-4);
}

// ---------------------------------------------------------------------------------------------
// Residual transfer (5.2)

TEST(AnimateTransfer, SameFlowsTransferTheResidualsInPlace)
{
    // A flow that differs at every position: each target patch's best window is itself, so R' = R.
    const int W = 72, H = 56;
    ChannelImage flow(W, H, 2);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            flow.at(x, y, 0) = float(0.05 * x + std::sin(0.3 * y));
            flow.at(x, y, 1) = float(0.07 * y + std::cos(0.2 * x));
        }
    ResidualTransferSettings ts;
    ts.downsample = 1;
    ts.pcaComponents = 64;
    ts.variety = 0.0; // the paper's nearest match (variety would take near windows as equally good)
    const TransferMap map = matchResiduals(flow, flow, ts);
    EXPECT_NEAR(map.stats.meanCost, 0.0, 1e-9);
    EXPECT_DOUBLE_EQ(map.stats.covered, 1.0);
    ChannelImage r(W, H, 3);
    std::mt19937 rng(1);
    for (float& v : r.data()) v = float(rng() % 1000) / 1000.0f;
    const ChannelImage rp = map.apply(r);
    double maxErr = 0.0;
    for (size_t q = 0; q < r.data().size(); ++q)
        maxErr = std::max(maxErr, double(std::abs(rp.data()[q] - r.data()[q])));
    EXPECT_LT(maxErr, 1e-5);
}

TEST(AnimateTransfer, AUniformDesignDoesNotTileOneWindow)
{
    // A uniform design against an example that moves uniformly almost everywhere: every window is an equally good
    // match. The nearest match alone gives few distinct windows, repeated with the patch stride; variety gives
    // neighbouring patches different windows, each still within variety x speed of the best match.
    const int W = 96, H = 80;
    ChannelImage ex(120, 100, 2), tg(W, H, 2);
    for (int y = 0; y < 100; ++y)
        for (int x = 0; x < 120; ++x) {
            ex.at(x, y, 0) = 0.0f;
            ex.at(x, y, 1) = float(-2.0 - 0.2 * std::exp(-(std::pow(x - 60.0, 2) + std::pow(y - 50.0, 2)) / 50.0));
        }
    for (size_t i = 0; i < tg.pixelCount(); ++i) tg.pixel(i)[1] = -2.0f;
    ResidualTransferSettings nearestOnly;
    nearestOnly.variety = 0.0;
    const TransferMap a = matchResiduals(ex, tg, nearestOnly), b = matchResiduals(ex, tg, ResidualTransferSettings{});
    EXPECT_EQ(a.stats.patches, b.stats.patches);
    EXPECT_GT(b.stats.distinct, a.stats.distinct);
    EXPECT_GE(b.stats.distinct, b.stats.patches / 2) << "of " << b.stats.patches;
    EXPECT_LE(std::sqrt(b.stats.maxCost), 0.1 * 2.0 + 1e-6) << "every pick within variety x speed";
    // Neighbouring target pixels one stride apart take residuals from example pixels that are not one stride apart
    // in the same window: sample R = a ramp, so R'(x + 8) - R'(x) = 8 where the same window covers both.
    ChannelImage ramp(120, 100, 1);
    for (int y = 0; y < 100; ++y)
        for (int x = 0; x < 120; ++x) ramp.at(x, y, 0) = float(x + 1000 * y);
    const ChannelImage ra = a.apply(ramp), rb = b.apply(ramp);
    const auto periodic = [&](const ChannelImage& r) { // fraction of pixels whose value repeats 16 px to the right
        int same = 0, n = 0;
        for (int y = 8; y < H - 8; ++y)
            for (int x = 8; x + 16 < W - 8; ++x, ++n) same += std::abs(r.at(x + 16, y, 0) - r.at(x, y, 0)) < 0.5f;
        return double(same) / n;
    };
    EXPECT_LT(periodic(rb), 0.2);
    std::cout << "[ measured ] uniform design: distinct windows " << a.stats.distinct << " (nearest) vs "
              << b.stats.distinct << " of " << b.stats.patches
              << " patches; residual repeating 16 px on: " << periodic(ra) << " vs " << periodic(rb) << std::endl;
}

TEST(AnimateTransfer, LappedPastingCoversTheMatteWithUnitWeights)
{
    const int W = 64, H = 48;
    ChannelImage ex(80, 60, 2), tg(W, H, 2), matte(W, H, 1);
    for (int y = 0; y < 60; ++y)
        for (int x = 0; x < 80; ++x) {
            ex.at(x, y, 0) = float(std::sin(0.1 * x));
            ex.at(x, y, 1) = float(std::cos(0.13 * y));
        }
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            tg.at(x, y, 0) = 0.5f;
            matte.at(x, y, 0) = x < 40 ? 1.0f : 0.0f;
        }
    const TransferMap map = matchResiduals(ex, tg, ResidualTransferSettings{}, &matte);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            double s = 0.0;
            for (int k = 0; k < TransferMap::kTaps; ++k) s += map.weight(size_t(y) * W + size_t(x), k);
            EXPECT_NEAR(s, x < 40 ? 1.0 : 0.0, 1e-5) << x << "," << y;
        }
}

// ---------------------------------------------------------------------------------------------
// Synthesis (5.4, 5.5)

TEST(AnimateSynthesis, IncrementalEq7EqualsTheLiteralSum)
{
    const int W = 40, H = 32, tau = 4, N = 9;
    ChannelImage flow(W, H, 2);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            flow.at(x, y, 0) = float(1.0 + 0.3 * std::sin(0.2 * y));
            flow.at(x, y, 1) = float(0.4 * std::cos(0.15 * x));
        }
    std::vector<ChannelImage> R;
    std::mt19937 rng(5);
    for (int k = 0; k < N - 1; ++k) {
        ChannelImage r(W, H, 3);
        for (float& v : r.data()) v = float(int(rng() % 2001) - 1000) / 1000.0f;
        R.push_back(r);
    }
    DifferenceSynthesizer synth(flow, tau);
    int produced = 0;
    for (int k = 0; k < N - 1; ++k) {
        const ChannelImage d = synth.push(R[size_t(k)]);
        const int i = k + 1;
        if (i < tau) {
            EXPECT_TRUE(d.empty());
            continue;
        }
        ++produced;
        ChannelImage lit(W, H, 3);
        for (int j = i - tau; j <= i - 1; ++j) {
            ChannelImage t = R[size_t(j)];
            for (int n = 0; n < i - j - 1; ++n) t = warpByFlow(t, flow);
            for (size_t q = 0; q < t.data().size(); ++q) lit.data()[q] += t.data()[q];
        }
        double e = 0.0;
        for (size_t q = 0; q < lit.data().size(); ++q) e = std::max(e, double(std::abs(lit.data()[q] - d.data()[q])));
        EXPECT_LT(e, 1e-5) << "frame " << i;
    }
    EXPECT_EQ(produced, N - tau);
}

TEST(AnimateSynthesis, Eq8GivesTheMeanAndStdOfC)
{
    const int W = 30, H = 20;
    std::vector<ChannelImage> d(3, ChannelImage(W, H, 3));
    ChannelImage c(W, H, 3);
    std::mt19937 rng(9);
    for (auto& img : d)
        for (float& v : img.data()) v = 0.3f + float(rng() % 1000) / 300.0f;
    for (float& v : c.data()) v = -0.2f + float(rng() % 1000) / 5000.0f;
    const ContrastAdjustment a = contrastAdjustment(d, c);
    for (auto& img : d) a.apply(img);
    for (int ch = 0; ch < 3; ++ch) {
        double s = 0.0, s2 = 0.0, n = 0.0;
        for (const auto& img : d)
            for (size_t i = 0; i < img.pixelCount(); ++i) {
                s += img.pixel(i)[ch];
                s2 += double(img.pixel(i)[ch]) * img.pixel(i)[ch];
                n += 1.0;
            }
        const MeanStd cs = meanStd(c, ch, 0, 0, W, H);
        EXPECT_NEAR(s / n, cs.mean, 1e-5);
        EXPECT_NEAR(std::sqrt(s2 / n - (s / n) * (s / n)), cs.std, 1e-5);
    }
}

// ---------------------------------------------------------------------------------------------
// Pyramids and histogram matching (5.6)

TEST(AnimatePyramids, SteerableAndLaplacianReconstruct)
{
    const ChannelImage img = luminance(Waves(11).frame(90, 70, 0.0, 0.0));
    for (int L : {1, 3}) {
        const SteerablePyramid p = buildSteerablePyramid(img, L, 4);
        const ChannelImage back = collapse(p);
        double e = 0.0;
        for (size_t q = 0; q < img.data().size(); ++q)
            e = std::max(e, double(std::abs(back.data()[q] - img.data()[q])));
        EXPECT_LT(e, 1e-4) << L << " levels";
        const LaplacianPyramid lp = buildLaplacianPyramid(img, L);
        const ChannelImage lback = collapse(lp);
        for (size_t q = 0; q < img.data().size(); ++q)
            e = std::max(e, double(std::abs(lback.data()[q] - img.data()[q])));
        EXPECT_LT(e, 1e-4) << L << " levels";
    }
    // A pattern varying along x only lands in orientation 0 (theta = 0) of the steerable bands.
    ChannelImage stripes(96, 96, 1);
    for (int y = 0; y < 96; ++y)
        for (int x = 0; x < 96; ++x) stripes.at(x, y, 0) = float(std::sin(2.0 * M_PI * x / 6.0));
    const SteerablePyramid p = buildSteerablePyramid(stripes, 2, 4);
    double e0 = 0.0, e2 = 0.0;
    for (float v : p.bands[0][0].data()) e0 += double(v) * v;
    for (float v : p.bands[0][2].data()) e2 += double(v) * v;
    EXPECT_GT(e0, 100.0 * e2);
}

TEST(AnimateHistogram, MatchesMeanAndStdPerFrameAndPerCell)
{
    // Target: waves with a level ramp across x and a contrast ramp down y (x 0.5 .. 1.3), so every cell
    // differs; frame: finer waves. After matching: mean and std within 2% of the target's, on the whole
    // frame and in every cell (means relative to max(|mean|, 0.05)).
    const int W = 128, H = 96;
    const auto waves = [](unsigned seed, double lmin, double lmax) {
        Waves w(seed, 40, lmin, lmax);
        for (auto& v : w.waves)
            for (double& a : v.amp) a *= 0.4;
        return w;
    };
    ChannelImage target = waves(21, 5.0, 24.0).frame(W, H, 0, 0), frame = waves(22, 3.0, 12.0).frame(W, H, 0, 0);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            for (int c = 0; c < 3; ++c) {
                float& v = target.at(x, y, c);
                v = 0.2f + 0.3f * float(x) / W + (v - 0.4f) * (0.5f + 0.8f * float(y) / H);
            }
    double worstMean = 0.0, worstStd = 0.0;
    const auto near = [&](const MeanStd& o, const MeanStd& t, const std::string& where) {
        EXPECT_LE(std::abs(o.mean - t.mean), 0.02 * std::max(std::abs(t.mean), 0.05)) << where;
        EXPECT_LE(std::abs(o.std - t.std), 0.02 * t.std) << where;
        worstMean = std::max(worstMean, std::abs(o.mean - t.mean) / std::max(std::abs(t.mean), 0.05));
        worstStd = std::max(worstStd, std::abs(o.std - t.std) / t.std);
    };
    for (HmPyramid mode : {HmPyramid::Steerable, HmPyramid::Laplacian}) {
        HistogramMatchSettings s;
        s.pyramid = mode;
        s.cellSize = 32; // 4 x 3 cells
        const HistogramMatcher hm(target, s);
        EXPECT_EQ(hm.gridCols(), 4);
        EXPECT_EQ(hm.gridRows(), 3);
        const ChannelImage out = hm.match(frame);
        for (int c = 0; c < 3; ++c) {
            near(meanStd(out, c, 0, 0, W, H), meanStd(target, c, 0, 0, W, H), "frame");
            for (const HmCell& cell : hm.cells())
                near(meanStd(out, c, cell.x0, cell.y0, cell.x1, cell.y1),
                    meanStd(target, c, cell.x0, cell.y0, cell.x1, cell.y1),
                    "cell " + std::to_string(cell.x0) + "," + std::to_string(cell.y0));
        }
        // One cell (the whole frame) is solved too: exact, where the histogram passes alone leave it a little off.
        HistogramMatchSettings one = s;
        one.gridCols = one.gridRows = 1;
        const ChannelImage whole = HistogramMatcher(target, one).match(frame);
        for (int c = 0; c < 3; ++c) {
            const MeanStd o = meanStd(whole, c, 0, 0, W, H), t = meanStd(target, c, 0, 0, W, H);
            EXPECT_NEAR(o.mean, t.mean, 1e-4 * std::abs(t.mean));
            EXPECT_NEAR(o.std, t.std, 1e-4 * t.std);
        }
        // Before matching the frame is far from the target in some cell: the test can fail.
        double worst = 0.0;
        for (const HmCell& cell : hm.cells()) {
            const MeanStd f = meanStd(frame, 0, cell.x0, cell.y0, cell.x1, cell.y1),
                          t = meanStd(target, 0, cell.x0, cell.y0, cell.x1, cell.y1);
            worst = std::max(worst, std::abs(f.std - t.std) / t.std);
        }
        EXPECT_GT(worst, 0.2);
        std::cout << "[ measured ] " << (mode == HmPyramid::Steerable ? "steerable" : "laplacian")
                  << ": worst relative mean error " << worstMean << ", std error " << worstStd
                  << " (frame and 12 cells, 3 channels)" << std::endl;
        worstMean = worstStd = 0.0;
    }
}

namespace {

/// The water at `level` with texture `contrast` (its std is about 0.1 x contrast).
void matchCellsThroughAMatte(float level, float contrast, bool seamVisibleUnblended)
{
    const int W = 128, H = 96;
    ChannelImage target = Waves(31, 40, 4.0, 16.0).frame(W, H, 0, 0);
    const ChannelImage frame = Waves(32, 40, 3.0, 10.0).frame(W, H, 0, 0);
    ChannelImage matte(W, H, 1);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const float edge = 30.0f + 0.35f * float(x) - float(y); // > 0: bank; soft over 3 px
            const float m = std::clamp(0.5f - edge / 3.0f, 0.0f, 1.0f);
            matte.at(x, y, 0) = m;
            for (int c = 0; c < 3; ++c) {
                float& v = target.at(x, y, c);
                const float water = level + 0.1f * float(c) + contrast * (v - 0.4f) * (0.6f + float(x) / W);
                const float bank = 0.55f - 0.1f * float(c) + 0.1f * (v - 0.4f);
                v = m * water + (1.0f - m) * bank;
            }
        }
    const auto deliver = [&](const HistogramMatcher& hm) {
        ChannelImage in = frame;
        for (size_t i = 0; i < in.pixelCount(); ++i)
            for (int c = 0; c < 3; ++c) {
                const float m = matte.pixel(i)[0];
                in.pixel(i)[c] = m * in.pixel(i)[c] + (1.0f - m) * target.pixel(i)[c];
            }
        ChannelImage out = hm.match(in);
        for (size_t i = 0; i < out.pixelCount(); ++i)
            for (int c = 0; c < 3; ++c) {
                const float m = matte.pixel(i)[0];
                out.pixel(i)[c] = m * out.pixel(i)[c] + (1.0f - m) * target.pixel(i)[c];
            }
        return out;
    };
    const auto worstCellStd = [&](const ChannelImage& out, const HistogramMatcher& hm) {
        double worst = 0.0;
        for (int c = 0; c < 3; ++c)
            for (const HmCell& cell : hm.cells()) {
                const MeanStd o = meanStd(out, c, cell.x0, cell.y0, cell.x1, cell.y1),
                              t = meanStd(target, c, cell.x0, cell.y0, cell.x1, cell.y1);
                EXPECT_GT(t.std, 0.0);
                worst = std::max(worst, std::abs(o.std - t.std) / t.std);
            }
        return worst;
    };
    HistogramMatchSettings s;
    s.cellSize = 32; // 4 x 3 cells
    const HistogramMatcher exact(target, s, &matte);
    const ChannelImage out = deliver(exact);
    const double withStep = worstCellStd(out, exact);
    for (int c = 0; c < 3; ++c)
        for (const HmCell& cell : exact.cells()) {
            const MeanStd o = meanStd(out, c, cell.x0, cell.y0, cell.x1, cell.y1),
                          t = meanStd(target, c, cell.x0, cell.y0, cell.x1, cell.y1);
            EXPECT_NEAR(o.mean, t.mean, 1e-3 * std::max(std::abs(t.mean), 0.05));
            EXPECT_NEAR(o.std, t.std, 1e-3 * t.std);
        }
    s.cellMoments = false;
    const HistogramMatcher blended(target, s, &matte);
    const ChannelImage before = deliver(blended);
    const double withoutStep = worstCellStd(before, blended);
    EXPECT_GT(withoutStep, 5.0 * withStep); // the step is what makes them exact
    // No seam: at the cells' borders the delivered frame jumps no more than the target does there, relative to
    // its jumps elsewhere (the blend spreads each cell's gain over a zone; exact, unblended cells jump at the border).
    const auto borderJump = [&](const ChannelImage& img, const HistogramMatcher& hm) {
        std::vector<char> edgeX(size_t(W), 0), edgeY(size_t(H), 0);
        for (const HmCell& cell : hm.cells()) {
            if (cell.x0 > 0) edgeX[size_t(cell.x0)] = 1;
            if (cell.y0 > 0) edgeY[size_t(cell.y0)] = 1;
        }
        double atEdge = 0.0, all = 0.0, nEdge = 0.0, nAll = 0.0;
        for (int y = 1; y < H; ++y)
            for (int x = 1; x < W; ++x)
                for (int c = 0; c < 3; ++c) {
                    const double m = matte.at(x, y, 0);
                    if (m < 0.99) continue; // the water, where the matching acts
                    const double jx = std::abs(img.at(x, y, c) - img.at(x - 1, y, c)),
                                 jy = std::abs(img.at(x, y, c) - img.at(x, y - 1, c));
                    all += jx + jy;
                    nAll += 2.0;
                    if (edgeX[size_t(x)]) {
                        atEdge += jx;
                        nEdge += 1.0;
                    }
                    if (edgeY[size_t(y)]) {
                        atEdge += jy;
                        nEdge += 1.0;
                    }
                }
        return (atEdge / nEdge) / (all / nAll);
    };
    s.cellMoments = true;
    s.blendPixels = false;
    const HistogramMatcher unblended(target, s, &matte);
    const ChannelImage cut = deliver(unblended);
    const double jTarget = borderJump(target, exact), jOut = borderJump(out, exact),
                 jBefore = borderJump(before, exact), jCut = borderJump(cut, exact);
    EXPECT_LT(jOut, 1.1 * std::max(jTarget, jBefore)) << "no seam at the cell borders";
    if (seamVisibleUnblended) EXPECT_GT(jCut, 1.5 * jOut) << "the measure sees the unblended cells' seams";
    std::cout << "[ measured ] water at " << level << " x " << contrast << ": worst cell std error: " << withoutStep
              << " blended matches, " << withStep << " with the moment step; border jump / mean jump: target "
              << jTarget << ", blended " << jBefore << ", with the step " << jOut << ", exact cells " << jCut
              << std::endl;
}

} // namespace

TEST(AnimateHistogram, CellsNextToVeryDifferentCellsMatchExactlyThroughAMatte)
{

    // The built-in river's hard case: a matte edge crosses the grid, so cells are partly a calm bank and partly
    // strongly textured water, and a cell of water sits next to half-bank cells whose maps cover its blend zones.
    // Frames are matched and composited through the matte as animate does; every cell's mean and std of the
    // delivered frame must then be the target's (the moment step solves for them), where the blended matches alone
    // leave them a few per cent off.
    matchCellsThroughAMatte(0.25f, 1.4f, false);
    // Bright, calm water (mean about 20 x its std): the step solves for the variance, not the second moment,
    // which there would hide a 5% std error behind a mean error 20 times smaller (found on the 640x480 river).
    matchCellsThroughAMatte(0.7f, 0.15f, true);
}

// ---------------------------------------------------------------------------------------------
// The pipeline

namespace {

/// A small run: translating noise as the example, another texture as the target, one diagonal stroke.
struct SmallRun
{
    std::vector<AnimatedFrame> frames;
    AnimateStats stats;
    ChannelImage designed;
};

SmallRun runSmall(int threads, int N = 14, int tau = 4, bool hm = true, HmApply apply = HmApply::PerFrame)
{
    SmallRun run;
    AnimateInput in;
    in.exampleFrames = translatedNoise(64, 48, N, 1.0, 0.5);
    in.target = Waves(31).frame(56, 40, 0, 0);
    const std::vector<FlowStroke> strokes{
        stroke(StrokeKind::Orientation, {{5, 5}, {50, 30}}), stroke(StrokeKind::Speed, {{5, 20}, {50, 20}}, 1.2)};
    in.strokes = &strokes;
    AnimateSettings s;
    s.tau = tau;
    s.histogramMatch = hm;
    s.hmApply = apply;
    s.hm.cellSize = 28;
    withThreads(threads, [&] {
        run.stats = animate(
            std::move(in), s, [&](const AnimatedFrame& f) { run.frames.push_back(f); }, nullptr,
            [&](const std::string& name, int, const ChannelImage& img) {
                if (name == "refined") run.designed = img;
            });
    });
    return run;
}

} // namespace

TEST(AnimatePipeline, WritesNMinusTauFramesBitIdenticalAtAnyThreadCount)
{
    for (HmApply apply : {HmApply::PerFrame, HmApply::Sequence}) {
        const SmallRun a = runSmall(1, 14, 4, true, apply), b = runSmall(2, 14, 4, true, apply);
        ASSERT_EQ(a.frames.size(), 10u) << "N - tau";
        ASSERT_EQ(b.frames.size(), 10u);
        for (size_t i = 0; i < a.frames.size(); ++i) {
            EXPECT_EQ(a.frames[i].index, int(i));
            EXPECT_EQ(a.frames[i].exampleIndex, int(i) + 4);
            EXPECT_EQ(a.frames[i].image.data(), b.frames[i].image.data()) << "frame " << i;
        }
        EXPECT_EQ(a.stats.frames, 10);
    }
}

TEST(AnimatePipeline, RefusesBadInput)
{
    AnimateInput in;
    in.exampleFrames = translatedNoise(32, 32, 5, 1.0, 0.0);
    in.target = ChannelImage(32, 32, 3, 0.5f);
    ChannelImage flow(32, 32, 2, 1.0f);
    in.designedFlow = &flow;
    AnimateSettings s; // tau 16: 5 frames are too few
    try {
        animate(std::move(in), s, [](const AnimatedFrame&) {});
        FAIL();
    } catch (const ValueError& e) {
        EXPECT_NE(std::string(e.what()).find("tau + 2"), std::string::npos) << e.what();
    }
    AnimateInput none;
    none.exampleFrames = translatedNoise(32, 32, 20, 1.0, 0.0);
    none.target = ChannelImage(32, 32, 3, 0.5f);
    EXPECT_THROW(animate(std::move(none), s, [](const AnimatedFrame&) {}), ValueError);
}

namespace {

struct MotionRun
{
    FlowAgreement tracks, field;
    double worstCellMean = 0.0, worstCellStd = 0.0;
};

/// Animates 40 frames of translated noise (tau 8: 32 output frames) onto `target` along a diagonal design at
/// 1.5 px/frame and measures the output's motion against the design: its tracks and its interpolated mean flow.
MotionRun runMotion(const ChannelImage& target, HmApply apply)
{
    AnimateInput in;
    in.exampleFrames = translatedNoise(96, 80, 40, 1.5, -0.5);
    in.target = target;
    const std::vector<FlowStroke> strokes{
        stroke(StrokeKind::Orientation, {{10, 70}, {85, 20}}), stroke(StrokeKind::Speed, {{10, 40}, {85, 40}}, 1.5)};
    in.strokes = &strokes;
    AnimateSettings s;
    s.tau = 8;
    s.hm.cellSize = 48;
    s.hmApply = apply;
    std::vector<ChannelImage> out;
    ChannelImage designed;
    MotionRun r;
    animate(
        std::move(in), s,
        [&](const AnimatedFrame& f) {
            out.push_back(f.image);
            r.worstCellMean = std::max(r.worstCellMean, f.cellMeanError);
            r.worstCellStd = std::max(r.worstCellStd, f.cellStdError);
        },
        nullptr,
        [&](const std::string& name, int, const ChannelImage& img) {
            if (name == "refined") designed = img;
        });
    EXPECT_EQ(out.size(), 32u);
    std::vector<FlowTrack> tracks;
    r.field = compareFlows(estimateMeanFlow(out, AnalysisSettings{}, nullptr, nullptr, &tracks), designed);
    r.tracks = compareTracks(tracks, designed);
    return r;
}

void expectFollows(const FlowAgreement& a, const std::string& what)
{
    EXPECT_LT(a.medianAngleDeg, 15.0) << what;
    EXPECT_GT(a.medianSpeedRatio, 0.8) << what;
    EXPECT_LT(a.medianSpeedRatio, 1.2) << what;
    EXPECT_GT(a.pixels, 0.5) << what;
}

} // namespace

TEST(AnimatePipeline, MotionFollowsTheDesign)
{
    // The output's own flow analysis against the designed flow: median angle < 15 degrees, speed ratio 0.8..1.2
    // (docs/animate.md), track by track and as the interpolated mean flow, with either way of matching histograms.
    for (HmApply apply : {HmApply::PerFrame, HmApply::Sequence}) {
        const std::string mode = apply == HmApply::PerFrame ? "per-frame" : "sequence";
        const MotionRun r = runMotion(Waves(41).frame(96, 80, 0, 0), apply);
        expectFollows(r.tracks, mode + ", tracks");
        expectFollows(r.field, mode + ", field");
        std::cout << "[ measured ] " << mode << ": tracks " << r.tracks.medianAngleDeg << " deg, ratio "
                  << r.tracks.medianSpeedRatio << "; field " << r.field.medianAngleDeg << " deg, ratio "
                  << r.field.medianSpeedRatio << std::endl;
    }
}

TEST(AnimatePipeline, SequenceMatchingKeepsTheMotionOnASmoothStill)
{
    // A still with no texture of its own (a soft blob on a ramp), as renders of smoke are: matching every frame's
    // histograms to it remaps the moving detail around the static average; matching the mean frame once and
    // correcting each frame's cell moments keeps the motion and still gives every frame and cell the still's mean
    // and std (within 2%).
    ChannelImage smooth(96, 80, 3);
    for (int y = 0; y < 80; ++y)
        for (int x = 0; x < 96; ++x) {
            const double r2 = (std::pow(x - 44.0, 2) + std::pow(y - 36.0, 2)) / (2 * 18.0 * 18.0);
            const float v = float(0.15 + 0.002 * x + 0.6 * std::exp(-r2));
            for (int c = 0; c < 3; ++c) smooth.at(x, y, c) = v * (1.0f - 0.1f * float(c));
        }
    const MotionRun seq = runMotion(smooth, HmApply::Sequence), per = runMotion(smooth, HmApply::PerFrame);
    expectFollows(seq.tracks, "sequence, tracks");
    expectFollows(seq.field, "sequence, field");
    EXPECT_LT(seq.worstCellMean, 0.02);
    EXPECT_LT(seq.worstCellStd, 0.02);
    std::cout << "[ measured ] smooth still, sequence: tracks " << seq.tracks.medianAngleDeg << " deg, ratio "
              << seq.tracks.medianSpeedRatio << ", worst cell mean/std error " << seq.worstCellMean << " / "
              << seq.worstCellStd << "; per-frame: tracks " << per.tracks.medianAngleDeg << " deg, ratio "
              << per.tracks.medianSpeedRatio << "; field " << per.field.medianAngleDeg << " deg, ratio "
              << per.field.medianSpeedRatio << std::endl;
}

TEST(AnimateQuality, TemporalStatsOfASinusoid)
{
    // Y(t) = sin(w t + phase(x)): temporal std 1/sqrt(2), autocorrelation cos(w L) (long series).
    const double w = 0.3;
    const auto sinusoid = [&](int frames) {
        TemporalStats ts(5);
        for (int t = 0; t < frames; ++t) {
            ChannelImage f(8, 4, 1);
            for (size_t i = 0; i < f.pixelCount(); ++i) f.pixel(i)[0] = float(std::sin(w * t + 0.7 * double(i)));
            ts.add(f);
        }
        return ts.summary();
    };
    const TemporalSummary s = sinusoid(400);
    EXPECT_NEAR(s.temporalStd, 1.0 / std::sqrt(2.0), 5e-3);
    for (int L = 1; L <= 5; ++L) EXPECT_NEAR(s.autocorrelation[size_t(L - 1)], std::cos(w * L), 0.02) << "lag " << L;
    // Three frames have lags 1 and 2 only: the rest are NaN, not zero.
    const TemporalSummary ss = sinusoid(3);
    EXPECT_FALSE(std::isnan(ss.autocorrelation[1]));
    for (int L = 3; L <= 5; ++L) EXPECT_TRUE(std::isnan(ss.autocorrelation[size_t(L - 1)])) << "lag " << L;
}

namespace {

/// A stationary dynamic texture, the model of section 4.5: D_{i+1} = rho shift(D_i) + sqrt(1 - rho^2) N_i,
/// with shift a whole-pixel translation (wrapping) and N_i smooth noise, over a smooth average A.
std::vector<ChannelImage> dynamicTexture(int W, int H, int N, double rho, unsigned seed)
{
    std::mt19937 rng(seed);
    std::normal_distribution<float> g(0.0f, 1.0f);
    const auto noise = [&] {
        ChannelImage n(W, H, 3);
        for (float& v : n.data()) v = g(rng);
        n = gaussianBlur(n, 1.5);
        for (float& v : n.data()) v *= 0.25f;
        return n;
    };
    ChannelImage d = noise();
    std::vector<ChannelImage> frames;
    for (int i = 0; i < N; ++i) {
        ChannelImage f(W, H, 3);
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
                for (int c = 0; c < 3; ++c)
                    f.at(x, y, c) = 0.3f + 0.2f * float(x) / W + 0.1f * float(c) + d.at(x, y, c);
        frames.push_back(f);
        const ChannelImage n = noise();
        ChannelImage next(W, H, 3);
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
                for (int c = 0; c < 3; ++c)
                    next.at(x, y, c) =
                        float(rho) * d.at((x - 1 + W) % W, y, c) + float(std::sqrt(1.0 - rho * rho)) * n.at(x, y, c);
        d = next;
    }
    return frames;
}

} // namespace

TEST(AnimateQuality, OutputFlickersLikeTheExample)
{
    // The example's own frame as the target and its own flow (1, 0) as the design: the output's temporal
    // std and its autocorrelation at lags 1..tau should be close to the example's (docs/animate.md).
    const int N = 48, tau = 16;
    std::vector<ChannelImage> frames = dynamicTexture(80, 64, N, 0.8, 13); // memory ~ 1/(1 - rho) = 5 frames << tau
    // Compared over the same number of frames (N - tau): sample autocorrelations of short series are
    // biased low at large lags, by an amount that depends on the length.
    TemporalStats exStats(tau);
    for (int i = tau; i < N; ++i) exStats.add(frames[size_t(i)]);
    ChannelImage v(80, 64, 2);
    for (size_t i = 0; i < v.pixelCount(); ++i) v.pixel(i)[0] = 1.0f;
    AnimateInput in;
    in.target = frames[N / 2];
    in.exampleFrames = frames;
    in.designedFlow = &v;
    AnimateSettings s;
    s.tau = tau;
    s.hm.cellSize = 40;
    TemporalStats outStats(tau);
    animate(std::move(in), s, [&](const AnimatedFrame& f) { outStats.add(f.image); });
    const TemporalSummary e = exStats.summary(), o = outStats.summary();
    std::string ac;
    for (int L = 1; L <= tau; ++L)
        ac += " " + std::to_string(o.autocorrelation[size_t(L - 1)]) + "/" +
              std::to_string(e.autocorrelation[size_t(L - 1)]);
    EXPECT_GT(o.temporalStd, 0.8 * e.temporalStd) << o.temporalStd << " vs " << e.temporalStd;
    EXPECT_LT(o.temporalStd, 1.25 * e.temporalStd) << o.temporalStd << " vs " << e.temporalStd;
    // Short lags carry the motion: close. Longer lags see the patch mosaic of the transfer (terms cross
    // into patches with other offsets after about patch / speed frames): looser.
    double sum = 0.0;
    for (int L = 1; L <= tau; ++L) {
        const double d = std::abs(o.autocorrelation[size_t(L - 1)] - e.autocorrelation[size_t(L - 1)]);
        sum += d;
        EXPECT_LT(d, L <= 3 ? 0.05 : 0.15) << "lag " << L << ":" << ac;
    }
    EXPECT_LT(sum / tau, 0.08) << ac;
    std::cout << "[ measured ] temporal std output/example " << o.temporalStd / e.temporalStd
              << "; mean |autocorrelation difference| over lags 1.." << tau << " " << sum / tau << "; lag 1 "
              << o.autocorrelation[0] << "/" << e.autocorrelation[0] << std::endl;
}

// ---------------------------------------------------------------------------------------------
// The Clone Brush (section 5.3)

namespace {

/// Gaussian blobs (std 1.5 px, height 1) at `centres` on a W x H single-channel image.
ChannelImage blobs(int W, int H, const std::vector<StrokePoint>& centres)
{
    ChannelImage img(W, H, 1);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            for (const StrokePoint& c : centres)
                img.at(x, y, 0) += float(std::exp(-(std::pow(x - c.x, 2) + std::pow(y - c.y, 2)) / (2 * 1.5 * 1.5)));
    return img;
}

/// The centroid of the positive values of `img` within `r` pixels of (x, y).
StrokePoint centroidNear(const ChannelImage& img, double x, double y, double r)
{
    double sw = 0.0, sx = 0.0, sy = 0.0;
    for (int v = int(y - r); v <= int(y + r); ++v)
        for (int u = int(x - r); u <= int(x + r); ++u) {
            if (u < 0 || v < 0 || u >= img.width() || v >= img.height()) continue;
            const double w = std::max(0.0f, img.at(u, v, 0));
            sw += w;
            sx += w * u;
            sy += w * v;
        }
    return sw > 0.0 ? StrokePoint{sx / sw, sy / sw} : StrokePoint{-1e9, -1e9};
}

/// A rigid motion: rotation by `deg` about the origin, then (tx, ty).
struct Rigid
{
    double deg, tx, ty;
    StrokePoint operator()(StrokePoint p) const
    {
        const double a = deg * M_PI / 180.0;
        return {std::cos(a) * p.x - std::sin(a) * p.y + tx, std::sin(a) * p.x + std::cos(a) * p.y + ty};
    }
};

} // namespace

TEST(AnimateClone, ARigidlyMovedStrokeCarriesTheResidualsWhereTheDestinationSays)
{
    // Residual blobs around a curved source stroke on a 96x80 example; the destination stroke is the source rotated
    // by 120 degrees and moved onto a 128x112 target. Each blob must land at the same rigid motion of its centre,
    // within a pixel, and keep its height (no smearing).
    const std::vector<StrokePoint> source{{20, 40}, {50, 30}, {75, 45}};
    const std::vector<StrokePoint> centres{{30, 41}, {55, 27}, {70, 50}, {45, 36}};
    const ChannelImage residual = blobs(96, 80, centres);
    for (const Rigid T : {Rigid{120.0, 130.0, 20.0}, Rigid{0.0, 30.0, 35.0}, Rigid{-35.0, 10.0, 70.0}}) {
        CloneStroke c;
        c.source = source;
        for (const StrokePoint& p : source) c.destination.push_back(T(p));
        c.size = 30.0;
        TransferMap map(128, 112, 96, 80);
        applyCloneStrokes(map, {c});
        const ChannelImage moved = map.apply(residual);
        double worst = 0.0;
        for (const StrokePoint& b : centres) {
            const StrokePoint want = T(b), got = centroidNear(moved, want.x, want.y, 5.0);
            worst = std::max(worst, std::hypot(got.x - want.x, got.y - want.y));
            EXPECT_LT(std::hypot(got.x - want.x, got.y - want.y), 1.0) << "blob " << b.x << "," << b.y;
            EXPECT_GT(moved.at(int(std::lround(want.x)), int(std::lround(want.y)), 0), 0.75f) << "the blob's height";
        }
        // The deformation is the inverse rigid motion exactly, on the strokes and away from them.
        const CloneDeformation f(c);
        const Rigid back{-T.deg, 0.0, 0.0};
        for (const StrokePoint& x : {c.destination[0], c.destination[2], StrokePoint{60, 60}, StrokePoint{100, 30}}) {
            const StrokePoint want = back({x.x - T.tx, x.y - T.ty}), got = f(x.x, x.y);
            EXPECT_NEAR(got.x, want.x, 1e-6);
            EXPECT_NEAR(got.y, want.y, 1e-6);
        }
        std::cout << "[ measured ] clone by a rigid motion (" << T.deg << " deg): worst blob position error " << worst
                  << " px, " << f.controlPoints() << " control points, cloned " << map.stats.cloned << std::endl;
    }
}

TEST(AnimateClone, StrokesOfDifferentLengthsFitEndToEnd)
{
    // A 40 px source stroke onto a 60 px destination: the ends and the middle map onto the source's, and between the
    // strokes' ends the residual is stretched along the stroke (an example position per target pixel, none outside).
    CloneStroke c;
    c.source = {{20, 20}, {60, 20}};
    c.destination = {{10, 50}, {70, 50}};
    c.size = 16.0;
    const CloneDeformation f(c);
    const auto near = [](StrokePoint a, StrokePoint b) { return std::hypot(a.x - b.x, a.y - b.y) < 1e-6; };
    EXPECT_TRUE(near(f(10, 50), {20, 20}));
    EXPECT_TRUE(near(f(70, 50), {60, 20}));
    EXPECT_TRUE(near(f(40, 50), {40, 20}));
    const StrokePoint above = f(40, 44); // 6 px off the middle of the stroke, on the side the rotation keeps
    EXPECT_NEAR(above.x, 40.0, 0.5);
    EXPECT_NEAR(above.y, 14.0, 1.0);
}

TEST(AnimateClone, SizeAndAlphaBlendWithTheResidualsUnder)
{
    // Under an identity transfer (every pixel its own), a brush of alpha 0.5 gives half the clone and half the residual
    // under it in its core, nothing beyond its size, and every pixel's weights still sum to 1.
    const int W = 80, H = 64;
    TransferMap map(W, H, W, H);
    for (size_t i = 0; i < size_t(W * H); ++i) map.addTap(i, std::uint32_t(i), 1.0f);
    ChannelImage residual(W, H, 1);
    for (int x = 0; x < W; ++x)
        for (int y = 0; y < H; ++y) residual.at(x, y, 0) = x < 40 ? 1.0f : 0.0f; // the left half
    CloneStroke c;
    c.source = {{20, 10}, {20, 50}};      // in the left half (1)
    c.destination = {{60, 10}, {60, 50}}; // in the right half (0)
    c.size = 12.0;
    c.alpha = 0.5;
    const ChannelImage m = applyCloneStrokes(map, {c});
    const ChannelImage out = map.apply(residual);
    EXPECT_NEAR(out.at(60, 30, 0), 0.5f, 1e-6f) << "alpha 0.5 in the core";
    EXPECT_NEAR(out.at(64, 30, 0), 0.5f, 1e-6f) << "the core reaches size / 2 = 6 px";
    EXPECT_EQ(out.at(73, 30, 0), 0.0f) << "nothing beyond the size";
    EXPECT_EQ(out.at(30, 30, 0), 1.0f) << "the rest keeps its residual";
    EXPECT_GT(out.at(68, 30, 0), 0.0f);
    EXPECT_LT(out.at(68, 30, 0), 0.5f) << "the smooth fall-off";
    EXPECT_NEAR(m.at(60, 30, 0), 0.5f, 1e-6f);
    for (size_t i = 0; i < size_t(W * H); ++i) {
        float s = 0.0f;
        for (int k = 0; k < TransferMap::kTaps; ++k) s += map.weight(i, k);
        ASSERT_NEAR(s, 1.0f, 1e-5f) << "pixel " << i;
    }
    EXPECT_GT(map.stats.cloned, 0.0);
}

TEST(AnimateClone, BadStrokesAreRefusedByName)
{
    CloneStroke good;
    good.source = {{5, 5}, {20, 5}};
    good.destination = {{5, 5}, {5, 20}};
    const auto refused = [&](CloneStroke c, const std::string& words) {
        try {
            validateCloneStrokes({good, c}, 32, 24, 40, 30);
            ADD_FAILURE() << "accepted: " << words;
        } catch (const ValueError& e) {
            EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
        }
    };
    CloneStroke c = good;
    c.source = {{5, 5}, {40, 5}};
    refused(c, "clone stroke 1 (source): point (40.000000, 5.000000) lies outside the 32x24 example");
    c = good;
    c.destination = {{5, 5}};
    refused(c, "clone stroke 1 (destination) needs at least 2 points");
    c = good;
    c.destination = {{5, 5}, {5, 5}};
    refused(c, "all its points are equal");
    c = good;
    c.size = 0.0;
    refused(c, "the size must be > 0");
    c = good;
    c.alpha = 1.5;
    refused(c, "alpha must be in [0, 1]");
    EXPECT_NO_THROW(validateCloneStrokes({good}, 32, 24, 40, 30));
}

namespace {

/// The output of translating noise (1.5 px/frame to the right) animated onto a texture with one clone stroke pair
/// that turns the source stroke (along the motion) by -90 degrees onto the destination; the tracks inside the brush
/// core are compared with the origin's motion turned the same way, (0, -1.5). `cloned` false: no clone (the control).
/// `residualMotion`: the example's v is given as zero and the design is still, so the residuals carry all of the
/// example's motion and the output moves only as its residuals do; otherwise v is the true motion and the design the
/// turned motion.
FlowAgreement clonedMotion(bool cloned, bool residualMotion, int threads, std::vector<ChannelImage>* frames = nullptr)
{
    const int W = 96, H = 80;
    AnimateInput in;
    in.exampleFrames = translatedNoise(W, H, 40, 1.5, 0.0);
    in.target = Waves(41).frame(W, H, 0, 0);
    ChannelImage exampleV(W, H, 2), design(W, H, 2);
    for (size_t i = 0; i < exampleV.pixelCount(); ++i) {
        exampleV.pixel(i)[0] = residualMotion ? 0.0f : 1.5f;
        design.pixel(i)[1] = residualMotion ? 0.0f : -1.5f;
    }
    in.exampleFlow = &exampleV;
    in.designedFlow = &design;
    CloneStroke c;
    c.source = {{16, 40}, {80, 40}};
    c.destination = {{48, 72}, {48, 8}};
    c.size = 24.0;
    const std::vector<CloneStroke> clones{c};
    if (cloned) in.clones = &clones;
    AnimateSettings s;
    s.tau = 8;
    s.refineFlow = false;
    s.analysis.givenFlow = GivenFlow::Use;
    s.hm.cellSize = 48;
    std::vector<ChannelImage> out;
    withThreads(threads, [&] { animate(std::move(in), s, [&](const AnimatedFrame& f) { out.push_back(f.image); }); });
    ChannelImage expected(W, H, 2), core(W, H, 1);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            expected.at(x, y, 1) = -1.5f;
            core.at(x, y, 0) = cloneMatte(c, x, y) >= 0.99 ? 1.0f : 0.0f;
        }
    std::vector<FlowTrack> tracks;
    estimateMeanFlow(out, AnalysisSettings{}, nullptr, nullptr, &tracks);
    if (frames) *frames = out;
    return compareTracks(tracks, expected, &core);
}

} // namespace

TEST(AnimatePipeline, TheClonedRegionMovesLikeItsOrigin)
{
    // Tracks inside the brush core against the origin's motion turned by the strokes: angle < 15 degrees, speed ratio
    // 0.8..1.2. With the residuals carrying the motion, only the clone can turn it: without it the same region moves
    // as the example does, 90 degrees off.
    for (bool residualMotion : {true, false}) {
        const std::string what = residualMotion ? "residuals carry the motion" : "v and the design carry it";
        const FlowAgreement a = clonedMotion(true, residualMotion, 0);
        EXPECT_LT(a.medianAngleDeg, 15.0) << what;
        EXPECT_GT(a.medianSpeedRatio, 0.8) << what;
        EXPECT_LT(a.medianSpeedRatio, 1.2) << what;
        EXPECT_GT(a.pixels, 0.15) << what << ": the core is a fifth of the image";
        std::cout << "[ measured ] cloned region (" << what << "): tracks " << a.medianAngleDeg << " deg, ratio "
                  << a.medianSpeedRatio << " of the origin's turned motion, " << a.pixels << " of the tracks"
                  << std::endl;
    }
    const FlowAgreement none = clonedMotion(false, true, 0);
    EXPECT_GT(none.medianAngleDeg, 45.0) << "without the clone the region does not turn: the test can fail";
    std::cout << "[ measured ] the same region without the clone: tracks " << none.medianAngleDeg << " deg, ratio "
              << none.medianSpeedRatio << std::endl;
    std::vector<ChannelImage> one, two;
    clonedMotion(true, true, 1, &one);
    clonedMotion(true, true, 2, &two);
    ASSERT_EQ(one.size(), two.size());
    for (size_t i = 0; i < one.size(); ++i) EXPECT_EQ(one[i].data(), two[i].data()) << "frame " << i;
}
