// Jamriška et al., "LazyFluids: Appearance Transfer for Fluid Animations": the EM pyramid over 9-channel patches
// with uniform patch usage.
#include <turb/Stylize.h>

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/PatchMatch.h>
#include <turb/Voting.h>
#include <turb/Warp.h>

#include "Search.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

namespace turb {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr int kChannels = 9; // eq. 8: RGBA, blurred alpha, previous RGBA
constexpr std::int8_t kBoundary = 0, kInterior = 1;

ChannelImage padClamped(const ChannelImage& img, int r)
{
    ChannelImage out(img.width() + 2 * r, img.height() + 2 * r, img.channels());
    for (int y = 0; y < out.height(); ++y)
        for (int x = 0; x < out.width(); ++x) {
            const float* s = img.pixel(
                std::min(img.width() - 1, std::max(0, x - r)), std::min(img.height() - 1, std::max(0, y - r)));
            std::copy(s, s + img.channels(), out.pixel(x, y));
        }
    return out;
}

ChannelImage cropped(const ChannelImage& img, int r, int channels)
{
    ChannelImage out(img.width() - 2 * r, img.height() - 2 * r, channels);
    for (int y = 0; y < out.height(); ++y)
        for (int x = 0; x < out.width(); ++x)
            std::copy(img.pixel(x + r, y + r), img.pixel(x + r, y + r) + channels, out.pixel(x, y));
    return out;
}

/// Boundary (l, u) and interior [u, 1] of a blurred alpha; -1 elsewhere.
std::vector<std::int8_t> segmentsOf(const ChannelImage& blurred, float l, float u)
{
    std::vector<std::int8_t> seg(blurred.pixelCount(), -1);
    for (size_t i = 0; i < seg.size(); ++i) {
        const float a = blurred.pixel(i)[0];
        seg[i] = a >= u ? kInterior : (a > l ? kBoundary : std::int8_t(-1));
    }
    return seg;
}

ChannelImage premultiplied(const RgbaImage& img)
{
    ChannelImage out(img.width(), img.height(), 4);
    for (size_t i = 0; i < img.size(); ++i) {
        const Rgba& p = img.pixels()[i];
        const float a = std::min(1.0f, std::max(0.0f, p[3]));
        float* o = out.pixel(i);
        for (int c = 0; c < 3; ++c) o[c] = std::isfinite(p[c]) ? p[c] * a : 0.0f;
        o[3] = a;
    }
    return out;
}

ChannelImage reducedTimes(ChannelImage img, int n)
{
    for (int i = 0; i < n; ++i) img = reduceByTwo(img);
    return img;
}

/// The exemplar at one pyramid level: its sheets (rotations) side by side on one canvas, 9 channels,
/// and the segment label of every whole-patch centre.
struct ExemplarLevel
{
    ChannelImage features;
    Labels labels;
    bool has[2] = {false, false}; // boundary, interior centres present
};

ExemplarLevel exemplarLevel(const ChannelImage& cur, const ChannelImage& prev, const ChannelImage& blur, int level,
    int r, bool rotations, const StylizeSettings& s)
{
    const ChannelImage c0 = reducedTimes(cur, level), p0 = reducedTimes(prev, level), b0 = reducedTimes(blur, level);
    const int turns = rotations ? 4 : 1, gap = 2 * r + 2;
    int W = 0, H = 0;
    for (int k = 0; k < turns; ++k) {
        const bool swap = k % 2 == 1;
        W += (swap ? c0.height() : c0.width()) + (k ? gap : 0);
        H = std::max(H, swap ? c0.width() : c0.height());
    }
    ExemplarLevel e;
    e.features = ChannelImage(W, H, kChannels);
    e.labels.assign(e.features.pixelCount(), -1);
    int x0 = 0;
    for (int k = 0; k < turns; ++k) {
        const ChannelImage c = rotated(c0, k), p = rotated(p0, k), b = rotated(b0, k);
        const Labels lab = centreLabels(segmentsOf(b, s.lower, s.upper), b.width(), b.height(), r);
        for (int y = 0; y < c.height(); ++y)
            for (int x = 0; x < c.width(); ++x) {
                float* f = e.features.pixel(x0 + x, y);
                std::copy(c.pixel(x, y), c.pixel(x, y) + 4, f);
                f[4] = b.pixel(x, y)[0];
                std::copy(p.pixel(x, y), p.pixel(x, y) + 4, f + 5);
                const std::int8_t L = lab[c.index(x, y)];
                e.labels[e.features.index(x0 + x, y)] = L;
                if (L >= 0) e.has[L] = true;
            }
        x0 += c.width() + gap;
    }
    return e;
}

/// The target at one pyramid level, padded by the patch radius (clamped) so every pixel is a centre.
struct TargetLevel
{
    int width = 0, height = 0; // unpadded
    ChannelImage features;     // 9 channels, padded
    ChannelImage weights;      // 9 channels, padded: eq. 9's weights with lambda_q per pixel
    Labels labels;             // padded
};

TargetLevel targetLevel(const ChannelImage& alpha, const ChannelImage& blur, const ChannelImage& prev,
    const ChannelImage& lambda, int level, int r, const StylizeSettings& s, const ExemplarLevel& ex)
{
    const ChannelImage a = reducedTimes(alpha, level), b = reducedTimes(blur, level), p = reducedTimes(prev, level),
                       l = reducedTimes(lambda, level);
    TargetLevel t;
    t.width = a.width();
    t.height = a.height();
    const ChannelImage ap = padClamped(a, r), bp = padClamped(b, r), pp = padClamped(p, r), lp = padClamped(l, r);
    t.features = ChannelImage(ap.width(), ap.height(), kChannels);
    t.weights = ChannelImage(ap.width(), ap.height(), kChannels);
    for (size_t i = 0; i < ap.pixelCount(); ++i) {
        float* f = t.features.pixel(i);
        f[3] = ap.pixel(i)[0]; // current RGBA starts as (0, 0, 0, X_a): the paper's zero initialisation
        f[4] = bp.pixel(i)[0];
        std::copy(pp.pixel(i), pp.pixel(i) + 4, f + 5);
        const float lq = lp.pixel(i)[0];
        const float w[kChannels] = {1, 1, 1, s.alphaWeight, s.eta, lq, lq, lq, s.alphaWeight * lq};
        std::copy(w, w + kChannels, t.weights.pixel(i));
    }
    t.labels = centreLabels(segmentsOf(bp, s.lower, s.upper), bp.width(), bp.height(), r);
    // A segment the exemplar lacks at this level (a thin boundary band lost to reduction) matches the other.
    for (auto& L : t.labels)
        if (L >= 0 && !ex.has[L]) L = ex.has[1 - L] ? std::int8_t(1 - L) : std::int8_t(-1);
    return t;
}

int autoLevels(int tw, int th, int ew, int eh, int r)
{
    int levels = 1;
    const int shortest = std::min(std::min(tw, th), std::min(ew, eh));
    while (levels < 5 && (shortest >> levels) >= std::max(32, 4 * (2 * r + 1))) ++levels;
    return levels;
}

double luminance(const float* rgb) { return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]; }

