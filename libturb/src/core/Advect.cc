// Field advection: the in-plane 2D path, the dense 3D path (AdvectDense.cc) and OpenVDB's VolumeAdvection.
// Template-heavy: kept in its own unit.
#include <turb/Advect.h>

#include "AdvectDense.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/VolumeAdvect.h>

#include <algorithm>
#include <cmath>

namespace turb {

namespace {

openvdb::math::Transform::Ptr transformOf(const Lattice& l)
{
    auto xf = openvdb::math::Transform::createLinearTransform(l.voxelSize);
    xf->postTranslate(l.origin);
    return xf;
}

// ---- 2D (one z layer) fields: dense, in the plane. OpenVDB's VolumeAdvection dilates the active voxels by the
// travel distance along z too, so a one-layer field would be advected as a slab 2 * travel + 1 layers thick; the
// same schemes on the layer alone cost a small fraction of that.

using detail::maxOf;
using detail::minOf;

// Bilinear sample of a flat field at in-plane index (x, y); zero outside its box (OpenVDB's background). With
// `range`, also the min and max of the (in-box) taps, for the clamp limiter.
template<typename T>
T sampleFlat(const Field<T>& f, double x, double y, T* lo = nullptr, T* hi = nullptr)
{
    const CoordBBox& b = f.bbox();
    const int k = b.min().z();
    const int i0 = int(std::floor(x)), j0 = int(std::floor(y));
    const float wx = float(x - i0), wy = float(y - j0);
    T acc = Field<T>::zeroValue();
    bool first = true;
    for (int dj = 0; dj < 2; ++dj)
        for (int di = 0; di < 2; ++di) {
            const int i = i0 + di, j = j0 + dj;
            const bool in = i >= b.min().x() && i <= b.max().x() && j >= b.min().y() && j <= b.max().y();
            const T v = in ? f(i, j, k) : Field<T>::zeroValue();
            acc += v * ((di ? wx : 1.0f - wx) * (dj ? wy : 1.0f - wy));
            if (lo) {
                if (first) *lo = *hi = v;
                else {
                    *lo = minOf(*lo, v);
                    *hi = maxOf(*hi, v);
                }
                first = false;
            }
        }
    return acc;
}

template<typename T>
Field<T> advectFlat(const Field<T>& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    const Lattice& ql = q.lattice();
    const Lattice& vl = velocity.lattice();
    const CoordBBox& b = q.bbox();
    const int k = b.min().z();
    // Displacement per unit time of each voxel centre, in q's index units (first-order backtraces, as
    // VolumeAdvection takes for its MacCormack and BFECC schemes); the velocity is sampled in world space.
    std::vector<Vec3d> disp(q.size());
    double fastest = 0.0;
    for (size_t n = 0; n < q.size(); ++n) {
        const Coord c = q.coordOf(n);
        const Vec3d w = ql.indexToWorld(c.asVec3d());
        const Vec3d vi = vl.worldToIndex(w);
        const Vec3f v = sampleFlat(velocity, vi.x(), vi.y());
        disp[n] = Vec3d(v.x(), v.y(), 0.0) / ql.voxelSize;
        fastest = std::max(fastest, std::max(std::abs(disp[n].x()), std::abs(disp[n].y())));
    }
    int substeps = s.substeps;
    if (substeps <= 0) substeps = std::max(1, int(std::ceil(fastest * std::abs(dt) / 3.0)));
    const double h = dt / substeps;
    // One semi-Lagrangian step of `from` over time `step`; with `lo`/`hi`, the range of the taps used.
    const auto semi = [&](const Field<T>& from, double step, Field<T>& to, Field<T>* lo, Field<T>* hi) {
        parallelFor(size_t(b.dim().x()), 1, [&](size_t x0, size_t x1) {
            for (size_t xi = x0; xi < x1; ++xi)
                for (int j = b.min().y(); j <= b.max().y(); ++j) {
                    const int i = b.min().x() + int(xi);
                    const size_t n = q.offset(i, j, k);
                    const double x = i - disp[n].x() * step, y = j - disp[n].y() * step;
                    to.data()[n] = lo ? sampleFlat(from, x, y, &lo->data()[n], &hi->data()[n]) : sampleFlat(from, x, y);
                }
        });
    };
    return detail::integrateScheme(q, substeps, h, s, semi);
}

template<typename T, typename GridT>
Field<T> advectImpl(const Field<T>& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    if (q.empty()) return q;
    if (velocity.empty()) throw ValueError("advect: empty velocity field");
    if (s.inPlane && isFlat(q.bbox()) && isFlat(velocity.bbox())) return advectFlat(q, velocity, dt, s);
    if (s.backend == AdvectSettings::Backend::Dense) return detail::advectDense(q, velocity, dt, s);
    openvdb::initialize();
    // Sparse: only non-zero voxels become active; VolumeAdvection dilates them by the travel distance,
    // so the cost follows the smoke, not the box.
    auto grid = GridT::create(Field<T>::zeroValue());
    {
        openvdb::tools::Dense<T, openvdb::tools::LayoutZYX> dense(q.bbox(), const_cast<T*>(q.data()));
        openvdb::tools::copyFromDense(dense, *grid, Field<T>::zeroValue());
    }
    grid->setTransform(transformOf(q.lattice()));
    if (grid->empty()) return Field<T>(q.bbox(), q.lattice());
    auto vel = openvdb::Vec3SGrid::create(Vec3f(0.0f));
    {
        openvdb::tools::Dense<Vec3f, openvdb::tools::LayoutZYX> dense(
            velocity.bbox(), const_cast<Vec3f*>(velocity.data()));
        openvdb::tools::copyFromDense(dense, *vel, Vec3f(0.0f));
    }
    vel->setTransform(transformOf(velocity.lattice()));

    using Advection = openvdb::tools::VolumeAdvection<openvdb::Vec3SGrid, /*staggered=*/false>;
    Advection adv(*vel);
    switch (s.scheme) {
    case AdvectSettings::Scheme::SemiLagrangian: adv.setIntegrator(openvdb::tools::Scheme::SEMI); break;
    case AdvectSettings::Scheme::MacCormack: adv.setIntegrator(openvdb::tools::Scheme::MAC); break;
    case AdvectSettings::Scheme::BFECC: adv.setIntegrator(openvdb::tools::Scheme::BFECC); break;
    }
    adv.setLimiter(s.clamp ? openvdb::tools::Scheme::CLAMP : openvdb::tools::Scheme::NO_LIMITER);
    int substeps = s.substeps;
    if (substeps <= 0) {
        const double travel = adv.getMaxVelocity() * std::abs(dt) / q.lattice().voxelSize;
        substeps = std::max(1, int(std::ceil(travel / 3.0)));
    }
    adv.setSubSteps(substeps);
    auto out = adv.template advect<GridT, openvdb::tools::Sampler<1, false>>(*grid, dt);
    Field<T> result(q.bbox(), q.lattice());
    openvdb::tools::Dense<T, openvdb::tools::LayoutZYX> dense(result.bbox(), result.data());
    openvdb::tools::copyToDense(*out, dense);
    return result;
}

} // namespace

const char* schemeName(AdvectSettings::Scheme scheme)
{
    switch (scheme) {
    case AdvectSettings::Scheme::SemiLagrangian: return "semi-lagrangian";
    case AdvectSettings::Scheme::MacCormack: return "maccormack";
    case AdvectSettings::Scheme::BFECC: return "bfecc";
    }
    return "?";
}

ScalarField advect(const ScalarField& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    return advectImpl<float, openvdb::FloatGrid>(q, velocity, dt, s);
}

VectorField advect(const VectorField& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    return advectImpl<Vec3f, openvdb::Vec3SGrid>(q, velocity, dt, s);
}

ScalarField estimateSources(const ScalarField* previous, const ScalarField& density, const VectorField& velocity,
    double dt, const AdvectSettings& advectSettings, const ScalarField* region)
{
    if (density.empty()) throw ValueError("sources: empty density");
    if (region && region->bbox() != density.bbox())
        throw ValueError("sources: the region must cover the density's box");
    ScalarField s = density;
    if (previous && !previous->empty()) {
        if (previous->bbox() != density.bbox())
            throw ValueError("sources: consecutive densities cover different boxes");
        s = advect(*previous, velocity, dt, advectSettings);
        for (size_t n = 0; n < s.size(); ++n) s.data()[n] = std::max(0.0f, density.data()[n] - s.data()[n]);
        if (region)
            for (size_t n = 0; n < s.size(); ++n)
                if (!(region->data()[n] > 0.0f)) s.data()[n] = 0.0f;
    }
    return s;
}

} // namespace turb
