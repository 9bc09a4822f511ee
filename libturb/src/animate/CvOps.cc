// The only translation unit of libturb that includes OpenCV (see CvOps.h).
#include "CvOps.h"

#include <turb/Error.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace turb::cv {

namespace {

/// A cv::Mat header over a ChannelImage's pixels (no copy).
::cv::Mat wrap(const ChannelImage& img)
{
    if (img.channels() < 1 || img.channels() > 4) throw ValueError("OpenCV image operations take 1 to 4 channels");
    return ::cv::Mat(img.height(), img.width(), CV_32FC(img.channels()), const_cast<float*>(img.data().data()));
}

ChannelImage fromMat(const ::cv::Mat& m)
{
    ChannelImage out(m.cols, m.rows, m.channels());
    ::cv::Mat dst(m.rows, m.cols, CV_32FC(m.channels()), out.data().data());
    m.convertTo(dst, CV_32F);
    return out;
}

} // namespace

ChannelImage gaussian(const ChannelImage& img, int ksize, double sigma)
{
    if (img.empty()) return img;
    const int k = std::max(1, ksize | 1);
    ChannelImage out(img.width(), img.height(), img.channels());
    ::cv::Mat dst = wrap(out);
    ::cv::GaussianBlur(wrap(img), dst, ::cv::Size(k, k), sigma, sigma, ::cv::BORDER_REFLECT_101);
    return out;
}

ChannelImage sobelGradient(const ChannelImage& gray)
{
    if (gray.channels() != 1) throw ValueError("sobelGradient: needs a 1-channel image");
    ::cv::Mat gx, gy;
    ::cv::Sobel(wrap(gray), gx, CV_32F, 1, 0, 3, 1.0 / 8.0, 0.0, ::cv::BORDER_REFLECT_101);
    ::cv::Sobel(wrap(gray), gy, CV_32F, 0, 1, 3, 1.0 / 8.0, 0.0, ::cv::BORDER_REFLECT_101);
    ChannelImage out(gray.width(), gray.height(), 2);
    for (int y = 0; y < gray.height(); ++y) {
        const float* a = gx.ptr<float>(y);
        const float* b = gy.ptr<float>(y);
        for (int x = 0; x < gray.width(); ++x) {
            out.at(x, y, 0) = a[x];
            out.at(x, y, 1) = b[x];
        }
    }
    return out;
}

// ---------------------------------------------------------------------------------------------

struct FlowWarp::Impl
{
    ::cv::Mat map1, map2; // fixed-point maps (CV_16SC2 + CV_16UC1): built once, fast to apply
};

FlowWarp::FlowWarp() = default;
FlowWarp::~FlowWarp() = default;
FlowWarp::FlowWarp(FlowWarp&&) noexcept = default;
FlowWarp& FlowWarp::operator=(FlowWarp&&) noexcept = default;

FlowWarp::FlowWarp(const ChannelImage& flow)
    : mImpl(std::make_unique<Impl>()), mWidth(flow.width()), mHeight(flow.height())
{
    if (flow.channels() != 2) throw ValueError("FlowWarp: the flow must have 2 channels");
    ::cv::Mat map(flow.height(), flow.width(), CV_32FC2);
    for (int y = 0; y < flow.height(); ++y) {
        float* row = map.ptr<float>(y);
        for (int x = 0; x < flow.width(); ++x) {
            const float* v = flow.pixel(x, y);
            // Backward mapping (Okabe eq. in 4.3): the value at x comes from x - v(x).
            row[2 * x] = float(x) - v[0];
            row[2 * x + 1] = float(y) - v[1];
        }
    }
    ::cv::convertMaps(map, ::cv::Mat(), mImpl->map1, mImpl->map2, CV_16SC2, false);
}

