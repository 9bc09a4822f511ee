#include <scenes/Animate2D.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace turb::scenes {

namespace {

struct Wave
{
    int kx; // cycles per period along x (periodic texture)
    double ky, phase, amp;
};

/// Ripples: crests mostly across the flow (x), some oblique; periodic in x with `period` pixels.
std::vector<Wave> ripples(std::mt19937_64& rng, int period, int count)
{
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Wave> w;
    for (int i = 0; i < count; ++i) {
        const double lambda = 4.0 + 22.0 * u(rng);
        const int kx = std::max(1, int(std::lround(period / lambda)));
        const double ky = (u(rng) - 0.5) * 0.9 * (2.0 * M_PI / lambda);
        w.push_back({kx, ky, 2.0 * M_PI * u(rng), std::pow(lambda / 26.0, 0.7) * (0.6 + 0.4 * u(rng))});
    }
    double norm = 0.0;
    for (const Wave& v : w) norm += v.amp * v.amp;
    for (Wave& v : w) v.amp /= std::sqrt(0.5 * norm); // unit standard deviation
    return w;
}

double rippleAt(const std::vector<Wave>& w, int period, double x, double y)
{
    double v = 0.0;
    for (const Wave& k : w) v += k.amp * std::cos(2.0 * M_PI * k.kx * x / period + k.ky * y + k.phase);
    return v;
}

double smoothstep(double a, double b, double x)
{
    const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

void checkSize(int w, int h)
{
    if (w < 16 || h < 16) throw ValueError("built-in river: the image must be at least 16x16 pixels");
}

} // namespace

std::vector<ChannelImage> riverExample(const RiverSettings& s)
{
    checkSize(s.width, s.height);
    if (s.frames < 1) throw ValueError("built-in river: needs at least one frame");
    const int W = s.width, H = s.height, P = 512;
    std::mt19937_64 rng(s.seed);
    const std::vector<Wave> waves = ripples(rng, P, 48);
    // The periodic texture tile, P columns x H rows, evaluated once.
    std::vector<float> tile(size_t(P) * size_t(H));
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < P; ++x) tile[y * size_t(P) + size_t(x)] = float(rippleAt(waves, P, x, double(y)));
    });
    const auto speed = [&](double y) {
        const double u = 2.0 * y / (H - 1) - 1.0;
        return 1.0 + s.fast * (1.0 - u * u);
    };
    struct Glint
    {
        double x, y;
        int born, life;
        float amp;
    };
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Glint> glints;
    const int perFrame = std::max(1, W * H / 900);
    for (int t = -8; t < s.frames; ++t)
        for (int k = 0; k < perFrame; ++k)
            glints.push_back({u(rng) * W, u(rng) * H, t, 3 + int(u(rng) * 6), float(0.25 + 0.35 * u(rng))});

    std::vector<ChannelImage> frames;
    for (int t = 0; t < s.frames; ++t) {
        ChannelImage f(W, H, 3);
        parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
            for (size_t yy = y0; yy < y1; ++yy) {
                const int y = int(yy);
                const double shift = speed(y) * t;
                for (int x = 0; x < W; ++x) {
                    double sx = std::fmod(x - shift, double(P));
                    if (sx < 0) sx += P;
                    const int i0 = int(sx) % P, i1 = (i0 + 1) % P;
                    const double fx = sx - std::floor(sx);
                    const double r =
                        (1.0 - fx) * tile[size_t(y) * P + size_t(i0)] + fx * tile[size_t(y) * P + size_t(i1)];
                    const double depth = 0.5 + 0.5 * std::cos(M_PI * (2.0 * y / (H - 1) - 1.0)); // darker mid-stream
                    float* p = f.pixel(x, y);
                    p[0] = float(0.10 + 0.05 * (1 - depth) + 0.07 * r);
                    p[1] = float(0.25 + 0.05 * (1 - depth) + 0.08 * r);
                    p[2] = float(0.30 + 0.04 * (1 - depth) + 0.08 * r);
                }
            }
        });
        for (const Glint& g : glints) {
            const int age = t - g.born;
            if (age < 0 || age >= g.life) continue;
            const float a = g.amp * float(std::sin(M_PI * (age + 0.5) / g.life));
            const double gx = g.x + speed(g.y) * age, gy = g.y;
            for (int y = int(gy) - 3; y <= int(gy) + 3; ++y)
                for (int x = int(gx) - 4; x <= int(gx) + 4; ++x) {
                    if (x < 0 || y < 0 || x >= W || y >= H) continue;
                    const double d2 = (x - gx) * (x - gx) / 4.0 + (y - gy) * (y - gy);
                    const float w = a * float(std::exp(-d2 / 1.5));
                    float* p = f.pixel(x, y);
                    p[0] += 0.9f * w;
                    p[1] += 0.95f * w;
                    p[2] += w;
                }
        }
        frames.push_back(std::move(f));
    }
    return frames;
}

