/// @file Projection.h
/// @brief Pressure projection: the divergence-free part of a velocity field (Helmholtz–Hodge), solved
///        with OpenVDB's Poisson solver (tools/PoissonSolver.h, incomplete-Cholesky PCG).
///
/// The solve happens on a MAC (staggered) grid, where the discrete divergence and the pressure
/// gradient are exact adjoints: divergence is the forward difference of face velocities over a cell,
/// the gradient is the backward difference of cell pressures across a face (OpenVDB's
/// math::ISGradient<math::BD_1ST>). Mixing a one-sided divergence with a central gradient is the
/// pitfall reuse.md measured (max |div| 0.6 left behind); with adjoint stencils the result is
/// divergence-free to the solver tolerance, and ProjectionResult reports it measured after the update.
///
/// MAC layout (OpenVDB's and Blender's staggered convention): for a box of cells C the MAC field
/// covers macBox(C), which is C grown by one voxel at its max corner; component a of voxel ijk is the
/// velocity through the face at ijk - e_a / 2. Values in the extra layer that are not faces of C are
/// ignored.
///
/// Boundaries: each domain face is Open (pressure 0 outside: flow may leave or enter) or Closed (a
/// wall: the normal velocity on it is kept as given, 0 for a still wall). Solid cells (obstacles) are
/// walls too. Units: velocities in world units per time; divergence reported in 1/time.
///
/// @code
/// turb::ProjectionSettings s;
/// s.faces[turb::kFaceZMin] = turb::Boundary::Closed;     // a floor
/// turb::ProjectionResult r = turb::projectMac(mac, s);    // mac is now divergence-free
/// // r.divMaxAfter / r.divMaxBefore <= s.tolerance when r.converged
/// @endcode
#pragma once

#include <turb/Field.h>
#include <turb/Progress.h>

#include <array>
#include <cstdint>
#include <memory>

namespace turb {

/// Per-cell flags; nonzero marks a solid (obstacle) cell.
using MaskField = Field<std::uint8_t>;

enum class Boundary {
    Open,  ///< pressure 0 outside (Dirichlet): flow crosses freely
    Closed ///< wall (Neumann): the normal velocity on the face is left as given
};

/// Index of a domain face in ProjectionSettings::faces: 2*axis + (max side ? 1 : 0).
enum DomainFace { kFaceXMin = 0, kFaceXMax, kFaceYMin, kFaceYMax, kFaceZMin, kFaceZMax };

struct ProjectionSettings
{
    /// Stop when max|div| <= tolerance * max|div of the input| (the solver's discrete divergence,
    /// infinity norm); in (0, 1).
    double tolerance = 1e-5;
    /// Conjugate-gradient iteration cap, >= 1. Reaching it is reported, not thrown.
    int maxIterations = 2000;
    /// Boundary type of the six domain faces (-x, +x, -y, +y, -z, +z; see DomainFace).
    std::array<Boundary, 6> faces{
        Boundary::Open, Boundary::Open, Boundary::Open, Boundary::Open, Boundary::Open, Boundary::Open};
    /// Incomplete-Cholesky preconditioner (true: fewer iterations) or Jacobi (false).
    bool incompleteCholesky = true;
};

/// What a projection did: solver outcome and the divergence measured before and after the update.
struct ProjectionResult
{
    bool converged = false;        ///< the solver reached the tolerance
    int iterations = 0;            ///< conjugate-gradient iterations
    double relativeResidual = 0.0; ///< solver's max|residual| / max|input divergence|
    double divMaxBefore = 0.0;     ///< max |div u| over fluid cells before, 1/time (MAC divergence)
    double divMaxAfter = 0.0;      ///< the same after the update, measured on the updated faces
    double divRmsBefore = 0.0;     ///< rms of div u over fluid cells before, 1/time
    double divRmsAfter = 0.0;      ///< rms after
    /// divMaxAfter / divMaxBefore (0 when the input was already divergence-free).
    double relativeDivergence() const { return divMaxBefore > 0.0 ? divMaxAfter / divMaxBefore : 0.0; }
};

/// The MAC box of a cell box (grown by one voxel at the max corner), and back.
inline CoordBBox macBox(const CoordBBox& cells) { return CoordBBox(cells.min(), cells.max().offsetBy(1)); }
inline CoordBBox cellBox(const CoordBBox& mac) { return CoordBBox(mac.min(), mac.max().offsetBy(-1)); }

/// Cell-centred velocity from a MAC field: the mean of each cell's two faces per axis.
VectorField macToCentred(const VectorField& mac);

/// MAC field from a cell-centred velocity: interior faces average their two cells; a face on an Open
/// domain face takes its cell's value, on a Closed one (or next to a solid cell) 0.
VectorField centredToMac(
    const VectorField& centred, const ProjectionSettings& s = {}, const MaskField* solid = nullptr);

/// The MAC (solver's) divergence per cell in 1/time; 0 in solid cells. Covers cellBox(mac.bbox()).
ScalarField macDivergence(const VectorField& mac, const MaskField* solid = nullptr);

/// Projection onto divergence-free MAC fields of one fixed domain, for solvers that project every time
/// step. The solver's matrix (OpenVDB's staggered Laplacian from
/// tools::poisson::createISLaplacianWithBoundaryConditions) and its preconditioner depend only on the cell
/// box, the solid cells and the boundary types, so they are built on the first solve and reused; each
/// project() then runs preconditioned conjugate gradient (math::pcg::solve's recurrence without its
/// divergence guard, which stopped 2D solves with walls early) on that matrix,
/// warm-started from `pressure`. At 128x128x192 building them costs about as much as 15 incomplete-Cholesky
/// iterations. Copies share nothing: a copy rebuilds its own matrix on its first solve.
///
/// @code
/// turb::MacProjector projector(cells, settings, &solid);   // cheap: nothing is built yet
/// turb::ScalarField pressure;
/// for (...) { advect(mac); projector.project(mac, &pressure); }
/// @endcode
class MacProjector
{
public:
    /// Throws ValueError on an empty box, settings out of range, or a solid mask whose box is not `cells`.
    explicit MacProjector(const CoordBBox& cells, const ProjectionSettings& s = {}, const MaskField* solid = nullptr);
    MacProjector(const MacProjector& other);
    MacProjector& operator=(const MacProjector& other);
    MacProjector(MacProjector&&) noexcept;
    MacProjector& operator=(MacProjector&&) noexcept;
    ~MacProjector();

