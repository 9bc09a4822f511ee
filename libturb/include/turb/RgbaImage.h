/// @file RgbaImage.h
/// @brief In-memory RGBA float images: exemplars, alpha masks, 2D motion fields and stylized frames.
///
/// The data-image counterpart of turb::Image (which is a display picture with captions). Values are
/// whatever the file held, never colour-converted: an sRGB PNG stays sRGB-encoded, a linear EXR stays
/// linear, and `colorSpace` remembers which, so a stage's output can be written in its input's space.
///
/// Alpha is always **straight** (unassociated) in memory: colour channels are not multiplied by alpha.
/// The IO layer (turbio/ImageIO.h) converts from and to files whose convention is associated (EXR).
/// Origin is the top-left corner, x to the right, y down; pixels are stored row by row.
///
/// @code
/// turb::RgbaImage img(64, 32, turb::Rgba(0, 0, 0, 0));
/// img.at(3, 4) = turb::Rgba(1.0f, 0.5f, 0.2f, 1.0f);
/// turb::Image shown = turb::overBackground(img, turb::Rgb(0.1f)); // for previews and contact sheets
/// @endcode
#pragma once

#include <turb/Image.h>

#include <openvdb/math/Vec4.h>

#include <string>
#include <vector>

namespace turb {

using Rgba = openvdb::math::Vec4<float>;

class RgbaImage
{
public:
    RgbaImage() = default;
    /// A width x height image filled with `fill`; negative sizes become 0.
    RgbaImage(int width, int height, const Rgba& fill = Rgba(0.0f, 0.0f, 0.0f, 0.0f));

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    size_t size() const { return mPixels.size(); }
    bool empty() const { return mPixels.empty(); }
    bool sameSize(const RgbaImage& o) const { return mWidth == o.mWidth && mHeight == o.mHeight; }

    bool inside(int x, int y) const { return x >= 0 && y >= 0 && x < mWidth && y < mHeight; }
    const Rgba& at(int x, int y) const { return mPixels[size_t(y) * size_t(mWidth) + size_t(x)]; }
    Rgba& at(int x, int y) { return mPixels[size_t(y) * size_t(mWidth) + size_t(x)]; }
    /// The pixel nearest to (x, y) inside the image (constant extension at the borders).
    const Rgba& clamped(int x, int y) const;

    const std::vector<Rgba>& pixels() const { return mPixels; }
    std::vector<Rgba>& pixels() { return mPixels; }

    /// Colour space the values are encoded in, as the file declared it (OpenImageIO's names: "sRGB",
    /// "Linear", ...); empty when unknown. Carried through stages unchanged, never applied.
    std::string colorSpace;

private:
    int mWidth = 0, mHeight = 0;
    std::vector<Rgba> mPixels;
};

/// Straight-alpha "over" onto a constant background: what a viewer shows. For previews and sheets.
Image overBackground(const RgbaImage& img, const Rgb& background);

/// The RGB channels alone (alpha dropped, no compositing): for images whose channels are data, such
/// as vector exemplars with R,G = x,y.
Image rgbOf(const RgbaImage& img);

/// An opaque RGBA copy of a picture (captions are not part of the pixels; see Image::texts()).
RgbaImage rgbaOf(const Image& picture);

/// A grey picture of one channel (0 = R ... 3 = A) mapped from [lo, hi] to [0, 1].
Image channelPicture(const RgbaImage& img, int channel, float lo = 0.0f, float hi = 1.0f);

} // namespace turb
