#include <turb/Animate.h>

#include "CvOps.h"

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Warp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <string>

namespace turb {

void validate(const AnimateSettings& s)
{
    validate(s.analysis);
    validate(s.refine);
    validate(s.transfer);
    validate(s.hm);
    if (s.tau < 1) throw ValueError("animate: tau must be >= 1");
    if (!(s.average.shutter >= 0.0) || s.average.shutter > 200.0)
        throw ValueError("animate: the shutter Sh must be in [0, 200] frames");
    if (!(s.average.wa >= 0.0) || s.average.wa > 500.0) throw ValueError("animate: w_a must be in [0, 500] pixels");
    if (s.batch < 1) throw ValueError("animate: batch must be >= 1");
}

namespace {

ChannelImage blurAlong(const ChannelImage& img, const ChannelImage& flow, const AverageSettings& s)
{
    ChannelImage a = img;
    if (s.shutter > 0.0) {
        double vmax = 0.0;
        for (size_t i = 0; i < flow.pixelCount(); ++i)
            vmax = std::max(vmax, double(std::hypot(flow.pixel(i)[0], flow.pixel(i)[1])));
        MotionBlurSettings mb;
        mb.shutter = float(s.shutter);
        mb.maxSamples = std::clamp(int(std::ceil(s.shutter * vmax)) + 1, 3, 129);
        a = motionBlur(img, flow, mb);
    }
    if (s.wa > 0.0) a = cv::gaussian(a, 2 * int(std::ceil(3.0 * s.wa)) + 1, s.wa);
    return a;
}

/// Matte-weighted sums of one channel's values, for eq. 8's means and standard deviations.
struct WeightedMoments
{
    double w = 0.0, s = 0.0, s2 = 0.0;
    void add(double m, double v)
    {
        w += m;
        s += m * v;
        s2 += m * v * v;
    }
    double mean() const { return w > 0 ? s / w : 0.0; }
    double stddev() const
    {
        const double mc = mean();
        return w > 0 ? std::sqrt(std::max(0.0, s2 / w - mc * mc)) : 0.0;
    }
};

} // namespace

ChannelImage approximateAverage(
    const ChannelImage& target, const ChannelImage& flow, const AverageSettings& s, const ChannelImage* matte)
{
    if (!flow.sameSize(target) || flow.channels() != 2)
        throw ValueError("approximateAverage: the flow must be a 2-channel image of the target's size");
    if (!matte) return blurAlong(target, flow, s);
    if (!matte->sameSize(target) || matte->channels() != 1)
        throw ValueError("approximateAverage: the matte must be a 1-channel image of the target's size");
    // Normalised blur of the fluid alone: blur(m T) / blur(m), so the still parts around the fluid do not
    // bleed into its average (pixels the blurred matte does not reach keep the target).
    const int C = target.channels();
    ChannelImage mt(target.width(), target.height(), C), m(target.width(), target.height(), 1);
    for (size_t i = 0; i < target.pixelCount(); ++i) {
        m.pixel(i)[0] = std::clamp(matte->pixel(i)[0], 0.0f, 1.0f);
        for (int c = 0; c < C; ++c) mt.pixel(i)[c] = m.pixel(i)[0] * target.pixel(i)[c];
    }
    const ChannelImage b = blurAlong(mt, flow, s), bw = blurAlong(m, flow, s);
    ChannelImage a = target;
    for (size_t i = 0; i < a.pixelCount(); ++i) {
        const float w = bw.pixel(i)[0];
        if (w > 1e-4f)
            for (int c = 0; c < C; ++c) a.pixel(i)[c] = b.pixel(i)[c] / w;
    }
    return a;
}

// ---------------------------------------------------------------------------------------------

struct DifferenceSynthesizer::Impl
{
    cv::FlowWarp warp;
    std::deque<ChannelImage> terms; // W'^{age}(R'_k), oldest first
};

DifferenceSynthesizer::DifferenceSynthesizer(const ChannelImage& flow, int tau)
    : mImpl(std::make_unique<Impl>()), mTau(tau)
{
    if (tau < 1) throw ValueError("DifferenceSynthesizer: tau must be >= 1");
    mImpl->warp = cv::FlowWarp(flow);
}

DifferenceSynthesizer::~DifferenceSynthesizer() = default;

ChannelImage DifferenceSynthesizer::push(const ChannelImage& residual)
{
    auto& terms = mImpl->terms;
    // Every live term ages by one warp; the new residual enters with W'^0 (eq. 7).
    parallelFor(terms.size(), 1, [&](size_t b, size_t e) {
        for (size_t k = b; k < e; ++k) {
            ChannelImage moved;
            mImpl->warp.apply(terms[k], moved);
            terms[k] = std::move(moved);
        }
    });
    terms.push_back(residual);
    if (int(terms.size()) > mTau) terms.pop_front();
    ++mPushed;
    if (mPushed < mTau) return ChannelImage();
    ChannelImage d(residual.width(), residual.height(), residual.channels());
    const size_t n = d.data().size();
    parallelFor(n, 1 << 14, [&](size_t b, size_t e) {
        for (const ChannelImage& t : terms)
            for (size_t q = b; q < e; ++q) d.data()[q] += t.data()[q];
    });
    return d;
}

// ---------------------------------------------------------------------------------------------

void ContrastAdjustment::apply(ChannelImage& d) const
{
    const int C = d.channels();
    for (size_t i = 0; i < d.pixelCount(); ++i) {
        float* p = d.pixel(i);
        for (int c = 0; c < C; ++c) p[c] = float((p[c] - mean[size_t(c)]) * alpha[size_t(c)] + beta[size_t(c)]);
    }
}

ContrastAdjustment contrastAdjustment(
    const std::vector<ChannelImage>& diffs, const ChannelImage& cimg, const ChannelImage* matte)
{
    const int C = cimg.channels();
    ContrastAdjustment a;
    a.mean.assign(size_t(C), 0.0);
    a.alpha.assign(size_t(C), 0.0);
    a.beta.assign(size_t(C), 0.0);
    a.sigmaD.assign(size_t(C), 0.0);
    a.sigmaC.assign(size_t(C), 0.0);
    const auto weight = [&](size_t i) { return matte ? double(std::clamp(matte->pixel(i)[0], 0.0f, 1.0f)) : 1.0; };
    for (int c = 0; c < C; ++c) {
        WeightedMoments still, differences;
        for (size_t i = 0; i < cimg.pixelCount(); ++i) still.add(weight(i), cimg.pixel(i)[c]);
        a.beta[size_t(c)] = still.mean();
        a.sigmaC[size_t(c)] = still.stddev();
        for (const ChannelImage& d : diffs) {
            if (!d.sameSize(cimg) || d.channels() != C)
                throw ValueError("contrastAdjustment: a difference image does not match C");
            for (size_t i = 0; i < d.pixelCount(); ++i) differences.add(weight(i), d.pixel(i)[c]);
        }
        a.mean[size_t(c)] = differences.mean();
        a.sigmaD[size_t(c)] = differences.stddev();
        a.alpha[size_t(c)] = a.sigmaD[size_t(c)] > 0.0 ? a.sigmaC[size_t(c)] / a.sigmaD[size_t(c)] : 0.0;
    }
    return a;
}

// ---------------------------------------------------------------------------------------------

namespace {

double since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// out = m img + (1 - m) target, in place.
void composite(ChannelImage& img, const ChannelImage& target, const ChannelImage* matte)
{
    if (!matte) return;
    const int C = img.channels();
    for (size_t i = 0; i < img.pixelCount(); ++i) {
        const float m = std::clamp(matte->pixel(i)[0], 0.0f, 1.0f);
        float* p = img.pixel(i);
        const float* t = target.pixel(i);
        for (int c = 0; c < C; ++c) p[c] = m * p[c] + (1.0f - m) * t[c];
    }
}

double relative(double a, double b, double floor) { return std::abs(a - b) / std::max(std::abs(b), floor); }

/// Mean and std errors of a frame against the target, whole image and worst cell.
void frameErrors(AnimatedFrame& f, const ChannelImage& target, const std::vector<HmCell>& cells)
{
    const int C = target.channels(), W = target.width(), H = target.height();
    for (int c = 0; c < C; ++c) {
        const MeanStd o = meanStd(f.image, c, 0, 0, W, H), t = meanStd(target, c, 0, 0, W, H);
        f.meanError = std::max(f.meanError, relative(o.mean, t.mean, 0.01));
        f.stdError = std::max(f.stdError, relative(o.std, t.std, 0.01));
        for (const HmCell& cell : cells) {
            const MeanStd oc = meanStd(f.image, c, cell.x0, cell.y0, cell.x1, cell.y1);
            const MeanStd tc = meanStd(target, c, cell.x0, cell.y0, cell.x1, cell.y1);
            f.cellMeanError = std::max(f.cellMeanError, relative(oc.mean, tc.mean, 0.01));
            f.cellStdError = std::max(f.cellStdError, relative(oc.std, tc.std, 0.01));
        }
    }
}

void checkInput(const AnimateInput& in, const AnimateSettings& s)
{
    if (int(in.exampleFrames.size()) < s.tau + 2)
        throw ValueError("the video example has " + std::to_string(in.exampleFrames.size()) + " frames; tau = " +
                         std::to_string(s.tau) + " needs at least tau + 2 = " + std::to_string(s.tau + 2));
    if (in.target.empty()) throw ValueError("the target image is empty");
    if (in.target.channels() != in.exampleFrames.front().channels())
        throw ValueError("the target has " + std::to_string(in.target.channels()) + " channels, the example " +
                         std::to_string(in.exampleFrames.front().channels()));
    if (!in.strokes && !in.designedFlow)
        throw ValueError("the target has no flow design: give strokes or a dense flow");
    if (in.strokes && in.designedFlow) throw ValueError("give either strokes or a dense flow, not both");
    if (in.designedFlow && (!in.designedFlow->sameSize(in.target) || in.designedFlow->channels() != 2))
        throw ValueError("the designed flow must be a 2-channel image of the target's size (" +
                         std::to_string(in.target.width()) + "x" + std::to_string(in.target.height()) + ")");
    if (in.matte && (!in.matte->sameSize(in.target) || in.matte->channels() != 1))
        throw ValueError("the matte must be a 1-channel image of the target's size");
}

/// Step 2 (sections 3.1, 5.1): the designed flow from the strokes (or the given dense flow), refined along the
/// target's edges when asked; fills designMeanSpeed, the matte-weighted mean |flow| in pixels per frame.
ChannelImage designFlow(
    const AnimateInput& in, double exampleSpeed, const AnimateSettings& s, const InspectFn& inspect, AnimateStats& st)
{
    const ChannelImage* matte = in.matte;
    RoughFlow rough;
    if (in.strokes) {
        StrokeSettings ss = s.strokes;
        ss.defaultSpeed = exampleSpeed;
        rough = interpolateStrokes(*in.strokes, in.target.width(), in.target.height(), ss);
    } else {
        rough = roughFromFlow(*in.designedFlow);
    }
    ChannelImage flow;
    if (s.refineFlow) {
        RefinedFlow refined = refineFlow(in.target, rough, s.refine);
        if (inspect) inspect("gradient", -1, refined.gradient);
        flow = std::move(refined.flow);
    } else {
        flow = rough.flow();
    }
    double sum = 0.0, w = 0.0;
    for (size_t i = 0; i < flow.pixelCount(); ++i) {
        const double m = matte ? matte->pixel(i)[0] : 1.0;
        sum += m * std::hypot(flow.pixel(i)[0], flow.pixel(i)[1]);
        w += m;
    }
    st.designMeanSpeed = w > 0.0 ? sum / w : 0.0;
    if (inspect) {
        inspect("rough", -1, rough.flow());
        inspect("refined", -1, flow);
    }
    return flow;
}

/// Step 5 (eq. 7), incrementally: every example residual transferred (R'_k) and accumulated along the designed
/// flow; returns the N - tau differences D'_i. The example's residuals are released as they are used.
std::vector<ChannelImage> synthesizeDifferences(ExampleDecomposition& ex, const TransferMap& map,
    const ChannelImage& flow, int tau, const InspectFn& inspect, Progress* progress)
{
    std::vector<ChannelImage> diffs;
    DifferenceSynthesizer synth(flow, tau);
    ex.first = ChannelImage();
    for (size_t k = 0; k < ex.residuals.size(); ++k) {
        checkCancelled(progress);
        if (progress) progress->update(double(k) / double(ex.residuals.size()));
        ChannelImage rk = map.apply(ex.residuals[k]);
        ex.residuals[k] = ChannelImage(); // the example's residual is no longer needed
        if (inspect) inspect("Rprime", int(k), rk);
        ChannelImage d = synth.push(rk);
        if (!d.empty()) diffs.push_back(std::move(d));
    }
    return diffs;
}

/// What step 6 composes every frame from.
struct FrameAssembly
{
    const ChannelImage& target;
    const ChannelImage* matte;
    const ChannelImage& average;      ///< A'
    const HistogramMatcher* matcher;  ///< null without histogram matching
    const ChannelImage* correction;   ///< HmApply::Sequence: HM(mean frame) - mean frame, added to every frame
    const std::vector<HmCell>& cells; ///< the matcher's cells, or none
    int tau;
};

/// Frame `index`: A' + D''_i composited into the target through the matte, histogram-matched, composited again, and
/// its errors against the target. Consumes `d`.
AnimatedFrame assembleFrame(ChannelImage& d, size_t index, const FrameAssembly& a)
{
    const auto tf = std::chrono::steady_clock::now();
    for (size_t q = 0; q < d.data().size(); ++q) d.data()[q] += a.average.data()[q];
    composite(d, a.target, a.matte);
    AnimatedFrame f;
    f.index = int(index);
    f.exampleIndex = int(index) + a.tau;
    if (a.correction) {
        for (size_t q = 0; q < d.data().size(); ++q) d.data()[q] += a.correction->data()[q];
        composite(d, a.target, a.matte);
        f.image = a.matcher->matchMoments(d);
    } else {
        f.image = a.matcher ? a.matcher->match(d) : std::move(d);
    }
    composite(f.image, a.target, a.matte);
    d = ChannelImage();
    frameErrors(f, a.target, a.cells);
    f.seconds = since(tf);
    return f;
}

/// HmApply::Sequence: HM(F) - F for the mean frame F = A' + mean_i D''_i, composited into the target.
ChannelImage sequenceCorrection(const std::vector<ChannelImage>& diffs, const ChannelImage& Aprime,
    const AnimateInput& in, const HistogramMatcher& hm)
{
    ChannelImage mean = Aprime;
    const size_t n = mean.data().size();
    parallelFor(n, 1 << 14, [&](size_t b, size_t e) {
        for (size_t q = b; q < e; ++q) {
            double sum = 0.0;
            for (const ChannelImage& d : diffs) sum += d.data()[q];
            mean.data()[q] += float(sum / double(diffs.size()));
        }
    });
    composite(mean, in.target, in.matte);
    ChannelImage c = hm.match(mean);
    for (size_t q = 0; q < n; ++q) c.data()[q] -= mean.data()[q];
    return c;
}

/// Step 6 (section 5.6): eq. 8's contrast adjustment and histogram matching, frames in parallel batches, delivered
/// to `sink` in order. Returns the seconds spent, the matcher's set-up included.
double matchAndDeliver(std::vector<ChannelImage>& diffs, const ContrastAdjustment& adj, const ChannelImage& Aprime,
    const AnimateInput& in, const AnimateSettings& s, const std::function<void(const AnimatedFrame&)>& sink,
    const InspectFn& inspect, AnimateStats& st, Progress* progress)
{
    const auto t0 = std::chrono::steady_clock::now();
    std::unique_ptr<HistogramMatcher> hm;
    if (s.histogramMatch) {
        hm = std::make_unique<HistogramMatcher>(in.target, s.hm, in.matte);
        st.gridCols = hm->gridCols();
        st.gridRows = hm->gridRows();
    }
    const std::vector<HmCell> noCells;
    const size_t count = diffs.size();
    for (size_t j = 0; j < count; ++j) {
        adj.apply(diffs[j]);
        if (inspect) inspect("Dsecond", int(j), diffs[j]);
    }
    std::optional<ChannelImage> correction;
    if (hm && s.hmApply == HmApply::Sequence) correction = sequenceCorrection(diffs, Aprime, in, *hm);
    const FrameAssembly assembly{
        in.target, in.matte, Aprime, hm.get(), correction ? &*correction : nullptr, hm ? hm->cells() : noCells, s.tau};
    double matching = since(t0); // the target's pyramids and tables (and the sequence's correction)
    for (size_t b0 = 0; b0 < count; b0 += size_t(s.batch)) {
        checkCancelled(progress);
        if (progress) progress->update(double(b0) / double(count));
        const auto tb = std::chrono::steady_clock::now();
        const size_t b1 = std::min(count, b0 + size_t(s.batch));
        std::vector<AnimatedFrame> out(b1 - b0);
        parallelFor(b1 - b0, 1, [&](size_t j0, size_t j1) {
            for (size_t j = j0; j < j1; ++j) {
                checkCancelled(progress);
                out[j] = assembleFrame(diffs[b0 + j], b0 + j, assembly);
            }
        });
        matching += since(tb);
        for (AnimatedFrame& f : out) sink(f);
    }
    return matching;
}

} // namespace

AnimateStats animate(AnimateInput in, const AnimateSettings& s, const std::function<void(const AnimatedFrame&)>& sink,
    Progress* progress, const InspectFn& inspect)
{
    validate(s);
    checkInput(in, s);
    AnimateStats st;
    const ChannelImage& target = in.target;
    const ChannelImage* matte = in.matte;
    if (in.strokes) validateStrokes(*in.strokes, target.width(), target.height());
    if (in.clones)
        validateCloneStrokes(*in.clones, in.exampleFrames.front().width(), in.exampleFrames.front().height(),
            target.width(), target.height(), s.clone);

    // 1. Decomposition (section 4).
    auto t0 = std::chrono::steady_clock::now();
    ExampleDecomposition ex = decomposeExample(std::move(in.exampleFrames), s.analysis, progress, in.exampleFlow);
    st.analysis = ex.stats;
    st.secondsAnalysis = since(t0);
    if (inspect) {
        inspect("A", -1, ex.average);
        inspect("v", -1, ex.flow);
        for (size_t k = 0; k < ex.residuals.size(); ++k) inspect("R", int(k), ex.residuals[k]);
    }
    checkCancelled(progress);

    // 2. Flow design (3.1, 5.1).
    t0 = std::chrono::steady_clock::now();
    if (progress) progress->begin("design");
    const ChannelImage flow = designFlow(in, ex.stats.meanSpeed, s, inspect, st);
    st.secondsDesign = since(t0);

    // 3. Residual transfer (5.2): one map for all frames; the Clone Brush (5.3) over it.
    t0 = std::chrono::steady_clock::now();
    TransferMap map = matchResiduals(ex.flow, flow, s.transfer, matte, progress);
    if (in.clones && !in.clones->empty()) {
        const ChannelImage cloneMatte = applyCloneStrokes(map, *in.clones, matte, s.clone);
        if (inspect) inspect("clone", -1, cloneMatte);
    }
    st.transfer = map.stats;
    st.secondsTransfer = since(t0);

    // 4. A' (5.4).
    t0 = std::chrono::steady_clock::now();
    if (progress) progress->begin("average");
    const ChannelImage Aprime = approximateAverage(target, flow, s.average, matte);
    if (inspect) inspect("Aprime", -1, Aprime);
    ChannelImage cimg = target;
    for (size_t q = 0; q < cimg.data().size(); ++q) cimg.data()[q] -= Aprime.data()[q];
    st.secondsAverage = since(t0);

    // 5. Eq. 7, incrementally; the N - tau differences are kept for eq. 8's global statistics.
    t0 = std::chrono::steady_clock::now();
    if (progress) progress->begin("synthesis");
    std::vector<ChannelImage> diffs = synthesizeDifferences(ex, map, flow, s.tau, inspect, progress);
    const ContrastAdjustment adj = contrastAdjustment(diffs, cimg, matte);
    st.alpha = adj.alpha;
    st.beta = adj.beta;
    st.meanD = adj.mean;
    st.sigmaD = adj.sigmaD;
    st.sigmaC = adj.sigmaC;
    st.frames = int(diffs.size());
    st.secondsSynthesis = since(t0);

    // 6. Histogram matching (5.6), frames in parallel batches, delivered in order.
    if (progress) progress->begin("histogram matching");
    st.secondsMatching = matchAndDeliver(diffs, adj, Aprime, in, s, sink, inspect, st, progress);
    return st;
}

} // namespace turb
