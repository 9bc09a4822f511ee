// Time chunks: the split of a frame list and the cross-fade of overlap frames (Farm.h).
#include <turb/Farm.h>

#include <turb/Error.h>
#include <turb/Metadata.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <string>

namespace turb {

std::vector<TimeChunk> planTimeChunks(size_t frameCount, int chunks, int preroll, int overlap)
{
    if (chunks < 1) throw ValueError("chunks must be at least 1");
    if (preroll < 0 || overlap < 0) throw ValueError("pre-roll and overlap must not be negative");
    // One chunk has no neighbour: its overlap and pre-roll mean nothing.
    if (chunks == 1) overlap = preroll = 0;
    const size_t n = frameCount, O = size_t(overlap), N = size_t(chunks);
    if (n < O + N)
        throw ValueError(std::to_string(n) + " frames cannot hold " + std::to_string(chunks) +
                         " chunks overlapping by " + std::to_string(overlap));
    // Chunk k keeps [b_k, b_{k+1} + O) with b_k spread evenly over [0, n - O]: the last chunk ends at n.
    std::vector<size_t> b(N + 1);
    for (size_t k = 0; k <= N; ++k) b[k] = k * (n - O) / N;
    std::vector<TimeChunk> out;
    for (size_t k = 0; k < N; ++k) {
        // A chunk between two others keeps its two overlaps apart, else three chunks share a frame. The first and the
        // last chunk have one overlap each: they only need a frame of their own.
        const bool middle = k > 0 && k + 1 < N;
        if (b[k + 1] - b[k] < (middle ? std::max<size_t>(O, 1) : 1))
            throw ValueError(std::to_string(n) + " frames in " + std::to_string(chunks) + " chunks give chunks of " +
                             std::to_string(b[k + 1] - b[k] + O) + " frames, fewer than two overlaps of " +
                             std::to_string(overlap) + ": use fewer chunks or a shorter overlap");
        TimeChunk c;
        c.index = int(k);
        c.keepBegin = b[k];
        c.end = b[k + 1] + O;
        c.computeBegin = b[k] > size_t(preroll) ? b[k] - size_t(preroll) : 0;
        out.push_back(c);
    }
    return out;
}

CrossFade crossFade(int j, int overlap)
{
    if (overlap < 1 || j < 0 || j >= overlap)
        throw ValueError("overlap frame " + std::to_string(j) + " of " + std::to_string(overlap));
    CrossFade w;
    w.t = double(j + 1) / double(overlap + 1);
    const double half = 1.5707963267948966 * w.t;
    w.detailA = std::cos(half);
    w.detailB = std::sin(half);
    w.densityA = 1.0 - w.t;
    w.densityB = w.t;
    return w;
}

Frame blendOverlap(const Frame& a, const Frame& b, const VectorField& upTarget, const CrossFade& w,
    float densityThreshold, BlendStats* stats)
{
    if (!a.hasVelocity() || !b.hasVelocity())
        throw ValueError("overlap frame " + std::to_string(b.number) + ": a chunk's frame has no velocity");
    if (a.velocity.bbox() != b.velocity.bbox() || upTarget.bbox() != b.velocity.bbox())
        throw ValueError("overlap frame " + std::to_string(b.number) +
                         ": the chunks' boxes differ (were they made from the same target?)");
    if (!a.velocity.lattice().approxEqual(b.velocity.lattice()))
        throw ValueError("overlap frame " + std::to_string(b.number) + ": the chunks' lattices differ");
    Frame out = b;
    out.metadata.erase(meta::kState);
    out.metadata.erase(meta::kResumeStateFile);
    const bool dens = a.hasDensity() && b.hasDensity() && a.density.bbox() == b.density.bbox();
    if (a.hasDensity() != b.hasDensity() || (a.hasDensity() && !dens))
        throw ValueError("overlap frame " + std::to_string(b.number) + ": the chunks' densities differ in extent");
    const bool sameDensityBox = dens && a.density.bbox() == a.velocity.bbox();
    const auto inSmoke = [&](size_t n) {
        return !sameDensityBox || a.density.data()[n] > densityThreshold || b.density.data()[n] > densityThreshold;
    };
    // First pass: the details' energies and correlation over the smoke.
    double ab = 0.0, aa = 0.0, bb = 0.0;
    size_t smoke = 0;
    for (size_t n = 0; n < out.velocity.size(); ++n) {
        if (!inSmoke(n)) continue;
        const Vec3f up = upTarget.data()[n];
        const Vec3f ha = a.velocity.data()[n] - up, hb = b.velocity.data()[n] - up;
        ++smoke;
        ab += double(ha.dot(hb));
        aa += double(ha.lengthSqr());
        bb += double(hb.lengthSqr());
    }
    // w_a^2 + w_b^2 = 1 keeps the energy of independent details. Two chunks that saw the same target are not quite
    // independent (correlation rho): their blend then has 1 + 2 w_a w_b rho times the interpolated energy (measured
    // +26% at rho 0.3). One factor per frame brings it back; it is 1 for rho = 0.
    const double rho = aa > 0.0 && bb > 0.0 ? ab / std::sqrt(aa * bb) : 0.0;
    const double interpolated = w.detailA * w.detailA * aa + w.detailB * w.detailB * bb;
    const double blended = interpolated + 2.0 * w.detailA * w.detailB * ab;
    const double scale = blended > 0.0 && interpolated > 0.0 ? std::sqrt(interpolated / blended) : 1.0;
    const float wa = float(w.detailA * scale), wb = float(w.detailB * scale);
    double oo = 0.0;
    for (size_t n = 0; n < out.velocity.size(); ++n) {
        const Vec3f up = upTarget.data()[n];
        const Vec3f h = wa * (a.velocity.data()[n] - up) + wb * (b.velocity.data()[n] - up);
        out.velocity.data()[n] = up + h;
        if (inSmoke(n)) oo += double(h.lengthSqr());
    }
    if (dens)
        for (size_t n = 0; n < out.density.size(); ++n)
            out.density.data()[n] = float(w.densityA) * a.density.data()[n] + float(w.densityB) * b.density.data()[n];
    if (stats) {
        stats->smokeVoxels = smoke;
        stats->correlation = rho;
        stats->energyScale = scale;
        stats->energyA = smoke ? aa / double(smoke) : 0.0;
        stats->energyB = smoke ? bb / double(smoke) : 0.0;
        stats->energyOut = smoke ? oo / double(smoke) : 0.0;
    }
    return out;
}

} // namespace turb

