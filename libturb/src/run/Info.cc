// turb::run::runInfo: vdbturb info's report, from file headers (turb/run/Info.h).
#include <turb/run/Info.h>

#include <turb/run/Flags.h>
#include <turb/run/Output.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turbio/Checksum.h>
#include <turbio/NanoVdb.h>
#include <turbio/Scan.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <sstream>

namespace turb::run {

namespace {

using InfoArgs = InfoJob;

// Rows of cells as text with every column padded to its widest cell, one line per row, each prefixed by `indent`.
std::string alignColumns(const std::vector<std::vector<std::string>>& rows, const std::string& indent = "  ")
{
    std::vector<size_t> width;
    for (const auto& r : rows)
        for (size_t c = 0; c < r.size(); ++c) {
            if (width.size() <= c) width.resize(c + 1, 0);
            width[c] = std::max(width[c], r[c].size());
        }
    std::string out;
    for (const auto& r : rows) {
        std::string line = indent;
        for (size_t c = 0; c < r.size(); ++c) {
            line += r[c];
            if (c + 1 < r.size()) line += std::string(width[c] - r[c].size() + 2, ' ');
        }
        while (!line.empty() && line.back() == ' ') line.pop_back();
        out += line + "\n";
    }
    return out;
}

std::string fmtCoord(const turb::Coord& c)
{
    std::ostringstream os;
    os << "(" << c.x() << "," << c.y() << "," << c.z() << ")";
    return os.str();
}

std::string fmtVec(const turb::Vec3d& v)
{
    char buf[96];
    const auto clean = [](double x) { return std::abs(x) < 1e-9 ? 0.0 : x; }; // 4e-17 is rounding, not a place
    std::snprintf(buf, sizeof(buf), "(%.4g,%.4g,%.4g)", clean(v.x()), clean(v.y()), clean(v.z()));
    return buf;
}

std::string fmtNum(const char* f, double v)
{
    char buf[64];
    std::snprintf(buf, sizeof(buf), f, v);
    return buf;
}

// World-space extent of the cells of index box `b`: from the low corner of its first voxel to the high
// corner of its last.
std::pair<turb::Vec3d, turb::Vec3d> worldBounds(const turb::CoordBBox& b, double voxel, const turb::Vec3d& origin)
{
    return {origin + (b.min().asVec3d() - turb::Vec3d(0.5)) * voxel,
        origin + (b.max().asVec3d() + turb::Vec3d(0.5)) * voxel};
}

nlohmann::json vecJson(const turb::Vec3d& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json gridJson(const turbio::GridInfo& g)
{
    nlohmann::json j;
    j["index"] = g.index;
    j["selector"] = g.selector;
    j["name"] = g.name;
    j["type"] = g.valueType;
    j["class"] = g.gridClass;
    j["vector_type"] = g.vectorType;
    j["role"] = turbio::roleName(g.role);
    if (!g.units.empty()) j["units"] = g.units;
    j["half_float"] = g.halfFloat;
    j["voxel_size"] = g.voxelSize;
    j["origin"] = vecJson(g.origin);
    j["map"] = g.mapType;
    j["supported_transform"] = g.supportedTransform;
    if (g.hasBBox) {
        j["active_bbox"] = {{g.activeBBox.min().x(), g.activeBBox.min().y(), g.activeBBox.min().z()},
            {g.activeBBox.max().x(), g.activeBBox.max().y(), g.activeBBox.max().z()}};
        const auto wb = worldBounds(g.activeBBox, g.voxelSize, g.origin);
        j["world_bounds"] = {vecJson(wb.first), vecJson(wb.second)};
    } else {
        j["active_bbox"] = nullptr;
        j["world_bounds"] = nullptr;
    }
    j["active_voxels"] = g.activeVoxels;
    if (g.hasRange) j["value_range"] = {g.minValue, g.maxValue};
    else j["value_range"] = nullptr;
    return j;
}

std::string gridTable(const turbio::FileInfo& fi)
{
    std::string out = fi.nanoVdb ? std::string("  NanoVDB file, read as every command reads it (its grids converted "
                                               "to OpenVDB's, quantised floats to float)")
                                 : "  file format " + std::to_string(fi.fileVersion) + ", written by OpenVDB " +
                                       fi.libraryVersion + (fi.creator.empty() ? "" : ", creator '" + fi.creator + "'");
    if (fi.baseResolution) {
        const turb::Coord r = *fi.baseResolution;
        out += ", Blender domain " + std::to_string(r.x()) + "x" + std::to_string(r.y()) + "x" + std::to_string(r.z());
    }
    if (fi.velocityMargin >= 0)
        out += ", velocity written only within " + std::to_string(fi.velocityMargin) + " voxel" +
               (fi.velocityMargin == 1 ? "" : "s") + " of the smoke";
    if (std::any_of(fi.grids.begin(), fi.grids.end(), [](const turbio::GridInfo& g) { return g.halfFloat; }))
        out += ", 16-bit floats";
    if (!fi.sourceFrame.empty()) out += ", made from source frame " + fi.sourceFrame + " (vdbturb_source_frame)";
    if (!fi.tileBox.empty()) out += ", a space tile of target box " + fi.tileBox + " (vdbturb_tile_box)";
    if (!fi.farmTiles.empty())
        out += ", joined from tiles " + fi.farmTiles + (fi.tileBorders.empty() ? "" : ", borders " + fi.tileBorders) +
               " (vdbturb_farm_tiles)";
    if (fi.rangesSkipped > 0)
        out += ", value ranges of the last " + std::to_string(fi.rangesSkipped) +
               " grids not read (1 GB of grids read for ranges already)";
    out += "\n";
    if (fi.grids.empty())
        return out + "  no grids: an empty frame (no command can read it; leave it out with --frames)";
    std::vector<std::vector<std::string>> rows{{"#", "grid", "type", "class", "role", "voxel", "origin",
        "active box (index)", "world bounds", "active", "values"}};
    for (const auto& g : fi.grids) {
        std::string range = "-";
        if (g.hasRange)
            range = "[" + fmtNum("%.4g", g.minValue) + ", " + fmtNum("%.4g", g.maxValue) + "]" +
                    (g.valueType.rfind("vec", 0) == 0 ? " |v|" : "");
        std::string role = turbio::roleName(g.role);
        if (!g.units.empty()) role += " (" + g.units + ")";
        std::string box = "(empty)", bounds = "-";
        if (g.hasBBox) {
            box = fmtCoord(g.activeBBox.min()) + "-" + fmtCoord(g.activeBBox.max());
            const auto wb = worldBounds(g.activeBBox, g.voxelSize, g.origin);
            bounds = fmtVec(wb.first) + "-" + fmtVec(wb.second);
        }
        std::string name = g.name.empty() ? "(unnamed) " + g.selector : g.name;
        if (!g.name.empty() && g.selector != g.name) name += " (" + g.selector + ")";
        rows.push_back({std::to_string(g.index), name, g.valueType, g.gridClass, role, fmtNum("%g", g.voxelSize),
            fmtVec(g.origin), box, bounds, g.activeVoxels < 0 ? "?" : std::to_string(g.activeVoxels),
            range + (g.supportedTransform ? "" : "  UNSUPPORTED " + g.mapType + " transform")});
    }
    return out + alignColumns(rows, "  ");
}

// What the frames can drive, from the grids a read found (said plainly: a density-only file is valid
// but cannot be a transfer target or source).
std::string usability(bool density, bool velocity)
{
    if (density && velocity)
        return "velocity and density: usable by transfer (target or source), synth, measure and preview";
    if (velocity)
        return "velocity without density: usable by synth (no smoke mask), measure's --output and preview's "
               "speed/vorticity/lic; transfer needs density in target and source";
    if (density)
        return "density only, no velocity grid: it cannot drive transfer (target or source) or synth; usable by "
               "preview --mode density";
    return "neither density nor velocity: no command can use it";
}

// Per-grid fingerprints of one file (--checksum), as text lines and into its JSON record.
std::string checksumLines(const std::string& path, nlohmann::json& fj)
{
    std::vector<std::vector<std::string>> rows{{"grid", "type", "active voxels", "values", "metadata"}};
    fj["checksums"] = nlohmann::json::array();
    for (const turbio::GridChecksum& g : turbio::gridChecksums(path)) {
        rows.push_back({g.name, g.valueType, std::to_string(g.activeVoxels), turbio::hexDigest(g.values),
            turbio::hexDigest(g.metadata)});
        fj["checksums"].push_back({{"grid", g.name}, {"type", g.valueType}, {"active_voxels", g.activeVoxels},
            {"values", turbio::hexDigest(g.values)}, {"metadata", turbio::hexDigest(g.metadata)}});
    }
    return alignColumns(rows);
}

// The first line: the frames found and missing.
std::string sequenceLine(const turbio::Sequence& seq)
{
    return "sequence " + seq.pattern.str() + ": " + std::to_string(seq.frames.size()) + " frame" +
           (seq.frames.size() == 1 ? "" : "s") +
           (seq.pattern.numbered() ? " (" + turbio::formatFrameList(seq.frames) + ")" : "") +
           ", missing: " + (seq.missing.empty() ? "none" : turbio::formatFrameList(seq.missing));
}

// From the first readable frame's headers: the lattice and its changes, the domain, dt and units with their sources.
std::string latticeLines(
    const turbio::FrameScan& first, const turbio::SequenceScan& scan, const turbio::ReadOptions& ro)
{
    const turbio::ReadReport& t = first.timing;
    const TimingSources source = timingSources(t);
    std::string head = "\nlattice: voxel " + fmtNum("%g", first.lattice.voxelSize) + ", origin " +
                       fmtVec(first.lattice.origin) +
                       (scan.changes.empty() ? std::string(", the same in every frame")
                                             : "; CHANGES within the sequence: " + scan.describeChanges()) +
                       (scan.blenderAdaptive.empty() ? std::string() : "\nWRONG SCALE: " + scan.blenderAdaptive);
    // The domain as the cache spans it; what a read holds (the smoke and its margin) after it.
    const auto wb = worldBounds(first.span, first.lattice.voxelSize, first.lattice.origin);
    const turb::Coord d = first.span.dim();
    head += "\ndomain (frame " + std::to_string(first.frame) + "): " + std::to_string(d.x()) + "x" +
            std::to_string(d.y()) + "x" + std::to_string(d.z()) + " voxels, world " + fmtVec(wb.first) + "-" +
            fmtVec(wb.second);
    if (first.span != first.domain) {
        const turb::Coord e = first.domain.dim();
        head += "; held in memory: " + std::to_string(e.x()) + "x" + std::to_string(e.y()) + "x" +
                std::to_string(e.z()) + " voxels (the smoke and a margin of " + std::to_string(ro.cropMargin) +
                " voxels)";
    }
    if (first.sequenceDomain) {
        const turb::CoordBBox& sd = *first.sequenceDomain;
        const auto sw = worldBounds(sd, first.lattice.voxelSize, first.lattice.origin);
        head += "\nmade from a domain of " + std::to_string(sd.dim().x()) + "x" + std::to_string(sd.dim().y()) + "x" +
                std::to_string(sd.dim().z()) + " voxels at this resolution, world " + fmtVec(sw.first) + "-" +
                fmtVec(sw.second) + " (vdbturb_sequence_domain: the target's)";
    }
    head += "\ndt: " + fmtNum("%.6g", t.dt) + " per frame (" + source.dt + ")";
    if (t.fpsSource != "not used") head += "; fps " + fmtNum("%g", t.fps) + " (" + source.fps + ")";
    if (!first.velocityGrid.empty())
        head +=
            "\nvelocity units: " +
            (t.cells ? "grid cells per time unit, x voxel " + fmtNum("%g", first.lattice.voxelSize) + " = world units"
                     : std::string("world units per time unit")) +
            " (" + source.units + "); time unit " + fmtNum("%.6g", t.timeUnit) + " s" +
            (t.timeUnit == 1.0 ? " (per second)" : "") + " (" + t.timeUnitSource + ")";
    for (const auto& n : t.notes) head += "\nnote: " + n;
    return head;
}

nlohmann::json sequenceJson(
    const turbio::Sequence& seq, const turbio::SequenceScan& scan, const turbio::FrameScan* first)
{
    nlohmann::json out;
    out["pattern"] = seq.pattern.str();
    out["frames"] = seq.frames;
    out["missing"] = seq.missing;
    out["lattice_changes"] = nlohmann::json::array();
    for (const auto& c : scan.changes)
        out["lattice_changes"].push_back(
            {{"from_frame", c.fromFrame}, {"to_frame", c.toFrame}, {"from_path", c.fromPath}, {"to_path", c.toPath},
                {"from_voxel", c.from.voxelSize}, {"to_voxel", c.to.voxelSize}, {"from_origin", vecJson(c.from.origin)},
                {"to_origin", vecJson(c.to.origin)}});
    if (!scan.blenderAdaptive.empty()) out["blender_adaptive"] = scan.blenderAdaptive;
    if (!seq.skippedFiles.empty()) out["skipped_files"] = seq.skippedFiles;
    if (first) {
        const TimingSources source = timingSources(first->timing);
        out["timing"] = {{"dt", first->timing.dt}, {"dt_source", source.dt}, {"fps", first->timing.fps},
            {"fps_source", source.fps}, {"velocity_units", first->timing.cells ? "cells" : "world"},
            {"units_source", source.units}, {"convention_assumed", first->timing.conventionAssumed},
            {"time_unit_s", first->timing.timeUnit}, {"time_unit_source", first->timing.timeUnitSource}};
    }
    out["files"] = nlohmann::json::array();
    return out;
}

// What --validate found over the frames.
struct Tally
{
    bool anyDensity = false, anyVelocity = false;
};

// --validate: the frame read exactly as the other commands would (every voxel, NaN/Inf checks).
void validateFrame(const std::string& path, int frame, const turbio::ReadOptions& ro, nlohmann::json& fj, Tally& tally)
{
    turbio::ReadReport report;
    const turb::Frame f = turbio::readFrame(path, frame, ro, &report);
    fj["valid"] = true;
    fj["dt"] = f.dt;
    fj["dt_source"] = timingSources(report).dt;
    fj["has_density"] = f.hasDensity();
    fj["has_velocity"] = f.hasVelocity();
    fj["usable"] = usability(f.hasDensity(), f.hasVelocity());
    tally.anyDensity = tally.anyDensity || f.hasDensity();
    tally.anyVelocity = tally.anyVelocity || f.hasVelocity();
}

void fileJson(const turbio::FileInfo& fi, nlohmann::json& fj)
{
    if (fi.nanoVdb) fj["format"] = "nanovdb";
    fj["file_version"] = fi.fileVersion;
    fj["library_version"] = fi.libraryVersion;
    fj["creator"] = fi.creator;
    fj["velocity_margin"] = fi.velocityMargin >= 0 ? nlohmann::json(fi.velocityMargin) : nlohmann::json(nullptr);
    if (!fi.sourceFrame.empty()) fj["source_frame"] = fi.sourceFrame;
    if (!fi.tileBox.empty()) fj["tile_box"] = fi.tileBox;
    if (!fi.farmTiles.empty()) fj["farm_tiles"] = fi.farmTiles;
    if (!fi.tileBorders.empty()) fj["tile_borders"] = fi.tileBorders;
    if (fi.recordedTimeUnit > 0.0) fj["time_unit_s"] = fi.recordedTimeUnit;
    if (fi.baseResolution)
        fj["blender_base_resolution"] = {fi.baseResolution->x(), fi.baseResolution->y(), fi.baseResolution->z()};
    fj["grids"] = nlohmann::json::array();
    for (const auto& g : fi.grids) fj["grids"].push_back(gridJson(g));
}

// Where the smoke is (it needs the voxels): strays far from it are left out of every read. Returns the lines to
// print ("" without density).
std::string smokeLines(const std::string& path, int frame, const turbio::ReadOptions& ro,
    const turbio::SequenceScan& scan, nlohmann::json& fj)
{
    const turbio::SmokeRegion region = turbio::smokeRegion(path, ro);
    if (!region.hasDensity) return "";
    turb::CoordBBox reach = region.smoke;
    for (const auto& f : scan.frames)
        if (f.frame == frame) reach.expand(f.others);
    const turb::CoordBBox held = turbio::heldRegion(region, reach, ro);
    fj["smoke_voxels"] = region.smokeVoxels;
    if (!held.empty())
        fj["held_box"] = {
            {held.min().x(), held.min().y(), held.min().z()}, {held.max().x(), held.max().y(), held.max().z()}};
    nlohmann::json strays = nlohmann::json::array();
    for (const auto& c : region.strays)
        strays.push_back({{"voxels", c.voxels}, {"distance", c.distance}, {"mass_share", c.massShare},
            {"min", {c.box.min().x(), c.box.min().y(), c.box.min().z()}},
            {"max", {c.box.max().x(), c.box.max().y(), c.box.max().z()}}});
    fj["strays"] = strays;
    std::string lines = region.describeStrays();
    if (!held.empty()) {
        const turb::Coord d = held.dim();
        lines = (lines.empty() ? "" : lines + "\n") + "held in memory: " + std::to_string(d.x()) + "x" +
                std::to_string(d.y()) + "x" + std::to_string(d.z()) + " voxels " + "(the smoke and a margin of " +
                std::to_string(ro.cropMargin) + " voxels)";
    }
    return lines;
}

// One frame's file: its grids as a table (the first frame, a lattice change, or when asked) or one line of active
// voxels, into `fj` for the JSON.
void describeFile(const InfoArgs& a, const turbio::ReadOptions& ro, const turbio::SequenceScan& scan, int frame,
    const std::string& path, bool first, nlohmann::json& fj, Tally& tally)
{
    // Value ranges need the voxels: read them for the first frame only unless asked, so info stays fast on long
    // sequences.
    const bool values = !a.noValues && (a.allValues || first);
    const turbio::FileInfo fi = turbio::inspectFile(path, values);
    if (a.validate) validateFrame(path, frame, ro, fj, tally);
    fileJson(fi, fj);
    std::string extra = values && ro.cropToSmoke ? smokeLines(path, frame, ro, scan, fj) : std::string();
    if (a.checksum) extra = (extra.empty() ? "" : extra + "\n") + checksumLines(path, fj);
    bool changed = false;
    for (const auto& c : scan.changes) changed = changed || c.toFrame == frame;
    if (first || a.allValues || a.checksum || changed || a.everyTable) {
        printData("frame " + std::to_string(frame) + ": " + path + (changed ? "  (lattice changes here)" : "") + "\n" +
                      gridTable(fi) + (extra.empty() ? "" : "\n" + extra),
            a.json);
    } else {
        std::string line = "frame " + std::to_string(frame) + ":";
        for (const auto& g : fi.grids)
            if (g.role != turbio::GridRole::Other) line += " " + g.name + "=" + std::to_string(g.activeVoxels);
        printData(line + " active voxels", a.json);
    }
}

// A NanoVDB grid type with its storage in words, for the table's header line.
std::string quantisationText(const std::string& type)
{
    if (type == "fp16") return "16-bit fixed point per 8^3 leaf";
    if (type == "fp8") return "8-bit fixed point per 8^3 leaf";
    if (type == "fp4") return "4-bit fixed point per 8^3 leaf";
    if (type == "fpN") return "variable bits per 8^3 leaf";
    return "";
}

nlohmann::json nanoGridJson(const turbio::NanoGridInfo& g)
{
    nlohmann::json j;
    j["index"] = g.index;
    j["name"] = g.name;
    j["type"] = g.valueType;
    j["class"] = g.gridClass;
    j["quantisation"] =
        quantisationText(g.valueType).empty() ? nlohmann::json(nullptr) : nlohmann::json(quantisationText(g.valueType));
    j["voxel_size"] = vecJson(g.voxelSize);
    j["origin"] = g.hasTransform ? vecJson(g.origin) : nlohmann::json(nullptr);
    if (g.hasBBox) {
        j["active_bbox"] = {{g.activeBBox.min().x(), g.activeBBox.min().y(), g.activeBBox.min().z()},
            {g.activeBBox.max().x(), g.activeBBox.max().y(), g.activeBBox.max().z()}};
        j["world_bbox"] = {vecJson(g.worldMin), vecJson(g.worldMax)};
    } else {
        j["active_bbox"] = nullptr;
        j["world_bbox"] = nullptr;
    }
    j["active_voxels"] = g.activeVoxels;
    j["bytes"] = g.bytes;
    j["file_bytes"] = g.fileBytes;
    j["codec"] = g.codec;
    j["version"] = g.version;
    return j;
}

// One NanoVDB file's grids as a table, from its headers.
std::string nanoGridTable(const turbio::NanoFileInfo& fi)
{
    std::string out = "  NanoVDB " + (fi.grids.empty() ? std::string("?") : fi.grids.front().version) + ", " +
                      turbio::formatBytes(double(fi.fileBytes)) + " (" + std::to_string(fi.fileBytes) + " bytes)";
    std::string quantised;
    for (const auto& g : fi.grids)
        if (!quantisationText(g.valueType).empty())
            quantised += (quantised.empty() ? "" : ", ") + g.name + " " + g.valueType;
    if (!quantised.empty()) out += "; quantised: " + quantised;
    out += "\n";
    std::vector<std::vector<std::string>> rows{{"#", "grid", "type", "class", "voxel", "origin", "active box (index)",
        "world bounds", "active", "bytes", "codec"}};
    for (const auto& g : fi.grids) {
        const turb::Vec3d v = g.voxelSize;
        const bool uniform = v.x() == v.y() && v.y() == v.z();
        std::string box = "(empty)", bounds = "-";
        if (g.hasBBox) {
            box = fmtCoord(g.activeBBox.min()) + "-" + fmtCoord(g.activeBBox.max());
            // The cells' extent, as for VDB files; NanoVDB's own world box where the transform was not read.
            const auto wb = g.hasTransform && uniform ? worldBounds(g.activeBBox, v.x(), g.origin)
                                                      : std::make_pair(g.worldMin, g.worldMax);
            bounds = fmtVec(wb.first) + "-" + fmtVec(wb.second);
        }
        rows.push_back({std::to_string(g.index), g.name.empty() ? "(unnamed)" : g.name, g.valueType, g.gridClass,
            uniform ? fmtNum("%g", v.x()) : fmtVec(v), g.hasTransform ? fmtVec(g.origin) : "?", box, bounds,
            std::to_string(g.activeVoxels), std::to_string(g.bytes), g.codec});
    }
    return out + alignColumns(rows, "  ");
}

// Every frame of `seq` is described by `describe` into its own JSON object in out["files"]; a damaged one gets its
// reason (and a FAILED line) instead, and the walk goes on. Returns the damaged frames.
std::vector<int> describeFrames(const turbio::Sequence& seq, bool json, nlohmann::json& out,
    const std::function<void(int, const std::string&, size_t, nlohmann::json&)>& describe)
{
    std::vector<int> damaged;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
        const int frame = seq.frames[i];
        const std::string path = seq.path(frame);
        nlohmann::json fj;
        fj["frame"] = frame;
        fj["path"] = path;
        try {
            describe(frame, path, i, fj);
        } catch (const turb::Error& e) {
            damaged.push_back(frame);
            fj["error"] = messageWithFlags(e);
            printData("frame " + std::to_string(frame) + ": FAILED: " + messageWithFlags(e), json);
        }
        out["files"].push_back(fj);
    }
    return damaged;
}

// The line naming the frames that failed to read; "" when none did.
std::string failedLine(const std::vector<int>& damaged, const turbio::Sequence& seq)
{
    if (damaged.empty()) return "";
    return std::to_string(damaged.size()) + " of " + std::to_string(seq.frames.size()) + " frame" +
           (seq.frames.size() == 1 ? "" : "s") + " failed to read: " + turbio::formatFrameList(damaged);
}

// The first lines: the frames found and missing, and the notes on the files the pattern left out.
std::string sequenceHead(const turbio::Sequence& seq)
{
    return sequenceLine(seq) + (seq.oneOfSequence.empty() ? "" : "\nnote: " + seq.oneOfSequence) +
           (seq.skippedFiles.empty() ? "" : "\nnote: " + seq.skippedFiles);
}

// One NanoVDB file: its grids into `fj`, and as a table (the first frame, -v, --all-values) or one line.
void describeNanoFile(const InfoArgs& a, int frame, const std::string& path, bool first, nlohmann::json& fj)
{
    const turbio::NanoFileInfo fi = turbio::inspectNanoFile(path);
    fj["file_bytes"] = fi.fileBytes;
    fj["grids"] = nlohmann::json::array();
    for (const auto& g : fi.grids) fj["grids"].push_back(nanoGridJson(g));
    if (first || a.allValues || a.everyTable) {
        printData("frame " + std::to_string(frame) + ": " + path + "\n" + nanoGridTable(fi), a.json);
    } else {
        std::string line = "frame " + std::to_string(frame) + ":";
        for (const auto& g : fi.grids) line += " " + g.name + "=" + std::to_string(g.activeVoxels);
        printData(line + " active voxels, " + turbio::formatBytes(double(fi.fileBytes)), a.json);
    }
}

// `info` on NanoVDB files: each frame's headers (grids, types and quantisation, voxel counts, boxes, voxel size,
// sizes). No voxel is read, and no vdbturb metadata exists to show: NanoVDB files hold none.
InfoRun nanoInfo(const InfoArgs& a, const turbio::Sequence& seq)
{
    printData(sequenceHead(seq) +
                  "\nNanoVDB files: grids and sizes from the headers (NanoVDB holds no vdbturb metadata: dt, units and "
                  "the settings are in the VDB files they were made from)",
        a.json);
    InfoRun run;
    nlohmann::json& out = run.report;
    out["pattern"] = seq.pattern.str();
    out["format"] = "nanovdb";
    out["frames"] = seq.frames;
    out["missing"] = seq.missing;
    out["files"] = nlohmann::json::array();
    const std::vector<int> damaged =
        describeFrames(seq, a.json, out, [&](int frame, const std::string& path, size_t i, nlohmann::json& fj) {
            describeNanoFile(a, frame, path, i == 0, fj);
        });
    run.framesFailed = int(damaged.size());
    run.failedLine = failedLine(damaged, seq);
    return run;
}

} // namespace

InfoRun runInfo(const InfoJob& a)
{
    const turbio::Sequence seq = turbio::resolveSequence(a.pattern, a.frames);
    // NanoVDB files (by name or by magic number): their headers, unless --validate or --checksum asks for every frame
    // read as the commands read it, which the rest does for them as for VDB files.
    const std::string firstFile = seq.pattern.format(seq.frames.empty() ? 0 : seq.frames.front());
    if ((turbio::isNanoVdbPath(firstFile) || turbio::isNanoVdbFile(firstFile)) && !a.validate && !a.checksum)
        return nanoInfo(a, seq);
    const bool toStderr = a.json; // stdout carries the JSON then
    turbio::ReadOptions ro = a.read;
    ro.requireDensity = !ro.densityGrid.empty();
    ro.requireVelocity = !ro.velocityGrid.empty();
    const turbio::SequenceScan scan = turbio::scanSequence(seq, seq.frames, ro);
    const turbio::FrameScan* first = nullptr;
    for (const auto& f : scan.frames)
        if (f.error.empty()) {
            first = &f;
            break;
        }
    printData(sequenceHead(seq) + (first ? latticeLines(*first, scan, ro) : std::string()), toStderr);

    InfoRun run;
    run.report = sequenceJson(seq, scan, first);
    Tally tally;
    const std::vector<int> damaged =
        describeFrames(seq, a.json, run.report, [&](int frame, const std::string& path, size_t i, nlohmann::json& fj) {
            describeFile(a, ro, scan, frame, path, i == 0, fj, tally);
        });
    run.framesFailed = int(damaged.size());
    run.failedLine = failedLine(damaged, seq);
    if (a.validate) {
        const std::string verdict = run.framesFailed ? std::to_string(run.framesFailed) + " of " +
                                                           std::to_string(seq.frames.size()) + " frames fail to read"
                                                     : "every frame reads";
        run.validateLine = "validate: " + verdict + "; " + usability(tally.anyDensity, tally.anyVelocity);
        run.report["usable"] = usability(tally.anyDensity, tally.anyVelocity);
    }
    return run;
}

} // namespace turb::run
