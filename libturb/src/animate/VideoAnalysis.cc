#include <turb/VideoAnalysis.h>

#include "CvOps.h"
#include "Rbf.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace turb {

void validate(const AnalysisSettings& s)
{
    if (s.features < 1) throw ValueError("analysis: features must be >= 1");
    if (s.window < 3 || s.window > 64) throw ValueError("analysis: the Lucas-Kanade window must be 3..64 pixels");
    if (s.levels < 0 || s.levels > 6) throw ValueError("analysis: Lucas-Kanade levels must be 0..6");
    if (!(s.maxRoundTrip > 0.0)) throw ValueError("analysis: the round-trip tolerance must be > 0");
    if (s.rbfStep < 1 || s.rbfStep > 16) throw ValueError("analysis: the RBF evaluation step must be 1..16 pixels");
}

ChannelImage luminance(const ChannelImage& img)
{
    ChannelImage y(img.width(), img.height(), 1);
    const int C = img.channels();
    for (size_t i = 0; i < img.pixelCount(); ++i) {
        const float* p = img.pixel(i);
        y.pixel(i)[0] = C >= 3 ? 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2] : p[0];
    }
    return y;
}

ChannelImage warpByFlow(const ChannelImage& image, const ChannelImage& flow)
{
    if (!flow.sameSize(image)) throw ValueError("warpByFlow: the flow and the image differ in size");
    return cv::FlowWarp(flow).apply(image);
}

namespace {

constexpr double kStillSigma = 1e-4; // rms difference from the mean below which a sequence counts as still
constexpr size_t kPairGrain = 8;     // pairs summed per chunk; fixed, so the float sums do not depend on threads

void checkFrames(const std::vector<ChannelImage>& frames)
{
    if (frames.size() < 2)
        throw ValueError("the video example needs at least 2 frames, got " + std::to_string(frames.size()));
    const ChannelImage& f0 = frames.front();
    if (f0.width() < 8 || f0.height() < 8) throw ValueError("the video example frames must be at least 8x8 pixels");
    if (f0.channels() < 1 || f0.channels() > 4) throw ValueError("the video example frames must have 1 to 4 channels");
    for (size_t i = 1; i < frames.size(); ++i)
        if (!frames[i].sameSize(f0) || frames[i].channels() != f0.channels())
            throw ValueError("video example frame " + std::to_string(i) + " is " + std::to_string(frames[i].width()) +
                             "x" + std::to_string(frames[i].height()) + "x" + std::to_string(frames[i].channels()) +
                             ", frame 0 is " + std::to_string(f0.width()) + "x" + std::to_string(f0.height()) + "x" +
                             std::to_string(f0.channels()));
}

double medianOf(std::vector<double> v)
{
    if (v.empty()) return 0.0;
    const size_t m = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(m), v.end());
    return v[m];
}

/// Drops tracks that disagree with their neighbours: r = |d - median of the 8 nearest tracks' d|, kept
/// when r <= max(0.5 px, 4 x the median r). Lucas-Kanade slides along edges (the aperture problem) and
/// locks onto features that appear or vanish; one such track would spread over its neighbourhood.
std::vector<cv::Track> consistentTracks(const std::vector<cv::Track>& t)
{
    if (t.size() < 5) return t;
    const size_t k = std::min<size_t>(8, t.size() - 1);
    std::vector<double> r(t.size());
    std::vector<std::pair<double, size_t>> near(t.size());
    for (size_t i = 0; i < t.size(); ++i) {
        for (size_t j = 0; j < t.size(); ++j) near[j] = {std::hypot(t[j].x - t[i].x, t[j].y - t[i].y), j};
        std::partial_sort(near.begin(), near.begin() + std::ptrdiff_t(k + 1), near.end());
        std::vector<double> dx, dy;
        for (size_t n = 1; n <= k; ++n) { // near[0] is the track itself
            dx.push_back(t[near[n].second].dx);
            dy.push_back(t[near[n].second].dy);
        }
        r[i] = std::hypot(t[i].dx - medianOf(dx), t[i].dy - medianOf(dy));
    }
    const double limit = std::max(0.5, 4.0 * medianOf(r));
    std::vector<cv::Track> kept;
    for (size_t i = 0; i < t.size(); ++i)
        if (r[i] <= limit) kept.push_back(t[i]);
    return kept;
}

