#include <turb/Resample.h>

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

namespace turb {

namespace {

struct AxisWeights
{
    std::vector<int> i0, i1;
    std::vector<float> w;
};

// Fine voxel I lies at coarse coordinate (I + 1/2)/f - 1/2; clamp the two taps to the coarse range.
AxisWeights axisWeights(int fineMin, int fineMax, int coarseMin, int coarseMax, int f)
{
    AxisWeights a;
    for (int I = fineMin; I <= fineMax; ++I) {
        const double x = (I + 0.5) / f - 0.5;
        int lo = int(std::floor(x));
        float w = float(x - lo);
        int hi = lo + 1;
        if (lo < coarseMin) {
            lo = hi = coarseMin;
            w = 0.0f;
        } else if (hi > coarseMax) {
            lo = hi = coarseMax;
            w = 0.0f;
        }
        a.i0.push_back(lo);
        a.i1.push_back(hi);
        a.w.push_back(w);
    }
    return a;
}

} // namespace

template<typename T>
Field<T> upsample(const Field<T>& coarse, int factor)
{
    if (factor < 1) throw ValueError("upsample: factor must be >= 1");
    const CoordBBox cb = coarse.bbox();
    const CoordBBox fb = refineDomain(cb, factor);
    Field<T> fine(fb, refinedLattice(coarse.lattice(), cb, factor));
    if (coarse.empty()) return fine;
    const Coord F = domainFactors(cb, factor); // z factor 1 keeps a 2D field's one layer
    AxisWeights ax[3];
    for (int a = 0; a < 3; ++a) ax[a] = axisWeights(fb.min()[a], fb.max()[a], cb.min()[a], cb.max()[a], F[a]);
    const Coord d = fb.dim();
    parallelFor(size_t(d.x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int ia = ax[0].i0[x], ib = ax[0].i1[x];
            const float wx = ax[0].w[x];
            for (int y = 0; y < d.y(); ++y) {
                const int ja = ax[1].i0[size_t(y)], jb = ax[1].i1[size_t(y)];
                const float wy = ax[1].w[size_t(y)];
                T* out = &fine(fb.min().x() + int(x), fb.min().y() + y, fb.min().z());
                for (int z = 0; z < d.z(); ++z) {
                    const int ka = ax[2].i0[size_t(z)], kb = ax[2].i1[size_t(z)];
                    const float wz = ax[2].w[size_t(z)];
                    const T c00 = coarse(ia, ja, ka) * (1 - wz) + coarse(ia, ja, kb) * wz;
                    const T c01 = coarse(ia, jb, ka) * (1 - wz) + coarse(ia, jb, kb) * wz;
                    const T c10 = coarse(ib, ja, ka) * (1 - wz) + coarse(ib, ja, kb) * wz;
                    const T c11 = coarse(ib, jb, ka) * (1 - wz) + coarse(ib, jb, kb) * wz;
                    out[z] = (c00 * (1 - wy) + c01 * wy) * (1 - wx) + (c10 * (1 - wy) + c11 * wy) * wx;
                }
            }
        }
    });
    return fine;
}

