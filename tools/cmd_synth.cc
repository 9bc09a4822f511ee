// vdbturb synth: motion-field texture synthesis (Ma et al. 2009) over a coarse flow.
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"

#include <scenes/Smoke.h>
#include <turb/Metadata.h>
#include <turb/Budget.h>
#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Projection.h>
#include <turb/Render.h>
#include <turb/Resample.h>
#include <turb/Synth.h>
#include <turb/SynthSequence.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iterator>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>

namespace vdbturb {

namespace {

struct SynthArgs
{
    std::string target, scene, flow;
    std::string sceneRes = "32x32x48", flowRes = "64x64x1";
    double flowSpeed = 1.0, flowAngle = 0.0, flowWidth = 4.0, flowDt = 1.0 / 24.0;
    std::string frames;
    int sceneSeed = 1;
    int sliceZ = -1;
    std::vector<std::string> exemplars;
    double exemplarScale = 1.0;
    bool periodic = false;
    std::string views, viewWeights, iterations, radius;
    std::string secondary = "density";
    std::string walls, obstacle;
    bool json = false, stats = false;
    bool skipExisting = false;
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
    bool strict = false; ///< a projection or detail divergence solve that does not converge fails the run (exit 1)
    std::string out = "synth/synth.####.vdb";
    std::string preview, previewView;
    int previewWidth = 256;
    std::string previewFormat = "png";
    int volumeCrop = 32;
    turbio::ReadOptions read;
    turbio::WriteOptions write;
    turb::SynthSequenceSettings seq; ///< what the options set: the synthesis, F = up(L) + omega H', the projection
};

const std::vector<std::pair<std::string, turb::CombineSettings::Weighting>> kWeightings{
    {"constant", turb::CombineSettings::Weighting::Constant},
    {"energy", turb::CombineSettings::Weighting::KineticEnergy},
    {"vorticity", turb::CombineSettings::Weighting::Vorticity}};

std::string weightingName(turb::CombineSettings::Weighting w)
{
    for (const auto& [name, v] : kWeightings)
        if (v == w) return name;
    return "constant";
}

std::string fmt(const char* f, double v)
{
    char b[64];
    std::snprintf(b, sizeof(b), f, v);
    return b;
}

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

/// One exemplar from its command-line description (see the --exemplar help).
turb::Exemplar loadExemplar(const std::string& spec, const SynthArgs& a)
{
    const size_t colon = spec.find(':');
    const std::string kind = spec.substr(0, colon);
    const std::string rest = colon == std::string::npos ? "" : spec.substr(colon + 1);
    turb::Exemplar e;
    // A trailing ":number" is a scale for picture exemplars.
    const auto pathAndScale = [&](double& scale) {
        const size_t c = rest.rfind(':');
        double v;
        if (c != std::string::npos && parseNumber(rest.substr(c + 1), v)) {
            scale = v;
            return rest.substr(0, c);
        }
        return rest;
    };
    if (kind == "rg" || kind == "gray") {
        double scale = 1.0;
        const std::string path = pathAndScale(scale);
        const turb::Image img = turb::rgbOf(turbio::readImage(path));
        e = kind == "rg" ? turb::exemplarFromVectorImage(img, scale)
                         : turb::exemplarFromGrayImage(img, scale, a.periodic);
        e.periodic = a.periodic;
        e.name = spec;
    } else if (kind == "vdb" || kind == "vdb3") {
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
        if (kind == "vdb3") {
            // A volume exemplar costs (voxels x 375) floats of descriptors: keep the central N^3 only.
            e = turb::exemplarFromVolume(turb::cropped(f.velocity, turb::centralBox(f.velocity.bbox(), a.volumeCrop)));
        } else {
            if (index == std::numeric_limits<int>::min()) index = (f.bbox().min()[axis] + f.bbox().max()[axis]) / 2;
            e = turb::exemplarFromSlice(f.velocity, axis, index);
        }
        e.periodic = a.periodic;
        e.name = spec;
    } else {
        // NAME[:PERIOD[:SIZE]]
        turb::ProceduralExemplarSettings p;
        p.pattern = turb::parseProceduralPattern(kind);
        const auto parts = rest.empty() ? std::vector<std::string>{} : split(rest, ':');
        if (!parts.empty()) p.period = toInt(parts[0], "--exemplar " + spec + " (period)");
        p.size = std::max(64, p.period);
        if (p.size % p.period) p.size = (p.size / p.period + 1) * p.period;
        if (parts.size() >= 2) p.size = toInt(parts[1], "--exemplar " + spec + " (size)");
        e = turb::proceduralExemplar(p);
    }
    if (a.exemplarScale != 1.0) e = turb::rescaledExemplar(e, a.exemplarScale);
    turb::normalizeExemplar(e);
    return e;
}

/// Where the coarse frames come from: a cache, a built-in scene simulated on the fly, or an analytic flow.
class CoarseSource
{
public:
    explicit CoarseSource(const SynthArgs& a) : mArgs(a)
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
        } else {
            const std::vector<int> list = a.frames.empty() ? std::vector<int>{1} : turbio::parseFrameList(a.frames);
            // A single number N means frames 1..N.
            if (list.size() == 1 && a.frames.find('-') == std::string::npos)
                for (int f = 1; f <= list[0]; ++f) mFrames.push_back(f);
            else mFrames = list;
            if (mFrames.empty() || mFrames.front() < 1)
                throw turb::ValueError("--frames: scene and flow frames start at 1");
            if (!a.scene.empty()) {
                mSceneSettings = turb::scenes::sceneSettings(
                    a.scene, parseRes(a.sceneRes, "--scene-res"), std::uint64_t(a.sceneSeed));
                mSceneSettings->threads = globals().threads;
                mSim = std::make_unique<turb::scenes::SmokeSim>(*mSceneSettings);
                mLabel = "scene " + a.scene + " " + a.sceneRes;
            } else {
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
        }
    }

    const std::vector<int>& frames() const { return mFrames; }
    const std::string& label() const { return mLabel; }
    /// The cache sequence, when the coarse motion comes from one.
    const std::optional<turbio::Sequence>& sequence() const { return mSeq; }

    turb::Frame read(int frame, turb::Progress* progress)
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