/// The mean of the frames, in double per pixel.
ChannelImage meanImage(const std::vector<ChannelImage>& frames)
{
    ChannelImage A(frames[0].width(), frames[0].height(), frames[0].channels());
    const size_t n = A.data().size();
    parallelFor(n, 4096, [&](size_t b, size_t e) {
        for (size_t k = b; k < e; ++k) {
            double s = 0.0;
            for (const ChannelImage& f : frames) s += f.data()[k];
            A.data()[k] = float(s / double(frames.size()));
        }
    });
    return A;
}

/// The consistent Lucas-Kanade tracks of each consecutive pair of `diffs` (section 4.2), per pair.
std::vector<std::vector<cv::Track>> trackPairs(
    const std::vector<ChannelImage>& diffs, const AnalysisSettings& s, Progress* progress)
{
    const int W = diffs[0].width(), H = diffs[0].height();
    const size_t N = diffs.size();
    std::vector<ChannelImage> gray(N);
    parallelFor(N, 1, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) gray[i] = luminance(diffs[i]);
    });
    double sum2 = 0.0;
    for (const ChannelImage& g : gray)
        for (float v : g.data()) sum2 += double(v) * v;
    const double sigma = std::sqrt(sum2 / (double(N) * double(W) * double(H)));
    std::vector<std::vector<cv::Track>> tracks(N - 1);
    // A still sequence: nothing moves. The tracker rescales the differences to +-3 sigma, so a floor keeps it from
    // following changes far below what an image shows (1e-4 is 1/40 of an 8-bit level).
    if (!(sigma > kStillSigma)) return tracks;
    const float scale = float(40.0 / sigma); // +-3 sigma over +-120 grey levels
    std::vector<cv::TrackFrame> frames(N);
    parallelFor(N, 1, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) frames[i] = cv::toTrackFrame(gray[i], scale);
    });
    gray.clear();
    cv::TrackSettings ts;
    ts.features = s.features;
    ts.window = s.window;
    ts.levels = s.levels;
    ts.maxRoundTrip = s.maxRoundTrip;
    ts.minDistance = std::max(3.0, std::min(W, H) / 40.0);
    if (progress) progress->begin("flow");
    parallelFor(N - 1, 1, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            checkCancelled(progress);
            tracks[i] = consistentTracks(cv::trackFeatures(frames[i], frames[i + 1], ts));
        }
    });
    return tracks;
}

/// The frames less their own mean A (eq. 1's D_i), in place; A into `average` when given.
std::vector<ChannelImage> differencesFromMean(std::vector<ChannelImage> frames, ChannelImage* average = nullptr)
{
    const ChannelImage A = meanImage(frames);
    for (ChannelImage& f : frames) {
        float* d = f.data().data();
        const float* a = A.data().data();
        parallelFor(f.data().size(), 1 << 14, [&](size_t b, size_t e) {
            for (size_t q = b; q < e; ++q) d[q] -= a[q];
        });
    }
    if (average) *average = A;
    return frames;
}

/// The tracks of every pair, in pair order.
std::vector<FlowTrack> flowTracks(const std::vector<std::vector<cv::Track>>& pairs)
{
    std::vector<FlowTrack> out;
    for (size_t i = 0; i < pairs.size(); ++i)
        for (const cv::Track& t : pairs[i]) out.push_back(FlowTrack{int(i), t.x, t.y, t.dx, t.dy});
    return out;
}

