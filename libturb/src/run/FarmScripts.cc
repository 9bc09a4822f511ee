// farm plan's scripts and plan.json (FarmShared.h): the command each task runs, the array and join sbatch scripts,
// and the same plan as JSON.
#include "FarmShared.h"

#include <turb/run/Output.h>

#include <turb/Error.h>
#include <turbio/Sequence.h>

#include <cctype>
#include <cstring>

namespace turb::run::farm {

namespace {

// The transfer's options the join needs too: the target's read options (it reads u_t as the chunks did) and the
// output options (blended frames are written like the chunks' own).
std::vector<std::string> joinArgs(const std::vector<std::string>& args)
{
    std::vector<std::string> out;
    for (size_t i = 0; i < args.size(); ++i)
        if (args[i].rfind("--target-", 0) == 0 || args[i].rfind("--style", 0) == 0 ||
            args[i].rfind("--velocity-margin", 0) == 0 || args[i].rfind("--clipping", 0) == 0 ||
            args[i].rfind("--vel-voxel-scale", 0) == 0 || isFormatOption(args[i])) {
            out.push_back(args[i]);
            if (args[i].find('=') == std::string::npos && i + 1 < args.size()) out.push_back(args[++i]);
        } else if (args[i] == "--half" || args[i] == "--full-float" || args[i] == "--no-velocity" ||
                   args[i] == "--no-clobber") {
            out.push_back(args[i]);
        }
    return out;
}

// What plan sets itself is refused after --: a chunk's frames, paths and threads are the plan's.

std::vector<int> boxArray(const turb::CoordBBox& b)
{
    return {b.min().x(), b.min().y(), b.min().z(), b.max().x(), b.max().y(), b.max().z()};
}

// The transfer a chunk's or tile's array task runs: its frames (with the pre-roll), resumable, and the options given
// after --. Task k is chunk k, or tile k over every frame.
std::vector<std::string> taskCommand(const FarmPlanJob& a, const Plan& p, size_t k)
{
    const turb::TimeChunk& c = p.chunks[p.tiled ? 0 : k];
    std::vector<std::string> argv = {p.exe, "transfer", "--target", p.target, "--source", p.source, "--out",
        chunkPattern(p.dir, int(k), a.out, p.word()), "--frames", turbio::formatFrameList(p.sub(c.computeBegin, c.end)),
        "--resume", "--threads", std::to_string(a.cpus)};
    if (p.tiled) {
        // A tile holds its core and halo on every frame: one box, so that the join finds it on every frame. The
        // source is held as an untiled run holds it (its smoke and margin): every tile reads the same source.
        argv.insert(argv.end(), {"--tile-box", turb::formatTileBox(p.tiles.tiles[k].held)});
    } else {
        // Every chunk holds the target's whole domain: held over the smoke of its own frames only, chunks would
        // get different output boxes and the join could not blend them.
        argv.insert(argv.end(), {"--target-no-crop", "--source-no-crop"});
    }
    for (size_t i = 0; i < a.transferArgs.size(); ++i) {
        if (isFormatOption(a.transferArgs[i])) { // the join's (chunkPattern)
            if (a.transferArgs[i].find('=') == std::string::npos) ++i;
            continue;
        }
        argv.push_back(a.transferArgs[i]);
    }
    return argv;
}

std::vector<std::string> joinCommandLine(const FarmPlanJob& a, const Plan& p)
{
    std::vector<std::string> argv = {p.exe, "farm", "join", "--dir", p.dir, "--threads", std::to_string(a.cpus)};
    for (const auto& r : joinArgs(a.transferArgs)) argv.push_back(r);
    return argv;
}

nlohmann::json taskJson(const FarmPlanJob& a, const Plan& p, size_t k)
{
    nlohmann::json t;
    const turb::TimeChunk& c = p.chunks[p.tiled ? 0 : k];
    t["name"] = std::string(p.word()) + std::to_string(k);
    t["array_index"] = int(k);
    t["frames_computed"] = turbio::formatFrameList(p.sub(c.computeBegin, c.end));
    t["frames_preroll"] = turbio::formatFrameList(p.sub(c.computeBegin, c.keepBegin));
    t["frames_kept"] = turbio::formatFrameList(p.sub(c.keepBegin, c.end));
    if (p.tiled) {
        t["tile_core"] = boxArray(p.tiles.tiles[k].core);
        t["tile_held"] = boxArray(p.tiles.tiles[k].held);
    }
    t["out"] = chunkPattern(p.dir, int(k), a.out, p.word());
    t["log"] = p.dir + "/logs/" + p.word() + "_" + std::to_string(k) + ".log";
    t["command"] = taskCommand(a, p, k);
    t["depends_on"] = nlohmann::json::array();
    t["retry_exit_codes"] = {75, 130, 137, 143};
    return t;
}

nlohmann::json joinTask(const FarmPlanJob& a, const Plan& p)
{
    nlohmann::json join;
    join["name"] = "join";
    join["frames"] = turbio::formatFrameList(p.frames);
    join["out"] = p.out;
    join["log"] = p.dir + "/logs/join.log";
    join["command"] = joinCommandLine(a, p);
    nlohmann::json deps = nlohmann::json::array();
    for (size_t k = 0; k < p.taskCount(); ++k) deps.push_back(p.word() + std::to_string(k));
    join["depends_on"] = deps;
    return join;
}

} // namespace

nlohmann::json planJson(const FarmPlanJob& a, const Plan& p)
{
    nlohmann::json plan;
    plan["version"] = 1;
    plan["kind"] = p.tiled ? "space_tiles" : "time_chunks";
    plan["dir"] = p.dir;
    plan["vdbturb"] = p.exe;
    plan["target"] = p.target;
    plan["source"] = p.source;
    plan["out"] = p.out;
    plan["frames"] = turbio::formatFrameList(p.frames);
    plan["chunks"] = p.tiled ? 1 : a.chunks;
    plan["preroll"] = p.tiled ? 0 : a.preroll;
    plan["overlap"] = p.tiled ? 0 : a.overlap;
    if (p.tiled)
        plan["tiles"] = {{"counts", {p.tiles.counts.x(), p.tiles.counts.y(), p.tiles.counts.z()}},
            {"box", boxArray(p.tiles.box)}, {"halo", p.tiles.halo}, {"ratio", p.ratio}, {"ramp", p.ramp},
            {"borders", turb::formatTileBorders(turb::tileBorders(p.tiles, p.ratio))}};
    plan["transfer_args"] = a.transferArgs;
    plan["exit_codes"] = {{"0", "done"},
        {"1", "a failure a retry cannot fix (bad input, a resume with other settings): do not retry"},
        {"2", "usage error: do not retry"},
        {"75",
            "worth a retry (disk full, a file-size limit, out of memory): retry, resuming from the last whole frame"},
        {"130", "interrupted: retry"}, {"137", "killed (SIGKILL: OOM killer, kill -9): retry"},
        {"143", "terminated (SIGTERM): retry"}};
    nlohmann::json tasks = nlohmann::json::array();
    for (size_t k = 0; k < p.taskCount(); ++k) tasks.push_back(taskJson(a, p, k));
    tasks.push_back(joinTask(a, p));
    plan["tasks"] = tasks;
    nlohmann::json overlaps = nlohmann::json::array();
    for (size_t k = 0; k + 1 < p.chunks.size(); ++k)
        for (int j = 0; j < a.overlap; ++j) {
            const turb::CrossFade w = turb::crossFade(j, a.overlap);
            overlaps.push_back({{"frame", p.frames[p.chunks[k + 1].keepBegin + size_t(j)]}, {"a", int(k)},
                {"b", int(k + 1)}, {"t", w.t}, {"detail_a", w.detailA}, {"detail_b", w.detailB},
                {"density_a", w.densityA}, {"density_b", w.densityB}});
        }
    plan["overlaps"] = overlaps;
    plan["slurm"] = {{std::string(p.word()) + "s_script", p.dir + "/" + p.word() + "s.sbatch"},
        {"join_script", p.dir + "/join.sbatch"}};
    return plan;
}

namespace {

// An #SBATCH line is read by sbatch, not a shell, and ends at the line's end: a value with a newline would add lines
// (a command in the script), one with spaces or quotes is split or unquoted by sbatch's own rules. Names, partitions,
// times and memory sizes never need either.
void checkSbatchValue(const std::string& flag, const std::string& value)
{
    for (const char c : value)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || std::strchr("._:,+=@%-", c)))
            throw UsageError(flag + " '" + value + "': only letters, digits and ._:,+=@%- may go into an #SBATCH line");
}