template<typename T>
Field<T> boxDownsample(const Field<T>& fine, int factor)
{
    if (factor < 1) throw ValueError("boxDownsample: factor must be >= 1");
    const CoordBBox fb = fine.bbox();
    const CoordBBox cb = coarsenDomain(fb, factor);
    Field<T> coarse(cb, coarsenedLattice(fine.lattice(), fb, factor));
    if (fine.empty()) return coarse;
    const int fz = domainFactors(fb, factor).z(); // 1 for a 2D field: its one layer is its own coarse layer
    const float inv = 1.0f / float(factor * factor * fz);
    const Coord d = cb.dim();
    parallelFor(size_t(d.x()), 1, [&](size_t x0, size_t x1) {
        for (size_t xi = x0; xi < x1; ++xi) {
            const int ci = cb.min().x() + int(xi);
            for (int cj = cb.min().y(); cj <= cb.max().y(); ++cj)
                for (int ck = cb.min().z(); ck <= cb.max().z(); ++ck) {
                    T sum = Field<T>::zeroValue();
                    for (int a = 0; a < factor; ++a) {
                        const int i = ci * factor + a;
                        if (i < fb.min().x() || i > fb.max().x()) continue;
                        for (int b = 0; b < factor; ++b) {
                            const int j = cj * factor + b;
                            if (j < fb.min().y() || j > fb.max().y()) continue;
                            for (int c = 0; c < fz; ++c) {
                                const int k = ck * fz + c;
                                if (k < fb.min().z() || k > fb.max().z()) continue;
                                sum += fine(i, j, k);
                            }
                        }
                    }
                    coarse(ci, cj, ck) = sum * inv;
                }
        }
    });
    return coarse;
}

template<typename T>
Field<T> cropped(const Field<T>& f, const CoordBBox& box)
{
    Field<T> out(box, f.lattice());
    CoordBBox common = box;
    common.intersect(f.bbox());
    if (common.empty()) return out;
    for (int i = common.min().x(); i <= common.max().x(); ++i)
        for (int j = common.min().y(); j <= common.max().y(); ++j)
            for (int k = common.min().z(); k <= common.max().z(); ++k) out(i, j, k) = f(i, j, k);
    return out;
}

void fillUnwrittenVelocity(VectorField& velocity, const VectorField& up)
{
    for (size_t n = 0; n < velocity.size(); ++n) {
        Vec3f& v = velocity.data()[n];
        if (v != Vec3f(0.0f)) continue;
        const Coord c = velocity.coordOf(n);
        v = up.valueOr(c.x(), c.y(), c.z(), Vec3f(0.0f));
    }
}

FrequencySplit splitFrequencies(const VectorField& fine, int factor)
{
    FrequencySplit s;
    s.coarse = boxDownsample(fine, factor);
    s.low = cropped(upsample(s.coarse, factor), fine.bbox());
    s.high = VectorField(fine.bbox(), fine.lattice());
    for (size_t n = 0; n < fine.size(); ++n) s.high.data()[n] = fine.data()[n] - s.low.data()[n];
    return s;
}

bool isIntegerRatio(double coarseVoxel, double fineVoxel, double tol)
{
    const double r = coarseVoxel / fineVoxel;
    const double n = std::max(1.0, double(std::lround(r)));
    return std::abs(r - n) <= tol * n;
}

int integerRatio(double coarseVoxel, double fineVoxel, double tol)
{
    const double r = coarseVoxel / fineVoxel;
    if (!(r >= 1.0 - tol) || !isIntegerRatio(coarseVoxel, fineVoxel, tol)) {
        std::ostringstream os;
        os << "resolution ratio " << coarseVoxel << " / " << fineVoxel << " = " << r;
        if (r < 1.0 - tol) os << " is below 1: the high-resolution input has larger voxels than the low-resolution one";
        else os << " is not an integer";
        throw ValueError(os.str());
    }
    return int(std::lround(r));
}

int nearestRatio(double coarseVoxel, double fineVoxel, double tol)
{
    const double r = coarseVoxel / fineVoxel;
    if (!(r >= 1.0 - tol)) return integerRatio(coarseVoxel, fineVoxel, tol); // throws, naming both
    return std::max(1, int(std::lround(r)));
}