/// Sparse Lucas-Kanade flow of each consecutive pair, interpolated with phi = r and averaged (4.2).
ChannelImage trackedMeanFlow(const std::vector<ChannelImage>& diffs, const AnalysisSettings& s, AnalysisStats& stats,
    Progress* progress, std::vector<FlowTrack>* tracksOut = nullptr)
{
    const int W = diffs[0].width(), H = diffs[0].height();
    const std::vector<std::vector<cv::Track>> tracks = trackPairs(diffs, s, progress);
    if (tracksOut) *tracksOut = flowTracks(tracks);
    const size_t pairs = tracks.size(), chunks = (pairs + kPairGrain - 1) / kPairGrain;
    stats.pairs = int(pairs);
    std::vector<ChannelImage> chunkSum(chunks);
    parallelFor(pairs, kPairGrain, [&](size_t b, size_t e) {
        ChannelImage acc(W, H, 2);
        for (size_t i = b; i < e; ++i) {
            const std::vector<cv::Track>& t = tracks[i];
            if (t.empty()) continue;
            std::vector<rbf::Sample> samples;
            samples.reserve(t.size());
            for (const cv::Track& k : t)
                samples.push_back(rbf::Sample{k.x + 0.5 * k.dx, k.y + 0.5 * k.dy, {double(k.dx), double(k.dy)}});
            rbf::Interpolant f;
            f.fit(std::move(samples));
            const ChannelImage v = f.render(W, H, s.rbfStep);
            for (size_t q = 0; q < acc.data().size(); ++q) acc.data()[q] += v.data()[q];
        }
        chunkSum[b / kPairGrain] = std::move(acc);
    });
    ChannelImage flow(W, H, 2);
    for (const ChannelImage& c : chunkSum)
        if (!c.empty())
            for (size_t q = 0; q < flow.data().size(); ++q) flow.data()[q] += c.data()[q];
    int nUsed = 0, nTracks = 0;
    double speedSum = 0.0;
    for (const auto& t : tracks) {
        nUsed += t.empty() ? 0 : 1;
        nTracks += int(t.size());
        for (const cv::Track& k : t) speedSum += std::hypot(k.dx, k.dy);
    }
    stats.trackSpeed = nTracks ? speedSum / nTracks : 0.0;
    stats.pairsUsed = nUsed;
    stats.tracksPerPair = nUsed ? double(nTracks) / nUsed : 0.0;
    if (nUsed > 0)
        for (float& v : flow.data()) v /= float(nUsed);
    return flow;
}

/// Mean |v| over the pixels that move: |v| >= 10% of the 99th percentile (a cache's background and a
/// video's still parts would dilute the speed a stroke fetches).
double meanSpeed(const ChannelImage& flow)
{
    std::vector<float> s(flow.pixelCount());
    for (size_t i = 0; i < s.size(); ++i) s[i] = std::hypot(flow.pixel(i)[0], flow.pixel(i)[1]);
    if (s.empty()) return 0.0;
    std::vector<float> sorted = s;
    const size_t k = std::min(sorted.size() - 1, size_t(0.99 * double(sorted.size())));
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(k), sorted.end());
    const float floor = 0.1f * sorted[k];
    double sum = 0.0;
    size_t n = 0;
    for (float v : s)
        if (v >= floor && v > 0.0f) {
            sum += v;
            ++n;
        }
    return n ? sum / double(n) : 0.0;
}

} // namespace

ChannelImage estimateMeanFlow(const std::vector<ChannelImage>& frames, const AnalysisSettings& settings,
    AnalysisStats* stats, Progress* progress, std::vector<FlowTrack>* tracks)
{
    validate(settings);
    checkFrames(frames);
    AnalysisStats st;
    ChannelImage v = trackedMeanFlow(differencesFromMean(frames), settings, st, progress, tracks);
    st.meanSpeed = st.trackSpeed > 0.0 ? st.trackSpeed : meanSpeed(v);
    if (stats) *stats = st;
    return v;
}

std::vector<FlowTrack> trackFlow(
    const std::vector<ChannelImage>& frames, const AnalysisSettings& settings, Progress* progress)
{
    validate(settings);
    checkFrames(frames);
    return flowTracks(trackPairs(differencesFromMean(frames), settings, progress));
}

