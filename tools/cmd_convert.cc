// vdbturb convert: a VDB sequence as NanoVDB (GPU renderers), grid for grid, one file per frame.
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"

#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turbio/NanoVdb.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <set>

namespace vdbturb {

namespace {

struct ConvertArgs
{
    std::string in, out, frames;
    bool json = false;
    turbio::NanoConvertOptions nano;
};

int runConvert(ConvertArgs& a)
{
    const turbio::Sequence seq = turbio::resolveSequence(a.in, a.frames);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    if (seq.frames.size() > 1 && !outPattern.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(seq.frames.size()) + " frames are requested");
    std::vector<std::string> outputs, inputs;
    for (int f : seq.frames) {
        outputs.push_back(outPattern.format(f));
        inputs.push_back(seq.path(f));
    }
    // Frames asked for by --frames must exist; without it, the frames on disk are converted and a gap is said.
    if (!seq.missing.empty()) {
        const std::string what = seq.pattern.str() +
                                 (seq.missing.size() == 1 ? ": missing frame " : ": missing frames ") +
                                 turbio::formatFrameList(seq.missing);
        if (!a.frames.empty()) throw turb::IoError(what);
        logWarning(what + "; converting the " + std::to_string(seq.frames.size()) + " frames on disk");
    }
    checkOutputs(outputs, inputs, a.nano.noClobber, false); // first: an --out naming the inputs says so
    if (!turbio::isNanoVdbPath(a.out))
        throw UsageError("--out '" + a.out +
                         "' must end in .nvdb: convert writes NanoVDB (transfer and resample write either format)");
    // Every frame's headers before the first write (the guarded header walk every command's checks start with): a
    // truncated, damaged, newer or foreign file stops the run here, naming it, with nothing written. Grid roles and
    // transforms do not matter to a grid-for-grid copy. Damage only a full read finds fails at its frame.
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
    if (globals().dryRun) {
        for (size_t i = 0; i < seq.frames.size(); ++i)
            printData("would write " + outputs[i] + " from " + inputs[i] + " (NanoVDB, float grids " +
                          turbio::quantizationName(a.nano.quantization) + ")",
                a.json);
        return kOk;
    }
    lockOutputFrames(outPattern, seq.frames);
    RunReport report("convert", a.json);
    std::set<std::string> warned;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
        if (interruptRequested()) throw turb::Cancelled();
        const int f = seq.frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        turbio::ensureParentDirectory(outputs[i]);
        turbio::NanoConvertReport r;
        turb::withThreads(globals().threads, [&] { r = turbio::convertToNanoVdb(inputs[i], outputs[i], a.nano); });
        for (const std::string& s : r.skipped)
            if (warned.insert(s.substr(0, s.find(" ("))).second)
                logWarning(inputs[i] + ": grid " + s + " left out: NanoVDB cannot hold it");
        if (i == 0) {
            std::string list;
            for (const auto& g : r.grids) list += (list.empty() ? "" : ", ") + g;
            logVerbose(outputs[i] + ": " + list);
        }
        report.frameDone(f, int(i), int(seq.frames.size()), secondsSince(t0),
            "-> " + outputs[i] + " (" + std::to_string(r.grids.size()) + " grid" + (r.grids.size() == 1 ? "" : "s") +
                ", " + turbio::formatBytes(double(r.bytes)) + ")",
            {{"out", outputs[i]}, {"in", inputs[i]}, {"bytes", r.bytes}, {"grids", r.grids}, {"skipped", r.skipped}});
    }
    report.finish();
    return kOk;
}

} // namespace

Command convertCommand()
{
    auto args = std::make_shared<ConvertArgs>();
    Command c;
    c.globals = kVerbosity | kThreads | kDryRun;
    c.name = "convert";
    c.help = "Turn a VDB sequence into NanoVDB (.nvdb, as GPU renderers load it), grid for grid (docs/nanovdb.md)";
    c.setup = [args](CLI::App* app) {
        app->add_option("input", args->in, "VDB cache: a pattern or one real file name")->required();
        app->add_option("--frames", args->frames, "Frames, e.g. 1001-1100x2 (default: all on disk)")
            ->check(frameListCheck());
        app->add_option("--out", args->out, "Output pattern ending in .nvdb, e.g. gpu/smoke.####.nvdb")
            ->required()
            ->group(kGroupOutput);
        addEnum<turbio::NanoQuantization>(app, "--nanovdb-quant", args->nano.quantization,
            {{"float", turbio::NanoQuantization::Float}, {"fp16", turbio::NanoQuantization::Fp16},
                {"fp8", turbio::NanoQuantization::Fp8}},
            "Float grids other than level sets: float (exact), fp16 or fp8 (16 or 8 bits a voxel, each 8^3 leaf "
            "quantised over its range: off by at most range/131070 or range/510); vectors stay Vec3f")
            ->group(kGroupOutput);
        app->add_flag("--no-clobber", args->nano.noClobber, "Never replace an existing output file")
            ->group(kGroupOutput);
        app->add_flag("--json", args->json, "One JSON line per frame and a summary on stdout");
    };
    c.run = [args] { return runConvert(*args); };
    return c;
}

} // namespace vdbturb
