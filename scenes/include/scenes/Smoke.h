/// @file Smoke.h
/// @brief A small incompressible smoke solver: the source of the built-in scenes (`vdbturb sim`).
///
/// Velocity lives on a MAC grid (turb/Projection.h layout) in world units per second; density and
/// temperature (above ambient) at cell centres. The +z axis is up. One substep is:
///   1. emitters write density, temperature and their initial velocity (seeded noise breaks symmetry);
///   2. density, temperature and the three face components are advected by the MAC velocity with
///      OpenVDB's VolumeAdvection (semi-Lagrangian, MacCormack or BFECC, with a limiter);
///   3. temperature cools, density decays; buoyancy (Fedkiw et al. 2001: -alpha*density +
///      beta*temperature, along +z), vorticity confinement and a side wind accelerate the velocity;
///   4. walls (closed domain faces, sphere obstacles) get zero normal velocity and the velocity is made
///      divergence-free by a turb::MacProjector (OpenVDB's Poisson solver; its Laplacian and
///      preconditioner are built once per simulation), warm-started from the pressure extrapolated from
///      the previous two substeps.
/// Open domain faces let smoke and air leave; what enters through them is smoke-free air at rest.
///
/// The solver prints nothing and opens no file: advanceFrame() returns each frame's statistics and
/// frame() the in-memory turb::Frame (cell-centred velocity). The same settings and seed give
/// bit-identical frames at any thread count.
///
/// @code
/// turb::scenes::SmokeSettings s = turb::scenes::sceneSettings("plume", turb::Coord(32, 32, 48), 7);
/// turb::scenes::SmokeSim sim(s);
/// for (int f = 1; f <= 60; ++f) {
///     turb::scenes::FrameStats st = sim.advanceFrame();
///     turb::Frame frame = sim.frame();   // hand to turbio::writeFrame in the tool
/// }
/// @endcode
#pragma once

