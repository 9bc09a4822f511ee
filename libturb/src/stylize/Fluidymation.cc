// Platkevič et al., "Fluidymation: Stylizing Animations Using Natural Dynamics of Artistic Media": generalized
// PatchMatch over (i, x, y, theta), the occurrence map, the rotation-aware pyramid with the previous frame's shifted
// NNF, and the per-frame measurements.
#include <turb/Fluidymation.h>

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Voting.h>

#include "FluidyLevels.h"
#include "Search.h"

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <limits>
#include <string>

namespace turb {

using namespace fluidy;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
constexpr float kInf = std::numeric_limits<float>::infinity();

double luminance(const float* rgb) { return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]; }

double pearson(double n, double sx, double sy, double sxx, double syy, double sxy)
{
    if (n < 2.0) return 0.0;
    const double cx = sxx - sx * sx / n, cy = syy - sy * sy / n, cxy = sxy - sx * sy / n;
    return cx > 0.0 && cy > 0.0 ? cxy / std::sqrt(cx * cy) : 0.0;
}

/// The 95th percentile of the exemplar's extents inside its masks (the default D^ext unit).
double percentile95(std::vector<float> v)
{
    if (v.empty()) return 1.0;
    const size_t k = std::min(v.size() - 1, size_t(0.95 * double(v.size())));
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
    return v[k] > 1e-3f ? double(v[k]) : 1.0;
}

} // namespace

void validate(const FluidySettings& s)
{
    if (s.patchSize < 3 || s.patchSize > 15 || s.patchSize % 2 == 0)
        throw ValueError("fluidymation: patch size n must be odd, 3..15");
    if (!(s.boundaryBlur > 0.0) || s.boundaryBlur > 1000.0)
        throw ValueError("fluidymation: the boundary blur b must lie in (0, 1000] pixels");
    if (s.cuboidFrames < 0 || s.cuboidFrames > 50)
        throw ValueError("fluidymation: the cuboid size r must lie in 0..50 frames");
    for (float w : {s.wBound, s.wExt, s.wDir, s.wTemp, s.wUni})
        if (!(w >= 0.0f) || !std::isfinite(w)) throw ValueError("fluidymation: term weights must be finite and >= 0");
    if (!(s.mLower >= 0.0) || !(s.mUpper > s.mLower) || s.mUpper > 10.0)
        throw ValueError("fluidymation: thresholds need 0 <= m_l < m_u <= 10 (fractions of d)");
    if (!(s.dirClamp > 0.0f) || !(s.flowEpsilon > 0.0f))
        throw ValueError("fluidymation: the direction clamp and eps must be > 0");
    if (!(s.extentScale >= 0.0) || !(s.targetExtentScale >= 0.0))
        throw ValueError("fluidymation: the extent scales must be >= 0");
    if (s.boundaryWidth < 0 || s.boundaryWidth > 1000)
        throw ValueError("fluidymation: the boundary width must lie in 0..1000 pixels");
    if (s.levels < 0 || s.levels > 8) throw ValueError("fluidymation: levels must lie in 0..8");
    if (s.iterations < 1 || s.fineIterations < 1 || s.sweeps < 1 || s.fineSweeps < 1 || s.randomCandidates < 0)
        throw ValueError("fluidymation: iterations and sweeps must be >= 1, random candidates >= 0");
}

int fluidyLevels(int sw, int sh, int tw, int th, int n)
{
    const int dmin = std::min(std::min(sw, sh), std::min(tw, th));
    if (n < 1 || dmin < 1) return 1;
    return std::max(1, int(std::floor(std::log2(double(dmin) / double(n)))));
}

float dirCost(double sourceAngle, double rotation, double targetAngle, float clamp)
{
    const double d = sourceAngle + rotation - targetAngle;
    const double sn = std::abs(std::sin(d)), cs = std::abs(std::cos(d));
    return sn >= double(clamp) * cs ? clamp : float(sn / cs);
}

