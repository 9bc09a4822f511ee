// Pressure projection through OpenVDB's Poisson solver. Template-heavy (PoissonSolver, ConjGradient,
// Morphology): kept in its own translation unit.
#include <turb/Projection.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <openvdb/openvdb.h>
#include <openvdb/math/ConjGradient.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/PoissonSolver.h>
#include <openvdb/tree/LeafManager.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <type_traits>
#include <vector>

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
    bool operator()(const Coord& c) const { return cells.isInside(c) && (!solid || (*solid)[c] == 0); }
};

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
    // One pass over fixed chunks, combined in chunk order: the same sums at any thread count.
    struct Part
    {
        double count = 0, sum = 0, sq = 0, max = 0;
    };
    const size_t n = d.size(), grain = 1 << 14;
    std::vector<Part> parts((n + grain - 1) / grain);
    parallelFor(parts.size(), 1, [&](size_t c0, size_t c1) {
        for (size_t c = c0; c < c1; ++c) {
            Part pt;
            for (size_t q = c * grain, e = std::min(n, q + grain); q < e; ++q) {
                const double v = d.data()[q];
                pt.max = std::max(pt.max, std::abs(v));
                if (!fluid(d.coordOf(q))) continue;
                pt.count += 1.0;
                pt.sum += v;
                pt.sq += v * v;
            }
            parts[c] = pt;
        }
    });
    DivStats s;
    double count = 0, sum = 0, sq = 0;
    for (const Part& pt : parts) {
        count += pt.count;
        sum += pt.sum;
        sq += pt.sq;
        s.max = std::max(s.max, pt.max);
    }
    s.count = size_t(count);
    if (s.count == 0) return s;
    s.mean = sum / count;
    s.rms = std::sqrt(sq / count);
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

enum class FaceKind { Interior, OpenBelow, OpenAbove, Closed };

/// Calls fn(i, j, k, a, kind, lo, hi) for every face a of the MAC box `macBox` that bounds the cell box:
/// lo and hi are the cells below and above the face along a, and kind says whether both are fluid, the
/// face is an open boundary below or above the box with fluid inside, or it is closed (wall, solid,
/// outside). One classification for every operator, so their boundary conditions agree.
template<typename Fn>
void forEachMacFace(const CoordBBox& macBox, const FluidTest& fluid, const std::array<Boundary, 6>& faces, Fn&& fn)
{
    const CoordBBox& cells = fluid.cells;
    forEachVoxel(macBox, [&](int i, int j, int k) {
        const Coord hi(i, j, k);
        for (int a = 0; a < 3; ++a) {
            // Only faces of the cell box: the other two coordinates must lie inside it.
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            if (hi[b] > cells.max()[b] || hi[c] > cells.max()[c]) continue;
            Coord lo = hi;
            lo[a] -= 1;
            const bool inLo = fluid(lo), inHi = fluid(hi);
            FaceKind kind = FaceKind::Closed;
            if (inLo && inHi) kind = FaceKind::Interior;
            else if (inHi && lo[a] < cells.min()[a] && faces[2 * a] == Boundary::Open) kind = FaceKind::OpenBelow;
            else if (inLo && hi[a] > cells.max()[a] && faces[2 * a + 1] == Boundary::Open) kind = FaceKind::OpenAbove;
            fn(i, j, k, a, kind, lo, hi);
        }
    });
}

/// Subtracts the voxel-unit pressure gradient from every face that has fluid on at least one side and
/// is not a wall. The gradient across a face is p(c+) - p(c-): the backward difference at c+
/// (math::ISGradient<math::BD_1ST>), the adjoint of voxelDivergence. Pressure outside an open face is 0.
void subtractGradient(
    VectorField& mac, const DoubleField& p, const FluidTest& fluid, const std::array<Boundary, 6>& faces)
{
    forEachMacFace(
        mac.bbox(), fluid, faces, [&](int i, int j, int k, int a, FaceKind kind, const Coord& lo, const Coord& hi) {
            double g;
            switch (kind) {
            case FaceKind::Interior: g = p[hi] - p[lo]; break;
            case FaceKind::OpenBelow: g = p[hi]; break;
            case FaceKind::OpenAbove: g = -p[lo]; break;
            default: return; // wall, solid or outside
            }
            Vec3f& u = mac(i, j, k);
            u[a] = float(double(u[a]) - g);
        });
}

} // namespace

VectorField macToCentred(const VectorField& mac)
{
    const CoordBBox cells = cellBox(mac.bbox());
    VectorField u(cells, mac.lattice());
    forEachVoxel(cells, [&](int i, int j, int k) {
        u(i, j, k) = Vec3f(0.5f * (mac(i, j, k)[0] + mac(i + 1, j, k)[0]),
            0.5f * (mac(i, j, k)[1] + mac(i, j + 1, k)[1]), 0.5f * (mac(i, j, k)[2] + mac(i, j, k + 1)[2]));
    });
    return u;
}

