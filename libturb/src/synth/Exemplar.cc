// Vector-field exemplars: procedural patterns, pictures, slices. Light code: no OpenVDB tools.
#include <turb/Exemplar.h>

#include <turb/Error.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <sstream>

namespace turb {

namespace {

constexpr double kPi = 3.14159265358979323846;

int wrap(int v, int n) { return ((v % n) + n) % n; }

// Radius of the heart outline along polar angle theta, max 1. The classic parametric heart
// (x = 16 sin^3 t, y = 13 cos t - 5 cos 2t - 2 cos 3t - cos 4t) is tabulated in polar form about a
// point inside it, so a "heart radius" rho = r / R(theta) has level sets that are nested hearts.
struct HeartTable
{
    static constexpr int kBins = 720;
    std::array<double, kBins> r{};
    HeartTable()
    {
        r.fill(0.0);
        const double cy = -2.5; // centre between the top dip (y = 5) and the bottom tip (y = -17)
        const int samples = 40000;
        for (int s = 0; s < samples; ++s) {
            const double t = 2.0 * kPi * s / samples;
            const double x = 16.0 * std::pow(std::sin(t), 3);
            const double y = 13.0 * std::cos(t) - 5.0 * std::cos(2 * t) - 2.0 * std::cos(3 * t) - std::cos(4 * t) - cy;
            double th = std::atan2(y, x);
            if (th < 0) th += 2 * kPi;
            const int b = std::min(kBins - 1, int(th / (2 * kPi) * kBins));
            r[size_t(b)] = std::max(r[size_t(b)], std::sqrt(x * x + y * y));
        }
        // Fill any bin the sampling missed from its neighbours, then normalise to a max of 1.
        for (int pass = 0; pass < 4; ++pass)
            for (int b = 0; b < kBins; ++b)
                if (r[size_t(b)] == 0.0)
                    r[size_t(b)] = std::max(r[size_t((b + 1) % kBins)], r[size_t((b + kBins - 1) % kBins)]);
        // Round the dip and the tip (a circular Gaussian of about 6 degrees): a kinked outline gives
        // velocity jumps along the heart's axis that finite differences read as divergence.
        std::array<double, kBins> sm{};
        const int half = 120;
        const double sigma = 40.0;
        for (int b = 0; b < kBins; ++b) {
            double acc = 0.0, wsum = 0.0;
            for (int o = -half; o <= half; ++o) {
                const double w = std::exp(-0.5 * o * o / (sigma * sigma));
                acc += w * r[size_t((b + o + kBins) % kBins)];
                wsum += w;
            }
            sm[size_t(b)] = acc / wsum;
        }
        r = sm;
        const double m = *std::max_element(r.begin(), r.end());
        for (auto& v : r) v /= m;
    }
    double operator()(double theta) const
    {
        double u = theta / (2 * kPi) * kBins - 0.5;
        u = u - std::floor(u / kBins) * kBins;
        const int b0 = int(std::floor(u)) % kBins, b1 = (b0 + 1) % kBins;
        const double w = u - std::floor(u);
        return r[size_t(b0)] * (1 - w) + r[size_t(b1)] * w;
    }
};

const HeartTable& heartTable()
{
    static const HeartTable t;
    return t;
}

// The stream function of a pattern at continuous pixel position (x, y); velocity = (dpsi/dy, -dpsi/dx).
std::function<double(double, double)> streamFunction(ProceduralPattern p, double period)
{
    const double P = period;
    // One vortex per cell of size P whose streamlines are the level sets of a star-shaped "radius";
    // the profile (1 + cos(pi rho)) / 2 makes the speed vanish at the centre and at the cell edge, so
    // neighbouring cells join without a seam.
    // `power` 2 for outlines that are not circles: a profile in rho^2 is flat at the centre, where a
    // non-circular "radius" has a cone-shaped singularity that would show as a velocity kink.
    const auto cellVortex = [P](std::function<double(double, double)> radius, int power) {
        return [P, radius, power](double x, double y) {
            const double cx = (std::floor(x / P) + 0.5) * P, cy = (std::floor(y / P) + 0.5) * P;
            const double R = 0.5 * P * 0.95;
            const double rho = radius((x - cx) / R, (y - cy) / R);
            return rho >= 1.0 ? 0.0 : R * 0.5 * (1.0 + std::cos(kPi * std::pow(rho, power))) / kPi;
        };
    };
    switch (p) {
    case ProceduralPattern::Circles:
        return cellVortex([](double dx, double dy) { return std::sqrt(dx * dx + dy * dy); }, 1);
    case ProceduralPattern::Squares:
        return cellVortex([](double dx, double dy) { return std::max(std::abs(dx), std::abs(dy)); }, 1);
    case ProceduralPattern::Hearts:
        return cellVortex(
            [](double dx, double dy) {
                const double r = std::sqrt(dx * dx + dy * dy);
                if (r < 1e-12) return 0.0;
                double th = std::atan2(dy, dx);
                if (th < 0) th += 2 * kPi;
                return r / heartTable()(th);
            },
            1);
    case ProceduralPattern::Swirls:
        return
            [P](double x, double y) { return P / (2 * kPi) * std::sin(2 * kPi * x / P) * std::sin(2 * kPi * y / P); };
    case ProceduralPattern::Stripes:
        return [P](double, double y) { return -P / (2 * kPi) * std::cos(2 * kPi * y / P); };
    case ProceduralPattern::Sinusoids:
        // Channels y + a sin(2 pi x / P) = const, alternating in direction every half period.
        return [P](double x, double y) {
            const double a = 0.2 * P;
            return -P / (2 * kPi) * std::cos(2 * kPi * (y + a * std::sin(2 * kPi * x / P)) / P);
        };
    }
    return [](double, double) { return 0.0; };
}

float luminance(const Rgb& c) { return (c[0] + c[1] + c[2]) / 3.0f; }

} // namespace

Exemplar makeExemplar(int nx, int ny, int nz, bool periodic, const std::string& name)
{
    if (nx < 1 || ny < 1 || nz < 1) throw ValueError("exemplar: empty size");
    Exemplar e;
    e.nx = nx;
    e.ny = ny;
    e.nz = nz;
    e.channels = nz == 1 ? 2 : 3;
    e.periodic = periodic;
    e.name = name;
    e.values.assign(e.count() * size_t(e.channels), 0.0f);
    return e;
}

ProceduralPattern parseProceduralPattern(const std::string& name)
{
    for (auto p : {ProceduralPattern::Circles, ProceduralPattern::Swirls, ProceduralPattern::Squares,
             ProceduralPattern::Hearts, ProceduralPattern::Stripes, ProceduralPattern::Sinusoids})
        if (name == proceduralPatternName(p)) return p;
    if (name == "circle") return ProceduralPattern::Circles;
    if (name == "swirl") return ProceduralPattern::Swirls;
    if (name == "square") return ProceduralPattern::Squares;
    if (name == "heart") return ProceduralPattern::Hearts;
    if (name == "stripe") return ProceduralPattern::Stripes;
    if (name == "sinusoid" || name == "sine") return ProceduralPattern::Sinusoids;
    throw ValueError("unknown exemplar pattern '" + name + "' (circles, swirls, squares, hearts, stripes, sinusoids)");
}

const char* proceduralPatternName(ProceduralPattern p)
{
    switch (p) {
    case ProceduralPattern::Circles: return "circles";
    case ProceduralPattern::Swirls: return "swirls";
    case ProceduralPattern::Squares: return "squares";
    case ProceduralPattern::Hearts: return "hearts";
    case ProceduralPattern::Stripes: return "stripes";
    case ProceduralPattern::Sinusoids: return "sinusoids";
    }
    return "?";
}

Exemplar proceduralExemplar(const ProceduralExemplarSettings& s)
{
    if (s.period < 4) throw ValueError("procedural exemplar: period must be >= 4 pixels");
    if (s.size < 8 || s.size % s.period != 0) {
        std::ostringstream os;
        os << "procedural exemplar: size " << s.size << " must be >= 8 and a multiple of the period " << s.period
           << " so that it tiles";
        throw ValueError(os.str());
    }
    const auto psi = streamFunction(s.pattern, double(s.period));
    Exemplar e = makeExemplar(
        s.size, s.size, 1, true, std::string(proceduralPatternName(s.pattern)) + ":" + std::to_string(s.period));
    // Central differences of psi at pixel centres with a small step: exact enough, and every pattern
    // uses one code path. Pixel (x, y) is centred at (x + 0.5, y + 0.5).
    const double h = 1e-3;
    for (int x = 0; x < s.size; ++x)
        for (int y = 0; y < s.size; ++y) {
            const double px = x + 0.5, py = y + 0.5;
            float* v = e.at(x, y);
            v[0] = float((psi(px, py + h) - psi(px, py - h)) / (2 * h));
            v[1] = float(-(psi(px + h, py) - psi(px - h, py)) / (2 * h));
        }
    normalizeExemplar(e);
    return e;
}

Exemplar exemplarFromVectorImage(const Image& image, double scale)
{
    if (image.empty()) throw ValueError("vector exemplar: empty picture");
    Exemplar e = makeExemplar(image.width(), image.height(), 1, false, "rg-image");
    for (int x = 0; x < image.width(); ++x)
        for (int y = 0; y < image.height(); ++y) {
            const Rgb& c = image.at(x, image.height() - 1 - y);
            float* v = e.at(x, y);
            v[0] = float((2.0 * c[0] - 1.0) * scale);
            v[1] = float((2.0 * c[1] - 1.0) * scale);
        }
    return e;
}

Exemplar exemplarFromGrayImage(const Image& image, double scale, bool periodic)
{
    if (image.width() < 2 || image.height() < 2) throw ValueError("gray exemplar: picture smaller than 2x2");
    const int w = image.width(), h = image.height();
    const auto I = [&](int x, int y) {
        if (periodic) {
            x = wrap(x, w);
            y = wrap(y, h);
        } else {
            x = std::clamp(x, 0, w - 1);
            y = std::clamp(y, 0, h - 1);
        }
        return double(luminance(image.at(x, h - 1 - y)));
    };
    Exemplar e = makeExemplar(w, h, 1, periodic, "gray-curl");
    for (int x = 0; x < w; ++x)
        for (int y = 0; y < h; ++y) {
            // One-sided at the edges (span 1), central inside (span 2).
            const int xl = periodic ? x - 1 : std::max(x - 1, 0), xr = periodic ? x + 1 : std::min(x + 1, w - 1);
            const int yl = periodic ? y - 1 : std::max(y - 1, 0), yr = periodic ? y + 1 : std::min(y + 1, h - 1);
            const double dIdx = (I(xr, y) - I(xl, y)) / double(xr - xl);
            const double dIdy = (I(x, yr) - I(x, yl)) / double(yr - yl);
            float* v = e.at(x, y);
            v[0] = float(dIdy * scale);
            v[1] = float(-dIdx * scale);
        }
    return e;
}

Exemplar exemplarFromSlice(const VectorField& field, int axis, int index)
{
    if (axis < 0 || axis > 2) throw ValueError("slice exemplar: axis must be 0, 1 or 2");
    const CoordBBox& b = field.bbox();
    if (field.empty() || index < b.min()[axis] || index > b.max()[axis]) {
        std::ostringstream os;
        os << "slice exemplar: index " << index << " along "
           << "xyz"[axis] << " is outside the field's box " << b;
        throw ValueError(os.str());
    }
    // View convention (Synth.h): along x the plane is (y, z), along y (x, z), along z (x, y).
    const int u = axis == 0 ? 1 : 0, v = axis == 2 ? 1 : 2;
    const Coord d = b.dim();
    Exemplar e = makeExemplar(d[u], d[v], 1, false, std::string("slice-") + "xyz"[axis] + std::to_string(index));
    for (int i = 0; i < d[u]; ++i)
        for (int j = 0; j < d[v]; ++j) {
            Coord c;
            c[axis] = index;
            c[u] = b.min()[u] + i;
            c[v] = b.min()[v] + j;
            const Vec3f w = field[c];
            float* o = e.at(i, j);
            o[0] = w[u];
            o[1] = w[v];
        }
    return e;
}

Exemplar exemplarFromVolume(const VectorField& field)
{
    if (field.empty()) throw ValueError("volume exemplar: empty field");
    const Coord d = field.bbox().dim();
    if (d.z() < 2) throw ValueError("volume exemplar: the field is one voxel thick; use a slice exemplar");
    Exemplar e = makeExemplar(d.x(), d.y(), d.z(), false, "volume");
    const Coord m = field.bbox().min();
    for (int i = 0; i < d.x(); ++i)
        for (int j = 0; j < d.y(); ++j)
            for (int k = 0; k < d.z(); ++k) {
                const Vec3f w = field(m.x() + i, m.y() + j, m.z() + k);
                float* o = e.at(i, j, k);
                o[0] = w[0];
                o[1] = w[1];
                o[2] = w[2];
            }
    return e;
}

Exemplar rescaledExemplar(const Exemplar& ex, double factor)
{
    if (!(factor > 0.0)) throw ValueError("exemplar scale must be > 0");
    const int n[3] = {std::max(1, int(std::lround(ex.nx * factor))), std::max(1, int(std::lround(ex.ny * factor))),
        ex.planar() ? 1 : std::max(1, int(std::lround(ex.nz * factor)))};
    const int src[3] = {ex.nx, ex.ny, ex.nz};
    Exemplar out = makeExemplar(n[0], n[1], n[2], ex.periodic, ex.name);
    out.channels = ex.channels;
    out.values.assign(out.count() * size_t(out.channels), 0.0f);
    // Per axis: the two source taps and the weight for each output index (pixel-centre aligned).
    struct Taps
    {
        std::vector<int> a, b;
        std::vector<float> w;
    } taps[3];
    for (int ax = 0; ax < 3; ++ax) {
        const double ratio = double(src[ax]) / double(n[ax]);
        for (int i = 0; i < n[ax]; ++i) {
            const double x = (i + 0.5) * ratio - 0.5;
            int lo = int(std::floor(x)), hi = lo + 1;
            float w = float(x - lo);
            if (ex.periodic) {
                lo = wrap(lo, src[ax]);
                hi = wrap(hi, src[ax]);
            } else {
                lo = std::clamp(lo, 0, src[ax] - 1);
                hi = std::clamp(hi, 0, src[ax] - 1);
            }
            taps[ax].a.push_back(lo);
            taps[ax].b.push_back(hi);
            taps[ax].w.push_back(w);
        }
    }
    for (int i = 0; i < n[0]; ++i)
        for (int j = 0; j < n[1]; ++j)
            for (int k = 0; k < n[2]; ++k) {
                float* o = out.at(i, j, k);
                for (int c = 0; c < ex.channels; ++c) {
                    double acc = 0.0;
                    for (int cx = 0; cx < 2; ++cx)
                        for (int cy = 0; cy < 2; ++cy)
                            for (int cz = 0; cz < 2; ++cz) {
                                const float wx = cx ? taps[0].w[size_t(i)] : 1 - taps[0].w[size_t(i)];
                                const float wy = cy ? taps[1].w[size_t(j)] : 1 - taps[1].w[size_t(j)];
                                const float wz = cz ? taps[2].w[size_t(k)] : 1 - taps[2].w[size_t(k)];
                                const int x = cx ? taps[0].b[size_t(i)] : taps[0].a[size_t(i)];
                                const int y = cy ? taps[1].b[size_t(j)] : taps[1].a[size_t(j)];
                                const int z = cz ? taps[2].b[size_t(k)] : taps[2].a[size_t(k)];
                                acc += double(wx) * wy * wz * ex.at(x, y, z)[c];
                            }
                    o[c] = float(acc);
                }
            }
    return out;
}

double exemplarRms(const Exemplar& ex)
{
    if (ex.count() == 0) return 0.0;
    double s = 0.0;
    for (float v : ex.values) s += double(v) * v;
    return std::sqrt(s / double(ex.count()));
}

double normalizeExemplar(Exemplar& ex)
{
    const double rms = exemplarRms(ex);
    if (!(rms > 0.0)) return 1.0;
    const float f = float(1.0 / rms);
    for (float& v : ex.values) v *= f;
    return 1.0 / rms;
}

VectorField exemplarAsField(const Exemplar& ex)
{
    VectorField f(CoordBBox(Coord(0), Coord(ex.nx - 1, ex.ny - 1, ex.nz - 1)), Lattice{});
    for (int x = 0; x < ex.nx; ++x)
        for (int y = 0; y < ex.ny; ++y)
            for (int z = 0; z < ex.nz; ++z) {
                const float* v = ex.at(x, y, z);
                f(x, y, z) = Vec3f(v[0], v[1], ex.planar() ? 0.0f : v[2]);
            }
    return f;
}

Image exemplarColorImage(const Exemplar& ex, double range)
{
    Image img(ex.nx, ex.ny, Rgb(0.5f));
    const int z = ex.nz / 2;
    if (range <= 0.0)
        for (int x = 0; x < ex.nx; ++x)
            for (int y = 0; y < ex.ny; ++y)
                for (int c = 0; c < 2; ++c) range = std::max(range, double(std::abs(ex.at(x, y, z)[c])));
    if (range <= 0.0) range = 1.0;
    for (int x = 0; x < ex.nx; ++x)
        for (int y = 0; y < ex.ny; ++y) {
            const float* v = ex.at(x, y, z);
            const float r = float(std::clamp(0.5 + 0.5 * v[0] / range, 0.0, 1.0));
            const float g = float(std::clamp(0.5 + 0.5 * v[1] / range, 0.0, 1.0));
            img.at(x, ex.ny - 1 - y) = Rgb(r, g, 0.5f);
        }
    return img;
}

} // namespace turb