// The log path as an #SBATCH directive when sbatch reads it back as written (no whitespace, quotes or backslash);
// otherwise farm submit gives --output on sbatch's command line, and the script says so.
std::string sbatchOutput(const std::string& path)
{
    if (path.find_first_of(" \t\n\r\"'\\") == std::string::npos) return "#SBATCH --output=" + path + "\n";
    // Not the path itself: a comment ends at a newline a hostile name may hold, and the shell runs the rest.
    return "# --output is given by vdbturb farm submit: an #SBATCH line cannot hold this directory's name\n";
}

std::string sbatchResources(const FarmPlanJob& a)
{
    std::string common = "#SBATCH --cpus-per-task=" + std::to_string(a.cpus) + "\n";
    if (!a.partition.empty()) common += "#SBATCH --partition=" + a.partition + "\n";
    if (!a.time.empty()) common += "#SBATCH --time=" + a.time + "\n";
    if (!a.mem.empty()) common += "#SBATCH --mem=" + a.mem + "\n";
    return common;
}

} // namespace

void checkSbatchValues(const FarmPlanJob& a)
{
    checkSbatchValue("--name", a.name);
    checkSbatchValue("--partition", a.partition);
    checkSbatchValue("--time", a.time);
    checkSbatchValue("--mem", a.mem);
}

