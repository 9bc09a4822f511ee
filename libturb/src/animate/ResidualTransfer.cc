#include <turb/ResidualTransfer.h>

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/PatchIndex.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>

namespace turb {

void validate(const ResidualTransferSettings& s)
{
    if (s.patchSize < 8 || s.patchSize > 64) throw ValueError("transfer: the patch size must be 8..64 pixels");
    if (s.downsample != 1 && s.downsample != 2 && s.downsample != 4)
        throw ValueError("transfer: downsample must be 1, 2 or 4");
    if (s.pcaComponents < 1) throw ValueError("transfer: PCA components must be >= 1");
    if (!(s.feather >= 0.0 && s.feather <= 0.5)) throw ValueError("transfer: feather must be in [0, 0.5]");
    if (s.candidates < 1 || s.candidates > 64) throw ValueError("transfer: candidates must be 1..64");
    if (!(s.variety >= 0.0 && s.variety <= 1.0)) throw ValueError("transfer: variety must be in [0, 1]");
}

TransferMap::TransferMap(int tw, int th, int ew, int eh)
    : mWidth(tw), mHeight(th), mExWidth(ew), mExHeight(eh), mSource(size_t(tw) * size_t(th) * kTaps, 0u),
      mWeight(size_t(tw) * size_t(th) * kTaps, 0.0f)
{}

void TransferMap::addTap(size_t i, std::uint32_t source, float w)
{
    float* wt = &mWeight[i * kTaps];
    std::uint32_t* src = &mSource[i * kTaps];
    int lightest = 0;
    for (int k = 0; k < kTaps; ++k) {
        if (wt[k] == 0.0f) {
            wt[k] = w;
            src[k] = source;
            return;
        }
        if (wt[k] < wt[lightest]) lightest = k;
    }
    if (w > wt[lightest]) {
        wt[lightest] = w;
        src[lightest] = source;
    }
}

void TransferMap::normalise()
{
    const size_t n = size_t(mWidth) * size_t(mHeight);
    for (size_t i = 0; i < n; ++i) {
        float s = 0.0f;
        for (int k = 0; k < kTaps; ++k) s += mWeight[i * kTaps + size_t(k)];
        if (s > 0.0f)
            for (int k = 0; k < kTaps; ++k) mWeight[i * kTaps + size_t(k)] /= s;
    }
}

void TransferMap::clearTaps(size_t i)
{
    for (int k = 0; k < kTaps; ++k) {
        mWeight[i * kTaps + size_t(k)] = 0.0f;
        mSource[i * kTaps + size_t(k)] = 0u;
    }
}

ChannelImage TransferMap::apply(const ChannelImage& ex) const
{
    if (ex.width() != mExWidth || ex.height() != mExHeight)
        throw ValueError("TransferMap: the image is " + std::to_string(ex.width()) + "x" + std::to_string(ex.height()) +
                         ", the example is " + std::to_string(mExWidth) + "x" + std::to_string(mExHeight));
    const int C = ex.channels();
    ChannelImage out(mWidth, mHeight, C);
    parallelFor(out.pixelCount(), 1 << 12, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            float* o = out.pixel(i);
            for (int k = 0; k < kTaps; ++k) {
                const float w = mWeight[i * kTaps + size_t(k)];
                if (w == 0.0f) continue;
                const float* s = ex.pixel(size_t(mSource[i * kTaps + size_t(k)]));
                for (int c = 0; c < C; ++c) o[c] += w * s[c];
            }
        }
    });
    return out;
}

