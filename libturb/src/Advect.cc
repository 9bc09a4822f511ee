// Dense-field advection through OpenVDB's VolumeAdvection. Template-heavy: kept in its own unit.
#include <turb/Advect.h>

#include <turb/Error.h>

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

template<typename T, typename GridT>
Field<T> advectImpl(const Field<T>& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    if (q.empty()) return q;
    if (velocity.empty()) throw ValueError("advect: empty velocity field");
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
        openvdb::tools::Dense<Vec3f, openvdb::tools::LayoutZYX> dense(velocity.bbox(), const_cast<Vec3f*>(velocity.data()));
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

ScalarField advect(const ScalarField& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    return advectImpl<float, openvdb::FloatGrid>(q, velocity, dt, s);
}

VectorField advect(const VectorField& q, const VectorField& velocity, double dt, const AdvectSettings& s)
{
    return advectImpl<Vec3f, openvdb::Vec3SGrid>(q, velocity, dt, s);
}

ScalarField estimateSources(const ScalarField* previous, const ScalarField& density, const VectorField& velocity, double dt,
    const AdvectSettings& advectSettings, const ScalarField* region)
{
    if (density.empty()) throw ValueError("sources: empty density");
    if (region && region->bbox() != density.bbox()) throw ValueError("sources: the region must cover the density's box");
    ScalarField s = density;
    if (previous && !previous->empty()) {
        if (previous->bbox() != density.bbox()) throw ValueError("sources: consecutive densities cover different boxes");
        s = advect(*previous, velocity, dt, advectSettings);
        for (size_t n = 0; n < s.size(); ++n) s.data()[n] = std::max(0.0f, density.data()[n] - s.data()[n]);
        if (region)
            for (size_t n = 0; n < s.size(); ++n)
                if (!(region->data()[n] > 0.0f)) s.data()[n] = 0.0f;
    }
    return s;
}

} // namespace turb
