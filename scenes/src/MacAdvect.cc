// Advection of the smoke state through OpenVDB's VolumeAdvection.
// Template-heavy: kept in its own translation unit.
#include "MacAdvect.h"

#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/VolumeAdvect.h>

namespace turb {
namespace scenes {
namespace detail {

namespace {

using openvdb::math::Transform;

/// The transform of a grid whose voxel (0,0,0) sits `shift` voxels away from the lattice's voxel
/// (0,0,0): face components of a MAC field sit half a voxel below their cell along their axis.
Transform::Ptr transformOf(const Lattice& l, const Vec3d& shift)
{
    auto xf = Transform::createLinearTransform(l.voxelSize);
    xf->postTranslate(l.origin + shift * l.voxelSize);
    return xf;
}

openvdb::tools::Scheme::SemiLagrangian toVdb(AdvectSettings::Scheme s)
{
    switch (s) {
    case AdvectSettings::Scheme::SemiLagrangian: return openvdb::tools::Scheme::SEMI;
    case AdvectSettings::Scheme::MacCormack: return openvdb::tools::Scheme::MAC;
    case AdvectSettings::Scheme::BFECC: return openvdb::tools::Scheme::BFECC;
    }
    return openvdb::tools::Scheme::MAC;
}

/// The velocity VolumeAdvection needs for the grid on `box` whose voxels sit half a voxel below the
/// cells along `axis` (a face component), or at the cell centres (axis = -1), as a collocated grid on
/// that same lattice.
///
/// Every scheme here (semi-Lagrangian, MacCormack, BFECC and the limiter) traces with one explicit Euler
/// step, which samples the velocity only at the advected grid's own voxel positions. At those positions
/// the staggered trilinear sample of the MAC field reduces to a mean of 1, 2 or 4 face values, so storing
/// that mean gives the same departure points as VolumeAdvection<Vec3SGrid, /*staggered=*/true> on the MAC
/// grid (up to round-off), while each velocity sample reads 8 values instead of the staggered sampler's
/// 24 and is taken once per grid instead of once per pass. The MAC field is 0 outside its box, as the
/// staggered grid's background was.
openvdb::Vec3SGrid::Ptr collocatedVelocity(const VectorField& mac, const CoordBBox& box, int axis, Transform::Ptr xf)
{
    const CoordBBox& mb = mac.bbox();
    const auto u = [&](int c, int i, int j, int k) { return mb.isInside(Coord(i, j, k)) ? mac(i, j, k)[c] : 0.0f; };
    std::vector<Vec3f> dense(size_t(box.volume()));
    const size_t dy = size_t(box.dim().y()), dz = size_t(box.dim().z());
    forEachVoxel(box, [&](int i, int j, int k) {
        Vec3f v;
        for (int c = 0; c < 3; ++c) {
            const int ec[3] = {c == 0, c == 1, c == 2};
            if (axis < 0) {
                // Cell centre: the two faces of the cell along c.
                v[c] = 0.5f * (u(c, i, j, k) + u(c, i + ec[0], j + ec[1], k + ec[2]));
            } else if (c == axis) {
                v[c] = u(c, i, j, k); // the face's own component
            } else {
                // Face of axis a: the four c-faces around it (cells ijk and ijk - e_a, sides 0 and +e_c).
                const int ea[3] = {axis == 0, axis == 1, axis == 2};
                v[c] = 0.25f *
                       (u(c, i, j, k) + u(c, i - ea[0], j - ea[1], k - ea[2]) + u(c, i + ec[0], j + ec[1], k + ec[2]) +
                           u(c, i - ea[0] + ec[0], j - ea[1] + ec[1], k - ea[2] + ec[2]));
            }
        }
        dense[(size_t(i - box.min().x()) * dy + size_t(j - box.min().y())) * dz + size_t(k - box.min().z())] = v;
    });
    auto grid = openvdb::Vec3SGrid::create(Vec3f(0.0f));
    grid->setTransform(xf);
    openvdb::tools::Dense<Vec3f, openvdb::tools::LayoutZYX> d(box, dense.data());
    openvdb::tools::copyFromDense(d, *grid, Vec3f(0.0f));
    return grid;
}

/// Copies two ghost layers outside each closed face from the edge voxels, so that values sampled
/// just beyond a wall are the wall's own (nothing flows in) instead of the zero background.
void addGhosts(openvdb::FloatGrid& grid, const CoordBBox& box, const std::array<Boundary, 6>& faces)
{
    auto acc = grid.getAccessor();
    for (int a = 0; a < 3; ++a) {
        const int b = (a + 1) % 3, c = (a + 2) % 3;
        for (int side = 0; side < 2; ++side) {
            if (faces[2 * a + side] != Boundary::Closed) continue;
            const int edge = side ? box.max()[a] : box.min()[a];
            const int dir = side ? 1 : -1;
            Coord e, g;
            for (int u = box.min()[b]; u <= box.max()[b]; ++u)
                for (int v = box.min()[c]; v <= box.max()[c]; ++v) {
                    e[a] = edge;
                    e[b] = u;
                    e[c] = v;
                    const float value = acc.getValue(e);
                    if (value == 0.0f) continue;
                    g = e;
                    for (int layer = 1; layer <= 2; ++layer) {
                        g[a] = edge + dir * layer;
                        acc.setValue(g, value);
                    }
                }
        }
    }
}

using Advection = openvdb::tools::VolumeAdvection<openvdb::Vec3SGrid, /*staggered=*/false>;

/// Advects `values` (dense, z-fastest over `box`, on the velocity grid's transform) in place.
void advectDense(float* values, const CoordBBox& box, Advection& adv, Transform::Ptr xf, double dt, int reach,
    const std::array<Boundary, 6>& faces)
{
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setTransform(xf);
    {
        openvdb::tools::Dense<float, openvdb::tools::LayoutZYX> dense(box, values);
        openvdb::tools::copyFromDense(dense, *grid, 0.0f); // exact zeros stay inactive (sparse)
    }
    addGhosts(*grid, box, faces);
    // VolumeAdvection only computes voxels within its face-neighbour (L1) dilation of the input's active
    // set by ceil(travel), but trilinear backtraces reach diagonal neighbours too: voxels left out would
    // stay 0 and smoke would vanish (measured: 17-43% of a closed box's mass in 48 frames). Activating
    // every voxel within `reach` in all 26 directions first makes the computed set cover all of them.
    if (reach > 0)
        openvdb::tools::dilateActiveValues(
            grid->tree(), reach, openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::EXPAND_TILES);
    auto mask = openvdb::MaskGrid::create(false);
    mask->setTransform(xf->copy());
    mask->tree().fill(box, true, true);

    auto out = adv.advect<openvdb::FloatGrid, openvdb::MaskGrid, openvdb::tools::Sampler<1, false>>(*grid, *mask, dt);

    openvdb::tools::Dense<float, openvdb::tools::LayoutZYX> dense(box, values);
    openvdb::tools::copyToDense(*out, dense);
}

} // namespace

void advectMac(VectorField& mac, const std::vector<ScalarField*>& scalars, double dt, const MacAdvectSettings& s)
{
    openvdb::initialize();
    const Lattice& lat = mac.lattice();
    const CoordBBox cells = cellBox(mac.bbox());

    // Voxels a backtrace can reach: the travel (fastest face component along all three axes at once)
    // plus the interpolation stencil.
    float fastest = 0.0f;
    for (const auto& v : mac.values())
        fastest = std::max(fastest, std::max(std::abs(v.x()), std::max(std::abs(v.y()), std::abs(v.z()))));
    const int reach = int(std::ceil(double(fastest) * std::abs(dt) / lat.voxelSize)) + 1;
    // REVERT falls back to the semi-Lagrangian value where MacCormack/BFECC leave the range of the
    // backtrace's 8 neighbours; CLAMP snaps to that range, which leaves voxel staircases on diagonal
    // fronts (seen on the wind scene's plume).
    const auto limiter = s.revert ? openvdb::tools::Scheme::REVERT : openvdb::tools::Scheme::CLAMP;
    // VolumeAdvection's default grain (128 leaves per task) runs a 32^3 grid (about 100 leaves) on one
    // thread; results do not depend on the grain.
    const size_t grain = 8;

    // Every field is advected by the velocity as it was on entry: the velocity grids are built before
    // any face component changes.
    std::vector<openvdb::Vec3SGrid::Ptr> faceVelocity(3);
    std::vector<Transform::Ptr> faceXf(3);
    for (int a = 0; a < 3; ++a) {
        Vec3d shift(0.0);
        shift[a] = -0.5;
        faceXf[a] = transformOf(lat, shift);
        faceVelocity[a] = collocatedVelocity(mac, mac.bbox(), a, faceXf[a]);
    }

    if (std::any_of(scalars.begin(), scalars.end(), [](const ScalarField* f) { return f && !f->empty(); })) {
        const Transform::Ptr xf = transformOf(lat, Vec3d(0.0));
        const auto velocity = collocatedVelocity(mac, cells, -1, xf);
        Advection adv(*velocity);
        adv.setIntegrator(toVdb(s.scalarScheme));
        adv.setLimiter(limiter);
        adv.setSubSteps(1);
        adv.setGrainSize(grain);
        for (ScalarField* f : scalars) {
            if (!f || f->empty()) continue;
            advectDense(f->data(), cells, adv, xf, dt, reach, s.faces);
        }
    }

    // Each face component is a scalar field on its own staggered lattice.
    std::vector<float> component(mac.size());
    const size_t n = mac.size(), chunk = 1 << 16;
    for (int a = 0; a < 3; ++a) {
        parallelFor(n, chunk, [&](size_t b, size_t e) {
            for (size_t q = b; q < e; ++q) component[q] = mac.data()[q][a];
        });
        Advection adv(*faceVelocity[a]);
        adv.setIntegrator(toVdb(s.velocityScheme));
        adv.setLimiter(limiter);
        adv.setSubSteps(1);
        adv.setGrainSize(grain);
        advectDense(component.data(), mac.bbox(), adv, faceXf[a], dt, reach, s.faces);
        faceVelocity[a].reset();
        parallelFor(n, chunk, [&](size_t b, size_t e) {
            for (size_t q = b; q < e; ++q) mac.data()[q][a] = component[q];
        });
    }
}

} // namespace detail
} // namespace scenes
} // namespace turb