/// Std of Y and mean |grad Y|^2 over pixels with `inside`, Y from straight colours.
InteriorStats luminanceStats(const ChannelImage& straight, const std::vector<char>& inside)
{
    InteriorStats st;
    double s1 = 0.0, s2 = 0.0, g = 0.0;
    long long ng = 0;
    const int W = straight.width(), H = straight.height();
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            if (!inside[straight.index(x, y)]) continue;
            const double Y = luminance(straight.pixel(x, y));
            s1 += Y;
            s2 += Y * Y;
            ++st.pixels;
            if (x > 0 && y > 0 && x < W - 1 && y < H - 1) {
                const double gx = 0.5 * (luminance(straight.pixel(x + 1, y)) - luminance(straight.pixel(x - 1, y)));
                const double gy = 0.5 * (luminance(straight.pixel(x, y + 1)) - luminance(straight.pixel(x, y - 1)));
                g += gx * gx + gy * gy;
                ++ng;
            }
        }
    if (st.pixels > 0) {
        const double m = s1 / double(st.pixels);
        st.stdLuminance = std::sqrt(std::max(0.0, s2 / double(st.pixels) - m * m));
    }
    st.gradientEnergy = ng ? g / double(ng) : 0.0;
    return st;
}

/// Normalised histogram of |grad alpha| (central differences) over pixels with blurred alpha in (l, u).
std::vector<double> boundaryGradientHistogram(
    const ChannelImage& alpha, int channel, const ChannelImage& blurred, float l, float u)
{
    std::vector<double> h(16, 0.0);
    double n = 0.0;
    const int W = alpha.width(), H = alpha.height();
    for (int y = 1; y < H - 1; ++y)
        for (int x = 1; x < W - 1; ++x) {
            const float b = blurred.at(x, y, 0);
            if (!(b > l && b < u)) continue;
            const double gx = 0.5 * (alpha.at(x + 1, y, channel) - alpha.at(x - 1, y, channel));
            const double gy = 0.5 * (alpha.at(x, y + 1, channel) - alpha.at(x, y - 1, channel));
            h[size_t(std::min(15, int(std::hypot(gx, gy) * 32.0)))] += 1.0;
            n += 1.0;
        }
    if (n > 0.0)
        for (double& v : h) v /= n;
    return h;
}

