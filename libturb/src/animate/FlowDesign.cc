#include <turb/FlowDesign.h>

#include "CvOps.h"
#include "Rbf.h"

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/VideoAnalysis.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace turb {

void validateStrokes(const std::vector<FlowStroke>& strokes, int width, int height)
{
    bool globalOrientation = false;
    for (size_t k = 0; k < strokes.size(); ++k) {
        const FlowStroke& s = strokes[k];
        const std::string who =
            "stroke " + std::to_string(k) + " (" + (s.kind == StrokeKind::Speed ? "speed" : "orientation") + ")";
        if (s.points.size() < 2)
            throw ValueError(who + ": needs at least 2 points, has " + std::to_string(s.points.size()));
        bool moves = false;
        for (const StrokePoint& p : s.points) {
            if (!std::isfinite(p.x) || !std::isfinite(p.y)) throw ValueError(who + ": a point is not a finite number");
            if (p.x < -0.5 || p.y < -0.5 || p.x > width - 0.5 || p.y > height - 0.5)
                throw ValueError(who + ": point (" + std::to_string(p.x) + ", " + std::to_string(p.y) +
                                 ") lies outside the " + std::to_string(width) + "x" + std::to_string(height) +
                                 " image");
            if (p.x != s.points[0].x || p.y != s.points[0].y) moves = true;
        }
        if (!moves) throw ValueError(who + ": all its points are the same, it has no direction");
        if (s.local && !(s.size > 0.0 && std::isfinite(s.size))) throw ValueError(who + ": brush size must be > 0");
        if (s.local && !(s.alpha >= 0.0 && s.alpha <= 1.0)) throw ValueError(who + ": brush alpha must be in [0, 1]");
        if (s.kind == StrokeKind::Speed && !s.exampleSpeed && !(s.speed >= 0.0 && std::isfinite(s.speed)))
            throw ValueError(who + ": speed must be a number >= 0 (pixels per frame)");
        if (s.kind == StrokeKind::Orientation && !s.local) globalOrientation = true;
    }
    if (!globalOrientation) throw ValueError("the flow design needs at least one global orientation stroke");
}

namespace {

double strokeLength(const FlowStroke& s)
{
    double L = 0.0;
    for (size_t i = 1; i < s.points.size(); ++i)
        L += std::hypot(s.points[i].x - s.points[i - 1].x, s.points[i].y - s.points[i - 1].y);
    return L;
}

/// Samples every `spacing` pixels along the stroke (and its end), with the stroke's value there:
/// the unit tangent (orientation) or the speed.
void sampleStroke(const FlowStroke& s, double spacing, double exampleSpeed, std::vector<rbf::Sample>& out)
{
    const double speed = s.exampleSpeed ? exampleSpeed : s.speed;
    double carried = 0.0; // distance along the stroke to the next sample, from the current segment's start
    for (size_t i = 1; i < s.points.size(); ++i) {
        const StrokePoint a = s.points[i - 1], b = s.points[i];
        const double len = std::hypot(b.x - a.x, b.y - a.y);
        if (len <= 0.0) continue;
        const double tx = (b.x - a.x) / len, ty = (b.y - a.y) / len;
        const auto push = [&](double t) {
            rbf::Sample smp{a.x + t * tx, a.y + t * ty, {}};
            if (s.kind == StrokeKind::Orientation) smp.values = {tx, ty};
            else smp.values = {speed};
            out.push_back(std::move(smp));
        };
        double t = carried;
        for (; t <= len; t += spacing) push(t);
        carried = t - len;
        if (i + 1 == s.points.size() && carried > 1e-9) push(len); // the end point
    }
}

rbf::Interpolant fitLayer(const std::vector<const FlowStroke*>& strokes, const StrokeSettings& st)
{
    double L = 0.0;
    for (const FlowStroke* s : strokes) L += strokeLength(*s);
    const double spacing = std::max(st.sampleSpacing, L / double(std::max(8, st.maxSamples)));
    std::vector<rbf::Sample> samples;
    for (const FlowStroke* s : strokes) sampleStroke(*s, spacing, st.defaultSpeed, samples);
    rbf::Interpolant f;
    f.fit(std::move(samples));
    return f;
}

/// The local brush matte: alpha within size/2 of the polyline, smoothstep to 0 at distance size.
float brushMatte(const FlowStroke& s, double x, double y)
{
    double d2 = 1e300;
    for (size_t i = 1; i < s.points.size(); ++i) {
        const StrokePoint a = s.points[i - 1], b = s.points[i];
        const double ex = b.x - a.x, ey = b.y - a.y, l2 = ex * ex + ey * ey;
        double t = l2 > 0.0 ? ((x - a.x) * ex + (y - a.y) * ey) / l2 : 0.0;
        t = std::clamp(t, 0.0, 1.0);
        const double dx = x - (a.x + t * ex), dy = y - (a.y + t * ey);
        d2 = std::min(d2, dx * dx + dy * dy);
    }
    const double d = std::sqrt(d2), r0 = 0.5 * s.size;
    if (d <= r0) return float(s.alpha);
    if (d >= s.size) return 0.0f;
    const double t = (d - r0) / (s.size - r0);
    return float(s.alpha * (1.0 - t * t * (3.0 - 2.0 * t)));
}

void normalise(ChannelImage& o)
{
    for (size_t i = 0; i < o.pixelCount(); ++i) {
        float* p = o.pixel(i);
        const float n = std::hypot(p[0], p[1]);
        if (n > 1e-6f) {
            p[0] /= n;
            p[1] /= n;
        } else {
            p[0] = p[1] = 0.0f;
        }
    }
}

} // namespace

ChannelImage RoughFlow::flow() const
{
    ChannelImage f(orientation.width(), orientation.height(), 2);
    for (size_t i = 0; i < f.pixelCount(); ++i) {
        f.pixel(i)[0] = orientation.pixel(i)[0] * speed.pixel(i)[0];
        f.pixel(i)[1] = orientation.pixel(i)[1] * speed.pixel(i)[0];
    }
    return f;
}

RoughFlow interpolateStrokes(const std::vector<FlowStroke>& strokes, int width, int height, const StrokeSettings& st)
{
    if (width < 1 || height < 1) throw ValueError("interpolateStrokes: empty image");
    if (!(st.sampleSpacing > 0.0) || st.maxSamples < 8 || st.rbfStep < 1 || st.rbfStep > 16 ||
        !(st.defaultSpeed >= 0.0))
        throw ValueError("interpolateStrokes: settings out of range");
    validateStrokes(strokes, width, height);
    std::vector<const FlowStroke*> globalO, globalS;
    for (const FlowStroke& s : strokes)
        if (!s.local) (s.kind == StrokeKind::Orientation ? globalO : globalS).push_back(&s);

    RoughFlow r;
    r.orientation = fitLayer(globalO, st).render(width, height, st.rbfStep);
    normalise(r.orientation);
    if (globalS.empty()) r.speed = ChannelImage(width, height, 1, float(st.defaultSpeed));
    else r.speed = fitLayer(globalS, st).render(width, height, st.rbfStep);

    for (const FlowStroke& s : strokes) {
        if (!s.local) continue;
        const ChannelImage layer = fitLayer({&s}, st).render(width, height, st.rbfStep);
        ChannelImage& into = s.kind == StrokeKind::Orientation ? r.orientation : r.speed;
        const int C = into.channels();
        double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
        for (const StrokePoint& p : s.points) {
            x0 = std::min(x0, p.x);
            y0 = std::min(y0, p.y);
            x1 = std::max(x1, p.x);
            y1 = std::max(y1, p.y);
        }
        const int bx0 = std::max(0, int(std::floor(x0 - s.size))),
                  bx1 = std::min(width - 1, int(std::ceil(x1 + s.size)));
        const int by0 = std::max(0, int(std::floor(y0 - s.size))),
                  by1 = std::min(height - 1, int(std::ceil(y1 + s.size)));
        if (bx0 > bx1 || by0 > by1) continue;
        parallelFor(size_t(by1 - by0 + 1), 4, [&](size_t j0, size_t j1) {
            for (size_t j = j0; j < j1; ++j) {
                const int y = by0 + int(j);
                for (int x = bx0; x <= bx1; ++x) {
                    const float m = brushMatte(s, x, y);
                    if (m <= 0.0f) continue;
                    float* v = into.pixel(x, y);
                    const float* l = layer.pixel(x, y);
                    for (int c = 0; c < C; ++c) v[c] = (1.0f - m) * v[c] + m * l[c];
                }
            }
        });
    }
    normalise(r.orientation);
    for (float& v : r.speed.data()) v = std::max(0.0f, v);
    return r;
}

RoughFlow roughFromFlow(const ChannelImage& flow)
{
    if (flow.channels() != 2) throw ValueError("a designed flow must have 2 channels (x, y in pixels per frame)");
    RoughFlow r;
    r.orientation = flow;
    r.speed = ChannelImage(flow.width(), flow.height(), 1);
    for (size_t i = 0; i < flow.pixelCount(); ++i) r.speed.pixel(i)[0] = std::hypot(flow.pixel(i)[0], flow.pixel(i)[1]);
    normalise(r.orientation);
    return r;
}

void validate(const RefineSettings& s)
{
    if (!(s.wf > 0.0) || s.wf > 500.0) throw ValueError("refine: w_f must be in (0, 500] pixels");
    if (!(s.gradientFloor >= 0.0)) throw ValueError("refine: the gradient floor must be >= 0");
    if (s.gradientKernel < 1 || s.gradientKernel % 2 == 0)
        throw ValueError("refine: the gradient kernel must be odd and >= 1");
}

RefinedFlow refineFlow(const ChannelImage& target, const RoughFlow& rough, const RefineSettings& s)
{
    validate(s);
    const int W = target.width(), H = target.height();
    if (!rough.orientation.sameSize(target) || !rough.speed.sameSize(target) || rough.orientation.channels() != 2 ||
        rough.speed.channels() != 1)
        throw ValueError("refineFlow: the rough field must match the target's size (" + std::to_string(W) + "x" +
                         std::to_string(H) + ")");
    RefinedFlow r;
    r.gradient = cv::sobelGradient(cv::gaussian(luminance(target), s.gradientKernel));

    std::vector<float> mags(r.gradient.pixelCount());
    for (size_t i = 0; i < mags.size(); ++i) mags[i] = std::hypot(r.gradient.pixel(i)[0], r.gradient.pixel(i)[1]);
    std::vector<float> sorted = mags;
    const size_t p90 = std::min(sorted.size() - 1, size_t(0.9 * double(sorted.size())));
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(p90), sorted.end());
    const double eps = s.gradientFloor * double(sorted[p90]);
    const double eps2 = std::max(eps * eps, 1e-20);

    ChannelImage psi(W, H, 2);
    parallelFor(psi.pixelCount(), 1 << 12, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            const float* g = r.gradient.pixel(i);
            const float* phi = rough.orientation.pixel(i);
            double gx = g[0], gy = g[1];
            if (s.orient == GradientOrientation::Perpendicular) {
                const double t = gx;
                gx = -gy;
                gy = t;
            }
            const double m = mags[i];
            double ux = 0.0, uy = 0.0;
            if (m > 0.0) {
                ux = gx / m;
                uy = gy / m;
                if (ux * phi[0] + uy * phi[1] < 0.0) {
                    ux = -ux;
                    uy = -uy;
                }
            }
            const double w = m * m / (m * m + eps2);
            psi.pixel(i)[0] = float(w * ux + (1.0 - w) * phi[0]);
            psi.pixel(i)[1] = float(w * uy + (1.0 - w) * phi[1]);
        }
    });
    const int ksize = 2 * int(std::ceil(3.0 * s.wf)) + 1;
    r.orientation = cv::gaussian(psi, ksize, s.wf);
    r.speed = ChannelImage(W, H, 1);
    r.flow = ChannelImage(W, H, 2);
    for (size_t i = 0; i < r.orientation.pixelCount(); ++i) {
        float* o = r.orientation.pixel(i);
        const float* phi = rough.orientation.pixel(i);
        const float n = std::hypot(o[0], o[1]);
        if (n >= 1e-3f) {
            o[0] /= n;
            o[1] /= n;
        } else {
            o[0] = phi[0];
            o[1] = phi[1];
        }
        const float sp = std::max(0.0f, o[0] * phi[0] + o[1] * phi[1]) * rough.speed.pixel(i)[0];
        r.speed.pixel(i)[0] = sp;
        r.flow.pixel(i)[0] = sp * o[0];
        r.flow.pixel(i)[1] = sp * o[1];
    }
    return r;
}

} // namespace turb
