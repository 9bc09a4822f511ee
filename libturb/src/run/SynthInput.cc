// runSynth's inputs: the coarse motion, the exemplars, and the job's text settings (SynthSteps.h).
#include "SynthSteps.h"

#include "RunHelpers.h"

#include <turb/run/Flags.h>

#include <turb/Error.h>
#include <turb/Render.h>
#include <turb/Resample.h>
#include <turbio/ImageIO.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

namespace turb::run::synth {

namespace {

std::vector<std::string> split(const std::string& s, char sep)
{
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, sep)) out.push_back(item);
    return out;
}

int toInt(const std::string& s, const std::string& what)
{
    double v;
    if (!parseNumber(s, v) || v != std::floor(v)) throw turb::ValueError(what + ": '" + s + "' is not an integer");
    return int(v);
}

turb::Coord parseRes(const std::string& s, const std::string& what)
{
    const auto p = split(s, 'x');
    if (p.size() == 1) {
        const int n = toInt(p[0], what);
        return turb::Coord(n, n, n);
    }
    if (p.size() != 3) throw turb::ValueError(what + ": expected NXxNYxNZ (cells along x, y, z) or N, got '" + s + "'");
    return turb::Coord(toInt(p[0], what), toInt(p[1], what), toInt(p[2], what));
}

// rg:PICTURE[:SCALE], gray:PICTURE[:SCALE] (`kind`, `rest`): a trailing ":number" is a scale.
turb::Exemplar pictureExemplar(const std::string& kind, const std::string& rest, bool periodic)
{
    double scale = 1.0;
    std::string path = rest;
    const size_t c = rest.rfind(':');
    double v;
    if (c != std::string::npos && parseNumber(rest.substr(c + 1), v)) {
        scale = v;
        path = rest.substr(0, c);
    }
    const turb::Image img = turb::rgbOf(turbio::readImage(path));
    return kind == "rg" ? turb::exemplarFromVectorImage(img, scale) : turb::exemplarFromGrayImage(img, scale, periodic);
}

// vdb:FILE.vdb[:AXIS:INDEX] (a slice, the middle one along z by default), vdb3:FILE.vdb (a volume).
turb::Exemplar vdbExemplar(const std::string& spec, const std::string& kind, const std::string& rest, const SynthJob& a)
{
    std::string path = rest;
    int axis = 2, index = std::numeric_limits<int>::min();
    if (kind == "vdb") {
        const auto parts = split(rest, ':');
        if (parts.size() >= 3 &&
            (parts[parts.size() - 2] == "x" || parts[parts.size() - 2] == "y" || parts[parts.size() - 2] == "z")) {
            axis = parts[parts.size() - 2][0] - 'x';
            index = toInt(parts.back(), "--exemplar " + spec);
            path = rest.substr(0, rest.size() - parts.back().size() - 3);
        }
    }
    turbio::ReadOptions ro = a.read;
    ro.requireDensity = false;
    ro.cropToSmoke = false; // an exemplar is its motion, wherever the smoke is
    const turb::Frame f = turbio::readFrame(path, 0, ro);
    if (kind == "vdb3")
        // A volume exemplar costs (voxels x 375) floats of descriptors: keep the central N^3 only.
        return turb::exemplarFromVolume(turb::cropped(f.velocity, turb::centralBox(f.velocity.bbox(), a.volumeCrop)));
    if (index == std::numeric_limits<int>::min()) index = (f.bbox().min()[axis] + f.bbox().max()[axis]) / 2;
    return turb::exemplarFromSlice(f.velocity, axis, index);
}

// NAME[:PERIOD[:SIZE]]
turb::Exemplar proceduralFromSpec(const std::string& spec, const std::string& kind, const std::string& rest)
{
    turb::ProceduralExemplarSettings p;
    p.pattern = turb::parseProceduralPattern(kind);
    const auto parts = rest.empty() ? std::vector<std::string>{} : split(rest, ':');
    if (!parts.empty()) p.period = toInt(parts[0], "--exemplar " + spec + " (period)");
    p.size = std::max(64, p.period);
    if (p.size % p.period) p.size = (p.size / p.period + 1) * p.period;
    if (parts.size() >= 2) p.size = toInt(parts[1], "--exemplar " + spec + " (size)");
    return turb::proceduralExemplar(p);
}

} // namespace

turb::Exemplar loadExemplar(const std::string& spec, const SynthJob& a)
{
    const size_t colon = spec.find(':');
    const std::string kind = spec.substr(0, colon);
    const std::string rest = colon == std::string::npos ? "" : spec.substr(colon + 1);
    turb::Exemplar e;
    if (kind == "rg" || kind == "gray" || kind == "vdb" || kind == "vdb3") {
        e = kind == "rg" || kind == "gray" ? pictureExemplar(kind, rest, a.periodic) : vdbExemplar(spec, kind, rest, a);
        e.periodic = a.periodic;
        e.name = spec;
    } else {
        e = proceduralFromSpec(spec, kind, rest);
    }
    if (a.exemplarScale != 1.0) e = turb::rescaledExemplar(e, a.exemplarScale);
    turb::normalizeExemplar(e);
    return e;
}

