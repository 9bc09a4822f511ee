// The named built-in scenes. Positions are world units in a domain 4 units wide, centred on x = y = 0
// with the floor at z = 0; at the 2:2:3 pair resolutions the domain is 4 x 4 x 6.
#include <scenes/Smoke.h>

#include <turb/Error.h>

namespace turb {
namespace scenes {

namespace {

constexpr double kWidth = 4.0;

Emitter plumeSource(const Vec3d& at)
{
    Emitter e;
    e.shape = {at, 0.45};
    e.velocity = Vec3f(0.0f, 0.0f, 2.0f);
    e.density = 1.0f;
    e.temperature = 1.0f;
    e.noise = 0.4f;
    return e;
}

} // namespace

const std::vector<SceneInfo>& sceneList()
{
    static const std::vector<SceneInfo> list{
        {"plume", "a buoyant plume rising from a sphere near the floor", kWidth, Coord(16, 16, 24),
            Coord(128, 128, 192)},
        {"swirl", "two opposed, offset jets with strong vorticity confinement: a tumbling vortex", kWidth,
            Coord(16, 16, 24), Coord(128, 128, 192)},
        {"obstacle", "a buoyant plume hitting a sphere and rolling around it", kWidth, Coord(16, 16, 24),
            Coord(128, 128, 192)},
        {"wind", "a buoyant plume bent over by a side wind along +x", kWidth, Coord(16, 16, 24), Coord(128, 128, 192)},
    };
    return list;
}

SmokeSettings sceneSettings(const std::string& name, const Coord& resolution, std::uint64_t seed)
{
    SmokeSettings s;
    s.label = name;
    s.resolution = resolution;
    s.width = kWidth;
    s.seed = seed;
    if (name == "plume") {
        s.emitters = {plumeSource(Vec3d(0.0, 0.0, 0.6))};
    } else if (name == "swirl") {
        // Two jets aimed at each other but passing 0.5 apart in y: the shear rolls them into a vortex
        // about z, and strong confinement keeps many small curls alive (a different style from the plume).
        Emitter a;
        a.shape = {Vec3d(-1.1, -0.25, 1.0), 0.35};
        a.velocity = Vec3f(4.0f, 0.0f, 0.5f);
        a.noise = 0.5f;
        Emitter b = a;
        b.shape.centre = Vec3d(1.1, 0.25, 1.0);
        b.velocity = Vec3f(-4.0f, 0.0f, 0.5f);
        s.emitters = {a, b};
        s.vorticity = 1.2f;
        s.buoyancyTemperature = 1.5f;
        s.cooling = 0.6f;
    } else if (name == "obstacle") {
        s.emitters = {plumeSource(Vec3d(0.0, 0.0, 0.6))};
        s.obstacles = {Sphere{Vec3d(0.15, 0.0, 2.6), 0.7}};
    } else if (name == "wind") {
        // The source releases smoke moving with the wind, so the emitter does not shear the flow.
        s.emitters = {plumeSource(Vec3d(-1.0, 0.0, 0.6))};
        s.emitters[0].velocity = Vec3f(1.5f, 0.0f, 1.0f);
        s.wind = Vec3f(1.5f, 0.0f, 0.0f);
        s.windRate = 0.8f;
    } else {
        std::string names;
        for (const auto& sc : sceneList()) names += (names.empty() ? "" : ", ") + sc.name;
        throw ValueError("unknown scene '" + name + "' (built-in scenes: " + names + ")");
    }
    if (resolution.z() == 1) {
        // 2D: the scene seen from the side, in the x-y plane with +y up. A position (x, y, z) goes to (x, z + y, 0),
        // so the swirl's jets, which pass 0.5 apart in y in 3D, pass 0.5 apart in height; velocities likewise.
        const auto flatten = [](const Vec3d& p) { return Vec3d(p.x(), p.z() + p.y(), 0.0); };
        for (auto& e : s.emitters) {
            e.shape.centre = flatten(e.shape.centre);
            e.velocity = Vec3f(e.velocity.x(), e.velocity.z() + e.velocity.y(), 0.0f);
        }
        for (auto& o : s.obstacles) o.centre = flatten(o.centre);
    }
    return s;
}

ScalarField emitterMask(const SmokeSettings& settings, const ScalarField& like, int frame)
{
    ScalarField m(like.bbox(), like.lattice(), 0.0f);
    const double t = frame * settings.frameDt, h = like.lattice().voxelSize;
    for (size_t n = 0; n < m.size(); ++n) {
        const Vec3d w = like.lattice().indexToWorld(m.coordOf(n).asVec3d());
        for (const auto& e : settings.emitters)
            if (t >= e.startTime && t - settings.frameDt <= e.endTime &&
                (w - e.shape.centre).length() <= e.shape.radius + h)
                m.data()[n] = 1.0f;
    }
    return m;
}

ScalarField obstacleDistance(const SmokeSettings& settings, const VectorField& like)
{
    ScalarField sdf(like.bbox(), like.lattice(), 1e9f);
    for (size_t n = 0; n < sdf.size(); ++n) {
        const Vec3d w = like.lattice().indexToWorld(Vec3d(sdf.coordOf(n).asVec3d()));
        for (const auto& s : settings.obstacles)
            sdf.data()[n] = std::min(sdf.data()[n], float((w - s.centre).length() - s.radius));
    }
    return sdf;
}

} // namespace scenes
} // namespace turb
