// Pressure projection through OpenVDB's Poisson solver. Template-heavy (PoissonSolver, ConjGradient,
// Morphology): kept in its own translation unit.
#include <turb/Projection.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/PoissonSolver.h>
#include <openvdb/tree/LeafManager.h>
#include <openvdb/util/NullInterrupter.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace turb {

namespace {

using DoubleField = Field<double>;

std::string boxText(const CoordBBox& b)
{
    std::ostringstream os;
    os << b;
    return os.str();
}

/// Whether cell c takes part in the solve: inside the domain and not solid.
struct FluidTest
{
    CoordBBox cells;
    const MaskField* solid;
    bool operator()(const Coord& c) const
    {
        return cells.isInside(c) && (!solid || (*solid)[c] == 0);
    }
};

/// Runs body(i, j, k) over every voxel of `box`, parallel over x slabs (deterministic: no reductions).
template<typename Fn>
void forEachVoxel(const CoordBBox& box, Fn&& body)
{
    parallelFor(size_t(box.dim().x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int i = box.min().x() + int(x);
            for (int j = box.min().y(); j <= box.max().y(); ++j)
                for (int k = box.min().z(); k <= box.max().z(); ++k) body(i, j, k);
        }
    });
}

/// Divergence in voxel units (sum of face differences) per fluid cell; 0 elsewhere.
DoubleField voxelDivergence(const VectorField& mac, const FluidTest& fluid)
{
    DoubleField d(fluid.cells, mac.lattice());
    forEachVoxel(fluid.cells, [&](int i, int j, int k) {
        if (!fluid(Coord(i, j, k))) return;
        d(i, j, k) = (double(mac(i + 1, j, k)[0]) - double(mac(i, j, k)[0])) +
                     (double(mac(i, j + 1, k)[1]) - double(mac(i, j, k)[1])) +
                     (double(mac(i, j, k + 1)[2]) - double(mac(i, j, k)[2]));
    });
    return d;
}

struct DivStats
{
    double max = 0.0, rms = 0.0, mean = 0.0;
    size_t count = 0;
};

DivStats divStats(const DoubleField& d, const FluidTest& fluid)
{
    const size_t n = d.size();
    const size_t grain = 4096;
    DivStats s;
    s.count = size_t(parallelSum(n, grain, [&](size_t b, size_t e) {
        double c = 0;
        for (size_t q = b; q < e; ++q) c += fluid(d.coordOf(q)) ? 1.0 : 0.0;
        return c;
    }));
    if (s.count == 0) return s;
    const double sum = parallelSum(n, grain, [&](size_t b, size_t e) {
        double a = 0;
        for (size_t q = b; q < e; ++q) a += d.data()[q];
        return a;
    });
    const double sq = parallelSum(n, grain, [&](size_t b, size_t e) {
        double a = 0;
        for (size_t q = b; q < e; ++q) a += d.data()[q] * d.data()[q];
        return a;
    });
    for (size_t q = 0; q < n; ++q) s.max = std::max(s.max, std::abs(d.data()[q]));
    s.mean = sum / double(s.count);
    s.rms = std::sqrt(sq / double(s.count));
    return s;
}

/// Neumann everywhere except Open domain faces, which are Dirichlet p = 0.
struct BoundaryOp
{
    CoordBBox cells;
    std::array<Boundary, 6> faces;

    void operator()(const openvdb::Coord& /*ijk*/, const openvdb::Coord& nb, double& /*source*/, double& diagonal) const
    {
        if (!cells.isInside(nb)) {
            for (int a = 0; a < 3; ++a) {
                if (nb[a] < cells.min()[a] && faces[2 * a] == Boundary::Open) diagonal -= 1.0;
                if (nb[a] > cells.max()[a] && faces[2 * a + 1] == Boundary::Open) diagonal -= 1.0;
            }
        }
        // A solid neighbour inside the box is a wall: the Neumann condition leaves the row alone.
    }
};

/// Turns turb::Progress cancellation into OpenVDB's interrupter protocol.
struct Interrupter : openvdb::util::NullInterrupter
{
    Progress* progress = nullptr;
    bool wasInterrupted(int /*percent*/ = -1) override { return progress && progress->cancelled(); }
};

