/// @file Seams.h
/// @brief Seam smoothing between pasted patches (Sato et al., "Example-based Synthesis of Turbulence by Flow Field
/// Style Transfer", section 3.3).
///
/// Ω is a band of `bandWidth` voxels on each side of every border between local patches where at
/// least one side carries detail. An EM loop alternates:
/// - E-step: minimise  sum_edges |X(q) - X(p) - g(p,q)|^2 + gamma * sum_v (div X)(v)^2  over X in Ω,
///   X fixed (the pasted field) outside Ω, by conjugate gradients on the normal equations (CGNR).
///   g is the average, over the boundary patches covering an edge, of the chosen patch Z's difference;
///   div is the central difference the quality metric `div_rel` uses.
/// - M-step: for each C^3 boundary patch (C^2 x 1 on a 2D layout) straddling a border, pick Z among the continuations
/// of the
///   neighbouring local patches' source matches on U_sh, minimising |grad X - grad Z|^2.
/// It stops when the energy changes by less than `emTolerance` (relative).
///
/// Differences are taken in grid units; gamma is therefore resolution independent.
#pragma once

#include <turb/Field.h>
#include <turb/Progress.h>

#include <cstdint>
#include <vector>

namespace turb {

/// How the E-step solves its least-squares system.
enum class SeamSolver {
    Cgnr,      ///< matrix-free conjugate gradients on the normal equations, in float with double sums (the default)
    EigenLscg, ///< the same rows assembled as a sparse matrix (double) and solved by Eigen's
               ///< LeastSquaresConjugateGradient with its diagonal (column-norm) preconditioner; same iteration cap and
               ///< relative residual |A^T r| / |A^T r0|; measured against Cgnr in docs/performance.md
};

struct SeamSettings
{
    bool enabled = true;       ///< false pastes patches without smoothing (ablation)
    int bandWidth = 2;         ///< Ω half-width: voxels on each side of a patch border, >= 1
    int bandWidth2D = 3;       ///< the same on a 2D (flat) layout, >= 1: with 8-voxel patches a 3-voxel band covers
                               ///< 94% of a B^2 patch, about the 88% a 2-voxel band covers of a B^3 one (measured on
                               ///< the built-in 2D pair: div_rel 0.04 and block <= 1.02, against 0.08 and 1.08 at 2)
    int boundaryPatch = 0;     ///< C: boundary patch edge (even); 0 = the local patch size B
    float gamma = 10.0f;       ///< weight of the divergence term, >= 0 (paper: 10)
    int maxEmIterations = 3;   ///< EM iterations (M-step + E-step), >= 1
    double emTolerance = 0.02; ///< stop when |E_b(k) - E_b(k-1)| / E_b(k-1) is below this
    int maxCgIterations = 100; ///< CG iterations per E-step
    double cgTolerance = 1e-3; ///< CG stops at this relative residual of the normal equations, > 0
    double cgTolerance2D = 1e-2; ///< the same on a 2D (flat) layout: on the built-in 2D pair 1e-2 takes 39% fewer CG
                                 ///< iterations than 1e-3 and leaves every measure of the 30 frames equal to 3 digits
                                 ///< (E_b within 2% per frame; docs/transfer.md, 2D)
    SeamSolver solver = SeamSolver::Cgnr; ///< the E-step's solver
    float boxWeight = 10.0f;              ///< nu/f^3: weight of the rows holding U_h's box means (coarse cells), >= 0
    float boxKeep = 1.0f;     ///< the box rows pull each coarse cell's mean of X to this fraction of its mean on
                              ///< entry: 1 = the solve moves detail within cells but leaves their means (the coarse
                              ///< motion) as they came in; 0 = pulls them to zero
    float valueWeight = 0.0f; ///< mu: weight of rows keeping X near its value on entry, times the temporal blend
                              ///< weight of its patch (carried detail changes less); 0 = the paper's energy
};

/// One EM iteration, for the per-frame log.
struct SeamIteration
{
    int cgIterations = 0;
    double cgResidual = 0.0; ///< relative residual |A^T r| / |A^T r0| when CG stopped
    double energy = 0.0;     ///< E_b after the E-step
};

struct SeamStats
{
    size_t bandVoxels = 0; ///< |Ω|
    size_t boundaryPatches = 0;
    double initialEnergy = 0.0; ///< E_b of the pasted field against the first M-step's Z
    std::vector<SeamIteration> iterations;
    bool converged = false; ///< EM stopped on emTolerance rather than maxEmIterations
    /// Energy of the last E-step's X against the next M-step's targets, when that M-step moved it by no more than
    /// emTolerance and EM stopped there without another E-step (0 otherwise).
    double stoppedAtMStep = 0.0;
    double setupSeconds = 0.0, mStepSeconds = 0.0, eStepSeconds = 0.0; ///< where the time went
};

/// The lattice of local patches over the fine output box: patch P covers
/// origin + P*size + [0, size-1]^3, clipped to the box; over a 2D (one z layer, `flat`) box,
/// origin + P*size + [0, size-1]^2 x {0}.
struct PatchLayout
{
    Coord origin{0};
    int size = 8;
    Coord count{0};
    bool flat = false; ///< 2D: patches are size x size x 1 (count.z() == 1)

