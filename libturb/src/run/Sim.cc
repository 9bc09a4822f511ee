// turb::run::runSim: vdbturb sim's run (turb/run/Sim.h).
#include <turb/run/Sim.h>

#include "RunHelpers.h"

#include <turb/run/Output.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <scenes/Ink2D.h>
#include <scenes/Smoke.h>
#include <turb/Error.h>
#include <turb/Metadata.h>
#include <turb/Parallel.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <sstream>

namespace turb::run {

using detail::fmt;
using detail::secondsSince;

namespace {} // namespace

turb::Coord parseResolution(const std::string& text)
{
    int x = 0, y = 0, z = 0;
    char c1 = 0, c2 = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%d%c%d%c%d%c", &x, &c1, &y, &c2, &z, &extra) == 5 && (c1 == 'x' || c1 == 'X') &&
        (c2 == 'x' || c2 == 'X'))
        return turb::Coord(x, y, z);
    if (std::sscanf(text.c_str(), "%d%c", &x, &extra) == 1) return turb::Coord(x, x, x);
    throw turb::ValueError("--res: expected NXxNYxNZ (cells along x, y, z; e.g. 16x16x24) or N, got '" + text + "'");
}

namespace {

std::string resText(const turb::Coord& r)
{
    return std::to_string(r.x()) + "x" + std::to_string(r.y()) + "x" + std::to_string(r.z());
}

/// The sibling pattern of `p` for another sequence: "dir/ink.####.png" -> "dir/ink_mask.####.exr".
turbio::FramePattern sibling(const turbio::FramePattern& p, const std::string& tag, const std::string& ext)
{
    std::string prefix = p.prefix(), sep = ".";
    if (!prefix.empty() && (prefix.back() == '.' || prefix.back() == '_' || prefix.back() == '-')) {
        sep = std::string(1, prefix.back());
        prefix.pop_back();
    }
    return turbio::FramePattern::parse(
        prefix + "_" + tag + sep + std::string(size_t(std::max(1, p.width())), '#') + ext);
}

/// `sim ink`: the 2D moving exemplar of Fluidymation (scenes/Ink2D.h), as RGB, mask and flow images.
SimRun runInk(const SimJob& a)
{
    turb::scenes::InkSettings s;
    const std::string res = a.res == SimJob{}.res ? "320x240" : a.res; // the 3D default means "not given"
    int w = 0, h = 0;
    char x = 0, extra = 0;
    if (std::sscanf(res.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
        throw turb::ValueError("--res: the ink scene is 2D, expected WxH (e.g. 320x240), got '" + a.res + "'");
    s.width = w;
    s.height = h;
    s.frames = a.frames;
    s.seed = a.seed;
    const std::string outText = a.out.empty() ? "sim/ink_" + res + "/ink.####.png" : a.out;
    const turbio::FramePattern rgb = turbio::FramePattern::parse(outText);
    if (!rgb.numbered() && a.frames > 1) throw UsageError("--out '" + outText + "' has no frame token (####)");
    turbio::outputFormatOf(outText);
    const turbio::FramePattern mask = sibling(rgb, "mask", ".png"), flow = sibling(rgb, "flow", ".exr");
    logInfo("scene ink at " + res + ", " + std::to_string(a.frames) + " frames, seed " + std::to_string(a.seed) + ": " +
            rgb.str() + ", " + mask.str() + ", " + flow.str());
    SimRun done;
    if (a.dryRun) return done;
    turb::scenes::InkSequence ink;
    turb::withThreads(a.threads, [&] { ink = turb::scenes::inkExemplar(s); });
    reporter().runStarted("sim ink " + res);
    for (int i = 0; i < a.frames; ++i) {
        const int number = a.start + i;
        turbio::ensureParentDirectory(rgb.format(number));
        turbio::ImageWriteOptions o;
        o.noClobber = a.write.noClobber;
        o.alpha = false;
        turbio::writeImage(rgb.format(number), ink.rgb[size_t(i)], o);
        turbio::writeImage(mask.format(number), turb::toRgba(ink.mask[size_t(i)]), o);
        turb::RgbaImage f(s.width, s.height, turb::Rgba(0, 0, 0, 1));
        for (size_t p = 0; p < f.size(); ++p)
            f.pixels()[p] = turb::Rgba(ink.flow[size_t(i)].pixel(p)[0], ink.flow[size_t(i)].pixel(p)[1], 0, 1);
        o.bits = turbio::PixelBits::Float;
        turbio::writeImage(flow.format(number), f, o);
        nlohmann::json extra;
        extra["out"] = rgb.format(number);
        reporter().frameDone(FrameRecord{number, i, a.frames, 0.0, "-> " + rgb.format(number), extra});
        ++done.framesWritten;
    }
    reporter().runFinished(0, nlohmann::json::object());
    return done;
}

} // namespace

std::string sceneListText()
{
    std::ostringstream os;
    for (const auto& s : turb::scenes::sceneList())
        os << s.name << "\t" << s.description << " (" << s.width << " units wide; pair " << resText(s.pairLow) << " / "
           << resText(s.pairHigh) << ")\n";
    os << "ink\t2D: a drop of ink spreading on wet paper, painted like watercolour (PNG frames, masks and EXR flows: "
          "Fluidymation's moving exemplar; --res WxH, default 320x240)\n";
    return os.str();
}

namespace {

// The scene's settings with the command's solver settings.
turb::scenes::SmokeSettings solverSettings(const SimJob& a, const turb::Coord& res)
{
    turb::scenes::SmokeSettings s = turb::scenes::sceneSettings(a.scene, res, a.seed);
    s.threads = a.threads;
    s.densityScheme = s.velocityScheme = a.scheme;
    s.pressureIncompleteCholesky = a.incompleteCholesky;
    s.pressureTolerance = a.pressureTolerance;
    s.cfl = a.cfl;
    s.maxSubsteps = a.maxSubsteps;
    return s;
}

std::string domainLine(
    const SimJob& a, const turb::scenes::SmokeSim& sim, const turb::scenes::SmokeSettings& s, const turb::Coord& res)
{
    const double h = sim.lattice().voxelSize;
    const turb::Vec3d lo = sim.lattice().indexToWorld(turb::Vec3d(-0.5));
    const turb::Vec3d hi = lo + turb::Vec3d(res.x(), res.y(), res.z()) * h;
    std::ostringstream domain;
    domain << "scene " << a.scene << " at " << resText(res) << ", voxel " << h << ", domain (" << lo.x() << ","
           << lo.y() << "," << lo.z() << ")-(" << hi.x() << "," << hi.y() << "," << hi.z() << ")"
           << (sim.twoD() ? ", 2D, y up, " : ", z up, ") << a.frames << " frames at " << fmt("%.4g", 1.0 / s.frameDt)
           << " fps, seed " << a.seed;
    return domain.str();
}

nlohmann::json frameJson(const turb::scenes::FrameStats& st, const std::string& path)
{
    nlohmann::json extra;
    extra["out"] = path;
    extra["substeps"] = st.substeps;
    extra["pressure_iterations"] = st.pressureIterations;
    extra["converged"] = st.converged;
    extra["relative_residual"] = st.relativeResidual;
    extra["relative_divergence"] = st.relativeDivergence;
    extra["div_max_after"] = st.divMaxAfter;
    extra["div_rel"] = st.divRel;
    extra["max_speed"] = st.maxSpeed;
    extra["mass"] = st.mass;
    extra["advect_s"] = st.advectSeconds;
    extra["project_s"] = st.projectSeconds;
    return extra;
}

std::string frameLine(const turb::scenes::FrameStats& st, const std::string& path)
{
    return std::to_string(st.substeps) + " substep" + (st.substeps == 1 ? "" : "s") + ", CG " +
           std::to_string(st.pressureIterations) + " it, max|div| after/before " + fmt("%.1e", st.relativeDivergence) +
           ", div_rel " + fmt("%.3f", st.divRel) + ", max speed " + fmt("%.2f", st.maxSpeed) + " -> " + path;
}

// Simulates every frame up to the last one to write and writes those not skipped (each frame follows the last, so
// a skipped one is simulated again); returns how many stopped before the pressure tolerance.
int writeFrames(const SimJob& a, turb::scenes::SmokeSim& sim, const turbio::FramePattern& pattern, const SkipPlan& plan,
    const std::string& settings)
{
    int unconverged = 0;
    bool warnedClipping = false;
    turb::withThreads(a.threads, [&] {
        for (int i = 0; i < int(plan.end); ++i) {
            const int number = a.start + i;
            const auto t0 = std::chrono::steady_clock::now();
            const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(i, a.frames, number);
            const turb::scenes::FrameStats st = sim.advanceFrame(progress.get());
            const std::string path = pattern.format(number);
            if (plan.skipped(size_t(i))) {
                progress->clear();
                reporter().frameSkipped(number, i, a.frames, secondsSince(t0), path, true);
                continue;
            }
            progress->begin("writing");
            turb::Frame frame = sim.frame();
            frame.number = number;
            frame.metadata[turb::meta::kCommand] = "sim";
            frame.metadata[turb::meta::kSettings] = settings;
            turbio::ensureParentDirectory(path);
            warnIfClippedAway(frame, a.write, path, warnedClipping);
            turbio::writeFrame(path, frame, a.write);
            progress->clear();
            if (!st.converged) {
                ++unconverged;
                logWarning("frame " + std::to_string(number) + ": pressure solve stopped at residual " +
                           fmt("%.2e", st.relativeResidual) + " (tolerance " + fmt("%.1e", a.pressureTolerance) + ")");
            }
            logVerbose("frame " + std::to_string(number) + ": advect " + fmt("%.2f s", st.advectSeconds) +
                       ", project " + fmt("%.2f s", st.projectSeconds));
            reporter().frameDone(
                FrameRecord{number, i, a.frames, secondsSince(t0), frameLine(st, path), frameJson(st, path)});
        }
    });
    return unconverged;
}

} // namespace

SimRun runSim(const SimJob& a)
{
    if (a.scene == "ink") {
        if (a.skipExisting)
            throw UsageError("sim ink makes its exemplar's frames together: --skip-existing is for the 3D scenes");
        return runInk(a);
    }
    if (a.scene.empty()) throw turb::ValueError("no scene given (try --list)");
    if (a.frames < 1) throw turb::ValueError("--frames must be >= 1");
    const turb::Coord res = parseResolution(a.res);
    const turb::scenes::SmokeSettings s = solverSettings(a, res);

    const std::string outText =
        a.out.empty() ? "sim/" + a.scene + "_" + resText(res) + "/" + a.scene + ".####.vdb" : a.out;
    const turbio::FramePattern pattern = turbio::FramePattern::parse(outText);
    checkOutputFormat(a.write, outText, a.skipExisting ? "--skip-existing" : "");
    if (!pattern.numbered() && a.frames > 1)
        throw UsageError("--out '" + outText + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(a.frames) + " frames were asked for");

    turb::scenes::SmokeSim sim(s); // validates the settings before anything is written
    logInfo(domainLine(a, sim, s, res));
    std::vector<int> numbers(size_t(a.frames));
    std::vector<std::string> outputs;
    for (int i = 0; i < a.frames; ++i) {
        numbers[size_t(i)] = a.start + i;
        outputs.push_back(pattern.format(a.start + i));
    }
    checkOutputs(outputs, {}, a.write.noClobber, a.skipExisting);
    // Frame k of a scene depends on its settings, --start and k only: the settings say all of it.
    const std::string& settings = a.settingsText;
    const SkipPlan plan = planSkips(outputs, numbers, "sim", settings, a.skipExisting);
    SimRun done;
    if (a.dryRun) {
        if (a.skipExisting) {
            printSkipPlan(plan, outputs);
        } else {
            logInfo("would write " + pattern.format(a.start) +
                    (a.frames > 1 ? " .. " + pattern.format(a.start + a.frames - 1) : ""));
        }
        return done;
    }

    lockOutputFrames(pattern, plan.writing); // two tasks never write one frame (a second exits 75)
    reporter().runStarted("sim " + a.scene + " " + resText(res));
    done.unconverged = writeFrames(a, sim, pattern, plan, settings);
    done.framesWritten = int(plan.writing.size());
    reporter().runFinished(0, nlohmann::json::object());
    if (done.unconverged)
        logWarning(std::to_string(done.unconverged) +
                   " frame(s) stopped before the pressure tolerance; try --max-substeps or --tolerance");
    return done;
}

} // namespace turb::run
