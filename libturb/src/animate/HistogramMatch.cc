#include <turb/HistogramMatch.h>

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/SteerablePyramid.h>

#include <Eigen/Dense>
#include <Eigen/Sparse>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <tuple>

namespace turb {

std::pair<int, int> histogramGrid(int width, int height, const HistogramMatchSettings& s)
{
    const int cols = s.gridCols > 0 ? s.gridCols : std::max(1, int(std::lround(double(width) / s.cellSize)));
    const int rows = s.gridRows > 0 ? s.gridRows : std::max(1, int(std::lround(double(height) / s.cellSize)));
    return {std::min(cols, std::max(1, width / 8)), std::min(rows, std::max(1, height / 8))};
}

void validate(const HistogramMatchSettings& s)
{
    if (s.reps < 1 || s.reps > 10) throw ValueError("histogram matching: HM Rep must be 1..10");
    if (s.gridCols < 0 || s.gridRows < 0 || s.gridCols > 256 || s.gridRows > 256)
        throw ValueError("histogram matching: grid must be 0..256 cells per axis");
    if (s.cellSize < 16) throw ValueError("histogram matching: the automatic cell size must be >= 16 pixels");
    if (!(s.overlap >= 0.0 && s.overlap <= 0.5)) throw ValueError("histogram matching: overlap must be in [0, 0.5]");
    if (!(s.reach >= 0.0 && s.reach <= 1.0)) throw ValueError("histogram matching: reach must be in [0, 1]");
    if (s.levels < 1) throw ValueError("histogram matching: levels must be >= 1");
    if (s.orientations < 1 || s.orientations > 8) throw ValueError("histogram matching: orientations must be 1..8");
    if (s.bins < 16 || s.quantiles < 16) throw ValueError("histogram matching: bins and quantiles must be >= 16");
    if (s.pixelPasses < 1 || s.pixelPasses > 20) throw ValueError("histogram matching: pixel passes must be 1..20");
}

MeanStd meanStd(const ChannelImage& img, int c, int x0, int y0, int x1, int y1)
{
    double s = 0.0, s2 = 0.0;
    size_t n = 0;
    for (int y = std::max(0, y0); y < std::min(img.height(), y1); ++y)
        for (int x = std::max(0, x0); x < std::min(img.width(), x1); ++x) {
            const double v = img.at(x, y, c);
            s += v;
            s2 += v * v;
            ++n;
        }
    MeanStd m;
    if (!n) return m;
    m.mean = s / double(n);
    m.std = std::sqrt(std::max(0.0, s2 / double(n) - m.mean * m.mean));
    return m;
}

namespace {

/// A pixel's two cells along one axis and the first one's weight (the second gets 1 - w).
struct AxisTap
{
    int a = 0, b = 0;
    float w = 1.0f;
};

/// The grid seen at one band's resolution.
struct Geometry
{
    int w = 0, h = 0;                 // band size
    std::vector<AxisTap> xs, ys;      // per column / row
    std::vector<HmCell> regions;      // per cell, statistics region in band pixels (valid part only)
    std::vector<std::uint8_t> mask;   // per band pixel: inside the matte (empty: no matte)
    std::vector<std::uint8_t> masked; // per cell: its statistics use the mask (enough matte pixels in it)

    /// Calls fn(cell index, weight) for every cell whose blend weight at pixel (x, y) is positive: at most four, and
    /// one of weight 1 in a cell's core. T is the arithmetic the weights are formed in; `cols` the grid's columns.
    template<typename T, typename Fn>
    void forTaps(int x, int y, int cols, Fn&& fn) const
    {
        const AxisTap tx = xs[size_t(x)], ty = ys[size_t(y)];
        const int ra[2] = {ty.a, ty.b}, ca[2] = {tx.a, tx.b};
        const T rw[2] = {T(ty.w), T(1) - T(ty.w)}, cw[2] = {T(tx.w), T(1) - T(tx.w)};
        for (int i = 0; i < 2; ++i)
            for (int j = 0; j < 2; ++j) {
                const T w = rw[i] * cw[j];
                if (w > T(0)) fn(ra[i] * cols + ca[j], w);
            }
    }