double temporalModulation(double v, double lower, double upper)
{
    if (v <= lower) return 1.0;
    if (v >= upper) return 0.0;
    const double t = (v - lower) / (upper - lower);
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

int bestTimeShift(const float* plus, const float* minus, size_t stride, int frames, int i, double inc, bool opposite)
{
    if (i < 0 || i >= frames) return 0;
    const float* e = opposite ? minus : plus;
    const double base = e[size_t(i) * stride];
    int best = 0;
    double bestErr = std::abs(inc);
    const int dir = opposite ? -1 : 1;
    for (int k = i + dir; k >= 0 && k < frames; k += dir) {
        const double err = std::abs(inc - (double(e[size_t(k) * stride]) - base));
        if (err < bestErr) {
            bestErr = err;
            best = k - i;
        }
    }
    return best;
}

// ---------------------------------------------------------------------------------------------------
// The synthesiser

struct Fluidymator::Impl
{
    FluidySettings s;
    int r = 2, n = 5, L = 1, F = 0, bw = 5;
    RotationTable table{2};
    double extScale = 1.0, targetExtScale = 1.0, mLower = 0.0, mUpper = 1.0;
    LevelRules rules;
    std::vector<ExemplarLevel> ex;
    std::vector<float> sExt, sPhi, sFlow; // level 0, per voxel: raw extents (2), signed distance, flow (2)
    double exLumStd = 0.0;
    const MotionSequence* target = nullptr;
    int j = 0;
    // The previous frame: finest NNF, output colour, mask, flow, extents (for the shift and the stats).
    bool havePrev = false;
    RotatedNnf prevNnf;
    ChannelImage prevRgb, prevMask, prevFlow, prevExt;
    // The finest level of the last frame, for terms().
    TargetLevel last;
    bool haveLast = false;

    Weights weights() const { return Weights{s.wBound, s.wExt, s.wDir, s.wUni, s.dirClamp}; }
    PatchRef randomRef(const ExemplarLevel& E, const TargetLevel& T, size_t q, std::uint64_t key) const;
    void repair(const ExemplarLevel& E, const TargetLevel& T, RotatedNnf& nnf, std::uint64_t key) const;
    void rebuildOmega(ExemplarLevel& E, const TargetLevel& T, const RotatedNnf& nnf) const;
    void distances(const Evaluator& ev, RotatedNnf& nnf) const;
    void findNnf(ExemplarLevel& E, const TargetLevel& T, RotatedNnf& nnf, std::uint64_t key, bool finest,
        Progress* progress) const;
    void voteInto(const ExemplarLevel& E, const RotatedNnf& nnf, TargetLevel& T, ChannelImage* rgba) const;
    RotatedNnf shiftPrevious(const ChannelImage& ext, const std::vector<std::uint8_t>& tSteps, const ChannelImage& phiT,
        ChannelImage& m, FluidyStats& st) const;
    void measure(const ExemplarLevel& E0, const TargetLevel& T0, RotatedNnf& nnf, const ChannelImage& rgba,
        const ChannelImage& mask, const ChannelImage& flow, const ChannelImage& ext, FluidyStats& st);
    /// Level 0's per-voxel extents, signed distance and flow, the exemplar's D^ext unit and interior luminance std.
    void levelZeroExtras(const std::vector<ChannelImage>& rgb, const MotionSequence& exMotion);
    /// The exemplar's pyramid and every level's patch centres; throws ValueError for a level without centres.
    void buildExemplarPyramid(const std::vector<ChannelImage>& rgb, const MotionSequence& exMotion, Progress* progress);

    /// One target frame's guides: its full-resolution images (with T^temp from the previous frame's shifted NNF),
    /// the raw extents, that shifted NNF and the target pyramid.
    struct FrameGuides
    {
        FrameImages images;
        ChannelImage extRaw;
        RotatedNnf shifted; ///< empty on the first frame of a shot
        std::vector<TargetLevel> levels;
    };
    FrameGuides frameGuides(int frame, FluidyStats& st) const;
    /// MERGENNF: takes the shifted previous NNF into `up` where it has the smaller D; returns how many pixels took it.
    double mergeShifted(ExemplarLevel& E, TargetLevel& TL, int l, const RotatedNnf& shifted,
        const ChannelImage& coarser, RotatedNnf& up) const;
    /// Level l of Algorithm 1: the start NNF (random, shifted, or the coarser one upscaled and merged), then
    /// Algorithm 2's FINDNNF + VOTE iterations. `result` holds the last vote.
    void synthesizeLevel(
        int l, int frame, FrameGuides& g, RotatedNnf& nnf, ChannelImage& result, FluidyStats& st, Progress* progress);
};

PatchRef Fluidymator::Impl::randomRef(const ExemplarLevel& E, const TargetLevel& T, size_t q, std::uint64_t key) const
{
    detail::Rng rng(detail::key(key, q, 0x5eed, 0));
    const size_t v = size_t(E.centres[rng.below(std::uint32_t(E.centres.size()))]);
    const std::uint8_t aS = E.dirStep[v], aT = T.dirStep[q];
    const bool free = aS == kNoDirection || aT == kNoDirection || s.wDir <= 0.0f;
    const int k = free ? int(rng.below(kRotations)) : (int(aT) - int(aS) + kRotations) % kRotations;
    return E.refOf(v, std::uint8_t(k));
}

void Fluidymator::Impl::repair(const ExemplarLevel& E, const TargetLevel& T, RotatedNnf& nnf, std::uint64_t key) const
{
    parallelFor(nnf.match.size(), 4096, [&](size_t b, size_t e) {
        for (size_t q = b; q < e; ++q) {
            if (T.label[q] < 0) {
                nnf.match[q] = PatchRef{};
                continue;
            }
            if (!E.isCentre(nnf.match[q])) nnf.match[q] = randomRef(E, T, q, key);
        }
    });
}

void Fluidymator::Impl::rebuildOmega(ExemplarLevel& E, const TargetLevel& T, const RotatedNnf& nnf) const
{
    std::fill(E.counts.begin(), E.counts.end(), 0);
    const int count = table.count();
    // Integer counts: the atomic adds give the same totals in any order, so the map is deterministic.
    parallelFor(nnf.match.size(), 4096, [&](size_t b, size_t e) {
        for (size_t q = b; q < e; ++q) {
            const PatchRef& m = nnf.match[q];
            if (T.label[q] < 0 || !m.valid()) continue;
            const int* off = table.offsets(m.rotation);
            for (int t = 0; t < count; ++t)
                __atomic_fetch_add(
                    &E.counts[E.voxel(m.frame, m.x + off[2 * t], m.y + off[2 * t + 1])], 1, __ATOMIC_RELAXED);
        }
    });
    // Omega*(i) sums the 2D footprints of frames i - r .. i + r (the cuboids' time extent); Omega = Omega* /
    // (n^2 omega*), omega* = n^2 (2r + 1) |T_seg| / |S_seg|.
    const int R = s.cuboidFrames;
    double factor[2];
    const long long sTot = E.segCount[0] + E.segCount[1], tTot = T.segCount[0] + T.segCount[1];
    for (int g = 0; g < 2; ++g) {
        const double sg = double(E.segCount[g] > 0 ? E.segCount[g] : sTot),
                     tg = double(T.segCount[g] > 0 ? T.segCount[g] : std::max(1LL, tTot));
        factor[g] = sg / (double(n) * n * double(n) * n * double(2 * R + 1) * tg);
    }
    const size_t plane = size_t(E.W) * size_t(E.H);
    parallelFor(plane, 1024, [&](size_t b, size_t e) {
        for (size_t p = b; p < e; ++p) {
            long long sum = 0;
            for (int i = 0; i <= std::min(R - 1, E.F - 1); ++i) sum += E.counts[size_t(i) * plane + p];
            for (int i = 0; i < E.F; ++i) {
                if (i + R < E.F) sum += E.counts[size_t(i + R) * plane + p];
                if (i - R - 1 >= 0) sum -= E.counts[size_t(i - R - 1) * plane + p];
                const size_t v = size_t(i) * plane + p;
                E.omega[v] = float(double(sum) * factor[E.segment[v]]);
            }
        }
    });
    // The n x n window sums of Omega per frame (separable box), read once per patch by D.
    std::vector<float>& rows = E.scratch;
    parallelFor(size_t(E.F) * size_t(E.H), 64, [&](size_t b, size_t e) {
        for (size_t fy = b; fy < e; ++fy) {
            const float* in = E.omega.data() + fy * size_t(E.W);
            float* out = rows.data() + fy * size_t(E.W);
            for (int x = 0; x < E.W; ++x) {
                float s = 0.0f;
                for (int d = std::max(0, x - r); d <= std::min(E.W - 1, x + r); ++d) s += in[d];
                out[x] = s;
            }
        }
    });
    parallelFor(size_t(E.F) * size_t(E.H), 64, [&](size_t b, size_t e) {
        for (size_t fy = b; fy < e; ++fy) {
            const int y = int(fy % size_t(E.H));
            const size_t base = fy - size_t(y);
            float* out = E.omegaPatch.data() + fy * size_t(E.W);
            for (int x = 0; x < E.W; ++x) {
                float s = 0.0f;
                for (int d = std::max(0, y - r); d <= std::min(E.H - 1, y + r); ++d)
                    s += rows[(base + size_t(d)) * size_t(E.W) + size_t(x)];
                out[x] = s;
            }
        }
    });
}

void Fluidymator::Impl::distances(const Evaluator& ev, RotatedNnf& nnf) const
{
    const TargetLevel& T = *ev.T;
    parallelFor(size_t(T.H), 4, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y)
            for (int x = 0; x < T.W; ++x) {
                const size_t q = y * size_t(T.W) + size_t(x);
                nnf.distance[q] = T.label[q] >= 0 && nnf.match[q].valid() ? ev(x, int(y), nnf.match[q], kInf) : kInf;
            }
    });
}

