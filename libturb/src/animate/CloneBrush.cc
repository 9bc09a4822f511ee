#include <turb/CloneBrush.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

namespace turb {

namespace {

double polylineLength(const std::vector<StrokePoint>& pts)
{
    double L = 0.0;
    for (size_t i = 1; i < pts.size(); ++i) L += std::hypot(pts[i].x - pts[i - 1].x, pts[i].y - pts[i - 1].y);
    return L;
}

/// The point at arc length t (0..length) along the polyline.
StrokePoint pointAt(const std::vector<StrokePoint>& pts, double t)
{
    for (size_t i = 1; i < pts.size(); ++i) {
        const double len = std::hypot(pts[i].x - pts[i - 1].x, pts[i].y - pts[i - 1].y);
        if (t <= len || i + 1 == pts.size()) {
            const double u = len > 0.0 ? std::clamp(t / len, 0.0, 1.0) : 0.0;
            return {pts[i - 1].x + u * (pts[i].x - pts[i - 1].x), pts[i - 1].y + u * (pts[i].y - pts[i - 1].y)};
        }
        t -= len;
    }
    return pts.back();
}

void checkSide(const std::vector<StrokePoint>& pts, int W, int H, const std::string& who, const char* image)
{
    if (pts.size() < 2) throw ValueError(who + " needs at least 2 points");
    if (!(polylineLength(pts) > 0.0)) throw ValueError(who + ": all its points are equal (no direction)");
    for (const StrokePoint& p : pts)
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || p.x < -0.5 || p.y < -0.5 || p.x > W - 0.5 || p.y > H - 0.5)
            throw ValueError(who + ": point (" + std::to_string(p.x) + ", " + std::to_string(p.y) +
                             ") lies outside the " + std::to_string(W) + "x" + std::to_string(H) + " " + image);
}

void validate(const CloneSettings& s)
{
    if (!(s.sampleSpacing > 0.0) || !std::isfinite(s.sampleSpacing))
        throw ValueError("clone brush: the control point spacing must be > 0 pixels");
    if (s.maxSamples < 2) throw ValueError("clone brush: at least 2 control points per stroke pair");
}

/// Squared distance from (x, y) to the polyline.
double distance2(const std::vector<StrokePoint>& pts, double x, double y)
{
    double d2 = 1e300;
    for (size_t i = 1; i < pts.size(); ++i) {
        const StrokePoint a = pts[i - 1], b = pts[i];
        const double ex = b.x - a.x, ey = b.y - a.y, l2 = ex * ex + ey * ey;
        const double t = l2 > 0.0 ? std::clamp(((x - a.x) * ex + (y - a.y) * ey) / l2, 0.0, 1.0) : 0.0;
        const double dx = x - (a.x + t * ex), dy = y - (a.y + t * ey);
        d2 = std::min(d2, dx * dx + dy * dy);
    }
    return d2;
}

/// Up to 8 taps of one pixel: the map's own (scaled by 1 - m) and the clone's bilinear ones (scaled by m).
struct PixelTaps
{
    std::array<std::uint32_t, 8> src{};
    std::array<float, 8> w{};
    int n = 0;
    void add(std::uint32_t s, float weight)
    {
        if (!(weight > 0.0f)) return;
        for (int k = 0; k < n; ++k)
            if (src[size_t(k)] == s) {
                w[size_t(k)] += weight;
                return;
            }
        src[size_t(n)] = s;
        w[size_t(n++)] = weight;
    }
    /// Back into the map: the heaviest kTaps (ties by source index: deterministic), rescaled to the same total.
    void store(TransferMap& map, size_t i)
    {
        std::array<int, 8> order{};
        for (int k = 0; k < n; ++k) order[size_t(k)] = k;
        std::sort(order.begin(), order.begin() + n, [&](int a, int b) {
            return w[size_t(a)] != w[size_t(b)] ? w[size_t(a)] > w[size_t(b)] : src[size_t(a)] < src[size_t(b)];
        });
        const int kept = std::min(n, TransferMap::kTaps);
        float total = 0.0f, keptTotal = 0.0f;
        for (int k = 0; k < n; ++k) total += w[size_t(k)];
        for (int k = 0; k < kept; ++k) keptTotal += w[size_t(order[size_t(k)])];
        map.clearTaps(i);
        for (int k = 0; k < kept; ++k)
            map.addTap(i, src[size_t(order[size_t(k)])], w[size_t(order[size_t(k)])] * total / keptTotal);
    }
};

/// The bilinear taps of example position p (pixel centres at integers), false when p lies more than half a pixel
/// outside the example.
bool bilinearTaps(StrokePoint p, int EW, int EH, std::array<std::uint32_t, 4>& src, std::array<float, 4>& w)
{
    if (p.x < -0.5 || p.y < -0.5 || p.x > EW - 0.5 || p.y > EH - 0.5) return false;
    const double x = std::clamp(p.x, 0.0, double(EW - 1)), y = std::clamp(p.y, 0.0, double(EH - 1));
    const int x0 = std::min(int(std::floor(x)), EW - 1), y0 = std::min(int(std::floor(y)), EH - 1);
    const int x1 = std::min(x0 + 1, EW - 1), y1 = std::min(y0 + 1, EH - 1);
    const float fx = float(x - x0), fy = float(y - y0);
    const auto at = [EW](int xx, int yy) { return std::uint32_t(size_t(yy) * size_t(EW) + size_t(xx)); };
    src = {at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1)};
    w = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
    return true;
}

