// Masks, flows from masks (Fluidymation Appendix A), signed distances and motion extents (section 3.3).
#include <turb/MotionGuides.h>

#include <turb/Distance.h>
#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

namespace turb {

namespace {

constexpr double kFar = kNoSiteSquaredDistance; // "no site": the squared distance of a pixel with no feature in reach

/// Squared Euclidean distance from every pixel to the nearest pixel with site[i] (kFar-ish if none).
std::vector<double> squaredDistance(const std::vector<char>& site, int W, int H)
{
    std::vector<double> g(site.size());
    parallelFor(size_t(W), 16, [&](size_t x0, size_t x1) {
        std::vector<double> f(static_cast<size_t>(H)), d(static_cast<size_t>(H)), z(static_cast<size_t>(H) + 1);
        std::vector<int> v(static_cast<size_t>(H));
        for (size_t x = x0; x < x1; ++x) {
            for (int y = 0; y < H; ++y) f[size_t(y)] = site[size_t(y) * size_t(W) + x] ? 0.0 : kFar;
            squaredDistance1D(f.data(), H, d.data(), v.data(), z.data());
            for (int y = 0; y < H; ++y) g[size_t(y) * size_t(W) + x] = d[size_t(y)];
        }
    });
    parallelFor(size_t(H), 16, [&](size_t y0, size_t y1) {
        std::vector<double> d(static_cast<size_t>(W)), z(static_cast<size_t>(W) + 1);
        std::vector<int> v(static_cast<size_t>(W));
        for (size_t y = y0; y < y1; ++y) {
            double* row = g.data() + y * size_t(W);
            squaredDistance1D(row, W, d.data(), v.data(), z.data());
            std::copy(d.begin(), d.end(), row);
        }
    });
    return g;
}

std::vector<char> insideOf(const ChannelImage& mask, float threshold)
{
    std::vector<char> in(mask.pixelCount());
    for (size_t i = 0; i < in.size(); ++i) in[i] = mask.pixel(i)[0] >= threshold;
    return in;
}

ChannelImage signedFromInside(const std::vector<char>& in, int W, int H)
{
    ChannelImage phi(W, H, 1);
    bool anyIn = false, anyOut = false;
    for (char c : in) (c ? anyIn : anyOut) = true;
    if (!anyIn || !anyOut) {
        std::fill(phi.data().begin(), phi.data().end(), float(anyIn ? -(W + H) : (W + H)));
        return phi;
    }
    std::vector<char> out(in.size());
    for (size_t i = 0; i < in.size(); ++i) out[i] = !in[i];
    const std::vector<double> dOut = squaredDistance(out, W, H), dIn = squaredDistance(in, W, H);
    for (size_t i = 0; i < in.size(); ++i)
        phi.pixel(i)[0] = in[i] ? -float(std::sqrt(dOut[i]) - 0.5) : float(std::sqrt(dIn[i]) - 0.5);
    return phi;
}

std::vector<char> boundaryOf(const std::vector<char>& in, int W, int H)
{
    std::vector<char> b(in.size(), 0);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const size_t i = size_t(y) * size_t(W) + size_t(x);
            if (!in[i]) continue;
            b[i] = (x > 0 && !in[i - 1]) || (x < W - 1 && !in[i + 1]) || (y > 0 && !in[i - size_t(W)]) ||
                   (y < H - 1 && !in[i + size_t(W)]);
        }
    return b;
}

/// Appendix A's boundary speed along the outward normal of phi, diffused inside (see the header).
ChannelImage flowFromDistances(const ChannelImage& phi, const ChannelImage& phiOther, bool otherIsNext,
    const std::vector<char>& in, const MotionGuideSettings& s)
{
    const int W = phi.width(), H = phi.height();
    const std::vector<char> fixed = boundaryOf(in, W, H);
    ChannelImage values(W, H, 2);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const size_t i = phi.index(x, y);
            if (!fixed[i]) continue;
            const double gx = 0.5 * (phi.at(std::min(W - 1, x + 1), y, 0) - phi.at(std::max(0, x - 1), y, 0));
            const double gy = 0.5 * (phi.at(x, std::min(H - 1, y + 1), 0) - phi.at(x, std::max(0, y - 1), 0));
            const double g = std::hypot(gx, gy);
            if (!(g > 1e-6)) continue;
            const double dphi =
                otherIsNext ? phiOther.pixel(i)[0] - phi.pixel(i)[0] : phi.pixel(i)[0] - phiOther.pixel(i)[0];
            const double speed = std::clamp(-dphi, -double(s.maxBoundarySpeed), double(s.maxBoundarySpeed));
            values.pixel(i)[0] = float(speed * gx / g);
            values.pixel(i)[1] = float(speed * gy / g);
        }
    return diffuseFromBoundary(values, fixed, in, s.diffusionSweeps);
}

