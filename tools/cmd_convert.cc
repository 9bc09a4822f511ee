// vdbturb convert: a VDB sequence as NanoVDB (GPU renderers), grid for grid, one file per frame.
// Parses the options into a turb::run::ConvertJob and runs it (libturb/src/run/Convert.cc).
#include "Commands.h"
#include "Console.h"

#include <turb/run/Convert.h>

#include <memory>

namespace vdbturb {

namespace {

int runCommand(const turb::run::ConvertJob& a)
{
    turb::run::ConvertJob job = a;
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    turb::run::runConvert(job);
    return kOk;
}

} // namespace

Command convertCommand()
{
    auto args = std::make_shared<turb::run::ConvertJob>();
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
        app->add_flag("--json", "One JSON line per frame and a summary on stdout");
    };
    c.run = [args] { return runCommand(*args); };
    return c;
}

} // namespace vdbturb