namespace {

/// FINDNNF's search for one target patch q at (x, y) in one sweep: the best candidate so far (m, with D = b) and the
/// random stream of this patch and sweep. Candidates are tried in a fixed order, so the result does not depend on
/// threads.
struct PatchSearch
{
    const ExemplarLevel& E;
    const TargetLevel& T;
    const Evaluator& ev;
    const FluidySettings& s;
    size_t q;
    int x, y;
    detail::Rng rng;
    PatchRef m;
    float b;

    void tryCandidate(const PatchRef& c)
    {
        if (c == m || !E.isCentre(c)) return;
        const float d = ev(x, y, c, b);
        if (d < b) {
            b = d;
            m = c;
        }
    }

    // A sampled (i, x, y) is tried with the rotations that minimise D^dir: the patch-mean flows aligned, or
    // opposite; where a flow has no direction, with the current rotation.
    void tryAligned(int fi, int cx, int cy)
    {
        if (!E.isCentre(fi, cx, cy)) return;
        const size_t v = E.voxel(fi, cx, cy);
        const std::uint8_t aS = E.dirStep[v], aT = T.dirStep[q];
        PatchRef c{std::int16_t(fi), std::int16_t(cx), std::int16_t(cy), m.rotation};
        if (s.wDir <= 0.0f) { // without D^dir every rotation minimises it: draw one
            c.rotation = std::uint8_t(rng.below(kRotations));
            tryCandidate(c);
            return;
        }
        if (aS == kNoDirection || aT == kNoDirection) {
            tryCandidate(c);
            return;
        }
        // Of the aligned and the opposite rotation, the one whose (swapped) extents fit better at the centres; both
        // when the extent term is off.
        const int k = (int(aT) - int(aS) + kRotations) % kRotations;
        const std::uint8_t aligned = std::uint8_t(k), flipped = std::uint8_t((k + kRotations / 2) % kRotations);
        if (s.wExt > 0.0f) {
            const float ea = ev.centreExtent(q, x, y, v, ev.opposite(q, v, aligned));
            const float ef = ev.centreExtent(q, x, y, v, ev.opposite(q, v, flipped));
            c.rotation = ea <= ef ? aligned : flipped;
            tryCandidate(c);
            return;
        }
        c.rotation = aligned;
        tryCandidate(c);
        c.rotation = flipped;
        tryCandidate(c);
    }

    // Propagation (generalized PatchMatch): the neighbour's patch moved back by the rotated offset.
    template<typename Neighbour>
    void propagate(int step, const Neighbour& neighbour)
    {
        for (int axis = 0; axis < 2; ++axis) {
            const int nx = x + (axis == 0 ? step : 0), ny = y + (axis == 1 ? step : 0);
            if (nx < 0 || ny < 0 || nx >= T.W || ny >= T.H) continue;
            const PatchRef& nm = neighbour(nx, ny);
            if (!nm.valid()) continue;
            double ox = 0.0, oy = 0.0;
            sourceOffset(nm.rotation, nx - x, ny - y, ox, oy);
            PatchRef c = nm;
            c.x = std::int16_t(std::lround(nm.x - ox));
            c.y = std::int16_t(std::lround(nm.y - oy));
            tryCandidate(c);
        }
    }

    // The same place one source frame earlier and later: the medium's own motion.
    void adjacentFrames()
    {
        for (int di : {-1, 1}) {
            PatchRef c = m;
            c.frame = std::int16_t(m.frame + di);
            tryCandidate(c);
        }
    }