std::vector<char> interiorMask(const ChannelImage& blurredAlpha, float upper)
{
    std::vector<char> m(blurredAlpha.pixelCount());
    for (size_t i = 0; i < m.size(); ++i) m[i] = blurredAlpha.pixel(i)[0] >= upper;
    return m;
}

void checkFrame(const StylizeFrame& f, int r)
{
    if (!f.alpha || !f.exemplar) throw ValueError("stylize: a frame needs a target alpha and an exemplar");
    if (f.alpha->channels() != 1 || f.alpha->empty())
        throw ValueError("stylize: the target alpha must be a non-empty 1-channel image");
    const auto sizeOf = [](const ChannelImage& i) {
        return std::to_string(i.width()) + "x" + std::to_string(i.height());
    };
    for (const ChannelImage* m : {f.motionIn, f.motionOut})
        if (m && (m->channels() != 2 || !m->sameSize(*f.alpha)))
            throw ValueError("stylize: the motion field (" + sizeOf(*m) + ") must be 2 channels of the alpha's size (" +
                             sizeOf(*f.alpha) + ")");
    const RgbaImage& z = *f.exemplar;
    if (z.width() < 2 * r + 1 || z.height() < 2 * r + 1)
        throw ValueError("stylize: the exemplar (" + std::to_string(z.width()) + "x" + std::to_string(z.height()) +
                         ") is smaller than a " + std::to_string(2 * r + 1) + "x" + std::to_string(2 * r + 1) +
                         " patch");
    if (f.exemplarPrevious && !f.exemplarPrevious->sameSize(z))
        throw ValueError("stylize: the previous exemplar frame must have the exemplar's size");
}

/// The target's guides at full resolution: the clamped alpha, its blur, the previous output warped along the motion
/// and eq. 6's lambda_q (with its shape, lambda_q / lambda); `prev` and the lambdas are zero on a first frame.
struct TargetGuides
{
    ChannelImage alpha, blur, prev, lambda, lambdaShape;
};

TargetGuides targetGuides(
    const StylizeFrame& frame, const ChannelImage& previous, bool first, const StylizeSettings& s, StylizeStats& st)
{
    const ChannelImage& alphaIn = *frame.alpha;
    const int W = alphaIn.width(), H = alphaIn.height();
    TargetGuides g;
    g.alpha = ChannelImage(W, H, 1);
    for (size_t i = 0; i < g.alpha.pixelCount(); ++i) {
        const float a = alphaIn.pixel(i)[0];
        g.alpha.pixel(i)[0] = std::isfinite(a) ? std::min(1.0f, std::max(0.0f, a)) : 0.0f;
    }
    g.blur = gaussianBlur(g.alpha, s.blurRadius);
    g.prev = ChannelImage(W, H, 4);
    g.lambda = ChannelImage(W, H, 1);
    g.lambdaShape = ChannelImage(W, H, 1);
    if (!first) {
        const auto tw = Clock::now();
        g.prev = forwardWarp(previous, *frame.motionIn).image;
        st.secondsWarp = since(tw);
        for (size_t i = 0; i < g.lambda.pixelCount(); ++i) {
            // eq. 6: fluid that is new here (an emitter, inflow) is free of the previous frame.
            g.lambdaShape.pixel(i)[0] = 1.0f - std::max(0.0f, g.alpha.pixel(i)[0] - g.prev.pixel(i)[3]);
            g.lambda.pixel(i)[0] = s.lambda * g.lambdaShape.pixel(i)[0];
        }
    }
    return g;
}