    /// Calls fn(value) for the pixels of cell k's statistics; `step` > 1 visits every step-th row and
    /// column (a sample of large cells for the frame's histograms; the target's tables use every pixel).
    template<typename Fn>
    void forCell(const ChannelImage& band, size_t k, Fn&& fn, int step = 1) const
    {
        const HmCell& r = regions[k];
        const bool useMask = !masked.empty() && masked[k];
        for (int y = r.sy0; y < r.sy1; y += step) {
            const float* row = band.pixel(0, y);
            const std::uint8_t* m = useMask ? &mask[size_t(y) * size_t(w)] : nullptr;
            for (int x = r.sx0; x < r.sx1; x += step)
                if (!m || m[x]) fn(row[x]);
        }
    }
};

std::vector<AxisTap> axisTaps(int n, const std::vector<double>& edges, double o)
{
    const int cells = int(edges.size()) - 1;
    std::vector<AxisTap> taps(static_cast<size_t>(n));
    for (int x = 0; x < n; ++x) {
        const double c = x + 0.5;
        int i = 0;
        while (i + 1 < cells && c >= edges[size_t(i + 1)]) ++i;
        AxisTap t{i, i, 1.0f};
        // Near the cell's lower edge the previous cell shares the pixel; near its upper edge the next one.
        if (o > 0.0 && i > 0 && c < edges[size_t(i)] + o) {
            const double u = (c - (edges[size_t(i)] - o)) / (2.0 * o);
            t = AxisTap{i - 1, i, float(1.0 - std::clamp(u, 0.0, 1.0))};
        } else if (o > 0.0 && i + 1 < cells && c > edges[size_t(i + 1)] - o) {
            const double u = (c - (edges[size_t(i + 1)] - o)) / (2.0 * o);
            t = AxisTap{i, i + 1, float(1.0 - std::clamp(u, 0.0, 1.0))};
        }
        taps[size_t(x)] = t;
    }
    return taps;
}

/// A cell's transfer function for one band: the source's cumulative histogram (`bins` bins over the
/// cell's value range, linear within a bin) composed with the target's quantile table, tabulated at the
/// bin edges; between edges it is linear (the composition is, to within the quantile table's steps).
struct CellMap
{
    float lo = 0.0f, scale = 0.0f; // bin coordinate t = (v - lo) * scale
    std::vector<float> at;         // bins + 1 values at the bin edges
    float operator()(float v) const
    {
        const int B = int(at.size()) - 1;
        const float t = std::clamp((v - lo) * scale, 0.0f, float(B));
        const int b = std::min(int(t), B - 1);
        const float f = t - float(b);
        return at[size_t(b)] + f * (at[size_t(b + 1)] - at[size_t(b)]);
    }
};

/// The target's value at cumulative probability p in [0, 1].
inline float quantileAt(const std::vector<float>& q, double p)
{
    const double at = std::clamp(p, 0.0, 1.0) * double(q.size() - 1);
    const size_t i = std::min(size_t(at), q.size() - 2);
    const double f = at - double(i);
    return float((1.0 - f) * q[i] + f * q[i + 1]);
}

CellMap cellMap(const ChannelImage& band, const Geometry& g, size_t k, int bins, const std::vector<float>& q)
{
    // Cells of >= 4096 pixels are sampled on every other row and column (a quarter of the cost; the
    // histogram of 1024+ samples is as good). Values beyond the sample's range map to the target's ends.
    const HmCell& r = g.regions[k];
    const int step = size_t(r.sx1 - r.sx0) * size_t(r.sy1 - r.sy0) >= 4096 ? 2 : 1;
    float lo = 1e30f, hi = -1e30f;
    g.forCell(
        band, k,
        [&](float v) {
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        },
        step);
    CellMap m;
    m.lo = lo;
    m.at.assign(size_t(bins) + 1, 0.0f);
    if (!(hi > lo)) {
        // A constant region: every value maps to the target's median.
        std::fill(m.at.begin(), m.at.end(), quantileAt(q, 0.5));
        return m;
    }
    m.scale = float(bins / (double(hi) - double(lo)));
    std::vector<double> count(size_t(bins), 0.0);
    double n = 0.0;
    g.forCell(
        band, k,
        [&](float v) {
            count[size_t(std::clamp(int((v - lo) * m.scale), 0, bins - 1))] += 1.0;
            n += 1.0;
        },
        step);
    double acc = 0.0;
    for (int b = 0; b <= bins; ++b) {
        m.at[size_t(b)] = quantileAt(q, acc / n);
        if (b < bins) acc += count[size_t(b)];
    }
    return m;
}

std::vector<float> quantileTable(std::vector<float> values, int Q)
{
    std::vector<float> q(size_t(Q), 0.0f);
    if (values.empty()) return q;
    std::sort(values.begin(), values.end());
    for (int j = 0; j < Q; ++j) {
        const double at = double(j) / (Q - 1) * double(values.size() - 1);
        const size_t i = std::min(size_t(at), values.size() - 1);
        const size_t i1 = std::min(i + 1, values.size() - 1);
        const double f = at - double(i);
        q[size_t(j)] = float((1.0 - f) * values[i] + f * values[i1]);
    }
    return q;
}

/// The moment step's sums over one cell's pixels (see correctMoments), indexed by the neighbour offset (3x3 around
/// the cell), with the matte m and the fixed part u = (1 - m) t: sum m w_j {1, v}, sum m w_j u {1, v}; per pair
/// (i, j), sum m^2 w_i w_j {1, v, v^2}; and sum u, sum u^2.
struct MomentSums
{
    double n = 0.0, u1 = 0.0, u2 = 0.0;
    std::array<std::array<double, 2>, 9> lin{}, cross{};
    std::array<std::array<std::array<double, 3>, 9>, 9> quad{};
};

/// The moment step's least-squares problem: per cell its sums, the target's mean and std, and the residuals' scale.
struct MomentProblem
{
    int N = 0; // cells
    std::vector<MomentSums> sums;
    const std::vector<std::array<double, 2>>* goal = nullptr;
    std::vector<double> scale;
};

} // namespace

struct HistogramMatcher::Impl
{
    HistogramMatchSettings s;
    int W = 0, H = 0, C = 0, levels = 1;
    int cols = 1, rows = 1;
    std::vector<HmCell> cells;
    std::vector<double> xEdges, yEdges;
    double ox = 0.0, oy = 0.0;
    // Colour PCA: y = E^T (x - mu) over the first 3 channels.
    bool pca = false;
    const ChannelImage* matte = nullptr; // only during construction
    Eigen::Matrix3d E = Eigen::Matrix3d::Identity();
    Eigen::Vector3d mu = Eigen::Vector3d::Zero();
    // Per band slot: geometry and, per channel, the target's quantile tables per cell.
    // Slot 0 = pixels; steerable: 1 = high-pass, then level x orientation, then low-pass;
    // Laplacian: 1..levels = bands, then low-pass.
    std::vector<Geometry> geometry;
    std::vector<std::vector<std::vector<std::vector<float>>>> tables; // [channel][slot][cell]
    std::vector<std::vector<std::vector<float>>> rgbTables;  // [channel][cell]: the target's own channels (with PCA)
    std::vector<std::vector<std::array<double, 2>>> moments; // [channel][cell]: the target's mean and std (slot 0)
    ChannelImage target, matteCopy; // for the moment step: the frame is composited over the target through the matte