    // Random search in windows halving around the best so far, in x, y and i; then `uniform` draws among all
    // centres.
    void randomSearch(int maxDim, int maxFrames, int uniform)
    {
        for (int w = maxDim, wf = maxFrames; w >= 1; w /= 2, wf /= 2) {
            const int fi = std::clamp(m.frame - wf + int(rng.below(std::uint32_t(2 * wf + 1))), 0, E.F - 1);
            const int cx = std::clamp(m.x - w + int(rng.below(std::uint32_t(2 * w + 1))), 0, E.W - 1);
            const int cy = std::clamp(m.y - w + int(rng.below(std::uint32_t(2 * w + 1))), 0, E.H - 1);
            tryAligned(fi, cx, cy);
        }
        for (int k = 0; k < uniform; ++k) {
            const PatchRef c = E.refOf(size_t(E.centres[rng.below(std::uint32_t(E.centres.size()))]), m.rotation);
            tryAligned(c.frame, c.x, c.y);
        }
    }
};

} // namespace

void Fluidymator::Impl::findNnf(
    ExemplarLevel& E, const TargetLevel& T, RotatedNnf& nnf, std::uint64_t key, bool finest, Progress* progress) const
{
    const Evaluator ev(E, T, table, weights());
    // The random search spans the whole exemplar on coarser levels; on the finest one, where the coarser
    // levels and the previous frame have placed every patch, an eighth of it (and of its frames): far
    // candidates there cost cache misses and are hardly ever taken. Uniform draws still reach everywhere.
    const int maxDim = finest ? std::max(4, std::max(E.W, E.H) / 8) : std::max(E.W, E.H);
    const int maxFrames = finest ? std::max(1, E.F / 8) : E.F;
    for (int sweep = 0, sweeps = finest ? s.fineSweeps : s.sweeps; sweep < sweeps; ++sweep) {
        if (s.wUni > 0.0f) rebuildOmega(E, T, nnf);
        distances(ev, nnf);
        detail::tiledSweeps(T.W, T.H, 64, sweep, 1, nnf.match, progress,
            [&](size_t q, int x, int y, int it, int step, const auto& neighbour) {
                if (T.label[q] < 0) return;
                PatchSearch p{E, T, ev, s, q, x, y, detail::Rng(detail::key(key, std::uint64_t(it), q, 0xf1d)),
                    nnf.match[q], nnf.distance[q]};
                p.propagate(step, neighbour);
                p.adjacentFrames();
                p.randomSearch(maxDim, maxFrames, s.randomCandidates);
                nnf.match[q] = p.m;
                nnf.distance[q] = p.b;
            });
    }
}

void Fluidymator::Impl::voteInto(
    const ExemplarLevel& E, const RotatedNnf& nnf, TargetLevel& T, ChannelImage* rgba) const
{
    std::vector<const ChannelImage*> frames;
    for (const ChannelImage& f : E.vote) frames.push_back(&f);
    ChannelImage out(T.W, T.H, 4);
    voteRotated(frames, nnf, r, 0, 0, rgba ? 4 : 3, out);
    for (int y = -T.pad; y < T.H + T.pad; ++y)
        for (int x = -T.pad; x < T.W + T.pad; ++x) {
            const float* v = out.pixel(std::clamp(x, 0, T.W - 1), std::clamp(y, 0, T.H - 1));
            std::copy(v, v + 3, T.at(x, y));
        }
    if (rgba) *rgba = std::move(out);
}

RotatedNnf Fluidymator::Impl::shiftPrevious(const ChannelImage& ext, const std::vector<std::uint8_t>& tSteps,
    const ChannelImage& phiT, ChannelImage& m, FluidyStats& st) const
{
    const ExemplarLevel& E = ex[0];
    const int W = ext.width(), H = ext.height();
    RotatedNnf out = emptyRotatedNnf(W, H);
    m = ChannelImage(W, H, 1);
    const size_t plane = size_t(E.W) * size_t(E.H);
    std::vector<double> shiftSum(size_t(H), 0.0);
    std::vector<long long> shiftCount(size_t(H), 0);
    parallelFor(size_t(H), 8, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy)
            for (int x = 0; x < W; ++x) {
                const size_t q = yy * size_t(W) + size_t(x);
                const PatchRef& p = prevNnf.match[q];
                if (!p.valid()) continue;
                // Delta i*: the source frame whose motion since p.frame matches the target's since j - 1.
                const double inc = double(ext.pixel(q)[0]) - double(prevExt.pixel(q)[0]);
                const size_t v = E.voxel(p.frame, p.x, p.y);
                const bool opposite = oppositeSteps(E.dirStep[v], p.rotation, tSteps[q]);
                const size_t col = size_t(p.y) * size_t(E.W) + size_t(p.x);
                const int di = bestTimeShift(
                    sExt.data() + 2 * col, sExt.data() + 2 * col + 1, 2 * plane, E.F, p.frame, inc, opposite);
                PatchRef c = p;
                c.frame = std::int16_t(p.frame + di);
                if (!E.isCentre(c)) c.frame = p.frame;
                if (!E.isCentre(c)) continue;
                out.match[q] = c;
                shiftSum[yy] += c.frame - p.frame;
                ++shiftCount[yy];
                if (prevMask.pixel(q)[0] >= 0.5f) {
                    const double dv = std::abs(double(phiT.pixel(q)[0]) - double(sPhi[E.voxel(c.frame, c.x, c.y)]));
                    m.pixel(q)[0] = float(temporalModulation(dv, mLower, mUpper));
                }
            }
    });
    double ss = 0.0;
    long long sc = 0;
    for (int y = 0; y < H; ++y) {
        ss += shiftSum[size_t(y)];
        sc += shiftCount[size_t(y)];
    }
    st.meanShift = sc ? ss / double(sc) : 0.0;
    return out;
}