void FlowWarp::apply(const ChannelImage& in, ChannelImage& out) const
{
    if (!mImpl || in.width() != mWidth || in.height() != mHeight)
        throw ValueError("FlowWarp: image " + std::to_string(in.width()) + "x" + std::to_string(in.height()) +
                         " does not match the flow " + std::to_string(mWidth) + "x" + std::to_string(mHeight));
    if (&in == &out) throw ValueError("FlowWarp: in and out must differ");
    if (out.width() != mWidth || out.height() != mHeight || out.channels() != in.channels())
        out = ChannelImage(mWidth, mHeight, in.channels());
    ::cv::Mat dst = wrap(out);
    ::cv::remap(wrap(in), dst, mImpl->map1, mImpl->map2, ::cv::INTER_LINEAR, ::cv::BORDER_REPLICATE);
}

ChannelImage FlowWarp::apply(const ChannelImage& in) const
{
    ChannelImage out;
    apply(in, out);
    return out;
}

// ---------------------------------------------------------------------------------------------

TrackFrame toTrackFrame(const ChannelImage& gray, float scale)
{
    if (gray.channels() != 1) throw ValueError("toTrackFrame: needs a 1-channel image");
    TrackFrame f;
    f.width = gray.width();
    f.height = gray.height();
    f.pixels.resize(gray.pixelCount());
    for (size_t i = 0; i < f.pixels.size(); ++i) {
        const float v = 128.0f + scale * gray.pixel(i)[0];
        f.pixels[i] = std::uint8_t(std::clamp(std::lround(v), 0L, 255L));
    }
    return f;
}

std::vector<Track> trackFeatures(const TrackFrame& a, const TrackFrame& b, const TrackSettings& s)
{
    if (a.width != b.width || a.height != b.height) throw ValueError("trackFeatures: frames differ in size");
    std::vector<Track> tracks;
    if (a.width < 8 || a.height < 8) return tracks;
    const ::cv::Mat ma(a.height, a.width, CV_8UC1, const_cast<std::uint8_t*>(a.pixels.data()));
    const ::cv::Mat mb(b.height, b.width, CV_8UC1, const_cast<std::uint8_t*>(b.pixels.data()));
    std::vector<::cv::Point2f> p0, p1, back;
    ::cv::goodFeaturesToTrack(ma, p0, std::max(1, s.features), s.quality, s.minDistance);
    if (p0.empty()) return tracks;
    const ::cv::Size win(std::max(3, s.window), std::max(3, s.window));
    const ::cv::TermCriteria crit(::cv::TermCriteria::COUNT | ::cv::TermCriteria::EPS, 30, 0.01);
    std::vector<unsigned char> st1, st2;
    std::vector<float> e1, e2;
    ::cv::calcOpticalFlowPyrLK(ma, mb, p0, p1, st1, e1, win, std::max(0, s.levels), crit);
    ::cv::calcOpticalFlowPyrLK(mb, ma, p1, back, st2, e2, win, std::max(0, s.levels), crit);
    for (size_t i = 0; i < p0.size(); ++i) {
        if (!st1[i] || !st2[i]) continue;
        const double rt = std::hypot(double(back[i].x - p0[i].x), double(back[i].y - p0[i].y));
        if (!(rt <= s.maxRoundTrip)) continue;
        if (!std::isfinite(p1[i].x) || !std::isfinite(p1[i].y)) continue;
        tracks.push_back(Track{p0[i].x, p0[i].y, p1[i].x - p0[i].x, p1[i].y - p0[i].y});
    }
    return tracks;
}

// ---------------------------------------------------------------------------------------------

ChannelImage pyramidDown(const ChannelImage& img)
{
    ::cv::Mat dst;
    ::cv::pyrDown(wrap(img), dst, ::cv::Size((img.width() + 1) / 2, (img.height() + 1) / 2), ::cv::BORDER_REFLECT_101);
    return fromMat(dst);
}

ChannelImage pyramidUp(const ChannelImage& img, int width, int height)
{
    ::cv::Mat dst;
    ::cv::pyrUp(wrap(img), dst, ::cv::Size(width, height), ::cv::BORDER_REFLECT_101);
    return fromMat(dst);
}

} // namespace turb::cv