/// The exemplar's premultiplied current and previous frames and its blurred alpha.
struct ExemplarGuides
{
    ChannelImage cur, prev, blur;
};

ExemplarGuides exemplarGuides(const StylizeFrame& frame, const StylizeSettings& s)
{
    ExemplarGuides e;
    e.cur = premultiplied(*frame.exemplar);
    e.prev = frame.exemplarPrevious ? premultiplied(*frame.exemplarPrevious) : e.cur;
    e.blur = gaussianBlur(channelOf(*frame.exemplar, 3), s.blurRadius);
    return e;
}

/// Throws ValueError when the target has a segment (boundary or interior) the exemplar cannot supply.
void requireExemplarSegments(const ExemplarGuides& e, const ChannelImage& targetBlur, int r, const StylizeSettings& s)
{
    const ExemplarLevel fine = exemplarLevel(e.cur, e.prev, e.blur, 0, r, false, s);
    const std::vector<std::int8_t> tseg = segmentsOf(targetBlur, s.lower, s.upper);
    bool needs[2] = {false, false};
    for (auto L : tseg)
        if (L >= 0) needs[L] = true;
    if (needs[kInterior] && !fine.has[kInterior])
        throw ValueError("stylize: the exemplar has no interior (no pixel whose alpha blurred by r = " +
                         std::to_string(s.blurRadius) + " reaches u = " + std::to_string(s.upper) +
                         "): check its alpha");
    if (needs[kBoundary] && !fine.has[kBoundary] && !fine.has[kInterior])
        throw ValueError("stylize: the exemplar has no usable alpha (empty or transparent everywhere)");
}

/// Kwatra et al.'s start on the coarsest level: random exemplar patches of each target patch's segment, voted.
void randomStart(const ExemplarLevel& ex, TargetLevel& tl, int r, const StylizeSettings& s, std::uint64_t frame)
{
    std::vector<std::vector<std::int32_t>> lists(2);
    for (size_t p = 0; p < ex.labels.size(); ++p)
        if (ex.labels[p] >= 0) lists[size_t(ex.labels[p])].push_back(std::int32_t(p));
    Nnf random = emptyNnf(tl.features.width(), tl.features.height());
    for (size_t q = 0; q < tl.labels.size(); ++q) {
        const int L = tl.labels[q];
        if (L < 0 || lists[size_t(L)].empty()) continue;
        detail::Rng rng(detail::key(s.seed, frame, q, 0x1d1d));
        random.source[q] = lists[size_t(L)][rng.below(std::uint32_t(lists[size_t(L)].size()))];
    }
    vote(ex.features, random, r, 0, 0, 4, tl.features);
}

/// The last E-step of the finest level: its NNF and the exemplar patches' usage.
struct Correspondence
{
    Nnf nnf;
    std::vector<SegmentUsage> usage;
};

