// turb::run::runResample: vdbturb resample's run, from files to files (turb/run/Resample.h).
#include <turb/run/Resample.h>

#include "RunHelpers.h"

#include <turb/run/Output.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Metadata.h>
#include <turb/Reorient.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <sstream>

namespace turb::run {

using detail::secondsSince;

namespace {

using ResampleArgs = ResampleJob;

// Metadata in output voxels (the up-res ratio, the recorded domain, the patch lattice) kept true after a box
// down-sample by `down`, or dropped where it cannot be: after a reorientation, or a patch size `down` does not divide.
void rescaleIndexMetadata(std::map<std::string, std::string>& meta, int down, bool reoriented)
{
    namespace m = turb::meta;
    const auto divide = [&](const char* key) {
        const auto it = meta.find(key);
        if (it == meta.end()) return;
        const int v = std::atoi(it->second.c_str());
        if (!reoriented && v > 0 && v % down == 0) it->second = std::to_string(v / down);
        else meta.erase(it);
    };
    divide(m::kRatio);
    divide(m::kPatchSize);
    if (down == 1 && !reoriented) return;
    if (reoriented) {
        meta.erase(m::kDomain);
        meta.erase(m::kPatchOrigin);
        return;
    }
    if (const auto it = meta.find(m::kDomain); it != meta.end()) {
        std::istringstream in(it->second);
        int b[6];
        if (in >> b[0] >> b[1] >> b[2] >> b[3] >> b[4] >> b[5]) {
            std::ostringstream out;
            for (int k = 0; k < 6; ++k) out << (k ? " " : "") << turb::floorDiv(b[k], down);
            it->second = out.str();
        } else {
            meta.erase(it);
        }
    }
    if (const auto it = meta.find(m::kPatchOrigin); it != meta.end()) {
        int x = 0, y = 0, z = 0;
        if (std::sscanf(it->second.c_str(), "%d,%d,%d", &x, &y, &z) == 3 && x % down == 0 && y % down == 0 &&
            z % down == 0)
            it->second = std::to_string(x / down) + "," + std::to_string(y / down) + "," + std::to_string(z / down);
        else {
            meta.erase(it); // the seams no longer fall on voxel faces: no patch lattice at all
            meta.erase(m::kPatchSize);
        }
    }
}

std::string joined(const std::vector<std::string>& names)
{
    std::string s;
    for (const auto& n : names) s += (s.empty() ? "'" : ", '") + n + "'";
    return s;
}

// The other grids carried, once per sequence at -v; what is not exact, as warnings, once.
void reportOtherGrids(const turbio::OtherGrids& others, const std::string& path, bool first, bool moved)
{
    if (!first || others.size() == 0) return;
    logVerbose(path + ": also carrying " + joined(others.names()));
    if (const auto u = others.unchanged(); !u.empty())
        logWarning(path + ": " + joined(u) + (u.size() == 1 ? " lies" : " lie") +
                   " on another lattice than the frame's: written unchanged (--drop-other-grids leaves them out)");
    if (const auto st = others.staggered(); moved && !st.empty())
        logWarning(path + ": " + joined(st) + (st.size() == 1 ? " is" : " are") +
                   " staggered (face-sampled): resampled as cell values, so the faces may be off by up to a voxel");
}

// AXIS:TURNS, e.g. y:1 = one right-handed quarter turn about y; "" = none.
turb::AxisRotation parseRotation(const std::string& text)
{
    if (text.empty()) return {};
    const size_t colon = text.find(':');
    const std::string axis = text.substr(0, colon);
    const int turns = colon == std::string::npos ? 1 : std::stoi(text.substr(colon + 1));
    if (axis != "x" && axis != "y" && axis != "z") throw turb::ValueError("--rotate: axis must be x, y or z");
    return turb::AxisRotation::quarterTurns(axis == "x" ? 0 : axis == "y" ? 1 : 2, turns);
}

// Everything else the file holds goes along, resampled with the frame: a proxy keeps Blender's flags, colours,
// level sets.
turbio::OtherGrids carriedGrids(const ResampleArgs& a, const turbio::ReadOptions& read, const std::string& path,
    const turb::Frame& frame, const turb::AxisRotation& rot, bool first)
{
    turbio::OtherGrids others = turbio::OtherGrids::read(path, read, frame.lattice());
    // A carried grid named as the frame's grids are written (a --density-grid other than 'density' leaves the
    // file's 'density' among the others) would give the file two grids of one name.
    const bool blender = a.write.style == turbio::WriteStyle::Blender;
    const std::vector<std::string> clash =
        others.dropNamed({"density", blender ? "velocity" : "vel", "temperature", "flame"});
    if (!clash.empty() && first)
        logWarning(path + ": " + joined(clash) + " left out: the frame's own grids are written under " +
                   (clash.size() == 1 ? "that name" : "those names"));
    if (a.down > 1) others.downsample(turb::domainFactors(frame.bbox(), a.down));
    others.rotate(rot);
    reportOtherGrids(others, path, first, a.down > 1 || !rot.isIdentity());
    return others;
}

// What the checks found: the frames, their inputs and outputs, the settings they record, which are written.
struct ResamplePlan
{
    turbio::Sequence seq;
    turbio::FramePattern outPattern;
    std::vector<std::string> outputs, inputs;
    std::string settings; ///< the job's with the input's absolute pattern, as commandSettingsText writes inputs
    SkipPlan skips;
};

// Every check before the first frame: the output options and paths, every input frame's headers, what
// --skip-existing skips.
ResamplePlan planResample(const ResampleArgs& a, const turbio::ReadOptions& read)
{
    ResamplePlan p;
    p.seq = turbio::resolveSequence(a.in, a.frames);
    p.outPattern = turbio::FramePattern::parse(a.out);
    checkOutputFormat(a.write, a.out, a.skipExisting ? "--skip-existing" : "");
    if (p.seq.frames.size() > 1 && !p.outPattern.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token but several frames are requested");
    // Each frame is resampled on its own, so a lattice change within the sequence is carried through.
    const turbio::SequenceScan scan = checkInput("resample", "cache", p.seq, p.seq.frames, read, LatticePolicy::Report);
    reportTiming("cache", scan, true); // the output records dt (vdbturb_dt)
    for (int f : p.seq.frames) {
        p.outputs.push_back(p.outPattern.format(f));
        p.inputs.push_back(p.seq.path(f));
    }
    checkOutputs(p.outputs, p.inputs, a.write.noClobber, a.skipExisting);
    // Each frame is made from its input alone, so a frame written by the same settings is whole and final.
    p.settings =
        a.settings + "input=" + std::filesystem::absolute(p.seq.pattern.str()).lexically_normal().string() + ";";
    p.skips = planSkips(p.outputs, p.seq.frames, "resample", p.settings, a.skipExisting);
    return p;
}

// One frame, read, resampled with the grids it carries and written. Returns the path written.
std::string resampleFrame(const ResampleArgs& a, const turbio::ReadOptions& read, const ResamplePlan& p, size_t i,
    const turb::AxisRotation& rot, bool& warnedClipping)
{
    const int f = p.seq.frames[i];
    turb::Frame frame = turbio::readFrame(p.seq.path(f), f, read);
    std::optional<turbio::OtherGrids> others;
    if (!a.dropOtherGrids) others = carriedGrids(a, read, p.seq.path(f), frame, rot, i == 0);
    if (a.down > 1) frame = turb::downsampleFrame(frame, a.down);
    if (!rot.isIdentity()) frame = turb::reorientFrame(frame, rot);
    rescaleIndexMetadata(frame.metadata, a.down, !rot.isIdentity());
    frame.metadata[turb::meta::kCommand] = "resample";
    frame.metadata[turb::meta::kSettings] = p.settings;
    const std::string path = p.outPattern.format(f);
    turbio::ensureParentDirectory(path);
    warnIfClippedAway(frame, a.write, path, warnedClipping);
    turbio::writeFrame(path, frame, a.write, others ? &*others : nullptr);
    return path;
}

// The frames in order, each reported (a skipped one as such).
ResampleRun resampleFrames(
    const ResampleArgs& a, const turbio::ReadOptions& read, const ResamplePlan& p, const turb::AxisRotation& rot)
{
    ResampleRun run;
    lockOutputFrames(p.outPattern, p.skips.writing);
    reporter().runStarted("resample");
    bool warnedClipping = false;
    const int count = int(p.seq.frames.size());
    for (size_t i = 0; i < p.seq.frames.size(); ++i) {
        const int f = p.seq.frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        if (p.skips.skip[i]) {
            reporter().frameDone(FrameRecord{f, int(i), count, secondsSince(t0),
                "skipped: " + p.outputs[i] + " was written by the same settings",
                {{"out", p.outputs[i]}, {"in", p.inputs[i]}, {"skipped", true}}});
            ++run.framesSkipped;
            continue;
        }
        const std::string path = resampleFrame(a, read, p, i, rot, warnedClipping);
        reporter().frameDone(
            FrameRecord{f, int(i), count, secondsSince(t0), "-> " + path, {{"out", path}, {"in", p.inputs[i]}}});
        ++run.framesWritten;
    }
    reporter().runFinished(0, nlohmann::json::object());
    return run;
}

} // namespace

ResampleRun runResample(const ResampleJob& a)
{
    const turb::AxisRotation rot = parseRotation(a.rotate);
    turbio::ReadOptions read = a.read;
    read.requireDensity = read.requireVelocity = false;
    const ResamplePlan p = planResample(a, read);
    if (!a.dryRun) return resampleFrames(a, read, p, rot);
    for (size_t i = 0; i < p.seq.frames.size(); ++i)
        printData((p.skips.skip[i] ? "would skip " : "would write ") + p.outputs[i] +
                  (p.skips.skip[i] ? " (written by the same settings)" : " from " + p.inputs[i]));
    return {};
}

} // namespace turb::run
