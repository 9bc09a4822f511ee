/// @file Reporter.h
/// @brief Where an entry point's words go while it runs (turb::run, the entry points' layer).
///
/// The entry points (runTransfer and the others of this folder) never print. What they have to say goes to the
/// Reporter of the run in progress: lines for people (warnings, information, -v detail), a dry run's plan, each
/// frame's progress and its finished record. The CLI's console prints them (stderr for people, stdout for data), the
/// Python module hands them to its callbacks, a test records them. With no reporter set they are dropped.
///
/// One run at a time per process (the CLI runs one command; the Python module one call at a time): the reporter is
/// process-wide, set for the length of a run by ReporterScope, and may be called from any thread.
#pragma once

#include <turb/Progress.h>

#include <nlohmann/json.hpp>

#include <memory>
#include <string>

namespace turb::run {

/// A frame's progress as the reporter shows it: a bar on a terminal, a callback in Python. `clear` takes a drawn bar
/// away before a line is logged under it.
class FrameProgress : public turb::Progress
{
public:
    virtual void clear() {}
};

/// A finished (written) frame: `line` is the farm log's text after "frame N (i/n) s", `extra` the fields of its JSON
/// line (what the method did, its solvers' outcomes).
struct FrameRecord
{
    int frame = 0, index = 0, count = 0;
    double seconds = 0.0;
    std::string line;
    nlohmann::json extra = nlohmann::json::object();
};

class Reporter
{
public:
    enum class Level { Error, Warning, Info, Verbose }; ///< Error: a part failed, the run goes on (a frame)
    virtual ~Reporter() = default;
    /// One line for people.
    virtual void log(Level level, const std::string& line) = 0;
    /// Data for people (a dry run's plan, info's tables): the CLI's stdout unless -q; `toStderr` keeps stdout free
    /// for JSON.
    virtual void printData(const std::string& text, bool toStderr) = 0;
    /// Whether the plan's detail (timing sources, memory, output size) is wanted: a dry run or -v in the CLI. The
    /// entry points then printData it; otherwise they keep quiet about it.
    virtual bool showsPlan() const { return false; }
    /// The progress of frame `frame`, the `index`-th of `count`; its cancelled() stops the run (Ctrl-C, Cancel).
    virtual std::unique_ptr<FrameProgress> frameProgress(int index, int count, int frame);
    /// A run of `command` begins its first frame (what the per-frame report and the summary time from).
    virtual void runStarted(const std::string& command) { (void)command; }
    virtual void frameDone(const FrameRecord& record) { (void)record; }
    /// A frame --skip-existing left as it was (`madeAgain`: made anyway, for the frames after it).
    virtual void frameSkipped(int frame, int index, int count, double seconds, const std::string& path, bool madeAgain)
    {
        (void)frame, (void)index, (void)count, (void)seconds, (void)path, (void)madeAgain;
    }
    /// The run's end: `failed` frames failed; `extra` goes into the summary.
    virtual void runFinished(int failed, const nlohmann::json& extra) { (void)failed, (void)extra; }
    /// The peak memory the run was estimated to need (preflight), for the message when memory runs out.
    virtual void memoryEstimate(double bytes) { (void)bytes; }
    /// Test hook (tests/cli/test_faults.cc, bench/kill_resume.sh): the run reached `where` of frame `frame`.
    virtual void killPoint(const std::string& where, int frame) { (void)where, (void)frame; }
};

/// The reporter of the run in progress: the one a ReporterScope set, or a silent one.
Reporter& reporter();

/// Sets `r` as the process's reporter until it goes out of scope (then the one before comes back).
class ReporterScope
{
public:
    explicit ReporterScope(Reporter& r);
    ~ReporterScope();
    ReporterScope(const ReporterScope&) = delete;
    ReporterScope& operator=(const ReporterScope&) = delete;

private:
    Reporter* mPrevious;
};

/// Shorthands for reporter().log and printData.
void logWarning(const std::string& msg);
void logInfo(const std::string& msg);
void logVerbose(const std::string& msg);
void printData(const std::string& text, bool toStderr = false);
/// Logs `warning` once per run for each distinct `key` (conventions assumed, conversions made).
void warnOnce(const std::string& key, const std::string& warning);
/// Forgets warnOnce's keys: a host process running one command after another.
void resetWarnOnce();
/// reporter().killPoint.
void testKillPoint(const std::string& where, int frame);

} // namespace turb::run