/// One stroke pair over the map; adds its matte into `total` (the clones' share at each pixel, composited in order).
void applyOne(
    TransferMap& map, const CloneStroke& c, const ChannelImage* matte, const CloneSettings& s, ChannelImage& total)
{
    const CloneDeformation f(c, s);
    const int W = map.width(), H = map.height(), EW = map.exampleWidth(), EH = map.exampleHeight();
    double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
    for (const StrokePoint& p : c.destination) {
        x0 = std::min(x0, p.x - c.size);
        y0 = std::min(y0, p.y - c.size);
        x1 = std::max(x1, p.x + c.size);
        y1 = std::max(y1, p.y + c.size);
    }
    const int bx0 = std::max(0, int(std::floor(x0))), by0 = std::max(0, int(std::floor(y0)));
    const int bx1 = std::min(W - 1, int(std::ceil(x1))), by1 = std::min(H - 1, int(std::ceil(y1)));
    if (bx0 > bx1 || by0 > by1) return;
    // Rows are independent and each pixel's result depends on nothing else: the same at any thread count.
    parallelFor(size_t(by1 - by0 + 1), 4, [&](size_t b, size_t e) {
        std::array<std::uint32_t, 4> src{};
        std::array<float, 4> bw{};
        for (int y = by0 + int(b); y < by0 + int(e); ++y)
            for (int x = bx0; x <= bx1; ++x) {
                const size_t i = size_t(y) * size_t(W) + size_t(x);
                const float m = float(cloneMatte(c, x, y));
                if (!(m > 0.0f) || (matte && !(matte->pixel(i)[0] > 0.0f))) continue;
                if (!bilinearTaps(f(x, y), EW, EH, src, bw)) continue;
                PixelTaps taps;
                for (int k = 0; k < TransferMap::kTaps; ++k) taps.add(map.source(i, k), (1.0f - m) * map.weight(i, k));
                for (int k = 0; k < 4; ++k) taps.add(src[size_t(k)], m * bw[size_t(k)]);
                taps.store(map, i);
                float& t = total.pixel(i)[0];
                t = m + (1.0f - m) * t;
            }
    });
}

} // namespace

void validateCloneStrokes(
    const std::vector<CloneStroke>& strokes, int EW, int EH, int TW, int TH, const CloneSettings& settings)
{
    validate(settings);
    for (size_t k = 0; k < strokes.size(); ++k) {
        const CloneStroke& c = strokes[k];
        const std::string who = "clone stroke " + std::to_string(k);
        checkSide(c.source, EW, EH, who + " (source)", "example");
        checkSide(c.destination, TW, TH, who + " (destination)", "target");
        if (!(c.size > 0.0) || !std::isfinite(c.size)) throw ValueError(who + ": the size must be > 0 pixels");
        if (!(c.alpha >= 0.0 && c.alpha <= 1.0)) throw ValueError(who + ": alpha must be in [0, 1]");
    }
}