#include <turb/Advect.h>
#include <turb/Frame.h>
#include <turb/Progress.h>
#include <turb/Projection.h>

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace turb {
namespace scenes {

struct Sphere
{
    Vec3d centre{0.0};   ///< world position
    double radius = 0.5; ///< world units, > 0
};

/// Where smoke is born. Inside the sphere (with a one-voxel soft edge) density and temperature are
/// raised to the emitter's values and the velocity is set to `velocity`, all modulated by noise.
struct Emitter
{
    Sphere shape;             ///< emission region, world units
    Vec3f velocity{0.0f};     ///< initial velocity imposed inside, world units per second
    float density = 1.0f;     ///< density written inside (max with what is there), >= 0
    float temperature = 1.0f; ///< temperature above ambient written inside, >= 0
    float noise = 0.5f;       ///< relative amplitude of the seeded space-time noise, [0, 1]
    double startTime = 0.0;   ///< emission begins at this simulation time, seconds
    double endTime = std::numeric_limits<double>::infinity(); ///< and ends here, seconds
};

struct SmokeSettings
{
    std::string label = "smoke";  ///< scene name, written into each frame's metadata
    Coord resolution{32, 32, 48}; ///< cells along x, y, z; each >= 4, or z = 1 for a 2D simulation (+y up)
    double width = 4.0;           ///< domain extent along x, world units (> 0); voxel = width / resolution.x
    /// World position of the domain's min corner; (nan) = centred in x and y with the floor at z = 0.
    Vec3d minCorner{std::numeric_limits<double>::quiet_NaN()};
    double frameDt = 1.0 / 24.0; ///< seconds per output frame, > 0
    double cfl = 5.0;            ///< most voxels the fastest face travels in one substep, > 0
    int maxSubsteps = 4;         ///< substeps per frame at most, >= 1 (CFL may then be exceeded)
    AdvectSettings::Scheme densityScheme = AdvectSettings::Scheme::MacCormack;  ///< density/temperature advection
    AdvectSettings::Scheme velocityScheme = AdvectSettings::Scheme::MacCormack; ///< velocity self-advection
    /// Limiter of MacCormack/BFECC: revert to the semi-Lagrangian value where the result leaves the range
    /// of its backtrace's neighbours (true: smooth fronts), or clamp to that range (false: a little
    /// sharper, but voxel staircases on diagonal fronts).
    bool revertLimiter = true;
    float buoyancyDensity = 0.1f;     ///< alpha: downward acceleration per unit density, units/s^2, >= 0
    float buoyancyTemperature = 3.0f; ///< beta: upward acceleration per unit temperature, units/s^2, >= 0
    float vorticity = 0.25f;          ///< vorticity confinement epsilon (force ~ eps * voxel * |curl|), >= 0
    float cooling = 0.4f;             ///< temperature decay rate, 1/s, >= 0
    float densityDecay = 0.0f;        ///< density decay rate, 1/s, >= 0
    Vec3f wind{0.0f};                 ///< ambient wind velocity the horizontal flow relaxes to, units/s
    float windRate = 0.0f;            ///< relaxation rate toward `wind`, 1/s, >= 0 (0 = no wind)
    /// Domain faces (-x, +x, -y, +y, -z, +z; turb::DomainFace): Closed = still wall, Open = smoke and
    /// air leave freely, smoke-free air at rest enters. Default: a floor, open sides and top.
    std::array<Boundary, 6> faces{
        Boundary::Open, Boundary::Open, Boundary::Open, Boundary::Open, Boundary::Closed, Boundary::Open};
    std::vector<Sphere> obstacles;    ///< static solid spheres (walls for flow, empty of smoke)
    std::vector<Emitter> emitters;    ///< smoke sources
    double pressureTolerance = 5e-5;  ///< projection: max|div| after <= this * max|div| before, (0, 1)
    int pressureMaxIterations = 1000; ///< projection: conjugate-gradient iteration cap, >= 1
    /// Projection preconditioner: OpenVDB's incomplete Cholesky (true: about a third of Jacobi's
    /// iterations, but applied on one thread) or Jacobi (false: every step parallel).
    bool pressureIncompleteCholesky = true;
    std::uint64_t seed = 0; ///< emitter noise seed: same seed, same frames
    int threads = 0;        ///< worker threads (0 = all); results do not depend on it
};

/// Statistics of one output frame (all substeps).
struct FrameStats
{
    int frame = 0;                   ///< frame number just completed (1 = first)
    int substeps = 0;                ///< solver substeps taken
    int pressureIterations = 0;      ///< conjugate-gradient iterations, summed over substeps
    bool converged = true;           ///< every projection reached its tolerance
    double relativeResidual = 0.0;   ///< worst solver residual max|r| / max|div before| over substeps
    double relativeDivergence = 0.0; ///< worst measured max|div after| / max|div before| over substeps
    double divMaxAfter = 0.0;        ///< max |MAC divergence| after the last projection, 1/s
    double divRel = 0.0;             ///< div_rel (docs/measure.md) of the cell-centred output (density > 0.01)
    double maxSpeed = 0.0;           ///< fastest face velocity, world units/s
    double mass = 0.0;               ///< total density times voxel volume
    double advectSeconds = 0.0;      ///< wall time in advection (for benchmarks; never affects results)
    double projectSeconds = 0.0;     ///< wall time in the projection
};

class SmokeSim
{
public:
    /// Validates the settings (throws ValueError naming the bad one) and builds an empty domain.
    explicit SmokeSim(const SmokeSettings& settings);

    /// Runs the substeps of one frame. Throws Cancelled when `progress` asks to stop.
    FrameStats advanceFrame(Progress* progress = nullptr);

    /// The current state as a frame: cell-centred velocity, density, temperature, dt = frameDt,
    /// metadata describing the run.
    Frame frame() const;

    const SmokeSettings& settings() const { return mSettings; }
    const Lattice& lattice() const { return mDensity.lattice(); }
    /// A 2D simulation: resolution z == 1. It runs in the x-y plane with +y up, the floor at y = 0, closed z
    /// faces (no z velocity) and a 2D pressure projection; frames are one voxel thick in z, as Houdini and
    /// Blender write 2D simulations.
    bool twoD() const { return mSettings.resolution.z() == 1; }
    /// The axis buoyancy pushes along: 2 (z) in 3D, 1 (y) in 2D.
    int upAxis() const { return twoD() ? 1 : 2; }
    const CoordBBox& cells() const { return mDensity.bbox(); }
    int frameCount() const { return mFrame; }
    double time() const { return mTime; }

    /// Direct access to the state, for initial conditions (tests, custom scenes).
    VectorField& macVelocity() { return mMac; }
    ScalarField& density() { return mDensity; }
    ScalarField& temperature() { return mTemperature; }
    const MaskField& solid() const { return mSolid; }

private:
    void emit(double dt);
    void addForces(double dt);
    void enforceWalls();
    ScalarField pressureGuess(double dt) const;

    SmokeSettings mSettings;
    VectorField mMac; // MAC velocity over macBox(cells)
    ScalarField mDensity, mTemperature;
    // The pressures of the last two projections and their substeps (0: none yet): the next projection
    // starts from their linear extrapolation in time.
    ScalarField mPressure, mPressurePrev;
    double mPressureDt = 0.0, mPressurePrevDt = 0.0;
    MaskField mSolid;
    std::optional<MacProjector> mProjector; // keeps OpenVDB's Laplacian and preconditioner between substeps
    int mFrame = 0;
    double mTime = 0.0;
};

/// The named built-in scenes, in the order `vdbturb sim --help` lists them.
struct SceneInfo
{
    std::string name;
    std::string description;
    double width;   ///< fixed world extent along x (and y); the voxel size is width / resolution.x
    Coord pairLow;  ///< recommended low resolution of a target/source pair
    Coord pairHigh; ///< recommended high resolution (the same world domain)
};
const std::vector<SceneInfo>& sceneList();

/// Settings of a named scene at a resolution (any resolution; x and y should be equal to see the whole
/// scene, and z = 1.5 x gives the scene's full height). Throws ValueError for an unknown name.
SmokeSettings sceneSettings(const std::string& name, const Coord& resolution, std::uint64_t seed);

/// Where the scene's emitters emit during frame `frame` (its time is frame x frameDt; an emitter counts from the frame
/// before its start to its end), on `like`'s lattice and box: 1 inside an emitter's sphere grown by one voxel, else 0.
/// `synth` keeps its detail and density out of them, as the simulation's own sources overwrite what is there.
ScalarField emitterMask(const SmokeSettings& settings, const ScalarField& like, int frame);

/// The scene's obstacles as a signed distance on `like`'s lattice and box, world units: negative inside the nearest
/// sphere, 1e9 far from all (no obstacles). The distance of a union of spheres is the minimum of theirs.
ScalarField obstacleDistance(const SmokeSettings& settings, const VectorField& like);

} // namespace scenes
} // namespace turb