    /// Walls of a built-in scene: its closed faces.
    unsigned sceneWalls() const
    {
        unsigned w = 0;
        if (mSceneSettings)
            for (int i = 0; i < 6; ++i)
                if (mSceneSettings->faces[size_t(i)] == turb::Boundary::Closed) w |= 1u << i;
        return w;
    }
    /// Where a built-in scene's emitters are at frame `frame` (grown by one voxel); nullopt for other inputs.
    std::optional<turb::ScalarField> sceneEmitters(const turb::ScalarField& like, int frame) const
    {
        if (!mSceneSettings) return std::nullopt;
        return turb::scenes::emitterMask(*mSceneSettings, like, frame);
    }
    /// Obstacles of a built-in scene as a signed distance on the coarse lattice.
    std::optional<turb::ScalarField> sceneObstacles(const turb::VectorField& like) const
    {
        if (!mSceneSettings || mSceneSettings->obstacles.empty()) return std::nullopt;
        return turb::scenes::obstacleDistance(*mSceneSettings, like);
    }

private:
    const SynthArgs& mArgs;
    std::optional<turbio::Sequence> mSeq;
    std::vector<int> mFrames;
    std::string mLabel;
    std::optional<turb::scenes::SmokeSettings> mSceneSettings;
    std::unique_ptr<turb::scenes::SmokeSim> mSim;
    turb::VectorField mFlow;
};

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

turb::View parseView(const std::string& s, bool twoD)
{
    if (s == "top" || (s.empty() && twoD)) return turb::View::Top;
    if (s == "side") return turb::View::Side;
    return turb::View::Front;
}

turb::Image labelled(const turb::Image& img, const std::string& label)
{
    turb::Image out(img.width(), img.height() + turb::Image::textHeight(1) + 6, turb::Rgb(0.07f));
    out.blit(img, 0, 0);
    out.drawText(3, img.height() + 3, label, turb::Rgb(0.9f), 1);
    return out;
}

// The synthesis carries look-back density only when the coarse input has density and it is written.
bool cf0HasDensity(const turb::Frame& f, const SynthArgs& a) { return f.hasDensity() && a.seq.density; }

// The command line into the library settings (a.seq.synth, a.seq.combine).
void fillSettings(SynthArgs& a)
{
    turb::SynthSettings& s = a.seq.synth;
    s.threads = globals().threads;
    if (a.secondary != "density") {
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
    const auto largeSmall = [](const std::string& text, const char* option, int& large, int& small) {
        if (text.empty()) return;
        const auto p = split(text, ',');
        if (p.size() == 1) small = toInt(p[0], option);
        else {
            large = toInt(p[0], option);
            small = toInt(p[1], option);
        }
    };
    largeSmall(a.iterations, "--iterations", s.largeIterations, s.smallIterations);
    largeSmall(a.radius, "--radius", s.largeRadius, s.smallRadius);
}

// The views the exemplars serve: one 2D view, one volume exemplar, or planar exemplars along local axes (--views,
// --view-weights).
std::vector<turb::SynthView> synthViews(const SynthArgs& a, const std::vector<turb::Exemplar>& ex, bool volume)
{
    std::vector<turb::SynthView> views;
    std::vector<int> normals;
    if (!a.views.empty())
        for (const auto& t : split(a.views, ',')) normals.push_back(toInt(t, "--views"));
    std::vector<float> weights;
    if (!a.viewWeights.empty())
        for (const auto& t : split(a.viewWeights, ',')) {
            double v;
            if (!parseNumber(t, v) || !(v > 0))
                throw turb::ValueError("--view-weights: '" + t + "' is not a positive number");
            weights.push_back(float(v));
        }
    if (!volume) {
        if (ex.size() != 1) throw turb::ValueError("a 2D synthesis takes exactly one --exemplar");
        views.push_back({ex[0], 2, 1.0f});
    } else if (ex.size() == 1 && !ex[0].planar()) {
        views.push_back({ex[0], -1, 1.0f});
    } else {
        // One planar exemplar serves all three axis views; otherwise one exemplar per view.
        const size_t n = normals.empty() ? (ex.size() == 1 ? 3 : ex.size()) : normals.size();
        if (normals.empty()) {
            if (n > 3)
                throw turb::ValueError("more than three exemplars: say which local axis each looks along with --views");
            for (size_t i = 0; i < n; ++i) normals.push_back(int(i));
        }
        if (ex.size() != 1 && ex.size() != n)
            throw turb::ValueError("--views names " + std::to_string(n) + " views but " + std::to_string(ex.size()) +
                                   " exemplars are given");
        for (size_t i = 0; i < n; ++i) views.push_back({ex[ex.size() == 1 ? 0 : i], normals[i], 1.0f});
    }
    if (!weights.empty()) {
        if (weights.size() != views.size())
            throw turb::ValueError("--view-weights has " + std::to_string(weights.size()) + " values for " +
                                   std::to_string(views.size()) + " views");
        for (size_t i = 0; i < views.size(); ++i) views[i].weight = weights[i];
    }
    return views;
}

// The obstacle: the scene's, or a level set named by --obstacle PATH[:GRID].
std::optional<turb::ScalarField> readObstacle(const SynthArgs& a, CoarseSource& source, const turb::Frame& f0)
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

// Before anything is read in full: every frame's headers, one lattice, the output paths. Sets the one box a
// cache is held over (synth's sources and look-back need one box over the sequence).
std::optional<turbio::SequenceScan> preflightSynth(
    SynthArgs& a, const CoarseSource& source, const std::vector<int>& frames, const turbio::FramePattern& outPattern)
{
    std::optional<turbio::SequenceScan> scan;
    std::vector<std::string> outputs, inputs;
    for (int fr : frames) outputs.push_back(outPattern.format(fr));
    if (const auto& seq = source.sequence()) {
        turbio::ReadOptions ro = a.read;
        ro.requireDensity = false;
        scan = checkInput("synth", "target", *seq, frames, ro, LatticePolicy::Refuse);
        reportTiming("target", *scan, true);
        // Synth's density sources and look-back need one box over the sequence: the union of the frames'
        // held boxes (each the smoke and its margin, strays left out), not the cache's domain. Over every frame on
        // disk, not only the requested ones (header boxes: cheap): a shot rendered in parts (--frames 1-10, then
        // 11-20, or on a farm) then holds the same box, and gives the same frames, as one run over the whole shot.
        if (a.read.cropToSmoke) {
            // The requested frames are scanned already; only the others are read here.
            const turbio::Sequence onDisk = turbio::resolveSequence(seq->pattern.str());
            std::vector<int> asked = frames, onDiskSorted = onDisk.frames, others;
            std::sort(asked.begin(), asked.end());
            std::sort(onDiskSorted.begin(), onDiskSorted.end());
            std::set_difference(
                onDiskSorted.begin(), onDiskSorted.end(), asked.begin(), asked.end(), std::back_inserter(others));
            turb::CoordBBox all;
            for (const auto& fs : scan->frames) all.expand(fs.domain);
            if (!others.empty())
                for (const auto& fs : turbio::scanSequence(onDisk, others, ro).frames) all.expand(fs.domain);
            a.read.holdBox = all;
        }
        for (int fr : frames) inputs.push_back(seq->path(fr));
    }
    checkOutputs(outputs, inputs, a.write.noClobber, a.skipExisting);
    return scan;
}

// The output lattice (dry run and -vv) and the memory check, from the largest coarse frame.
void checkSynthLatticeAndMemory(const SynthArgs& a, const turb::Frame& f0,
    const std::optional<turbio::SequenceScan>& scan, bool volume, int frameCount)
{
    const turb::SynthSettings& s = a.seq.synth;
    turb::CoordBBox coarse = f0.velocity.bbox();
    if (scan)
        if (const turbio::FrameScan* l = scan->largestDomain()) coarse = l->domain;
    const turb::FineDomain d = turb::fineDomain(f0.velocity, a.seq.factor);
    const turb::Lattice& cl = f0.velocity.lattice();
    const turb::Vec3d lo = cl.indexToWorld(coarse.min().asVec3d() - turb::Vec3d(0.5));
    const turb::Vec3d hi = cl.indexToWorld(coarse.max().asVec3d() + turb::Vec3d(0.5));
    const double outVoxels = double(coarse.volume()) * std::pow(double(a.seq.factor), volume ? 3.0 : 2.0);
    if (globals().dryRun || globals().verbosity >= 2)
        printData("output lattice: " + std::to_string(d.box.dim().x()) + "x" + std::to_string(d.box.dim().y()) + "x" +
                  std::to_string(d.box.dim().z()) + " voxels of " + fmt("%g", d.lattice.voxelSize) + " (factor " +
                  std::to_string(a.seq.factor) + "), world (" + fmt("%.4g", lo.x()) + "," + fmt("%.4g", lo.y()) + "," +
                  fmt("%.4g", lo.z()) + ")-(" + fmt("%.4g", hi.x()) + "," + fmt("%.4g", hi.y()) + "," +
                  fmt("%.4g", hi.z()) + "); output size about " + turbio::formatBytes(outVoxels * 16.0) + " per frame");
    const int lb = cf0HasDensity(f0, a) ? a.seq.lookback : 0;
    // The synthesis runs on the box grown by --face-padding on its open faces (walls not grown).
    double grown = 1.0;
    for (int ax = 0; ax < (volume ? 3 : 2); ++ax) {
        const int open = !(s.boundary.walls & (1u << (2 * ax))) + !(s.boundary.walls & (1u << (2 * ax + 1)));
        grown *= double(coarse.dim()[ax] + open * s.facePadding) / double(coarse.dim()[ax]);
    }
    const double coarseVoxels = (volume ? double(coarse.volume()) : double(coarse.volume()) / a.seq.factor) * grown;
    const double need = turb::synthPeakBytes(coarseVoxels, a.seq.factor, frameCount, lb);
    const long long usable = turbio::usableMemoryBytes();
    const int fMax = usable > 0 ? turb::largestSynthFactor(0.9 * double(usable), coarseVoxels, frameCount, lb) : 0;
    checkMemory(need,
        std::to_string(coarse.dim().x()) + "x" + std::to_string(coarse.dim().y()) + "x" +
            std::to_string(coarse.dim().z()) + " coarse voxels at factor " + std::to_string(a.seq.factor),
        fMax >= 1 ? "--factor " + std::to_string(fMax) + " fits" : "no factor fits: crop the coarse cache");
}

// The projection's outcome for the JSON line; one that stopped short is warned about and listed.
nlohmann::json projectionReport(const SynthArgs& a, const turb::SynthFrameResult& r, int fr, ConsoleProgress& progress,
    std::vector<int>& unconverged)
{
    nlohmann::json projJson;
    if (r.projection) {
        const turb::ProjectionResult& pr = *r.projection;
        projJson = {{"converged", pr.converged}, {"iterations", pr.iterations}, {"div_max_before", pr.divMaxBefore},
            {"div_max_after", pr.divMaxAfter}};
        if (!pr.converged) {
            // A solver that stops short is a result the user must hear about, not only a JSON field.
            unconverged.push_back(fr);
            progress.clear();
            logWarning("frame " + std::to_string(fr) + ": the projection did not converge (" +
                       std::to_string(pr.iterations) + " iterations); the written velocity is not divergence-free" +
                       (a.strict ? "" : " (--strict makes this an error)"));
            logVerbose("frame " + std::to_string(fr) + ": projection max|div| " + fmt("%.3g", pr.divMaxBefore) +
                       " -> " + fmt("%.3g", pr.divMaxAfter) + " (x" + fmt("%.2e", pr.relativeDivergence()) +
                       "), solver residual " + fmt("%.2e", pr.relativeResidual));
        }
    }
    return projJson;
}

// The detail's divergence solve for the JSON line (null without one); one that stopped short is warned about and
// listed, as a projection is.
nlohmann::json detailDivergenceReport(const SynthArgs& a, const turb::SynthFrameResult& r, int fr,
    ConsoleProgress& progress, std::vector<int>& unconverged)
{
    if (!r.detailDivergence) return nullptr;
    const turb::CentralDivergenceResult& d = *r.detailDivergence;
    logVerbose("frame " + std::to_string(fr) + ": detail divergence rms " + fmt("%.3g", d.divRmsBefore) + " -> " +
               fmt("%.3g", d.divRmsAfter) + " (" + std::to_string(d.iterations) + " CG iterations)");
    if (!d.converged) {
        if (unconverged.empty() || unconverged.back() != fr) unconverged.push_back(fr);
        progress.clear();
        logWarning("frame " + std::to_string(fr) + ": taking the detail's divergence out did not converge (" +
                   std::to_string(d.iterations) + " iterations, rms " + fmt("%.3g", d.divRmsBefore) + " -> " +
                   fmt("%.3g", d.divRmsAfter) + ")" + (a.strict ? "" : " (--strict makes this an error)"));
    }
    return {{"converged", d.converged}, {"iterations", d.iterations}, {"div_rms_before", d.divRmsBefore},
        {"div_rms_after", d.divRmsAfter}};
}

// --stats: how well each planar view's neighbourhoods match its exemplar.
nlohmann::json textureStats(const std::vector<turb::SynthView>& views, const turb::DetailField& H, bool volume)
{
    nlohmann::json m = nlohmann::json::array();
    for (size_t v = 0; v < views.size(); ++v) {
        if (!views[v].exemplar.planar()) continue;
        turb::TextureMatchSettings ts;
        ts.axis = volume ? views[v].normal : 2; // exact for axis-aligned local frames
        ts.stride = volume ? 8 : 4;
        const turb::TextureMatch tm = turb::textureMatch(views[v].exemplar, H.local, ts);
        m.push_back({{"view", v}, {"nn_distance", tm.distance}, {"shuffled", tm.shuffled}, {"ratio", tm.ratio()},
            {"rms", {tm.fieldRms[0], tm.fieldRms[1]}}, {"exemplar_rms", {tm.exemplarRms[0], tm.exemplarRms[1]}}});
    }
    return m;
}

// --preview: a sheet of the exemplar, up(L), H', F and the density; returns the picture's path.
std::string writeSynthPreview(const SynthArgs& a, const std::vector<turb::SynthView>& views, const turb::Frame& cf,
    const turb::DetailField& H, const turb::VectorField& F, const turb::Frame& outFrame, int fr, bool volume)
{
    const turb::View view = parseView(a.previewView, !volume);
    turb::LicSettings ls;
    ls.view = view;
    ls.width = a.previewWidth;
    turb::LicSettings le = ls;
    le.view = turb::View::Top;
    le.width = std::max(64, a.previewWidth / 2);
    const turb::Image exImg = labelled(turb::renderLic(turb::exemplarAsField(views[0].exemplar), le), "exemplar");
    const turb::Image hImg = labelled(turb::renderLic(H.world, ls), "detail H'");
    const turb::Image lImg =
        labelled(turb::renderLic(turb::upsampleCoarse(cf.velocity, a.seq.factor), ls), "coarse up(L)");
    const turb::Image fImg = labelled(turb::renderLic(F, ls), "F = up(L) + w H'");
    std::vector<turb::SheetCell> row{{&exImg, ""}, {&lImg, ""}, {&hImg, ""}, {&fImg, ""}};
    turb::Image dImg;
    if (!outFrame.density.empty()) {
        turb::DensityRenderSettings dr;
        dr.view = view;
        dr.width = a.previewWidth;
        dImg = labelled(volume ? turb::renderDensity(outFrame.density, dr)
                               : turb::renderSlice(outFrame.density, turb::SliceSettings{view, 0.5, a.previewWidth}),
            "density");
        row.push_back({&dImg, ""});
    }
    const turb::Image sheet = turb::contactSheet({row}, {""}, "synth frame " + std::to_string(fr), 1);
    const std::string png = a.preview + "/" + turbio::FramePattern::parse("synth.####." + a.previewFormat).format(fr);
    turbio::ensureParentDirectory(png);
    turbio::writeImage(png, sheet);
    return png;
}

// A frame's JSON line: the output, the synthesis's levels and energies, the detail's strength and region.
nlohmann::json frameJson(const SynthArgs& a, const turb::SynthFrameResult& r, const turb::DetailField& H,
    bool hasDensity, const nlohmann::json& projJson, const std::string& outPath)
{
    const turb::VectorField& F = r.motion;
    nlohmann::json extra;
    extra["out"] = outPath;
    extra["size"] = {F.bbox().dim().x(), F.bbox().dim().y(), F.bbox().dim().z()};
    extra["continued"] = H.fromPrevious;
    nlohmann::json lv = nlohmann::json::array();
    for (const auto& l : H.levels) {
        nlohmann::json lj = {{"level", l.level}, {"size", {l.dim.x(), l.dim.y(), l.dim.z()}}, {"radius", l.radius},
            {"energy", l.energy}};
        if (!l.descent.empty()) lj["descent"] = l.descent; // [at search, after the average, after all terms]
        lv.push_back(lj);
    }
    extra["levels"] = lv;
    extra["energy"] = H.finalEnergy();
    double h2 = 0.0;
    for (const auto& v : H.world.values()) h2 += v.lengthSqr();
    extra["detail_rms"] = std::sqrt(h2 / double(std::max<size_t>(1, H.world.size())));
    extra["detail_region"] = a.seq.detailNearSmoke && hasDensity ? "smoke" : "everywhere";
    if (a.seq.project) extra["projection"] = projJson;
    if (r.densityMass) extra["density_mass"] = *r.densityMass;
    return extra;
}

// What the written frame records about how it was made.
void tagOutput(turb::Frame& outFrame, const SynthArgs& a, const std::vector<turb::SynthView>& views)
{
    outFrame.metadata[turb::meta::kCommand] = "synth";
    std::string names;
    for (const auto& v : views) names += (names.empty() ? "" : ",") + v.exemplar.name;
    outFrame.metadata[turb::meta::kExemplars] = names;
    outFrame.metadata[turb::meta::kOmega] = fmt("%g", a.seq.combine.omega) +
                                            (a.seq.combine.relative ? " x rms|L|" : "") + " " +
                                            weightingName(a.seq.combine.weighting);
    outFrame.metadata[turb::meta::kSeed] = std::to_string(a.seq.synth.seed);
    outFrame.metadata[turb::meta::kRatio] = std::to_string(a.seq.factor); // Blender-style placement (io.md)
}

// The run's fixed parts: the coarse input, its first frame, the exemplars as views, walls and obstacle.
struct SynthPlan
{
    std::vector<int> frames;
    turbio::FramePattern out;
    std::optional<turbio::SequenceScan> scan;
    turb::Frame first; ///< the first coarse frame, read to decide 2D or 3D and the views
    bool volume = false;
    std::vector<turb::SynthView> views;
    std::optional<turb::ScalarField> obstacle;
    std::vector<std::string> outputs, settings; ///< per frame: the file and the settings it records
    SkipPlan skips;                             ///< --skip-existing
};

SynthPlan planSynth(SynthArgs& a, CoarseSource& source)
{
    SynthPlan p;
    p.frames = source.frames();
    p.out = turbio::FramePattern::parse(a.out);
    checkOutputFormat(a.write, a.out, a.skipExisting ? "--skip-existing" : "");
    if (p.frames.size() > 1 && !p.out.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(p.frames.size()) + " frames are requested");
    p.scan = preflightSynth(a, source, p.frames, p.out);
    if (a.exemplars.empty()) a.exemplars.push_back("circles:16");
    std::vector<turb::Exemplar> ex;
    for (const auto& spec : a.exemplars) ex.push_back(loadExemplar(spec, a));
    ConsoleProgress progress(0, int(p.frames.size()), p.frames.front());
    progress.begin("reading");
    p.first = source.read(p.frames.front(), &progress);
    progress.clear();
    if (!p.first.hasVelocity())
        throw turb::ValueError(source.label() + ": frame " + std::to_string(p.frames.front()) + " has no velocity");
    p.volume = p.first.bbox().dim().z() > 1;
    p.views = synthViews(a, ex, p.volume);
    a.seq.synth.boundary.walls = a.walls.empty() ? source.sceneWalls() : parseWalls(a.walls);
    p.obstacle = readObstacle(a, source, p.first);
    return p;
}

void logPlan(const SynthArgs& a, const CoarseSource& source, const SynthPlan& p)
{
    logInfo("synth: " + source.label() + ", frames " + turbio::formatFrameList(p.frames) + ", " +
            (p.volume ? "3D" : "2D") + ", factor " + std::to_string(a.seq.factor) + ", " +
            std::to_string(p.views.size()) + " view" + (p.views.size() == 1 ? "" : "s") + ", " +
            (a.seq.synth.search == turb::SearchMethod::Tree ? "tree search" : "k-coherence"));
    for (const auto& v : p.views)
        logInfo("  exemplar " + v.exemplar.name + " (" + std::to_string(v.exemplar.nx) + "x" +
                std::to_string(v.exemplar.ny) + (v.exemplar.planar() ? "" : "x" + std::to_string(v.exemplar.nz)) +
                (v.exemplar.periodic ? ", periodic" : "") + ")" +
                (v.exemplar.planar() && p.volume ? ", looks along e" + std::to_string(v.normal + 1) : "") +
                (p.views.size() > 1 ? ", weight " + fmt("%g", v.weight) : ""));
}

// -v: every level's energy after each iteration.
void logLevels(const turb::DetailField& H, int fr)
{
    for (const auto& l : H.levels) {
        std::string e;
        for (double x : l.energy) e += fmt(" %.4f", x);
        logVerbose("frame " + std::to_string(fr) + ": level " + std::to_string(l.level) + " " +
                   std::to_string(l.dim.x()) + "x" + std::to_string(l.dim.y()) + "x" + std::to_string(l.dim.z()) +
                   " energy" + e);
    }
}

// One frame: read, synthesise and combine, write, report.
void synthFrame(const SynthArgs& a, CoarseSource& source, SynthPlan& p, turb::SynthSequence& sequence, size_t i,
    RunReport& report, std::vector<int>& unconverged, bool& warnedClipping)
{
    const int fr = p.frames[i];
    const auto t0 = std::chrono::steady_clock::now();
    ConsoleProgress progress(int(i), int(p.frames.size()), fr);
    progress.begin("reading");
    turb::Frame cf = i == 0 ? std::move(p.first) : source.read(fr, &progress);
    if (!cf.hasVelocity())
        throw turb::ValueError(source.label() + ": frame " + std::to_string(fr) + " has no velocity");
    const double readSeconds = secondsSince(t0);

    turb::SynthFrameInput in;
    in.coarse = &cf.velocity;
    in.coarseDensity = cf.hasDensity() ? &cf.density : nullptr;
    in.obstacle = p.obstacle ? &*p.obstacle : nullptr;
    in.frame = fr;
    in.dt = cf.dt > 0.0 ? cf.dt : a.flowDt;
    in.timeUnit = cf.timeUnit;
    const std::optional<turb::ScalarField> emitters =
        cf.hasDensity() && a.seq.density ? source.sceneEmitters(cf.density, fr) : std::nullopt;
    in.emitters = emitters ? &*emitters : nullptr;
    turb::SynthFrameResult r;
    try {
        r = sequence.next(in, &progress);
    } catch (const turb::ValueError& e) {
        const auto& seq = source.sequence();
        throw turb::ValueError(
            "frame " + std::to_string(fr) + (seq ? " (" + seq->path(fr) + ")" : std::string()) + ": " + e.what(),
            e.settings());
    }
    const turb::DetailField& H = sequence.lastDetail();
    turb::Frame& outFrame = r.frame;
    if (r.smokeless) {
        progress.clear();
        logWarning("frame " + std::to_string(fr) + ": the density has no smoke (nothing above " +
                   fmt("%g", a.seq.combine.smokeThreshold) +
                   "), so no detail is written; --detail-everywhere puts it everywhere");
    }
    const nlohmann::json projJson = projectionReport(a, r, fr, progress, unconverged);
    const nlohmann::json divJson = detailDivergenceReport(a, r, fr, progress, unconverged);
    const auto tWrite = std::chrono::steady_clock::now();
    const std::string outPath = p.out.format(fr);
    if (p.skips.skipped(i)) {
        progress.clear();
        report.frameSkipped(fr, int(i), int(p.frames.size()), secondsSince(t0), outPath, true);
        return;
    }
    tagOutput(outFrame, a, p.views);
    outFrame.metadata[turb::meta::kSettings] = p.settings[i];
    progress.begin("writing");
    turbio::ensureParentDirectory(outPath);
    warnIfClippedAway(outFrame, a.write, outPath, warnedClipping);
    turbio::writeFrame(outPath, outFrame, a.write);
    const double writeSeconds = secondsSince(tWrite);

    nlohmann::json extra = frameJson(a, r, H, cf.hasDensity(), projJson, outPath);
    if (!divJson.is_null()) extra["detail_divergence"] = divJson;
    extra["steps_s"] = {{"read", readSeconds}, {"write", writeSeconds}};
    for (const auto& [name, sec] : r.seconds.named()) extra["steps_s"][name] = sec;
    if (a.stats) {
        progress.begin("statistics");
        extra["texture_match"] = textureStats(p.views, H, p.volume);
    }
    if (!a.preview.empty()) {
        progress.begin("preview");
        extra["preview"] = writeSynthPreview(a, p.views, cf, H, r.motion, outFrame, fr, p.volume);
    }
    progress.clear();
    const std::string human =
        std::string(H.fromPrevious ? "continued" : "synthesised") + fmt(", E %.4f", H.finalEnergy()) +
        fmt(", |H'| rms %.3f", extra["detail_rms"].get<double>()) + fmt(", synthesis %.2f s", r.seconds.synthesis) +
        (a.seq.project ? " projection " + std::to_string(projJson["iterations"].get<int>()) + " it" : "") + " -> " +
        outPath;
    logLevels(H, fr);
    report.frameDone(fr, int(i), int(p.frames.size()), secondsSince(t0), human, extra);
}

int runSynth(SynthArgs& a)
{
    fillSettings(a);
    CoarseSource source(a);
    SynthPlan p = planSynth(a, source);
    logPlan(a, source, p);
    checkSynthLatticeAndMemory(a, p.first, p.scan, p.volume, int(p.frames.size()));
    for (int fr : p.frames) p.outputs.push_back(p.out.format(fr));
    // Each frame continues the one before it: what it records names the run's frames up to it.
    p.settings = sequentialSettings(
        commandSettingsText(*a.app, a.target.empty() ? std::vector<std::string>{} : std::vector<std::string>{a.target}),
        p.frames);
    p.skips = planSkips(p.outputs, p.frames, "synth", p.settings, a.skipExisting);
    if (globals().dryRun) {
        printSkipPlan(p.skips, p.outputs);
        return kOk;
    }
    lockOutputFrames(p.out, p.skips.writing); // two tasks never write one frame (a second exits 75)
    if (a.seq.synth.traceDescent && !a.json) logWarning("--trace-descent reports in the JSON lines only: add --json");
    // The report's clock starts here, so its total includes building the exemplar indices.
    RunReport report("synth", a.json);
    const auto tPrep = std::chrono::steady_clock::now();
    ConsoleProgress prepProgress(0, int(p.frames.size()), p.frames.front());
    prepProgress.begin("exemplar indices");
    const turb::SynthExemplars prepared(p.views, a.seq.synth, p.volume, &prepProgress);
    prepProgress.clear();
    logVerbose("exemplar pyramids and indices: " + fmt("%.2f s", secondsSince(tPrep)) + ", " +
               std::to_string(prepared.levels()) + " levels");
    turb::SynthSequence sequence(prepared, a.seq);
    std::vector<int> unconverged; // frames whose projection or detail divergence solve stopped short
    bool warnedClipping = false;
    for (size_t i = 0; i < p.skips.end; ++i) synthFrame(a, source, p, sequence, i, report, unconverged, warnedClipping);
    report.finish();
    if (unconverged.empty()) return kOk;
    std::string list;
    for (int fr : unconverged) list += (list.empty() ? "" : ", ") + std::to_string(fr);
    const std::string msg = std::to_string(unconverged.size()) +
                            " frame(s) with a projection or a detail divergence solve that did not converge: " + list;
    if (a.strict) {
        return reportFailure(msg + " (--strict)", kFailed);
    }
    logWarning(msg);
    return kOk;
}

} // namespace

namespace {

// A second-tier setting of the command: the option under `key`.
template<typename T>
CLI::Option* knob(CLI::App* app, const std::string& names, T& v, const std::string& help, const std::string& key)
{
    return setting(app->add_option(names, v, help), key);
}

// Where the coarse motion comes from beyond the everyday --target/--scene/--flow, and the exemplars' shape.
void addInputSettings(CLI::App* app, SynthArgs& a)
{
    knob(app, "--scene-res", a.sceneRes, "Scene cells NXxNYxNZ along x, y, z (z is up), as sim --res", "scene-res");
    knob(app, "--scene-seed", a.sceneSeed, "Scene emitter noise seed", "scene-seed");
    knob(app, "--flow-res", a.flowRes, "Analytic flow cells NXxNYxNZ along x, y, z; NZ = 1 is 2D", "flow-res");
    knob(app, "--flow-speed", a.flowSpeed, "Analytic flow speed, world units/s (the domain is 4 units wide)",
        "flow-speed");
    knob(app, "--flow-angle", a.flowAngle, "Uniform flow direction in the xy plane, degrees from +x", "flow-angle");
    knob(app, "--slice-z", a.sliceZ, "Synthesise in 2D on coarse layer K of a 3D input", "slice-z")
        ->check(finiteIn(0.0));
    knob(app, "--exemplar-scale", a.exemplarScale, "Texture scale: features this many times larger", "exemplar-scale")
        ->check(finitePositive());
    knob(app, "--volume-crop", a.volumeCrop, "vdb3 exemplars: use the central N^3 voxels", "volume-crop")
        ->check(CLI::Range(8, 128));
    setting(app->add_flag("--periodic", a.periodic, "Picture/VDB exemplars tile seamlessly (procedurals always do)"),
        "periodic");
    knob(app, "--views", a.views,
        "3D: local axis each exemplar looks along, e.g. 0,1,2 (0 = along L; one exemplar for all views by default)",
        "views");
    knob(app, "--view-weights", a.viewWeights, "3D: relative weight per view, e.g. 1,1,4", "view-weights");
    knob(app, "--obstacle", a.obstacle, "Obstacle signed distance: FILE.vdb[:GRID] in world units (grid 'surface')",
        "obstacle");
}

// The texture optimisation (Ma et al. sections 3.2-3.4, 3.7): pyramid, neighbourhoods, search, orientation.
void addSynthesisSettings(CLI::App* app, SynthArgs& a)
{
    turb::SynthSettings& s = a.seq.synth;
    setting(addEnum<turb::SearchMethod>(app, "--search,--synth.search", s.search,
                {{"tree", turb::SearchMethod::Tree}, {"kcoherence", turb::SearchMethod::KCoherence}},
                "Neighbourhood search: tree (the paper) or k-coherence (section 3.7)"),
        "synth.search");
    knob(app, "--k,--synth.kSimilar", s.kSimilar, "k-coherence: similar neighbourhoods per exemplar pixel",
        "synth.kSimilar")
        ->check(CLI::Range(1, 64));
    knob(app, "--tree-iterations,--synth.treeIterationsPerLevel", s.treeIterationsPerLevel,
        "k-coherence: iterations per level that still search the tree (0 = pure k-coherence)",
        "synth.treeIterationsPerLevel")
        ->check(CLI::Range(0, 100));
    knob(app, "--levels,--synth.levels", s.levels, "Pyramid levels (0 = the paper's: 3, or 2 for exemplars <= 16^2)",
        "synth.levels")
        ->check(CLI::Range(0, 8));
    knob(app, "--iterations", a.iterations, "Iterations per level: LARGE,SMALL in 2D, SMALL in 3D (paper 3-5)",
        "iterations");
    knob(app, "--radius", a.radius, "Neighbourhood radii LARGE,SMALL (8,4 = 17^2 and 9^2)", "radius");
    knob(app, "--spacing,--synth.spacing", s.spacing, "Distance between neighbourhood centres (0 = auto)",
        "synth.spacing")
        ->check(CLI::Range(0, 16));
    knob(app, "--tap-step,--synth.volumeTapStep", s.volumeTapStep,
        "vdb3 exemplars: a tap every N voxels over the 9^3 footprint (1 = all 729)", "synth.volumeTapStep")
        ->check(CLI::Range(1, 4));
    knob(app, "--pca,--synth.pcaComponents", s.pcaComponents, "PCA dimensions for the tree search",
        "synth.pcaComponents")
        ->check(CLI::Range(1, 256));
    knob(app, "--robust,--synth.robustExponent", s.robustExponent,
        "Robust exponent r of Kwatra's weights (2 = least squares)", "synth.robustExponent")
        ->check(finiteIn(0.01, 2.0));
    boolSetting(app, "--synth.matchVariance", s.matchVariance,
        "3D: views keep their mean and spread (false: the paper's plain average)", "synth.matchVariance");
    legacy(app->add_flag_function(
               "--no-variance-match", [&s](int64_t) { s.matchVariance = false; }, ""),
        "synth.matchVariance", "false");
    boolSetting(app, "--synth.orientation.follow", s.orientation.follow,
        "Neighbourhoods and vectors follow L's local frame (false: world axes)", "synth.orientation.follow");
    legacy(app->add_flag_function(
               "--no-orient", [&s](int64_t) { s.orientation.follow = false; }, ""),
        "synth.orientation.follow", "false");
    knob(app, "--secondary", a.secondary,
        "3D second local axis: density (its gradient, else the direction L has least of) or a fixed vector X,Y,Z",
        "secondary");
    knob(app, "--seed,--synth.seed", s.seed, "Random seed: the same seed gives the same output", "synth.seed");
    knob(app, "--continue-iterations,--synth.continueIterations", s.continueIterations,
        "Later frames: iterations from the advected detail", "synth.continueIterations")
        ->check(CLI::Range(1, 100));
    knob(app, "--temporal-weight,--synth.temporalWeight", s.temporalWeight,
        "Later frames: pull toward the advected detail", "synth.temporalWeight")
        ->check(finiteIn(0.0));
    knob(app, "--wall-lambda,--synth.boundary.lambda", s.boundary.lambda,
        "Wall term weight: normal detail shrinks by 1/(1+lambda) on the wall", "synth.boundary.lambda")
        ->check(finiteIn(0.0));
    knob(app, "--wall-width,--synth.boundary.width", s.boundary.width,
        "Gaussian width of the wall term in voxels of each level", "synth.boundary.width")
        ->check(finitePositive());
    knob(app, "--face-padding,--synth.facePadding", s.facePadding,
        "Coarse cells synthesised beyond each open box face and cut off, so faces show no seams (0 = the paper)",
        "synth.facePadding")
        ->check(CLI::Range(0, 16));
    setting(app->add_flag("--trace-descent,--synth.traceDescent", s.traceDescent,
                "JSON: Kwatra's objective at every step of every iteration (levels[].descent; slower)"),
        "synth.traceDescent");
}

// CLI11's number ranges let NaN through and print their infinite bound in full.
CLI::Validator coarseCells(bool zeroOk)
{
    return CLI::Validator(
        [zeroOk](std::string& text) -> std::string {
            double v = 0.0;
            if (!parseNumber(text, v) || !std::isfinite(v) || v > 1e6 || (zeroOk ? v < 0.0 : v <= 0.0))
                return std::string("must be a number of coarse cells ") + (zeroOk ? ">= 0" : "> 0") + " (up to 1e6)";
            return {};
        },
        zeroOk ? "CELLS>=0" : "CELLS>0");
}

// F = up(L) + omega H' (section 3.5), the projection, the density and the pictures.
void addCombineSettings(CLI::App* app, SynthArgs& a)
{
    turb::SynthSequenceSettings& q = a.seq;
    turb::CombineSettings& c = q.combine;
    boolSetting(app, "--combine.removeCoarsePart", c.removeCoarsePart,
        "Take the detail's coarse part out, so the coarse motion stays L's (false: the paper's F)",
        "combine.removeCoarsePart");
    legacy(app->add_flag_function(
               "--keep-coarse", [&c](int64_t) { c.removeCoarsePart = false; }, ""),
        "combine.removeCoarsePart", "false");
    boolSetting(app, "--combine.solenoidalDetail", c.solenoidalDetail,
        "Take the detail's central-difference divergence out, so F's div_rel stays at or below L's (false: the paper)",
        "combine.solenoidalDetail");
    legacy(app->add_flag_function(
               "--keep-divergence", [&c](int64_t) { c.solenoidalDetail = false; }, ""),
        "combine.solenoidalDetail", "false");
    knob(app, "--combine.solenoidalTolerance", c.solenoidalTolerance,
        "Relative rms divergence left in the detail by that solve", "combine.solenoidalTolerance")
        ->check(finiteIn(1e-9, 0.999));
    knob(app, "--combine.solenoidalIterations", c.solenoidalIterations, "Conjugate-gradient cap of that solve",
        "combine.solenoidalIterations")
        ->check(CLI::Range(1, 100000));
    boolSetting(app, "--combine.relative", c.relative, "omega is relative to L's rms speed (false: velocity units)",
        "combine.relative");
    legacy(app->add_flag_function(
               "--omega-absolute", [&c](int64_t) { c.relative = false; }, ""),
        "combine.relative", "false");
    setting(addEnum<turb::CombineSettings::Weighting>(app, "--omega-mode,--combine.weighting", c.weighting, kWeightings,
                "Shape of omega: constant, energy (|L|^2), vorticity (|curl L|)"),
        "combine.weighting");
    knob(app, "--detail-margin,--combine.smokeMargin", c.smokeMargin,
        "Coarse cells of full detail around the smoke; the detail then fades out", "combine.smokeMargin")
        ->check(coarseCells(true));
    knob(app, "--detail-falloff,--combine.smokeFalloff", c.smokeFalloff,
        "Coarse cells over which the detail fades to zero beyond the margin", "combine.smokeFalloff")
        ->check(coarseCells(false));
    boolSetting(app, "--detailNearSmoke", q.detailNearSmoke,
        "Detail near the smoke only, when L has density (false: the whole box, the paper)", "detailNearSmoke");
    legacy(app->add_flag_function(
               "--detail-everywhere", [&q](int64_t) { q.detailNearSmoke = false; }, ""),
        "detailNearSmoke", "false");
    knob(app, "--project-iterations,--projectIterations", q.projectIterations, "Conjugate-gradient cap of --project",
        "projectIterations")
        ->check(CLI::Range(1, 100000));
    boolSetting(
        app, "--detailOnly", q.detailOnly, "Write F - up(L), what the synthesis added (false: F)", "detailOnly");
    legacy(app->add_option_function<std::string>(
                  "--output", [&q](const std::string& v) { q.detailOnly = v == "detail"; }, "combined or detail")
               ->check(CLI::IsMember({"combined", "detail"})),
        "detailOnly");
    knob(app, "--lookback", q.lookback, "Density: frames of look-back integration m (paper 10-20; 0 = naive)",
        "lookback")
        ->check(CLI::Range(0, 200));
    boolSetting(app, "--density", q.density, "Carry a fine density (false: velocity only)", "density");
    legacy(app->add_flag_function(
               "--no-density", [&q](int64_t) { q.density = false; }, ""),
        "density", "false");
    knob(app, "--preview-format", a.previewFormat, "Picture format of --preview: png, exr (linear half), tif",
        "preview-format")
        ->check(CLI::IsMember({"png", "exr", "tif"}));
    knob(app, "--preview-width", a.previewWidth, "Width of each preview panel in pixels", "preview-width")
        ->check(CLI::Range(32, 4096));
    knob(app, "--preview-view", a.previewView, "Preview slice: top, front, side (top in 2D, front in 3D)",
        "preview-view")
        ->check(CLI::IsMember({"top", "front", "side"}));
    setting(app->add_flag("--stats", a.stats,
                "Texture statistics per frame: nearest-neighbour distance to each exemplar against a shuffled field"),
        "stats");
}

} // namespace

Command synthCommand()
{
    auto args = std::make_shared<SynthArgs>();
    Command c;
    c.name = "synth";
    c.help = "Motion-field texture synthesis: detail motion from small exemplars, oriented along a coarse flow";
    c.setup = [args](CLI::App* app) {
        SynthArgs& a = *args;
        app->add_option("--target", a.target, "Coarse motion L: a VDB cache (pattern or one file); density optional");
        app->add_option("--scene", a.scene,
            "Coarse motion from a built-in scene simulated on the fly (plume, swirl, obstacle, wind)");
        app->add_option("--flow", a.flow, "Coarse motion from an analytic flow (no density)")
            ->check(CLI::IsMember({"uniform", "vortex", "shear"}));
        app->add_option(
               "--frames", a.frames, "Cache: frames to use (default all). Scene/flow: a count N or a list (default 1)")
            ->check(frameListCheck());
        app->add_option("--factor", a.seq.factor, "Up-res factor: output voxel = coarse voxel / factor")
            ->check(CLI::Range(1, 32));
        app->add_option("--exemplar", a.exemplars,
            "Exemplar, repeatable (one per view): circles|swirls|squares|hearts|stripes|sinusoids[:PERIOD[:SIZE]] "
            "(default "
            "circles:16), rg:PICTURE[:SCALE], gray:PICTURE[:SCALE], vdb:FILE.vdb[:AXIS:INDEX], vdb3:FILE.vdb "
            "(docs/synth.md)");
        app->add_option("--omega", a.seq.combine.omega, "Detail strength: times rms|L|")->check(finiteIn(0.0));
        app->add_option(
            "--walls", a.walls, "Walls: x-,x+,y-,y+,z-,z+, all or none (default: a scene's closed faces, else none)");
        app->add_flag(
            "--project", a.seq.project, "Make F divergence-free (Helmholtz-Hodge projection); walls are closed faces");
        app->add_flag("--strict", a.strict,
            "Exit 1 when a projection or the detail's divergence solve does not converge (always a warning naming the "
            "frame)");
        app->add_option(
            "--preview", a.preview, "Write a picture per frame into DIR: LIC of exemplar, up(L), H', F, and density");
        app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.read);
        app->add_option("--out", a.out, "Output pattern (directories are created)")->group(kGroupOutput);
        addWriteOptions(app, a.write);
        app->add_flag("--skip-existing", a.skipExisting,
               "Skip the frames already written by the same settings (farm wrappers' retries; the frames before the "
               "last one to write are made again, not written); a frame written otherwise is refused (exit 1)")
            ->group(kGroupOutput);
        a.app = app;
        addInputSettings(app, a);
        addSynthesisSettings(app, a);
        addCombineSettings(app, a);
    };
    c.run = [args] { return runSynth(*args); };
    return c;
}

} // namespace vdbturb
