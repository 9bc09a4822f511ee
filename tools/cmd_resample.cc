// vdbturb resample: box-downsample and/or turn a cache by quarter turns (proxies and test inputs).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"

#include <turb/Metadata.h>
#include <turb/Error.h>
#include <turb/Reorient.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>
#include <memory>
#include <optional>

namespace vdbturb {

namespace {

struct ResampleArgs
{
    std::string in, out, frames;
    int down = 1;
    std::string rotate;
    bool dropOtherGrids = false;
    bool skipExisting = false;
    bool json = false;
    turbio::ReadOptions read;
    turbio::WriteOptions write;
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
};

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
turbio::OtherGrids carriedGrids(
    const ResampleArgs& a, const std::string& path, const turb::Frame& frame, const turb::AxisRotation& rot, bool first)
{
    turbio::OtherGrids others = turbio::OtherGrids::read(path, a.read, frame.lattice());
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

int runResample(ResampleArgs& a)
{
    const turb::AxisRotation rot = parseRotation(a.rotate);
    const turbio::Sequence seq = turbio::resolveSequence(a.in, a.frames);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    checkOutputFormat(a.write, a.out, a.skipExisting ? "--skip-existing" : "");
    if (seq.frames.size() > 1 && !outPattern.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token but several frames are requested");
    a.read.requireDensity = a.read.requireVelocity = false;
    // Each frame is resampled on its own, so a lattice change within the sequence is carried through.
    const turbio::SequenceScan scan = checkInput("resample", "cache", seq, seq.frames, a.read, LatticePolicy::Report);
    reportTiming("cache", scan, true); // the output records dt (vdbturb_dt)
    std::vector<std::string> outputs, inputs;
    for (int f : seq.frames) {
        outputs.push_back(outPattern.format(f));
        inputs.push_back(seq.path(f));
    }
    checkOutputs(outputs, inputs, a.write.noClobber, a.skipExisting);
    // Each frame is made from its input alone, so a frame written by the same settings is whole and final.
    const std::string settings = commandSettingsText(*a.app, {seq.pattern.str()});
    const SkipPlan plan = planSkips(outputs, seq.frames, "resample", settings, a.skipExisting);
    if (globals().dryRun) {
        for (size_t i = 0; i < seq.frames.size(); ++i)
            printData((plan.skip[i] ? "would skip " : "would write ") + outputs[i] +
                      (plan.skip[i] ? " (written by the same settings)" : " from " + inputs[i]));
        return kOk;
    }
    lockOutputFrames(outPattern, plan.writing);
    RunReport report("resample", a.json);
    bool warnedClipping = false;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
        const int f = seq.frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        if (plan.skip[i]) {
            report.frameDone(f, int(i), int(seq.frames.size()), secondsSince(t0),
                "skipped: " + outputs[i] + " was written by the same settings",
                {{"out", outputs[i]}, {"in", inputs[i]}, {"skipped", true}});
            continue;
        }
        turb::Frame frame = turbio::readFrame(seq.path(f), f, a.read);
        std::optional<turbio::OtherGrids> others;
        if (!a.dropOtherGrids) others = carriedGrids(a, seq.path(f), frame, rot, i == 0);
        if (a.down > 1) frame = turb::downsampleFrame(frame, a.down);
        if (!rot.isIdentity()) frame = turb::reorientFrame(frame, rot);
        rescaleIndexMetadata(frame.metadata, a.down, !rot.isIdentity());
        frame.metadata[turb::meta::kCommand] = "resample";
        frame.metadata[turb::meta::kSettings] = settings;
        const std::string path = outPattern.format(f);
        turbio::ensureParentDirectory(path);
        warnIfClippedAway(frame, a.write, path, warnedClipping);
        turbio::writeFrame(path, frame, a.write, others ? &*others : nullptr);
        report.frameDone(
            f, int(i), int(seq.frames.size()), secondsSince(t0), "-> " + path, {{"out", path}, {"in", inputs[i]}});
    }
    report.finish();
    return kOk;
}

} // namespace

Command resampleCommand()
{
    auto args = std::make_shared<ResampleArgs>();
    Command c;
    c.globals = kVerbosity | kDryRun;
    c.name = "resample";
    c.help = "Box-downsample a cache by an integer factor and/or turn it by quarter turns (exact)";
    c.setup = [args](CLI::App* app) {
        app->add_option("input", args->in, "Cache: a pattern or one real file name")->required();
        app->add_option("--frames", args->frames, "Frames, e.g. 1-30 (default: all on disk)")->check(frameListCheck());
        app->add_option("--down", args->down, "Mean over NxNxN blocks onto an N times coarser lattice")
            ->check(CLI::Range(1, 64));
        app->add_option(
            "--rotate", args->rotate, "AXIS:TURNS quarter turns about x, y or z (e.g. y:1), grids and vectors");
        addReadOptions(app, args->read);
        app->add_option("--out", args->out, "Output pattern, e.g. proxy/plume.####.vdb (.nvdb: NanoVDB)")
            ->required()
            ->group(kGroupOutput);
        addWriteOptions(app, args->write);
        addFormatOptions(app, args->write);
        // Rarely wanted: a proxy normally keeps Blender's flags, colours and level sets (docs/io.md).
        app->add_flag("--skip-existing", args->skipExisting,
               "Skip the frames already written by the same settings (farm wrappers' retries); a frame written "
               "otherwise is refused (exit 1)")
            ->group(kGroupOutput);
        app->add_flag("--json", args->json, "One JSON line per frame and a summary on stdout");
        args->app = app;
        setting(app->add_flag("--drop-other-grids", args->dropOtherGrids,
                    "Write only density, velocity, temperature and flame, not the file's other grids"),
            "drop-other-grids");
    };
    c.run = [args] { return runResample(*args); };
    return c;
}

} // namespace vdbturb