CoarseSource::CoarseSource(const SynthJob& a) : mArgs(a)
{
    int kinds = int(!a.target.empty()) + int(!a.scene.empty()) + int(!a.flow.empty());
    if (kinds != 1)
        throw turb::ValueError("give exactly one coarse input: --target CACHE, --scene NAME or --flow KIND");
    if (!a.target.empty()) {
        mSeq = turbio::resolveSequence(a.target, a.frames);
        if (!mSeq->missing.empty())
            throw turb::IoError(mSeq->pattern.str() +
                                (mSeq->missing.size() == 1 ? ": missing frame " : ": missing frames ") +
                                turbio::formatFrameList(mSeq->missing));
        mFrames = mSeq->frames;
        mLabel = "cache " + mSeq->pattern.str();
        return;
    }
    const std::vector<int> list = a.frames.empty() ? std::vector<int>{1} : turbio::parseFrameList(a.frames);
    // A single number N means frames 1..N.
    if (list.size() == 1 && a.frames.find('-') == std::string::npos)
        for (int f = 1; f <= list[0]; ++f) mFrames.push_back(f);
    else mFrames = list;
    if (mFrames.empty() || mFrames.front() < 1) throw turb::ValueError("--frames: scene and flow frames start at 1");
    if (!a.scene.empty()) openScene(a);
    else openFlow(a);
}

CoarseSource::~CoarseSource() = default;

void CoarseSource::openScene(const SynthJob& a)
{
    mSceneSettings =
        turb::scenes::sceneSettings(a.scene, parseRes(a.sceneRes, "--scene-res"), std::uint64_t(a.sceneSeed));
    mSceneSettings->threads = a.threads;
    mSim = std::make_unique<turb::scenes::SmokeSim>(*mSceneSettings);
    mLabel = "scene " + a.scene + " " + a.sceneRes;
}

void CoarseSource::openFlow(const SynthJob& a)
{
    turb::AnalyticFlowSettings f;
    f.kind = a.flow == "vortex"  ? turb::AnalyticFlowSettings::Kind::Vortex
             : a.flow == "shear" ? turb::AnalyticFlowSettings::Kind::Shear
                                 : turb::AnalyticFlowSettings::Kind::Uniform;
    f.res = parseRes(a.flowRes, "--flow-res");
    f.voxelSize = a.flowWidth / f.res.x();
    f.speed = a.flowSpeed;
    f.angleDegrees = a.flowAngle;
    mFlow = turb::analyticFlow(f);
    mLabel = "flow " + a.flow + " " + a.flowRes;
}

turb::Frame CoarseSource::read(int frame, turb::Progress* progress)
{
    turb::Frame f;
    if (mSeq) {
        turbio::ReadOptions ro = mArgs.read;
        ro.requireDensity = false;
        f = turbio::readFrame(mSeq->path(frame), frame, ro);
    } else if (mSim) {
        while (mSim->frameCount() < frame) mSim->advanceFrame(progress);
        f = mSim->frame();
        f.number = frame;
    } else {
        f.velocity = mFlow;
        f.dt = mArgs.flowDt;
        f.number = frame;
    }
    if (mArgs.sliceZ >= 0) {
        try {
            f = turb::zLayer(f, mArgs.sliceZ);
        } catch (const turb::ValueError& e) {
            throw turb::ValueError(std::string("--slice-z: ") + e.what(), e.settings());
        }
    }
    return f;
}

unsigned CoarseSource::sceneWalls() const
{
    unsigned w = 0;
    if (mSceneSettings)
        for (int i = 0; i < 6; ++i)
            if (mSceneSettings->faces[size_t(i)] == turb::Boundary::Closed) w |= 1u << i;
    return w;
}

std::optional<turb::ScalarField> CoarseSource::sceneEmitters(const turb::ScalarField& like, int frame) const
{
    if (!mSceneSettings) return std::nullopt;
    return turb::scenes::emitterMask(*mSceneSettings, like, frame);
}

std::optional<turb::ScalarField> CoarseSource::sceneObstacles(const turb::VectorField& like) const
{
    if (!mSceneSettings || mSceneSettings->obstacles.empty()) return std::nullopt;
    return turb::scenes::obstacleDistance(*mSceneSettings, like);
}

unsigned parseWalls(const std::string& s)
{
    unsigned w = 0;
    if (s.empty() || s == "none") return 0;
    if (s == "all") return 63u;
    for (const std::string& t : split(s, ',')) {
        if (t.size() != 2 || (t[0] != 'x' && t[0] != 'y' && t[0] != 'z') || (t[1] != '-' && t[1] != '+'))
            throw turb::ValueError("--walls: '" + t + "' is not one of x-, x+, y-, y+, z-, z+");
        w |= 1u << (2 * (t[0] - 'x') + (t[1] == '+' ? 1 : 0));
    }
    return w;
}

