#include <turb/Voting.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <string>

namespace turb {

std::vector<int> vote(const ChannelImage& source, const Nnf& nnf, int radius, int firstSource, int firstTarget, int count,
    ChannelImage& target, const VoteSettings& settings)
{
    if (nnf.width != target.width() || nnf.height != target.height())
        throw ValueError("vote: the field must have the target's size");
    if (firstSource < 0 || firstTarget < 0 || count < 1 || firstSource + count > source.channels() ||
        firstTarget + count > target.channels())
        throw ValueError("vote: channel range outside the images");
    const int W = target.width(), H = target.height(), sW = source.width();
    std::vector<int> votes(target.pixelCount(), 0);
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        std::vector<double> acc(static_cast<size_t>(count));
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            for (int x = 0; x < W; ++x) {
                std::fill(acc.begin(), acc.end(), 0.0);
                int n = 0;
                for (int dy = -radius; dy <= radius; ++dy) {
                    const int cy = y - dy;
                    if (cy < 0 || cy >= H) continue;
                    for (int dx = -radius; dx <= radius; ++dx) {
                        const int cx = x - dx;
                        if (cx < 0 || cx >= W) continue;
                        const std::int32_t p = nnf.source[size_t(cy) * size_t(W) + size_t(cx)];
                        if (p < 0) continue;
                        const float* s = source.pixel(p % sW + dx, p / sW + dy) + firstSource;
                        for (int c = 0; c < count; ++c) acc[size_t(c)] += s[c];
                        ++n;
                    }
                }
                float* t = target.pixel(x, y) + firstTarget;
                for (int c = 0; c < count; ++c) t[c] = n ? float(acc[size_t(c)] / n) : settings.empty;
                votes[size_t(y) * size_t(W) + size_t(x)] = n;
            }
        }
    });
    return votes;
}

std::vector<int> voteRotated(const std::vector<const ChannelImage*>& frames, const RotatedNnf& nnf, int radius, int firstSource,
    int firstTarget, int count, ChannelImage& target, const VoteSettings& settings)
{
    if (nnf.width != target.width() || nnf.height != target.height())
        throw ValueError("voteRotated: the field must have the target's size");
    if (frames.empty()) throw ValueError("voteRotated: no source frames");
    for (const ChannelImage* f : frames)
        if (!f || f->empty() || firstSource < 0 || count < 1 || firstSource + count > f->channels())
            throw ValueError("voteRotated: a source frame is missing or lacks the channels");
    if (firstTarget < 0 || firstTarget + count > target.channels()) throw ValueError("voteRotated: channel range outside the target");
    for (const PatchRef& m : nnf.match)
        if (m.valid() && size_t(m.frame) >= frames.size())
            throw ValueError("voteRotated: a match names frame " + std::to_string(m.frame) + " of " + std::to_string(frames.size()));
    const int W = target.width(), H = target.height();
    std::vector<int> votes(target.pixelCount(), 0);
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        std::vector<double> acc(static_cast<size_t>(count));
        std::vector<float> sample;
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            for (int x = 0; x < W; ++x) {
                std::fill(acc.begin(), acc.end(), 0.0);
                int n = 0;
                for (int dy = -radius; dy <= radius; ++dy) {
                    const int cy = y - dy;
                    if (cy < 0 || cy >= H) continue;
                    for (int dx = -radius; dx <= radius; ++dx) {
                        const int cx = x - dx;
                        if (cx < 0 || cx >= W) continue;
                        const PatchRef& m = nnf.match[size_t(cy) * size_t(W) + size_t(cx)];
                        if (!m.valid()) continue;
                        const ChannelImage& src = *frames[size_t(m.frame)];
                        double ox = 0.0, oy = 0.0;
                        sourceOffset(m.rotation, dx, dy, ox, oy);
                        sample.resize(size_t(src.channels()));
                        sampleBilinear(src, m.x + ox, m.y + oy, sample.data());
                        for (int c = 0; c < count; ++c) acc[size_t(c)] += sample[size_t(firstSource + c)];
                        ++n;
                    }
                }
                float* t = target.pixel(x, y) + firstTarget;
                for (int c = 0; c < count; ++c) t[c] = n ? float(acc[size_t(c)] / n) : settings.empty;
                votes[size_t(y) * size_t(W) + size_t(x)] = n;
            }
        }
    });
    return votes;
}

} // namespace turb
