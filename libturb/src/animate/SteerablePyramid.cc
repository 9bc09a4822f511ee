#include <turb/SteerablePyramid.h>

#include "CvOps.h"

#include <turb/Error.h>

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>

namespace turb {

namespace {

using Complex = std::complex<float>;

/// fftwf_malloc'ed storage: every buffer has FFTW's alignment, so plans made on one run on any.
template<typename T>
class FftwBuffer
{
public:
    /// Uninitialised storage of n elements (`zero` fills it).
    explicit FftwBuffer(size_t n, bool zero = false)
        : mN(n), mP(static_cast<T*>(fftwf_malloc(sizeof(T) * std::max<size_t>(n, 1))))
    {
        if (!mP) throw std::bad_alloc();
        if (zero) std::fill(mP, mP + n, T{});
    }
    ~FftwBuffer() { fftwf_free(mP); }
    FftwBuffer(const FftwBuffer&) = delete;
    FftwBuffer& operator=(const FftwBuffer&) = delete;
    T* data() { return mP; }
    const T* data() const { return mP; }
    size_t size() const { return mN; }

private:
    size_t mN;
    T* mP;
};

/// Plans per size, made once under a lock (the FFTW planner is not thread-safe; execution is).
struct Plans
{
    fftwf_plan r2c = nullptr, c2r = nullptr;
};

const Plans& plansFor(int w, int h)
{
    static std::mutex mutex;
    static std::map<std::pair<int, int>, Plans> cache;
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find({w, h});
    if (it != cache.end()) return it->second;
    FftwBuffer<float> real(size_t(w) * size_t(h));
    FftwBuffer<Complex> spec(size_t(h) * size_t(w / 2 + 1));
    Plans p;
    p.r2c = fftwf_plan_dft_r2c_2d(h, w, real.data(), reinterpret_cast<fftwf_complex*>(spec.data()), FFTW_ESTIMATE);
    p.c2r = fftwf_plan_dft_c2r_2d(h, w, reinterpret_cast<fftwf_complex*>(spec.data()), real.data(), FFTW_ESTIMATE);
    if (!p.r2c || !p.c2r)
        throw ValueError("FFTW could not plan a " + std::to_string(w) + "x" + std::to_string(h) + " transform");
    return cache.emplace(std::make_pair(w, h), p).first->second;
}

/// A half spectrum (r2c layout: h rows of w/2 + 1) of a w x h real image, normalised by 1/(w h) so
/// that coefficients do not depend on the sampling rate (cropping them is exact downsampling).
struct Spectrum
{
    int w = 0, h = 0;
    std::shared_ptr<FftwBuffer<Complex>> c;
    int cols() const { return w / 2 + 1; }
    Complex& at(int y, int kx) { return c->data()[size_t(y) * size_t(cols()) + size_t(kx)]; }
    Complex at(int y, int kx) const { return c->data()[size_t(y) * size_t(cols()) + size_t(kx)]; }
};

Spectrum emptySpectrum(int w, int h, bool zero = false)
{
    Spectrum s;
    s.w = w;
    s.h = h;
    s.c = std::make_shared<FftwBuffer<Complex>>(size_t(h) * size_t(w / 2 + 1), zero);
    return s;
}

Spectrum forward(const ChannelImage& img)
{
    const int w = img.width(), h = img.height();
    FftwBuffer<float> real(size_t(w) * size_t(h));
    std::copy(img.data().begin(), img.data().end(), real.data());
    Spectrum s = emptySpectrum(w, h);
    fftwf_execute_dft_r2c(plansFor(w, h).r2c, real.data(), reinterpret_cast<fftwf_complex*>(s.c->data()));
    const float norm = 1.0f / (float(w) * float(h));
    for (size_t i = 0; i < s.c->size(); ++i) s.c->data()[i] *= norm;
    return s;
}

/// The real image of a spectrum. FFTW's c2r overwrites its input: the spectrum is consumed.
ChannelImage inverse(Spectrum& s)
{
    FftwBuffer<float> real(size_t(s.w) * size_t(s.h));
    fftwf_execute_dft_c2r(plansFor(s.w, s.h).c2r, reinterpret_cast<fftwf_complex*>(s.c->data()), real.data());
    ChannelImage img(s.w, s.h, 1);
    std::copy(real.data(), real.data() + real.size(), img.data().begin());
    return img;
}

/// Normalised frequency of half-spectrum entry (row y, column kx): fx in [0, 1], fy in [-1, 1), with 1
/// at Nyquist.
inline void frequency(int w, int h, int y, int kx, double& fx, double& fy)
{
    fx = double(kx) / (0.5 * w);
    fy = double(y < (h + 1) / 2 ? y : y - h) / (0.5 * h);
}

/// The raised-cosine pair in log radius: hi rises from 0 at rho = 1/2 to 1 at rho = 1, hi^2 + lo^2 = 1.
inline double hiProfile(double rho)
{
    if (rho >= 1.0) return 1.0;
    if (rho <= 0.5) return 0.0;
    return std::cos(0.5 * M_PI * -std::log2(rho));
}
inline double loProfile(double rho)
{
    const double h = hiProfile(rho);
    return std::sqrt(std::max(0.0, 1.0 - h * h));
}

double angularConstant(int K)
{
    // alpha^2 = 2^{2(K-1)} ((K-1)!)^2 / (K (2(K-1))!): makes sum_k (alpha cos^{K-1})^2 = 1.
    const int n = K - 1;
    double f = 1.0, f2 = 1.0;
    for (int i = 2; i <= n; ++i) f *= i;
    for (int i = 2; i <= 2 * n; ++i) f2 *= i;
    return std::sqrt(std::pow(2.0, 2.0 * n) * f * f / (K * f2));
}

/// (-i)^{K-1}: the constant factor that makes every oriented band real.
Complex bandPhase(int K)
{
    static const Complex minusI(0.0f, -1.0f);
    Complex f(1.0f, 0.0f);
    for (int i = 0; i < K - 1; ++i) f *= minusI;
    return f;
}

/// The real masks of one level's half spectrum, made once per (size, orientations) and shared.
struct Masks
{
    std::vector<float> hi0, lo0;           // level 0 only: H0 and L0 (transition 1/2..1 of Nyquist)
    std::vector<float> hi, lo;             // band and low-pass radial parts (transition 1/4..1/2)
    std::vector<std::vector<float>> angle; // per orientation: alpha cos^{K-1}(theta - pi k / K)
};

const Masks& masksFor(int w, int h, int K)
{
    static std::mutex mutex;
    static std::map<std::tuple<int, int, int>, std::unique_ptr<Masks>> cache;
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find({w, h, K});
    if (it != cache.end()) return *it->second;
    auto m = std::make_unique<Masks>();
    const int cols = w / 2 + 1;
    const size_t n = size_t(h) * size_t(cols);
    m->hi0.resize(n);
    m->lo0.resize(n);
    m->hi.resize(n);
    m->lo.resize(n);
    m->angle.assign(size_t(K), std::vector<float>(n));
    const double alpha = angularConstant(K);
    for (int y = 0; y < h; ++y)
        for (int kx = 0; kx < cols; ++kx) {
            const size_t i = size_t(y) * size_t(cols) + size_t(kx);
            double fx, fy;
            frequency(w, h, y, kx, fx, fy);
            const double rho = std::hypot(fx, fy);
            m->hi0[i] = float(hiProfile(rho));
            m->lo0[i] = float(loProfile(rho));
            m->hi[i] = float(hiProfile(2.0 * rho));
            m->lo[i] = float(loProfile(2.0 * rho));
            const double theta = std::atan2(fy, fx);
            for (int k = 0; k < K; ++k) {
                const double c = std::cos(theta - M_PI * k / K);
                double a = alpha;
                for (int e = 0; e < K - 1; ++e) a *= c;
                m->angle[size_t(k)][i] = float(a);
            }
        }
    return *cache.emplace(std::make_tuple(w, h, K), std::move(m)).first->second;
}

/// Keeps the |f| < 1/2 part of a spectrum as the spectrum of the half-size image.
Spectrum cropHalf(const Spectrum& s)
{
    Spectrum out = emptySpectrum(s.w / 2, s.h / 2);
    for (int y = 0; y < out.h; ++y) {
        const int ky = y < (out.h + 1) / 2 ? y : y - out.h;
        const int sy = ky >= 0 ? ky : s.h + ky;
        for (int kx = 0; kx < out.cols(); ++kx) out.at(y, kx) = s.at(sy, kx);
    }
    return out;
}

/// The inverse of cropHalf: zero outside.
Spectrum padDouble(const Spectrum& s, int w, int h)
{
    Spectrum out = emptySpectrum(w, h, true);
    for (int y = 0; y < s.h; ++y) {
        const int ky = y < (s.h + 1) / 2 ? y : y - s.h;
        const int dy = ky >= 0 ? ky : h + ky;
        for (int kx = 0; kx < s.cols(); ++kx) out.at(dy, kx) = s.at(y, kx);
    }
    return out;
}

bool smooth(int n)
{
    for (int p : {2, 3, 5, 7})
        while (n % p == 0) n /= p;
    return n == 1;
}

int paddedSize(int n, int levels)
{
    const int unit = 1 << levels;
    int m = ((n + 8 + unit - 1) / unit) * unit;
    while (!smooth(m)) m += unit;
    return m;
}

/// Reflection at the right and bottom (x = n - 1 + k reads n - 1 - k, repeated as needed).
int reflectIndex(int i, int n)
{
    if (n == 1) return 0;
    const int period = 2 * (n - 1);
    i %= period;
    if (i < 0) i += period;
    return i < n ? i : period - i;
}

void checkLevels(const ChannelImage& image, int levels)
{
    if (image.empty() || image.channels() != 1) throw ValueError("pyramid: needs a non-empty 1-channel image");
    const int maxL = maxSteerableLevels(image.width(), image.height());
    if (levels < 1 || levels > maxL)
        throw ValueError("pyramid: " + std::to_string(levels) + " levels for a " + std::to_string(image.width()) + "x" +
                         std::to_string(image.height()) + " image (1.." + std::to_string(maxL) + ")");
}

} // namespace

int maxSteerableLevels(int width, int height)
{
    int L = 1;
    while ((std::min(width, height) >> (L + 1)) >= 8) ++L;
    return L;
}

SteerablePyramid buildSteerablePyramid(const ChannelImage& image, int levels, int K)
{
    checkLevels(image, levels);
    if (K < 1 || K > 8) throw ValueError("steerable pyramid: orientations must be 1..8");
    SteerablePyramid pyr;
    pyr.width = image.width();
    pyr.height = image.height();
    pyr.paddedWidth = paddedSize(image.width(), levels);
    pyr.paddedHeight = paddedSize(image.height(), levels);
    ChannelImage padded(pyr.paddedWidth, pyr.paddedHeight, 1);
    for (int y = 0; y < pyr.paddedHeight; ++y)
        for (int x = 0; x < pyr.paddedWidth; ++x)
            padded.at(x, y, 0) = image.at(reflectIndex(x, image.width()), reflectIndex(y, image.height()), 0);

    const Spectrum X = forward(padded);
    const Complex phase = bandPhase(K);
    Spectrum hi = emptySpectrum(X.w, X.h), lo = emptySpectrum(X.w, X.h);
    {
        const Masks& m = masksFor(X.w, X.h, K);
        for (size_t i = 0; i < X.c->size(); ++i) {
            hi.c->data()[i] = X.c->data()[i] * m.hi0[i];
            lo.c->data()[i] = X.c->data()[i] * m.lo0[i];
        }
    }
    pyr.highpass = inverse(hi);
    Spectrum L = lo;
    for (int l = 0; l < levels; ++l) {
        const Masks& m = masksFor(L.w, L.h, K);
        std::vector<ChannelImage> level;
        Spectrum band = emptySpectrum(L.w, L.h), low = emptySpectrum(L.w, L.h);
        const Complex* in = L.c->data();
        for (int k = 0; k < K; ++k) {
            const float* a = m.angle[size_t(k)].data();
            Complex* out = band.c->data();
            for (size_t i = 0; i < L.c->size(); ++i) out[i] = in[i] * phase * (m.hi[i] * a[i]);
            level.push_back(inverse(band));
        }
        for (size_t i = 0; i < L.c->size(); ++i) low.c->data()[i] = in[i] * m.lo[i];
        pyr.bands.push_back(std::move(level));
        L = cropHalf(low);
    }
    pyr.lowpass = inverse(L);
    return pyr;
}

ChannelImage collapse(const SteerablePyramid& pyr)
{
    const int levels = pyr.levels();
    if (levels < 1 || pyr.lowpass.empty()) throw ValueError("collapse: empty pyramid");
    const int K = int(pyr.bands[0].size());
    const Complex phase = std::conj(bandPhase(K));
    Spectrum L = forward(pyr.lowpass);
    for (int l = levels - 1; l >= 0; --l) {
        const int w = pyr.bands[size_t(l)][0].width(), h = pyr.bands[size_t(l)][0].height();
        const Masks& m = masksFor(w, h, K);
        Spectrum S = padDouble(L, w, h);
        Complex* s = S.c->data();
        for (size_t i = 0; i < S.c->size(); ++i) s[i] *= m.lo[i];
        for (int k = 0; k < K; ++k) {
            const Spectrum B = forward(pyr.bands[size_t(l)][size_t(k)]);
            const float* a = m.angle[size_t(k)].data();
            for (size_t i = 0; i < S.c->size(); ++i) s[i] += B.c->data()[i] * phase * (m.hi[i] * a[i]);
        }
        L = S;
    }
    {
        const Masks& m = masksFor(L.w, L.h, K);
        const Spectrum H0 = forward(pyr.highpass);
        for (size_t i = 0; i < L.c->size(); ++i)
            L.c->data()[i] = L.c->data()[i] * m.lo0[i] + H0.c->data()[i] * m.hi0[i];
    }
    const ChannelImage full = inverse(L);
    ChannelImage out(pyr.width, pyr.height, 1);
    for (int y = 0; y < pyr.height; ++y)
        for (int x = 0; x < pyr.width; ++x) out.at(x, y, 0) = full.at(x, y, 0);
    return out;
}

LaplacianPyramid buildLaplacianPyramid(const ChannelImage& image, int levels)
{
    checkLevels(image, levels);
    LaplacianPyramid pyr;
    ChannelImage g = image;
    for (int l = 0; l < levels; ++l) {
        ChannelImage down = cv::pyramidDown(g);
        const ChannelImage up = cv::pyramidUp(down, g.width(), g.height());
        for (size_t q = 0; q < g.data().size(); ++q) g.data()[q] -= up.data()[q];
        pyr.bands.push_back(std::move(g));
        g = std::move(down);
    }
    pyr.lowpass = std::move(g);
    return pyr;
}

ChannelImage collapse(const LaplacianPyramid& pyr)
{
    if (pyr.lowpass.empty()) throw ValueError("collapse: empty pyramid");
    ChannelImage g = pyr.lowpass;
    for (int l = pyr.levels() - 1; l >= 0; --l) {
        const ChannelImage& b = pyr.bands[size_t(l)];
        ChannelImage up = cv::pyramidUp(g, b.width(), b.height());
        for (size_t q = 0; q < up.data().size(); ++q) up.data()[q] += b.data()[q];
        g = std::move(up);
    }
    return g;
}

} // namespace turb
