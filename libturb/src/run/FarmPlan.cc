// turb::run::runFarmPlan: vdbturb farm plan, the chunks or tiles of a transfer and the scripts that run them
// (turb/run/Farm.h). The scripts and plan.json are FarmScripts.cc's.
#include <turb/run/Farm.h>

#include "FarmShared.h"

#include <turb/run/Output.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Transfer.h>
#include <turbio/Scan.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <filesystem>
#include <sstream>

namespace turb::run {

using namespace farm;

namespace {

namespace fs = std::filesystem;

// The final output's format options from the ones after -- (the join gets them), checked at plan time: a NanoVDB
// output in the Blender style would otherwise fail only in the join, after every chunk ran.
void checkPlannedFormat(const FarmPlanJob& a)
{
    turbio::WriteOptions w;
    const auto& t = a.transferArgs;
    for (size_t i = 0; i < t.size(); ++i) {
        const std::string name = t[i].substr(0, t[i].find('='));
        const bool inline_ = t[i].find('=') != std::string::npos;
        const std::string value = inline_ ? t[i].substr(t[i].find('=') + 1) : i + 1 < t.size() ? t[i + 1] : "";
        if (name == "--style" && value == "blender") w.style = turbio::WriteStyle::Blender;
        if (name == "--format")
            w.format = value == "vdb"       ? turbio::OutputFormat::Vdb
                       : value == "nanovdb" ? turbio::OutputFormat::NanoVdb
                                            : turbio::OutputFormat::Auto;
        if (name == "--nanovdb-quant")
            w.nanoQuantization = value == "fp16"  ? turbio::NanoQuantization::Fp16
                                 : value == "fp8" ? turbio::NanoQuantization::Fp8
                                                  : turbio::NanoQuantization::Float;
    }
    checkOutputFormat(w, a.out);
}

// What plan sets itself is refused after --: a chunk's frames, paths and threads are the plan's.
void checkPassThrough(const std::vector<std::string>& transferArgs, bool tiled)
{
    for (const auto& t : transferArgs) {
        const std::string name = t.substr(0, t.find('='));
        if (name == "--threads")
            throw turb::ValueError("'" + t + "' after -- is set by farm plan itself: give --cpus to farm plan");
        if (name == "--tile-box" || (tiled && name == "--target-no-crop"))
            throw turb::ValueError("'" + t + "' after -- is set by farm plan itself: give --tiles and --halo");
        if (name == "--frames" || name == "--out" || name == "--target" || name == "--source" || name == "--resume")
            throw turb::ValueError(
                "'" + t + "' after -- is set by farm plan itself; give --target/--source/--out/--frames to farm plan");
    }
}

// The output must not be an input or a task's scratch: the join would overwrite what it reads.
void checkOutput(const std::string& out, const std::string& target, const std::string& source, const std::string& dir)
{
    if (out == target || out == source)
        throw turb::ValueError("--out " + out + " is the " + std::string(out == target ? "target" : "source") +
                               " cache: the join would overwrite it; give another --out");
    for (const char* scratch : {"/chunks/", "/tiles/"})
        if (out.rfind(dir + scratch, 0) == 0)
            throw turb::ValueError("--out " + out + " is inside the farm directory's scratch (" + dir + scratch +
                                   "): the join would overwrite the frames it reads; give another --out");
}

// The largest overlap under `below` that `chunks` chunks of `n` frames can hold (-1: none, too many chunks). The
// overlaps that fit are those up to a limit: planTimeChunks, the one rule, is asked from `below` down.
int largestOverlap(size_t n, int chunks, int preroll, int below)
{
    for (int o = std::min(below, int(std::min<size_t>(n, INT_MAX))) - 1; o >= 0; --o) {
        try {
            turb::planTimeChunks(n, chunks, preroll, o);
            return o;
        } catch (const turb::ValueError&) {}
    }
    return -1;
}

// The time chunks. Without --overlap the default (20) shrinks to what the shot holds, with a line saying so; a given
// --overlap that does not fit is refused, naming the largest that does.
std::vector<turb::TimeChunk> timeChunks(FarmPlanJob& a, size_t n)
{
    try {
        return turb::planTimeChunks(n, a.chunks, a.preroll, a.overlap);
    } catch (const turb::ValueError& e) {
        const int most = largestOverlap(n, a.chunks, a.preroll, a.overlap);
        if (most < 0) throw UsageError(std::string(e.what()) + ": use fewer --chunks");
        if (a.overlapGiven)
            throw UsageError(std::string(e.what()) + ": --overlap " + std::to_string(most) + " is the most that " +
                             std::to_string(a.chunks) + " chunks of this shot hold (or use fewer --chunks)");
        logInfo("overlap " + std::to_string(most) + " frames: the default " + std::to_string(a.overlap) +
                " does not fit " + std::to_string(n) + " frames in " + std::to_string(a.chunks) + " chunks");
        a.overlap = most;
        return turb::planTimeChunks(n, a.chunks, a.preroll, a.overlap);
    }
}

// The target's frames the plan splits: every one requested must be on disk.
turbio::Sequence targetFrames(const FarmPlanJob& a)
{
    const turbio::Sequence target = turbio::resolveSequence(a.target, a.frames);
    if (!target.missing.empty())
        throw turb::IoError(target.pattern.str() +
                            (target.missing.size() == 1 ? ": missing target frame " : ": missing target frames ") +
                            turbio::formatFrameList(target.missing));
    return target;
}

// The box every tile's transfer holds: the union of the frames' held boxes (smoke and margin), found with the default
// read options (not those after --). One frame's scan error stops the plan. Sets p.ratio from the source's first frame.
turb::CoordBBox heldBox(const FarmPlanJob& a, const turbio::Sequence& target, Plan& p)
{
    const turbio::ReadOptions ro;
    const turbio::SequenceScan scan = turbio::scanSequence(target, target.frames, ro);
    if (const turbio::FrameScan* bad = scan.firstFailure()) throw turb::IoError(bad->error);
    turb::CoordBBox box;
    for (const auto& f : scan.frames) box.expand(f.domain);
    const turbio::Sequence source = turbio::resolveSequence(a.source);
    if (source.frames.empty()) throw turb::IoError(source.pattern.str() + ": no source frames");
    const turbio::FrameScan s0 = turbio::scanFrame(source.path(source.frames.front()), source.frames.front(), ro);
    if (!s0.error.empty()) throw turb::IoError(s0.error);
    p.ratio = turb::transferRatio(scan.frames.front().lattice.voxelSize, s0.lattice.voxelSize, true);
    return box;
}

// Space tiles: each task covers every frame and holds its tile of the target's box.
void planTiles(const FarmPlanJob& a, const turbio::Sequence& target, Plan& p)
{
    if (a.prerollGiven || a.overlapGiven)
        logWarning("--preroll and --overlap are time-chunk options: a tile task computes every frame");
    if (a.chunksGiven && a.chunks > 1)
        throw turb::ValueError("--tiles and --chunks " + std::to_string(a.chunks) +
                               ": a plan splits either the box (tiles) or the frames (chunks), not both");
    p.chunks = turb::planTimeChunks(p.frames.size(), 1, 0, 0);
    const turb::CoordBBox box = heldBox(a, target, p);
    p.tiles = turb::planSpaceTiles(box, parseTileCounts(a.tiles), a.halo);
    p.ramp = a.ramp > 0 ? a.ramp : std::max(1, a.halo * p.ratio);
    // Smoke rises along z in 3D caches (Houdini, Blender, vdbturb) and along y in a 2D (one z layer) one.
    const bool flat = turb::isFlat(p.tiles.box);
    if (flat ? p.tiles.counts.y() > 1 : p.tiles.counts.z() > 1)
        logWarning("--tiles " + a.tiles + " splits the box along " + (flat ? "y" : "z") +
                   ", the way smoke rises: a tile's inflow (fresh "
                   "detail, smoke without its advected structure) then reaches the seam, which a halo bounds only "
                   "with --density lookback, and each tile calibrates its detail over its own part of the plume. "
                   "Split across the main flow if you can (docs/farm.md, What bounds the halo)");
    // The join checks the ramp against the tiles; refuse it here, before anything runs.
    try {
        turb::checkTileRamp(p.tiles, p.ratio, p.ramp);
    } catch (const turb::ValueError& e) {
        throw turb::ValueError(std::string("--ramp: ") + e.what());
    }
}

// What a plan's paths and tiles would do wrong without failing: tiles that save nothing, and the frames of an
// earlier run in the scratch, which the tasks resume from.
void warnAboutPlan(const FarmPlanJob& a, const Plan& p)
{
    if (p.tiled && p.tiles.tiles.size() > 1) {
        bool saves = false;
        for (const auto& t : p.tiles.tiles) saves |= t.held != p.tiles.box;
        if (!saves)
            logWarning("every tile holds the whole box (halo " + std::to_string(a.halo) +
                       " against tiles of the box's size): no tile saves memory; use fewer tiles or a smaller halo");
    }
    // Tasks resume from the frames in their scratch directory: another plan's frames there would be refused by
    // the tasks (other settings) or, worse, joined (the same settings, another split).
    const fs::path scratch = fs::path(p.dir) / (std::string(p.word()) + "s");
    std::error_code ec;
    if (fs::is_directory(scratch, ec) && !fs::is_empty(scratch, ec))
        logWarning(scratch.string() + " holds frames of an earlier run: the tasks resume from them. Delete it to " +
                   "start over (a plan with other transfer options or another split needs that)");
}

std::string selfExe()
{
    std::error_code ec;
    const fs::path p = fs::read_symlink("/proc/self/exe", ec);
    return ec ? std::string("vdbturb") : p.string();
}

// A plan's paths (absolute: the tasks run elsewhere), frames and chunks, or space tiles. Settles a.overlap when the
// default does not fit the shot.
Plan makePlan(FarmPlanJob& a)
{
    Plan p;
    p.tiled = !a.tiles.empty();
    checkPassThrough(a.transferArgs, p.tiled);
    checkPlannedFormat(a);
    const turbio::Sequence target = targetFrames(a);
    p.frames = target.frames;
    if (p.tiled) {
        planTiles(a, target, p);
    } else {
        p.chunks = timeChunks(a, p.frames.size());
    }
    if (!turbio::FramePattern::parse(a.out).numbered())
        throw UsageError("--out '" + a.out + "' has no frame token (####)");
    p.dir = absolute(a.dir);
    p.exe = a.exe.empty() ? selfExe() : a.exe;
    p.target = absolute(a.target);
    p.source = absolute(a.source);
    p.out = absolute(a.out);
    checkOutput(p.out, p.target, p.source, p.dir);
    warnAboutPlan(a, p);
    return p;
}

// The plan for people: the split, then one line per chunk or tile.
void printPlan(const FarmPlanJob& a, const Plan& p)
{
    if (p.tiled) {
        const turb::Coord n = p.tiles.counts;
        printData("plan: " + std::to_string(p.frames.size()) + " frames " + turbio::formatFrameList(p.frames) + " in " +
                  std::to_string(n.x()) + "x" + std::to_string(n.y()) + "x" + std::to_string(n.z()) +
                  " space tiles of target box " + turb::formatTileBox(p.tiles.box) + ", halo " +
                  std::to_string(p.tiles.halo) + " target voxels, ramp " + std::to_string(p.ramp) +
                  " output voxels (ratio " + std::to_string(p.ratio) + ")");
        for (const auto& t : p.tiles.tiles) {
            const turb::Coord d = t.held.dim();
            printData("  tile " + std::to_string(t.index) + ": core " + turb::formatTileBox(t.core) + ", holds " +
                      turb::formatTileBox(t.held) + " (" + std::to_string(d.x()) + "x" + std::to_string(d.y()) + "x" +
                      std::to_string(d.z()) + ", " +
                      std::to_string(int(std::lround(100.0 * double(t.held.volume()) / double(p.tiles.box.volume())))) +
                      "% of the box)");
        }
        return;
    }
    printData("plan: " + std::to_string(p.frames.size()) + " frames " + turbio::formatFrameList(p.frames) + " in " +
              std::to_string(p.chunks.size()) + " chunks, pre-roll " + std::to_string(a.preroll) + ", overlap " +
              std::to_string(a.overlap));
    for (const auto& c : p.chunks)
        printData("  chunk " + std::to_string(c.index) + ": computes " +
                  turbio::formatFrameList(p.sub(c.computeBegin, c.end)) + ", keeps " +
                  turbio::formatFrameList(p.sub(c.keepBegin, c.end)));
}

} // namespace

turb::Coord parseTileCounts(const std::string& text)
{
    int v[3] = {1, 1, 1};
    std::stringstream in(text);
    std::string part;
    int n = 0;
    while (std::getline(in, part, 'x')) {
        size_t used = 0;
        try {
            v[n < 3 ? n : 2] = std::stoi(part, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (n >= 3 || part.empty() || used != part.size() || v[n] < 1)
            throw turb::ValueError("--tiles '" + text + "': expected NX, NXxNY or NXxNYxNZ with counts >= 1");
        ++n;
    }
    if (n == 0 || text.back() == 'x') throw turb::ValueError("--tiles '" + text + "': expected NX, NXxNY or NXxNYxNZ");
    return turb::Coord(v[0], v[1], v[2]);
}

FarmPlanRun runFarmPlan(const FarmPlanJob& job)
{
    FarmPlanJob a = job; // its overlap settles with the plan
    checkSbatchValues(a);
    const Plan p = makePlan(a);
    FarmPlanRun run{planJson(a, p), p.dir};
    const std::string script = std::string(p.word()) + "s.sbatch";
    if (!a.dryRun) {
        fs::create_directories(fs::path(p.dir) / "logs");
        writeText(p.dir + "/plan.json", run.plan.dump(2) + "\n");
        writeText(p.dir + "/" + script, tasksScript(a, p), true);
        writeText(p.dir + "/join.sbatch", joinScript(a, p), true);
    }
    printPlan(a, p);
    if (a.json) a.json(run.plan.dump() + "\n");
    if (a.dryRun) {
        printData("would write " + p.dir + "/plan.json, " + script + ", join.sbatch (dry run: nothing written)");
        return run;
    }
    printData("wrote " + p.dir + "/plan.json, " + script + ", join.sbatch; submit with: vdbturb farm submit --dir " +
              shellQuote(p.dir));
    return run;
}

} // namespace turb::run