// A task that failed in a way a retry can fix (exit 75), was interrupted (130) or killed (137, 143) requeues itself
// up to --retries times;
// transfer --resume then continues from the last whole frame in the chunk's scratch directory. A usage error (2)
// would fail again and is not retried. Slurm's own --requeue covers node failure and preemption.
std::string tasksScript(const FarmPlanJob& a, const Plan& p)
{
    const std::string w = p.word();
    std::string cases;
    for (size_t k = 0; k < p.taskCount(); ++k)
        cases += "  " + std::to_string(k) + ") set -- " + joinCommand(taskCommand(a, p, k)) + " ;;\n";
    return "#!/bin/sh\n"
           "# Written by vdbturb farm plan: one array task per " +
           std::string(p.tiled ? "space tile" : "time chunk") +
           " (plan.json has the same plan as JSON).\n"
           "#SBATCH --job-name=" +
           a.name + "-" + w +
           "s\n"
           "#SBATCH --array=0-" +
           std::to_string(p.taskCount() - 1) +
           "\n"
           "#SBATCH --requeue\n"
           "#SBATCH --open-mode=append\n" +
           sbatchOutput(p.dir + "/logs/" + w + "_%a.log") + sbatchResources(a) + "case \"$SLURM_ARRAY_TASK_ID\" in\n" +
           cases + "  *) echo \"farm: no " + w +
           " $SLURM_ARRAY_TASK_ID\" >&2; exit 2 ;;\n"
           "esac\n"
           "echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID start (restart ${SLURM_RESTART_COUNT:-0}) on $(hostname)\" >&2\n"
           "\"$@\"\n"
           "rc=$?\n"
           "echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID exit $rc\" >&2\n"
           "# Only what a retry can fix requeues: vdbturb's 75 (disk full, a file-size limit, out of memory), an\n"
           "# interruption (130) or a kill (137 SIGKILL: the OOM killer, kill -9; 143 SIGTERM). 1 (bad input, a "
           "resume\n"
           "# with other settings) and 2 (usage) would fail again.\n"
           "case $rc in\n"
           "  75|130|137|143) ;;\n"
           "  *) exit $rc ;;\n"
           "esac\n"
           "# A stop by Slurm itself (scancel, scontrol requeue, the time limit) signals this shell too, which then\n"
           "# ends with vdbturb; should it outlive it, the job is COMPLETING: a cancel must stick, and Slurm requeues\n"
           "# by itself what it requeues. Only a task that is still RUNNING (vdbturb killed alone: the OOM killer,\n"
           "# kill -9) requeues itself.\n"
           "state=$(squeue -h -j \"${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\" -o %T 2>/dev/null)\n"
           "if [ \"$state\" != RUNNING ]; then\n"
           "  echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID not requeued by its script: the job is ${state:-unknown to squeue} (stopped by "
           "Slurm)\" >&2\n"
           "elif [ \"${SLURM_RESTART_COUNT:-0}\" -lt " +
           std::to_string(a.retries) +
           " ]; then\n"
           "  echo \"farm: " +
           w +
           " $SLURM_ARRAY_TASK_ID requeued; it resumes from its last whole frame\" >&2\n"
           "  scontrol requeue \"${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\"\n"
           "  sleep 30 # the requeue ends this job; do not let it finish as failed first\n"
           "fi\n"
           "exit $rc\n";
}

std::string joinScript(const FarmPlanJob& a, const Plan& p)
{
    return "#!/bin/sh\n"
           "# Written by vdbturb farm plan: assembles the " +
           std::string(
               p.tiled ? "tiles (after every tile" : "chunks and cross-fades their overlaps (after every chunk") +
           " succeeded).\n"
           "#SBATCH --job-name=" +
           a.name + "-join\n" + sbatchOutput(p.dir + "/logs/join.log") + "#SBATCH --open-mode=append\n" +
           sbatchResources(a) + "exec " + joinCommand(joinCommandLine(a, p)) + "\n";
}

} // namespace turb::run::farm