namespace {

/// Throws ValueError when the exemplar and the target cannot be synthesised from (see the constructor's doc).
void checkFluidyInputs(const FluidySettings& settings, const std::vector<ChannelImage>& rgb,
    const MotionSequence& exMotion, const MotionSequence& target, const RotationTable& table)
{
    const int F = exMotion.frames(), n = settings.patchSize;
    if (!exMotion.finished() || !target.finished())
        throw ValueError("fluidymation: the motion sequences must be finished");
    if (int(rgb.size()) != F)
        throw ValueError("fluidymation: " + std::to_string(rgb.size()) + " exemplar frames but " + std::to_string(F) +
                         " exemplar masks");
    if (F < 2 * settings.cuboidFrames + 1)
        throw ValueError("fluidymation: the exemplar has " + std::to_string(F) +
                         " frames, fewer than 2r + 1 = " + std::to_string(2 * settings.cuboidFrames + 1) +
                         " (r = " + std::to_string(settings.cuboidFrames) + ")");
    const int sw = exMotion.width(), sh = exMotion.height(), tw = target.width(), th = target.height();
    for (const ChannelImage& c : rgb)
        if (c.width() != sw || c.height() != sh || c.channels() < 3)
            throw ValueError("fluidymation: every exemplar frame must be RGB of the masks' size (" +
                             std::to_string(sw) + "x" + std::to_string(sh) + ")");
    if (sw > 32767 || sh > 32767 || F > 32767)
        throw ValueError("fluidymation: the exemplar must be at most 32767 pixels and frames along each axis");
    const int minSide = 2 * (table.reach() + 1) + 1;
    if (std::min(sw, sh) < minSide || std::min(tw, th) < n)
        throw ValueError("fluidymation: the exemplar (" + std::to_string(sw) + "x" + std::to_string(sh) +
                         ") or the target (" + std::to_string(tw) + "x" + std::to_string(th) + ") is too small for " +
                         std::to_string(n) + "x" + std::to_string(n) + " rotated patches");
    long long exMasked = 0, tMasked = 0;
    for (int i = 0; i < F; ++i) exMasked += exMotion.maskedPixels(i);
    for (int k = 0; k < target.frames(); ++k) tMasked += target.maskedPixels(k);
    if (exMasked == 0) throw ValueError("fluidymation: the exemplar's masks are empty in every frame");
    if (tMasked == 0) throw ValueError("fluidymation: the target's masks are empty in every frame");
}

/// The target's own D^ext unit: the 95th percentile of its extents inside its masks, from at most ~1M samples
/// (every k-th frame and pixel).
double targetExtentUnit(const MotionSequence& target)
{
    std::vector<float> t;
    long long total = 0;
    for (int k = 0; k < target.frames(); ++k) total += target.maskedPixels(k);
    const long long step = std::max(1LL, total / 1000000);
    long long seen = 0;
    for (int k = 0; k < target.frames(); ++k) {
        if (target.maskedPixels(k) == 0) continue;
        const ChannelImage e = target.extents(k), m = target.mask(k);
        for (size_t p = 0; p < e.pixelCount(); ++p)
            if (m.pixel(p)[0] >= 0.5f && seen++ % step == 0) {
                t.push_back(e.pixel(p)[0]);
                t.push_back(e.pixel(p)[1]);
            }
    }
    return percentile95(std::move(t));
}

} // namespace

void Fluidymator::Impl::levelZeroExtras(const std::vector<ChannelImage>& rgb, const MotionSequence& exMotion)
{
    const size_t plane = size_t(exMotion.width()) * size_t(exMotion.height()), voxels = plane * size_t(F);
    sExt.assign(2 * voxels, 0.0f);
    sPhi.assign(voxels, 0.0f);
    sFlow.assign(2 * voxels, 0.0f);
    std::vector<float> extValues;
    double l1 = 0.0, l2 = 0.0, ln = 0.0;
    for (int i = 0; i < F; ++i) {
        const ChannelImage e = exMotion.extents(i), fl = exMotion.flow(i), ph = exMotion.distance(i),
                           mk = exMotion.mask(i);
        for (size_t p = 0; p < plane; ++p) {
            const size_t v = size_t(i) * plane + p;
            std::copy(e.pixel(p), e.pixel(p) + 2, sExt.data() + 2 * v);
            std::copy(fl.pixel(p), fl.pixel(p) + 2, sFlow.data() + 2 * v);
            sPhi[v] = ph.pixel(p)[0];
            if (mk.pixel(p)[0] >= 0.5f) {
                extValues.push_back(e.pixel(p)[0]);
                extValues.push_back(e.pixel(p)[1]);
                const double Y = luminance(rgb[size_t(i)].pixel(p));
                l1 += Y;
                l2 += Y * Y;
                ln += 1.0;
            }
        }
    }
    extScale = s.extentScale > 0.0 ? s.extentScale : percentile95(std::move(extValues));
    exLumStd = ln > 1.0 ? std::sqrt(std::max(0.0, l2 / ln - (l1 / ln) * (l1 / ln))) : 0.0;
}

