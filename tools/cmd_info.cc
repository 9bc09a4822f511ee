// vdbturb info PATTERN: what a cache holds, from file headers. The tables are the command's data: stdout.
// Parses the options into a turb::run::InfoJob and runs it (libturb/src/run/Info.cc).
#include "Commands.h"
#include "Console.h"

#include <turb/run/Info.h>

#include <memory>

namespace vdbturb {

namespace {

int runCommand(const turb::run::InfoJob& a)
{
    turb::run::InfoJob job = a;
    job.everyTable = globals().verbosity >= 2;
    const turb::run::InfoRun info = turb::run::runInfo(job);
    if (!info.failedLine.empty()) logError(info.failedLine);
    if (!info.validateLine.empty()) printData(info.validateLine, a.json);
    if (a.json) writeData(info.report.dump(1) + "\n");
    return info.framesFailed ? kFailed : kOk;
}

} // namespace

Command infoCommand()
{
    auto args = std::make_shared<turb::run::InfoJob>();
    Command c;
    c.name = "info";
    c.help = "Describe a cache: frames found and missing, grids, lattice and its changes, world bounds, dt and units";
    c.globals = kVerbosity;
    c.setup = [args](CLI::App* app) {
        app->add_option("pattern", args->pattern,
               "Cache: a pattern (####, @, %04d, $F4, ${F4}; quote $ patterns in the shell) or one real file name")
            ->required();
        app->add_option("--frames", args->frames, "Frames to inspect, e.g. 1001-1100x2,1200 (default: all on disk)")
            ->check(frameListCheck());
        app->add_flag("--json", args->json, "Print a JSON report on stdout (the tables then go to stderr)");
        app->add_flag("--all-values", args->allValues, "Read every frame's voxels for value ranges (slower)");
        app->add_flag("--headers-only", args->noValues, "Read no voxels at all (no value ranges)");
        app->add_flag("--validate", args->validate,
            "Also read every frame as the other commands do and say which commands can use it; exit 1 on a bad frame");
        addReadOptions(app, args->read);
        setting(app->add_flag("--checksum", args->checksum,
                    "Fingerprint every grid of every frame, bit for bit, for regression tests"),
            "checksum");
    };
    c.run = [args] { return runCommand(*args); };
    return c;
}

} // namespace vdbturb
