// vdbturb farm: a transfer split into time chunks or space tiles that run as Slurm array tasks, and the join that
// assembles their frames (docs/farm.md). Parses the options into turb::run's farm jobs and runs them
// (libturb/src/run/Farm*.cc).
#include "Commands.h"
#include "Console.h"

#include <turb/run/Farm.h>

#include <array>
#include <memory>

namespace vdbturb {

namespace {

using turb::run::FarmJoinJob;
using turb::run::FarmPlanJob;
using turb::run::FarmSubmitJob;

// The command line's farm: each subcommand's job, the options whose being given matters, and --json.
struct FarmArgs
{
    FarmPlanJob plan;
    FarmSubmitJob submit;
    FarmJoinJob join;
    const CLI::Option* chunksGiven = nullptr;
    const CLI::Option* prerollGiven = nullptr;
    const CLI::Option* overlapGiven = nullptr;
    bool json = false;
};

int runPlan(const FarmArgs& a)
{
    FarmPlanJob job = a.plan;
    job.chunksGiven = a.chunksGiven && a.chunksGiven->count() > 0;
    job.prerollGiven = a.prerollGiven && a.prerollGiven->count() > 0;
    job.overlapGiven = a.overlapGiven && a.overlapGiven->count() > 0;
    if (a.json) job.json = writeData;
    job.dryRun = globals().dryRun;
    turb::run::runFarmPlan(job);
    return kOk;
}

int runSubmit(const FarmArgs& a)
{
    FarmSubmitJob job = a.submit;
    if (a.json) job.json = writeData;
    job.dryRun = globals().dryRun;
    turb::run::runFarmSubmit(job);
    return kOk;
}

int runJoin(const FarmArgs& a)
{
    FarmJoinJob job = a.join;
    job.dryRun = globals().dryRun; // the frames' --json lines follow --json (globals().json), as transfer's
    turb::run::runFarmJoin(job);
    return kOk;
}

void addPlanOptions(CLI::App* plan, FarmArgs& args)
{
    FarmPlanJob& a = args.plan;
    plan->add_option("--target", a.target, "Low-res target cache, as for transfer")->required();
    plan->add_option("--source", a.source, "High-res source cache, as for transfer")->required();
    plan->add_option("--frames", a.frames, "Target frames (empty: all on disk)")->check(frameListCheck());
    plan->add_option("--out", a.out, "Final output pattern, as for transfer")->required();
    plan->add_option("--dir", a.dir, "Farm directory: scripts, plan.json, logs, chunk scratch");
    args.chunksGiven =
        plan->add_option("--chunks", a.chunks, "Number of time chunks (array tasks)")->check(CLI::Range(1, 100000));
    args.prerollGiven = plan->add_option("--preroll", a.preroll, "P: frames computed before a chunk's first kept frame")
                            ->check(CLI::Range(0, 10000));
    args.overlapGiven =
        plan->add_option("--overlap", a.overlap, "O: frames two consecutive chunks share and the join cross-fades")
            ->check(CLI::Range(0, 10000));
    plan->add_option("--tiles", a.tiles,
            "Space tiles instead of time chunks: NX, NXxNY or NXxNYxNZ tiles of the target's box, each a task over "
            "every frame")
        ->check(parsedBy([](const std::string& t) { turb::run::parseTileCounts(t); }, "NX[xNY[xNZ]]"));
    plan->add_option("--halo", a.halo, "Target voxels a tile holds past its core toward each neighbour")
        ->check(CLI::Range(1, 4096));
    setting(
        plan->add_option("--ramp", a.ramp,
                "Output voxels over which the join fades one tile into the next (0: halo x ratio; at most twice that)")
            ->check(CLI::Range(0, 1 << 20)),
        "ramp");
    plan->add_option("--cpus", a.cpus, "CPUs per task (sbatch --cpus-per-task and transfer --threads)")
        ->check(CLI::Range(1, 1024))
        ->group(kGroupRun);
    plan->add_option("--partition", a.partition, "sbatch --partition")->group(kGroupRun);
    plan->add_option("--time", a.time, "sbatch --time per task")->group(kGroupRun);
    plan->add_option("--mem", a.mem, "sbatch --mem per task")->group(kGroupRun);
    setting(plan->add_option("--retries", a.retries, "Times a failed task requeues itself")->check(CLI::Range(0, 100)),
        "retries");
    setting(plan->add_option("--vdbturb", a.exe, "vdbturb binary the tasks run (empty: this one)"), "vdbturb");
    setting(plan->add_option("--name", a.name, "Job name prefix"), "name");
    // Not a setting: the options after -- go to every chunk's transfer as given (farm join takes its read and write
    // options from them).
    plan->add_option("transfer_args", a.transferArgs, "After --: further transfer options, given to every chunk");
}

// The join reads the target and writes the frames as the chunks' transfer did: plan passes those options from the
// ones after --, so here they are settings.
void addJoinOptions(CLI::App* join, FarmArgs& args)
{
    FarmJoinJob& a = args.join;
    join->add_option("--dir", a.dir, "Farm directory written by farm plan");
    join->add_flag("--json", args.json, "One JSON line per frame and a summary on stdout");
    addReadOptions(join, a.targetRead, "target");
    addWriteOptions(join, a.write);
    addFormatOptions(join, a.write);
    addVelocityWriteOptions(join, a.write);
    for (const char* name : {"target-density-grid", "target-vel-grid", "target-fps", "style", "no-clobber", "half",
             "clipping", "velocity-margin", "vel-voxel-scale", "no-velocity", "format", "nanovdb-quant"})
        setting(join->get_option(std::string("--") + name), name);
}

} // namespace

Command farmCommand()
{
    auto args = std::make_shared<FarmArgs>();
    Command c;
    c.name = "farm";
    c.help = "Split a transfer into time chunks or space tiles run as Slurm array tasks, and join them (docs/farm.md)";
    c.globals = kVerbosity | kThreads;
    auto subs = std::make_shared<std::array<CLI::App*, 3>>();
    c.setup = [args, subs](CLI::App* app) {
        FarmArgs& a = *args;
        app->require_subcommand(1);
        app->fallthrough(); // -v, -q, --threads may follow the plan/submit/join word
        CLI::App* plan = app->add_subcommand(
            "plan", "Write sbatch scripts (an array of chunks or tiles + a dependent join) and plan.json");
        addPlanOptions(plan, a);
        plan->add_flag("--json", a.json, "Print the plan (plan.json's content) as one JSON line on stdout");
        CLI::App* submit =
            app->add_subcommand("submit", "Submit a plan with sbatch: the chunk array, then the join with afterok");
        submit->add_option("--dir", a.submit.dir, "Farm directory written by farm plan");
        submit->add_flag("--json", a.json, "Print the job ids as JSON on stdout");
        CLI::App* join = app->add_subcommand(
            "join", "Assemble the chunks' frames (cross-fading the overlaps) or the tiles' into the output");
        addJoinOptions(join, a);
        // Each subcommand has its own two tiers (--help-all, --print-settings, --settings); --threads stays farm's.
        for (CLI::App* sub : {plan, submit, join}) addGlobalOptions(sub, kDryRun);
        (*subs)[0] = plan;
        (*subs)[1] = submit;
        (*subs)[2] = join;
    };
    c.run = [args, subs] {
        if ((*subs)[0]->parsed()) return runPlan(*args);
        if ((*subs)[1]->parsed()) return runSubmit(*args);
        return runJoin(*args);
    };
    return c;
}

} // namespace vdbturb