    /// As projectMac() with this projector's settings and solid mask; `mac` must cover macBox(cells).
    ProjectionResult project(VectorField& mac, ScalarField* pressure = nullptr, Progress* progress = nullptr);

    const CoordBBox& cells() const;
    const ProjectionSettings& settings() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

/// Makes a MAC velocity divergence-free in place. `solid` (optional) covers cellBox(mac.bbox()).
/// `pressure` (optional, in/out): when it holds a field over the cell box it is used as the initial
/// guess (warm start between time steps); on return it holds the pressure potential p, in velocity
/// times voxels, with u_new = u - (p(c+) - p(c-)) on each face. Throws ValueError on mismatched boxes,
/// Cancelled when `progress` asks to stop. Builds the solver's matrix and preconditioner for this one
/// call: to project many fields of one domain, keep a MacProjector.
ProjectionResult projectMac(VectorField& mac, const ProjectionSettings& s = {}, const MaskField* solid = nullptr,
    ScalarField* pressure = nullptr, Progress* progress = nullptr);

/// What removeCentralDivergence did; divergences in 1/time, rms over the field's box.
struct CentralDivergenceResult
{
    bool converged = false;    ///< the remaining divergence is within the tolerance
    int iterations = 0;        ///< conjugate-gradient iterations
    double divRmsBefore = 0.0; ///< rms central-difference divergence before
    double divRmsAfter = 0.0;  ///< and after (of the stored floats)
};

/// Takes the gradient part out of a cell-centred field so that its central-difference divergence,
/// sum_a (u_a(c + e_a) - u_a(c - e_a)) / (2 h) with u zero outside its box, is zero to `tolerance` (rms, relative to
/// the field's own): u -= G psi, G the central gradient (psi also zero outside the box), psi from the normal
/// equations G^T G psi = G^T u by conjugate gradient (Eigen, matrix-free; -G^T is that divergence, so the CG
/// residual is the divergence left). This is the divergence `measure`'s div_rel counts in the box's interior
/// (it differences one-sidedly on the outermost layer), which a MAC projection (projectCentred) only reduces.
/// Where u is zero near the box faces (a detail field faded out in air) the two agree everywhere. Axes one voxel
/// long are left out (2D). Deterministic at any thread count. Throws ValueError for a tolerance outside (0, 1) or
/// maxIterations < 1; not converging is reported, not thrown.
CentralDivergenceResult removeCentralDivergence(VectorField& u, double tolerance = 1e-3, int maxIterations = 1000);

/// Projection of a cell-centred field (Helmholtz–Hodge): the field is averaged to faces, projected on
/// the MAC grid, and each cell receives the mean of its faces' corrections, so the field's own detail
/// is never smoothed. The result's divergences are those of the intermediate MAC field; the
/// central-difference divergence of the cell-centred result is reduced, not zeroed (measure it with
/// relativeDivergence() in Measure.h, div_rel of docs/measure.md).
ProjectionResult project(VectorField& centred, const ProjectionSettings& s = {}, const MaskField* solid = nullptr,
    Progress* progress = nullptr);

} // namespace turb