/// Subtracts the voxel-unit pressure gradient from every face that has fluid on at least one side and
/// is not a wall. The gradient across a face is p(c+) - p(c-): the backward difference at c+
/// (math::ISGradient<math::BD_1ST>), the adjoint of voxelDivergence. Pressure outside an open face is 0.
void subtractGradient(VectorField& mac, const DoubleField& p, const FluidTest& fluid,
    const std::array<Boundary, 6>& faces)
{
    const CoordBBox& cells = fluid.cells;
    forEachVoxel(mac.bbox(), [&](int i, int j, int k) {
        const Coord hi(i, j, k);
        Vec3f& u = mac(i, j, k);
        for (int a = 0; a < 3; ++a) {
            // Only faces of the cell box: the other two coordinates must lie inside it.
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            if (hi[b] > cells.max()[b] || hi[c] > cells.max()[c]) continue;
            Coord lo = hi;
            lo[a] -= 1;
            const bool inLo = fluid(lo), inHi = fluid(hi);
            double g;
            if (inLo && inHi) g = p[hi] - p[lo];
            else if (inHi && lo[a] < cells.min()[a] && faces[2 * a] == Boundary::Open) g = p[hi];
            else if (inLo && hi[a] > cells.max()[a] && faces[2 * a + 1] == Boundary::Open) g = -p[lo];
            else continue; // wall, solid or outside
            u[a] = float(double(u[a]) - g);
        }
    });
}

} // namespace

VectorField macToCentred(const VectorField& mac)
{
    const CoordBBox cells = cellBox(mac.bbox());
    VectorField u(cells, mac.lattice());
    forEachVoxel(cells, [&](int i, int j, int k) {
        u(i, j, k) = Vec3f(0.5f * (mac(i, j, k)[0] + mac(i + 1, j, k)[0]), 0.5f * (mac(i, j, k)[1] + mac(i, j + 1, k)[1]),
            0.5f * (mac(i, j, k)[2] + mac(i, j, k + 1)[2]));
    });
    return u;
}

VectorField centredToMac(const VectorField& centred, const ProjectionSettings& s, const MaskField* solid)
{
    const CoordBBox cells = centred.bbox();
    if (solid && solid->bbox() != cells) throw ValueError("centredToMac: solid mask box differs from the field's");
    const FluidTest fluid{cells, solid};
    VectorField mac(macBox(cells), centred.lattice());
    forEachVoxel(mac.bbox(), [&](int i, int j, int k) {
        const Coord hi(i, j, k);
        for (int a = 0; a < 3; ++a) {
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            if (hi[b] > cells.max()[b] || hi[c] > cells.max()[c]) continue;
            Coord lo = hi;
            lo[a] -= 1;
            const bool inLo = fluid(lo), inHi = fluid(hi);
            float v = 0.0f;
            if (inLo && inHi) v = 0.5f * (centred[lo][a] + centred[hi][a]);
            else if (inHi && lo[a] < cells.min()[a] && s.faces[2 * a] == Boundary::Open) v = centred[hi][a];
            else if (inLo && hi[a] > cells.max()[a] && s.faces[2 * a + 1] == Boundary::Open) v = centred[lo][a];
            mac(i, j, k)[a] = v;
        }
    });
    return mac;
}

ScalarField macDivergence(const VectorField& mac, const MaskField* solid)
{
    const CoordBBox cells = cellBox(mac.bbox());
    if (solid && solid->bbox() != cells) throw ValueError("macDivergence: solid mask box differs from the cell box");
    const DoubleField d = voxelDivergence(mac, FluidTest{cells, solid});
    ScalarField out(cells, mac.lattice());
    const double inv = 1.0 / mac.lattice().voxelSize;
    for (size_t q = 0; q < d.size(); ++q) out.data()[q] = float(d.data()[q] * inv);
    return out;
}

