// Fluidymation's pyramid levels: the exemplar's voxels and the target's padded pixels.
#include "FluidyLevels.h"

#include <turb/MotionGuides.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb::fluidy {

namespace {

ChannelImage binary(const ChannelImage& soft)
{
    ChannelImage b(soft.width(), soft.height(), 1);
    for (size_t i = 0; i < b.pixelCount(); ++i) b.pixel(i)[0] = soft.pixel(i)[0] >= 0.5f ? 1.0f : 0.0f;
    return b;
}

/// Segment of a pixel from the signed distance: interior deeper than the boundary width, else boundary.
std::int8_t segmentOf(float phi, int boundaryWidth) { return phi < -float(boundaryWidth) ? kInterior : kBoundary; }

void directionChannels(const float* flow, float eps, float* out)
{
    const float m = std::hypot(flow[0], flow[1]);
    if (!(m > 0.0f)) {
        out[0] = out[1] = 0.0f;
        return;
    }
    const float conf = std::min(1.0f, m / eps);
    out[0] = conf * flow[0] / m;
    out[1] = conf * flow[1] / m;
}

} // namespace

std::vector<std::uint8_t> patchMeanSteps(const ChannelImage& flow, int radius, float eps)
{
    const int W = flow.width(), H = flow.height();
    ChannelImage tmp(W, H, 2);
    std::vector<std::uint8_t> a(flow.pixelCount());
    const float n = float((2 * radius + 1) * (2 * radius + 1));
    parallelFor(size_t(H), 16, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < W; ++x)
                for (int d = -radius; d <= radius; ++d) {
                    const float* s = flow.pixel(std::clamp(x + d, 0, W - 1), int(y));
                    tmp.at(x, int(y), 0) += s[0];
                    tmp.at(x, int(y), 1) += s[1];
                }
    });
    parallelFor(size_t(H), 16, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < W; ++x) {
                float bx = 0.0f, by = 0.0f;
                for (int d = -radius; d <= radius; ++d) {
                    const float* s = tmp.pixel(x, std::clamp(int(y) + d, 0, H - 1));
                    bx += s[0];
                    by += s[1];
                }
                const float mx = bx / n, my = by / n;
                a[flow.index(x, int(y))] =
                    std::hypot(mx, my) >= eps ? std::uint8_t(rotationIndex(std::atan2(my, mx))) : kNoDirection;
            }
    });
    return a;
}

FrameImages reduced(const FrameImages& f)
{
    FrameImages r;
    const auto red = [](const ChannelImage& c) { return c.empty() ? ChannelImage() : reduceByTwo(c); };
    r.rgb = red(f.rgb);
    r.mask = red(f.mask);
    r.shape = red(f.shape);
    r.ext = red(f.ext);
    r.flow = red(f.flow);
    r.temp = red(f.temp);
    return r;
}

void fillExemplarFrame(ExemplarLevel& E, int i, const FrameImages& f, const LevelRules& rules)
{
    const int W = E.W, H = E.H;
    const ChannelImage mask = binary(f.mask);
    const ChannelImage phi = signedDistance(mask);
    const std::vector<std::uint8_t> steps = patchMeanSteps(f.flow, rules.radius, rules.eps);
    ChannelImage vote(W, H, 4);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const size_t p = size_t(y) * size_t(W) + size_t(x), v = E.voxel(i, x, y);
            float* o = E.feat.data() + v * kS;
            std::copy(f.rgb.pixel(p), f.rgb.pixel(p) + 3, o);
            o[3] = f.shape.pixel(p)[0];
            o[4] = f.ext.pixel(p)[0];
            o[5] = f.ext.pixel(p)[1];
            directionChannels(f.flow.pixel(p), rules.eps, o + 6);
            E.dirStep[v] = steps[p];
            const float ph = phi.pixel(p)[0];
            E.segment[v] = segmentOf(ph, rules.boundaryWidth);
            const bool centre = x >= rules.reach && y >= rules.reach && x < W - rules.reach && y < H - rules.reach &&
                                ph <= float(rules.radius);
            E.label[v] = centre ? E.segment[v] : std::int8_t(-1);
            float* vo = vote.pixel(p);
            std::copy(f.rgb.pixel(p), f.rgb.pixel(p) + 3, vo);
            vo[3] = f.mask.pixel(p)[0];
        }
    E.vote[size_t(i)] = std::move(vote);
}

TargetLevel makeTargetLevel(const FrameImages& f, const LevelRules& rules)
{
    TargetLevel T;
    T.W = f.mask.width();
    T.H = f.mask.height();
    T.pad = rules.radius;
    const int W = T.W, H = T.H, P = T.pad;
    T.feat.assign(size_t(W + 2 * P) * size_t(H + 2 * P) * kT, 0.0f);
    const ChannelImage phi = signedDistance(binary(f.mask));
    T.dirStep = patchMeanSteps(f.flow, rules.radius, rules.eps);
    T.label.assign(size_t(W) * size_t(H), -1);
    parallelFor(size_t(H + 2 * P), 16, [&](size_t r0, size_t r1) {
        for (size_t row = r0; row < r1; ++row) {
            const int y = int(row) - P;
            for (int x = -P; x < W + P; ++x) {
                const int cx = std::clamp(x, 0, W - 1), cy = std::clamp(y, 0, H - 1);
                const size_t p = size_t(cy) * size_t(W) + size_t(cx);
                float* o = T.at(x, y);
                o[3] = f.shape.pixel(p)[0];
                o[4] = f.ext.pixel(p)[0];
                o[5] = f.ext.pixel(p)[1];
                directionChannels(f.flow.pixel(p), rules.eps, o + 6);
                std::copy(f.temp.pixel(p), f.temp.pixel(p) + 4, o + 8);
            }
        }
    });
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const size_t p = size_t(y) * size_t(W) + size_t(x);
            const float ph = phi.pixel(p)[0];
            if (ph > float(rules.radius)) continue;
            T.label[p] = segmentOf(ph, rules.boundaryWidth);
            ++T.segCount[T.label[p]];
        }
    return T;
}

} // namespace turb::fluidy
