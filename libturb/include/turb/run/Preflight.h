/// @file Preflight.h (turb::run, the entry points' layer)
/// @brief The checks every command runs before its first frame, and that --dry-run prints: every input
///        frame's headers (missing grids, damaged or newer files, unsupported transforms, lattices that change
///        halfway), the output paths, and the memory the run needs. A dry run therefore fails where the run
///        would, and a run fails before it writes anything.
#pragma once

#include <turbio/Scan.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <string>
#include <utility>
#include <vector>

namespace turb::run {

/// What a command does with a sequence whose lattice changes between frames.
enum class LatticePolicy {
    Refuse, ///< temporal commands (transfer, synth): carried state lives on one lattice; refuse before writing
    Report  ///< per-frame commands (measure, resample, preview): each frame is read on its own lattice; say so
};

/// Scans the headers of `frames` of `seq` as `read` will read them. Throws the first frame's error (it names
/// the file and grid, and its settings qualified with `readPrefix`, the prefix addReadOptions declared `read`'s
/// flags with), and with LatticePolicy::Refuse a lattice change naming the frames and files; with Report it logs
/// the change once. `role` ("target", "source", "cache") and `command` word the messages.
turbio::SequenceScan checkInput(const std::string& command, const std::string& role, const turbio::Sequence& seq,
    const std::vector<int>& frames, const turbio::ReadOptions& read, LatticePolicy policy,
    const std::string& readPrefix = "");

/// Where a read's time step, frame rate and velocity units came from, in the command line's words: a setting the
/// user gave is its flag ("--target-dt", "--vel-units cells"), with the prefix addReadOptions declared it with.
struct TimingSources
{
    std::string dt, fps, units;
};
TimingSources timingSources(const turbio::ReadReport& timing, const std::string& readPrefix = "");

/// How a scanned input's time step and velocity units were decided, one line each (for -v and dry runs).
std::vector<std::string> timingLines(
    const std::string& role, const turbio::FrameScan& frame, const std::string& readPrefix = "");

/// Prints timingLines in a dry run (always) or at -v, and warns once when the time step rests on an assumed
/// frame rate and the command uses it (`usesDt`); the warning names --PREFIX-fps / --PREFIX-dt.
void reportTiming(
    const std::string& role, const turbio::SequenceScan& scan, bool usesDt, const std::string& readPrefix = "");

/// Refuses outputs that cannot be written: a parent path that is a file, a directory that cannot be
/// written, an output that is a directory, an output that is one of `inputs`, and (with `noClobber`) an
/// output that exists, unless `skipExisting` (a resume) will skip it.
void checkOutputs(
    const std::vector<std::string>& outputs, const std::vector<std::string>& inputs, bool noClobber, bool skipExisting);

/// --skip-existing for one frame: true when `path` (a VDB file, or an image with frameMetadata) exists and was
/// written by `command` with `settings` (the frame is complete: vdbturb renames a file into place only when whole).
/// False when it does not exist. Throws turb::ValueError (exit 1: a retry cannot fix it) when it exists but was made
/// otherwise, naming what differs.
bool writtenWithSettings(const std::string& path, const std::string& command, const std::string& settings);

/// --skip-existing's plan for a command's outputs (`outputs[i]` is frame `frames[i]`, in the order it makes them).
struct SkipPlan
{
    std::vector<bool> skip;   ///< per output: already written by the same command and settings
    std::vector<int> writing; ///< the frame numbers still to write (what lockOutputFrames takes)
    size_t end = 0;           ///< one past the last output to write: a command that makes frames in order stops there
    bool skipped(size_t i) const { return i < skip.size() && skip[i]; }
};

/// Which outputs --skip-existing skips: with `skipExisting` off, none (every frame written, `end` the count);
/// on, each one writtenWithSettings finds (VDB frames by their metadata, images by their header's text
/// attributes, frameMetadata). Throws as writtenWithSettings for a frame made otherwise.
SkipPlan planSkips(const std::vector<std::string>& outputs, const std::vector<int>& frames, const std::string& command,
    const std::string& settings, bool skipExisting);
/// The same with each output's own settings (`settings[i]` for `outputs[i]`: sequentialSettings).
SkipPlan planSkips(const std::vector<std::string>& outputs, const std::vector<int>& frames, const std::string& command,
    const std::vector<std::string>& settings, bool skipExisting);

/// Each frame's settings for a command whose frame follows the one before it (synth, stylize): `settings` and
/// "shot_frames=FIRST-THIS" (the run's frames up to it, turbio::formatFrameList), since a frame made in a run that
/// began elsewhere, or stepped otherwise, differs. So a longer run of the same shot skips the frames an earlier
/// one wrote, and a run that began later is refused rather than continued from them.
std::vector<std::string> sequentialSettings(const std::string& settings, const std::vector<int>& frames);

/// A dry run's plan under --skip-existing: "would skip PATH (written by the same settings)" or "would write PATH",
/// one line per output on stdout, as the dry run's data.
void printSkipPlan(const SkipPlan& plan, const std::vector<std::string>& outputs);

/// The header attributes an image frame records (vdbturb_command, vdbturb_settings) so that --skip-existing knows
/// it again: give them to turbio::ImageWriteOptions::metadata.
std::vector<std::pair<std::string, std::string>> frameMetadata(const std::string& command, const std::string& settings);

/// Takes, for this process's life, a write lock on each of `frames` of the output `pattern`: an fcntl byte-range
/// lock per frame in one lock file beside the outputs (`.NAME.lock`, NAME the pattern's file name), so that two
/// processes given the same frame never both write it while tasks writing other frames of the shot into the same
/// folder run side by side (the farm's case). The kernel drops the locks when the process ends, however it ends;
/// the last holder removes the file when it ends normally (a killed run leaves it, for the next to take over).
/// Throws turb::TransientError (exit 75: retry once the other is done) naming the other process when one of the
/// frames is held, and nothing when the folder cannot hold a lock file (read-only: the write fails later, named).
void lockOutputFrames(const turbio::FramePattern& pattern, const std::vector<int>& frames);
/// Drops the locks lockOutputFrames took, as the end of the process does: a host process (the Python module)
/// calls it after each command line.
void releaseOutputLocks();

/// Refuses a run whose peak memory estimate exceeds what this process may use, with the estimate, the
/// reason and `whatFits` (what would run instead). Logged at -v and in dry runs either way.
void checkMemory(double estimateBytes, const std::string& what, const std::string& whatFits);

/// Which world axis points up in the cache file `path` (1 y, 2 z) under `requested` ("auto", "y" or "z"): auto
/// reads the vdbturb_up_axis metadata, else takes y for a file written by Houdini (its world is y up and its VDBs
/// say so only through their creator), else z (Blender, EmberGen, vdbturb's scenes). `why` gets the reason auto
/// chose y (empty otherwise).
int upAxisOf(const std::string& path, const std::string& requested, std::string& why);

} // namespace turb::run
