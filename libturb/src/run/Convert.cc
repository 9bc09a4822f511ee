// turb::run::runConvert: vdbturb convert's run, VDB files to NanoVDB files (turb/run/Convert.h).
#include <turb/run/Convert.h>

#include "RunHelpers.h"

#include <turb/run/Output.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turbio/NanoVdb.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <memory>
#include <set>

namespace turb::run {

using detail::secondsSince;

namespace {

using ConvertArgs = ConvertJob;

// The frames, their inputs and outputs.
struct ConvertPlan
{
    turbio::Sequence seq;
    turbio::FramePattern outPattern;
    std::vector<std::string> outputs, inputs;
};

// Every frame's headers before the first write (the guarded header walk every command's checks start with): a
// truncated, damaged, newer or foreign file stops the run here, naming it, with nothing written. Grid roles and
// transforms do not matter to a grid-for-grid copy. Damage only a full read finds fails at its frame.
void checkHeaders(const std::vector<std::string>& inputs)
{
    for (const std::string& in : inputs) {
        const turbio::FileInfo fi = turbio::inspectFile(in, false);
        const bool anyHeld = std::any_of(fi.grids.begin(), fi.grids.end(),
            [](const turbio::GridInfo& g) { return turbio::nanoVdbCannotHold(g).empty(); });
        if (!anyHeld)
            throw turb::IoError(in + ": no grid NanoVDB can hold" +
                                (fi.grids.empty() ? std::string(": the file has none")
                                                  : ": grid '" + fi.grids.front().name + "' has " +
                                                        turbio::nanoVdbCannotHold(fi.grids.front())));
    }
}

// Every check before the first frame: the frames, the output pattern and paths, every input's headers.
ConvertPlan planConvert(const ConvertArgs& a)
{
    ConvertPlan p;
    p.seq = turbio::resolveSequence(a.in, a.frames);
    p.outPattern = turbio::FramePattern::parse(a.out);
    if (p.seq.frames.size() > 1 && !p.outPattern.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(p.seq.frames.size()) + " frames are requested");
    for (int f : p.seq.frames) {
        p.outputs.push_back(p.outPattern.format(f));
        p.inputs.push_back(p.seq.path(f));
    }
    // Frames asked for by --frames must exist; without it, the frames on disk are converted and a gap is said.
    if (!p.seq.missing.empty()) {
        const std::string what = p.seq.pattern.str() +
                                 (p.seq.missing.size() == 1 ? ": missing frame " : ": missing frames ") +
                                 turbio::formatFrameList(p.seq.missing);
        if (!a.frames.empty()) throw turb::IoError(what);
        logWarning(what + "; converting the " + std::to_string(p.seq.frames.size()) + " frames on disk");
    }
    checkOutputs(p.outputs, p.inputs, a.nano.noClobber, false); // first: an --out naming the inputs says so
    if (!turbio::isNanoVdbPath(a.out))
        throw UsageError("--out '" + a.out +
                         "' must end in .nvdb: convert writes NanoVDB (transfer and resample write either format)");
    checkHeaders(p.inputs);
    return p;
}

// One frame converted and reported; each grid left out is warned about once per run (`warned`).
void convertFrame(const ConvertArgs& a, const ConvertPlan& p, size_t i, std::set<std::string>& warned)
{
    const int f = p.seq.frames[i];
    const int count = int(p.seq.frames.size());
    if (reporter().frameProgress(int(i), count, f)->cancelled()) throw turb::Cancelled();
    const auto t0 = std::chrono::steady_clock::now();
    turbio::ensureParentDirectory(p.outputs[i]);
    turbio::NanoConvertReport r;
    turb::withThreads(a.threads, [&] { r = turbio::convertToNanoVdb(p.inputs[i], p.outputs[i], a.nano); });
    for (const std::string& s : r.skipped)
        if (warned.insert(s.substr(0, s.find(" ("))).second)
            logWarning(p.inputs[i] + ": grid " + s + " left out: NanoVDB cannot hold it");
    if (i == 0) {
        std::string list;
        for (const auto& g : r.grids) list += (list.empty() ? "" : ", ") + g;
        logVerbose(p.outputs[i] + ": " + list);
    }
    reporter().frameDone(FrameRecord{f, int(i), count, secondsSince(t0),
        "-> " + p.outputs[i] + " (" + std::to_string(r.grids.size()) + " grid" + (r.grids.size() == 1 ? "" : "s") +
            ", " + turbio::formatBytes(double(r.bytes)) + ")",
        {{"out", p.outputs[i]}, {"in", p.inputs[i]}, {"bytes", r.bytes}, {"grids", r.grids}, {"skipped", r.skipped}}});
}

} // namespace

ConvertRun runConvert(const ConvertJob& a)
{
    const ConvertPlan p = planConvert(a);
    ConvertRun run;
    if (a.dryRun) {
        for (size_t i = 0; i < p.seq.frames.size(); ++i)
            printData("would write " + p.outputs[i] + " from " + p.inputs[i] + " (NanoVDB, float grids " +
                      turbio::quantizationName(a.nano.quantization) + ")");
        return run;
    }
    lockOutputFrames(p.outPattern, p.seq.frames);
    reporter().runStarted("convert");
    std::set<std::string> warned;
    for (size_t i = 0; i < p.seq.frames.size(); ++i, ++run.framesWritten) convertFrame(a, p, i, warned);
    reporter().runFinished(0, nlohmann::json::object());
    return run;
}

} // namespace turb::run
