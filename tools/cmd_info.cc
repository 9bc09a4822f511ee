// vdbturb info PATTERN: what a cache holds, from file headers.
#include "Commands.h"
#include "Console.h"

#include <turbio/Sequence.h>
#include <turbio/Vdb.h>
#include <turb/Error.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>

namespace vdbturb {

namespace {

struct InfoArgs
{
    std::string pattern;
    std::string frames;
    bool json = false;
    bool allValues = false;
    bool noValues = false;
    bool validate = false;
    turbio::ReadOptions read;
};

std::string fmtCoord(const turb::Coord& c)
{
    std::ostringstream os;
    os << "(" << c.x() << "," << c.y() << "," << c.z() << ")";
    return os.str();
}

std::string fmtVec(const turb::Vec3d& v)
{
    char buf[96];
    std::snprintf(buf, sizeof(buf), "(%g,%g,%g)", v.x(), v.y(), v.z());
    return buf;
}

nlohmann::json gridJson(const turbio::GridInfo& g)
{
    nlohmann::json j;
    j["name"] = g.name;
    j["type"] = g.valueType;
    j["class"] = g.gridClass;
    j["vector_type"] = g.vectorType;
    j["role"] = turbio::roleName(g.role);
    if (!g.units.empty()) j["units"] = g.units;
    j["half_float"] = g.halfFloat;
    j["voxel_size"] = g.voxelSize;
    j["origin"] = {g.origin.x(), g.origin.y(), g.origin.z()};
    j["map"] = g.mapType;
    j["supported_transform"] = g.supportedTransform;
    if (g.hasBBox)
        j["active_bbox"] = {{g.activeBBox.min().x(), g.activeBBox.min().y(), g.activeBBox.min().z()},
            {g.activeBBox.max().x(), g.activeBBox.max().y(), g.activeBBox.max().z()}};
    else
        j["active_bbox"] = nullptr;
    j["active_voxels"] = g.activeVoxels;
    if (g.hasRange) j["value_range"] = {g.minValue, g.maxValue};
    else j["value_range"] = nullptr;
    return j;
}

void printGridTable(const turbio::FileInfo& fi)
{
    logInfo("  file format " + std::to_string(fi.fileVersion) + ", written by OpenVDB " + fi.libraryVersion +
            (fi.creator.empty() ? "" : ", creator '" + fi.creator + "'") +
            (fi.baseResolution ? ", Blender domain " + fmtCoord(*fi.baseResolution) : ""));
    for (const auto& g : fi.grids) {
        char line[512];
        std::string range = g.hasRange ? "" : "-";
        if (g.hasRange) {
            char r[96];
            std::snprintf(r, sizeof(r), "[%.4g, %.4g]%s", g.minValue, g.maxValue,
                (g.valueType.rfind("vec", 0) == 0) ? " |v|" : "");
            range = r;
        }
        std::snprintf(line, sizeof(line), "  %-20s %-6s %-11s %-9s%s voxel %-8g origin %-22s bbox %s-%s  %lld active  range %s%s",
            g.name.c_str(), g.valueType.c_str(), g.gridClass.c_str(), turbio::roleName(g.role),
            g.units.empty() ? "" : (" [" + g.units + "]").c_str(), g.voxelSize, fmtVec(g.origin).c_str(),
            g.hasBBox ? fmtCoord(g.activeBBox.min()).c_str() : "(empty)",
            g.hasBBox ? fmtCoord(g.activeBBox.max()).c_str() : "", g.activeVoxels, range.c_str(),
            g.supportedTransform ? "" : ("  UNSUPPORTED " + g.mapType).c_str());
        logInfo(line);
    }
}

int runInfo(const InfoArgs& a)
{
    const turbio::Sequence seq = turbio::resolveSequence(a.pattern, a.frames);
    const bool numbered = seq.pattern.numbered();
    logInfo("sequence " + seq.pattern.str() + ": " + std::to_string(seq.frames.size()) + " frame" +
            (seq.frames.size() == 1 ? "" : "s") +
            (numbered ? " (" + turbio::formatFrameList(seq.frames) + ")" : "") +
            ", missing: " + (seq.missing.empty() ? "none" : turbio::formatFrameList(seq.missing)));

    nlohmann::json out;
    out["pattern"] = seq.pattern.str();
    out["frames"] = seq.frames;
    out["missing"] = seq.missing;
    out["files"] = nlohmann::json::array();
    int failures = 0;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
        const int frame = seq.frames[i];
        const std::string path = seq.path(frame);
        // Value ranges need the voxels: read them for the first frame only unless asked, so info stays
        // fast on long sequences.
        const bool values = !a.noValues && (a.allValues || i == 0);
        nlohmann::json fj;
        fj["frame"] = frame;
        fj["path"] = path;
        try {
            const turbio::FileInfo fi = turbio::inspectFile(path, values);
            if (a.validate) {
                // Read the frame exactly as the other commands would: every voxel, NaN/Inf checks.
                turbio::ReadOptions ro = a.read;
                ro.requireDensity = !ro.densityGrid.empty();
                ro.requireVelocity = !ro.velocityGrid.empty();
                const turb::Frame f = turbio::readFrame(path, frame, ro);
                fj["valid"] = true;
                fj["dt"] = f.dt;
            }
            fj["file_version"] = fi.fileVersion;
            fj["library_version"] = fi.libraryVersion;
            fj["creator"] = fi.creator;
            if (fi.baseResolution)
                fj["blender_base_resolution"] = {fi.baseResolution->x(), fi.baseResolution->y(), fi.baseResolution->z()};
            fj["grids"] = nlohmann::json::array();
            for (const auto& g : fi.grids) fj["grids"].push_back(gridJson(g));
            if (i == 0 || a.allValues || globals().verbosity >= 2) {
                logInfo("frame " + std::to_string(frame) + ": " + path);
                printGridTable(fi);
            } else {
                std::string s = "frame " + std::to_string(frame) + ":";
                for (const auto& g : fi.grids)
                    if (g.role != turbio::GridRole::Other)
                        s += " " + g.name + "=" + std::to_string(g.activeVoxels);
                logInfo(s + " active voxels");
            }
        } catch (const turb::Error& e) {
            ++failures;
            fj["error"] = e.what();
            logError(e.what());
        }
        out["files"].push_back(fj);
    }
    if (a.json) std::cout << out.dump(1) << std::endl;
    return failures ? kFailed : kOk;
}

} // namespace

Command infoCommand()
{
    auto args = std::make_shared<InfoArgs>();
    Command c;
    c.name = "info";
    c.help = "Describe a cache: frames found and missing, grids, units, transforms, bounding boxes";
    c.setup = [args](CLI::App* app) {
        app->add_option("pattern", args->pattern, "Cache: a pattern (####, @, %04d, $F4) or one real file name")
            ->required();
        app->add_option("--frames", args->frames, "Frames to inspect, e.g. 1001-1100x2,1200 (default: all on disk)");
        app->add_flag("--json", args->json, "Print a JSON report on stdout (human text stays on stderr)");
        app->add_flag("--all-values", args->allValues, "Read every frame's voxels for value ranges (slower)");
        app->add_flag("--headers-only", args->noValues, "Read no voxels at all (no value ranges)");
        app->add_flag("--validate", args->validate,
            "Also load every frame as transfer/measure would (all voxels, NaN/Inf checks); exit 1 on any bad frame");
        addReadOptions(app, args->read);
    };
    c.run = [args] { return runInfo(*args); };
    return c;
}

} // namespace vdbturb
