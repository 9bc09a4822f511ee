// Advection of dense 3D fields over their own box, without a VDB round trip (Advect.cc dispatches here).
#pragma once

#include <turb/Advect.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <utility>

namespace turb::detail {

// Component-wise min, max and clamp of scalars and vectors: the limiter's range of the taps (both advection paths).
inline float minOf(float a, float b) { return std::min(a, b); }
inline float maxOf(float a, float b) { return std::max(a, b); }
inline Vec3f minOf(const Vec3f& a, const Vec3f& b)
{
    return Vec3f(std::min(a[0], b[0]), std::min(a[1], b[1]), std::min(a[2], b[2]));
}
inline Vec3f maxOf(const Vec3f& a, const Vec3f& b)
{
    return Vec3f(std::max(a[0], b[0]), std::max(a[1], b[1]), std::max(a[2], b[2]));
}
inline float clampTo(float v, float lo, float hi) { return std::min(std::max(v, lo), hi); }
inline Vec3f clampTo(const Vec3f& v, const Vec3f& lo, const Vec3f& hi)
{
    return Vec3f(clampTo(v[0], lo[0], hi[0]), clampTo(v[1], lo[1], hi[1]), clampTo(v[2], lo[2], hi[2]));
}

/// The schemes of OpenVDB's VolumeAdvection on a dense field, `substeps` steps of `h` each, given one semi-Lagrangian
/// pass semi(from, step, to, lo, hi) that writes every voxel of `to` (and, with lo/hi, the range of the taps it
/// read): semi-Lagrangian; MacCormack, a = A(phi), c = A^R(a), phi' = a + (phi - c) / 2; BFECC, a = A(phi),
/// c = A^R(a), phi' = A(phi + (phi - c) / 2); the last two clamped to the range of phi's taps at the first pass's
/// backtrace when s.clamp.
template<typename T, typename Semi>
Field<T> integrateScheme(const Field<T>& q, int substeps, double h, const AdvectSettings& s, Semi&& semi)
{
    const auto eachVoxel = [&](auto&& body) {
        parallelFor(q.size(), size_t(1) << 16, [&](size_t n0, size_t n1) {
            for (size_t n = n0; n < n1; ++n) body(n);
        });
    };
    const CoordBBox& b = q.bbox();
    const Lattice& l = q.lattice();
    Field<T> phi = q, a(b, l), c(b, l), lo(b, l), hi(b, l);
    const bool limit = s.clamp && s.scheme != AdvectSettings::Scheme::SemiLagrangian;
    for (int step = 0; step < substeps; ++step) {
        T *P = phi.data(), *A = a.data(), *C = c.data();
        switch (s.scheme) {
        case AdvectSettings::Scheme::SemiLagrangian: semi(phi, h, a, nullptr, nullptr); break;
        case AdvectSettings::Scheme::MacCormack:
            semi(phi, h, a, &lo, &hi);
            semi(a, -h, c, nullptr, nullptr);
            eachVoxel([&](size_t n) { A[n] = A[n] + (P[n] - C[n]) * 0.5f; });
            break;
        case AdvectSettings::Scheme::BFECC:
            semi(phi, h, a, &lo, &hi);
            semi(a, -h, c, nullptr, nullptr);
            eachVoxel([&](size_t n) { C[n] = P[n] + (P[n] - C[n]) * 0.5f; });
            semi(c, h, a, nullptr, nullptr);
            break;
        }
        if (limit) {
            const T *LO = lo.data(), *HI = hi.data();
            eachVoxel([&](size_t n) { A[n] = clampTo(A[n], LO[n], HI[n]); });
        }
        std::swap(phi, a);
    }
    return phi;
}

/// q advected by `velocity` over `dt` with s.scheme and s.clamp: first-order backtraces from each voxel centre (the
/// velocity sampled trilinearly there, in world space), trilinear taps of q, zero outside q's box; the number of
/// substeps from the CFL number as OpenVDB's VolumeAdvection takes it (the largest |velocity|, 3 voxels a substep).
ScalarField advectDense(const ScalarField& q, const VectorField& velocity, double dt, const AdvectSettings& s);
VectorField advectDense(const VectorField& q, const VectorField& velocity, double dt, const AdvectSettings& s);

} // namespace turb::detail
