#include "Rbf.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>

namespace turb::rbf {

void Interpolant::fit(std::vector<Sample> samples, double mergeDistance)
{
    if (samples.empty()) throw ValueError("RBF interpolation needs at least one sample");
    mChannels = int(samples.front().values.size());
    if (mChannels < 1) throw ValueError("RBF interpolation needs at least one value per sample");
    for (const Sample& s : samples)
        if (int(s.values.size()) != mChannels) throw ValueError("RBF samples carry different numbers of values");

    // Merge near-duplicates in input order (keeps the system regular; deterministic).
    std::vector<Sample> kept;
    std::vector<int> counts;
    const double md2 = mergeDistance * mergeDistance;
    for (Sample& s : samples) {
        size_t k = 0;
        for (; k < kept.size(); ++k) {
            const double dx = kept[k].x - s.x, dy = kept[k].y - s.y;
            if (dx * dx + dy * dy < md2) break;
        }
        if (k == kept.size()) {
            kept.push_back(std::move(s));
            counts.push_back(1);
        } else {
            for (int c = 0; c < mChannels; ++c) kept[k].values[size_t(c)] += s.values[size_t(c)];
            ++counts[k];
        }
    }
    for (size_t k = 0; k < kept.size(); ++k)
        for (double& v : kept[k].values) v /= counts[k];

    const size_t n = kept.size();
    mCx.resize(n);
    mCy.resize(n);
    double mx = 0.0, my = 0.0;
    for (size_t i = 0; i < n; ++i) {
        mCx[i] = kept[i].x;
        mCy[i] = kept[i].y;
        mx += kept[i].x;
        my += kept[i].y;
    }
    mx /= double(n);
    my /= double(n);
    // The linear part needs centres that span the plane: check the spread's smaller axis.
    double sxx = 0.0, syy = 0.0, sxy = 0.0;
    for (size_t i = 0; i < n; ++i) {
        sxx += (mCx[i] - mx) * (mCx[i] - mx);
        syy += (mCy[i] - my) * (mCy[i] - my);
        sxy += (mCx[i] - mx) * (mCy[i] - my);
    }
    const double tr = sxx + syy, det = sxx * syy - sxy * sxy;
    const double lmin = 0.5 * (tr - std::sqrt(std::max(0.0, tr * tr - 4.0 * det)));
    mPoly = (n >= 3 && lmin > 1e-6 * std::max(tr, 1e-12) && lmin > 1e-8) ? 3 : 1;

    const Eigen::Index m = Eigen::Index(n) + mPoly;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(m, m);
    Eigen::MatrixXd b = Eigen::MatrixXd::Zero(m, mChannels);
    for (size_t i = 0; i < n; ++i) {
        for (size_t j = 0; j < n; ++j)
            A(Eigen::Index(i), Eigen::Index(j)) = std::hypot(mCx[i] - mCx[j], mCy[i] - mCy[j]);
        const double q[3] = {1.0, mCx[i], mCy[i]};
        for (int p = 0; p < mPoly; ++p) {
            A(Eigen::Index(i), Eigen::Index(n) + p) = q[p];
            A(Eigen::Index(n) + p, Eigen::Index(i)) = q[p];
        }
        for (int c = 0; c < mChannels; ++c) b(Eigen::Index(i), c) = kept[i].values[size_t(c)];
    }
    const Eigen::MatrixXd w = A.fullPivLu().solve(b);
    mW.assign(size_t(m) * size_t(mChannels), 0.0);
    for (Eigen::Index r = 0; r < m; ++r)
        for (int c = 0; c < mChannels; ++c)
            mW[size_t(r) * size_t(mChannels) + size_t(c)] = std::isfinite(w(r, c)) ? w(r, c) : 0.0;
}

void Interpolant::evaluate(double x, double y, double* out) const
{
    const size_t n = mCx.size();
    const size_t C = size_t(mChannels);
    for (size_t c = 0; c < C; ++c) out[c] = 0.0;
    for (size_t i = 0; i < n; ++i) {
        const double r = std::hypot(x - mCx[i], y - mCy[i]);
        const double* w = &mW[i * C];
        for (size_t c = 0; c < C; ++c) out[c] += w[c] * r;
    }
    const double q[3] = {1.0, x, y};
    for (int p = 0; p < mPoly; ++p) {
        const double* w = &mW[(n + size_t(p)) * C];
        for (size_t c = 0; c < C; ++c) out[c] += w[c] * q[p];
    }
}

namespace {

std::vector<int> lattice(int size, int step)
{
    std::vector<int> at;
    for (int v = 0; v < size; v += step) at.push_back(v);
    if (at.empty() || at.back() != size - 1) at.push_back(size - 1);
    return at;
}

} // namespace

ChannelImage Interpolant::render(int width, int height, int step) const
{
    if (mChannels < 1) throw ValueError("RBF interpolant used before fit");
    ChannelImage out(width, height, mChannels);
    if (width <= 0 || height <= 0) return out;
    step = std::max(1, step);
    const std::vector<int> xs = lattice(width, step), ys = lattice(height, step);
    const size_t C = size_t(mChannels);
    std::vector<double> grid(xs.size() * ys.size() * C);
    parallelFor(ys.size(), 1, [&](size_t j0, size_t j1) {
        for (size_t j = j0; j < j1; ++j)
            for (size_t i = 0; i < xs.size(); ++i) evaluate(xs[i], ys[j], &grid[(j * xs.size() + i) * C]);
    });
    parallelFor(size_t(height), 8, [&](size_t y0, size_t y1) {
        for (size_t yy = y0; yy < y1; ++yy) {
            const int y = int(yy);
            const size_t j = std::min(size_t(y / step), ys.size() - 2 + (ys.size() == 1));
            const size_t j1 = std::min(j + 1, ys.size() - 1);
            const double ty = ys[j1] == ys[j] ? 0.0 : double(y - ys[j]) / double(ys[j1] - ys[j]);
            for (int x = 0; x < width; ++x) {
                const size_t i = std::min(size_t(x / step), xs.size() - 2 + (xs.size() == 1));
                const size_t i1 = std::min(i + 1, xs.size() - 1);
                const double tx = xs[i1] == xs[i] ? 0.0 : double(x - xs[i]) / double(xs[i1] - xs[i]);
                const double* a = &grid[(j * xs.size() + i) * C];
                const double* b = &grid[(j * xs.size() + i1) * C];
                const double* c = &grid[(j1 * xs.size() + i) * C];
                const double* d = &grid[(j1 * xs.size() + i1) * C];
                float* o = out.pixel(x, y);
                for (size_t k = 0; k < C; ++k)
                    o[k] = float((1 - ty) * ((1 - tx) * a[k] + tx * b[k]) + ty * ((1 - tx) * c[k] + tx * d[k]));
            }
        }
    });
    return out;
}

} // namespace turb::rbf