void validate(const MotionGuideSettings& s)
{
    if (!(s.smoothingRadius >= 0.0) || s.smoothingRadius > 50.0)
        throw ValueError("motion guides: smoothing radius must lie in 0..50 frames");
    if (!(s.maxBoundarySpeed > 0.0f)) throw ValueError("motion guides: the maximum boundary speed must be > 0");
    if (s.diffusionSweeps < 1) throw ValueError("motion guides: diffusion sweeps must be >= 1");
}

} // namespace

ChannelImage signedDistance(const ChannelImage& mask, float threshold)
{
    return signedFromInside(insideOf(mask, threshold), mask.width(), mask.height());
}

std::vector<char> boundaryPixels(const ChannelImage& mask, float threshold)
{
    return boundaryOf(insideOf(mask, threshold), mask.width(), mask.height());
}

namespace {

/// One level of diffuseFromBoundary's pyramid.
struct Level
{
    int W, H;
    std::vector<std::uint8_t> state; // 0 outside, 1 free, 2 fixed
    ChannelImage val;
};

/// The finest level: the fixed values where fixed, zero elsewhere. `anyFree`: some inside pixel is not fixed.
Level finestLevel(
    const ChannelImage& values, const std::vector<char>& fixed, const std::vector<char>& inside, bool& anyFree)
{
    const int C = values.channels();
    Level l0{values.width(), values.height(), std::vector<std::uint8_t>(values.pixelCount()),
        ChannelImage(values.width(), values.height(), C)};
    anyFree = false;
    for (size_t i = 0; i < values.pixelCount(); ++i) {
        const std::uint8_t st = inside[i] ? (fixed[i] ? 2 : 1) : 0;
        l0.state[i] = st;
        anyFree |= st == 1;
        if (st == 2) std::copy(values.pixel(i), values.pixel(i) + C, l0.val.pixel(i));
    }
    return l0;
}

/// The next coarser level: a coarse pixel is fixed (the mean of its fixed children) if any child is fixed.
Level coarserLevel(const Level& f, int C)
{
    Level c{(f.W + 1) / 2, (f.H + 1) / 2, {}, {}};
    c.state.assign(size_t(c.W) * size_t(c.H), 0);
    c.val = ChannelImage(c.W, c.H, C);
    for (int y = 0; y < c.H; ++y)
        for (int x = 0; x < c.W; ++x) {
            int nFixed = 0;
            bool free = false;
            float* o = c.val.pixel(x, y);
            for (int dy = 0; dy < 2; ++dy)
                for (int dx = 0; dx < 2; ++dx) {
                    const int fx = 2 * x + dx, fy = 2 * y + dy;
                    if (fx >= f.W || fy >= f.H) continue;
                    const std::uint8_t st = f.state[size_t(fy) * size_t(f.W) + size_t(fx)];
                    if (st == 2) {
                        const float* v = f.val.pixel(fx, fy);
                        for (int k = 0; k < C; ++k) o[k] += v[k];
                        ++nFixed;
                    }
                    free |= st == 1;
                }
            if (nFixed)
                for (int k = 0; k < C; ++k) o[k] /= float(nFixed);
            c.state[c.val.index(x, y)] = nFixed ? 2 : (free ? 1 : 0);
        }
    return c;
}

/// n red-black Gauss-Seidel sweeps of the Laplace equation over the free pixels of L (a colour's pixels read only
/// the other colour's, so rows can run in parallel with the same result).
void relax(Level& L, int n, int C)
{
    for (int it = 0; it < n; ++it)
        for (int colour = 0; colour < 2; ++colour)
            parallelFor(size_t(L.H), 32, [&](size_t y0, size_t y1) {
                std::vector<float> acc(static_cast<size_t>(C));
                for (size_t yy = y0; yy < y1; ++yy) {
                    const int y = int(yy);
                    for (int x = (y + colour) % 2; x < L.W; x += 2) {
                        const size_t i = L.val.index(x, y);
                        if (L.state[i] != 1) continue;
                        std::fill(acc.begin(), acc.end(), 0.0f);
                        int n = 0;
                        const auto add = [&](int nx, int ny) {
                            if (nx < 0 || ny < 0 || nx >= L.W || ny >= L.H) return;
                            const size_t j = L.val.index(nx, ny);
                            if (!L.state[j]) return;
                            const float* v = L.val.pixel(j);
                            for (int k = 0; k < C; ++k) acc[size_t(k)] += v[k];
                            ++n;
                        };
                        add(x - 1, y);
                        add(x + 1, y);
                        add(x, y - 1);
                        add(x, y + 1);
                        if (n)
                            for (int k = 0; k < C; ++k) L.val.pixel(i)[k] = acc[size_t(k)] / float(n);
                    }
                }
            });
}

/// The coarser level's solution as the start of the finer one's free pixels (nearest parent).
void prolong(const Level& c, Level& f, int C)
{
    for (int y = 0; y < f.H; ++y)
        for (int x = 0; x < f.W; ++x) {
            const size_t i = f.val.index(x, y);
            if (f.state[i] == 1) std::copy(c.val.pixel(x / 2, y / 2), c.val.pixel(x / 2, y / 2) + C, f.val.pixel(i));
        }
}

} // namespace

