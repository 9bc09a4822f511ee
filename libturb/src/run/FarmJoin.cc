// turb::run::runFarmJoin: vdbturb farm join, the tasks' frames assembled into the plan's output (turb/run/Farm.h).
#include <turb/run/Farm.h>

#include "RunHelpers.h"

#include "FarmShared.h"

#include <turb/run/Output.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Metadata.h>
#include <turb/Resample.h>
#include <turbio/NanoVdb.h>
#include <turbio/Scan.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <chrono>
#include <cstdio>
#include <filesystem>

namespace turb::run {

using detail::secondsSince;

using namespace farm;

namespace {

namespace fs = std::filesystem;

turb::CoordBBox boxFromArray(const nlohmann::json& j)
{
    const auto v = j.get<std::vector<int>>();
    if (v.size() != 6) throw turb::ValueError("plan.json: a box needs 6 indices");
    return turb::CoordBBox(turb::Coord(v[0], v[1], v[2]), turb::Coord(v[3], v[4], v[5]));
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

JoinPlan readJoinPlan(const FarmJoinJob& a)
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
void joinTileFrame(const FarmJoinJob& a, const JoinPlan& p, size_t i)
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
    reporter().frameDone(FrameRecord{t, int(i), int(p.frames.size()), secondsSince(t0), std::string(human) + dst,
        {{"tiles", int(tiles.size())}, {"out", dst}, {"seam_voxels", st.seamVoxels}, {"correlation", st.correlation},
            {"min_correlation", st.minCorrelation}, {"disagreement", st.disagreement}}});
}

// Overlap frame j after chunk k: chunks k and k + 1 cross-faded over up(u_t), written like the chunks' frames.
void blendFrame(const FarmJoinJob& a, const JoinPlan& p, size_t k, int j)
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
    reporter().frameDone(FrameRecord{t, int(i), int(p.frames.size()), secondsSince(t0), std::string(human) + dst,
        {{"chunks", {c.index, next.index}}, {"out", dst}, {"detail_a", w.detailA}, {"detail_b", w.detailB},
            {"density_a", w.densityA}, {"density_b", w.densityB}, {"correlation", st.correlation},
            {"energy_scale", st.energyScale}, {"energy_ratio", expected > 0.0 ? st.energyOut / expected : 1.0}}});
}

// --velocity-margin auto writes the joined frames as the tasks' transfer wrote theirs: one target voxel.
void resolveJoinMargin(turbio::WriteOptions& w, const JoinPlan& p)
{
    if (p.tiled) {
        resolveVelocityMargin(w, p.ratio);
    } else if (w.velocityMargin == kVelocityMarginAuto && !p.chunks.empty()) {
        const turb::TimeChunk& c = p.chunks.front();
        w.velocityMargin = turbio::inspectFile(p.chunkFrames(0).format(p.frames[c.keepBegin]), false).velocityMargin;
    }
}

// Frame i, which chunk k alone owns: copied, or converted from its VDB frame for a NanoVDB output.
void copyOwnFrame(const FarmJoinJob& a, const JoinPlan& p, size_t k, size_t i, bool nano)
{
    const auto t0 = std::chrono::steady_clock::now();
    const std::string src = p.chunkFrames(k).format(p.frames[i]);
    const std::string dst = turbio::FramePattern::parse(p.out).format(p.frames[i]);
    turbio::ensureParentDirectory(dst);
    if (nano) {
        turbio::NanoConvertOptions to;
        to.quantization = a.write.nanoQuantization;
        to.noClobber = a.write.noClobber;
        turbio::convertToNanoVdb(src, dst, to);
    } else {
        copyAtomic(src, dst);
    }
    const int index = p.chunks[k].index;
    reporter().frameDone(FrameRecord{p.frames[i], int(i), int(p.frames.size()), secondsSince(t0),
        "chunk " + std::to_string(index) + " -> " + dst, {{"chunk", index}, {"out", dst}}});
}

// The chunks in frame order: each one's own frames copied, the O it shares with the next cross-faded.
void joinChunks(const FarmJoinJob& a, const JoinPlan& p, bool nano)
{
    for (size_t k = 0; k < p.chunks.size(); ++k) {
        const turb::TimeChunk& c = p.chunks[k];
        const size_t ownEnd = k + 1 < p.chunks.size() ? p.chunks[k + 1].keepBegin : c.end;
        const size_t ownBegin = k > 0 ? c.keepBegin + size_t(p.overlap) : c.keepBegin;
        for (size_t i = ownBegin; i < ownEnd; ++i) copyOwnFrame(a, p, k, i, nano);
        if (k + 1 < p.chunks.size())
            for (int j = 0; j < p.overlap; ++j) blendFrame(a, p, k, j);
    }
}

} // namespace

FarmJoinRun runFarmJoin(const FarmJoinJob& job)
{
    FarmJoinJob a = job; // its velocity margin resolves to the tasks'
    const JoinPlan p = readJoinPlan(a);
    checkOutputFormat(a.write, p.out);
    // NanoVDB output: frames a chunk owns are converted from its VDB frame, blended ones written as NanoVDB.
    const bool nano = turbio::outputFormatFor(p.out, a.write.format) == turbio::OutputFormat::NanoVdb;
    checkChunksComplete(p);
    resolveJoinMargin(a.write, p);
    FarmJoinRun run;
    if (a.dryRun) {
        printData("every " + std::string(p.word()) + "'s frames are present and read; would write " +
                  std::to_string(p.frames.size()) + " frames to " + p.out + " (dry run: nothing written)");
        return run;
    }
    reporter().runStarted("farm join");
    if (p.tiled) {
        for (size_t i = 0; i < p.frames.size(); ++i) joinTileFrame(a, p, i);
    } else {
        joinChunks(a, p, nano);
    }
    reporter().runFinished(0, nlohmann::json::object());
    run.framesWritten = int(p.frames.size());
    return run;
}

} // namespace turb::run
