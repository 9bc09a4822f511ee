#include <scenes/Ink2D.h>

#include "Noise.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb::scenes {

namespace {

constexpr double kPi = 3.14159265358979323846;

using detail::valueNoise2D;

double fractal(double x, double y, double cell, int octaves, std::uint64_t seed)
{
    double f = 0.0, amp = 0.5, norm = 0.0;
    for (int o = 0; o < octaves; ++o, cell /= 2.0, amp *= 0.55) {
        f += amp * valueNoise2D(x, y, cell, seed + std::uint64_t(o) * 101);
        norm += amp;
    }
    return f / norm;
}

struct Sim
{
    const InkSettings& s;
    int W, H;
    double cx, cy, R0;

    explicit Sim(const InkSettings& settings) : s(settings), W(settings.width), H(settings.height)
    {
        cx = 0.42 * W;
        cy = 0.52 * H;
        R0 = 0.1 * std::min(W, H);
    }

    double frontSpeed(double t) const { return s.speed / (1.0 + t / s.decay); }
    /// The mean front radius at time t: R0 + integral of the front speed.
    double front(double t) const { return R0 + s.speed * s.decay * std::log(1.0 + t / s.decay); }

    /// Velocity in pixels per frame at (x, y), time t (frames).
    void velocity(double x, double y, double t, double& ux, double& uy) const
    {
        const double dx = x - cx, dy = y - cy, r = std::hypot(dx, dy);
        const double phi = std::atan2(dy, dx);
        // Fingers: the front's speed wobbles along the rim, slowly changing in time.
        const double wob = 1.0 + 0.35 * (2.0 * valueNoise2D(8.0 * std::cos(phi) + 50.0 + 0.04 * t,
                                                   8.0 * std::sin(phi) + 50.0, 2.2, s.seed + 11) -
                                            1.0);
        // Capillary spreading: the wet front moves, the paint behind it comes to rest ((r / R)^2), and
        // beyond the front the speed falls as R / r.
        const double R = front(t), q = r / R;
        const double ur = frontSpeed(t) * wob * (q <= 1.0 ? q * q : 1.0 / q);
        ux = r > 1e-9 ? ur * dx / r : 0.0;
        uy = r > 1e-9 ? ur * dy / r : 0.0;
        // A weak swirl: the curl of a noise potential (divergence-free), fading with the spreading.
        const double e = 1.5, a = 0.25 * frontSpeed(t) * R0 * std::min(1.0, q * q);
        const auto pot = [&](double px, double py) {
            return fractal(px + 0.3 * t, py, 0.35 * R0 * 4.0, 2, s.seed + 23);
        };
        ux += a * (pot(x, y + e) - pot(x, y - e)) / (2.0 * e);
        uy -= a * (pot(x + e, y) - pot(x - e, y)) / (2.0 * e);
    }
};

ChannelImage advect(const ChannelImage& f, const Sim& sim, double t, double dt)
{
    ChannelImage out(f.width(), f.height(), f.channels());
    parallelFor(size_t(f.height()), 8, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy)
            for (int x = 0; x < f.width(); ++x) {
                double ux = 0, uy = 0;
                sim.velocity(x, double(yy), t, ux, uy);
                sampleBilinear(f, x - ux * dt, double(yy) - uy * dt, out.pixel(x, int(yy)));
            }
    });
    return out;
}

} // namespace

InkSequence inkExemplar(const InkSettings& s)
{
    if (s.width < 32 || s.height < 32 || s.frames < 1)
        throw ValueError("ink: size must be at least 32x32 and frames >= 1");
    if (!(s.speed > 0.0) || !(s.decay > 0.0)) throw ValueError("ink: speed and decay must be > 0");
    const Sim sim(s);
    const int W = s.width, H = s.height;
    // c: wetness (the drop), p: pigment texture carried by the flow.
    ChannelImage field(W, H, 2);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const double phi = std::atan2(y - sim.cy, x - sim.cx);
            const double edge =
                sim.R0 *
                (1.0 + 0.15 * (valueNoise2D(5.0 * std::cos(phi) + 20.0, 5.0 * std::sin(phi) + 20.0, 1.7, s.seed + 3) -
                                  0.5));
            field.at(x, y, 0) = float(std::clamp((edge - std::hypot(x - sim.cx, y - sim.cy)) / 1.5 + 0.5, 0.0, 1.0));
            field.at(x, y, 1) = float(fractal(x, y, 0.5 * sim.R0, 5, s.seed + 5));
        }
    InkSequence out;
    constexpr int kSubsteps = 4;
    for (int i = 0; i < s.frames; ++i) {
        if (i > 0)
            for (int k = 0; k < kSubsteps; ++k)
                field = advect(field, sim, (i - 1) + double(k) / kSubsteps, 1.0 / kSubsteps);
        const ChannelImage c = channelRange(field, 0, 1);
        const double unit = std::max(1.0, sim.R0 / 16.0); // the rim's width follows the drop's size
        const ChannelImage b1 = gaussianBlur(c, 1.2 * unit), b2 = gaussianBlur(c, 3.5 * unit);
        RgbaImage rgb(W, H);
        rgb.colorSpace = "sRGB";
        ChannelImage mask(W, H, 1), flow(W, H, 2);
        const double k[3] = {1.05, 0.72, 0.18}; // indigo: absorbs red most
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const double cv = std::clamp(double(c.at(x, y, 0)), 0.0, 1.0), pv = field.at(x, y, 1);
                const double rim = std::max(0.0, double(b1.at(x, y, 0)) - double(b2.at(x, y, 0))) * 3.0;
                const double tex = std::clamp(2.6 * (pv - 0.5) + 0.5, 0.0, 1.0);
                const double density = cv * (0.12 + 0.88 * tex * tex) + 1.1 * rim;
                const double paper = 0.93 + 0.05 * fractal(x * 1.7, y * 0.6, 6.0 * unit, 3, s.seed + 9);
                Rgba px(0, 0, 0, 1);
                for (int ch = 0; ch < 3; ++ch)
                    px[ch] =
                        float(std::clamp(paper * (ch == 2 ? 0.97 : 1.0) * std::exp(-1.6 * k[ch] * density), 0.0, 1.0));
                rgb.at(x, y) = px;
                const bool in = cv >= 0.5;
                mask.at(x, y, 0) = in ? 1.0f : 0.0f;
                if (in) {
                    double ux = 0, uy = 0;
                    sim.velocity(x, y, i, ux, uy);
                    flow.at(x, y, 0) = float(ux);
                    flow.at(x, y, 1) = float(uy);
                }
            }
        out.rgb.push_back(std::move(rgb));
        out.mask.push_back(std::move(mask));
        out.flow.push_back(std::move(flow));
    }
    return out;
}

} // namespace turb::scenes