/// One level's EM iterations: the NNF (uniform patch usage or PatchMatch), then the vote into tl's RGBA.
void emIterations(const ExemplarLevel& ex, TargetLevel& tl, int level, int r, const StylizeSettings& s,
    std::uint64_t frame, Correspondence& c, StylizeStats& st, Progress* progress)
{
    const PatchSpace space{&ex.features, &tl.features, &tl.weights, r};
    c.nnf = emptyNnf(tl.features.width(), tl.features.height());
    const int iterations = level == 0 ? s.fineIterations : s.iterations;
    for (int it = 0; it < iterations; ++it) {
        if (progress) progress->begin("level " + std::to_string(level) + " iteration " + std::to_string(it + 1));
        const std::uint64_t seed = detail::key(s.seed, frame, std::uint64_t(level), std::uint64_t(it));
        auto tn = Clock::now();
        if (s.nnf == NnfMode::Uniform) {
            UniformNnfSettings us;
            us.sweepsPerRound = s.sweeps;
            us.seed = seed;
            UniformNnf u = uniformNnf(space, ex.labels, tl.labels, us, progress);
            st.rounds += u.rounds;
            c.nnf = std::move(u.nnf);
            c.usage = std::move(u.usage);
        } else {
            PatchMatchSettings ps;
            ps.iterations = 2 * s.sweeps;
            ps.seed = seed;
            patchMatch(space, ex.labels, tl.labels, ps, c.nnf, progress);
            c.usage = patchUsage(c.nnf, ex.labels, tl.labels);
        }
        st.secondsNnf += since(tn);
        auto tv = Clock::now();
        VoteSettings vs;
        if (s.voteWeight > 0.0f) {
            std::vector<float> d;
            for (size_t q = 0; q < c.nnf.source.size(); ++q)
                if (c.nnf.source[q] >= 0) d.push_back(c.nnf.distance[q]);
            if (!d.empty()) {
                const auto q75 = d.begin() + std::ptrdiff_t(d.size() * 3 / 4);
                std::nth_element(d.begin(), q75, d.end());
                vs.distanceScale = s.voteWeight * std::max(1e-9f, *q75);
            }
        }
        vote(ex.features, c.nnf, r, 0, 0, 4, tl.features, vs);
        st.secondsVote += since(tv);
    }
}

/// The EM pyramid from the coarsest level to the finest: each level starts from the coarser result enlarged (the
/// coarsest from random patches), or on later frames with startFromPrevious from the previous output advected.
/// Returns the finest level's premultiplied RGBA, unpadded.
ChannelImage synthesizePyramid(const TargetGuides& g, const ExemplarGuides& e, bool first, int levels, int r,
    const StylizeSettings& s, std::uint64_t frame, Correspondence& c, StylizeStats& st, Progress* progress)
{
    const int W = g.alpha.width(), H = g.alpha.height();
    ChannelImage current; // synthesised premultiplied RGBA of the previous (coarser) level, unpadded
    for (int level = levels - 1; level >= 0; --level) {
        checkCancelled(progress);
        auto tg = Clock::now();
        const ExemplarLevel ex = exemplarLevel(e.cur, e.prev, e.blur, level, r, s.rotations, s);
        TargetLevel tl = targetLevel(g.alpha, g.blur, first ? ChannelImage(W, H, 4) : g.prev,
            first ? ChannelImage(W, H, 1) : g.lambda, level, r, s, ex);
        ChannelImage init;
        if (!first && s.startFromPrevious) init = padClamped(reducedTimes(g.prev, level), r);
        else if (!current.empty()) init = padClamped(enlarge(current, tl.width, tl.height), r);
        if (init.empty()) {
            randomStart(ex, tl, r, s, frame);
        } else {
            for (size_t i = 0; i < init.pixelCount(); ++i)
                std::copy(init.pixel(i), init.pixel(i) + 4, tl.features.pixel(i));
        }
        st.secondsGuides += since(tg);
        emIterations(ex, tl, level, r, s, frame, c, st, progress);
        current = cropped(tl.features, r, 4);
    }
    return current;
}

/// Eq. 7's mean energy per matched target patch and the fraction of exemplar patches used.
void matchStats(const Correspondence& c, StylizeStats& st)
{
    st.usage = c.usage;
    double e = 0.0;
    long long n = 0;
    for (size_t q = 0; q < c.nnf.source.size(); ++q)
        if (c.nnf.source[q] >= 0) {
            e += c.nnf.distance[q];
            ++n;
        }
    st.energy = n ? e / double(n) : 0.0;
    long long used = 0, sources = 0;
    for (const auto& u : c.usage) {
        used += (long long)std::llround(u.coverage * double(u.sources));
        sources += u.sources;
    }
    st.coverage = sources ? double(used) / double(sources) : 0.0;
}