namespace {

ChannelImage reduced(const ChannelImage& flow, int factor)
{
    ChannelImage r = flow;
    for (int f = factor; f > 1; f /= 2) r = reduceByTwo(r);
    return r;
}

/// The p x p x 2 descriptor of `flow` at (x0, y0), coordinates clamped into the image.
void descriptor(const ChannelImage& flow, int x0, int y0, int p, float* out)
{
    for (int v = 0; v < p; ++v)
        for (int u = 0; u < p; ++u) {
            const int x = std::clamp(x0 + u, 0, flow.width() - 1), y = std::clamp(y0 + v, 0, flow.height() - 1);
            const float* f = flow.pixel(x, y);
            *out++ = f[0];
            *out++ = f[1];
        }
}

std::vector<int> patchStarts(int size, int patch)
{
    std::vector<int> at;
    const int stride = std::max(1, patch / 2);
    for (int v = 0; v + patch < size; v += stride) at.push_back(v);
    at.push_back(std::max(0, size - patch));
    return at;
}

struct Placed
{
    int tx = 0, ty = 0; // target patch corner, full resolution
    int ex = 0, ey = 0; // example window corner, full resolution
    double cost = 0.0;  // |s - e|^2 per pixel
    size_t order = 0;   // position in the patch grid (tie-break)
};

/// Linear ramp of the patch alpha along one axis: 1 in the core, 0 at edges that lie inside the image.
float ramp(int u, int patch, bool lowInside, bool highInside, double fw)
{
    if (fw <= 0.0) return 1.0f;
    float r = 1.0f;
    if (lowInside) r = std::min(r, float((u + 0.5) / fw));
    if (highInside) r = std::min(r, float((patch - u - 0.5) / fw));
    return std::clamp(r, 0.0f, 1.0f);
}

/// Example window n of the search grid, in full-resolution pixels.
struct WindowGrid
{
    int nx, stride, d;
    int x(int n) const { return (n % nx) * stride * d; }
    int y(int n) const { return (n / nx) * stride * d; }
};

/// Which of patch k's K candidates (`nearest`, with costs `c`; -1 / < 0 where none) it takes: the cheapest, or with
/// `slack` > 0, among those whose rms flow difference is within `slack` of the cheapest's, the window farthest from
/// those the patches already decided within `reach` pixels took (cheaper on ties). `placed` is in row order, so those
/// neighbours are among the last rows before k; deciding in that order keeps the choice independent of threads.
int variedPick(const std::vector<Placed>& placed, size_t k, const int* nearest, const double* c, int K, double slack,
    int reach, const WindowGrid& grid)
{
    int best = 0;
    for (int j = 1; j < K; ++j)
        if (c[j] >= 0.0 && (c[best] < 0.0 || c[j] < c[best])) best = j;
    if (K == 1 || c[best] < 0.0 || !(slack > 0.0)) return best;
    std::vector<size_t> around;
    for (size_t o = k; o-- > 0 && placed[o].ty >= placed[k].ty - reach;)
        if (std::abs(placed[o].tx - placed[k].tx) <= reach) around.push_back(o);
    const double limit = std::sqrt(c[best]) + slack;
    int pick = best;
    double farthest = -1.0;
    for (int j = 0; j < K; ++j) {
        if (c[j] < 0.0 || std::sqrt(c[j]) > limit) continue;
        const int cx = grid.x(nearest[j]), cy = grid.y(nearest[j]);
        double dmin = std::numeric_limits<double>::max();
        for (size_t o : around) dmin = std::min(dmin, std::hypot(double(placed[o].ex - cx), double(placed[o].ey - cy)));
        if (dmin > farthest + 1e-9 || (dmin >= farthest - 1e-9 && c[j] < c[pick])) {
            farthest = dmin;
            pick = j;
        }
    }
    return pick;
}

/// The example's p x p windows at the search resolution, every `stride`-th along each axis (an nx x ny grid of M),
/// and the index of their descriptors.
struct ExampleWindows
{
    int p = 0, stride = 1, nx = 0, ny = 0;
    size_t dim = 0, M = 0;
    PatchIndex index;
};

// Every example window at the search resolution (a stride only when the descriptors would not fit in about 120 MB).
ExampleWindows indexWindows(const ChannelImage& ex, int p, int pcaComponents)
{
    ExampleWindows w;
    w.p = p;
    w.dim = size_t(2 * p * p);
    const size_t dim = w.dim;
    int stride = 1;
    while (size_t((ex.width() - p) / stride + 1) * size_t((ex.height() - p) / stride + 1) * dim > size_t(3e7)) ++stride;
    const int nx = (ex.width() - p) / stride + 1, ny = (ex.height() - p) / stride + 1;
    w.stride = stride;
    w.nx = nx;
    w.ny = ny;
    w.M = size_t(nx) * size_t(ny);
    std::vector<float> rows(w.M * dim);
    parallelFor(w.M, 1024, [&](size_t b, size_t e) {
        for (size_t k = b; k < e; ++k)
            descriptor(ex, int(k % size_t(nx)) * stride, int(k / size_t(nx)) * stride, p, &rows[k * dim]);
    });
    PcaSettings pca;
    pca.components = pcaComponents;
    w.index.build(std::move(rows), dim, pca);
    return w;
}

// The target's patches (P x P, half overlapping) that touch the matte, in row order.
std::vector<Placed> patchesOnMatte(int W, int H, int P, const ChannelImage* matte)
{
    std::vector<Placed> placed;
    const std::vector<int> xs = patchStarts(W, P), ys = patchStarts(H, P);
    for (int ty : ys)
        for (int tx : xs) {
            bool touches = !matte;
            for (int y = ty; !touches && y < std::min(H, ty + P); ++y)
                for (int x = tx; x < std::min(W, tx + P); ++x)
                    if (matte->at(x, y, 0) > 0.0f) {
                        touches = true;
                        break;
                    }
            if (touches) placed.push_back(Placed{tx, ty, 0, 0, 0.0, placed.size()});
        }
    return placed;
}

/// Per target patch: its K candidate windows (-1: none), their exact costs (< 0: none, until candidateCosts) and its
/// rms design speed.
struct Candidates
{
    int K = 1;
    std::vector<int> nearest;
    std::vector<double> costs, speed;
};

// Candidates: the nearest windows, and with variety windows drawn at random (seeded by the patch), which are
// what a flat region needs: its nearest windows are neighbours of one another, the same detail shifted.
Candidates candidateWindows(
    const ExampleWindows& w, const std::vector<float>& queries, size_t count, double variety, int candidates)
{
    const int KN = variety > 0.0 ? 8 : 1, KR = variety > 0.0 ? candidates : 0, K = KN + KR;
    Candidates c;
    c.K = K;
    std::vector<int> knn;
    std::vector<float> dist2;
    w.index.queryMany(queries.data(), count, KN, knn, dist2);
    std::vector<int>& nearest = c.nearest;
    nearest.assign(count * size_t(K), -1);
    for (size_t k = 0; k < count; ++k) {
        for (int j = 0; j < KN; ++j) nearest[k * size_t(K) + size_t(j)] = knn[k * size_t(KN) + size_t(j)];
        std::mt19937 rng(std::uint32_t(1000003u * k + 17u));
        std::uniform_int_distribution<int> any(0, int(w.M) - 1);
        for (int j = KN; j < K; ++j) nearest[k * size_t(K) + size_t(j)] = any(rng);
    }
    c.costs.assign(count * size_t(K), -1.0);
    c.speed.assign(count, 0.0);
    return c;
}

// Exact costs of every candidate, per pixel at the search resolution, and each patch's rms design speed.
void candidateCosts(Candidates& c, const ExampleWindows& w, const ChannelImage& ex, const std::vector<float>& queries,
    Progress* progress)
{
    const size_t dim = w.dim, count = c.speed.size();
    const int K = c.K, p = w.p, nx = w.nx, stride = w.stride;
    parallelFor(count, 64, [&](size_t b, size_t e) {
        checkCancelled(progress);
        std::vector<float> win(dim);
        for (size_t k = b; k < e; ++k) {
            const float* q = &queries[k * dim];
            double s2 = 0.0;
            for (size_t i = 0; i < dim; ++i) s2 += double(q[i]) * q[i];
            c.speed[k] = std::sqrt(s2 / double(p * p));
            for (int j = 0; j < K; ++j) {
                const int n = c.nearest[k * size_t(K) + size_t(j)];
                if (n < 0) continue;
                descriptor(ex, (n % nx) * stride, (n / nx) * stride, p, win.data());
                double cost = 0.0;
                for (size_t i = 0; i < dim; ++i) cost += double(q[i] - win[i]) * double(q[i] - win[i]);
                c.costs[k * size_t(K) + size_t(j)] = cost / double(p * p);
            }
        }
    });
}

// Each patch's window among its candidates (variedPick), decided in row order.
void pickWindows(std::vector<Placed>& placed, const Candidates& c, const WindowGrid& grid, double variety, int P)
{
    const int K = c.K;
    for (size_t k = 0; k < placed.size(); ++k) {
        const int pick = variedPick(placed, k, &c.nearest[k * size_t(K)], &c.costs[k * size_t(K)], K,
            variety * c.speed[k], 2 * std::max(1, P / 2), grid);
        const int n = std::max(0, c.nearest[k * size_t(K) + size_t(pick)]);
        placed[k].ex = grid.x(n);
        placed[k].ey = grid.y(n);
        placed[k].cost = std::max(0.0, c.costs[k * size_t(K) + size_t(pick)]);
    }
}

// The map's statistics: patches pasted, their costs, the distinct windows used and the share of pixels covered.
void recordStats(TransferMap& map, const std::vector<Placed>& placed, const std::vector<float>& cover, double costSum)
{
    map.stats.patches = int(placed.size());
    map.stats.meanCost = map.stats.pasted ? costSum / map.stats.pasted : 0.0;
    std::vector<std::pair<int, int>> used;
    for (const Placed& pl : placed) used.emplace_back(pl.ex, pl.ey);
    std::sort(used.begin(), used.end());
    map.stats.distinct = int(std::unique(used.begin(), used.end()) - used.begin());
    size_t covered = 0;
    for (float c : cover) covered += c > 0.0f;
    map.stats.covered = cover.empty() ? 0.0 : double(covered) / double(cover.size());
}

// Lapped pasting, most similar first, each patch under what is there.
TransferMap pastePatches(std::vector<Placed>& placed, const ChannelImage& exampleFlow, int W, int H,
    const ResidualTransferSettings& s, const ChannelImage* matte, Progress* progress)
{
    const int P = s.patchSize;
    std::sort(placed.begin(), placed.end(),
        [](const Placed& a, const Placed& b) { return a.cost != b.cost ? a.cost < b.cost : a.order < b.order; });
    TransferMap map(W, H, exampleFlow.width(), exampleFlow.height());
    std::vector<float> cover(size_t(W) * size_t(H), 0.0f);
    const double fw = s.feather * P;
    const int EW = exampleFlow.width(), EH = exampleFlow.height();
    double costSum = 0.0;
    for (const Placed& pl : placed) {
        checkCancelled(progress);
        const int x1 = std::min(W, pl.tx + P), y1 = std::min(H, pl.ty + P);
        float open = 0.0f;
        for (int y = pl.ty; y < y1; ++y)
            for (int x = pl.tx; x < x1; ++x) open = std::max(open, 1.0f - cover[size_t(y) * size_t(W) + size_t(x)]);
        if (open < 1e-3f) continue;
        for (int y = pl.ty; y < y1; ++y) {
            const float ry = ramp(y - pl.ty, P, pl.ty > 0, pl.ty + P < H, fw);
            for (int x = pl.tx; x < x1; ++x) {
                const float m = ry * ramp(x - pl.tx, P, pl.tx > 0, pl.tx + P < W, fw);
                const size_t i = size_t(y) * size_t(W) + size_t(x);
                if (matte && matte->at(x, y, 0) <= 0.0f) continue;
                const float a = m * (1.0f - cover[i]);
                if (a <= 1e-6f) continue;
                const int sx = std::min(EW - 1, pl.ex + (x - pl.tx)), sy = std::min(EH - 1, pl.ey + (y - pl.ty));
                map.addTap(i, std::uint32_t(size_t(sy) * size_t(EW) + size_t(sx)), a);
                cover[i] += a;
            }
        }
        ++map.stats.pasted;
        costSum += pl.cost;
        map.stats.maxCost = std::max(map.stats.maxCost, pl.cost);
    }
    map.normalise();
    recordStats(map, placed, cover, costSum);
    return map;
}

} // namespace

