#include <turb/RgbaImage.h>

#include <algorithm>

namespace turb {

RgbaImage::RgbaImage(int width, int height, const Rgba& fill)
    : mWidth(std::max(0, width)), mHeight(std::max(0, height)), mPixels(size_t(mWidth) * size_t(mHeight), fill)
{}

const Rgba& RgbaImage::clamped(int x, int y) const
{
    return at(std::min(std::max(x, 0), mWidth - 1), std::min(std::max(y, 0), mHeight - 1));
}

Image overBackground(const RgbaImage& img, const Rgb& background)
{
    Image out(img.width(), img.height());
    for (size_t i = 0; i < img.size(); ++i) {
        const Rgba& p = img.pixels()[i];
        const float a = std::min(1.0f, std::max(0.0f, p[3]));
        out.pixels()[i] = Rgb(p[0], p[1], p[2]) * a + background * (1.0f - a);
    }
    return out;
}

Image rgbOf(const RgbaImage& img)
{
    Image out(img.width(), img.height());
    for (size_t i = 0; i < img.size(); ++i) {
        const Rgba& p = img.pixels()[i];
        out.pixels()[i] = Rgb(p[0], p[1], p[2]);
    }
    return out;
}

RgbaImage rgbaOf(const Image& picture)
{
    RgbaImage out(picture.width(), picture.height());
    for (size_t i = 0; i < out.size(); ++i) {
        const Rgb& p = picture.pixels()[i];
        out.pixels()[i] = Rgba(p[0], p[1], p[2], 1.0f);
    }
    return out;
}

Image channelPicture(const RgbaImage& img, int channel, float lo, float hi)
{
    channel = std::min(3, std::max(0, channel));
    const float inv = hi > lo ? 1.0f / (hi - lo) : 0.0f;
    Image out(img.width(), img.height());
    for (size_t i = 0; i < img.size(); ++i) {
        const float v = std::min(1.0f, std::max(0.0f, (img.pixels()[i][channel] - lo) * inv));
        out.pixels()[i] = Rgb(v);
    }
    return out;
}

} // namespace turb