namespace turb {

namespace {

// The output-voxel factor per axis (refineDomain's: a flat box keeps its one z layer).
Coord factorsOf(const CoordBBox& box, int ratio) { return domainFactors(box, ratio); }

// A tile's weight factor along one axis at output-voxel centre c: a linear ramp `ramp` output voxels wide, centred
// on each border of its core [lo, hi] (target voxels, F output voxels each) that has a neighbour.
double rampFactor(double c, int lo, int hi, bool lowerNeighbour, bool upperNeighbour, int F, int ramp)
{
    const double r = double(ramp), half = 0.5 * double(ramp);
    double w = 1.0;
    if (lowerNeighbour) w *= std::clamp((c - (double(lo) * F - half)) / r, 0.0, 1.0);
    if (upperNeighbour) w *= std::clamp(((double(hi + 1) * F + half) - c) / r, 0.0, 1.0);
    return w;
}

// `text` as integers separated by `sep`; throws ValueError("<what> '<text>': ...") naming a piece that is not one.
std::vector<int> parseIndices(const std::string& text, char sep, const std::string& what)
{
    std::vector<int> out;
    size_t p = 0;
    while (p <= text.size()) {
        const size_t end = std::min(text.find(sep, p), text.size());
        const std::string num = text.substr(p, end - p);
        size_t used = 0;
        int v = 0;
        try {
            v = std::stoi(num, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (num.empty() || used != num.size())
            throw ValueError(what + " '" + text + "': '" + num + "' is not a voxel index");
        out.push_back(v);
        p = end + 1;
    }
    return out;
}

void requireSame(const std::vector<Frame>& tiles, const char* what, bool (*has)(const Frame&))
{
    const bool first = has(tiles.front());
    for (size_t k = 1; k < tiles.size(); ++k)
        if (has(tiles[k]) != first)
            throw ValueError(std::string("tile ") + std::to_string(k) + " " + (first ? "has no " : "has a ") + what +
                             " where tile 0 " + (first ? "has one" : "has none") + " (frame " +
                             std::to_string(tiles[k].number) + ")");
}

} // namespace

TilePlan planSpaceTiles(const CoordBBox& box, const Coord& counts, int halo, int align)
{
    if (box.empty()) throw ValueError("space tiles: the box to split is empty");
    if (halo < 0) throw ValueError("space tiles: the halo must not be negative");
    if (align < 1) throw ValueError("space tiles: the alignment must be at least 1");
    for (int a = 0; a < 3; ++a)
        if (counts[a] < 1) throw ValueError("space tiles: at least one tile per axis");
    if (isFlat(box) && counts.z() != 1) throw ValueError("space tiles: a 2D (one-layer) box cannot be split in z");
    TilePlan plan;
    plan.box = box;
    plan.counts = counts;
    plan.halo = halo;
    // Per axis the borders b_0 = min < b_1 < ... < b_n = max + 1, the inner ones on absolute multiples of `align`.
    std::array<std::vector<int>, 3> borders;
    for (int a = 0; a < 3; ++a) {
        const int lo = box.min()[a], len = box.dim()[a], n = counts[a];
        borders[a].push_back(lo);
        for (int k = 1; k < n; ++k) {
            const double raw = lo + double(k) * len / n;
            borders[a].push_back(int(std::lround(raw / align)) * align);
        }
        borders[a].push_back(lo + len);
        for (int k = 0; k < n; ++k) {
            const int width = borders[a][size_t(k) + 1] - borders[a][size_t(k)];
            if (width < 1 || (n > 1 && width < halo))
                throw ValueError("space tiles: " + std::to_string(n) + " tiles along " + "xyz"[a] + " over " +
                                 std::to_string(len) + " voxels give a tile " + std::to_string(width) +
                                 " voxels wide, narrower than the halo of " + std::to_string(halo) +
                                 ": use fewer tiles or a smaller halo");
        }
    }
    for (int k = 0; k < counts.z(); ++k)
        for (int j = 0; j < counts.y(); ++j)
            for (int i = 0; i < counts.x(); ++i) {
                SpaceTile t;
                t.index = int(plan.tiles.size());
                t.cell = Coord(i, j, k);
                const Coord c = t.cell;
                t.core =
                    CoordBBox(Coord(borders[0][size_t(c.x())], borders[1][size_t(c.y())], borders[2][size_t(c.z())]),
                        Coord(borders[0][size_t(c.x()) + 1] - 1, borders[1][size_t(c.y()) + 1] - 1,
                            borders[2][size_t(c.z()) + 1] - 1));
                t.held = t.core;
                t.held.expand(halo);
                t.held.intersect(box);
                plan.tiles.push_back(t);
            }
    return plan;
}

double TilePlan::weight(size_t k, const Coord& v, int ratio, int ramp) const
{
    const SpaceTile& t = tiles.at(k);
    const Coord F = factorsOf(box, ratio);
    double w = 1.0;
    for (int a = 0; a < 3 && w > 0.0; ++a)
        w *= rampFactor(double(v[a]) + 0.5, t.core.min()[a], t.core.max()[a], t.core.min()[a] > box.min()[a],
            t.core.max()[a] < box.max()[a], F[a], ramp);
    return w;
}

void checkTileRamp(const TilePlan& plan, int ratio, int ramp)
{
    if (plan.tiles.size() < 2) return;
    const Coord F = factorsOf(plan.box, ratio);
    int narrowest = std::numeric_limits<int>::max(), haloOut = std::numeric_limits<int>::max();
    for (int a = 0; a < 3; ++a)
        if (plan.counts[a] > 1) {
            haloOut = std::min(haloOut, plan.halo * F[a]);
            for (const SpaceTile& t : plan.tiles) narrowest = std::min(narrowest, t.core.dim()[a] * F[a]);
        }
    if (ramp < 1 || ramp > narrowest || ramp > 2 * haloOut)
        throw ValueError("a tile ramp of " + std::to_string(ramp) + " output voxels must be at least 1, at most the " +
                         "narrowest tile (" + std::to_string(narrowest) + ") and at most twice the halo (" +
                         std::to_string(2 * haloOut) + ")");
}

std::string formatTileBox(const CoordBBox& b)
{
    return std::to_string(b.min().x()) + "," + std::to_string(b.min().y()) + "," + std::to_string(b.min().z()) + "," +
           std::to_string(b.max().x()) + "," + std::to_string(b.max().y()) + "," + std::to_string(b.max().z());
}

CoordBBox parseTileBox(const std::string& text)
{
    const std::vector<int> v = parseIndices(text, ',', "tile box");
    if (v.size() != 6 || v[0] > v[3] || v[1] > v[4] || v[2] > v[5])
        throw ValueError("tile box '" + text + "': expected X0,Y0,Z0,X1,Y1,Z1 with X0<=X1, Y0<=Y1, Z0<=Z1");
    return CoordBBox(Coord(v[0], v[1], v[2]), Coord(v[3], v[4], v[5]));
}

std::vector<TileBorder> tileBorders(const TilePlan& plan, int ratio)
{
    const Coord F = factorsOf(plan.box, ratio);
    std::vector<TileBorder> out;
    for (int a = 0; a < 3; ++a) {
        std::vector<int> planes;
        for (const SpaceTile& t : plan.tiles)
            if (t.core.min()[a] > plan.box.min()[a]) planes.push_back(t.core.min()[a] * F[a]);
        std::sort(planes.begin(), planes.end());
        planes.erase(std::unique(planes.begin(), planes.end()), planes.end());
        for (int p : planes) out.push_back({a, p});
    }
    return out;
}

std::string formatTileBorders(const std::vector<TileBorder>& borders)
{
    std::string s;
    int axis = -1;
    for (const TileBorder& b : borders) {
        if (b.axis != axis) {
            if (!s.empty()) s += ';';
            s += std::string(1, "xyz"[b.axis]) + ":";
            axis = b.axis;
        } else {
            s += ',';
        }
        s += std::to_string(b.plane);
    }
    return s;
}

std::vector<TileBorder> parseTileBorders(const std::string& text)
{
    std::vector<TileBorder> out;
    const auto bad = [&](const std::string& why) {
        return ValueError("tile borders '" + text + "': " + why + " (expected e.g. x:64,128;y:64)");
    };
    size_t pos = 0;
    while (pos < text.size()) {
        const size_t end = std::min(text.find(';', pos), text.size());
        const std::string part = text.substr(pos, end - pos);
        pos = end + 1;
        if (part.empty()) continue;
        if (part.size() < 3 || part[1] != ':' || std::string("xyz").find(part[0]) == std::string::npos)
            throw bad("'" + part + "' does not start with x:, y: or z:");
        const int axis = int(std::string("xyz").find(part[0]));
        for (int v : parseIndices(part.substr(2), ',', "tile borders")) out.push_back({axis, v});
    }
    std::sort(out.begin(), out.end(), [](const TileBorder& a, const TileBorder& b) {
        return a.axis != b.axis ? a.axis < b.axis : a.plane < b.plane;
    });
    return out;
}

namespace {

// One tile's factor along one axis at one output coordinate: the tile's cell along the axis and its weight (> 0).
struct AxisWeight
{
    int cell = 0;
    double w = 0.0;
};

// For each output coordinate of `box` along axis `a`, the cells whose weight there is not zero (at most two, as the
// ramps are no wider than a core): TilePlan::weight factors per axis, so a voxel's tiles are the products.
std::vector<std::vector<AxisWeight>> axisWeights(const TilePlan& plan, int a, int ratio, int ramp, const CoordBBox& box)
{
    const Coord F = factorsOf(plan.box, ratio);
    const int n = plan.counts[a];
    std::vector<int> lo(static_cast<size_t>(n)),
        hi(static_cast<size_t>(n)); // each cell's core along the axis, in target voxels
    for (const SpaceTile& t : plan.tiles) {
        lo[size_t(t.cell[a])] = t.core.min()[a];
        hi[size_t(t.cell[a])] = t.core.max()[a];
    }
    std::vector<std::vector<AxisWeight>> out(size_t(box.dim()[a]));
    for (int x = box.min()[a]; x <= box.max()[a]; ++x)
        for (int i = 0; i < n; ++i) {
            const double w = rampFactor(double(x) + 0.5, lo[size_t(i)], hi[size_t(i)], i > 0, i + 1 < n, F[a], ramp);
            if (w > 0.0) out[size_t(x - box.min()[a])].push_back({i, w});
        }
    return out;
}

// Per pair of tiles (k < l): the dot product and energies of their details over the smoke they share.
struct PairSums
{
    double dot = 0.0, aa = 0.0, bb = 0.0;
    double rho() const { return aa > 0.0 && bb > 0.0 ? std::clamp(dot / std::sqrt(aa * bb), -1.0, 1.0) : 0.0; }
};

using PairMap = std::map<std::pair<size_t, size_t>, PairSums>;

// A tile with weight at an output voxel, as (tile index, linear weight lambda); lambda sums to 1 over the tiles.
struct Share
{
    size_t k;
    double lambda;
};

// Throws unless the tiles can be joined: one per planned tile, the same fields in each, on one lattice.
void checkTileFrames(const std::vector<Frame>& tiles, const TilePlan& plan, int ratio, int ramp)
{
    if (tiles.size() != plan.tiles.size() || tiles.empty())
        throw ValueError("tile join: " + std::to_string(tiles.size()) + " frames for " +
                         std::to_string(plan.tiles.size()) + " tiles");
    if (ratio < 1) throw ValueError("tile join: ratio must be at least 1");
    checkTileRamp(plan, ratio, ramp);
    const Frame& first = tiles.front();
    requireSame(tiles, "velocity", [](const Frame& f) { return f.hasVelocity(); });
    requireSame(tiles, "density", [](const Frame& f) { return f.hasDensity(); });
    requireSame(tiles, "temperature", [](const Frame& f) { return bool(f.temperature); });
    requireSame(tiles, "flame", [](const Frame& f) { return bool(f.flame); });
    for (size_t k = 1; k < tiles.size(); ++k)
        if (!tiles[k].lattice().approxEqual(first.lattice()))
            throw ValueError("tile join: tile " + std::to_string(k) + "'s lattice differs from tile 0's (frame " +
                             std::to_string(first.number) + ")");
}

// The joined frame before blending: tile 0's header and zero fields over the whole output box.
Frame emptyJoinedFrame(const Frame& first, const CoordBBox& box)
{
    const Lattice& lattice = first.lattice();
    Frame out;
    out.number = first.number;
    out.dt = first.dt;
    out.timeUnit = first.timeUnit;
    out.metadata = first.metadata;
    out.metadata.erase(meta::kState);
    out.metadata.erase(meta::kResumeStateFile);
    out.metadata.erase(meta::kTileBox); // tile 0's: the joined frame covers the whole box
    if (first.hasVelocity()) out.velocity = VectorField(box, lattice);
    if (first.hasDensity()) out.density = ScalarField(box, lattice);
    if (first.temperature) out.temperature = ScalarField(box, lattice);
    if (first.flame) out.flame = ScalarField(box, lattice);
    return out;
}

// What both blending passes read at an output voxel: which tiles have weight there, and each tile's detail split
// into its coarse-cell means c_k and the rest f_k.
struct TileJoin
{
    const std::vector<Frame>& tiles;
    const VectorField& upTarget;
    CoordBBox box;                                            // the output box
    Coord n, F;                                               // tiles per axis; output voxels per target voxel
    std::array<std::vector<std::vector<AxisWeight>>, 3> axes; // axisWeights along x, y and z
    bool vel = false, detail = false;                         // velocity at all; its detail blended apart
    std::vector<Field<Vec3f>> means;                          // per tile: c_k on the target's cells (with `detail`)

    // The tiles with weight at v.
    void shares(const Coord& v, std::vector<Share>& sh) const
    {
        sh.clear();
        const Coord o = v - box.min();
        for (const AxisWeight& x : axes[0][size_t(o.x())])
            for (const AxisWeight& y : axes[1][size_t(o.y())])
                for (const AxisWeight& z : axes[2][size_t(o.z())])
                    sh.push_back({size_t(x.cell + n.x() * (y.cell + n.y() * z.cell)), x.w * y.w * z.w});
    }
    template<typename FieldT>
    void require(const FieldT& field, const Coord& v, size_t k, const char* what) const
    {
        if (!field.contains(v))
            throw ValueError("tile join: tile " + std::to_string(k) + "'s " + what + " does not cover output voxel (" +
                             std::to_string(v.x()) + "," + std::to_string(v.y()) + "," + std::to_string(v.z()) +
                             ") where its weight is not zero (frame " + std::to_string(tiles[k].number) + ")");
    }
    Coord cellOf(const Coord& v) const
    {
        return Coord(floorDiv(v.x(), F.x()), floorDiv(v.y(), F.y()), floorDiv(v.z(), F.z()));
    }
    // f_k at v: tile k's detail less its coarse-cell mean.
    Vec3f fineDetail(size_t k, const Coord& v, const Vec3f& up) const
    {
        return tiles[k].velocity[v] - up - means[k][cellOf(v)];
    }
};

// Each tile's detail splits into its coarse-cell means c_k (the coarse motion it adds, which lf_err measures) and
// the rest, f_k. The means are motion, like density: they are blended linearly, so the joined coarse means are
// the tiles' interpolated. Only f_k, the random-phase part, takes the energy-preserving weights.
std::vector<Field<Vec3f>> coarseDetailMeans(const TileJoin& j, const TilePlan& plan, int ratio)
{
    std::vector<Field<Vec3f>> means(j.tiles.size());
    for (size_t k = 0; k < j.tiles.size(); ++k) {
        CoordBBox reach = refineDomain(plan.tiles[k].held, ratio);
        reach.intersect(j.box);
        reach.intersect(j.tiles[k].velocity.bbox());
        Field<Vec3f> sum(CoordBBox(j.cellOf(reach.min()), j.cellOf(reach.max())), Lattice{}, Vec3f(0.0f));
        Field<float> count(sum.bbox(), Lattice{}, 0.0f);
        for (auto it = reach.beginXYZ(); it; ++it) {
            const Coord c = j.cellOf(*it);
            sum[c] += j.tiles[k].velocity[*it] - j.upTarget[*it];
            count[c] += 1.0f;
        }
        for (size_t n = 0; n < sum.size(); ++n)
            if (count.data()[n] > 0.0f) sum.data()[n] /= count.data()[n];
        means[k] = std::move(sum);
    }
    return means;
}

// Adds the lambda-weighted tiles' fields at v (output offset o) to `out`; returns the densest tile's density there.
float addWeightedTiles(const TileJoin& j, const Coord& v, size_t o, const std::vector<Share>& sh, Frame& out)
{
    float dmax = 0.0f;
    for (const Share& s : sh) {
        const Frame& t = j.tiles[s.k];
        const float w = float(s.lambda);
        if (j.vel) {
            j.require(t.velocity, v, s.k, "velocity");
            if (!j.detail || sh.size() == 1) out.velocity.data()[o] += w * t.velocity[v];
        }
        if (t.hasDensity()) {
            j.require(t.density, v, s.k, "density");
            out.density.data()[o] += w * t.density[v];
            dmax = std::max(dmax, t.density[v]);
        }
        if (t.temperature) {
            j.require(*t.temperature, v, s.k, "temperature");
            out.temperature->data()[o] += w * (*t.temperature)[v];
        }
        if (t.flame) {
            j.require(*t.flame, v, s.k, "flame");
            out.flame->data()[o] += w * (*t.flame)[v];
        }
    }
    return dmax;
}

// Pass 1: density, temperature and flame (and velocity where one tile owns the voxel, or without up(u_t)) are
// the lambda-weighted sums: weights that sum to 1 keep the smoke's mass and agree with tiles that agree. Where
// tiles share a voxel, their details' correlation is summed per pair of tiles.
PairMap blendLinear(const TileJoin& j, Frame& out, float densityThreshold)
{
    const bool density = j.tiles.front().hasDensity();
    PairMap pairs;
    std::vector<Share> sh;
    for (auto it = j.box.beginXYZ(); it; ++it) {
        const Coord v = *it;
        j.shares(v, sh);
        const size_t o =
            out.velocity.empty() ? out.density.offset(v.x(), v.y(), v.z()) : out.velocity.offset(v.x(), v.y(), v.z());
        const float dmax = addWeightedTiles(j, v, o, sh, out);
        if (!j.detail || sh.size() < 2 || (density && !(dmax > densityThreshold))) continue;
        const Vec3f up = j.upTarget[v];
        for (size_t a = 0; a < sh.size(); ++a)
            for (size_t b = a + 1; b < sh.size(); ++b) {
                const Vec3f ha = j.fineDetail(sh[a].k, v, up), hb = j.fineDetail(sh[b].k, v, up);
                PairSums& p = pairs[std::minmax(sh[a].k, sh[b].k)];
                p.dot += double(ha.dot(hb));
                p.aa += double(sh[a].k < sh[b].k ? ha.lengthSqr() : hb.lengthSqr());
                p.bb += double(sh[a].k < sh[b].k ? hb.lengthSqr() : ha.lengthSqr());
            }
    }
    return pairs;
}

// U at a voxel that tiles share: up(u_t) + sum_k lambda_k c_k + s sum_k sqrt(lambda_k) f_k (see blendDetail).
Vec3f energyPreservingBlend(
    const TileJoin& j, const Coord& v, const Vec3f& up, const std::vector<Share>& sh, const PairMap& pairs)
{
    double cross = 0.0;
    for (size_t a = 0; a < sh.size(); ++a)
        for (size_t b = a + 1; b < sh.size(); ++b) {
            const auto p = pairs.find(std::minmax(sh[a].k, sh[b].k));
            if (p != pairs.end()) cross += 2.0 * std::sqrt(sh[a].lambda * sh[b].lambda) * p->second.rho();
        }
    const float scale = float(1.0 / std::sqrt(std::max(1.0 + cross, 1e-6)));
    Vec3f coarse(0.0f), fine(0.0f);
    for (const Share& s : sh) {
        coarse += float(s.lambda) * j.means[s.k][j.cellOf(v)];
        fine += float(std::sqrt(s.lambda)) * j.fineDetail(s.k, v, up);
    }
    return up + coarse + scale * fine;
}

// The seam's sums for TileJoinStats::disagreement: the tiles' spread around the blend, and the detail's energy.
struct SeamSums
{
    double spread = 0.0, detail = 0.0;
    size_t voxels = 0;
};

// Pass 2, where tiles share a voxel: U = up(u_t) + sum_k lambda_k c_k + s sum_k sqrt(lambda_k) f_k. sum_k lambda_k
// = 1, so independent f_k keep their energy (a linear fade would lose up to half of it mid-ramp); with pair
// correlations rho_kl the sum has 1 + sum_{k != l} sqrt(lambda_k lambda_l) rho_kl times that energy, and s undoes
// it (s = 1 / sum_k sqrt(lambda_k) for tiles that agree exactly: the blend is then their common detail).
SeamSums blendDetail(const TileJoin& j, const PairMap& pairs, float densityThreshold, Frame& out)
{
    const bool density = j.tiles.front().hasDensity();
    SeamSums seam;
    std::vector<Share> sh;
    for (auto it = j.box.beginXYZ(); it; ++it) {
        const Coord v = *it;
        j.shares(v, sh);
        if (sh.size() < 2) continue;
        const size_t o = out.velocity.offset(v.x(), v.y(), v.z());
        const Vec3f up = j.detail ? j.upTarget[v] : Vec3f(0.0f);
        if (j.detail) out.velocity.data()[o] = energyPreservingBlend(j, v, up, sh, pairs);
        if (density && !(out.density.data()[o] > densityThreshold)) continue;
        // The tiles' spread around the blend, over the detail's energy.
        for (const Share& s : sh)
            seam.spread += s.lambda * double((j.tiles[s.k].velocity[v] - out.velocity.data()[o]).lengthSqr());
        seam.detail += double((out.velocity.data()[o] - up).lengthSqr());
        ++seam.voxels;
    }
    return seam;
}

// TileJoinStats from the seam's sums and the pairs' correlations (all pairs pooled, and the lowest pair's).
void recordJoinStats(const SeamSums& seam, const PairMap& pairs, TileJoinStats& stats)
{
    stats.seamVoxels = seam.voxels;
    stats.disagreement = seam.detail > 0.0 ? std::sqrt(seam.spread / seam.detail) : 0.0;
    PairSums all;
    stats.minCorrelation = 1.0;
    for (const auto& [key, p] : pairs) {
        all.dot += p.dot;
        all.aa += p.aa;
        all.bb += p.bb;
        stats.minCorrelation = std::min(stats.minCorrelation, p.rho());
    }
    stats.correlation = pairs.empty() ? 1.0 : all.rho();
    if (pairs.empty()) stats.minCorrelation = 1.0;
}

} // namespace

Frame joinTiles(const std::vector<Frame>& tiles, const TilePlan& plan, int ratio, int ramp, float densityThreshold,
    const VectorField& upTarget, TileJoinStats* stats)
{
    checkTileFrames(tiles, plan, ratio, ramp);
    const Frame& first = tiles.front();
    const CoordBBox box = refineDomain(plan.box, ratio);
    Frame out = emptyJoinedFrame(first, box);
    const bool vel = first.hasVelocity();
    const bool detail = vel && !upTarget.empty() && upTarget.bbox().isInside(box);
    TileJoin j{tiles, upTarget, box, plan.counts, factorsOf(plan.box, ratio),
        {axisWeights(plan, 0, ratio, ramp, box), axisWeights(plan, 1, ratio, ramp, box),
            axisWeights(plan, 2, ratio, ramp, box)},
        vel, detail, {}};
    if (j.detail) j.means = coarseDetailMeans(j, plan, ratio);

    const PairMap pairs = blendLinear(j, out, densityThreshold);
    const SeamSums seam = j.vel ? blendDetail(j, pairs, densityThreshold, out) : SeamSums{};
    if (stats) recordJoinStats(seam, pairs, *stats);
    return out;
}

} // namespace turb