    Geometry makeGeometry(int w, int h, double scale, double overlapScale = 1.0) const
    {
        Geometry g;
        g.w = w;
        g.h = h;
        std::vector<double> xe, ye;
        for (double e : xEdges) xe.push_back(e * scale);
        for (double e : yEdges) ye.push_back(e * scale);
        g.xs = axisTaps(w, xe, ox * scale * overlapScale);
        g.ys = axisTaps(h, ye, oy * scale * overlapScale);
        const int vw = std::min(w, int(std::ceil(W * scale))), vh = std::min(h, int(std::ceil(H * scale)));
        for (const HmCell& c : cells) {
            HmCell r;
            r.sx0 = std::clamp(int(std::floor(c.sx0 * scale)), 0, vw - 1);
            r.sy0 = std::clamp(int(std::floor(c.sy0 * scale)), 0, vh - 1);
            r.sx1 = std::clamp(int(std::ceil(c.sx1 * scale)), r.sx0 + 1, vw);
            r.sy1 = std::clamp(int(std::ceil(c.sy1 * scale)), r.sy0 + 1, vh);
            g.regions.push_back(r);
        }
        if (matte) {
            // The matte seen at this band's resolution (nearest sample); cells with too few fluid
            // pixels keep all their pixels.
            g.mask.assign(size_t(w) * size_t(h), 0);
            for (int y = 0; y < vh; ++y)
                for (int x = 0; x < vw; ++x) {
                    const int mx = std::min(W - 1, int((x + 0.5) / scale)),
                              my = std::min(H - 1, int((y + 0.5) / scale));
                    g.mask[size_t(y) * size_t(w) + size_t(x)] = matte->at(mx, my, 0) >= 0.5f;
                }
            for (const HmCell& r : g.regions) {
                size_t n = 0;
                for (int y = r.sy0; y < r.sy1; ++y)
                    for (int x = r.sx0; x < r.sx1; ++x) n += g.mask[size_t(y) * size_t(w) + size_t(x)];
                g.masked.push_back(n >= 16);
            }
        }
        return g;
    }

    std::vector<std::vector<float>> cellTables(const ChannelImage& band, const Geometry& g) const
    {
        std::vector<std::vector<float>> t(cells.size());
        parallelFor(cells.size(), 1, [&](size_t b, size_t e) {
            for (size_t k = b; k < e; ++k) {
                std::vector<float> v;
                g.forCell(band, k, [&](float x) { v.push_back(x); });
                t[k] = quantileTable(std::move(v), s.quantiles);
            }
        });
        return t;
    }

    void matchSlot(ChannelImage& band, size_t slot, int channel) const
    {
        matchTables(band, geometry[slot], tables[size_t(channel)][slot]);
    }

