#include <turb/Warp.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace turb {

namespace {

void checkMotion(const ChannelImage& image, const ChannelImage& motion, const char* who)
{
    if (motion.channels() != 2 || !motion.sameSize(image))
        throw ValueError(std::string(who) + ": motion must be a 2-channel image of the image's size (" +
                         std::to_string(image.width()) + "x" + std::to_string(image.height()) + ")");
}

} // namespace

WarpResult forwardWarp(const ChannelImage& image, const ChannelImage& motion, float minWeight)
{
    checkMotion(image, motion, "forwardWarp");
    const int W = image.width(), H = image.height(), C = image.channels();
    std::vector<double> acc(image.data().size(), 0.0), wsum(image.pixelCount(), 0.0);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const float* m = motion.pixel(x, y);
            const double tx = x + double(m[0]), ty = y + double(m[1]);
            if (!std::isfinite(tx) || !std::isfinite(ty)) continue;
            const int x0 = int(std::floor(tx)), y0 = int(std::floor(ty));
            const double fx = tx - x0, fy = ty - y0;
            const float* v = image.pixel(x, y);
            for (int j = 0; j < 2; ++j)
                for (int i = 0; i < 2; ++i) {
                    const int px = x0 + i, py = y0 + j;
                    if (px < 0 || py < 0 || px >= W || py >= H) continue;
                    const double w = (i ? fx : 1.0 - fx) * (j ? fy : 1.0 - fy);
                    if (w <= 0.0) continue;
                    const size_t q = size_t(py) * size_t(W) + size_t(px);
                    wsum[q] += w;
                    for (int c = 0; c < C; ++c) acc[q * size_t(C) + size_t(c)] += w * v[c];
                }
        }
    WarpResult r{ChannelImage(W, H, C), ChannelImage(W, H, 1)};
    for (size_t q = 0; q < image.pixelCount(); ++q) {
        r.weight.pixel(q)[0] = float(wsum[q]);
        if (wsum[q] < minWeight) continue;
        for (int c = 0; c < C; ++c) r.image.pixel(q)[c] = float(acc[q * size_t(C) + size_t(c)] / wsum[q]);
    }
    return r;
}

ChannelImage backwardWarp(const ChannelImage& image, const ChannelImage& motion)
{
    checkMotion(image, motion, "backwardWarp");
    ChannelImage out(image.width(), image.height(), image.channels());
    parallelFor(size_t(image.height()), 8, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < image.width(); ++x) {
                const float* m = motion.pixel(x, int(y));
                sampleBilinear(image, x - double(m[0]), double(y) - double(m[1]), out.pixel(x, int(y)));
            }
    });
    return out;
}

ChannelImage motionBlur(const ChannelImage& image, const ChannelImage& motion, const MotionBlurSettings& s)
{
    checkMotion(image, motion, "motionBlur");
    if (!(s.shutter >= 0.0f) || s.maxSamples < 3)
        throw ValueError("motionBlur: shutter must be >= 0 and maxSamples >= 3");
    if (s.shutter == 0.0f) return image;
    const int C = image.channels();
    ChannelImage out(image.width(), image.height(), C);
    parallelFor(size_t(image.height()), 4, [&](size_t y0, size_t y1) {
        std::vector<float> tap(static_cast<size_t>(C)), acc(static_cast<size_t>(C));
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            for (int x = 0; x < image.width(); ++x) {
                const float* m = motion.pixel(x, y);
                const double len = s.shutter * std::hypot(double(m[0]), double(m[1]));
                float* o = out.pixel(x, y);
                if (len < 0.5) {
                    std::copy(image.pixel(x, y), image.pixel(x, y) + C, o);
                    continue;
                }
                // Samples a pixel apart (at most maxSamples) along the line through the pixel centre.
                const int n = std::min(s.maxSamples, 2 * int(std::ceil(len / 2.0)) + 1);
                const double sigma = len / 4.0;
                std::fill(acc.begin(), acc.end(), 0.0f);
                double wsum = 0.0;
                for (int k = 0; k < n; ++k) {
                    const double t = (double(k) / (n - 1) - 0.5) * len; // along the line, pixels
                    const double w = std::exp(-0.5 * t * t / (sigma * sigma));
                    const double ux = m[0] / (len / s.shutter), uy = m[1] / (len / s.shutter);
                    sampleBilinear(image, x + t * ux, y + t * uy, tap.data());
                    for (int c = 0; c < C; ++c) acc[size_t(c)] += float(w) * tap[size_t(c)];
                    wsum += w;
                }
                for (int c = 0; c < C; ++c) o[c] = float(acc[size_t(c)] / wsum);
            }
        }
    });
    return out;
}

} // namespace turb
