#include <turb/AnimateQuality.h>

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/VideoAnalysis.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace turb {

namespace {

double median(std::vector<double> v)
{
    if (v.empty()) return 0.0;
    const size_t m = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(m), v.end());
    if (v.size() % 2) return v[m];
    const double hi = v[m];
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(m - 1), v.end());
    return 0.5 * (hi + v[m - 1]);
}

} // namespace

namespace {

/// Accumulates the angle and speed ratio of measured displacements against the design.
struct Agreement
{
    std::vector<double> angles, ratios;
    void add(double mx, double my, double dx, double dy)
    {
        const double sd = std::hypot(dx, dy), sm = std::hypot(mx, my);
        const double c = sm > 0.0 ? (dx * mx + dy * my) / (sd * sm) : -1.0;
        angles.push_back(std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI);
        ratios.push_back(sm / sd);
    }
    FlowAgreement result(double total) const
    {
        FlowAgreement a;
        // Nothing compared is no figure, not a perfect one.
        a.medianAngleDeg = angles.empty() ? std::nan("") : median(angles);
        a.medianSpeedRatio = ratios.empty() ? std::nan("") : median(ratios);
        a.pixels = total > 0 ? double(angles.size()) / total : 0.0;
        return a;
    }
};

void checkDesign(const ChannelImage& designed, const ChannelImage* matte, const char* who)
{
    if (designed.channels() != 2) throw ValueError(std::string(who) + ": the design must be a 2-channel flow");
    if (matte && (!matte->sameSize(designed) || matte->channels() != 1))
        throw ValueError(std::string(who) + ": the matte must match the flows");
}

} // namespace

FlowAgreement compareFlows(
    const ChannelImage& measured, const ChannelImage& designed, const ChannelImage* matte, double minSpeed, int border)
{
    checkDesign(designed, matte, "compareFlows");
    if (measured.channels() != 2 || !measured.sameSize(designed))
        throw ValueError("compareFlows: needs two 2-channel flows of one size");
    Agreement a;
    const int W = designed.width(), H = designed.height();
    for (int y = border; y < H - border; ++y)
        for (int x = border; x < W - border; ++x) {
            if (matte && matte->at(x, y, 0) < 0.5f) continue;
            const float* d = designed.pixel(x, y);
            const float* m = measured.pixel(x, y);
            if (std::hypot(d[0], d[1]) < minSpeed) continue;
            a.add(m[0], m[1], d[0], d[1]);
        }
    return a.result(double(designed.pixelCount()));
}

FlowAgreement compareTracks(const std::vector<FlowTrack>& tracks, const ChannelImage& designed,
    const ChannelImage* matte, double minSpeed, int border)
{
    checkDesign(designed, matte, "compareTracks");
    Agreement a;
    const int W = designed.width(), H = designed.height();
    for (const FlowTrack& t : tracks) {
        // The design where the feature was half-way through its step: the step's own mid-point rule.
        const int x = int(std::lround(t.x + 0.5f * t.dx)), y = int(std::lround(t.y + 0.5f * t.dy));
        if (x < border || y < border || x >= W - border || y >= H - border) continue;
        if (matte && matte->at(x, y, 0) < 0.5f) continue;
        const float* d = designed.pixel(x, y);
        if (std::hypot(d[0], d[1]) < minSpeed) continue;
        a.add(t.dx, t.dy, d[0], d[1]);
    }
    return a.result(double(tracks.size()));
}

TemporalStats::TemporalStats(int maxLag, const ChannelImage* matte) : mLag(std::max(1, maxLag)), mMatte(matte) {}

void TemporalStats::add(const ChannelImage& frame)
{
    const ChannelImage y = luminance(frame);
    if (mFrames == 0) {
        mW = y.width();
        mH = y.height();
        const size_t n = y.pixelCount();
        mSum.assign(n, 0.0);
        mSum2.assign(n, 0.0);
        mLagSum.assign(size_t(mLag), std::vector<double>(n, 0.0));
        mHead.assign(size_t(mLag), std::vector<double>(n, 0.0));
    } else if (y.width() != mW || y.height() != mH) {
        throw ValueError("TemporalStats: frame " + std::to_string(mFrames) + " differs in size");
    }
    const size_t n = y.pixelCount();
    const std::vector<float>& v = y.data();
    parallelFor(n, 1 << 12, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            const double x = v[i];
            mSum[i] += x;
            mSum2[i] += x * x;
            // mRing.back() is the previous frame (lag 1), and so on.
            for (int L = 1; L <= mLag && L <= int(mRing.size()); ++L)
                mLagSum[size_t(L - 1)][i] += x * mRing[mRing.size() - size_t(L)][i];
            for (int L = mFrames + 1; L <= mLag; ++L) mHead[size_t(L - 1)][i] += x; // sum of the first L frames
        }
    });
    mRing.push_back(v);
    if (int(mRing.size()) > mLag) mRing.erase(mRing.begin());
    ++mFrames;
}

TemporalSummary TemporalStats::summary() const
{
    TemporalSummary s;
    s.frames = mFrames;
    s.autocorrelation.assign(size_t(mLag), std::nan("")); // lags the sequence is too short for stay NaN
    if (mFrames < 2) return s;
    const size_t n = mSum.size();
    const double T = mFrames;
    std::vector<double> acSum(size_t(mLag), 0.0);
    double stdSum = 0.0, count = 0.0, acCount = 0.0;
    for (size_t i = 0; i < n; ++i) {
        if (mMatte && mMatte->pixel(i)[0] < 0.5f) continue;
        const double mu = mSum[i] / T, var = std::max(0.0, mSum2[i] / T - mu * mu);
        stdSum += std::sqrt(var);
        count += 1.0;
        if (var <= 1e-12) continue;
        acCount += 1.0;
        double tail = 0.0; // sum of the last L frames, grown lag by lag
        for (int L = 1; L <= mLag; ++L) {
            if (L > mFrames - 1) break;
            tail += mRing[mRing.size() - size_t(L)][i];
            const double head = mHead[size_t(L - 1)][i];
            const double m = T - L;
            const double c = (mLagSum[size_t(L - 1)][i] - mu * ((mSum[i] - tail) + (mSum[i] - head)) + m * mu * mu) / m;
            acSum[size_t(L - 1)] += c / var;
        }
    }
    s.temporalStd = count > 0 ? stdSum / count : 0.0;
    for (int L = 1; L <= std::min(mLag, mFrames - 1); ++L)
        s.autocorrelation[size_t(L - 1)] = acCount > 0 ? acSum[size_t(L - 1)] / acCount : std::nan("");
    return s;
}

} // namespace turb
