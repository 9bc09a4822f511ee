/// @file CvOps.h
/// @brief The image operations `animate` (Okabe et al. 2009) takes from OpenCV, over turb::ChannelImage.
///
/// The one boundary to OpenCV in libturb: only CvOps.cc includes OpenCV headers, so the rest of the
/// library (and its users) never see cv::Mat. Everything here is per pixel or per feature, so results
/// do not depend on the thread count; OpenCV's own parallel loops run on TBB, inside the caller's
/// turb::withThreads arena.
///
/// Conventions are ChannelImage's: interleaved float channels, x right, y down, pixel centres at
/// integer positions; motion and flow in pixels per frame.
#pragma once

#include <turb/ChannelImage.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace turb::cv {

/// Gaussian blur of every channel with a square kernel of `ksize` pixels (made odd, >= 1) and
/// standard deviation `sigma` (<= 0: OpenCV's rule sigma = 0.3 ((ksize - 1) / 2 - 1) + 0.8);
/// borders are reflected (OpenCV's BORDER_REFLECT_101). At most 4 channels.
ChannelImage gaussian(const ChannelImage& img, int ksize, double sigma = 0.0);

/// Image gradient of a 1-channel image: a 3x3 Sobel filter, divided by 8 so that a ramp of slope s
/// gives s (per pixel). Returns 2 channels (d/dx, d/dy).
ChannelImage sobelGradient(const ChannelImage& gray);

/// Backward warp by a fixed flow: out(x) = in(x - flow(x)), bilinear (OpenCV remap, INTER_LINEAR:
/// sub-pixel weights quantised to 1/32 pixel), borders replicated. The maps are built once, so the
/// same linear operator W is applied every time (Okabe et al. section 4.3).
class FlowWarp
{
public:
    FlowWarp();
    /// Throws ValueError unless `flow` has 2 channels.
    explicit FlowWarp(const ChannelImage& flow);
    ~FlowWarp();
    FlowWarp(FlowWarp&&) noexcept;
    FlowWarp& operator=(FlowWarp&&) noexcept;

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    /// W(in); `in` must have the flow's size and 1..4 channels. Throws ValueError otherwise.
    ChannelImage apply(const ChannelImage& in) const;
    /// The same into `out` (resized as needed; must not alias `in`).
    void apply(const ChannelImage& in, ChannelImage& out) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
    int mWidth = 0, mHeight = 0;
};

/// A grey frame prepared for feature tracking: 8-bit pixels (OpenCV's Lucas-Kanade needs them).
struct TrackFrame
{
    int width = 0, height = 0;
    std::vector<std::uint8_t> pixels;
};

/// Maps a signed 1-channel image to 8 bits: v -> clamp(128 + scale v, 0, 255), rounded.
TrackFrame toTrackFrame(const ChannelImage& gray, float scale);

/// One tracked feature between two frames: position in the first frame and its displacement.
struct Track
{
    float x = 0.0f, y = 0.0f;   ///< feature position in frame a (pixels)
    float dx = 0.0f, dy = 0.0f; ///< displacement to frame b (pixels)
};

struct TrackSettings
{
    int features = 100;        ///< Shi-Tomasi corners per frame pair (Okabe: 100), >= 1
    int window = 10;           ///< Lucas-Kanade window in pixels (Okabe: 10), >= 3
    int levels = 3;            ///< pyramid levels above the base (Bouguet), >= 0
    double quality = 0.01;     ///< corner quality relative to the strongest, (0, 1)
    double minDistance = 5.0;  ///< minimum distance between corners, pixels
    double maxRoundTrip = 0.5; ///< forward-backward check: drop tracks that come back further than this, pixels
};

/// Sparse flow from a to b: good features to track in a (Shi-Tomasi), pyramidal Lucas-Kanade to b
/// (Bouguet 1999), kept when LK converged both ways and the round trip closes within maxRoundTrip.
std::vector<Track> trackFeatures(const TrackFrame& a, const TrackFrame& b, const TrackSettings& settings);

/// Gaussian pyramid step (OpenCV pyrDown: 5x5 Gaussian, drop odd rows/columns): size ceil(W/2) x ceil(H/2).
ChannelImage pyramidDown(const ChannelImage& img);
/// The inverse step to an explicit size (OpenCV pyrUp, then cropped/extended to width x height).
ChannelImage pyramidUp(const ChannelImage& img, int width, int height);

} // namespace turb::cv