ChannelImage diffuseFromBoundary(
    const ChannelImage& values, const std::vector<char>& fixed, const std::vector<char>& inside, int sweeps)
{
    const int C = values.channels();
    if (fixed.size() != values.pixelCount() || inside.size() != values.pixelCount())
        throw ValueError("diffuseFromBoundary: fixed and inside must have one entry per pixel");
    std::vector<Level> levels(1);
    bool anyFree = false;
    levels[0] = finestLevel(values, fixed, inside, anyFree);
    if (!anyFree) return levels[0].val;
    while (std::max(levels.back().W, levels.back().H) > 4) levels.push_back(coarserLevel(levels.back(), C));
    relax(levels.back(), std::max(sweeps, 4 * (levels.back().W + levels.back().H)), C);
    for (int l = int(levels.size()) - 2; l >= 0; --l) {
        prolong(levels[size_t(l) + 1], levels[size_t(l)], C);
        relax(levels[size_t(l)], sweeps, C);
    }
    return std::move(levels[0].val);
}

ChannelImage maskFlow(
    const ChannelImage& mask, const ChannelImage& other, bool otherIsNext, const MotionGuideSettings& settings)
{
    validate(settings);
    if (mask.channels() != 1 || other.channels() != 1 || !mask.sameSize(other))
        throw ValueError("maskFlow: the two masks must be 1-channel images of one size");
    const std::vector<char> in = insideOf(mask, 0.5f);
    const ChannelImage phi = signedFromInside(in, mask.width(), mask.height());
    const ChannelImage phiOther = signedDistance(other);
    return flowFromDistances(phi, phiOther, otherIsNext, in, settings);
}

MotionSequence::MotionSequence(int width, int height) : mWidth(width), mHeight(height)
{
    if (width < 1 || height < 1) throw ValueError("motion sequence: size must be at least 1x1");
}

void MotionSequence::addFrame(const ChannelImage& mask, const ChannelImage* flow, float threshold)
{
    const std::string which = "motion sequence frame " + std::to_string(mFrames.size());
    if (mFinished) throw ValueError(which + ": the sequence is already finished");
    if (mask.channels() != 1 || mask.width() != mWidth || mask.height() != mHeight)
        throw ValueError(which + ": the mask must be 1 channel of " + std::to_string(mWidth) + "x" +
                         std::to_string(mHeight) + " pixels");
    if (flow && (flow->channels() != 2 || !flow->sameSize(mask)))
        throw ValueError(which + ": the flow must be 2 channels of the mask's size");
    if (!mFrames.empty() && mFlowGiven != (flow != nullptr))
        throw ValueError(which + ": give a flow for every frame or for none (then they are estimated from the masks)");
    mFlowGiven = flow != nullptr;
    Frame f;
    for (size_t i = 0; i < mask.pixelCount(); ++i)
        if (mask.pixel(i)[0] >= threshold) f.pixels.push_back(std::int32_t(i));
    f.flow.assign(2 * f.pixels.size(), 0.0f);
    if (flow)
        for (size_t k = 0; k < f.pixels.size(); ++k) {
            const float* v = flow->pixel(size_t(f.pixels[k]));
            if (!std::isfinite(v[0]) || !std::isfinite(v[1]))
                throw ValueError(which + ": the flow holds NaN or infinite values");
            f.flow[2 * k] = v[0];
            f.flow[2 * k + 1] = v[1];
        }
    mFrames.push_back(std::move(f));
}

