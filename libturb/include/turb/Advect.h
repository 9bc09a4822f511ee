/// @file Advect.h
/// @brief Moving a field along a velocity field for one time step (density, detail velocity).
///
/// The schemes of OpenVDB's tools/VolumeAdvect.h (semi-Lagrangian or BFECC/MacCormack with a clamping
/// limiter), computed on the dense field itself by default or by OpenVDB's VolumeAdvection
/// (AdvectSettings::Backend::OpenVdb). The velocity may live on a different (coarser) lattice than the advected
/// field; both are in world units. Deterministic at any thread count.
///
/// @code
/// turb::AdvectSettings s;              // BFECC + clamp
/// turb::ScalarField rho1 = turb::advect(rho0, velocity, dt, s);
/// @endcode
#pragma once

#include <turb/Field.h>

namespace turb {

struct AdvectSettings
{
    enum class Scheme { SemiLagrangian, MacCormack, BFECC };
    Scheme scheme = Scheme::BFECC; ///< integration scheme (BFECC: 2nd order, 3 backtraces)
    bool clamp = true;             ///< clamp to the range of the sampled neighbourhood (no new extrema)
    int substeps = 0;              ///< 0 = from the CFL number: at most 3 voxels of travel per substep
    /// Dense: the schemes computed on the field's own array (first-order backtraces from each voxel centre,
    /// trilinear taps, zero outside the box), over the box of its non-zero values grown by the travel.
    /// OpenVdb: tools::VolumeAdvection on a sparse copy of the field and the velocity, as before 2026-12-04: the
    /// same schemes (2e-5 rms apart on a 3D swirl), several times slower on 128x128x192 frames
    /// (docs/performance.md).
    enum class Backend { Dense, OpenVdb };
    Backend backend = Backend::Dense;
    /// 2D fields (q and velocity one z layer, isFlat): advect densely in the x-y plane, with the same schemes
    /// (first-order backtraces, bilinear, zero outside the box) instead of OpenVDB's VolumeAdvection, which
    /// dilates the one layer by the travel distance along z and so costs 2 * travel + 1 layers. Off: unchanged.
    bool inPlane = false;
};

/// The scheme's command-line name: "bfecc", "maccormack" or "semi-lagrangian".
const char* schemeName(AdvectSettings::Scheme scheme);

/// q advected by `velocity` over `dt` (velocity * dt is a world-space displacement). The result lives
/// on q's lattice and box; values arriving from outside the box are zero.
ScalarField advect(const ScalarField& q, const VectorField& velocity, double dt, const AdvectSettings& s = {});
VectorField advect(const VectorField& q, const VectorField& velocity, double dt, const AdvectSettings& s = {});

/// The density sources of one coarse frame: what advection alone does not explain,
/// max(0, rho_i - advect(rho_{i-1}, L_i, dt)); all of rho_i when there is no previous frame. With
/// `region` (same box) and a previous frame, only where region > 0: where the emitters are known,
/// this keeps the difference between the cache's advection scheme and ours from counting as sources.
ScalarField estimateSources(const ScalarField* previousDensity, const ScalarField& density, const VectorField& velocity,
    double dt, const AdvectSettings& advect = {}, const ScalarField* region = nullptr);

} // namespace turb
