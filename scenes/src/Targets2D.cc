#include <scenes/Targets2D.h>

#include "Noise.h"

#include <turb/Error.h>

#include <algorithm>
#include <cmath>

namespace turb::scenes {

namespace {

constexpr double kPi2 = 3.14159265358979323846;

/// Three-lobed blob of mean radius R (pixels) in polar coordinates, soft edge of 2 pixels.
float lobes(double r, double theta, double R)
{
    const double edge = R * (1.0 + 0.22 * std::cos(3.0 * theta));
    return float(std::min(1.0, std::max(0.0, (edge - r) / 2.0 + 0.5)));
}

using detail::valueNoise2D;

/// `grow` and `stroke`: shapes that spread and then rest, with regions that never move.
Target2D growingTarget(const Target2DSettings& s, int frame)
{
    const int W = s.width, H = s.height;
    const double m = std::min(W, H), cx = 0.5 * (W - 1), cy = 0.5 * (H - 1);
    Target2D t{ChannelImage(W, H, 1), ChannelImage(W, H, 2)};
    if (s.kind == "grow") {
        // A wobbly disc whose radius grows at speed * min(W, H) pixels a frame from 0.12 to 0.42 of the
        // short side, then rests: uniform dilation about the centre while it grows.
        const double v = s.speed * m, R0 = 0.12 * m, R1 = 0.42 * m;
        const double f = std::max(0, frame);
        const double R = std::min(R1, R0 + v * f);
        const double rate = R0 + v * f < R1 ? v / R : 0.0; // dR/dt / R
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const double dx = x - cx, dy = y - cy, phi = std::atan2(dy, dx);
                const double edge = R * (1.0 + 0.12 * std::cos(3.0 * phi) + 0.06 * std::sin(5.0 * phi + 1.0));
                t.alpha.at(x, y, 0) = float(std::clamp((edge - std::hypot(dx, dy)) / 2.0 + 0.5, 0.0, 1.0));
                t.motion.at(x, y, 0) = float(rate * dx);
                t.motion.at(x, y, 1) = float(rate * dy);
            }
        return t;
    }
    // A brush stroke along a gentle wave, its tip advancing speed * W pixels a frame from 0.1 W to 0.9 W:
    // the body already painted rests, the tip moves along the path.
    const double th = 0.07 * m, x0 = 0.1 * W, x1 = 0.9 * W;
    const double tip = std::min(x1, x0 + th + s.speed * W * std::max(0, frame));
    const bool moving = x0 + th + s.speed * W * std::max(0, frame) < x1;
    const auto path = [&](double x) { return cy + 0.18 * H * std::sin(2.0 * kPi2 * (x - x0) / (x1 - x0) * 0.75); };
    const auto slope = [&](double x) {
        return 0.18 * H * std::cos(2.0 * kPi2 * (x - x0) / (x1 - x0) * 0.75) * 2.0 * kPi2 * 0.75 / (x1 - x0);
    };
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            // Distance to the path between x0 and the tip (the path is shallow: vertical distance
            // scaled by the slope's cosine, round caps at both ends).
            const double xc = std::clamp(double(x), x0, tip);
            const double sl = slope(xc), dy = (y - path(xc)) / std::sqrt(1.0 + sl * sl);
            const double d = std::hypot(x - xc, dy);
            t.alpha.at(x, y, 0) = float(std::clamp((th - d) / 2.0 + 0.5, 0.0, 1.0));
            if (!moving) continue;
            const double w = std::clamp((x - (tip - 2.0 * th)) / (2.0 * th), 0.0, 1.0);
            const double v = s.speed * W, n = std::sqrt(1.0 + slope(tip) * slope(tip));
            t.motion.at(x, y, 0) = float(w * v / n);
            t.motion.at(x, y, 1) = float(w * v * slope(tip) / n);
        }
    return t;
}

} // namespace