ChannelImage MotionSequence::scatter(const Frame& f, const std::vector<float>& values, int channels) const
{
    ChannelImage out(mWidth, mHeight, channels);
    for (size_t k = 0; k < f.pixels.size(); ++k)
        for (int c = 0; c < channels; ++c) out.pixel(size_t(f.pixels[k]))[c] = values[k * size_t(channels) + size_t(c)];
    return out;
}

ChannelImage MotionSequence::mask(int i) const
{
    const Frame& f = mFrames.at(size_t(i));
    ChannelImage out(mWidth, mHeight, 1);
    for (std::int32_t p : f.pixels) out.pixel(size_t(p))[0] = 1.0f;
    return out;
}

ChannelImage MotionSequence::flow(int i) const { return scatter(mFrames.at(size_t(i)), mFrames.at(size_t(i)).flow, 2); }

ChannelImage MotionSequence::extents(int i) const
{
    const Frame& f = mFrames.at(size_t(i));
    if (!mFinished) throw ValueError("motion sequence: extents are known after finish()");
    return scatter(f, f.ext, 2);
}

ChannelImage MotionSequence::distance(int i) const { return signedDistance(mask(i)); }

namespace {

// The steps of MotionSequence::finish. They take the frames as a template parameter because Frame is the class's
// private record (the public header stays as it is); `mask(i)` gives frame i's dense mask and `dense(frame, values)`
// a frame's 2 values per masked pixel as a dense image.

// Appendix A: each frame's raw flow (2 per masked pixel) from the distance fields of it and its next (the last
// frame: previous) frame, before temporal smoothing.
template<typename Frames, typename MaskOf>
std::vector<std::vector<float>> rawMaskFlows(
    const Frames& frames, const MaskOf& mask, const MotionGuideSettings& s, Progress* progress)
{
    const int F = int(frames.size());
    std::map<int, ChannelImage> phi;
    const auto phiOf = [&](int i) -> const ChannelImage& {
        auto it = phi.find(i);
        if (it == phi.end()) it = phi.emplace(i, signedDistance(mask(i))).first;
        return it->second;
    };
    std::vector<std::vector<float>> raw(static_cast<size_t>(F));
    for (int i = 0; i < F; ++i) {
        checkCancelled(progress);
        const auto& f = frames[size_t(i)];
        if (F > 1) {
            const bool next = i + 1 < F;
            const ChannelImage m = mask(i);
            const ChannelImage fl =
                flowFromDistances(phiOf(i), phiOf(next ? i + 1 : i - 1), next, insideOf(m, 0.5f), s);
            raw[size_t(i)].resize(2 * f.pixels.size());
            for (size_t k = 0; k < f.pixels.size(); ++k) {
                raw[size_t(i)][2 * k] = fl.pixel(size_t(f.pixels[k]))[0];
                raw[size_t(i)][2 * k + 1] = fl.pixel(size_t(f.pixels[k]))[1];
            }
        } else {
            raw[size_t(i)].assign(2 * f.pixels.size(), 0.0f);
        }
        phi.erase(i - 1);
        if (progress) progress->update(0.5 * double(i + 1) / F);
    }
    return raw;
}

// Appendix A's temporal smoothing: a frame's flow at a pixel is the Gaussian-weighted mean (sigma = radius / 3) of
// the raw flows of the frames within R that hold the pixel in their masks.
template<typename Frames, typename MaskOf, typename Dense>
void smoothFlowsInTime(Frames& frames, const std::vector<std::vector<float>>& raw, int R, const MotionGuideSettings& s,
    const MaskOf& mask, const Dense& dense, Progress* progress)
{
    const int F = int(frames.size());
    const double sigma = s.smoothingRadius / 3.0;
    std::map<int, std::pair<ChannelImage, ChannelImage>> window; // flow, mask per frame in the window
    for (int i = 0; i < F; ++i) {
        checkCancelled(progress);
        for (int k = std::max(0, i - R); k <= std::min(F - 1, i + R); ++k)
            if (!window.count(k)) window.emplace(k, std::make_pair(dense(frames[size_t(k)], raw[size_t(k)]), mask(k)));
        window.erase(i - R - 1);
        auto& f = frames[size_t(i)];
        for (size_t n = 0; n < f.pixels.size(); ++n) {
            const size_t p = size_t(f.pixels[n]);
            double sx = 0.0, sy = 0.0, sw = 0.0;
            for (int k = std::max(0, i - R); k <= std::min(F - 1, i + R); ++k) {
                const auto& [fl, m] = window.at(k);
                if (m.pixel(p)[0] < 0.5f) continue;
                const double w = std::exp(-0.5 * double(k - i) * double(k - i) / (sigma * sigma));
                sx += w * fl.pixel(p)[0];
                sy += w * fl.pixel(p)[1];
                sw += w;
            }
            f.flow[2 * n] = float(sx / sw);
            f.flow[2 * n + 1] = float(sy / sw);
        }
    }
}

// Section 3.3: forward and backward accumulation of the flow, restarted outside the mask: a frame's extents are
// the lengths of the accumulated flows at its masked pixels.
template<typename Frames>
void accumulateExtents(Frames& frames, int width, int height, Progress* progress)
{
    const int F = int(frames.size());
    ChannelImage acc(width, height, 2);
    for (int pass = 0; pass < 2; ++pass) {
        std::fill(acc.data().begin(), acc.data().end(), 0.0f);
        for (int n = 0; n < F; ++n) {
            checkCancelled(progress);
            const int i = pass == 0 ? n : F - 1 - n;
            auto& f = frames[size_t(i)];
            const int src = pass == 0 ? i - 1 : i; // acc+(i) adds F^{i-1}; acc-(i) adds F^i
            ChannelImage next(width, height, 2);
            if (n > 0) { // acc+(0) = 0 and acc-(last) = 0
                const auto& g = frames[size_t(src)];
                for (size_t k = 0; k < g.pixels.size(); ++k) {
                    float* a = acc.pixel(size_t(g.pixels[k]));
                    a[0] += g.flow[2 * k];
                    a[1] += g.flow[2 * k + 1];
                }
            }
            f.ext.resize(2 * f.pixels.size());
            for (size_t k = 0; k < f.pixels.size(); ++k) {
                const float* a = acc.pixel(size_t(f.pixels[k]));
                f.ext[2 * k + size_t(pass)] = std::hypot(a[0], a[1]);
                std::copy(a, a + 2, next.pixel(size_t(f.pixels[k])));
            }
            acc = std::move(next); // zero outside mask i
        }
    }
}

} // namespace

void MotionSequence::finish(const MotionGuideSettings& s, Progress* progress)
{
    validate(s);
    if (mFrames.empty()) throw ValueError("motion sequence: no frames");
    if (mFinished) return;
    const int F = frames();
    if (!mFlowGiven) {
        // Appendix A: raw flows from consecutive distance fields, then temporal smoothing.
        mEstimated = true;
        const auto maskOf = [this](int i) { return mask(i); };
        const std::vector<std::vector<float>> raw = rawMaskFlows(mFrames, maskOf, s, progress);
        const int R = int(std::floor(s.smoothingRadius));
        if (R >= 1 && F > 1) {
            const auto dense = [this](const Frame& f, const std::vector<float>& v) { return scatter(f, v, 2); };
            smoothFlowsInTime(mFrames, raw, R, s, maskOf, dense, progress);
        } else {
            for (int i = 0; i < F; ++i) mFrames[size_t(i)].flow = raw[size_t(i)];
        }
    }
    accumulateExtents(mFrames, mWidth, mHeight, progress);
    mFinished = true;
    if (progress) progress->update(1.0);
}

} // namespace turb
