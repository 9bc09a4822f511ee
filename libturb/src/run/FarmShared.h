// What farm plan, submit and join share (turb/run/Farm.h): the split a plan and its join agree on, the tasks'
// scratch paths, and the shell's and the farm directory's small file chores.
#pragma once

#include <turb/Farm.h>
#include <turb/run/Farm.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace turb::run::farm {

/// The split a plan and its join share: time chunks, or space tiles (each task then covers every frame). Paths are
/// absolute: the tasks run elsewhere.
struct Split
{
    std::string dir, out;
    std::vector<int> frames;
    std::vector<turb::TimeChunk> chunks; ///< time chunks (one chunk covering every frame when tiled)
    bool tiled = false;
    turb::TilePlan tiles; ///< space tiles (tiled)
    int ratio = 0;        ///< the transfer's ratio (tiled)
    int ramp = 0;         ///< output voxels (tiled)
    const char* word() const { return tiled ? "tile" : "chunk"; }
    size_t taskCount() const { return tiled ? tiles.tiles.size() : chunks.size(); }
};

/// `s` as one shell word: as it is when it holds only characters no shell treats specially, else single-quoted.
std::string shellQuote(const std::string& s);
/// `argv` as one shell command line.
std::string joinCommand(const std::vector<std::string>& argv);
/// `p` absolute and normalised (against the working directory).
std::string absolute(const std::string& p);
/// The whole text of `path`. Throws turb::IoError when it cannot be read.
std::string readText(const std::string& path);
/// Writes `text` to `path` atomically; `executable` adds the execute bits.
void writeText(const std::string& path, const std::string& text, bool executable = false);

/// Task k's scratch frame pattern: every frame it computes, pre-roll included, so --resume can continue a killed
/// task. Always VDB: a NanoVDB output (.nvdb) is made by the join, from frames that can resume and that it can read.
std::string chunkPattern(const std::string& dir, int k, const std::string& out, const char* word = "chunk");

/// Whether `arg` (an option after --, "--name" or "--name=value") sets the final file's format (--format,
/// --nanovdb-quant): the join's, never the tasks' (they write VDB).
bool isFormatOption(const std::string& arg);

/// A plan: the split, the binary the tasks run and the inputs they read.
struct Plan : Split
{
    std::string exe, target, source;
    std::vector<int> sub(size_t b, size_t e) const
    {
        return std::vector<int>(frames.begin() + long(b), frames.begin() + long(e));
    }
};

/// Refuses (UsageError) a job name, partition, time or memory size an #SBATCH line cannot hold.
void checkSbatchValues(const FarmPlanJob& job);
/// plan.json: the same plan as the scripts, for tools that schedule otherwise, and for the join. `job` as planned
/// (its overlap settled).
nlohmann::json planJson(const FarmPlanJob& job, const Plan& p);
/// The array of tasks: one per chunk or tile, each requeueing itself on what a retry can fix.
std::string tasksScript(const FarmPlanJob& job, const Plan& p);
/// The join's script, which Slurm runs after every task succeeded.
std::string joinScript(const FarmPlanJob& job, const Plan& p);

} // namespace turb::run::farm