TransferMap matchResiduals(const ChannelImage& exampleFlow, const ChannelImage& targetFlow,
    const ResidualTransferSettings& s, const ChannelImage* matte, Progress* progress)
{
    validate(s);
    if (exampleFlow.channels() != 2 || targetFlow.channels() != 2)
        throw ValueError("matchResiduals: flows must have 2 channels");
    if (matte && (!matte->sameSize(targetFlow) || matte->channels() != 1))
        throw ValueError("matchResiduals: the matte must be a 1-channel image of the target's size");
    const int d = s.downsample, P = s.patchSize, p = std::max(2, int(std::lround(double(P) / d)));
    const ChannelImage ex = reduced(exampleFlow, d), tg = reduced(targetFlow, d);
    if (ex.width() < p || ex.height() < p)
        throw ValueError("the video example (" + std::to_string(exampleFlow.width()) + "x" +
                         std::to_string(exampleFlow.height()) + ") is smaller than one " + std::to_string(P) +
                         " px patch");
    if (progress) progress->begin("transfer: index");
    const ExampleWindows windows = indexWindows(ex, p, s.pcaComponents);
    checkCancelled(progress);

    // Target patches touching the matte, their descriptors, candidates and the window each takes.
    if (progress) progress->begin("transfer: match");
    const int W = targetFlow.width(), H = targetFlow.height();
    std::vector<Placed> placed = patchesOnMatte(W, H, P, matte);
    const size_t dim = windows.dim;
    std::vector<float> queries(placed.size() * dim);
    parallelFor(placed.size(), 64, [&](size_t b, size_t e) {
        for (size_t k = b; k < e; ++k)
            descriptor(tg, int(std::lround(double(placed[k].tx) / d)), int(std::lround(double(placed[k].ty) / d)), p,
                &queries[k * dim]);
    });
    Candidates candidates = candidateWindows(windows, queries, placed.size(), s.variety, s.candidates);
    candidateCosts(candidates, windows, ex, queries, progress);
    pickWindows(placed, candidates, WindowGrid{windows.nx, windows.stride, d}, s.variety, P);
    checkCancelled(progress);

    if (progress) progress->begin("transfer: paste");
    return pastePatches(placed, exampleFlow, W, H, s, matte, progress);
}

} // namespace turb