    /// Matches a band to per-cell quantile tables under a geometry.
    void matchTables(ChannelImage& band, const Geometry& g, const std::vector<std::vector<float>>& tab) const
    {
        std::vector<CellMap> maps(cells.size());
        parallelFor(cells.size(), 1, [&](size_t b, size_t e) {
            for (size_t k = b; k < e; ++k) maps[k] = cellMap(band, g, k, s.bins, tab[k]);
        });
        parallelFor(size_t(g.h), 8, [&](size_t y0, size_t y1) {
            for (size_t y = y0; y < y1; ++y) {
                const AxisTap ty = g.ys[y];
                float* row = band.pixel(0, int(y));
                for (int x = 0; x < g.w; ++x) {
                    const AxisTap tx = g.xs[size_t(x)];
                    const float v = row[x];
                    if (ty.w >= 1.0f && tx.w >= 1.0f) { // a cell's core: its own map alone
                        row[x] = maps[size_t(ty.a) * size_t(cols) + size_t(tx.a)](v);
                        continue;
                    }
                    float out = 0.0f;
                    g.forTaps<float>(x, int(y), cols, [&](int k, float w) { out += w * maps[size_t(k)](v); });
                    row[x] = out;
                }
            }
        });
    }

    /// Mean and std of channel c of an image over each whole cell.
    std::vector<std::array<double, 2>> cellMoments(const ChannelImage& img, int c) const
    {
        std::vector<std::array<double, 2>> m(cells.size());
        for (size_t k = 0; k < cells.size(); ++k) {
            const MeanStd ms = meanStd(img, c, cells[k].x0, cells[k].y0, cells[k].x1, cells[k].y1);
            m[k] = {ms.mean, ms.std};
        }
        return m;
    }

