/// @file Farm.h
/// @brief `vdbturb farm` as library calls (turb::run, the entry points' layer): a transfer split into time chunks or
///        space tiles run as Slurm array tasks (plan, submit), and the join that assembles their frames (docs/farm.md).
///
/// @code
/// turb::run::FarmPlanJob plan;
/// plan.target = "lowres/smoke.####.vdb";
/// plan.source = "hires/swirl.####.vdb";
/// plan.out = "up/turb.####.vdb";
/// plan.chunks = 10;
/// turb::run::runFarmPlan(plan); // writes farm/plan.json, chunks.sbatch, join.sbatch
/// turb::run::FarmSubmitJob submit;
/// turb::run::runFarmSubmit(submit); // sbatch: the chunk array, then the join after it
/// // ... or, once every chunk's task ran elsewhere:
/// turb::run::FarmJoinJob join;
/// turb::run::runFarmJoin(join);
/// @endcode
///
/// The scheduling is Slurm's: the plan writes sbatch scripts and plan.json (the same plan, for other schedulers), the
/// submit calls sbatch. The chunk and tile math and the blends are libturb's (turb/Farm.h). What the calls have to
/// say goes to turb::run::reporter(); the join's frames are reported as a run ("farm join").
#pragma once

#include <turb/Field.h>
#include <turb/run/Output.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace turb::run {

/// Where a call's JSON document goes, one line with its newline (the CLI's stdout with --json).
using JsonSink = std::function<void(const std::string& line)>;

/// Defaults from the measurements in docs/farm.md (Blender pair and paper configuration): the cross-fade's added
/// change per frame falls as 1/(O+1), and O = 20 keeps the seam frames' tcoh within 0.94-1.06x (paper) and 0.95-1.11x
/// (Blender) of the sequential run's same frames, where O = 10 gave up to 1.32x. P + O = 24 frames of history settle
/// the later chunk before it goes on alone.
inline constexpr int kFarmDefaultPreroll = 4;
inline constexpr int kFarmDefaultOverlap = 20;
/// Space tiles: the target read's default crop margin (patch radius, advection reach and seam band, io.md); the
/// measurements behind it are in docs/farm.md.
inline constexpr int kFarmDefaultHalo = 8;

/// `vdbturb farm plan`: the CLI's options as plain values (same names, same defaults).
struct FarmPlanJob
{
    std::string dir = "farm";          ///< farm directory: scripts, plan.json, logs, the tasks' scratch frames
    std::string target, source, out;   ///< as for transfer; out needs a frame token (####)
    std::string frames;                ///< target frames ("1001-1100x2"); empty = every frame on disk
    int chunks = 2;                    ///< time chunks (array tasks), >= 1
    int preroll = kFarmDefaultPreroll; ///< P: frames computed before a chunk's first kept frame, >= 0
    int overlap = kFarmDefaultOverlap; ///< O: frames two consecutive chunks share and the join cross-fades, >= 0
    /// Whether chunks, preroll, overlap were given: a given --overlap that does not fit the shot is refused, the
    /// default shrinks to what fits; --preroll/--overlap with tiles are warned about, --chunks > 1 refused.
    bool chunksGiven = false, prerollGiven = false, overlapGiven = false;
    std::string tiles;           ///< "NX[xNY[xNZ]]": space tiles instead of time chunks (parseTileCounts); "" = chunks
    int halo = kFarmDefaultHalo; ///< target voxels a tile holds past its core toward each neighbour, >= 1
    int ramp = 0;                ///< output voxels of the join's ramp across a tile border; 0 = halo x ratio
    int cpus = 2;                ///< CPUs per task: sbatch --cpus-per-task and the tasks' --threads
    int retries = 2;             ///< times a failed task requeues itself
    std::string exe;             ///< vdbturb binary the tasks run; "" = the running executable
    std::string partition, time, mem; ///< sbatch --partition, --time, --mem per task; "" = not given
    std::string name = "vdbturb";     ///< job name prefix
    /// Further transfer options, given to every task (the CLI's options after --); the join takes the target's read
    /// options and the output options from them.
    std::vector<std::string> transferArgs;
    JsonSink json;       ///< given: receives plan.json's content as one line, after the plan's lines
    bool dryRun = false; ///< check and print the plan, write nothing
};

/// What a plan made.
struct FarmPlanRun
{
    nlohmann::json plan; ///< plan.json's content
    std::string dir;     ///< the farm directory, absolute
};

/// Plans `job` and writes DIR/plan.json, DIR/chunks.sbatch (tiles.sbatch) and DIR/join.sbatch, saying what it planned
/// (printData). Throws turb::ValueError (options that contradict each other, options after -- the plan sets itself,
/// a split the shot or box cannot hold, an --out that is an input or inside the scratch), UsageError (a value an
/// #SBATCH line cannot hold, an --out without a frame token, an --overlap the chunks cannot hold) and turb::IoError
/// (missing or unreadable target or source frames).
FarmPlanRun runFarmPlan(const FarmPlanJob& job);

/// "2", "2x2", "2x1x3": tiles per axis, missing axes 1. Throws turb::ValueError naming --tiles otherwise.
turb::Coord parseTileCounts(const std::string& text);

/// `vdbturb farm submit`.
struct FarmSubmitJob
{
    std::string dir = "farm"; ///< farm directory written by runFarmPlan
    JsonSink json;            ///< given: receives the job ids as one JSON line (the line for people goes to stderr)
    bool dryRun = false;      ///< say the sbatch calls, run none
};

/// The jobs sbatch queued.
struct FarmSubmitRun
{
    std::string tasksJob, joinJob; ///< Slurm job ids ("" in a dry run)
};

/// Submits the plan in `job.dir` with sbatch: the task array, then the join with afterok; records the ids in
/// DIR/submitted.json. Throws turb::IoError (no plan, sbatch failed: its output in the message).
FarmSubmitRun runFarmSubmit(const FarmSubmitJob& job);

/// `vdbturb farm join`: the options the chunks' transfer read the target and wrote its frames with.
struct FarmJoinJob
{
    std::string dir = "farm"; ///< farm directory written by runFarmPlan, its tasks complete
    turbio::ReadOptions targetRead;
    turbio::WriteOptions write = upResWriteDefaults(); ///< as transfer writes its chunks
    bool dryRun = false; ///< check that every task's frames are present and read, write nothing
};

/// What a join wrote.
struct FarmJoinRun
{
    int framesWritten = 0;
};

/// Assembles the tasks' frames into the plan's output: a chunk's own frames are copied (converted for a NanoVDB
/// output), the overlaps cross-faded; the tiles' frames are joined over their ramps. Checks every task's frames
/// before writing any. Throws turb::IoError (no plan, a task incomplete or a frame damaged: naming the sbatch line that
/// reruns it; an unreadable target frame), turb::ValueError (a plan.json with a bad field), nlohmann::json's errors (a
/// plan.json that does not parse) and UsageError (output options that contradict each other).
FarmJoinRun runFarmJoin(const FarmJoinJob& job);

} // namespace turb::run
