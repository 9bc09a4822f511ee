#include <turb/Voting.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace turb {

namespace {

/// The vote's frame: every target pixel averages, over the patches of radius `radius` that cover it (those
/// centred within the image), the values `add(cx, cy, dx, dy, acc)` accumulates for the patch at (cx, cy) and
/// the pixel's offset (dx, dy) from its centre; `add` returns false for a patch without a match. Pixels no patch
/// covers get settings.empty. Returns the votes per pixel.
template<typename AddTap>
std::vector<int> averageOverCoveringPatches(
    int radius, int firstTarget, int count, ChannelImage& target, const VoteSettings& settings, const AddTap& add)
{
    const int W = target.width(), H = target.height();
    std::vector<int> votes(target.pixelCount(), 0);
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        std::vector<double> acc(static_cast<size_t>(count));
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            for (int x = 0; x < W; ++x) {
                std::fill(acc.begin(), acc.end(), 0.0);
                int n = 0;
                double wsum = 0.0;
                for (int dy = -radius; dy <= radius; ++dy) {
                    const int cy = y - dy;
                    if (cy < 0 || cy >= H) continue;
                    for (int dx = -radius; dx <= radius; ++dx) {
                        const int cx = x - dx;
                        if (cx < 0 || cx >= W) continue;
                        const double w = add(cx, cy, dx, dy, acc);
                        if (w > 0.0) {
                            ++n;
                            wsum += w;
                        }
                    }
                }
                float* t = target.pixel(x, y) + firstTarget;
                for (int c = 0; c < count; ++c) t[c] = wsum > 0.0 ? float(acc[size_t(c)] / wsum) : settings.empty;
                votes[size_t(y) * size_t(W) + size_t(x)] = n;
            }
        }
    });
    return votes;
}

} // namespace

std::vector<int> vote(const ChannelImage& source, const Nnf& nnf, int radius, int firstSource, int firstTarget,
    int count, ChannelImage& target, const VoteSettings& settings)
{
    if (nnf.width != target.width() || nnf.height != target.height())
        throw ValueError("vote: the field must have the target's size");
    if (firstSource < 0 || firstTarget < 0 || count < 1 || firstSource + count > source.channels() ||
        firstTarget + count > target.channels())
        throw ValueError("vote: channel range outside the images");
    const int W = target.width(), sW = source.width();
    return averageOverCoveringPatches(
        radius, firstTarget, count, target, settings, [&](int cx, int cy, int dx, int dy, std::vector<double>& acc) {
            const size_t q = size_t(cy) * size_t(W) + size_t(cx);
            const std::int32_t p = nnf.source[q];
            if (p < 0) return 0.0;
            const double w = settings.distanceScale > 0.0f
                                 ? std::max(1e-12, std::exp(-double(nnf.distance[q]) / double(settings.distanceScale)))
                                 : 1.0;
            const float* s = source.pixel(p % sW + dx, p / sW + dy) + firstSource;
            for (int c = 0; c < count; ++c) acc[size_t(c)] += w * s[c];
            return w;
        });
}

std::vector<int> voteRotated(const std::vector<const ChannelImage*>& frames, const RotatedNnf& nnf, int radius,
    int firstSource, int firstTarget, int count, ChannelImage& target, const VoteSettings& settings)
{
    if (nnf.width != target.width() || nnf.height != target.height())
        throw ValueError("voteRotated: the field must have the target's size");
    if (frames.empty()) throw ValueError("voteRotated: no source frames");
    for (const ChannelImage* f : frames)
        if (!f || f->empty() || firstSource < 0 || count < 1 || firstSource + count > f->channels())
            throw ValueError("voteRotated: a source frame is missing or lacks the channels");
    if (firstTarget < 0 || firstTarget + count > target.channels())
        throw ValueError("voteRotated: channel range outside the target");
    for (const PatchRef& m : nnf.match)
        if (m.valid() && size_t(m.frame) >= frames.size())
            throw ValueError(
                "voteRotated: a match names frame " + std::to_string(m.frame) + " of " + std::to_string(frames.size()));
    const int W = target.width(), n = 2 * radius + 1;
    // Bilinear taps per rotation step and offset: centres are whole pixels, so the fractions depend on
    // (rotation, offset) only.
    struct Tap
    {
        int ix, iy;
        float fx, fy;
    };
    std::vector<Tap> taps(size_t(kRotations) * size_t(n) * size_t(n));
    for (int k = 0; k < kRotations; ++k)
        for (int dy = -radius; dy <= radius; ++dy)
            for (int dx = -radius; dx <= radius; ++dx) {
                double ox = 0.0, oy = 0.0;
                sourceOffset(k, dx, dy, ox, oy);
                const double fx = std::floor(ox), fy = std::floor(oy);
                taps[(size_t(k) * size_t(n) + size_t(dy + radius)) * size_t(n) + size_t(dx + radius)] =
                    Tap{int(fx), int(fy), float(ox - fx), float(oy - fy)};
            }
    return averageOverCoveringPatches(
        radius, firstTarget, count, target, settings, [&](int cx, int cy, int dx, int dy, std::vector<double>& acc) {
            const PatchRef& m = nnf.match[size_t(cy) * size_t(W) + size_t(cx)];
            if (!m.valid()) return 0.0;
            const ChannelImage& src = *frames[size_t(m.frame)];
            const Tap& t =
                taps[(size_t(m.rotation) * size_t(n) + size_t(dy + radius)) * size_t(n) + size_t(dx + radius)];
            const int sw = src.width(), sh = src.height();
            const int x0 = std::clamp(m.x + t.ix, 0, sw - 1), x1 = std::clamp(m.x + t.ix + 1, 0, sw - 1);
            const int y0s = std::clamp(m.y + t.iy, 0, sh - 1), y1s = std::clamp(m.y + t.iy + 1, 0, sh - 1);
            const float *a = src.pixel(x0, y0s) + firstSource, *b = src.pixel(x1, y0s) + firstSource;
            const float *c = src.pixel(x0, y1s) + firstSource, *d = src.pixel(x1, y1s) + firstSource;
            for (int ch = 0; ch < count; ++ch)
                acc[size_t(ch)] +=
                    (1 - t.fy) * ((1 - t.fx) * a[ch] + t.fx * b[ch]) + t.fy * ((1 - t.fx) * c[ch] + t.fx * d[ch]);
            return 1.0;
        });
}

} // namespace turb