VectorField centredToMac(const VectorField& centred, const ProjectionSettings& s, const MaskField* solid)
{
    const CoordBBox cells = centred.bbox();
    if (solid && solid->bbox() != cells) throw ValueError("centredToMac: solid mask box differs from the field's");
    const FluidTest fluid{cells, solid};
    VectorField mac(macBox(cells), centred.lattice());
    forEachMacFace(
        mac.bbox(), fluid, s.faces, [&](int i, int j, int k, int a, FaceKind kind, const Coord& lo, const Coord& hi) {
            float v = 0.0f;
            switch (kind) {
            case FaceKind::Interior: v = 0.5f * (centred[lo][a] + centred[hi][a]); break;
            case FaceKind::OpenBelow: v = centred[hi][a]; break;
            case FaceKind::OpenAbove: v = centred[lo][a]; break;
            case FaceKind::Closed: break;
            }
            mac(i, j, k)[a] = v;
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

namespace {

/// What one conjugate-gradient solve did.
struct PcgOutcome
{
    bool converged = false;
    int iterations = 0;
    double residual = 0.0; ///< max|b - Ax| at the end, voxel units
};

} // namespace

// ---- MacProjector

struct MacProjector::Impl
{
    using Matrix = openvdb::tools::poisson::LaplacianMatrix;
    using Vector = openvdb::math::pcg::Vector<double>;

    CoordBBox cells;
    ProjectionSettings settings;
    MaskField solid; // empty: no solid cell

    // Built on the first solve (build()): the matrix row of each cell (dense offset over `cells`; -1 for
    // solid cells), the negated Laplacian (positive definite, as OpenVDB's solver negates it) and its
    // preconditioner.
    std::vector<std::int32_t> row;
    Matrix::Ptr matrix;
    openvdb::math::pcg::Preconditioner<double>::Ptr preconditioner;

    FluidTest fluid() const { return FluidTest{cells, solid.empty() ? nullptr : &solid}; }

    size_t offset(const Coord& c) const
    {
        const Coord d = cells.dim();
        return (size_t(c.x() - cells.min().x()) * size_t(d.y()) + size_t(c.y() - cells.min().y())) * size_t(d.z()) +
               size_t(c.z() - cells.min().z());
    }

    /// The same steps as tools::poisson::solveWithBoundaryConditionsAndPreconditioner (index tree, interior
    /// mask, staggered Laplacian with the boundary op, preconditioner with its Jacobi fallback), kept
    /// instead of rebuilt on every solve.
    /// Preconditioned conjugate gradient on the matrix and preconditioner built by build(), from the
    /// initial guess in `x`, until max|b - Ax| <= `absTol` or `maxIt` iterations. OpenVDB's math::pcg::solve
    /// runs the same recurrence but also stops when the L2 residual exceeds twice its smallest value so far,
    /// taking that for divergence. On an SPD matrix CG cannot diverge (the error's energy norm falls every
    /// iteration) while its L2 residual may rise: on 2D problems (one z layer, both z faces closed) with
    /// wall faces it rose past that guard after 30-90 iterations, leaving max|div| at 1e-3..1e-2 of the
    /// input. Here only non-finite values stop early. `singular` (no open face): the constant null space is
    /// removed from the preconditioned residual every iteration, so round-off cannot grow in it.
    PcgOutcome solve(const Vector& b, Vector& x, double absTol, int maxIt, bool singular, Progress* progress) const
    {
        const size_t n = b.size(), grain = 1 << 14;
        Vector r(n), z(n), p(n, 0.0), q(n);
        matrix->vectorMultiply(x, q);
        parallelFor(n, grain, [&](size_t i0, size_t i1) {
            for (size_t i = i0; i < i1; ++i) r[i] = b[i] - q[i];
        });
        PcgOutcome out;
        out.residual = r.infNorm();
        double rz = 0.0;
        for (int it = 0; it < maxIt && out.residual > absTol; ++it) {
            checkCancelled(progress);
            preconditioner->apply(r, z);
            if (singular) removeMean(z);
            const double rzNew = r.dot(z);
            const double beta = it == 0 ? 0.0 : rzNew / rz;
            rz = rzNew;
            parallelFor(n, grain, [&](size_t i0, size_t i1) {
                for (size_t i = i0; i < i1; ++i) p[i] = it == 0 ? z[i] : z[i] + beta * p[i];
            });
            matrix->vectorMultiply(p, q);
            const double pq = p.dot(q);
            if (!(std::isfinite(pq) && pq > 0.0 && std::isfinite(rz))) break; // breakdown: keep the last iterate
            const double alpha = rz / pq;
            parallelFor(n, grain, [&](size_t i0, size_t i1) {
                for (size_t i = i0; i < i1; ++i) {
                    x[i] += alpha * p[i];
                    r[i] -= alpha * q[i];
                }
            });
            out.iterations = it + 1;
            out.residual = r.infNorm();
            if (!std::isfinite(out.residual)) break;
        }
        out.converged = out.residual <= absTol;
        return out;
    }

    static void removeMean(Vector& v)
    {
        const Vector ones(v.size(), 1.0);
        const double mean = v.dot(ones) / double(std::max<size_t>(1, v.size()));
        parallelFor(v.size(), 1 << 14, [&](size_t i0, size_t i1) {
            for (size_t i = i0; i < i1; ++i) v[i] -= mean;
        });
    }

    void build()
    {
        using BoolTree = openvdb::BoolTree;
        BoolTree domain(false);
        domain.denseFill(cells, true, /*active=*/true);
        if (!solid.empty())
            for (size_t q = 0; q < solid.size(); ++q)
                if (solid.data()[q]) domain.setValueOff(solid.coordOf(q), false);
        const auto index = openvdb::tools::poisson::createIndexTree(domain);
        BoolTree interior(*index, /*background=*/false, openvdb::TopologyCopy());
        openvdb::tools::erodeActiveValues(interior, 1, openvdb::tools::NN_FACE, openvdb::tools::IGNORE_TILES);
        const auto rows = openvdb::math::pcg::SizeType(index->activeVoxelCount());
        Vector source(rows, 0.0); // BoundaryOp leaves the source alone: the matrix depends on the domain only
        const BoundaryOp boundary{cells, settings.faces};
        matrix = openvdb::tools::poisson::createISLaplacianWithBoundaryConditions(
            *index, interior, boundary, source, /*staggered=*/true);
        matrix->scale(-1.0);
        if (settings.incompleteCholesky)
            preconditioner.reset(new openvdb::math::pcg::IncompleteCholeskyPreconditioner<Matrix>(*matrix));
        // Incomplete Cholesky breaks down on the singular all-Neumann Laplacian: fall back to Jacobi, as
        // OpenVDB's solver does.
        if (!preconditioner || !preconditioner->isValid())
            preconditioner.reset(new openvdb::math::pcg::JacobiPreconditioner<Matrix>(*matrix));

        row.assign(size_t(cells.volume()), -1);
        openvdb::tree::LeafManager<const std::remove_reference_t<decltype(*index)>> leaves(*index);
        leaves.foreach ([&](const auto& leaf, size_t) {
            for (auto it = leaf.cbeginValueOn(); it; ++it) row[offset(it.getCoord())] = std::int32_t(*it);
        });
    }
};

MacProjector::MacProjector(const CoordBBox& cells, const ProjectionSettings& s, const MaskField* solid)
    : mImpl(std::make_unique<Impl>())
{
    if (cells.empty()) throw ValueError("projection: the cell box " + boxText(cells) + " is empty");
    if (solid && solid->bbox() != cells)
        throw ValueError(
            "projection: solid mask box " + boxText(solid->bbox()) + " differs from the cell box " + boxText(cells));
    if (!(s.tolerance > 0.0 && s.tolerance < 1.0)) throw ValueError("projection: tolerance must lie in (0, 1)");
    if (s.maxIterations < 1) throw ValueError("projection: maxIterations must be >= 1");
    mImpl->cells = cells;
    mImpl->settings = s;
    if (solid && std::any_of(solid->values().begin(), solid->values().end(), [](std::uint8_t v) { return v != 0; }))
        mImpl->solid = *solid;
}

MacProjector::MacProjector(const MacProjector& other) : mImpl(std::make_unique<Impl>())
{
    mImpl->cells = other.mImpl->cells;
    mImpl->settings = other.mImpl->settings;
    mImpl->solid = other.mImpl->solid;
}

MacProjector& MacProjector::operator=(const MacProjector& other)
{
    if (this != &other) *this = MacProjector(other);
    return *this;
}

MacProjector::MacProjector(MacProjector&&) noexcept = default;
MacProjector& MacProjector::operator=(MacProjector&&) noexcept = default;
MacProjector::~MacProjector() = default;

const CoordBBox& MacProjector::cells() const { return mImpl->cells; }
const ProjectionSettings& MacProjector::settings() const { return mImpl->settings; }

ProjectionResult MacProjector::project(VectorField& mac, ScalarField* pressure, Progress* progress)
{
    Impl& m = *mImpl;
    const CoordBBox& cells = m.cells;
    const ProjectionSettings& s = m.settings;
    if (mac.empty() || mac.bbox() != macBox(cells))
        throw ValueError(
            "projection: velocity box " + boxText(mac.bbox()) + " is not the MAC box of the cells " + boxText(cells));
    const bool warm = pressure && !pressure->empty();
    if (warm && pressure->bbox() != cells)
        throw ValueError("projection: pressure box " + boxText(pressure->bbox()) + " differs from the cell box");
    checkCancelled(progress);
    openvdb::initialize();

    const double h = mac.lattice().voxelSize;
    const FluidTest fluid = m.fluid();
    ProjectionResult result;

    DoubleField d = voxelDivergence(mac, fluid);
    const DivStats before = divStats(d, fluid);
    result.divMaxBefore = before.max / h;
    result.divRmsBefore = before.rms / h;
    if (before.count == 0 || before.max == 0.0) {
        // Nothing to remove: p = 0 is a solution.
        result.converged = true;
        result.divMaxAfter = result.divMaxBefore;
        result.divRmsAfter = result.divRmsBefore;
        if (pressure) *pressure = ScalarField(cells, mac.lattice());
        return result;
    }

    // With no open face the Laplacian is singular (pressure is defined up to a constant). The system
    // is consistent when the right-hand side sums to zero, which still walls guarantee up to round-off:
    // remove that round-off mean and let CG find one of the solutions. (Pinning one cell instead makes
    // the matrix regular but so ill-conditioned that OpenVDB's CG stops on its divergence guard.)
    const bool anyOpen = std::any_of(s.faces.begin(), s.faces.end(), [](Boundary b) { return b == Boundary::Open; });
    const double mean = anyOpen ? 0.0 : before.mean;

    if (!m.matrix) m.build();
    const size_t n = d.size(), grain = 1 << 14;
    // Right-hand side: minus the voxel-unit divergence, because the matrix is the negated index-space
    // 7-point Laplacian (no h^2 factor anywhere). Initial guess: the previous pressure (warm start).
    Impl::Vector b(m.matrix->numRows(), 0.0), x(m.matrix->numRows(), 0.0);
    parallelFor(n, grain, [&](size_t q0, size_t q1) {
        for (size_t q = q0; q < q1; ++q) {
            const std::int32_t r = m.row[q];
            if (r < 0) continue;
            b[r] = -(d.data()[q] - mean);
            if (warm) x[r] = double(pressure->data()[q]);
        }
    });

    const PcgOutcome st = m.solve(b, x, s.tolerance * before.max, s.maxIterations, !anyOpen, progress);
    result.iterations = st.iterations;
    result.converged = st.converged;
    result.relativeResidual = st.residual / before.max;

    DoubleField p(cells, mac.lattice());
    parallelFor(n, grain, [&](size_t q0, size_t q1) {
        for (size_t q = q0; q < q1; ++q)
            if (m.row[q] >= 0) p.data()[q] = x[m.row[q]];
    });
    subtractGradient(mac, p, fluid, s.faces);

    const DivStats after = divStats(voxelDivergence(mac, fluid), fluid);
    result.divMaxAfter = after.max / h;
    result.divRmsAfter = after.rms / h;
    if (pressure) {
        *pressure = ScalarField(cells, mac.lattice());
        parallelFor(n, grain, [&](size_t q0, size_t q1) {
            for (size_t q = q0; q < q1; ++q) pressure->data()[q] = float(p.data()[q]);
        });
    }
    return result;
}

ProjectionResult projectMac(
    VectorField& mac, const ProjectionSettings& s, const MaskField* solid, ScalarField* pressure, Progress* progress)
{
    if (mac.empty()) throw ValueError("projectMac: empty velocity field");
    const CoordBBox cells = cellBox(mac.bbox());
    if (cells.empty()) throw ValueError("projectMac: the MAC box " + boxText(mac.bbox()) + " holds no cell");
    if (solid && solid->bbox() != cells)
        throw ValueError(
            "projectMac: solid mask box " + boxText(solid->bbox()) + " differs from the cell box " + boxText(cells));
    if (!(s.tolerance > 0.0 && s.tolerance < 1.0)) throw ValueError("projectMac: tolerance must lie in (0, 1)");
    if (s.maxIterations < 1) throw ValueError("projectMac: maxIterations must be >= 1");
    if (pressure && !pressure->empty() && pressure->bbox() != cells)
        throw ValueError("projectMac: pressure box " + boxText(pressure->bbox()) + " differs from the cell box");
    MacProjector projector(cells, s, solid);
    return projector.project(mac, pressure, progress);
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