CloneDeformation::CloneDeformation(const CloneStroke& c, const CloneSettings& s)
{
    validate(s);
    if (c.source.size() < 2 || c.destination.size() < 2 || !(polylineLength(c.source) > 0.0) ||
        !(polylineLength(c.destination) > 0.0))
        throw ValueError("clone stroke: both strokes need at least 2 points, not all equal");
    // Both strokes at the same fractions of their arc length: vertex-free, so strokes drawn with different numbers
    // of points still correspond from end to end.
    const double Ls = polylineLength(c.source), Ld = polylineLength(c.destination);
    const int n = std::clamp(int(std::ceil(std::max(Ls, Ld) / s.sampleSpacing)) + 1, 2, s.maxSamples);
    for (int j = 0; j < n; ++j) {
        const double u = double(j) / double(n - 1);
        mP.push_back(pointAt(c.destination, u * Ld));
        mQ.push_back(pointAt(c.source, u * Ls));
    }
}

StrokePoint CloneDeformation::operator()(double x, double y) const
{
    // Weighted centroids and the weighted Procrustes rotation (Schaefer et al. 2006, rigid, alpha = 1).
    const auto weight = [&](size_t j) { return 1.0 / ((mP[j].x - x) * (mP[j].x - x) + (mP[j].y - y) * (mP[j].y - y)); };
    double sw = 0.0, px = 0.0, py = 0.0, qx = 0.0, qy = 0.0;
    for (size_t j = 0; j < mP.size(); ++j) {
        if (std::hypot(mP[j].x - x, mP[j].y - y) < 1e-6) return mQ[j]; // on a control point: its constraint
        const double w = weight(j);
        sw += w;
        px += w * mP[j].x;
        py += w * mP[j].y;
        qx += w * mQ[j].x;
        qy += w * mQ[j].y;
    }
    px /= sw;
    py /= sw;
    qx /= sw;
    qy /= sw;
    double a = 0.0, b = 0.0; // sum w (p^ . q^), sum w (p^ x q^)
    for (size_t j = 0; j < mP.size(); ++j) {
        const double w = weight(j), ux = mP[j].x - px, uy = mP[j].y - py, vx = mQ[j].x - qx, vy = mQ[j].y - qy;
        a += w * (ux * vx + uy * vy);
        b += w * (ux * vy - uy * vx);
    }
    const double r = std::hypot(a, b), c = r > 0.0 ? a / r : 1.0, s = r > 0.0 ? b / r : 0.0;
    const double dx = x - px, dy = y - py;
    return {qx + c * dx - s * dy, qy + s * dx + c * dy};
}

double cloneMatte(const CloneStroke& c, double x, double y)
{
    const double d = std::sqrt(distance2(c.destination, x, y)), r0 = 0.5 * c.size;
    if (d <= r0) return c.alpha;
    if (d >= c.size) return 0.0;
    const double t = (d - r0) / (c.size - r0);
    return c.alpha * (1.0 - t * t * (3.0 - 2.0 * t));
}

ChannelImage applyCloneStrokes(
    TransferMap& map, const std::vector<CloneStroke>& strokes, const ChannelImage* matte, const CloneSettings& s)
{
    validateCloneStrokes(strokes, map.exampleWidth(), map.exampleHeight(), map.width(), map.height(), s);
    if (matte && (matte->width() != map.width() || matte->height() != map.height() || matte->channels() != 1))
        throw ValueError("applyCloneStrokes: the matte must be a 1-channel image of the target's size");
    ChannelImage total(map.width(), map.height(), 1);
    for (const CloneStroke& c : strokes) applyOne(map, c, matte, s, total);
    size_t n = 0;
    for (float v : total.data()) n += v > 0.0f;
    map.stats.cloned = total.data().empty() ? 0.0 : double(n) / double(total.data().size());
    return total;
}

} // namespace turb