template<typename T>
Field<T> resampledToVoxel(const Field<T>& f, double voxelSize)
{
    if (!(voxelSize > 0.0)) throw ValueError("resampledToVoxel: voxel size must be positive");
    const Lattice from = f.lattice();
    Lattice to = from;
    to.voxelSize = voxelSize;
    if (f.empty()) {
        Field<T> none;
        none.setLattice(to);
        return none;
    }
    const double k = from.voxelSize / voxelSize; // new index per old index
    const double eps = 1e-9;
    const CoordBBox& b = f.bbox();
    const Coord lo(int(std::ceil(b.min().x() * k - eps)), int(std::ceil(b.min().y() * k - eps)),
        int(std::ceil(b.min().z() * k - eps)));
    const Coord hi(int(std::floor(b.max().x() * k + eps)), int(std::floor(b.max().y() * k + eps)),
        int(std::floor(b.max().z() * k + eps)));
    Field<T> out(CoordBBox(lo, hi), to);
    const double inv = 1.0 / k;
    // Every new centre lies inside the hull of f's centres, so the clamping never moves a sample.
    forEachVoxel(out.bbox(), [&](int i, int j, int kk) { out(i, j, kk) = sampleTrilinear(f, Vec3d(i, j, kk) * inv); });
    return out;
}

CoordBBox centralBox(const CoordBBox& box, int n)
{
    Coord lo, hi;
    for (int ax = 0; ax < 3; ++ax) {
        const int m = std::min(box.dim()[ax], n);
        lo[ax] = box.min()[ax] + (box.dim()[ax] - m) / 2;
        hi[ax] = lo[ax] + m - 1;
    }
    return CoordBBox(lo, hi);
}

Frame zLayer(const Frame& f, int k)
{
    const CoordBBox b = f.bbox();
    if (k < b.min().z() || k > b.max().z())
        throw ValueError("layer " + std::to_string(k) + " is outside the frame's z range " +
                         std::to_string(b.min().z()) + ".." + std::to_string(b.max().z()));
    const CoordBBox s(Coord(b.min().x(), b.min().y(), k), Coord(b.max().x(), b.max().y(), k));
    Frame out;
    out.number = f.number;
    out.dt = f.dt;
    out.timeUnit = f.timeUnit;
    out.metadata = f.metadata;
    if (f.hasVelocity()) {
        out.velocity = VectorField(s, f.velocity.lattice());
        for (int i = s.min().x(); i <= s.max().x(); ++i)
            for (int j = s.min().y(); j <= s.max().y(); ++j) {
                Vec3f v = f.velocity(i, j, k);
                v[2] = 0.0f;
                out.velocity(i, j, k) = v;
            }
    }
    if (f.hasDensity()) {
        out.density = ScalarField(s, f.density.lattice());
        for (int i = s.min().x(); i <= s.max().x(); ++i)
            for (int j = s.min().y(); j <= s.max().y(); ++j) out.density(i, j, k) = f.density(i, j, k);
    }
    return out;
}

Frame resampledToVoxel(const Frame& frame, double voxelSize)
{
    return mapFields(frame, [&](const auto& field) { return resampledToVoxel(field, voxelSize); });
}

void toTimeUnit(Frame& f, double seconds)
{
    if (!(std::isfinite(seconds) && seconds > 0.0))
        throw ValueError("time unit must be a finite number of seconds > 0, not " + std::to_string(seconds));
    if (seconds == f.timeUnit) return;
    // u [world / unit_old] = u / timeUnit [world / s] = u * seconds / timeUnit [world / unit_new].
    const float scale = float(seconds / f.timeUnit);
    for (size_t n = 0; n < f.velocity.size(); ++n) f.velocity.data()[n] *= scale;
    f.dt *= f.timeUnit / seconds;
    f.timeUnit = seconds;
}

template Field<float> resampledToVoxel(const Field<float>&, double);
template Field<Vec3f> resampledToVoxel(const Field<Vec3f>&, double);
template Field<float> upsample(const Field<float>&, int);
template Field<Vec3f> upsample(const Field<Vec3f>&, int);
template Field<float> boxDownsample(const Field<float>&, int);
template Field<Vec3f> boxDownsample(const Field<Vec3f>&, int);
template Field<float> cropped(const Field<float>&, const CoordBBox&);
template Field<Vec3f> cropped(const Field<Vec3f>&, const CoordBBox&);

} // namespace turb