/// The output's interior texture and boundary against the exemplar's: luminance contrast, gradient energy and the
/// histogram of |grad alpha| in the boundary segment.
void appearanceStats(const ChannelImage& current, const TargetGuides& g, const ExemplarGuides& e,
    const RgbaImage& exemplar, const StylizeSettings& s, StylizeStats& st)
{
    ChannelImage straight(current.width(), current.height(), 4);
    for (size_t i = 0; i < straight.pixelCount(); ++i) {
        const float* p = current.pixel(i);
        float* o = straight.pixel(i);
        for (int c = 0; c < 3; ++c) o[c] = p[3] > 1e-6f ? p[c] / p[3] : 0.0f;
        o[3] = p[3];
    }
    const InteriorStats outStats = luminanceStats(straight, interiorMask(g.blur, s.upper));
    const InteriorStats exStats = luminanceStats(toChannels(exemplar), interiorMask(e.blur, s.upper));
    st.stdRatio = exStats.stdLuminance > 0.0 ? outStats.stdLuminance / exStats.stdLuminance : 0.0;
    st.gradientRatio = exStats.gradientEnergy > 0.0 ? outStats.gradientEnergy / exStats.gradientEnergy : 0.0;
    st.boundaryGradient = boundaryGradientHistogram(current, 3, g.blur, s.lower, s.upper);
    st.exemplarBoundaryGradient = boundaryGradientHistogram(e.cur, 3, e.blur, s.lower, s.upper);
    for (size_t b = 0; b < st.boundaryGradient.size(); ++b)
        st.boundaryGradientMatch += std::min(st.boundaryGradient[b], st.exemplarBoundaryGradient[b]);
}

/// The output's shape against the target alpha (IoU) and its change from the warped previous output where eq. 6's
/// lambda_q holds it (not on a first frame).
void shapeStats(const ChannelImage& current, const TargetGuides& g, bool first, StylizeStats& st)
{
    long long inter = 0, uni = 0, region = 0;
    double change = 0.0;
    for (size_t i = 0; i < current.pixelCount(); ++i) {
        const bool o = current.pixel(i)[3] >= 0.5f, t = g.alpha.pixel(i)[0] >= 0.5f;
        inter += o && t;
        uni += o || t;
        if (!first && g.alpha.pixel(i)[0] >= 0.05f && g.lambdaShape.pixel(i)[0] >= 0.5f) {
            double d = 0.0;
            for (int c = 0; c < 4; ++c) d += std::abs(double(current.pixel(i)[c]) - double(g.prev.pixel(i)[c]));
            change += d / 4.0;
            ++region;
        }
    }
    st.iou = uni ? double(inter) / double(uni) : 1.0;
    if (!first) {
        st.temporalChange = region ? change / double(region) : 0.0;
        st.temporalPixels = double(region) / double(current.pixelCount());
    }
}

/// Straight RGBA from premultiplied, alpha clamped to [0, 1]; transparent where alpha is about 0.
RgbaImage straightRgba(const ChannelImage& premultipliedRgba, const std::string& colorSpace)
{
    RgbaImage image(premultipliedRgba.width(), premultipliedRgba.height());
    image.colorSpace = colorSpace;
    for (size_t i = 0; i < image.size(); ++i) {
        const float* p = premultipliedRgba.pixel(i);
        const float a = std::min(1.0f, std::max(0.0f, p[3]));
        image.pixels()[i] = a > 1e-6f ? Rgba(p[0] / a, p[1] / a, p[2] / a, a) : Rgba(0.0f, 0.0f, 0.0f, 0.0f);
    }
    return image;
}

} // namespace

void validate(const StylizeSettings& s)
{
    if (s.patchSize < 3 || s.patchSize > 15 || s.patchSize % 2 == 0)
        throw ValueError("stylize: patch size must be odd, 3..15");
    if (!(s.lambda >= 0.0f) || !(s.eta >= 0.0f) || !(s.alphaWeight >= 0.0f))
        throw ValueError("stylize: lambda, eta and the alpha weight must be >= 0");
    if (!(s.blurRadius > 0.0)) throw ValueError("stylize: the blur radius r must be > 0");
    if (!(s.lower >= 0.0f && s.lower < s.upper && s.upper <= 1.0f))
        throw ValueError("stylize: thresholds need 0 <= l < u <= 1");
    if (s.levels < 0 || s.levels > 8) throw ValueError("stylize: levels must lie in 0..8");
    if (s.iterations < 1 || s.fineIterations < 1 || s.sweeps < 1)
        throw ValueError("stylize: iterations and sweeps must be >= 1");
    if (!(s.motionBlur >= 0.0f)) throw ValueError("stylize: motion blur must be >= 0");
    if (!(s.voteWeight >= 0.0f)) throw ValueError("stylize: the vote weight must be >= 0");
    if (s.preroll < 0 || s.preroll > 100) throw ValueError("stylize: the pre-roll must lie in 0..100 frames");
}

