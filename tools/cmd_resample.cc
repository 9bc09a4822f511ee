// vdbturb resample: box-downsample and/or turn a cache by quarter turns (proxies and test inputs).
// Parses the options into a turb::run::ResampleJob and runs it (libturb/src/run/Resample.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"

#include <turb/run/Resample.h>

#include <memory>

namespace vdbturb {

namespace {

// The command line's resample: the job, and the parser its settings text is read from.
struct ResampleArgs : turb::run::ResampleJob
{
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
};

int runCommand(const ResampleArgs& a)
{
    turb::run::ResampleJob job = a;
    job.settings = commandSettingsText(*a.app, {});
    job.dryRun = globals().dryRun;
    turb::run::runResample(job);
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
        app->add_flag("--json", "One JSON line per frame and a summary on stdout");
        args->app = app;
        setting(app->add_flag("--drop-other-grids", args->dropOtherGrids,
                    "Write only density, velocity, temperature and flame, not the file's other grids"),
            "drop-other-grids");
    };
    c.run = [args] { return runCommand(*args); };
    return c;
}

} // namespace vdbturb
