#include <turb/Spectrum.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <new>

namespace turb {

namespace {

// FFTW's planner keeps global state: planning and destroying plans must not run concurrently
// (executing plans may). One lock for the whole library.
std::mutex& plannerMutex()
{
    static std::mutex m;
    return m;
}

class FftwFloats
{
public:
    explicit FftwFloats(size_t n) : mP(static_cast<float*>(fftwf_malloc(sizeof(float) * n)))
    {
        if (!mP) throw std::bad_alloc();
    }
    ~FftwFloats() { fftwf_free(mP); }
    FftwFloats(const FftwFloats&) = delete;
    FftwFloats& operator=(const FftwFloats&) = delete;
    float* get() const { return mP; }

private:
    float* mP;
};

class R2cPlan
{
public:
    R2cPlan(int side, float* buffer)
    {
        std::lock_guard<std::mutex> lock(plannerMutex());
        // FFTW_ESTIMATE: no timing-based choices, so the plan (and the rounding) is the same every run;
        // it also leaves the buffer untouched while planning.
        mPlan =
            fftwf_plan_dft_r2c_3d(side, side, side, buffer, reinterpret_cast<fftwf_complex*>(buffer), FFTW_ESTIMATE);
        if (!mPlan) throw Error("energySpectrum: FFTW could not plan a " + std::to_string(side) + "^3 transform");
    }
    ~R2cPlan()
    {
        std::lock_guard<std::mutex> lock(plannerMutex());
        fftwf_destroy_plan(mPlan);
    }
    R2cPlan(const R2cPlan&) = delete;
    R2cPlan& operator=(const R2cPlan&) = delete;
    void execute() const { fftwf_execute(mPlan); }

private:
    fftwf_plan mPlan = nullptr;
};

std::vector<double> window1d(int d, SpectrumSettings::Window w)
{
    std::vector<double> v(size_t(d), 1.0);
    if (w == SpectrumSettings::Window::Hann)
        for (int i = 0; i < d; ++i) v[size_t(i)] = 0.5 - 0.5 * std::cos(2.0 * M_PI * (i + 0.5) / d);
    return v;
}

double meanSquare(const std::vector<double>& v)
{
    double s = 0.0;
    for (double x : v) s += x * x;
    return s / double(v.size());
}

// The window's separable factors along each axis of the analysed box.
struct Window3
{
    std::vector<double> x, y, z;
};

// Window-weighted mean: subtracting it makes the windowed field's own mean exactly zero, so the
// mean flow does not leak into the first shells through the window's spectrum.
Vec3d windowedMean(const VectorField& u, const Coord& lo, const Coord& d, const Window3& w)
{
    const std::vector<double>&wx = w.x, &wy = w.y, &wz = w.z;
    Vec3d mean(0.0);
    double wsum = 0.0;
    for (int i = 0; i < d.x(); ++i)
        for (int j = 0; j < d.y(); ++j)
            for (int k = 0; k < d.z(); ++k) wsum += wx[size_t(i)] * wy[size_t(j)] * wz[size_t(k)];
    for (int a = 0; a < 3; ++a)
        mean[a] = parallelSum(size_t(d.x()), 1, [&](size_t i0, size_t i1) {
            double acc = 0.0;
            for (size_t i = i0; i < i1; ++i)
                for (int j = 0; j < d.y(); ++j)
                    for (int k = 0; k < d.z(); ++k)
                        acc += wx[i] * wy[size_t(j)] * wz[size_t(k)] * u(lo.x() + int(i), lo.y() + j, lo.z() + k)[a];
            return acc;
        }) / wsum;
    return mean;
}

// Fills the transform's S^3 input (rows padded to rowReal floats) with component `a` of the windowed field less
// its mean, zero-padded beyond the box.
void fillWindowedComponent(float* r, int S, size_t rowReal, const VectorField& u, const Coord& lo, const Coord& d,
    const Window3& w, int a, const Vec3d& mean)
{
    parallelFor(size_t(S), 1, [&](size_t i0, size_t i1) {
        for (size_t i = i0; i < i1; ++i)
            for (int j = 0; j < S; ++j) {
                float* row = r + (i * size_t(S) + size_t(j)) * rowReal;
                std::fill(row, row + rowReal, 0.0f);
                if (int(i) >= d.x() || j >= d.y()) continue;
                const double wij = w.x[i] * w.y[size_t(j)];
                for (int k = 0; k < d.z(); ++k)
                    row[k] = float(wij * w.z[size_t(k)] * (u(lo.x() + int(i), lo.y() + j, lo.z() + k)[a] - mean[a]));
            }
    });
}

// Adds the transform's power |u^|^2 per shell of integer wavenumber |n| to `shells` and its sum to `total`.
void addShellPower(const fftwf_complex* c, int S, int H, int maxShell, std::vector<double>& shells, double& total)
{
    // Shell sums per x-slab, combined in slab order: the same sums at any thread count.
    std::vector<std::vector<double>> part(static_cast<size_t>(S));
    parallelFor(size_t(S), 1, [&](size_t i0, size_t i1) {
        for (size_t i = i0; i < i1; ++i) {
            std::vector<double>& h = part[i];
            h.assign(size_t(maxShell) + 1, 0.0); // last slot: the slab's total
            const int ni = int(i) <= S / 2 ? int(i) : int(i) - S;
            for (int j = 0; j < S; ++j) {
                const int nj = j <= S / 2 ? j : j - S;
                const fftwf_complex* rowc = c + (i * size_t(S) + size_t(j)) * size_t(H);
                for (int kz = 0; kz < H; ++kz) {
                    // The r2c output holds kz >= 0 only; the conjugate half doubles the others.
                    const double mult = (kz == 0 || (S % 2 == 0 && kz == S / 2)) ? 1.0 : 2.0;
                    const double p = mult * (double(rowc[kz][0]) * rowc[kz][0] + double(rowc[kz][1]) * rowc[kz][1]);
                    const double n = std::sqrt(double(ni * ni + nj * nj + kz * kz));
                    h[size_t(std::lround(n))] += p;
                    h[size_t(maxShell)] += p;
                }
            }
        }
    });
    for (const auto& h : part) {
        for (int n = 0; n < maxShell; ++n) shells[size_t(n)] += h[size_t(n)];
        total += h[size_t(maxShell)];
    }
}

} // namespace

int fftFriendlySize(int m)
{
    for (int n = std::max(1, m);; ++n) {
        int r = n;
        for (int p : {2, 3, 5, 7})
            while (r % p == 0) r /= p;
        if (r == 1) return n;
    }
}

Spectrum energySpectrum(const VectorField& u, const CoordBBox& boxIn, const SpectrumSettings& s)
{
    Spectrum out;
    CoordBBox box = boxIn;
    box.intersect(u.bbox());
    if (box.empty() || u.empty()) return out;
    out.box = box;

    const Coord d = box.dim();
    const int S = fftFriendlySize(std::max({d.x(), d.y(), d.z()}));
    const int H = S / 2 + 1;              // complex values along the last axis
    const size_t rowReal = size_t(2 * H); // padded real row of the in-place transform
    const double voxel = u.lattice().voxelSize;
    out.fftSide = S;
    out.dk = 2.0 * M_PI / (S * voxel);

    const Window3 w{window1d(d.x(), s.window), window1d(d.y(), s.window), window1d(d.z(), s.window)};
    const Coord lo = box.min();
    const Vec3d mean = s.subtractMean ? windowedMean(u, lo, d, w) : Vec3d(0.0);

    FftwFloats buf(size_t(S) * size_t(S) * rowReal);
    const R2cPlan plan(S, buf.get());

    const int maxShell = int(std::ceil(std::sqrt(3.0) * (S / 2 + 1))) + 1;
    std::vector<double> shells(size_t(maxShell), 0.0);
    double total = 0.0;
    for (int a = 0; a < 3; ++a) {
        fillWindowedComponent(buf.get(), S, rowReal, u, lo, d, w, a, mean);
        plan.execute();
        addShellPower(reinterpret_cast<const fftwf_complex*>(buf.get()), S, H, maxShell, shells, total);
    }

    // Parseval: sum |u^|^2 = M sum |w u|^2 and sum |w u|^2 ~ mean(w^2) N mean|u|^2.
    const double M = double(S) * S * S;
    const double N = double(d.x()) * d.y() * d.z();
    const double W = meanSquare(w.x) * meanSquare(w.y) * meanSquare(w.z);
    const double norm = 0.5 / (M * N * W);
    out.meanEnergy = total * norm;
    for (int n = 1; n <= S / 2; ++n) {
        out.k.push_back(n * out.dk);
        out.energy.push_back(shells[size_t(n)] * norm / out.dk);
    }
    return out;
}

} // namespace turb
