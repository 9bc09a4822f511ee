#include <turb/ChannelImage.h>

#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb {

ChannelImage::ChannelImage(int width, int height, int channels, float fill)
    : mWidth(std::max(0, width)), mHeight(std::max(0, height)), mChannels(std::max(0, channels)),
      mData(size_t(mWidth) * size_t(mHeight) * size_t(mChannels), fill)
{}

namespace {

std::vector<float> gaussianKernel(double sigma)
{
    const int r = std::max(1, int(std::ceil(3.0 * sigma)));
    std::vector<float> k(size_t(2 * r + 1));
    double sum = 0.0;
    for (int i = -r; i <= r; ++i) sum += std::exp(-0.5 * i * i / (sigma * sigma));
    for (int i = -r; i <= r; ++i) k[size_t(i + r)] = float(std::exp(-0.5 * i * i / (sigma * sigma)) / sum);
    return k;
}

} // namespace

ChannelImage gaussianBlur(const ChannelImage& img, double sigma)
{
    if (!(sigma > 0.0) || img.empty()) return img;
    const std::vector<float> k = gaussianKernel(sigma);
    const int r = int(k.size() / 2), W = img.width(), H = img.height(), C = img.channels();
    ChannelImage tmp(W, H, C), out(W, H, C);
    parallelFor(size_t(H), 8, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < W; ++x) {
                float* o = tmp.pixel(x, int(y));
                if (x >= r && x < W - r) { // inside: no clamping, the same sums in the same order
                    const float* s = img.pixel(x - r, int(y));
                    for (int i = 0; i <= 2 * r; ++i, s += C)
                        for (int c = 0; c < C; ++c) o[c] += k[size_t(i)] * s[c];
                    continue;
                }
                for (int i = -r; i <= r; ++i) {
                    const float* s = img.pixel(std::min(W - 1, std::max(0, x + i)), int(y));
                    for (int c = 0; c < C; ++c) o[c] += k[size_t(i + r)] * s[c];
                }
            }
    });
    parallelFor(size_t(H), 8, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y) {
            if (int(y) >= r && int(y) < H - r) { // inside: row by row, the same sums in the same order per pixel
                for (int i = -r; i <= r; ++i) {
                    const float* s = tmp.pixel(0, int(y) + i);
                    float* o = out.pixel(0, int(y));
                    const float w = k[size_t(i + r)];
                    for (size_t j = 0; j < size_t(W) * size_t(C); ++j) o[j] += w * s[j];
                }
                continue;
            }
            for (int x = 0; x < W; ++x) {
                float* o = out.pixel(x, int(y));
                for (int i = -r; i <= r; ++i) {
                    const float* s = tmp.pixel(x, std::min(H - 1, std::max(0, int(y) + i)));
                    for (int c = 0; c < C; ++c) o[c] += k[size_t(i + r)] * s[c];
                }
            }
        }
    });
    return out;
}

ChannelImage reduceByTwo(const ChannelImage& img)
{
    const int W = (img.width() + 1) / 2, H = (img.height() + 1) / 2, C = img.channels();
    ChannelImage out(W, H, C);
    parallelFor(size_t(H), 16, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < W; ++x) {
                float* o = out.pixel(x, int(y));
                int n = 0;
                for (int dy = 0; dy < 2; ++dy)
                    for (int dx = 0; dx < 2; ++dx) {
                        const int fx = 2 * x + dx, fy = 2 * int(y) + dy;
                        if (!img.inside(fx, fy)) continue;
                        const float* s = img.pixel(fx, fy);
                        for (int c = 0; c < C; ++c) o[c] += s[c];
                        ++n;
                    }
                for (int c = 0; c < C; ++c) o[c] /= float(n);
            }
    });
    return out;
}

void sampleBilinear(const ChannelImage& img, double x, double y, float* out)
{
    const int W = img.width(), H = img.height(), C = img.channels();
    x = std::min(std::max(x, 0.0), double(W - 1));
    y = std::min(std::max(y, 0.0), double(H - 1));
    const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
    const int x1 = std::min(x0 + 1, W - 1), y1 = std::min(y0 + 1, H - 1);
    const float fx = float(x - x0), fy = float(y - y0);
    const float *a = img.pixel(x0, y0), *b = img.pixel(x1, y0), *c = img.pixel(x0, y1), *d = img.pixel(x1, y1);
    for (int k = 0; k < C; ++k) out[k] = (1 - fy) * ((1 - fx) * a[k] + fx * b[k]) + fy * ((1 - fx) * c[k] + fx * d[k]);
}

ChannelImage enlarge(const ChannelImage& coarse, int W, int H)
{
    ChannelImage out(W, H, coarse.channels());
    parallelFor(size_t(H), 16, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < W; ++x)
                sampleBilinear(coarse, (x - 0.5) / 2.0, (double(y) - 0.5) / 2.0, out.pixel(x, int(y)));
    });
    return out;
}

ChannelImage channelRange(const ChannelImage& img, int first, int count)
{
    ChannelImage out(img.width(), img.height(), count);
    for (size_t i = 0; i < img.pixelCount(); ++i)
        for (int c = 0; c < count; ++c) out.pixel(i)[c] = img.pixel(i)[first + c];
    return out;
}

ChannelImage toChannels(const RgbaImage& img)
{
    ChannelImage out(img.width(), img.height(), 4);
    for (size_t i = 0; i < img.size(); ++i)
        for (int c = 0; c < 4; ++c) out.pixel(i)[c] = img.pixels()[i][c];
    return out;
}

RgbaImage toRgba(const ChannelImage& img, const std::string& colorSpace)
{
    RgbaImage out(img.width(), img.height(), Rgba(0.0f, 0.0f, 0.0f, 1.0f));
    out.colorSpace = colorSpace;
    const int n = std::min(4, img.channels());
    for (size_t i = 0; i < out.size(); ++i)
        for (int c = 0; c < n; ++c) out.pixels()[i][c] = img.pixel(i)[c];
    return out;
}

ChannelImage channelOf(const RgbaImage& img, int c)
{
    ChannelImage out(img.width(), img.height(), 1);
    for (size_t i = 0; i < img.size(); ++i) out.pixel(i)[0] = img.pixels()[i][c];
    return out;
}

ChannelImage rotated(const ChannelImage& img, int quarterTurns)
{
    const int q = ((quarterTurns % 4) + 4) % 4;
    const int W = img.width(), H = img.height(), C = img.channels();
    if (q == 0) return img;
    const bool swap = q % 2 == 1;
    ChannelImage out(swap ? H : W, swap ? W : H, C);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            int nx = x, ny = y;
            // Counter-clockwise on screen (y down): (x, y) -> (y, W-1-x) for 90 degrees.
            if (q == 1) {
                nx = y;
                ny = W - 1 - x;
            } else if (q == 2) {
                nx = W - 1 - x;
                ny = H - 1 - y;
            } else {
                nx = H - 1 - y;
                ny = x;
            }
            const float* s = img.pixel(x, y);
            std::copy(s, s + C, out.pixel(nx, ny));
        }
    return out;
}

} // namespace turb
