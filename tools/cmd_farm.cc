// vdbturb farm: a transfer split into time chunks that run as Slurm array tasks, and the join that cross-fades
// their overlaps (docs/farm.md). The scheduling is Slurm's: this writes sbatch scripts and a JSON plan, and
// calls sbatch. The blend math is libturb's (turb/Farm.h).
#include "Commands.h"
#include "Console.h"
#include "RunReport.h"

#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Metadata.h>
#include <turb/Resample.h>
#include <turb/Transfer.h>
#include <turbio/NanoVdb.h>
#include <turbio/Scan.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <array>
#include <climits>
#include <cstdio>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <unistd.h>

namespace vdbturb {

namespace {

namespace fs = std::filesystem;

// Defaults from the measurements in docs/farm.md (Blender pair and paper configuration): the cross-fade's added
// change per frame falls as 1/(O+1), and O = 20 keeps the seam frames' tcoh within 0.94-1.06x (paper) and 0.95-1.11x
// (Blender) of the sequential run's same frames, where O = 10 gave up to 1.32x. P + O = 24 frames of history settle
// the later chunk before it goes on alone.
constexpr int kDefaultPreroll = 4;
constexpr int kDefaultOverlap = 20;
// Space tiles: the target read's default crop margin (patch radius, advection reach and seam band, io.md); the
// measurements behind it are in docs/farm.md.
constexpr int kDefaultHalo = 8;

struct FarmArgs
{
    // plan
    std::string dir = "farm";
    std::string target, source, out, frames;
    int chunks = 2, preroll = kDefaultPreroll, overlap = kDefaultOverlap;
    std::string tiles;       ///< "NX[xNY[xNZ]]": space tiles instead of time chunks
    int halo = kDefaultHalo; ///< target voxels a tile holds past its core
    int ramp = 0;            ///< output voxels of the join's ramp across a border; 0 = halo x ratio
    const CLI::Option* chunksGiven = nullptr;
    const CLI::Option* prerollGiven = nullptr;
    const CLI::Option* overlapGiven = nullptr;
    int cpus = 2, retries = 2;
    std::string exe, partition, time, mem, name = "vdbturb";
    std::vector<std::string> transferArgs;
    // join
    bool keepScratch = true;
    bool json = false;
    turbio::ReadOptions targetRead;
    turbio::WriteOptions write = upResWriteDefaults(); // as transfer writes its chunks
};

std::string shellQuote(const std::string& s)
{
    if (!s.empty() &&
        s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=/.,:@%#") ==
            std::string::npos)
        return s;
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

std::string joinCommand(const std::vector<std::string>& argv)
{
    std::string s;
    for (const auto& a : argv) s += (s.empty() ? "" : " ") + shellQuote(a);
    return s;
}

std::string absolute(const std::string& p) { return fs::absolute(fs::path(p)).lexically_normal().string(); }

std::string selfExe()
{
    std::error_code ec;
    const fs::path p = fs::read_symlink("/proc/self/exe", ec);
    return ec ? std::string("vdbturb") : p.string();
}

std::string readText(const std::string& path)
{
    std::ifstream in(path);
    if (!in) throw turb::IoError(path + ": cannot read");
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

void writeText(const std::string& path, const std::string& text, bool executable = false)
{
    turbio::writeFileAtomic(path, text);
    if (executable)
        fs::permissions(
            path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec, fs::perm_options::add);
}

// The chunk's scratch pattern: every frame it computes, pre-roll included, so --resume can continue a killed task.
// Always VDB: a NanoVDB output (.nvdb) is made by the join, from chunks that can resume and that it can read.
std::string chunkPattern(const std::string& dir, int k, const std::string& out, const char* word = "chunk")
{
    char sub[32];
    std::snprintf(sub, sizeof(sub), "%ss/%03d/", word, k);
    fs::path name = fs::path(out).filename();
    if (turbio::outputFormatFor(name.string()) == turbio::OutputFormat::NanoVdb) name.replace_extension(".vdb");
    return (fs::path(dir) / sub / name).string();
}

// The options of the final file's format (--format, --nanovdb-quant): the join's, never the chunks' (they write VDB).
bool isFormatOption(const std::string& arg)
{
    const std::string name = arg.substr(0, arg.find('='));
    return name == "--format" || name == "--nanovdb-quant";
}

// The final output's format options from the ones after -- (the join gets them), checked at plan time: a NanoVDB
// output in the Blender style would otherwise fail only in the join, after every chunk ran.
void checkPlannedFormat(const FarmArgs& a)
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

// The transfer's options the join needs too: the target's read options (it reads u_t as the chunks did) and the
// output options (blended frames are written like the chunks' own).
std::vector<std::string> joinArgs(const std::vector<std::string>& args)
{
    std::vector<std::string> out;
    for (size_t i = 0; i < args.size(); ++i)
        if (args[i].rfind("--target-", 0) == 0 || args[i].rfind("--style", 0) == 0 ||
            args[i].rfind("--velocity-margin", 0) == 0 || args[i].rfind("--clipping", 0) == 0 ||
            args[i].rfind("--vel-voxel-scale", 0) == 0 || isFormatOption(args[i])) {
            out.push_back(args[i]);
            if (args[i].find('=') == std::string::npos && i + 1 < args.size()) out.push_back(args[++i]);
        } else if (args[i] == "--half" || args[i] == "--full-float" || args[i] == "--no-velocity" ||
                   args[i] == "--no-clobber") {
            out.push_back(args[i]);
        }
    return out;
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

// A plan's paths (absolute: the tasks run elsewhere), frames and chunks, or space tiles.
// The split a plan and its join share: time chunks, or space tiles (each task then covers every frame).
struct Split
{
    std::string dir, out;
    std::vector<int> frames;
    std::vector<turb::TimeChunk> chunks; ///< time chunks (one chunk covering every frame when tiled)
    bool tiled = false;
    turb::TilePlan tiles; ///< space tiles (tiled)
    int ratio = 0;        ///< the transfer's ratio (tiled)
    int ramp = 0;         ///< output voxels (tiled)
    const char* word() const { return tiled ? "tile" : "chunk"; }
    size_t taskCount() const { return tiled ? tiles.tiles.size() : chunks.size(); }
};

struct Plan : Split
{
    std::string exe, target, source;
    std::vector<int> sub(size_t b, size_t e) const
    {
        return std::vector<int>(frames.begin() + long(b), frames.begin() + long(e));
    }
};

// "2", "2x2", "2x1x3": tiles per axis (missing axes 1).
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

std::vector<int> boxArray(const turb::CoordBBox& b)
{
    return {b.min().x(), b.min().y(), b.min().z(), b.max().x(), b.max().y(), b.max().z()};
}

turb::CoordBBox boxFromArray(const nlohmann::json& j)
{
    const auto v = j.get<std::vector<int>>();
    if (v.size() != 6) throw turb::ValueError("plan.json: a box needs 6 indices");
    return turb::CoordBBox(turb::Coord(v[0], v[1], v[2]), turb::Coord(v[3], v[4], v[5]));
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
std::vector<turb::TimeChunk> timeChunks(FarmArgs& a, size_t n)
{
    try {
        return turb::planTimeChunks(n, a.chunks, a.preroll, a.overlap);
    } catch (const turb::ValueError& e) {
        const int most = largestOverlap(n, a.chunks, a.preroll, a.overlap);
        if (most < 0) throw UsageError(std::string(e.what()) + ": use fewer --chunks");
        if (a.overlapGiven->count() > 0)
            throw UsageError(std::string(e.what()) + ": --overlap " + std::to_string(most) + " is the most that " +
                             std::to_string(a.chunks) + " chunks of this shot hold (or use fewer --chunks)");
        logInfo("overlap " + std::to_string(most) + " frames: the default " + std::to_string(a.overlap) +
                " does not fit " + std::to_string(n) + " frames in " + std::to_string(a.chunks) + " chunks");
        a.overlap = most;
        return turb::planTimeChunks(n, a.chunks, a.preroll, a.overlap);
    }
}

Plan makePlan(FarmArgs& a) // settles a.overlap when the default does not fit the shot
{
    Plan p;
    p.tiled = !a.tiles.empty();
    checkPassThrough(a.transferArgs, p.tiled);
    checkPlannedFormat(a);
    const turbio::Sequence target = turbio::resolveSequence(a.target, a.frames);
    if (!target.missing.empty())
        throw turb::IoError(target.pattern.str() +
                            (target.missing.size() == 1 ? ": missing target frame " : ": missing target frames ") +
                            turbio::formatFrameList(target.missing));
    p.frames = target.frames;
    if (p.tiled) {
        if (a.prerollGiven->count() > 0 || a.overlapGiven->count() > 0)
            logWarning("--preroll and --overlap are time-chunk options: a tile task computes every frame");
        if (a.chunksGiven && a.chunksGiven->count() > 0 && a.chunks > 1)
            throw turb::ValueError("--tiles and --chunks " + std::to_string(a.chunks) +
                                   ": a plan splits either the box (tiles) or the frames (chunks), not both");
        p.chunks = turb::planTimeChunks(p.frames.size(), 1, 0, 0);
        // The box every tile's transfer holds: the union of the frames' held boxes (smoke and margin), found with
        // the default read options (not those after --). One frame's scan error stops the plan.
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
    return p;
}

// The transfer a chunk's or tile's array task runs: its frames (with the pre-roll), resumable, and the options given
// after --. Task k is chunk k, or tile k over every frame.
std::vector<std::string> taskCommand(const FarmArgs& a, const Plan& p, size_t k)
{
    const turb::TimeChunk& c = p.chunks[p.tiled ? 0 : k];
    std::vector<std::string> argv = {p.exe, "transfer", "--target", p.target, "--source", p.source, "--out",
        chunkPattern(p.dir, int(k), a.out, p.word()), "--frames", turbio::formatFrameList(p.sub(c.computeBegin, c.end)),
        "--resume", "--threads", std::to_string(a.cpus)};
    if (p.tiled) {
        // A tile holds its core and halo on every frame: one box, so that the join finds it on every frame. The
        // source is held as an untiled run holds it (its smoke and margin): every tile reads the same source.
        argv.insert(argv.end(), {"--tile-box", turb::formatTileBox(p.tiles.tiles[k].held)});
    } else {
        // Every chunk holds the target's whole domain: held over the smoke of its own frames only, chunks would
        // get different output boxes and the join could not blend them.
        argv.insert(argv.end(), {"--target-no-crop", "--source-no-crop"});
    }
    for (size_t i = 0; i < a.transferArgs.size(); ++i) {
        if (isFormatOption(a.transferArgs[i])) { // the join's (chunkPattern)
            if (a.transferArgs[i].find('=') == std::string::npos) ++i;
            continue;
        }
        argv.push_back(a.transferArgs[i]);
    }
    return argv;
}

std::vector<std::string> joinCommandLine(const FarmArgs& a, const Plan& p)
{
    std::vector<std::string> argv = {p.exe, "farm", "join", "--dir", p.dir, "--threads", std::to_string(a.cpus)};
    for (const auto& r : joinArgs(a.transferArgs)) argv.push_back(r);
    return argv;
}

nlohmann::json taskJson(const FarmArgs& a, const Plan& p, size_t k)
{
    nlohmann::json t;
    const turb::TimeChunk& c = p.chunks[p.tiled ? 0 : k];
    t["name"] = std::string(p.word()) + std::to_string(k);
    t["array_index"] = int(k);
    t["frames_computed"] = turbio::formatFrameList(p.sub(c.computeBegin, c.end));
    t["frames_preroll"] = turbio::formatFrameList(p.sub(c.computeBegin, c.keepBegin));
    t["frames_kept"] = turbio::formatFrameList(p.sub(c.keepBegin, c.end));
    if (p.tiled) {
        t["tile_core"] = boxArray(p.tiles.tiles[k].core);
        t["tile_held"] = boxArray(p.tiles.tiles[k].held);
    }
    t["out"] = chunkPattern(p.dir, int(k), a.out, p.word());
    t["log"] = p.dir + "/logs/" + p.word() + "_" + std::to_string(k) + ".log";
    t["command"] = taskCommand(a, p, k);
    t["depends_on"] = nlohmann::json::array();
    t["retry_exit_codes"] = {75, 130, 137, 143};
    return t;
}

nlohmann::json joinTask(const FarmArgs& a, const Plan& p)
{
    nlohmann::json join;
    join["name"] = "join";
    join["frames"] = turbio::formatFrameList(p.frames);
    join["out"] = p.out;
    join["log"] = p.dir + "/logs/join.log";
    join["command"] = joinCommandLine(a, p);
    nlohmann::json deps = nlohmann::json::array();
    for (size_t k = 0; k < p.taskCount(); ++k) deps.push_back(p.word() + std::to_string(k));
    join["depends_on"] = deps;
    return join;
}

// plan.json: the same plan as the scripts, for tools that schedule otherwise, and for the join.
nlohmann::json planJson(const FarmArgs& a, const Plan& p)
{
    nlohmann::json plan;
    plan["version"] = 1;
    plan["kind"] = p.tiled ? "space_tiles" : "time_chunks";
    plan["dir"] = p.dir;
    plan["vdbturb"] = p.exe;
    plan["target"] = p.target;
    plan["source"] = p.source;
    plan["out"] = p.out;
    plan["frames"] = turbio::formatFrameList(p.frames);
    plan["chunks"] = p.tiled ? 1 : a.chunks;
    plan["preroll"] = p.tiled ? 0 : a.preroll;
    plan["overlap"] = p.tiled ? 0 : a.overlap;
    if (p.tiled)
        plan["tiles"] = {{"counts", {p.tiles.counts.x(), p.tiles.counts.y(), p.tiles.counts.z()}},
            {"box", boxArray(p.tiles.box)}, {"halo", p.tiles.halo}, {"ratio", p.ratio}, {"ramp", p.ramp},
            {"borders", turb::formatTileBorders(turb::tileBorders(p.tiles, p.ratio))}};
    plan["transfer_args"] = a.transferArgs;
    plan["exit_codes"] = {{"0", "done"},
        {"1", "a failure a retry cannot fix (bad input, a resume with other settings): do not retry"},
        {"2", "usage error: do not retry"},
        {"75",
            "worth a retry (disk full, a file-size limit, out of memory): retry, resuming from the last whole frame"},
        {"130", "interrupted: retry"}, {"137", "killed (SIGKILL: OOM killer, kill -9): retry"},
        {"143", "terminated (SIGTERM): retry"}};
    nlohmann::json tasks = nlohmann::json::array();
    for (size_t k = 0; k < p.taskCount(); ++k) tasks.push_back(taskJson(a, p, k));
    tasks.push_back(joinTask(a, p));
    plan["tasks"] = tasks;
    nlohmann::json overlaps = nlohmann::json::array();
    for (size_t k = 0; k + 1 < p.chunks.size(); ++k)
        for (int j = 0; j < a.overlap; ++j) {
            const turb::CrossFade w = turb::crossFade(j, a.overlap);
            overlaps.push_back({{"frame", p.frames[p.chunks[k + 1].keepBegin + size_t(j)]}, {"a", int(k)},
                {"b", int(k + 1)}, {"t", w.t}, {"detail_a", w.detailA}, {"detail_b", w.detailB},
                {"density_a", w.densityA}, {"density_b", w.densityB}});
        }
    plan["overlaps"] = overlaps;
    plan["slurm"] = {{std::string(p.word()) + "s_script", p.dir + "/" + p.word() + "s.sbatch"},
        {"join_script", p.dir + "/join.sbatch"}};
    return plan;
}

// An #SBATCH line is read by sbatch, not a shell, and ends at the line's end: a value with a newline would add lines
// (a command in the script), one with spaces or quotes is split or unquoted by sbatch's own rules. Names, partitions,
// times and memory sizes never need either.
void checkSbatchValue(const std::string& flag, const std::string& value)
{
    for (const char c : value)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || std::strchr("._:,+=@%-", c)))
            throw UsageError(flag + " '" + value + "': only letters, digits and ._:,+=@%- may go into an #SBATCH line");
}

// The log path as an #SBATCH directive when sbatch reads it back as written (no whitespace, quotes or backslash);
// otherwise farm submit gives --output on sbatch's command line, and the script says so.
std::string sbatchOutput(const std::string& path)
{
    if (path.find_first_of(" \t\n\r\"'\\") == std::string::npos) return "#SBATCH --output=" + path + "\n";
    // Not the path itself: a comment ends at a newline a hostile name may hold, and the shell runs the rest.
    return "# --output is given by vdbturb farm submit: an #SBATCH line cannot hold this directory's name\n";
}

std::string sbatchResources(const FarmArgs& a)
{
    std::string common = "#SBATCH --cpus-per-task=" + std::to_string(a.cpus) + "\n";
    if (!a.partition.empty()) common += "#SBATCH --partition=" + a.partition + "\n";
    if (!a.time.empty()) common += "#SBATCH --time=" + a.time + "\n";
    if (!a.mem.empty()) common += "#SBATCH --mem=" + a.mem + "\n";
    return common;
}

// A task that failed in a way a retry can fix (exit 75), was interrupted (130) or killed (137, 143) requeues itself
// up to --retries times;
// transfer --resume then continues from the last whole frame in the chunk's scratch directory. A usage error (2)
// would fail again and is not retried. Slurm's own --requeue covers node failure and preemption.
std::string tasksScript(const FarmArgs& a, const Plan& p)
{
    const std::string w = p.word();
    std::string cases;
    for (size_t k = 0; k < p.taskCount(); ++k)
        cases += "  " + std::to_string(k) + ") set -- " + joinCommand(taskCommand(a, p, k)) + " ;;\n";
    return "#!/bin/sh\n"
           "# Written by vdbturb farm plan: one array task per " +
           std::string(p.tiled ? "space tile" : "time chunk") +
           " (plan.json has the same plan as JSON).\n"
           "#SBATCH --job-name=" +
           a.name + "-" + w +
           "s\n"
           "#SBATCH --array=0-" +
           std::to_string(p.taskCount() - 1) +
           "\n"
           "#SBATCH --requeue\n"
           "#SBATCH --open-mode=append\n" +
           sbatchOutput(p.dir + "/logs/" + w + "_%a.log") + sbatchResources(a) + "case \"$SLURM_ARRAY_TASK_ID\" in\n" +
           cases + "  *) echo \"farm: no " + w +
           " $SLURM_ARRAY_TASK_ID\" >&2; exit 2 ;;\n"
           "esac\n"
           "echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID start (restart ${SLURM_RESTART_COUNT:-0}) on $(hostname)\" >&2\n"
           "\"$@\"\n"
           "rc=$?\n"
           "echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID exit $rc\" >&2\n"
           "# Only what a retry can fix requeues: vdbturb's 75 (disk full, a file-size limit, out of memory), an\n"
           "# interruption (130) or a kill (137 SIGKILL: the OOM killer, kill -9; 143 SIGTERM). 1 (bad input, a "
           "resume\n"
           "# with other settings) and 2 (usage) would fail again.\n"
           "case $rc in\n"
           "  75|130|137|143) ;;\n"
           "  *) exit $rc ;;\n"
           "esac\n"
           "# A stop by Slurm itself (scancel, scontrol requeue, the time limit) signals this shell too, which then\n"
           "# ends with vdbturb; should it outlive it, the job is COMPLETING: a cancel must stick, and Slurm requeues\n"
           "# by itself what it requeues. Only a task that is still RUNNING (vdbturb killed alone: the OOM killer,\n"
           "# kill -9) requeues itself.\n"
           "state=$(squeue -h -j \"${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\" -o %T 2>/dev/null)\n"
           "if [ \"$state\" != RUNNING ]; then\n"
           "  echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID not requeued by its script: the job is ${state:-unknown to squeue} (stopped by "
           "Slurm)\" >&2\n"
           "elif [ \"${SLURM_RESTART_COUNT:-0}\" -lt " +
           std::to_string(a.retries) +
           " ]; then\n"
           "  echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID requeued; it resumes from its last whole frame\" >&2\n"
           "  scontrol requeue \"${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\"\n"
           "  sleep 30 # the requeue ends this job; do not let it finish as failed first\n"
           "fi\n"
           "exit $rc\n";
}

std::string joinScript(const FarmArgs& a, const Plan& p)
{
    return "#!/bin/sh\n"
           "# Written by vdbturb farm plan: assembles the " +
           std::string(
               p.tiled ? "tiles (after every tile" : "chunks and cross-fades their overlaps (after every chunk") +
           " succeeded).\n"
           "#SBATCH --job-name=" +
           a.name + "-join\n" + sbatchOutput(p.dir + "/logs/join.log") + "#SBATCH --open-mode=append\n" +
           sbatchResources(a) + "exec " + joinCommand(joinCommandLine(a, p)) + "\n";
}

int runPlan(FarmArgs& a)
{
    checkSbatchValue("--name", a.name);
    checkSbatchValue("--partition", a.partition);
    checkSbatchValue("--time", a.time);
    checkSbatchValue("--mem", a.mem);
    const Plan p = makePlan(a);
    const std::string script = std::string(p.word()) + "s.sbatch";
    if (!globals().dryRun) {
        fs::create_directories(fs::path(p.dir) / "logs");
        writeText(p.dir + "/plan.json", planJson(a, p).dump(2) + "\n");
        writeText(p.dir + "/" + script, tasksScript(a, p), true);
        writeText(p.dir + "/join.sbatch", joinScript(a, p), true);
    }
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
    } else {
        printData("plan: " + std::to_string(p.frames.size()) + " frames " + turbio::formatFrameList(p.frames) + " in " +
                  std::to_string(p.chunks.size()) + " chunks, pre-roll " + std::to_string(a.preroll) + ", overlap " +
                  std::to_string(a.overlap));
        for (const auto& c : p.chunks)
            printData("  chunk " + std::to_string(c.index) + ": computes " +
                      turbio::formatFrameList(p.sub(c.computeBegin, c.end)) + ", keeps " +
                      turbio::formatFrameList(p.sub(c.keepBegin, c.end)));
    }
    if (a.json) writeData(planJson(a, p).dump() + "\n");
    if (globals().dryRun) {
        printData("would write " + p.dir + "/plan.json, " + script + ", join.sbatch (dry run: nothing written)");
        return kOk;
    }
    printData("wrote " + p.dir + "/plan.json, " + script + ", join.sbatch; submit with: vdbturb farm submit --dir " +
              shellQuote(p.dir));
    return kOk;
}

// Runs a command, returns its stdout; throws with its output when it fails.
std::string runCapture(const std::string& cmd)
{
    std::array<char, 4096> buf{};
    std::string out;
    FILE* p = popen((cmd + " 2>&1").c_str(), "r");
    if (!p) throw turb::IoError("cannot run: " + cmd);
    while (fgets(buf.data(), int(buf.size()), p)) out += buf.data();
    const int rc = pclose(p);
    if (rc != 0) throw turb::IoError(cmd + " failed: " + out);
    return out;
}

std::string trim(std::string s)
{
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ' || s.back() == '\r')) s.pop_back();
    return s;
}

int runSubmit(FarmArgs& a)
{
    const std::string dir = absolute(a.dir);
    if (!fs::exists(dir + "/plan.json"))
        throw turb::IoError(dir + "/plan.json: no plan (vdbturb farm plan --dir " + dir + " first)");
    const nlohmann::json plan = nlohmann::json::parse(readText(dir + "/plan.json"));
    const std::string word = plan.value("kind", "time_chunks") == "space_tiles" ? "tile" : "chunk";
    if (globals().dryRun) {
        printData("would run: sbatch --parsable " + shellQuote(dir + "/" + word + "s.sbatch") +
                  ", then sbatch --parsable --dependency=afterok:<that job> " + shellQuote(dir + "/join.sbatch"));
        return kOk;
    }
    // --parsable prints "jobid[;cluster]".
    // --output on the command line too: it wins over the script's, and holds any directory name.
    std::string chunks = trim(runCapture("sbatch --parsable --output=" + shellQuote(dir + "/logs/" + word + "_%a.log") +
                                         " " + shellQuote(dir + "/" + word + "s.sbatch")));
    chunks = chunks.substr(0, chunks.find(';'));
    std::string join = trim(runCapture("sbatch --parsable --dependency=afterok:" + chunks + " --output=" +
                                       shellQuote(dir + "/logs/join.log") + " " + shellQuote(dir + "/join.sbatch")));
    join = join.substr(0, join.find(';'));
    nlohmann::json j = {{word + "s_job", chunks}, {"join_job", join}};
    writeText(dir + "/submitted.json", j.dump() + "\n");
    if (a.json) writeData(j.dump() + "\n");
    printData(
        "submitted: " + word + "s job " + chunks + " (array), join job " + join + " (after the " + word + "s succeed)",
        a.json);
    return kOk;
}

void copyAtomic(const std::string& from, const std::string& to)
{
    const std::string tmp = to + ".farm-tmp";
    fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
    fs::rename(tmp, to);
}

// What the join reads from plan.json: the frames, the chunks, the output and the target the chunks read.
struct JoinPlan : Split
{
    int overlap = 0;
    turbio::Sequence target;
    float densityThreshold = 0.01f; ///< transfer's, unless the chunks were given another
    turbio::FramePattern chunkFrames(size_t k) const
    {
        return turbio::FramePattern::parse(chunkPattern(dir, int(k), out, word()));
    }
};

JoinPlan readJoinPlan(const FarmArgs& a)
{
    JoinPlan p;
    p.dir = absolute(a.dir);
    const nlohmann::json plan = nlohmann::json::parse(readText(p.dir + "/plan.json"));
    p.frames = turbio::parseFrameList(plan.at("frames").get<std::string>());
    p.overlap = plan.at("overlap").get<int>();
    p.chunks =
        turb::planTimeChunks(p.frames.size(), plan.at("chunks").get<int>(), plan.at("preroll").get<int>(), p.overlap);
    p.out = plan.at("out").get<std::string>();
    p.tiled = plan.value("kind", "time_chunks") == "space_tiles";
    if (p.tiled) {
        const nlohmann::json& t = plan.at("tiles");
        const auto n = t.at("counts").get<std::vector<int>>();
        if (n.size() != 3) throw turb::ValueError(p.dir + "/plan.json: tiles.counts needs 3 numbers");
        p.tiles =
            turb::planSpaceTiles(boxFromArray(t.at("box")), turb::Coord(n[0], n[1], n[2]), t.at("halo").get<int>());
        p.ratio = t.at("ratio").get<int>();
        p.ramp = t.at("ramp").get<int>();
    }
    p.target = turbio::resolveSequence(plan.at("target").get<std::string>(), plan.at("frames").get<std::string>());
    const auto& ta = plan.at("transfer_args");
    for (size_t i = 0; i + 1 < ta.size(); ++i)
        if (ta[i] == "--density-threshold") p.densityThreshold = std::stof(ta[i + 1].get<std::string>());
    return p;
}

// Every chunk or tile complete before anything is written: a join of a partial one would leave holes.
void checkChunksComplete(const JoinPlan& p)
{
    for (size_t k = 0; k < p.taskCount(); ++k) {
        const turb::TimeChunk& c = p.chunks[p.tiled ? 0 : k];
        const turbio::FramePattern pattern = p.chunkFrames(k);
        for (size_t i = c.keepBegin; i < c.end; ++i) {
            const std::string rerun = "sbatch --array=" + std::to_string(k) +
                                      " --output=" + shellQuote(p.dir + "/logs/" + p.word() + "_%a.log") + " " +
                                      shellQuote(p.dir + "/" + p.word() + "s.sbatch");
            const std::string path = pattern.format(p.frames[i]);
            if (!fs::exists(path))
                throw turb::IoError(std::string(p.word()) + " " + std::to_string(k) + " is not complete: " + path +
                                    " is missing (rerun it: " + rerun + ")");
            // A damaged frame (a full disk, a copy cut short) is found before anything is written, not halfway.
            const turbio::FrameScan scan = turbio::scanFrame(path, p.frames[i], turbio::ReadOptions{});
            if (!scan.error.empty())
                throw turb::IoError(std::string(p.word()) + " " + std::to_string(k) + " has a damaged frame: " +
                                    scan.error + " (delete " + path + ", then rerun it: " + rerun + ")");
        }
    }
}

// Frame i of a tiled plan: every tile's output, weighted by the plan's ramps, written like the tiles' frames.
void joinTileFrame(const FarmArgs& a, const JoinPlan& p, size_t i, RunReport& report)
{
    const int t = p.frames[i];
    const auto t0 = std::chrono::steady_clock::now();
    turbio::ReadOptions ro;
    ro.cropToSmoke = false; // the box the tile held
    std::vector<turb::Frame> tiles;
    for (size_t k = 0; k < p.taskCount(); ++k) tiles.push_back(turbio::readFrame(p.chunkFrames(k).format(t), t, ro));
    // up(u_t) over the whole box: the stats' detail, and what tiles written with --velocity-margin mean where they
    // hold no velocity.
    turbio::ReadOptions tro = a.targetRead;
    tro.cropToSmoke = true;
    tro.holdBox = p.tiles.box;
    turb::Frame ft = readingAs("target", [&] { return turbio::readFrame(p.target.path(t), t, tro); });
    turb::toTimeUnit(ft, tiles.front().timeUnit); // the tiles' vel is per second, a Blender target's per its unit
    const turb::VectorField up = turb::upsample(ft.velocity, p.ratio);
    for (turb::Frame& fr : tiles)
        if (fr.metadata.count(turb::meta::kVelocityMargin))
            turb::fillUnwrittenVelocity(fr.velocity, turb::cropped(up, fr.velocity.bbox()));
    turb::TileJoinStats st;
    turb::Frame joined = turb::joinTiles(tiles, p.tiles, p.ratio, p.ramp, p.densityThreshold, up, &st);
    const turb::Coord n = p.tiles.counts;
    joined.metadata[turb::meta::kFarmTiles] = std::to_string(n.x()) + "x" + std::to_string(n.y()) + "x" +
                                              std::to_string(n.z()) + " halo " + std::to_string(p.tiles.halo) +
                                              " ramp " + std::to_string(p.ramp);
    joined.metadata[turb::meta::kTileBorders] = turb::formatTileBorders(turb::tileBorders(p.tiles, p.ratio));
    const std::string dst = turbio::FramePattern::parse(p.out).format(t);
    turbio::ensureParentDirectory(dst);
    turbio::writeFrame(dst, joined, a.write);
    char human[200];
    std::snprintf(human, sizeof(human),
        "join %zu tiles, %zu seam voxels, correlation %.3f (lowest pair %.3f), disagreement %.3f -> ", tiles.size(),
        st.seamVoxels, st.correlation, st.minCorrelation, st.disagreement);
    report.frameDone(t, int(i), int(p.frames.size()), secondsSince(t0), std::string(human) + dst,
        {{"tiles", int(tiles.size())}, {"out", dst}, {"seam_voxels", st.seamVoxels}, {"correlation", st.correlation},
            {"min_correlation", st.minCorrelation}, {"disagreement", st.disagreement}});
}

// Overlap frame j after chunk k: chunks k and k + 1 cross-faded over up(u_t), written like the chunks' frames.
void blendFrame(const FarmArgs& a, const JoinPlan& p, size_t k, int j, RunReport& report)
{
    const turb::TimeChunk &c = p.chunks[k], &next = p.chunks[k + 1];
    const turbio::FramePattern pa = p.chunkFrames(k), pb = p.chunkFrames(k + 1);
    const size_t i = next.keepBegin + size_t(j);
    const int t = p.frames[i];
    const auto t0 = std::chrono::steady_clock::now();
    turbio::ReadOptions ro;
    ro.cropToSmoke = false; // the chunks' whole (shared) domain
    turb::Frame fa = turbio::readFrame(pa.format(t), t, ro);
    turb::Frame fb = turbio::readFrame(pb.format(t), t, ro);
    turbio::ReadOptions tro = a.targetRead;
    tro.cropToSmoke = false;
    turb::Frame ft = readingAs("target", [&] { return turbio::readFrame(p.target.path(t), t, tro); });
    turb::toTimeUnit(ft, fb.timeUnit);
    turb::toTimeUnit(fa, fb.timeUnit);
    const auto r = fb.metadata.find(turb::meta::kRatio);
    if (r == fb.metadata.end())
        throw turb::IoError(
            pb.format(t) + ": no " + std::string(turb::meta::kRatio) + " metadata: not a transfer output");
    const turb::VectorField up = turb::cropped(turb::upsample(ft.velocity, std::stoi(r->second)), fb.velocity.bbox());
    // Chunks written with --velocity-margin hold up(u_t) where no velocity was written: blend what they mean.
    for (turb::Frame* fr : {&fa, &fb})
        if (fr->metadata.count(turb::meta::kVelocityMargin)) turb::fillUnwrittenVelocity(fr->velocity, up);
    const turb::CrossFade w = turb::crossFade(j, p.overlap);
    turb::BlendStats st;
    turb::Frame blended = turb::blendOverlap(fa, fb, up, w, p.densityThreshold, &st);
    char note[160];
    std::snprintf(note, sizeof(note), "%.4f,%.4f,%.4f,%.4f", w.detailA, w.detailB, w.densityA, w.densityB);
    blended.metadata[turb::meta::kFarmBlend] = std::string(note);
    const std::string dst = turbio::FramePattern::parse(p.out).format(t);
    turbio::ensureParentDirectory(dst);
    turbio::writeFrame(dst, blended, a.write);
    const double expected = w.detailA * w.detailA * st.energyA + w.detailB * w.detailB * st.energyB;
    char human[200];
    std::snprintf(human, sizeof(human),
        "blend chunks %d+%d, w_detail %.3f/%.3f x %.3f (correlation %.3f), w_density %.3f/%.3f -> ", c.index,
        next.index, w.detailA, w.detailB, st.energyScale, st.correlation, w.densityA, w.densityB);
    report.frameDone(t, int(i), int(p.frames.size()), secondsSince(t0), std::string(human) + dst,
        {{"chunks", {c.index, next.index}}, {"out", dst}, {"detail_a", w.detailA}, {"detail_b", w.detailB},
            {"density_a", w.densityA}, {"density_b", w.densityB}, {"correlation", st.correlation},
            {"energy_scale", st.energyScale}, {"energy_ratio", expected > 0.0 ? st.energyOut / expected : 1.0}});
}

int runJoin(FarmArgs& a)
{
    const JoinPlan p = readJoinPlan(a);
    checkOutputFormat(a.write, p.out);
    // NanoVDB output: frames a chunk owns are converted from its VDB frame, blended ones written as NanoVDB.
    const bool nano = turbio::outputFormatFor(p.out, a.write.format) == turbio::OutputFormat::NanoVdb;
    checkChunksComplete(p);
    // --velocity-margin auto writes the joined frames as the chunks' transfer wrote theirs: one target voxel.
    if (p.tiled) {
        resolveVelocityMargin(a.write, p.ratio);
    } else if (a.write.velocityMargin == kVelocityMarginAuto && !p.chunks.empty()) {
        const turb::TimeChunk& c = p.chunks.front();
        a.write.velocityMargin =
            turbio::inspectFile(p.chunkFrames(0).format(p.frames[c.keepBegin]), false).velocityMargin;
    }
    if (globals().dryRun) {
        printData("every " + std::string(p.word()) + "'s frames are present and read; would write " +
                  std::to_string(p.frames.size()) + " frames to " + p.out + " (dry run: nothing written)");
        return kOk;
    }
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(p.out);
    RunReport report("farm join", a.json);
    const int count = int(p.frames.size());
    if (p.tiled) {
        for (size_t i = 0; i < p.frames.size(); ++i) joinTileFrame(a, p, i, report);
        report.finish();
        return kOk;
    }
    for (size_t k = 0; k < p.chunks.size(); ++k) {
        const turb::TimeChunk& c = p.chunks[k];
        const turbio::FramePattern pattern = p.chunkFrames(k);
        // Frames this chunk alone owns are copied; the last O (shared with the next chunk) are blended.
        const size_t ownEnd = k + 1 < p.chunks.size() ? p.chunks[k + 1].keepBegin : c.end;
        const size_t ownBegin = k > 0 ? c.keepBegin + size_t(p.overlap) : c.keepBegin;
        for (size_t i = ownBegin; i < ownEnd; ++i) {
            const auto t0 = std::chrono::steady_clock::now();
            const std::string dst = outPattern.format(p.frames[i]);
            turbio::ensureParentDirectory(dst);
            if (nano) {
                turbio::NanoConvertOptions to;
                to.quantization = a.write.nanoQuantization;
                to.noClobber = a.write.noClobber;
                turbio::convertToNanoVdb(pattern.format(p.frames[i]), dst, to);
            } else {
                copyAtomic(pattern.format(p.frames[i]), dst);
            }
            report.frameDone(p.frames[i], int(i), count, secondsSince(t0),
                "chunk " + std::to_string(c.index) + " -> " + dst, {{"chunk", c.index}, {"out", dst}});
        }
        if (k + 1 < p.chunks.size())
            for (int j = 0; j < p.overlap; ++j) blendFrame(a, p, k, j, report);
    }
    report.finish();
    return kOk;
}

} // namespace

namespace {

void addPlanOptions(CLI::App* plan, FarmArgs& a)
{
    plan->add_option("--target", a.target, "Low-res target cache, as for transfer")->required();
    plan->add_option("--source", a.source, "High-res source cache, as for transfer")->required();
    plan->add_option("--frames", a.frames, "Target frames (empty: all on disk)")->check(frameListCheck());
    plan->add_option("--out", a.out, "Final output pattern, as for transfer")->required();
    plan->add_option("--dir", a.dir, "Farm directory: scripts, plan.json, logs, chunk scratch");
    a.chunksGiven =
        plan->add_option("--chunks", a.chunks, "Number of time chunks (array tasks)")->check(CLI::Range(1, 100000));
    a.prerollGiven = plan->add_option("--preroll", a.preroll, "P: frames computed before a chunk's first kept frame")
                         ->check(CLI::Range(0, 10000));
    a.overlapGiven =
        plan->add_option("--overlap", a.overlap, "O: frames two consecutive chunks share and the join cross-fades")
            ->check(CLI::Range(0, 10000));
    plan->add_option("--tiles", a.tiles,
            "Space tiles instead of time chunks: NX, NXxNY or NXxNYxNZ tiles of the target's box, each a task over "
            "every frame")
        ->check(parsedBy([](const std::string& t) { parseTileCounts(t); }, "NX[xNY[xNZ]]"));
    plan->add_option("--halo", a.halo, "Target voxels a tile holds past its core toward each neighbour")
        ->check(CLI::Range(1, 4096));
    setting(
        plan->add_option("--ramp", a.ramp,
                "Output voxels over which the join fades one tile into the next (0: halo x ratio; at most twice that)")
            ->check(CLI::Range(0, 1 << 20)),
        "ramp");
    plan->add_option("--cpus", a.cpus, "CPUs per task (sbatch --cpus-per-task and transfer --threads)")
        ->check(CLI::Range(1, 1024))
        ->group(kGroupRun);
    plan->add_option("--partition", a.partition, "sbatch --partition")->group(kGroupRun);
    plan->add_option("--time", a.time, "sbatch --time per task")->group(kGroupRun);
    plan->add_option("--mem", a.mem, "sbatch --mem per task")->group(kGroupRun);
    setting(plan->add_option("--retries", a.retries, "Times a failed task requeues itself")->check(CLI::Range(0, 100)),
        "retries");
    setting(plan->add_option("--vdbturb", a.exe, "vdbturb binary the tasks run (empty: this one)"), "vdbturb");
    setting(plan->add_option("--name", a.name, "Job name prefix"), "name");
    // Not a setting: the options after -- go to every chunk's transfer as given (farm join takes its read and write
    // options from them).
    plan->add_option("transfer_args", a.transferArgs, "After --: further transfer options, given to every chunk");
}

// The join reads the target and writes the frames as the chunks' transfer did: plan passes those options from the
// ones after --, so here they are settings.
void addJoinOptions(CLI::App* join, FarmArgs& a)
{
    join->add_option("--dir", a.dir, "Farm directory written by farm plan");
    join->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
    addReadOptions(join, a.targetRead, "target");
    addWriteOptions(join, a.write);
    addFormatOptions(join, a.write);
    addVelocityWriteOptions(join, a.write);
    for (const char* name : {"target-density-grid", "target-vel-grid", "target-fps", "style", "no-clobber", "half",
             "clipping", "velocity-margin", "vel-voxel-scale", "no-velocity", "format", "nanovdb-quant"})
        setting(join->get_option(std::string("--") + name), name);
}

} // namespace

Command farmCommand()
{
    auto args = std::make_shared<FarmArgs>();
    Command c;
    c.name = "farm";
    c.help = "Split a transfer into time chunks or space tiles run as Slurm array tasks, and join them (docs/farm.md)";
    c.globals = kVerbosity | kThreads;
    auto subs = std::make_shared<std::array<CLI::App*, 3>>();
    c.setup = [args, subs](CLI::App* app) {
        FarmArgs& a = *args;
        app->require_subcommand(1);
        app->fallthrough(); // -v, -q, --threads may follow the plan/submit/join word
        CLI::App* plan = app->add_subcommand(
            "plan", "Write sbatch scripts (an array of chunks or tiles + a dependent join) and plan.json");
        addPlanOptions(plan, a);
        plan->add_flag("--json", a.json, "Print the plan (plan.json's content) as one JSON line on stdout");
        CLI::App* submit =
            app->add_subcommand("submit", "Submit a plan with sbatch: the chunk array, then the join with afterok");
        submit->add_option("--dir", a.dir, "Farm directory written by farm plan");
        submit->add_flag("--json", a.json, "Print the job ids as JSON on stdout");
        CLI::App* join = app->add_subcommand(
            "join", "Assemble the chunks' frames (cross-fading the overlaps) or the tiles' into the output");
        addJoinOptions(join, a);
        // Each subcommand has its own two tiers (--help-all, --print-settings, --settings); --threads stays farm's.
        for (CLI::App* sub : {plan, submit, join}) addGlobalOptions(sub, kDryRun);
        (*subs)[0] = plan;
        (*subs)[1] = submit;
        (*subs)[2] = join;
    };
    c.run = [args, subs] {
        if ((*subs)[0]->parsed()) return runPlan(*args);
        if ((*subs)[1]->parsed()) return runSubmit(*args);
        return runJoin(*args);
    };
    return c;
}

} // namespace vdbturb