void Fluidymator::Impl::buildExemplarPyramid(
    const std::vector<ChannelImage>& rgb, const MotionSequence& exMotion, Progress* progress)
{
    ex.resize(size_t(L));
    for (int l = 0; l < L; ++l) {
        ExemplarLevel& E = ex[size_t(l)];
        E.W = exMotion.width();
        E.H = exMotion.height();
        for (int k = 0; k < l; ++k) {
            E.W = (E.W + 1) / 2;
            E.H = (E.H + 1) / 2;
        }
        E.F = F;
        const size_t v = size_t(E.W) * size_t(E.H) * size_t(E.F);
        E.feat.assign(v * kS, 0.0f);
        E.dirStep.assign(v, kNoDirection);
        E.label.assign(v, -1);
        E.segment.assign(v, kBoundary);
        E.vote.resize(size_t(E.F));
        E.counts.assign(v, 0);
        E.omega.assign(v, 0.0f);
        E.omegaPatch.assign(v, 0.0f);
        E.scratch.assign(v, 0.0f);
    }
    for (int i = 0; i < F; ++i) {
        checkCancelled(progress);
        FrameImages f;
        f.rgb = channelRange(rgb[size_t(i)], 0, 3);
        f.mask = exMotion.mask(i);
        f.shape = gaussianBlur(f.mask, s.boundaryBlur / 3.0);
        f.ext = exMotion.extents(i);
        for (float& x : f.ext.data()) x = float(x / extScale);
        f.flow = exMotion.flow(i);
        for (int l = 0; l < L; ++l) {
            if (l > 0) f = reduced(f);
            fillExemplarFrame(ex[size_t(l)], i, f, rules);
        }
        if (progress) progress->update(double(i + 1) / F);
    }
    for (int l = 0; l < L; ++l) {
        ExemplarLevel& E = ex[size_t(l)];
        for (size_t v = 0; v < E.label.size(); ++v)
            if (E.label[v] >= 0) {
                E.centres.push_back(std::int32_t(v));
                ++E.segCount[E.label[v]];
            }
        if (E.centres.empty())
            throw ValueError("fluidymation: the exemplar has no patch centre at pyramid level " + std::to_string(l) +
                             " (its masks are too small or too close to the border); use fewer pyramid levels");
    }
}

Fluidymator::Fluidymator(const FluidySettings& settings, const std::vector<ChannelImage>& rgb,
    const MotionSequence& exMotion, const MotionSequence& target, Progress* progress)
    : mImpl(std::make_unique<Impl>())
{
    validate(settings);
    Impl& I = *mImpl;
    I.s = settings;
    I.n = settings.patchSize;
    I.r = settings.patchSize / 2;
    I.table = RotationTable(I.r);
    I.target = &target;
    I.F = exMotion.frames();
    checkFluidyInputs(settings, rgb, exMotion, target, I.table);
    const int sw = exMotion.width(), sh = exMotion.height(), tw = target.width(), th = target.height();
    I.L = settings.levels > 0 ? settings.levels : fluidyLevels(sw, sh, tw, th, I.n);
    I.bw = settings.boundaryWidth > 0 ? settings.boundaryWidth : I.n;
    I.rules = LevelRules{I.r, I.bw, settings.flowEpsilon, I.table.reach()};
    const double d = std::max(tw, th);
    I.mLower = settings.mLower * d;
    I.mUpper = settings.mUpper * d;

    // Level 0 extras and the extent units, then the exemplar's pyramid: every frame reduced level by level.
    I.levelZeroExtras(rgb, exMotion);
    I.targetExtScale = settings.targetExtentScale > 0.0 ? settings.targetExtentScale : targetExtentUnit(target);
    I.buildExemplarPyramid(rgb, exMotion, progress);
}

Fluidymator::~Fluidymator() = default;

int Fluidymator::levels() const { return mImpl->L; }
int Fluidymator::frame() const { return mImpl->j; }
double Fluidymator::extentScale() const { return mImpl->extScale; }
double Fluidymator::targetExtentScale() const { return mImpl->targetExtScale; }
const FluidySettings& Fluidymator::settings() const { return mImpl->s; }

FluidyTerms Fluidymator::terms(const PatchRef& p, int x, int y) const
{
    const Impl& I = *mImpl;
    if (!I.haveLast) throw ValueError("fluidymation: terms() needs a synthesised frame");
    const ExemplarLevel& E = I.ex[0];
    if (!E.isCentre(p)) throw ValueError("fluidymation: terms(): the source patch is not an exemplar patch centre");
    if (x < 0 || y < 0 || x >= I.last.W || y >= I.last.H)
        throw ValueError("fluidymation: terms(): the target pixel is outside the frame");
    const Evaluator ev(E, I.last, I.table, I.weights());
    FluidyTerms t;
    ev(x, y, p, kInf, &t);
    return t;
}

namespace {

/// Deterministic parallel sums of `count` values accumulated per row, added in row order.
std::vector<double> rowSums(int H, int count, const std::function<void(int, double*)>& row)
{
    std::vector<double> part(size_t(H) * size_t(count), 0.0);
    parallelFor(size_t(H), 4, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y) row(int(y), part.data() + y * size_t(count));
    });
    std::vector<double> sum(size_t(count), 0.0);
    for (int y = 0; y < H; ++y)
        for (int c = 0; c < count; ++c) sum[size_t(c)] += part[size_t(y) * size_t(count) + size_t(c)];
    return sum;
}

} // namespace

