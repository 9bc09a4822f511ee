/// @file ChannelImage.h
/// @brief The 2D engine's working image: W x H pixels of C float channels, and the image operations
///        the patch-based stages share (Gaussian blur, 2x reduction, bilinear sampling).
///
/// Shared by stylize (Jamriška et al. 2015) and meant for the other image-space methods (Fluidymation; Okabe et al.).
/// Channels are interleaved per pixel, rows top to bottom: channel c of pixel (x, y) is
/// data()[(y * W + x) * C + c]. Pixel (x, y) has its centre at the continuous position (x, y), so a
/// motion vector (dx, dy) in pixels moves pixel (x, y) to (x + dx, y + dy); x is right, y is down.
///
/// @code
/// turb::ChannelImage img(64, 48, 4);                 // RGBA, zero
/// img.at(3, 2, 1) = 0.5f;
/// turb::ChannelImage soft = turb::gaussianBlur(img, 3.0); // sigma 3 pixels
/// turb::ChannelImage half = turb::reduceByTwo(img);       // 32 x 24, 2x2 box means
/// @endcode
#pragma once

#include <turb/RgbaImage.h>

#include <cstddef>
#include <vector>

namespace turb {

class ChannelImage
{
public:
    ChannelImage() = default;
    /// width x height pixels of `channels` channels, all `fill`. Negative sizes become 0.
    ChannelImage(int width, int height, int channels, float fill = 0.0f);

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    int channels() const { return mChannels; }
    size_t pixelCount() const { return size_t(mWidth) * size_t(mHeight); }
    bool empty() const { return mData.empty(); }
    bool sameSize(const ChannelImage& o) const { return mWidth == o.mWidth && mHeight == o.mHeight; }
    bool inside(int x, int y) const { return x >= 0 && y >= 0 && x < mWidth && y < mHeight; }

    size_t index(int x, int y) const { return size_t(y) * size_t(mWidth) + size_t(x); }
    float* pixel(size_t i) { return mData.data() + i * size_t(mChannels); }
    const float* pixel(size_t i) const { return mData.data() + i * size_t(mChannels); }
    float* pixel(int x, int y) { return pixel(index(x, y)); }
    const float* pixel(int x, int y) const { return pixel(index(x, y)); }
    float& at(int x, int y, int c) { return pixel(x, y)[c]; }
    float at(int x, int y, int c) const { return pixel(x, y)[c]; }

    std::vector<float>& data() { return mData; }
    const std::vector<float>& data() const { return mData; }

private:
    int mWidth = 0, mHeight = 0, mChannels = 0;
    std::vector<float> mData;
};

/// Separable Gaussian blur of every channel with standard deviation `sigma` pixels (kernel cut at
/// 3 sigma), constant extension at the borders. sigma <= 0 returns a copy.
ChannelImage gaussianBlur(const ChannelImage& img, double sigma);

/// Halves the resolution: pixel (x, y) of the result is the mean of pixels (2x..2x+1, 2y..2y+1) that
/// exist; the size is ceil(W/2) x ceil(H/2). Pixel (x, y) of the result covers fine pixel (2x, 2y).
ChannelImage reduceByTwo(const ChannelImage& img);

/// Bilinear 2x enlargement onto a width x height grid (about twice `coarse`): fine pixel x sits at
/// coarse position (x - 0.5) / 2, the inverse of reduceByTwo's pixel layout. Constant extension.
ChannelImage enlarge(const ChannelImage& coarse, int width, int height);

/// Bilinear sample of all channels at the continuous position (x, y) with constant extension; writes
/// channels() floats to `out`.
void sampleBilinear(const ChannelImage& img, double x, double y, float* out);

/// Channels [first, first + count) of `img` as a new image.
ChannelImage channelRange(const ChannelImage& img, int first, int count);

/// An RGBA image as 4 channels, and back (the RgbaImage gets `colorSpace`).
ChannelImage toChannels(const RgbaImage& img);
RgbaImage toRgba(const ChannelImage& img, const std::string& colorSpace = "");

/// Channel `c` of an RGBA image as a 1-channel image (0 = R ... 3 = A).
ChannelImage channelOf(const RgbaImage& img, int c);

/// The image rotated by quarter turns counter-clockwise as seen on screen (1 = 90, 2 = 180, 3 = 270 degrees).
ChannelImage rotated(const ChannelImage& img, int quarterTurns);

} // namespace turb