    void correctMoments(ChannelImage& p, int c) const;
    /// Neighbour o (0..8) of cell k, or -1 outside the grid.
    int cellAt(int k, int o) const
    {
        const int i = k % cols + o % 3 - 1, j = k / cols + o / 3 - 1;
        return i < 0 || j < 0 || i >= cols || j >= rows ? -1 : j * cols + i;
    }
    std::vector<MomentSums> momentSums(const ChannelImage& p, int channel) const;
    void momentResiduals(const MomentProblem& mp, const Eigen::VectorXd& ab, Eigen::VectorXd& r,
        std::vector<Eigen::Triplet<double>>* J) const;
    bool solveMomentGains(const MomentProblem& mp, Eigen::VectorXd& ab) const;
    void applyMomentGains(ChannelImage& p, const Eigen::VectorXd& ab) const;
    void layOutCells();
    void fitColourPca(const ChannelImage& image);
    void buildGeometry();
    void buildTables(const ChannelImage& image);
    ChannelImage plane(const ChannelImage& img, int c) const;
    void unplane(const std::vector<ChannelImage>& planes, ChannelImage& out) const;
    void matchPlane(ChannelImage& p, int c) const;
};

// The blended pixel matches leave a cell's mean and std a few per cent off where a neighbour's map covers much of it
// (the blend weights make each cell's statistics depend on its neighbours' maps). The last step solves for that
// coupling exactly: one gain a_k and offset b_k per cell, applied blended with the same weights,
//   y(x) = sum_k w_k(x) (a_k v(x) + b_k),
// such that every cell of the frame as it is delivered, y composited over the target through the matte
// (m y + (1 - m) t), has the target's mean and variance over the whole cell: 2 equations per cell, polynomial in
// (a, b), solved by Levenberg-Marquardt from (1, 0). The correction is smooth (a blend of affine maps), so it adds
// no seam; it is kept only where it lowers the residual.
void HistogramMatcher::Impl::correctMoments(ChannelImage& p, int channel) const
{
    const int N = int(cells.size());
    // A reach > 0 lets a cell's statistics see cells two away, beyond the 3x3 neighbourhood summed here; such grids
    // keep the blended matches' result. One cell is solved too: the histogram passes leave it a little off as well.
    if (N < 1 || s.reach > 0.0) return;
    MomentProblem mp;
    mp.N = N;
    mp.goal = &moments[size_t(channel)];
    mp.sums = momentSums(p, channel);
    // Residuals scaled by the target's std (a floor keeps flat cells from dominating): r = [mean - M, m2 - Q].
    const std::vector<std::array<double, 2>>& goal = *mp.goal;
    mp.scale.resize(static_cast<size_t>(N));
    double spread = 0.0;
    for (int k = 0; k < N; ++k) spread = std::max(spread, goal[size_t(k)][1]);
    for (int k = 0; k < N; ++k) mp.scale[size_t(k)] = 1.0 / std::max(goal[size_t(k)][1], 1e-3 * spread + 1e-12);
    Eigen::VectorXd ab;
    if (!solveMomentGains(mp, ab)) return;
    applyMomentGains(p, ab);
}

// The moment step's sums per cell (MomentSums) over the pixels of plane `p` of `channel`.
std::vector<MomentSums> HistogramMatcher::Impl::momentSums(const ChannelImage& p, int channel) const
{
    const Geometry& g = geometry[0];
    std::vector<MomentSums> sums(cells.size());
    const bool matted = !matteCopy.empty();
    parallelFor(cells.size(), 1, [&](size_t b, size_t e) {
        for (size_t k = b; k < e; ++k) {
            const HmCell& cell = cells[k];
            const int ki = int(k) % cols, kj = int(k) / cols;
            MomentSums& S = sums[k];
            for (int y = cell.y0; y < cell.y1; ++y)
                for (int x = cell.x0; x < cell.x1; ++x) {
                    const double v = p.at(x, y, 0);
                    const double m = matted ? std::clamp(double(matteCopy.at(x, y, 0)), 0.0, 1.0) : 1.0;
                    const double u = matted ? (1.0 - m) * target.at(x, y, channel) : 0.0;
                    int o[4];
                    double w[4];
                    int cnt = 0;
                    g.forTaps<double>(x, y, cols, [&](int j, double wj) {
                        const double ww = wj * m;
                        const int di = j % cols - ki + 1, dj = j / cols - kj + 1;
                        if (ww <= 0.0 || di < 0 || di > 2 || dj < 0 || dj > 2) return;
                        o[cnt] = dj * 3 + di;
                        w[cnt++] = ww;
                    });
                    S.n += 1.0;
                    S.u1 += u;
                    S.u2 += u * u;
                    for (int q = 0; q < cnt; ++q) {
                        S.lin[size_t(o[q])][0] += w[q];
                        S.lin[size_t(o[q])][1] += w[q] * v;
                        S.cross[size_t(o[q])][0] += w[q] * u;
                        S.cross[size_t(o[q])][1] += w[q] * u * v;
                        for (int t = 0; t < cnt; ++t) {
                            auto& qq = S.quad[size_t(o[q])][size_t(o[t])];
                            const double ww = w[q] * w[t];
                            qq[0] += ww;
                            qq[1] += ww * v;
                            qq[2] += ww * v * v;
                        }
                    }
                }
        }
    });
    return sums;
}

// The residuals r (mean and variance per cell, scaled) at gains and offsets `ab`; with J, its Jacobian's entries.
void HistogramMatcher::Impl::momentResiduals(const MomentProblem& mp, const Eigen::VectorXd& ab, Eigen::VectorXd& r,
    std::vector<Eigen::Triplet<double>>* J) const
{
    const int N = mp.N;
    const std::vector<std::array<double, 2>>& goal = *mp.goal;
    r.resize(2 * N);
    for (int k = 0; k < N; ++k) {
        const MomentSums& S = mp.sums[size_t(k)];
        const double inv = S.n > 0.0 ? 1.0 / S.n : 0.0, sc = mp.scale[size_t(k)];
        const double M = goal[size_t(k)][0], S2 = goal[size_t(k)][1] * goal[size_t(k)][1];
        double mean = S.u1 * inv, m2 = S.u2 * inv;
        std::array<double, 9> dMa{}, dMb{}, d2a{}, d2b{};
        for (int oi = 0; oi < 9; ++oi) {
            const int i = cellAt(k, oi);
            if (i < 0) continue;
            const double ai = ab[2 * i], bi = ab[2 * i + 1];
            mean += (ai * S.lin[size_t(oi)][1] + bi * S.lin[size_t(oi)][0]) * inv;
            dMa[size_t(oi)] = S.lin[size_t(oi)][1] * inv;
            dMb[size_t(oi)] = S.lin[size_t(oi)][0] * inv;
            m2 += 2.0 * (ai * S.cross[size_t(oi)][1] + bi * S.cross[size_t(oi)][0]) * inv;
            d2a[size_t(oi)] += 2.0 * S.cross[size_t(oi)][1] * inv;
            d2b[size_t(oi)] += 2.0 * S.cross[size_t(oi)][0] * inv;
            for (int oj = 0; oj < 9; ++oj) {
                const int j = cellAt(k, oj);
                if (j < 0) continue;
                const auto& q = S.quad[size_t(oi)][size_t(oj)];
                const double aj = ab[2 * j], bj = ab[2 * j + 1];
                m2 += (ai * aj * q[2] + 2.0 * ai * bj * q[1] + bi * bj * q[0]) * inv;
                d2a[size_t(oi)] += 2.0 * (aj * q[2] + bj * q[1]) * inv;
                d2b[size_t(oi)] += 2.0 * (aj * q[1] + bj * q[0]) * inv;
            }
        }
        // The variance, not the second moment: m2 - Q mixes in the mean's error times 2M, which for a cell with
        // M >> S swamps the std's (a 5% std error hid behind a 0.3% residual on the 640x480 river).
        r[2 * k] = (mean - M) * sc;
        r[2 * k + 1] = (m2 - mean * mean - S2) * sc * sc;
        if (!J) continue;
        for (int oi = 0; oi < 9; ++oi) {
            const int i = cellAt(k, oi);
            if (i < 0) continue;
            J->emplace_back(2 * k, 2 * i, dMa[size_t(oi)] * sc);
            J->emplace_back(2 * k, 2 * i + 1, dMb[size_t(oi)] * sc);
            J->emplace_back(2 * k + 1, 2 * i, (d2a[size_t(oi)] - 2.0 * mean * dMa[size_t(oi)]) * sc * sc);
            J->emplace_back(2 * k + 1, 2 * i + 1, (d2b[size_t(oi)] - 2.0 * mean * dMb[size_t(oi)]) * sc * sc);
        }
    }
}

// Levenberg-Marquardt from (a, b) = (1, 0). Returns false (and the caller keeps the frame) unless the gains and
// offsets left in `ab` lower the residual.
bool HistogramMatcher::Impl::solveMomentGains(const MomentProblem& mp, Eigen::VectorXd& ab) const
{
    const int N = mp.N;
    Eigen::VectorXd r, rTry;
    ab.resize(2 * N);
    for (int k = 0; k < N; ++k) {
        ab[2 * k] = 1.0;
        ab[2 * k + 1] = 0.0;
    }
    std::vector<Eigen::Triplet<double>> trips;
    momentResiduals(mp, ab, r, &trips);
    const double start = r.squaredNorm();
    double mu = 1e-6;
    for (int it = 0; it < 50 && r.lpNorm<Eigen::Infinity>() > 1e-6; ++it) {
        Eigen::SparseMatrix<double> J(2 * N, 2 * N);
        J.setFromTriplets(trips.begin(), trips.end());
        const Eigen::SparseMatrix<double> JtJ = J.transpose() * J;
        const Eigen::VectorXd Jtr = J.transpose() * r;
        bool stepped = false;
        for (int tries = 0; tries < 12 && !stepped; ++tries) {
            Eigen::SparseMatrix<double> A = JtJ;
            for (int c = 0; c < 2 * N; ++c) A.coeffRef(c, c) += mu * (1.0 + JtJ.coeff(c, c));
            Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
            if (ldlt.info() != Eigen::Success) {
                mu *= 10.0;
                continue;
            }
            const Eigen::VectorXd next = ab - ldlt.solve(Jtr);
            momentResiduals(mp, next, rTry, nullptr);
            if (rTry.squaredNorm() < r.squaredNorm()) {
                ab = next;
                stepped = true;
                mu = std::max(1e-9, mu * 0.3);
            } else {
                mu *= 10.0;
            }
        }
        if (!stepped) break;
        trips.clear();
        momentResiduals(mp, ab, r, &trips);
    }
    return r.squaredNorm() < start;
}

// y(x) = sum_k w_k(x) (a_k v(x) + b_k) over the plane, with the pixel blend's weights.
void HistogramMatcher::Impl::applyMomentGains(ChannelImage& p, const Eigen::VectorXd& ab) const
{
    const Geometry& g = geometry[0];
    parallelFor(size_t(g.h), 8, [&](size_t y0, size_t y1) {
        for (size_t y = y0; y < y1; ++y) {
            float* row = p.pixel(0, int(y));
            for (int x = 0; x < g.w; ++x) {
                double out = 0.0;
                g.forTaps<double>(
                    x, int(y), cols, [&](int k, double w) { out += w * (ab[2 * k] * row[x] + ab[2 * k + 1]); });
                row[x] = float(out);
            }
        }
    });
}

ChannelImage HistogramMatcher::Impl::plane(const ChannelImage& img, int c) const
{
    ChannelImage p(W, H, 1);
    for (size_t i = 0; i < p.pixelCount(); ++i) {
        const float* v = img.pixel(i);
        if (pca && c < 3) {
            const Eigen::Vector3d x(v[0] - mu[0], v[1] - mu[1], v[2] - mu[2]);
            p.pixel(i)[0] = float(E.col(c).dot(x));
        } else {
            p.pixel(i)[0] = v[c];
        }
    }
    return p;
}

void HistogramMatcher::Impl::unplane(const std::vector<ChannelImage>& planes, ChannelImage& out) const
{
    for (size_t i = 0; i < out.pixelCount(); ++i) {
        float* o = out.pixel(i);
        if (pca) {
            const Eigen::Vector3d y(planes[0].pixel(i)[0], planes[1].pixel(i)[0], planes[2].pixel(i)[0]);
            const Eigen::Vector3d x = E * y + mu;
            for (int c = 0; c < 3; ++c) o[c] = float(x[c]);
            for (int c = 3; c < C; ++c) o[c] = planes[size_t(c)].pixel(i)[0];
        } else {
            for (int c = 0; c < C; ++c) o[c] = planes[size_t(c)].pixel(i)[0];
        }
    }
}

void HistogramMatcher::Impl::matchPlane(ChannelImage& p, int c) const
{
    matchSlot(p, 0, c);
    const int reps = s.pyramid == HmPyramid::Laplacian ? 1 : s.reps;
    for (int r = 0; r < reps; ++r) {
        if (s.pyramid == HmPyramid::Steerable) {
            SteerablePyramid pyr = buildSteerablePyramid(p, levels, s.orientations);
            size_t slot = 1;
            matchSlot(pyr.highpass, slot++, c);
            for (auto& level : pyr.bands)
                for (auto& band : level) matchSlot(band, slot++, c);
            matchSlot(pyr.lowpass, slot, c);
            p = collapse(pyr);
        } else {
            LaplacianPyramid pyr = buildLaplacianPyramid(p, levels);
            size_t slot = 1;
            for (auto& band : pyr.bands) matchSlot(band, slot++, c);
            matchSlot(pyr.lowpass, slot, c);
            p = collapse(pyr);
        }
        matchSlot(p, 0, c);
    }
    // Blended cells leave each cell's statistics a little off where neighbours differ; matching the
    // pixels again moves every cell's map towards the identity and its statistics to the target's.
    for (int k = 1; k < s.pixelPasses; ++k) matchSlot(p, 0, c);
}

HistogramMatcher::HistogramMatcher(
    const ChannelImage& target, const HistogramMatchSettings& settings, const ChannelImage* matte)
    : mImpl(std::make_unique<Impl>())
{
    if (matte && (!matte->sameSize(target) || matte->channels() != 1))
        throw ValueError("histogram matching: the matte must be a 1-channel image of the target's size");
    validate(settings);
    if (target.empty() || target.channels() < 1 || target.channels() > 4)
        throw ValueError("histogram matching: the target must be a non-empty 1..4 channel image");
    Impl& m = *mImpl;
    m.s = settings;
    m.matte = matte;
    m.W = target.width();
    m.H = target.height();
    m.C = target.channels();
    m.levels = std::min(settings.levels, maxSteerableLevels(m.W, m.H));
    m.layOutCells();
    if (settings.colorPca && m.C >= 3) m.fitColourPca(target);
    m.buildGeometry();
    m.buildTables(target);
}

// The grid of cells over the target: edges, overlaps and each cell's statistics region (its reach around it).
void HistogramMatcher::Impl::layOutCells()
{
    std::tie(cols, rows) = histogramGrid(W, H, s);
    for (int i = 0; i <= cols; ++i) xEdges.push_back(std::round(double(W) * i / cols));
    for (int j = 0; j <= rows; ++j) yEdges.push_back(std::round(double(H) * j / rows));
    ox = s.overlap * double(W) / cols;
    oy = s.overlap * double(H) / rows;
    for (int j = 0; j < rows; ++j)
        for (int i = 0; i < cols; ++i) {
            HmCell c;
            c.x0 = int(xEdges[size_t(i)]);
            c.x1 = int(xEdges[size_t(i + 1)]);
            c.y0 = int(yEdges[size_t(j)]);
            c.y1 = int(yEdges[size_t(j + 1)]);
            const double rx = s.reach * double(W) / cols, ry = s.reach * double(H) / rows;
            c.sx0 = std::max(0, int(std::floor(c.x0 - rx)));
            c.sy0 = std::max(0, int(std::floor(c.y0 - ry)));
            c.sx1 = std::min(W, int(std::ceil(c.x1 + rx)));
            c.sy1 = std::min(H, int(std::ceil(c.y1 + ry)));
            cells.push_back(c);
        }
}

// The colour PCA: the target's mean colour and the eigenvectors of its colour covariance.
void HistogramMatcher::Impl::fitColourPca(const ChannelImage& image)
{
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < image.pixelCount(); ++i)
        for (int c = 0; c < 3; ++c) mean[c] += image.pixel(i)[c];
    mean /= double(image.pixelCount());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < image.pixelCount(); ++i) {
        const Eigen::Vector3d d(image.pixel(i)[0] - mean[0], image.pixel(i)[1] - mean[1], image.pixel(i)[2] - mean[2]);
        cov += d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    E = eig.eigenvectors();
    mu = mean;
    pca = true;
}