void Fluidymator::Impl::measure(const ExemplarLevel& E0c, const TargetLevel& T0, RotatedNnf& nnf,
    const ChannelImage& rgba, const ChannelImage& mask, const ChannelImage& flow, const ChannelImage& ext,
    FluidyStats& st)
{
    ExemplarLevel& E0 = const_cast<ExemplarLevel&>(E0c);
    rebuildOmega(E0, T0, nnf); // also without w^uni: the coverage below reads it
    const Evaluator ev(E0, T0, table, weights());
    const int W = T0.W, H = T0.H;
    const size_t plane = size_t(E0.W) * size_t(E0.H);
    // Energy terms per centre.
    const std::vector<double> e = rowSums(H, 7, [&](int y, double* a) {
        for (int x = 0; x < W; ++x) {
            const size_t q = size_t(y) * size_t(W) + size_t(x);
            if (T0.label[q] < 0 || !nnf.match[q].valid()) continue;
            FluidyTerms t;
            nnf.distance[q] = ev(x, y, nnf.match[q], kInf, &t);
            a[0] += t.tex, a[1] += t.bound, a[2] += t.dir, a[3] += t.ext, a[4] += t.temp, a[5] += t.uni, a[6] += 1.0;
        }
    });
    if (e[6] > 0.0)
        st.energy = FluidyTerms{e[0] / e[6], e[1] / e[6], e[2] / e[6], e[3] / e[6], e[4] / e[6], e[5] / e[6], false};
    // Direction, extent and contrast over the mask's pixels; flicker where both masks hold and nothing moves.
    const std::vector<double> m = rowSums(H, 20, [&](int y, double* a) {
        for (int x = 0; x < W; ++x) {
            const size_t q = size_t(y) * size_t(W) + size_t(x);
            if (mask.pixel(q)[0] < 0.5f) continue;
            const float* out = rgba.pixel(q);
            const double Y = luminance(out);
            a[0] += Y, a[1] += Y * Y, a[2] += 1.0;
            const PatchRef& p = nnf.match[q];
            if (p.valid()) {
                const size_t v = E0.voxel(p.frame, p.x, p.y);
                const float* sf = sFlow.data() + 2 * v;
                const float* tf = flow.pixel(q);
                const double sm = std::hypot(sf[0], sf[1]), tm = std::hypot(tf[0], tf[1]);
                if (sm >= kMovingSpeed && tm >= kMovingSpeed) {
                    const double d = std::atan2(sf[1], sf[0]) + rotationAngle(p.rotation) - std::atan2(tf[1], tf[0]);
                    a[3] += std::abs(std::sin(d)), a[4] += 1.0;
                }
                a[5] += 1.0, a[6] += tm, a[7] += sm, a[8] += tm * tm, a[9] += sm * sm, a[10] += tm * sm;
                const double te = ext.pixel(q)[0], se = sExt[2 * v];
                a[11] += te, a[12] += se, a[13] += te * te, a[14] += se * se, a[15] += te * se;
            }
            if (!prevRgb.empty() && prevMask.pixel(q)[0] >= 0.5f) {
                const float* pf = prevFlow.pixel(q);
                if (std::hypot(flow.pixel(q)[0], flow.pixel(q)[1]) < kStillSpeed &&
                    std::hypot(pf[0], pf[1]) < kStillSpeed) {
                    const float* pr = prevRgb.pixel(q);
                    a[16] += (std::abs(out[0] - pr[0]) + std::abs(out[1] - pr[1]) + std::abs(out[2] - pr[2])) / 3.0;
                    a[17] += 1.0;
                }
            }
        }
    });
    if (m[2] > 1.0 && exLumStd > 0.0)
        st.contrastRatio = std::sqrt(std::max(0.0, m[1] / m[2] - (m[0] / m[2]) * (m[0] / m[2]))) / exLumStd;
    st.movingPixels = (long long)m[4];
    if (m[4] > 0.0) st.meanAbsSin = m[3] / m[4];
    st.speedCorrelation = pearson(m[5], m[6], m[7], m[8], m[9], m[10]);
    st.extentCorrelation = pearson(m[5], m[11], m[12], m[13], m[14], m[15]);
    if (!prevRgb.empty()) {
        st.stationaryPixels = (long long)m[17];
        st.stationaryChange = m[17] > 0.0 ? m[16] / m[17] : 0.0;
    }
    // Wash-out: how much of the exemplar the cuboids cover, and how many distinct patches are used.
    long long covered = 0;
    for (std::int32_t v : E0.centres) covered += E0.omega[size_t(v)] > 0.0f;
    st.coverage = E0.centres.empty() ? 0.0 : double(covered) / double(E0.centres.size());
    std::vector<std::int64_t> keys;
    for (size_t q = 0; q < nnf.match.size(); ++q)
        if (T0.label[q] >= 0 && nnf.match[q].valid()) {
            const PatchRef& p = nnf.match[q];
            keys.push_back(std::int64_t(p.frame) * std::int64_t(plane) + std::int64_t(p.y) * E0.W + p.x);
        }
    std::sort(keys.begin(), keys.end());
    const size_t distinct = size_t(std::unique(keys.begin(), keys.end()) - keys.begin());
    st.distinctPatches = keys.empty() ? 0.0 : double(distinct) / double(keys.size());
}

Fluidymator::Impl::FrameGuides Fluidymator::Impl::frameGuides(int frame, FluidyStats& st) const
{
    const MotionSequence& tg = *target;
    FrameGuides g;
    FrameImages& f = g.images;
    f.mask = tg.mask(frame);
    f.flow = tg.flow(frame);
    g.extRaw = tg.extents(frame);
    f.ext = g.extRaw;
    for (float& x : f.ext.data()) x = float(x / targetExtScale);
    f.shape = gaussianBlur(f.mask, s.boundaryBlur / 3.0);
    f.temp = ChannelImage(tg.width(), tg.height(), 4);
    if (havePrev) {
        // Section 3.4: the previous NNF shifted by Delta i*, voted into T^temp, weighted by w^temp m.
        ChannelImage m;
        g.shifted = shiftPrevious(g.extRaw, patchMeanSteps(f.flow, r, s.flowEpsilon), signedDistance(f.mask), m, st);
        std::vector<const ChannelImage*> frames;
        for (const ChannelImage& v : ex[0].vote) frames.push_back(&v);
        voteRotated(frames, g.shifted, r, 0, 0, 3, f.temp);
        for (size_t p = 0; p < f.temp.pixelCount(); ++p) f.temp.pixel(p)[3] = s.wTemp * m.pixel(p)[0];
    }
    FrameImages reducedImages = f;
    g.levels.resize(size_t(L));
    for (int l = 0; l < L; ++l) {
        if (l > 0) reducedImages = reduced(reducedImages);
        g.levels[size_t(l)] = makeTargetLevel(reducedImages, rules);
    }
    return g;
}

