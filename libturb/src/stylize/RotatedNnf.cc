// The (i, x, y, theta) nearest-neighbour field of Fluidymation: rotation tables, UPSCALENNF, DOWNSCALENNF.
#include <turb/RotatedNnf.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace turb {

namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

int roundHalfUp(double v) { return int(std::floor(v + 0.5)); }

struct Trig
{
    double c[kRotations], s[kRotations];
    Trig()
    {
        for (int k = 0; k < kRotations; ++k) {
            c[k] = std::cos(rotationAngle(k));
            s[k] = std::sin(rotationAngle(k));
        }
    }
};
const Trig& trig()
{
    static const Trig t;
    return t;
}

} // namespace

double rotationAngle(int k) { return kTwoPi * double(((k % kRotations) + kRotations) % kRotations) / kRotations; }

int rotationIndex(double theta)
{
    if (!std::isfinite(theta)) return 0;
    const long k = std::lround(theta / kTwoPi * kRotations);
    return int(((k % kRotations) + kRotations) % kRotations);
}

RotatedNnf emptyRotatedNnf(int width, int height)
{
    RotatedNnf n;
    n.width = std::max(0, width);
    n.height = std::max(0, height);
    n.match.assign(size_t(n.width) * size_t(n.height), PatchRef{});
    n.distance.assign(n.match.size(), std::numeric_limits<float>::infinity());
    return n;
}

void sourceOffset(int k, double dx, double dy, double& sx, double& sy)
{
    // R_{-theta}: the transpose of R_theta.
    const int i = ((k % kRotations) + kRotations) % kRotations;
    const double c = trig().c[i], s = trig().s[i];
    sx = c * dx + s * dy;
    sy = -s * dx + c * dy;
}

RotationTable::RotationTable(int radius) : mRadius(radius), mCount((2 * radius + 1) * (2 * radius + 1))
{
    if (radius < 1) throw ValueError("rotation table: radius must be >= 1");
    mOffsets.resize(size_t(kRotations) * size_t(2 * mCount));
    for (int k = 0; k < kRotations; ++k) {
        int t = 0;
        for (int dy = -radius; dy <= radius; ++dy)
            for (int dx = -radius; dx <= radius; ++dx, ++t) {
                double sx = 0.0, sy = 0.0;
                sourceOffset(k, dx, dy, sx, sy);
                const int ix = roundHalfUp(sx), iy = roundHalfUp(sy);
                mOffsets[size_t(k) * size_t(2 * mCount) + size_t(2 * t)] = ix;
                mOffsets[size_t(k) * size_t(2 * mCount) + size_t(2 * t + 1)] = iy;
                mReach = std::max(mReach, std::max(std::abs(ix), std::abs(iy)));
            }
    }
}

RotatedNnf upscaleNnf(const RotatedNnf& coarse, int fineWidth, int fineHeight)
{
    if (coarse.match.size() != size_t(coarse.width) * size_t(coarse.height))
        throw ValueError("upscaleNnf: malformed field");
    if ((fineWidth + 1) / 2 > coarse.width || (fineHeight + 1) / 2 > coarse.height)
        throw ValueError("upscaleNnf: the fine grid must be at most twice the coarse one");
    RotatedNnf fine = emptyRotatedNnf(fineWidth, fineHeight);
    parallelFor(size_t(fineHeight), 16, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            for (int x = 0; x < fineWidth; ++x) {
                const PatchRef& c = coarse.match[size_t(y / 2) * size_t(coarse.width) + size_t(x / 2)];
                if (!c.valid()) continue;
                double ox = 0.0, oy = 0.0;
                sourceOffset(c.rotation, double(x % 2) - 0.5, double(y % 2) - 0.5, ox, oy);
                PatchRef f = c;
                f.x = std::int16_t(roundHalfUp(2.0 * c.x + 0.5 + ox));
                f.y = std::int16_t(roundHalfUp(2.0 * c.y + 0.5 + oy));
                fine.match[size_t(y) * size_t(fineWidth) + size_t(x)] = f;
            }
        }
    });
    return fine;
}

RotatedNnf downscaleNnf(const RotatedNnf& fine, int levels, int coarseWidth, int coarseHeight)
{
    if (levels < 0 || levels > 12) throw ValueError("downscaleNnf: levels must lie in 0..12");
    if (fine.match.size() != size_t(fine.width) * size_t(fine.height))
        throw ValueError("downscaleNnf: malformed field");
    const int B = 1 << levels;
    const double c = (B - 1) / 2.0;
    RotatedNnf out = emptyRotatedNnf(coarseWidth, coarseHeight);
    parallelFor(size_t(coarseHeight), 8, [&](size_t y0, size_t y1) {
        std::vector<PatchRef> keys;
        std::vector<int> counts;
        for (size_t yy = y0; yy < y1; ++yy) {
            const int Y = int(yy);
            for (int X = 0; X < coarseWidth; ++X) {
                keys.clear();
                counts.clear();
                for (int b = 0; b < B; ++b)
                    for (int a = 0; a < B; ++a) {
                        const int fx = B * X + a, fy = B * Y + b;
                        if (fx >= fine.width || fy >= fine.height) continue;
                        const PatchRef& m = fine.match[size_t(fy) * size_t(fine.width) + size_t(fx)];
                        if (!m.valid()) continue;
                        double ox = 0.0, oy = 0.0;
                        sourceOffset(m.rotation, a - c, b - c, ox, oy);
                        PatchRef k = m;
                        k.x = std::int16_t(roundHalfUp((m.x - ox - c) / B));
                        k.y = std::int16_t(roundHalfUp((m.y - oy - c) / B));
                        size_t j = 0;
                        while (j < keys.size() && !(keys[j].frame == k.frame && keys[j].x == k.x && keys[j].y == k.y))
                            ++j;
                        if (j == keys.size()) {
                            keys.push_back(k);
                            counts.push_back(0);
                        }
                        ++counts[j];
                    }
                if (keys.empty()) continue;
                size_t best = 0;
                for (size_t j = 1; j < keys.size(); ++j)
                    if (counts[j] > counts[best]) best = j;
                out.match[size_t(Y) * size_t(coarseWidth) + size_t(X)] = keys[best];
            }
        }
    });
    return out;
}

} // namespace turb
