// Dense-field advection through OpenVDB's VolumeAdvection. Template-heavy: kept in its own unit.
#include <turb/Advect.h>

#include <turb/Error.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/VolumeAdvect.h>

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
    // Build the grid: activate the box, then write the values (background-valued voxels stay active).
    auto grid = GridT::create(Field<T>::zeroValue());
    grid->tree().denseFill(q.bbox(), Field<T>::zeroValue(), true);
    {
        auto acc = grid->getAccessor();
        const CoordBBox b = q.bbox();
        for (int i = b.min().x(); i <= b.max().x(); ++i)
            for (int j = b.min().y(); j <= b.max().y(); ++j)
                for (int k = b.min().z(); k <= b.max().z(); ++k) acc.setValue(Coord(i, j, k), q(i, j, k));
    }
    grid->setTransform(transformOf(q.lattice()));

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
    // Only voxels inside the box are wanted back: a mask grid stops dilation from growing the work.
    auto mask = openvdb::MaskGrid::create();
    mask->tree().denseFill(q.bbox(), true, true);
    mask->setTransform(grid->transform().copy());
    auto out = adv.template advect<GridT, openvdb::MaskGrid, openvdb::tools::Sampler<1, false>>(*grid, *mask, dt);

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

} // namespace turb