// The grid seen at every band slot's resolution (the slots of the class comment).
void HistogramMatcher::Impl::buildGeometry()
{
    geometry.push_back(makeGeometry(W, H, 1.0, s.blendPixels ? 1.0 : 0.0));
    const ChannelImage probe(W, H, 1);
    if (s.pyramid == HmPyramid::Steerable) {
        const SteerablePyramid pyr = buildSteerablePyramid(probe, levels, s.orientations);
        geometry.push_back(makeGeometry(pyr.highpass.width(), pyr.highpass.height(), 1.0));
        for (int l = 0; l < levels; ++l)
            for (int k = 0; k < s.orientations; ++k)
                geometry.push_back(makeGeometry(pyr.bands[size_t(l)][size_t(k)].width(),
                    pyr.bands[size_t(l)][size_t(k)].height(), std::ldexp(1.0, -l)));
        geometry.push_back(makeGeometry(pyr.lowpass.width(), pyr.lowpass.height(), std::ldexp(1.0, -levels)));
    } else {
        const LaplacianPyramid pyr = buildLaplacianPyramid(probe, levels);
        for (int l = 0; l < levels; ++l)
            geometry.push_back(
                makeGeometry(pyr.bands[size_t(l)].width(), pyr.bands[size_t(l)].height(), std::ldexp(1.0, -l)));
        geometry.push_back(makeGeometry(pyr.lowpass.width(), pyr.lowpass.height(), std::ldexp(1.0, -levels)));
    }
}