Target2D target2D(const Target2DSettings& s, int frame)
{
    if (s.width < 16 || s.height < 16) throw ValueError("target2D: size must be at least 16x16");
    if (s.kind != "rotate" && s.kind != "swirl" && s.kind != "rise" && s.kind != "fill" && s.kind != "grow" &&
        s.kind != "stroke")
        throw ValueError("target2D: unknown kind '" + s.kind + "' (rotate, swirl, rise, fill, grow, stroke)");
    if (s.kind == "grow" || s.kind == "stroke") return growingTarget(s, frame);
    const int W = s.width, H = s.height;
    const double cx = (W - 1) / 2.0, cy = (H - 1) / 2.0, R = 0.3 * std::min(W, H);
    Target2D t{ChannelImage(W, H, 1), ChannelImage(W, H, 2)};
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            double dx = x - cx, dy = y - cy;
            if (s.kind == "rise") {
                // The blob moves up by speed * W pixels a frame, wrapping around.
                const double v = s.speed * W;
                const double py = std::fmod(dy + v * frame + 1e6 * H, double(H));
                const double wy = py > H / 2.0 ? py - H : py;
                t.alpha.at(x, y, 0) = float(std::min(1.0, std::max(0.0, (0.8 * R - std::hypot(dx, wy)) / 2.0 + 0.5)));
                t.motion.at(x, y, 1) = float(-v);
                continue;
            }
            const double r = std::hypot(dx, dy);
            // Angular speed (radians per frame, counter-clockwise on screen with y down).
            const double w = s.kind != "swirl" ? s.speed : s.speed * std::exp(-(r * r) / (2.0 * R * R));
            const double theta = std::atan2(-dy, dx) - w * frame; // where this point was at frame 0
            t.alpha.at(x, y, 0) = s.kind == "fill" ? 1.0f : lobes(r, theta, R);
            // Screen rotation counter-clockwise: (dx, -dy) turns by w, so the motion is w * (dy, -dx).
            t.motion.at(x, y, 0) = float(w * dy);
            t.motion.at(x, y, 1) = float(-w * dx);
        }
    return t;
}

RgbaImage fireExemplar(int n, std::uint64_t seed)
{
    if (n < 16) throw ValueError("fireExemplar: size must be at least 16");
    RgbaImage z(n, n);
    z.colorSpace = "sRGB";
    const double c = (n - 1) / 2.0, R = 0.44 * n;
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            // Ragged edge: the radius wobbles with low-frequency noise; the edge is soft over ~4 pixels.
            const double theta = std::atan2(y - c, x - c);
            const double wobble =
                0.12 * R *
                (valueNoise2D(std::cos(theta) * 40.0 + 100.0, std::sin(theta) * 40.0 + 100.0, 9.0, seed + 7) - 0.5);
            const double a = std::min(1.0, std::max(0.0, (R + wobble - std::hypot(x - c, y - c)) / 4.0 + 0.5));
            // Smooth on the left (a ramp, brighter at the top), textured on the right, blended over the
            // middle fifth so no hard seam becomes a feature of its own.
            const double ramp = 0.25 + 0.7 * (1.0 - double(y) / n);
            double f = 0.0, amp = 0.5;
            for (double cell = n / 6.0; cell >= 1.5; cell /= 2.0, amp *= 0.6)
                f += amp * (valueNoise2D(x, y, cell, seed) - 0.5);
            const double tex = std::min(1.0, std::max(0.0, 0.55 + 1.6 * f));
            const double m = std::min(1.0, std::max(0.0, (double(x) / n - 0.4) / 0.2));
            const double v = ramp + (tex - ramp) * m * m * (3.0 - 2.0 * m);
            // A fire ramp: dark red -> orange -> pale yellow.
            const float r = float(std::min(1.0, 0.35 + 0.9 * v)),
                        g = float(std::min(1.0, std::max(0.0, 1.25 * v - 0.25))),
                        b = float(std::min(1.0, std::max(0.0, 1.6 * v - 1.0)));
            z.at(x, y) = Rgba(r, g, b, float(a));
        }
    return z;
}

} // namespace turb::scenes