    /// Patch extent per axis: (size, size, size), or (size, size, 1) when flat.
    Coord extent() const { return flat ? Coord(size, size, 1) : Coord(size); }
    size_t patchCount() const { return size_t(count.x()) * size_t(count.y()) * size_t(count.z()); }
    size_t patchIndex(const Coord& P) const
    {
        return (size_t(P.x()) * size_t(count.y()) + size_t(P.y())) * size_t(count.z()) + size_t(P.z());
    }
    Coord patchCoord(size_t p) const
    {
        return Coord(int(p / (size_t(count.y()) * size_t(count.z()))), int((p / size_t(count.z())) % size_t(count.y())),
            int(p % size_t(count.z())));
    }
    Coord patchOf(const Coord& voxel) const
    {
        return Coord(floorDiv(voxel.x() - origin.x(), size), floorDiv(voxel.y() - origin.y(), size),
            floorDiv(voxel.z() - origin.z(), flat ? 1 : size));
    }
    CoordBBox patchBox(const Coord& P) const
    {
        const Coord e = extent();
        const Coord lo(origin.x() + P.x() * e.x(), origin.y() + P.y() * e.y(), origin.z() + P.z() * e.z());
        return CoordBBox(lo, lo + e - Coord(1));
    }
    /// Patches of edge `size` >= 1 from box.min() covering `box`; flat when the box is (isFlat). Throws ValueError
    /// for size < 1.
    static PatchLayout covering(const CoordBBox& box, int size);
};

/// What the seam stage needs to know about the pasted patches.
struct SeamProblem
{
    const VectorField* sourceHigh = nullptr; ///< U_sh on the source lattice
    float sourceScale = 1.0f;                ///< multiplies U_sh into the output's units
    PatchLayout layout;                      ///< local patches over the detail field's box
    std::vector<uint8_t> active;             ///< per patch: 1 if it carries pasted detail
    std::vector<Coord> offset;               ///< per active patch: source voxel = output voxel + offset
    int boxFactor = 0;                       ///< coarse cell size f for the box-mean rows (0 = none)
    const VectorField* temporal = nullptr;   ///< optional previous detail (advected): edge targets become
    std::vector<float> temporalWeights;      ///< (1 - w) * boundary patches' + w * its differences, w per local
                                             ///< patch (the mean of the edge's two patches)
    const VectorField* base = nullptr;       ///< optional field added to X in the divergence term: the
                                             ///< gamma term then penalises div(baseScale * base + X) (same box as X)
    std::vector<uint8_t> wholePatches;       ///< optional, per patch: 1 puts all of the patch's voxels in Ω, not only
                                             ///< its band (fresh patches: the gamma term then reaches their insides)
    float baseScale = 1.0f;                  ///< 1 / the factor X will be scaled by afterwards, so that
                                             ///< div(base + factor * X) is what the solve makes small
};

/// Ω as a per-voxel mask over `box` (1 = in the band).
std::vector<uint8_t> seamBand(
    const CoordBBox& box, const PatchLayout& layout, const std::vector<uint8_t>& active, int bandWidth);

/// Smooths the seams of `detail` (the pasted U_h) in place. Returns the EM/CG log.
SeamStats smoothSeams(
    VectorField& detail, const SeamProblem& problem, const SeamSettings& settings, Progress* progress = nullptr);

/// The E-step alone, for tests and diagnostics: minimises the energy above over the voxels with
/// omega = 1, for given edge targets g (per voxel p and axis a: the target of X(p + e_a) - X(p)),
/// starting from and writing into X. Returns {iterations, relative residual, final energy}.
SeamIteration solveSeamEStep(VectorField& X, const std::vector<uint8_t>& omega, const std::vector<Vec3f>& edgeTargets,
    float gamma, int maxIterations, double tolerance, SeamSolver solver = SeamSolver::Cgnr);

/// The energy the E-step minimises, evaluated over the rows touching Ω (for tests).
double seamEnergy(
    const VectorField& X, const std::vector<uint8_t>& omega, const std::vector<Vec3f>& edgeTargets, float gamma);

} // namespace turb