// The target's quantile tables per channel, slot and cell (and its own channels' with PCA, its moments per cell).
void HistogramMatcher::Impl::buildTables(const ChannelImage& image)
{
    if (pca)
        for (int c = 0; c < C; ++c) rgbTables.push_back(cellTables(channelRange(image, c, 1), geometry[0]));
    if (s.cellMoments) {
        for (int c = 0; c < C; ++c) moments.push_back(cellMoments(image, c));
        target = image;
        if (matte) matteCopy = *matte;
    }
    tables.resize(size_t(C));
    for (int c = 0; c < C; ++c) {
        const ChannelImage p = plane(image, c);
        auto& t = tables[size_t(c)];
        t.push_back(cellTables(p, geometry[0]));
        if (s.pyramid == HmPyramid::Steerable) {
            const SteerablePyramid pyr = buildSteerablePyramid(p, levels, s.orientations);
            size_t slot = 1;
            t.push_back(cellTables(pyr.highpass, geometry[slot++]));
            for (const auto& level : pyr.bands)
                for (const auto& band : level) t.push_back(cellTables(band, geometry[slot++]));
            t.push_back(cellTables(pyr.lowpass, geometry[slot]));
        } else {
            const LaplacianPyramid pyr = buildLaplacianPyramid(p, levels);
            size_t slot = 1;
            for (const auto& band : pyr.bands) t.push_back(cellTables(band, geometry[slot++]));
            t.push_back(cellTables(pyr.lowpass, geometry[slot]));
        }
    }
}