double Fluidymator::Impl::mergeShifted(ExemplarLevel& E, TargetLevel& TL, int l, const RotatedNnf& shifted,
    const ChannelImage& coarser, RotatedNnf& up) const
{
    // MERGENNF: per pixel the start with the smaller D, compared on the coarser result enlarged.
    const ChannelImage big = enlarge(coarser, TL.W, TL.H);
    for (int y = -TL.pad; y < TL.H + TL.pad; ++y)
        for (int x = -TL.pad; x < TL.W + TL.pad; ++x)
            std::copy(big.pixel(std::clamp(x, 0, TL.W - 1), std::clamp(y, 0, TL.H - 1)),
                big.pixel(std::clamp(x, 0, TL.W - 1), std::clamp(y, 0, TL.H - 1)) + 3, TL.at(x, y));
    const RotatedNnf pd = l == 0 ? shifted : downscaleNnf(shifted, l, TL.W, TL.H);
    if (s.wUni > 0.0f) rebuildOmega(E, TL, up);
    const Evaluator ev(E, TL, table, weights());
    const std::vector<double> taken = rowSums(TL.H, 1, [&](int y, double* a) {
        for (int x = 0; x < TL.W; ++x) {
            const size_t q = size_t(y) * size_t(TL.W) + size_t(x);
            if (TL.label[q] < 0 || !E.isCentre(pd.match[q])) continue;
            const float du = ev(x, y, up.match[q], kInf);
            if (ev(x, y, pd.match[q], du) < du) {
                up.match[q] = pd.match[q];
                a[0] += 1.0;
            }
        }
    });
    return taken[0];
}

void Fluidymator::Impl::synthesizeLevel(
    int l, int frame, FrameGuides& g, RotatedNnf& nnf, ChannelImage& result, FluidyStats& st, Progress* progress)
{
    ExemplarLevel& E = ex[size_t(l)];
    TargetLevel& TL = g.levels[size_t(l)];
    const bool reuse = havePrev && s.reusePrevious;
    const std::uint64_t key = detail::key(s.seed, std::uint64_t(frame), std::uint64_t(l), 0x1e7e1);
    auto ts = Clock::now();
    if (l == L - 1) {
        // Algorithm 1: random only at the coarsest level of the first frame (and where the previous
        // frame had no patch); else the previous frame's shifted field, downscaled by mode.
        nnf = reuse ? downscaleNnf(g.shifted, l, TL.W, TL.H) : emptyRotatedNnf(TL.W, TL.H);
        repair(E, TL, nnf, key);
    } else {
        RotatedNnf up = upscaleNnf(nnf, TL.W, TL.H);
        repair(E, TL, up, key);
        if (reuse) {
            const double taken = mergeShifted(E, TL, l, g.shifted, result, up);
            if (l == 0) st.reusedFraction = st.centres ? taken / double(st.centres) : 0.0;
        }
        nnf = std::move(up);
    }
    st.secondsSearch += since(ts);
    // Algorithm 2: vote the start, then FINDNNF + VOTE.
    auto tv = Clock::now();
    voteInto(E, nnf, TL, &result);
    st.secondsVote += since(tv);
    const int iterations = l == 0 ? s.fineIterations : s.iterations;
    for (int it = 0; it < iterations; ++it) {
        if (progress) progress->begin("level " + std::to_string(l) + " iteration " + std::to_string(it + 1));
        ts = Clock::now();
        findNnf(E, TL, nnf, detail::key(key, std::uint64_t(it), 0x5ea, 0), l == 0, progress);
        st.secondsSearch += since(ts);
        tv = Clock::now();
        voteInto(E, nnf, TL, &result);
        st.secondsVote += since(tv);
    }
}

FluidyFrame Fluidymator::next(Progress* progress)
{
    Impl& I = *mImpl;
    const MotionSequence& tg = *I.target;
    if (I.j >= tg.frames())
        throw ValueError("fluidymation: no target frame left (" + std::to_string(tg.frames()) + " frames)");
    const int j = I.j, W = tg.width(), H = tg.height();
    FluidyFrame out;
    FluidyStats& st = out.stats;
    st.frame = j;
    st.levels = I.L;
    st.width = W;
    st.height = H;
    out.rotation = ChannelImage(W, H, 2);
    out.nnf = emptyRotatedNnf(W, H);
    st.maskedPixels = tg.maskedPixels(j);
    if (st.maskedPixels == 0) { // nothing to paint: a transparent frame, and the next one starts a new shot
        out.image = RgbaImage(W, H);
        I.havePrev = false;
        I.prevRgb = ChannelImage(); // no flicker measured across the cut
        ++I.j;
        return out;
    }
    auto t0 = Clock::now();
    if (progress) progress->begin("guides");
    Impl::FrameGuides g = I.frameGuides(j, st);
    st.centres = g.levels[0].segCount[0] + g.levels[0].segCount[1];
    st.secondsGuides = since(t0);

    RotatedNnf nnf;
    ChannelImage result; // the last vote: R, G, B, mask at the current level
    for (int l = I.L - 1; l >= 0; --l) {
        checkCancelled(progress);
        I.synthesizeLevel(l, j, g, nnf, result, st, progress);
    }

    auto tm = Clock::now();
    I.measure(I.ex[0], g.levels[0], nnf, result, g.images.mask, g.images.flow, g.extRaw, st);
    st.secondsStats = since(tm);
    out.image = RgbaImage(W, H);
    out.image.colorSpace = "";
    for (size_t p = 0; p < out.image.size(); ++p) {
        const float* v = result.pixel(p);
        out.image.pixels()[p] = Rgba(v[0], v[1], v[2], std::clamp(v[3], 0.0f, 1.0f));
        const PatchRef& m = nnf.match[p];
        if (g.levels[0].label[p] >= 0 && m.valid()) {
            out.rotation.pixel(p)[0] = float(rotationAngle(m.rotation));
            out.rotation.pixel(p)[1] = 1.0f;
        }
    }
    out.nnf = nnf;
    I.prevNnf = std::move(nnf);
    I.prevRgb = channelRange(result, 0, 3);
    I.prevMask = std::move(g.images.mask);
    I.prevFlow = std::move(g.images.flow);
    I.prevExt = std::move(g.extRaw);
    I.havePrev = true;
    I.last = std::move(g.levels[0]);
    I.haveLast = true;
    ++I.j;
    return out;
}

} // namespace turb
