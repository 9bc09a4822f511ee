/// @file Sim.h
/// @brief `vdbturb sim` as a library call (turb::run, the entry points' layer): a built-in smoke scene simulated
///        into a VDB sequence (scenes/Smoke.h), or the 2D ink exemplar into images (scenes/Ink2D.h).
#pragma once

#include <scenes/Smoke.h>
#include <turb/Advect.h>
#include <turbio/Vdb.h>

#include <cstdint>
#include <string>

namespace turb::run {

/// A sim run: the CLI's options as plain values (same names, same defaults).
struct SimJob
{
    std::string scene;            ///< plume, swirl, obstacle, wind (turb::scenes::sceneList()) or ink
    std::string res = "32x32x48"; ///< cells NXxNYxNZ (z up; NZ = 1 is 2D) or N; ink: WxH (default 320x240)
    int frames = 60;              ///< frames to simulate (>= 1), at 24 per second
    int start = 1;                ///< the first frame's number
    std::uint64_t seed = 1;       ///< emitter noise: the same seed gives identical caches
    std::string out;              ///< pattern; empty: sim/SCENE_RES/SCENE.####.vdb (ink: sim/ink_RES/ink.####.png)
    bool skipExisting = false;    ///< keep frames written with the same `settingsText` (not for ink)
    std::string settingsText;     ///< what frames record and --skip-existing compares (the CLI's option values)
    // The solver: every scene keeps turb::scenes::SmokeSettings' defaults for these.
    turb::AdvectSettings::Scheme scheme = turb::scenes::SmokeSettings{}.densityScheme;
    bool incompleteCholesky = true; ///< the pressure solve's preconditioner: IC (one thread) or Jacobi (all threads)
    double pressureTolerance = turb::scenes::SmokeSettings{}.pressureTolerance; ///< max|div| after / before
    double cfl = turb::scenes::SmokeSettings{}.cfl;                             ///< voxels per substep at most
    int maxSubsteps = turb::scenes::SmokeSettings{}.maxSubsteps;
    turbio::WriteOptions write;
    bool dryRun = false; ///< say what would be written, write nothing
    int threads = 0;     ///< 0 = all cores
};

struct SimRun
{
    int framesWritten = 0;
    int unconverged = 0; ///< frames whose pressure solve stopped before the tolerance (warned about)
};

/// Runs `job`. Throws turb::ValueError (no scene, a bad resolution or setting), UsageError (--out without a frame
/// token for several frames; --skip-existing for ink), turb::IoError and turb::TransientError (writes, locks) and
/// turb::Cancelled.
SimRun runSim(const SimJob& job);

/// "16x16x24" or "32" (a cube) as cells along x, y, z. Throws turb::ValueError naming --res.
turb::Coord parseResolution(const std::string& text);

/// The scenes, one line each: name, what it is, its width and the transfer pair's resolutions.
std::string sceneListText();

} // namespace turb::run