Stylizer::Stylizer(const StylizeSettings& settings) : mSettings(settings) { validate(settings); }

void Stylizer::reset()
{
    mPrevious = ChannelImage();
    mFrames = 0;
}

InteriorStats interiorStats(const RgbaImage& img, const StylizeSettings& s)
{
    const ChannelImage straight = toChannels(img);
    return luminanceStats(straight, interiorMask(gaussianBlur(channelOf(img, 3), s.blurRadius), s.upper));
}

StylizedFrame Stylizer::next(const StylizeFrame& frame, Progress* progress)
{
    const StylizeSettings& s = mSettings;
    const int r = s.patchSize / 2;
    checkFrame(frame, r);
    StylizedFrame out;
    StylizeStats& st = out.stats;
    const int W = frame.alpha->width(), H = frame.alpha->height();
    st.width = W;
    st.height = H;
    const bool first = mPrevious.empty() || !frame.motionIn || !mPrevious.sameSize(*frame.alpha);
    auto t0 = Clock::now();

    // Guides at full resolution (eq. 8's channels, eq. 9's weights): the target's and the exemplar's.
    if (progress) progress->begin("guides");
    const TargetGuides g = targetGuides(frame, mPrevious, first, s, st);
    const ExemplarGuides e = exemplarGuides(frame, s);
    requireExemplarSegments(e, g.blur, r, s);
    const int levels = s.levels > 0 ? s.levels : autoLevels(W, H, frame.exemplar->width(), frame.exemplar->height(), r);
    st.levels = levels;
    st.secondsGuides = since(t0);

    Correspondence c;
    // Seeds follow the frame's number, so a frame is the same whichever part of the shot is rendered (a shot split at
    // a cut, or frames rendered alone with lambda 0); without a number, its place in the run.
    const std::uint64_t frameKey = std::uint64_t(std::int64_t(frame.number ? *frame.number : mFrames));
    ChannelImage current = synthesizePyramid(g, e, first, levels, r, s, frameKey, c, st, progress);

    // Pre-roll: a first frame is synthesised again, s.preroll times, as a later frame whose previous output is its own
    // last result moved by its own motion (F^t; none when there is no motion). Synthesis under the temporal term
    // settles within about 5 frames to a look a little softer than a frame made without it (docs/stylize.md); the
    // pre-roll starts the shot in that state, so frame 2 does not step away from frame 1.
    const TargetGuides* finalGuides = &g;
    TargetGuides held;
    st.shotStart = first;
    if (first && s.preroll > 0 && s.lambda > 0.0f) {
        st.preroll = s.preroll;
        const ChannelImage still(W, H, 2);
        StylizeFrame f = frame;
        f.motionIn = frame.motionOut ? frame.motionOut : &still;
        for (int k = 1; k <= s.preroll; ++k) {
            held = targetGuides(f, current, false, s, st);
            // Seeds of their own per pre-roll step.
            current = synthesizePyramid(
                held, e, false, levels, r, s, frameKey ^ (0x9E3779B97F4A7C15ull * std::uint64_t(k)), c, st, progress);
        }
        finalGuides = &held;
    }

    // Statistics of the frame, then the output.
    auto ts = Clock::now();
    matchStats(c, st);
    appearanceStats(current, *finalGuides, e, *frame.exemplar, s, st);
    shapeStats(current, *finalGuides, first, st);
    st.secondsStats = since(ts);

    mPrevious = current;
    ++mFrames;
    ChannelImage shown = current;
    if (s.motionBlur > 0.0f && frame.motionOut) {
        MotionBlurSettings mb;
        mb.shutter = s.motionBlur;
        shown = motionBlur(current, *frame.motionOut, mb);
    }
    out.image = straightRgba(shown, frame.exemplar->colorSpace);
    return out;
}

} // namespace turb