ProjectionResult projectMac(VectorField& mac, const ProjectionSettings& s, const MaskField* solid,
    ScalarField* pressure, Progress* progress)
{
    if (mac.empty()) throw ValueError("projectMac: empty velocity field");
    const CoordBBox cells = cellBox(mac.bbox());
    if (cells.empty()) throw ValueError("projectMac: the MAC box " + boxText(mac.bbox()) + " holds no cell");
    if (solid && solid->bbox() != cells)
        throw ValueError("projectMac: solid mask box " + boxText(solid->bbox()) + " differs from the cell box " +
                         boxText(cells));
    if (!(s.tolerance > 0.0 && s.tolerance < 1.0)) throw ValueError("projectMac: tolerance must lie in (0, 1)");
    if (s.maxIterations < 1) throw ValueError("projectMac: maxIterations must be >= 1");
    const bool warm = pressure && !pressure->empty();
    if (warm && pressure->bbox() != cells)
        throw ValueError("projectMac: pressure box " + boxText(pressure->bbox()) + " differs from the cell box");
    checkCancelled(progress);
    openvdb::initialize();

    const double h = mac.lattice().voxelSize;
    const FluidTest fluid{cells, solid};
    ProjectionResult result;

    DoubleField d = voxelDivergence(mac, fluid);
    const DivStats before = divStats(d, fluid);
    result.divMaxBefore = before.max / h;
    result.divRmsBefore = before.rms / h;

    DoubleField p(cells, mac.lattice());
    if (before.count == 0) {
        result.converged = true;
        if (pressure) *pressure = ScalarField(cells, mac.lattice());
        return result;
    }
    if (warm) {
        // Start from the previous step's pressure: remove its gradient, then solve for the correction.
        for (size_t q = 0; q < p.size(); ++q) p.data()[q] = double(pressure->data()[q]);
        subtractGradient(mac, p, fluid, s.faces);
        d = voxelDivergence(mac, fluid);
    }
    const DivStats start = warm ? divStats(d, fluid) : before;

    // With no open face the Laplacian is singular (pressure is defined up to a constant). The system
    // is consistent when the right-hand side sums to zero, which still walls guarantee up to round-off:
    // remove that round-off mean and let CG find one of the solutions. (Pinning one cell instead makes
    // the matrix regular but so ill-conditioned that OpenVDB's CG stops on its divergence guard.)
    BoundaryOp boundary{cells, s.faces};
    const bool anyOpen = std::any_of(s.faces.begin(), s.faces.end(), [](Boundary b) { return b == Boundary::Open; });
    if (!anyOpen)
        for (size_t q = 0; q < d.size(); ++q)
            if (fluid(d.coordOf(q))) d.data()[q] -= start.mean;

    result.converged = true;
    result.relativeResidual = start.max / before.max;
    if (start.max > s.tolerance * before.max) {
        // Right-hand side: the voxel-unit divergence on the active (fluid) voxels. The solver's
        // Laplacian is the index-space 7-point stencil, so no h^2 factor appears anywhere.
        openvdb::DoubleTree rhs(0.0);
        rhs.denseFill(cells, 0.0, /*active=*/true);
        if (solid)
            for (size_t q = 0; q < solid->size(); ++q)
                if (solid->data()[q]) rhs.setValueOff(solid->coordOf(q), 0.0);
        {
            openvdb::tree::LeafManager<openvdb::DoubleTree> leaves(rhs);
            leaves.foreach([&](openvdb::DoubleTree::LeafNodeType& leaf, size_t) {
                for (auto it = leaf.beginValueOn(); it; ++it) it.setValue(d[it.getCoord()]);
            });
        }

        openvdb::math::pcg::State state = openvdb::math::pcg::terminationDefaults<double>();
        state.iterations = s.maxIterations;
        // Tolerance relative to the input's divergence, also when warm-started from a smaller residual.
        state.absoluteError = s.tolerance * before.max;
        state.relativeError = s.tolerance * before.max / start.max;
        Interrupter interrupter;
        interrupter.progress = progress;
        openvdb::DoubleTree::Ptr solution;
        try {
            if (s.incompleteCholesky) {
                using Pre = openvdb::math::pcg::IncompleteCholeskyPreconditioner<openvdb::tools::poisson::LaplacianMatrix>;
                solution = openvdb::tools::poisson::solveWithBoundaryConditionsAndPreconditioner<Pre>(
                    rhs, boundary, state, interrupter, /*staggered=*/true);
            } else {
                using Pre = openvdb::math::pcg::JacobiPreconditioner<openvdb::tools::poisson::LaplacianMatrix>;
                solution = openvdb::tools::poisson::solveWithBoundaryConditionsAndPreconditioner<Pre>(
                    rhs, boundary, state, interrupter, /*staggered=*/true);
            }
        } catch (const openvdb::RuntimeError&) {
            checkCancelled(progress);
            throw;
        }
        checkCancelled(progress);
        result.iterations = state.iterations;
        result.converged = state.success;
        result.relativeResidual = state.absoluteError / before.max;

        DoubleField dp(cells, mac.lattice());
        openvdb::tools::Dense<double, openvdb::tools::LayoutZYX> dense(cells, dp.data());
        openvdb::tools::copyToDense(*solution, dense);
        subtractGradient(mac, dp, fluid, s.faces);
        for (size_t q = 0; q < p.size(); ++q) p.data()[q] += dp.data()[q];
    }

    const DivStats after = divStats(voxelDivergence(mac, fluid), fluid);
    result.divMaxAfter = after.max / h;
    result.divRmsAfter = after.rms / h;
    if (pressure) {
        *pressure = ScalarField(cells, mac.lattice());
        for (size_t q = 0; q < p.size(); ++q) pressure->data()[q] = float(p.data()[q]);
    }
    return result;
}

ProjectionResult project(VectorField& centred, const ProjectionSettings& s, const MaskField* solid, Progress* progress)
{
    if (centred.empty()) throw ValueError("project: empty velocity field");
    VectorField mac = centredToMac(centred, s, solid);
    const VectorField mac0 = mac;
    const ProjectionResult r = projectMac(mac, s, solid, nullptr, progress);
    const FluidTest fluid{centred.bbox(), solid};
    forEachVoxel(centred.bbox(), [&](int i, int j, int k) {
        if (!fluid(Coord(i, j, k))) return;
        const Coord c(i, j, k);
        for (int a = 0; a < 3; ++a) {
            Coord n = c;
            n[a] += 1;
            const float dLo = mac[c][a] - mac0[c][a], dHi = mac[n][a] - mac0[n][a];
            centred[c][a] += 0.5f * (dLo + dHi);
        }
    });
    return r;
}

} // namespace turb