namespace {

double centreLine(double x, int W, int H) { return H * (0.5 + 0.12 * std::sin(2.0 * M_PI * 0.8 * x / W + 0.4)); }
double halfWidth(double x, int W, int H) { return H * (0.2 + 0.04 * std::cos(2.0 * M_PI * 1.3 * x / W)); }

} // namespace

ChannelImage riverMatte(int W, int H)
{
    checkSize(W, H);
    ChannelImage m(W, H, 1);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const double d = std::abs(y - centreLine(x, W, H)) - halfWidth(x, W, H);
            m.at(x, y, 0) = float(1.0 - smoothstep(-1.0, 1.0, d));
        }
    return m;
}

ChannelImage riverStill(int W, int H, std::uint64_t seed)
{
    checkSize(W, H);
    const int P = 1024;
    std::mt19937_64 rng(seed);
    const std::vector<Wave> water = ripples(rng, P, 40);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Wave> grass;
    for (int i = 0; i < 60; ++i) {
        const double lambda = 2.0 + 10.0 * u(rng);
        grass.push_back(
            {std::max(1, int(P / lambda)), (u(rng) - 0.5) * 4.0 / lambda, 2.0 * M_PI * u(rng), 0.5 + 0.5 * u(rng)});
    }
    const ChannelImage matte = riverMatte(W, H);
    ChannelImage img(W, H, 3);
    const double scale = 320.0 / W; // the texture keeps its look per 320-pixel width
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            for (int x = 0; x < W; ++x) {
                const double X = x * scale, Y = y * scale;
                const double c = centreLine(x, W, H), h = halfWidth(x, W, H);
                const double across = std::clamp((y - c) / h, -1.0, 1.0);
                // Water: ripples along the winding stream (coordinates follow the bank), sky reflection.
                const double r = rippleAt(water, P, X, across * 40.0) / 3.0;
                const double sky = 0.5 + 0.5 * across;
                const float wr = float(0.16 + 0.10 * sky + 0.06 * r), wg = float(0.30 + 0.10 * sky + 0.07 * r),
                            wb = float(0.36 + 0.12 * sky + 0.07 * r);
                // Banks: grassy stripes, lighter far from the water.
                double gsum = 0.0, gn = 0.0;
                for (const Wave& g : grass) {
                    gsum += g.amp * std::cos(2.0 * M_PI * g.kx * X / P + g.ky * Y + g.phase);
                    gn += g.amp;
                }
                const double gv = gsum / gn;
                const double far = std::min(1.0, std::abs(y - c) / (0.6 * H));
                const float br = float(0.22 + 0.10 * far + 0.10 * gv), bg = float(0.34 + 0.12 * far + 0.12 * gv),
                            bb = float(0.12 + 0.05 * far + 0.05 * gv);
                const float m = matte.at(x, y, 0);
                float* p = img.pixel(x, y);
                p[0] = std::clamp(m * wr + (1 - m) * br, 0.0f, 1.0f);
                p[1] = std::clamp(m * wg + (1 - m) * bg, 0.0f, 1.0f);
                p[2] = std::clamp(m * wb + (1 - m) * bb, 0.0f, 1.0f);
            }
        }
    });
    return img;
}

} // namespace turb::scenes