HistogramMatcher::~HistogramMatcher() = default;
HistogramMatcher::HistogramMatcher(HistogramMatcher&&) noexcept = default;
HistogramMatcher& HistogramMatcher::operator=(HistogramMatcher&&) noexcept = default;

int HistogramMatcher::gridCols() const { return mImpl->cols; }
int HistogramMatcher::gridRows() const { return mImpl->rows; }
const std::vector<HmCell>& HistogramMatcher::cells() const { return mImpl->cells; }
int HistogramMatcher::levels() const { return mImpl->levels; }

namespace {

void checkFrame(const ChannelImage& frame, int W, int H, int C)
{
    if (frame.width() != W || frame.height() != H || frame.channels() != C)
        throw ValueError("histogram matching: the frame is " + std::to_string(frame.width()) + "x" +
                         std::to_string(frame.height()) + "x" + std::to_string(frame.channels()) + ", the target " +
                         std::to_string(W) + "x" + std::to_string(H) + "x" + std::to_string(C));
}

} // namespace

ChannelImage HistogramMatcher::match(const ChannelImage& frame) const
{
    const Impl& m = *mImpl;
    checkFrame(frame, m.W, m.H, m.C);
    std::vector<ChannelImage> planes(size_t(m.C));
    parallelFor(size_t(m.C), 1, [&](size_t b, size_t e) {
        for (size_t c = b; c < e; ++c) {
            planes[c] = m.plane(frame, int(c));
            m.matchPlane(planes[c], int(c));
        }
    });
    ChannelImage out(m.W, m.H, m.C);
    m.unplane(planes, out);
    if (m.pca) {
        // Matched in the decorrelated space; the target's own channels get the last word.
        parallelFor(size_t(m.C), 1, [&](size_t b, size_t e) {
            for (size_t c = b; c < e; ++c) {
                ChannelImage p = channelRange(out, int(c), 1);
                for (int k = 0; k < m.s.pixelPasses; ++k) m.matchTables(p, m.geometry[0], m.rgbTables[c]);
                for (size_t i = 0; i < p.pixelCount(); ++i) out.pixel(i)[c] = p.pixel(i)[0];
            }
        });
    }
    return matchMoments(out);
}

ChannelImage HistogramMatcher::matchMoments(const ChannelImage& frame) const
{
    const Impl& m = *mImpl;
    checkFrame(frame, m.W, m.H, m.C);
    ChannelImage out = frame;
    if (!m.s.cellMoments) return out;
    parallelFor(size_t(m.C), 1, [&](size_t b, size_t e) {
        for (size_t c = b; c < e; ++c) {
            ChannelImage p = channelRange(out, int(c), 1);
            m.correctMoments(p, int(c));
            for (size_t i = 0; i < p.pixelCount(); ++i) out.pixel(i)[c] = p.pixel(i)[0];
        }
    });
    return out;
}

} // namespace turb
