#include <turb/Plot.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace turb {

namespace {

const Rgb kText(0.1f), kAxis(0.25f), kGrid(0.9f), kMinorGrid(0.95f), kWhite(1.0f);

bool usable(double v, bool log) { return std::isfinite(v) && (!log || v > 0.0); }

struct Axis
{
    double lo = 0.0, hi = 1.0;
    bool log = false;
    std::vector<double> major, minor;
    std::vector<std::string> labels;

    double t(double v) const { return log ? std::log10(v) : v; }
    double frac(double v) const { return (t(v) - t(lo)) / (t(hi) - t(lo)); }
};

std::string formatLinear(double v, double step)
{
    if (std::abs(v) < step * 1e-6) v = 0.0;
    char buf[32];
    const double mag = std::max(std::abs(v), step);
    if (mag >= 1e5 || step < 1e-4) std::snprintf(buf, sizeof(buf), "%.3g", v);
    else {
        const int decimals = std::max(0, int(std::ceil(-std::log10(step) - 1e-9)));
        std::snprintf(buf, sizeof(buf), "%.*f", decimals, v);
    }
    return buf;
}

std::string formatDecade(int e)
{
    char buf[32];
    if (e >= -2 && e <= 3) std::snprintf(buf, sizeof(buf), "%g", std::pow(10.0, e));
    else std::snprintf(buf, sizeof(buf), "1e%d", e);
    return buf;
}

Axis makeAxis(const std::vector<double>& values, bool log, double fixedLo, double fixedHi)
{
    Axis a;
    a.log = log;
    double lo = HUGE_VAL, hi = -HUGE_VAL;
    for (double v : values)
        if (usable(v, log)) {
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
    if (lo > hi) { // no data
        lo = log ? 1.0 : 0.0;
        hi = log ? 10.0 : 1.0;
    }
    if (usable(fixedLo, log)) lo = fixedLo;
    if (usable(fixedHi, log)) hi = fixedHi;
    if (log) {
        // Snap the ends to 1, 2 or 5 x 10^n: whole decades would waste up to 90% of the axis.
        const auto snapDown = [](double v) {
            const double d = std::pow(10.0, std::floor(std::log10(v) + 1e-9));
            for (double m : {5.0, 2.0, 1.0})
                if (m * d <= v * (1 + 1e-9)) return m * d;
            return d;
        };
        const auto snapUp = [](double v) {
            const double d = std::pow(10.0, std::floor(std::log10(v) - 1e-9));
            for (double m : {1.0, 2.0, 5.0, 10.0})
                if (m * d >= v * (1 - 1e-9)) return m * d;
            return 10.0 * d;
        };
        if (!usable(fixedLo, log)) lo = snapDown(lo);
        if (!usable(fixedHi, log)) hi = snapUp(hi);
        if (hi <= lo) hi = lo * 10.0;
        const int e0 = int(std::floor(std::log10(lo) + 1e-9)), e1 = int(std::ceil(std::log10(hi) - 1e-9));
        const int every = std::max(1, (e1 - e0 + 7) / 8); // at most about 8 labelled decades
        const bool fewDecades = std::log10(hi / lo) < 1.5;  // then label 2 and 5 too
        for (int e = e0; e <= e1; ++e) {
            const double v = std::pow(10.0, e);
            for (int m = 1; m <= 9; ++m) {
                const double w = m * v;
                if (w < lo * (1 - 1e-9) || w > hi * (1 + 1e-9)) continue;
                if (m == 1 && (e - e0) % every == 0) {
                    a.major.push_back(w);
                    a.labels.push_back(formatDecade(e));
                } else if (fewDecades && (m == 2 || m == 5)) {
                    char buf[32];
                    std::snprintf(buf, sizeof(buf), "%g", w);
                    a.major.push_back(w);
                    a.labels.push_back(buf);
                } else if (every == 1) {
                    a.minor.push_back(w);
                }
            }
        }
    } else {
        if (hi - lo <= 0.0) {
            const double pad = lo == 0.0 ? 1.0 : std::abs(lo) * 0.1;
            lo -= pad;
            hi += pad;
        }
        std::vector<double> ticks = niceTicks(lo, hi);
        const double step = ticks.size() > 1 ? ticks[1] - ticks[0] : (hi - lo);
        if (!usable(fixedLo, log)) lo = std::floor(lo / step + 1e-9) * step;
        if (!usable(fixedHi, log)) hi = std::ceil(hi / step - 1e-9) * step;
        ticks = niceTicks(lo, hi);
        for (double v : ticks) {
            a.major.push_back(v);
            a.labels.push_back(formatLinear(v, step));
        }
    }
    a.lo = lo;
    a.hi = hi;
    return a;
}

// Liang-Barsky clip of a segment to [x0,x1] x [y0,y1]; false when nothing is left.
bool clipSegment(double& ax, double& ay, double& bx, double& by, double x0, double y0, double x1, double y1)
{
    double t0 = 0.0, t1 = 1.0;
    const double dx = bx - ax, dy = by - ay;
    const double p[4] = {-dx, dx, -dy, dy};
    const double q[4] = {ax - x0, x1 - ax, ay - y0, y1 - ay};
    for (int i = 0; i < 4; ++i) {
        if (p[i] == 0.0) {
            if (q[i] < 0.0) return false;
            continue;
        }
        const double r = q[i] / p[i];
        if (p[i] < 0.0) t0 = std::max(t0, r);
        else t1 = std::min(t1, r);
        if (t0 > t1) return false;
    }
    const double nax = ax + t0 * dx, nay = ay + t0 * dy;
    bx = ax + t1 * dx;
    by = ay + t1 * dy;
    ax = nax;
    ay = nay;
    return true;
}

// About two pixels wide: two anti-aliased lines offset across the direction of travel.
void thickLine(Image& img, double ax, double ay, double bx, double by, const Rgb& c)
{
    const double len = std::hypot(bx - ax, by - ay);
    const double nx = len > 0 ? -(by - ay) / len * 0.5 : 0.0, ny = len > 0 ? (bx - ax) / len * 0.5 : 0.5;
    img.drawLine(ax + nx, ay + ny, bx + nx, by + ny, c);
    img.drawLine(ax - nx, ay - ny, bx - nx, by - ny, c);
}

struct Dash
{
    double phase = 0.0; // position in the 10-on/6-off pattern, carried across segments
};

void dashedLine(Image& img, double ax, double ay, double bx, double by, const Rgb& c, Dash& d, bool thick)
{
    const double len = std::hypot(bx - ax, by - ay);
    double s = 0.0;
    while (s < len) {
        const double inPattern = std::fmod(d.phase, 16.0);
        const bool on = inPattern < 10.0;
        const double run = std::min(len - s, (on ? 10.0 : 16.0) - inPattern);
        if (on) {
            const double t0 = s / len, t1 = (s + run) / len;
            const double x0 = ax + (bx - ax) * t0, y0 = ay + (by - ay) * t0;
            const double x1 = ax + (bx - ax) * t1, y1 = ay + (by - ay) * t1;
            if (thick) thickLine(img, x0, y0, x1, y1, c);
            else img.drawLine(x0, y0, x1, y1, c);
        }
        s += run;
        d.phase += run;
    }
}

} // namespace

std::vector<double> niceTicks(double lo, double hi, int target)
{
    std::vector<double> t;
    if (!(hi > lo) || !std::isfinite(lo) || !std::isfinite(hi)) return t;
    const double raw = (hi - lo) / std::max(1, target);
    const double mag = std::pow(10.0, std::floor(std::log10(raw)));
    double step = mag;
    for (double m : {1.0, 2.0, 5.0, 10.0})
        if (m * mag >= raw) {
            step = m * mag;
            break;
        }
    const double first = std::ceil(lo / step - 1e-9) * step;
    for (double v = first; v <= hi + step * 1e-9; v += step) t.push_back(std::abs(v) < step * 1e-9 ? 0.0 : v);
    return t;
}

Image linePlot(const std::vector<PlotSeries>& series, const PlotSettings& s, const std::vector<PlotRule>& rules)
{
    const int W = std::max(200, s.width), H = std::max(150, s.height), ts = std::max(1, s.textScale);
    const int ch = Image::textHeight(ts), cw = 6 * ts;
    Image img(W, H, kWhite);

    std::vector<double> xs, ys;
    for (const auto& ser : series) {
        for (size_t i = 0; i < std::min(ser.x.size(), ser.y.size()); ++i)
            if (usable(ser.x[i], s.logX) && usable(ser.y[i], s.logY)) {
                xs.push_back(ser.x[i]);
                ys.push_back(ser.y[i]);
            }
    }
    const bool noData = xs.empty();
    // Horizontal rules belong in the y range (a threshold should be visible next to the data).
    for (const auto& r : rules)
        if (!r.vertical && !noData) ys.push_back(r.value);
    const Axis ax = makeAxis(xs, s.logX, s.xMin, s.xMax);
    const Axis ay = makeAxis(ys, s.logY, s.yMin, s.yMax);

    size_t ylabelChars = 0;
    for (const auto& l : ay.labels) ylabelChars = std::max(ylabelChars, l.size());
    const int left = int(ylabelChars) * cw + 3 * cw;
    const int top = (s.title.empty() ? ch : 3 * ch) + (s.yLabel.empty() ? 0 : 2 * ch);
    const int bottom = 2 * ch + (s.xLabel.empty() ? 0 : ch + ch);
    const int right = 3 * cw;
    const int px0 = left, py0 = top, pw = W - left - right, ph = H - top - bottom;
    const auto X = [&](double v) { return px0 + ax.frac(v) * pw; };
    const auto Y = [&](double v) { return py0 + ph - ay.frac(v) * ph; };

    // Grid, ticks and tick labels.
    for (double v : ax.minor) img.fillRect(int(std::lround(X(v))), py0, 1, ph, kMinorGrid);
    for (double v : ay.minor) img.fillRect(px0, int(std::lround(Y(v))), pw, 1, kMinorGrid);
    for (size_t i = 0; i < ax.major.size(); ++i) {
        const int x = int(std::lround(X(ax.major[i])));
        img.fillRect(x, py0, 1, ph, kGrid);
        img.fillRect(x, py0 + ph, 1, ch / 2, kAxis);
        img.drawText(x - Image::textWidth(ax.labels[i], ts) / 2, py0 + ph + ch / 2 + ts * 2, ax.labels[i], kText, ts);
    }
    for (size_t i = 0; i < ay.major.size(); ++i) {
        const int y = int(std::lround(Y(ay.major[i])));
        img.fillRect(px0, y, pw, 1, kGrid);
        img.fillRect(px0 - cw / 2, y, cw / 2, 1, kAxis);
        img.drawText(px0 - cw / 2 - ts * 2 - Image::textWidth(ay.labels[i], ts), y - ch / 2, ay.labels[i], kText, ts);
    }
    img.drawRect(px0, py0, pw + 1, ph + 1, kAxis);

    if (!s.title.empty()) img.drawText((W - Image::textWidth(s.title, ts)) / 2, ch / 2 + ts, s.title, kText, ts);
    // Above the axis, clear of the top tick label.
    if (!s.yLabel.empty()) img.drawText(std::max(2, px0 - cw * 2), py0 - 2 * ch, s.yLabel, kText, ts);
    if (!s.xLabel.empty())
        img.drawText(px0 + (pw - Image::textWidth(s.xLabel, ts)) / 2, H - ch - ch / 2, s.xLabel, kText, ts);
    if (noData) {
        const std::string t = "no data";
        img.drawText(px0 + (pw - Image::textWidth(t, ts)) / 2, py0 + ph / 2 - ch / 2, t, Rgb(0.5f), ts);
    }

    const double cx0 = px0, cy0 = py0, cx1 = px0 + pw, cy1 = py0 + ph;
    for (const auto& r : rules) {
        const double lo = r.vertical ? ax.lo : ay.lo, hi = r.vertical ? ax.hi : ay.hi;
        const bool log = r.vertical ? ax.log : ay.log;
        if (!usable(r.value, log) || r.value < lo || r.value > hi) continue;
        Dash d;
        if (r.vertical) {
            const double x = X(r.value);
            dashedLine(img, x, cy0, x, cy1, r.color, d, true);
            if (!r.label.empty()) {
                const int tw = Image::textWidth(r.label, ts);
                const int tx = x + cw / 2 + tw < cx1 ? int(x) + cw / 2 : int(x) - cw / 2 - tw;
                img.fillRect(tx - 2, int(cy1) - 2 * ch - 2, tw + 4, ch + 4, kWhite);
                img.drawText(tx, int(cy1) - 2 * ch, r.label, r.color, ts);
            }
        } else {
            const double y = Y(r.value);
            dashedLine(img, cx0, y, cx1, y, r.color, d, false);
            if (!r.label.empty())
                img.drawText(int(cx0) + cw / 2, int(y) - ch - ts * 2, r.label, r.color, ts);
        }
    }

    for (const auto& ser : series) {
        const size_t n = std::min(ser.x.size(), ser.y.size());
        Dash d;
        bool havePrev = false;
        double prevX = 0, prevY = 0;
        for (size_t i = 0; i < n; ++i) {
            if (!usable(ser.x[i], ax.log) || !usable(ser.y[i], ay.log)) {
                havePrev = false;
                continue;
            }
            const double x = X(ser.x[i]), y = Y(ser.y[i]);
            if (havePrev) {
                double a0 = prevX, a1 = prevY, b0 = x, b1 = y;
                if (clipSegment(a0, a1, b0, b1, cx0, cy0, cx1, cy1)) {
                    if (ser.dashed) dashedLine(img, a0, a1, b0, b1, ser.color, d, true);
                    else thickLine(img, a0, a1, b0, b1, ser.color);
                }
            }
            if (ser.markers && x >= cx0 && x <= cx1 && y >= cy0 && y <= cy1)
                img.fillRect(int(std::lround(x)) - 2, int(std::lround(y)) - 2, 5, 5, ser.color);
            prevX = x;
            prevY = y;
            havePrev = true;
        }
    }

    // Legend in the top-right corner of the plot area.
    std::vector<const PlotSeries*> named;
    size_t longest = 0;
    for (const auto& ser : series)
        if (!ser.label.empty()) {
            named.push_back(&ser);
            longest = std::max(longest, ser.label.size());
        }
    if (!named.empty()) {
        const int rowH = ch + ch / 2, sample = 4 * cw;
        const int lw = sample + cw + int(longest) * cw + cw, lh = int(named.size()) * rowH + ch / 2;
        // The corner that hides the fewest data points (checked along every segment), top-right first.
        const int cands[4][2] = {{px0 + pw - lw - cw / 2, py0 + ch / 2}, {px0 + cw / 2, py0 + ch / 2},
            {px0 + pw - lw - cw / 2, py0 + ph - lh - ch / 2}, {px0 + cw / 2, py0 + ph - lh - ch / 2}};
        int best = 0;
        size_t bestHidden = size_t(-1);
        for (int c = 0; c < 4; ++c) {
            size_t hidden = 0;
            const auto inside = [&](double x, double y) {
                return x >= cands[c][0] - 2 && x <= cands[c][0] + lw + 2 && y >= cands[c][1] - 2 && y <= cands[c][1] + lh + 2;
            };
            for (const auto& ser : series) {
                const size_t n = std::min(ser.x.size(), ser.y.size());
                for (size_t i = 0; i < n; ++i) {
                    if (!usable(ser.x[i], ax.log) || !usable(ser.y[i], ay.log)) continue;
                    const double x = X(ser.x[i]), y = Y(ser.y[i]);
                    hidden += inside(x, y) ? 4 : 0; // points count more than the line between them
                    if (i + 1 < n && usable(ser.x[i + 1], ax.log) && usable(ser.y[i + 1], ay.log))
                        for (int t = 1; t < 8; ++t) {
                            const double u = t / 8.0;
                            hidden += inside(x + (X(ser.x[i + 1]) - x) * u, y + (Y(ser.y[i + 1]) - y) * u) ? 1 : 0;
                        }
                }
            }
            if (hidden < bestHidden) {
                bestHidden = hidden;
                best = c;
            }
        }
        const int lx = cands[best][0], ly = cands[best][1];
        img.fillRect(lx, ly, lw, lh, kWhite);
        img.drawRect(lx, ly, lw, lh, Rgb(0.7f));
        for (size_t i = 0; i < named.size(); ++i) {
            const int y = ly + ch / 2 + int(i) * rowH + ch / 2;
            Dash d;
            if (named[i]->dashed) dashedLine(img, lx + cw / 2, y, lx + cw / 2 + sample, y, named[i]->color, d, true);
            else thickLine(img, lx + cw / 2, y, lx + cw / 2 + sample, y, named[i]->color);
            if (named[i]->markers) img.fillRect(lx + cw / 2 + sample / 2 - 2, y - 2, 5, 5, named[i]->color);
            img.drawText(lx + cw + sample, y - ch / 2, named[i]->label, kText, ts);
        }
    }
    return img;
}

Image tileImages(const std::vector<Image>& images, int columns, int gap)
{
    if (images.empty()) return Image();
    columns = std::max(1, std::min(columns, int(images.size())));
    int cw = 0, chh = 0;
    for (const auto& im : images) {
        cw = std::max(cw, im.width());
        chh = std::max(chh, im.height());
    }
    const int rows = (int(images.size()) + columns - 1) / columns;
    Image out(columns * cw + (columns + 1) * gap, rows * chh + (rows + 1) * gap, kWhite);
    for (size_t i = 0; i < images.size(); ++i) {
        const int r = int(i) / columns, c = int(i) % columns;
        out.blit(images[i], gap + c * (cw + gap), gap + r * (chh + gap));
    }
    return out;
}

} // namespace turb