namespace {

/// The rms of the residuals R_i = D_{i+1} - W(D_i) that `flow` leaves (eq. 1), over all pairs and channels; with
/// `write`, each R_i replaces D_i (the last difference is then no longer needed). The rms of D_{i+1} - D_i into
/// `rmsDifference` when given.
double residualRms(std::vector<ChannelImage>& diffs, const ChannelImage& flow, bool write, Progress* progress,
    double* rmsDifference = nullptr)
{
    const cv::FlowWarp warp(flow);
    ChannelImage moved;
    double sumDiff = 0.0, sumRes = 0.0;
    const size_t pairs = diffs.size() - 1;
    for (size_t i = 0; i < pairs; ++i) {
        checkCancelled(progress);
        if (progress) progress->update(double(i) / double(pairs));
        warp.apply(diffs[i], moved);
        std::vector<float>& d = diffs[i].data();
        const std::vector<float>& next = diffs[i + 1].data();
        const size_t n = d.size();
        if (rmsDifference)
            sumDiff += parallelSum(n, 1 << 14, [&](size_t b, size_t e) {
                double s = 0.0;
                for (size_t q = b; q < e; ++q) s += double(next[q] - d[q]) * double(next[q] - d[q]);
                return s;
            });
        sumRes += parallelSum(n, 1 << 14, [&](size_t b, size_t e) {
            double s = 0.0;
            for (size_t q = b; q < e; ++q) {
                const float r = next[q] - moved.data()[q];
                if (write) d[q] = r;
                s += double(r) * double(r);
            }
            return s;
        });
    }
    const double count = double(pairs) * double(diffs[0].data().size());
    if (rmsDifference) *rmsDifference = std::sqrt(sumDiff / count);
    return std::sqrt(sumRes / count);
}

/// v for the differences `diffs` (section 4.2, or the given flow as settings.givenFlow says), into ex.flow/stats.
void chooseFlow(std::vector<ChannelImage>& diffs, const ChannelImage* given, const AnalysisSettings& s,
    ExampleDecomposition& ex, Progress* progress)
{
    const int W = diffs[0].width(), H = diffs[0].height();
    if (given && (given->channels() != 2 || given->width() != W || given->height() != H))
        throw ValueError(
            "the given example flow must be a 2-channel " + std::to_string(W) + "x" + std::to_string(H) + " image");
    ex.stats.pairs = int(diffs.size()) - 1;
    if (given && s.givenFlow == GivenFlow::Use) {
        ex.flow = *given;
        ex.stats.flowGiven = true;
        return;
    }
    ex.flow = trackedMeanFlow(diffs, s, ex.stats, progress);
    if (!given || s.givenFlow == GivenFlow::Track) return;
    // The flow that explains the video better, by the decomposition's own measure (ties keep the given flow).
    if (progress) progress->begin("flow check");
    ex.stats.rmsResidualGiven = residualRms(diffs, *given, false, progress);
    ex.stats.rmsResidualTracked = residualRms(diffs, ex.flow, false, progress);
    if (ex.stats.rmsResidualGiven <= ex.stats.rmsResidualTracked) {
        ex.flow = *given;
        ex.stats.flowGiven = true;
    }
}

} // namespace

ExampleDecomposition decomposeExample(std::vector<ChannelImage> frames, const AnalysisSettings& settings,
    Progress* progress, const ChannelImage* givenFlow)
{
    validate(settings);
    checkFrames(frames);
    ExampleDecomposition ex;
    if (progress) progress->begin("average");
    frames = differencesFromMean(std::move(frames), &ex.average);
    chooseFlow(frames, givenFlow, settings, ex, progress);
    ex.stats.meanSpeed = !ex.stats.flowGiven && ex.stats.trackSpeed > 0.0 ? ex.stats.trackSpeed : meanSpeed(ex.flow);

    // Residuals (eq. 1), written over the differences they no longer need: R_i replaces D_i.
    if (progress) progress->begin("residuals");
    ex.first = frames[0];
    ex.stats.rmsResidual = residualRms(frames, ex.flow, true, progress, &ex.stats.rmsDifference);
    frames.pop_back();
    ex.residuals = std::move(frames);
    return ex;
}

std::vector<ChannelImage> reconstructExample(const ExampleDecomposition& ex)
{
    std::vector<ChannelImage> out;
    if (ex.first.empty()) return out;
    const cv::FlowWarp warp(ex.flow);
    ChannelImage d = ex.first, moved;
    out.reserve(ex.residuals.size() + 1);
    for (size_t i = 0;; ++i) {
        ChannelImage f = d;
        for (size_t q = 0; q < f.data().size(); ++q) f.data()[q] += ex.average.data()[q];
        out.push_back(std::move(f));
        if (i == ex.residuals.size()) break;
        warp.apply(d, moved);
        for (size_t q = 0; q < d.data().size(); ++q) d.data()[q] = moved.data()[q] + ex.residuals[i].data()[q];
    }
    return out;
}

} // namespace turb