namespace {

// --secondary X,Y,Z: a fixed second local axis instead of the density's gradient.
void fixedSecondary(const SynthJob& a, turb::SynthSettings& s)
{
    const auto p = split(a.secondary, ',');
    double v[3];
    if (p.size() != 3 || !parseNumber(p[0], v[0]) || !parseNumber(p[1], v[1]) || !parseNumber(p[2], v[2]))
        throw turb::ValueError("--secondary: 'density' or a vector X,Y,Z");
    const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!std::isfinite(float(v[0])) || !std::isfinite(float(v[1])) || !std::isfinite(float(v[2])) ||
        !std::isfinite(len) || !(len > 1e-6))
        throw turb::ValueError("--secondary: X,Y,Z must be finite and not zero (got '" + a.secondary + "')");
    s.orientation.densitySecondary = false;
    s.orientation.autoSecondary = false;
    s.orientation.secondary = turb::Vec3d(v[0], v[1], v[2]);
}

// "SMALL" or "LARGE,SMALL" (the two neighbourhood passes per level).
void largeSmall(const std::string& text, const char* option, int& large, int& small)
{
    if (text.empty()) return;
    const auto p = split(text, ',');
    if (p.size() == 1) small = toInt(p[0], option);
    else {
        large = toInt(p[0], option);
        small = toInt(p[1], option);
    }
}

// --view-weights: one positive number per view.
std::vector<float> viewWeights(const SynthJob& a)
{
    std::vector<float> weights;
    if (!a.viewWeights.empty())
        for (const auto& t : split(a.viewWeights, ',')) {
            double v;
            if (!parseNumber(t, v) || !(v > 0))
                throw turb::ValueError("--view-weights: '" + t + "' is not a positive number");
            weights.push_back(float(v));
        }
    return weights;
}

// Planar exemplars in 3D: one serves all three axis views; otherwise one exemplar per view, looking along the local
// axes --views names.
void planarViews(std::vector<int> normals, const std::vector<turb::Exemplar>& ex, std::vector<turb::SynthView>& views)
{
    const size_t n = normals.empty() ? (ex.size() == 1 ? 3 : ex.size()) : normals.size();
    if (normals.empty()) {
        if (n > 3)
            throw turb::ValueError("more than three exemplars: say which local axis each looks along with --views");
        for (size_t i = 0; i < n; ++i) normals.push_back(int(i));
    }
    if (ex.size() != 1 && ex.size() != n)
        throw turb::ValueError(
            "--views names " + std::to_string(n) + " views but " + std::to_string(ex.size()) + " exemplars are given");
    for (size_t i = 0; i < n; ++i) views.push_back({ex[ex.size() == 1 ? 0 : i], normals[i], 1.0f});
}

} // namespace

void fillSettings(SynthJob& a)
{
    turb::SynthSettings& s = a.seq.synth;
    s.threads = a.threads;
    if (a.secondary != "density") fixedSecondary(a, s);
    largeSmall(a.iterations, "--iterations", s.largeIterations, s.smallIterations);
    largeSmall(a.radius, "--radius", s.largeRadius, s.smallRadius);
}

std::vector<turb::SynthView> synthViews(const SynthJob& a, const std::vector<turb::Exemplar>& ex, bool volume)
{
    std::vector<turb::SynthView> views;
    std::vector<int> normals;
    if (!a.views.empty())
        for (const auto& t : split(a.views, ',')) normals.push_back(toInt(t, "--views"));
    const std::vector<float> weights = viewWeights(a);
    if (!volume) {
        if (ex.size() != 1) throw turb::ValueError("a 2D synthesis takes exactly one --exemplar");
        views.push_back({ex[0], 2, 1.0f});
    } else if (ex.size() == 1 && !ex[0].planar()) {
        views.push_back({ex[0], -1, 1.0f});
    } else {
        planarViews(normals, ex, views);
    }
    if (!weights.empty()) {
        if (weights.size() != views.size())
            throw turb::ValueError("--view-weights has " + std::to_string(weights.size()) + " values for " +
                                   std::to_string(views.size()) + " views");
        for (size_t i = 0; i < views.size(); ++i) views[i].weight = weights[i];
    }
    return views;
}

std::optional<turb::ScalarField> readObstacle(const SynthJob& a, CoarseSource& source, const turb::Frame& f0)
{
    std::optional<turb::ScalarField> obstacle = source.sceneObstacles(f0.velocity);
    if (!a.obstacle.empty()) {
        const size_t c = a.obstacle.rfind(':');
        turbio::ReadOptions ro;
        ro.requireVelocity = false;
        ro.readExtras = false;
        ro.checkFinite = false;
        ro.cropToSmoke = false; // a level set, not smoke: its "density" is a distance
        std::string path = a.obstacle;
        ro.densityGrid = "surface";
        if (c != std::string::npos && a.obstacle.find(".vdb") < c) {
            path = a.obstacle.substr(0, c);
            ro.densityGrid = a.obstacle.substr(c + 1);
        }
        obstacle = turbio::readFrame(path, 0, ro).density;
    }
    return obstacle;
}

} // namespace turb::run::synth
