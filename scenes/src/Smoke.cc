// The smoke solver's substep: emitters, advection, forces, walls, projection.
#include <scenes/Smoke.h>

#include "MacAdvect.h"
#include "Noise.h"

#include <turb/Metadata.h>
#include <turb/Error.h>
#include <turb/Measure.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

namespace turb {
namespace scenes {

namespace {

// ---- Seeded noise: a pure function of (seed, position, time), so it does not depend on threads.

using detail::splitmix;

/// Uniform in [-1, 1] at an integer lattice point of space-time.
double latticeValue(std::uint64_t seed, int i, int j, int k, int t)
{
    std::uint64_t h = splitmix(seed);
    h = splitmix(h ^ std::uint64_t(std::uint32_t(i)));
    h = splitmix(h ^ (std::uint64_t(std::uint32_t(j)) << 1));
    h = splitmix(h ^ (std::uint64_t(std::uint32_t(k)) << 2));
    h = splitmix(h ^ (std::uint64_t(std::uint32_t(t)) << 3));
    return double(h >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

double smooth(double t) { return t * t * (3.0 - 2.0 * t); }

/// Smooth value noise in [-1, 1]: p in noise cells, t in noise periods.
double valueNoise(std::uint64_t seed, const Vec3d& p, double t)
{
    const int i0 = int(std::floor(p.x())), j0 = int(std::floor(p.y())), k0 = int(std::floor(p.z()));
    const int t0 = int(std::floor(t));
    const double fx = smooth(p.x() - i0), fy = smooth(p.y() - j0), fz = smooth(p.z() - k0), ft = smooth(t - t0);
    double acc = 0.0;
    for (int dt = 0; dt < 2; ++dt)
        for (int di = 0; di < 2; ++di)
            for (int dj = 0; dj < 2; ++dj)
                for (int dk = 0; dk < 2; ++dk) {
                    const double w = (dt ? ft : 1 - ft) * (di ? fx : 1 - fx) * (dj ? fy : 1 - fy) * (dk ? fz : 1 - fz);
                    acc += w * latticeValue(seed, i0 + di, j0 + dj, k0 + dk, t0 + dt);
                }
    return acc;
}

/// Cells whose centres lie within `r` (+ margin) of `c`, clipped to `cells`.
CoordBBox sphereBox(const Lattice& lat, const Vec3d& c, double r, const CoordBBox& cells)
{
    const Vec3d lo = lat.worldToIndex(c - Vec3d(r)), hi = lat.worldToIndex(c + Vec3d(r));
    CoordBBox b(Coord(int(std::floor(lo.x())) - 1, int(std::floor(lo.y())) - 1, int(std::floor(lo.z())) - 1),
        Coord(int(std::ceil(hi.x())) + 1, int(std::ceil(hi.y())) + 1, int(std::ceil(hi.z())) + 1));
    b.intersect(cells);
    return b;
}

void require(bool ok, const std::string& what)
{
    if (!ok) throw ValueError("smoke settings: " + what);
}

} // namespace

SmokeSim::SmokeSim(const SmokeSettings& s) : mSettings(s)
{
    const Coord& r = s.resolution;
    require(r.x() >= 4 && r.y() >= 4 && (r.z() >= 4 || r.z() == 1),
        "resolution must be at least 4 cells along each axis, or 1 along z for a 2D simulation");
    require(double(r.x()) * r.y() * r.z() <= 2.0e8, "resolution above 2e8 cells");
    require(s.width > 0.0 && std::isfinite(s.width), "width must be > 0");
    require(s.frameDt > 0.0, "frameDt must be > 0");
    require(s.cfl > 0.0, "cfl must be > 0");
    require(s.maxSubsteps >= 1, "maxSubsteps must be >= 1");
    require(s.buoyancyDensity >= 0 && s.buoyancyTemperature >= 0 && s.vorticity >= 0 && s.cooling >= 0 &&
                s.densityDecay >= 0 && s.windRate >= 0,
        "buoyancy, vorticity, cooling, decay and wind rate must be >= 0");
    require(s.pressureTolerance > 0 && s.pressureTolerance < 1, "pressureTolerance must lie in (0, 1)");
    require(s.pressureMaxIterations >= 1, "pressureMaxIterations must be >= 1");
    for (const auto& e : s.emitters)
        require(e.shape.radius > 0 && e.noise >= 0 && e.noise <= 1 && e.density >= 0 && e.temperature >= 0,
            "emitter radius must be > 0, noise in [0, 1], density and temperature >= 0");
    for (const auto& o : s.obstacles) require(o.radius > 0, "obstacle radius must be > 0");

    const double h = s.width / r.x();
    Vec3d corner = s.minCorner;
    if (!std::isfinite(corner.x()) || !std::isfinite(corner.y()) || !std::isfinite(corner.z()))
        corner = twoD() ? Vec3d(-0.5 * s.width, 0.0, -0.5 * h) // 2D: y up from the floor, the layer's centre at z = 0
                        : Vec3d(-0.5 * s.width, -0.5 * r.y() * h, 0.0);
    const Lattice lat{h, corner + Vec3d(0.5 * h)};
    const CoordBBox cells(Coord(0), r.offsetBy(-1));

    mMac = VectorField(macBox(cells), lat);
    mDensity = ScalarField(cells, lat);
    mTemperature = ScalarField(cells, lat);
    mSolid = MaskField(cells, lat);
    for (const auto& o : s.obstacles) {
        const CoordBBox b = sphereBox(lat, o.centre, o.radius, cells);
        forEachVoxel(b, [&](int i, int j, int k) {
            if ((lat.indexToWorld(Vec3d(i, j, k)) - o.centre).length() <= o.radius) mSolid(i, j, k) = 1;
        });
    }
    ProjectionSettings projection;
    projection.tolerance = s.pressureTolerance;
    projection.maxIterations = s.pressureMaxIterations;
    projection.faces = s.faces;
    if (twoD()) {
        // One layer: the floor is y-, and the z faces are walls (a 2D flow has no z velocity).
        projection.faces[2] = Boundary::Closed;
        projection.faces[4] = projection.faces[5] = Boundary::Closed;
        mSettings.faces = projection.faces;
    }
    projection.incompleteCholesky = s.pressureIncompleteCholesky;
    mProjector.emplace(cells, projection, &mSolid);
}

void SmokeSim::emit(double dt)
{
    const Lattice& lat = lattice();
    const double h = lat.voxelSize;
    const CoordBBox& cellsBox = cells();
    const CoordBBox faces = mMac.bbox();
    for (size_t e = 0; e < mSettings.emitters.size(); ++e) {
        const Emitter& em = mSettings.emitters[e];
        // Emit when the substep's interval overlaps the emitter's.
        if (mTime + dt <= em.startTime || mTime >= em.endTime) continue;
        const std::uint64_t seed = splitmix(mSettings.seed * 0x100000001b3ull + e);
        const double cellSize = std::max(0.5 * em.shape.radius, 1.5 * h); // noise feature size, world
        const double period = 0.15;                                       // noise time scale, seconds
        const double t = mTime / period;
        const auto noiseAt = [&](const Vec3d& x, int channel) {
            return valueNoise(seed + std::uint64_t(channel) * 0x9e37ull, (x - em.shape.centre) / cellSize, t);
        };
        // Weight 1 inside, falling to 0 over one voxel at the surface, so even a sphere smaller than a
        // voxel at low resolution emits.
        const auto weight = [&](const Vec3d& x) {
            const double d = (x - em.shape.centre).length();
            return std::min(1.0, std::max(0.0, (em.shape.radius + 0.5 * h - d) / h));
        };
        const CoordBBox b = sphereBox(lat, em.shape.centre, em.shape.radius + h, cellsBox);
        forEachVoxel(b, [&](int i, int j, int k) {
            if (mSolid(i, j, k)) return;
            const Vec3d x = lat.indexToWorld(Vec3d(i, j, k));
            const double w = weight(x);
            if (w <= 0.0) return;
            const double n = 1.0 + em.noise * noiseAt(x, 0);
            mDensity(i, j, k) = std::max(mDensity(i, j, k), float(w * em.density * n));
            mTemperature(i, j, k) = std::max(mTemperature(i, j, k), float(w * em.temperature * n));
        });
        const double speed = em.velocity.length();
        if (speed <= 0.0) continue;
        CoordBBox fb = sphereBox(lat, em.shape.centre, em.shape.radius + h, faces);
        forEachVoxel(fb, [&](int i, int j, int k) {
            Vec3f& u = mMac(i, j, k);
            for (int a = 0; a < 3; ++a) {
                Vec3d x = lat.indexToWorld(Vec3d(i, j, k));
                x[a] -= 0.5 * h; // face centre
                const double w = weight(x);
                if (w <= 0.0) continue;
                const double target =
                    em.velocity[a] * (1.0 + em.noise * noiseAt(x, 0)) + 0.5 * em.noise * speed * noiseAt(x, 1 + a);
                u[a] = float((1.0 - w) * u[a] + w * target);
            }
        });
    }
}

void SmokeSim::addForces(double dt)
{
    const Lattice& lat = lattice();
    const CoordBBox& cellsBox = cells();
    const float alpha = mSettings.buoyancyDensity, beta = mSettings.buoyancyTemperature;
    const int up = upAxis();

    // Vorticity confinement (Fedkiw et al. 2001): f = eps * h * (N x omega), N = grad|omega| / |grad|omega||,
    // at cell centres, then averaged to the faces with the buoyancy.
    VectorField confinement;
    if (mSettings.vorticity > 0.0f) {
        const VectorField omega = curl(macToCentred(mMac));
        const ScalarField mag = magnitude(omega);
        confinement = VectorField(cellsBox, lat);
        const float scale = float(mSettings.vorticity * lat.voxelSize);
        forEachVoxel(cellsBox, [&](int i, int j, int k) {
            Vec3f g;
            const int c[3] = {i, j, k};
            for (int a = 0; a < 3; ++a) {
                int lo[3] = {i, j, k}, hi[3] = {i, j, k};
                lo[a] = std::max(c[a] - 1, cellsBox.min()[a]);
                hi[a] = std::min(c[a] + 1, cellsBox.max()[a]);
                g[a] = mag(hi[0], hi[1], hi[2]) - mag(lo[0], lo[1], lo[2]);
            }
            const float len = g.length();
            if (len <= 1e-12f) return;
            confinement(i, j, k) = scale * (g / len).cross(omega(i, j, k));
        });
    }

    const float windKeep = std::exp(-float(mSettings.windRate * dt));
    const Vec3f wind = mSettings.wind;
    forEachVoxel(mMac.bbox(), [&](int i, int j, int k) {
        const Coord hi(i, j, k);
        Vec3f& u = mMac(i, j, k);
        for (int a = 0; a < 3; ++a) {
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            if (hi[b] > cellsBox.max()[b] || hi[c] > cellsBox.max()[c]) continue; // not a face
            Coord lo = hi;
            lo[a] -= 1;
            const bool inLo = cellsBox.isInside(lo) && !mSolid[lo];
            const bool inHi = cellsBox.isInside(hi) && !mSolid[hi];
            if (!inLo && !inHi) continue;
            // Face value of a cell field: the mean of the fluid cells on either side.
            const auto face = [&](const auto& f) {
                return inLo && inHi ? 0.5f * (f[lo] + f[hi]) : (inLo ? f[lo] : f[hi]);
            };
            float acc = 0.0f;
            if (a == up) acc += beta * face(mTemperature) - alpha * face(mDensity);
            if (!confinement.empty()) {
                const Vec3f f = inLo && inHi ? 0.5f * (confinement[lo] + confinement[hi])
                                             : (inLo ? confinement[lo] : confinement[hi]);
                acc += f[a];
            }
            u[a] += float(dt) * acc;
            if (a != up && mSettings.windRate > 0.0f) u[a] = wind[a] + (u[a] - wind[a]) * windKeep;
        }
    });
}

void SmokeSim::enforceWalls()
{
    const CoordBBox& cellsBox = cells();
    forEachVoxel(mMac.bbox(), [&](int i, int j, int k) {
        const Coord hi(i, j, k);
        Vec3f& u = mMac(i, j, k);
        for (int a = 0; a < 3; ++a) {
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            // Entries of the MAC box that are no face of the domain stay 0: they are what the staggered
            // sampler sees just outside the domain.
            if (hi[b] > cellsBox.max()[b] || hi[c] > cellsBox.max()[c]) {
                u[a] = 0.0f;
                continue;
            }
            Coord lo = hi;
            lo[a] -= 1;
            const bool solidLo = cellsBox.isInside(lo) && mSolid[lo];
            const bool solidHi = cellsBox.isInside(hi) && mSolid[hi];
            const bool wall = (hi[a] == cellsBox.min()[a] && mSettings.faces[2 * a] == Boundary::Closed) ||
                              (hi[a] == cellsBox.max()[a] + 1 && mSettings.faces[2 * a + 1] == Boundary::Closed);
            if (solidLo || solidHi || wall) u[a] = 0.0f;
        }
    });
}

ScalarField SmokeSim::pressureGuess(double dt) const
{
    if (mPressure.empty()) return {};
    // The projection's pressure p (velocity times voxels) is dt times the physical pressure P, which
    // varies smoothly in time: extrapolate P linearly from the last two projections to this one and scale
    // back (with one projection so far: P constant). Measured on plume 64x64x96, 30 frames: 1078 CG
    // iterations against 1229 from the last pressure alone and 1135 / 1185 with half / 1.5 times the
    // linear trend. The guess only changes where CG starts, not where it stops.
    const bool linear = !mPressurePrev.empty();
    const double r = dt / mPressureDt; // time to this projection over the time between the last two
    const float wLast = float(r * (linear ? 1.0 + r : 1.0));
    const float wPrev = linear ? float(-r * dt / mPressurePrevDt) : 0.0f;
    ScalarField guess(mPressure.bbox(), mPressure.lattice());
    const float* last = mPressure.data();
    const float* prev = linear ? mPressurePrev.data() : nullptr;
    float* g = guess.data();
    parallelFor(guess.size(), 1 << 14, [&](size_t b, size_t e) {
        for (size_t q = b; q < e; ++q) g[q] = wLast * last[q] + (prev ? wPrev * prev[q] : 0.0f);
    });
    return guess;
}

namespace {

// The frame's substeps, by the CFL condition on the fastest face component now and the emitters' nominal speeds
// (their noise may exceed it a little within the frame).
int substepCount(const VectorField& mac, const SmokeSettings& s, double h)
{
    double speed = 0.0;
    for (const auto& v : mac.values())
        speed = std::max(speed, double(std::max(std::abs(v.x()), std::max(std::abs(v.y()), std::abs(v.z())))));
    for (const auto& e : s.emitters) speed = std::max(speed, double(e.velocity.length()));
    return std::min(s.maxSubsteps, std::max(1, int(std::ceil(speed * s.frameDt / (s.cfl * h) - 1e-9))));
}

// Adds one projection's solver figures to the frame's (the worst over its substeps), and shows them.
void recordProjection(const ProjectionResult& r, FrameStats& st, Progress* progress)
{
    st.pressureIterations += r.iterations;
    st.converged = st.converged && r.converged;
    st.relativeResidual = std::max(st.relativeResidual, r.relativeResidual);
    st.relativeDivergence = std::max(st.relativeDivergence, r.relativeDivergence());
    st.divMaxAfter = r.divMaxAfter;
    if (progress) {
        std::ostringstream os;
        os << "pressure: " << r.iterations << " iterations, max|div| " << r.divMaxBefore << " -> " << r.divMaxAfter
           << " 1/s";
        progress->note(os.str());
        progress->update(1.0);
    }
}

// The finished frame's figures: div_rel of the cell-centred velocity, the fastest face velocity and the mass.
void recordFrameFigures(const VectorField& mac, const ScalarField& density, double h, FrameStats& st)
{
    const VectorField centred = macToCentred(mac);
    st.divRel = relativeDivergence(centred, smokeMask(density, 0.01f)).value_or(0.0);
    for (const auto& v : mac.values()) st.maxSpeed = std::max(st.maxSpeed, double(v.length()));
    const double vol = h * h * h;
    st.mass = vol * parallelSum(density.size(), 1 << 14, [&](size_t b, size_t e) {
        double a = 0;
        for (size_t q = b; q < e; ++q) a += density.data()[q];
        return a;
    });
}

} // namespace

FrameStats SmokeSim::advanceFrame(Progress* progress)
{
    using Clock = std::chrono::steady_clock;
    FrameStats st;
    withThreads(mSettings.threads, [&] {
        const double h = lattice().voxelSize;
        const int n = substepCount(mMac, mSettings, h);
        const double dt = mSettings.frameDt / n;
        st.substeps = n;

        detail::MacAdvectSettings adv;
        adv.scalarScheme = mSettings.densityScheme;
        adv.velocityScheme = mSettings.velocityScheme;
        adv.revert = mSettings.revertLimiter;
        adv.faces = mSettings.faces;
        const float cool = std::exp(-float(mSettings.cooling * dt));
        const float decay = std::exp(-float(mSettings.densityDecay * dt));

        for (int s = 0; s < n; ++s) {
            checkCancelled(progress);
            if (progress) {
                progress->begin("substep " + std::to_string(s + 1) + "/" + std::to_string(n));
                progress->update(0.0);
            }
            emit(dt);
            auto t0 = Clock::now();
            detail::advectMac(mMac, {&mDensity, &mTemperature}, dt, adv);
            st.advectSeconds += std::chrono::duration<double>(Clock::now() - t0).count();
            if (progress) progress->update(0.4);
            if (cool != 1.0f)
                for (float& v : mTemperature.values()) v *= cool;
            if (decay != 1.0f)
                for (float& v : mDensity.values()) v *= decay;
            addForces(dt);
            enforceWalls();
            // Smoke inside obstacles (advected in through the soft edge) is removed.
            for (size_t q = 0; q < mSolid.size(); ++q)
                if (mSolid.data()[q]) mDensity.data()[q] = mTemperature.data()[q] = 0.0f;
            if (progress) progress->update(0.5);
            t0 = Clock::now();
            ScalarField pressure = pressureGuess(dt);
            const ProjectionResult r = mProjector->project(mMac, &pressure, progress);
            mPressurePrev = std::move(mPressure);
            mPressurePrevDt = mPressureDt;
            mPressure = std::move(pressure);
            mPressureDt = dt;
            st.projectSeconds += std::chrono::duration<double>(Clock::now() - t0).count();
            recordProjection(r, st, progress);
            mTime += dt;
        }
        ++mFrame;
        st.frame = mFrame;
        recordFrameFigures(mMac, mDensity, h, st);
    });
    return st;
}

Frame SmokeSim::frame() const
{
    Frame f;
    f.number = mFrame;
    f.velocity = macToCentred(mMac);
    f.density = mDensity;
    f.temperature = mTemperature;
    f.dt = mSettings.frameDt;
    const Coord& r = mSettings.resolution;
    f.metadata[turb::meta::kSimResolution] =
        std::to_string(r.x()) + "x" + std::to_string(r.y()) + "x" + std::to_string(r.z());
    f.metadata[turb::meta::kSimSeed] = std::to_string(mSettings.seed);
    std::ostringstream os;
    os.precision(9);
    os << mTime;
    f.metadata[turb::meta::kSimTime] = os.str();
    f.metadata[turb::meta::kUpAxis] = twoD() ? "y" : "z";
    f.metadata[turb::meta::kScene] = mSettings.label;
    return f;
}

} // namespace scenes
} // namespace turb
