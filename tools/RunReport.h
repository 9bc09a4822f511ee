/// @file RunReport.h
/// @brief The per-frame log and summary every frame-producing command prints.
///
/// stderr gets one human line per frame (the farm-log unit); with --json, stdout gets one JSON object
/// per frame and a final summary line that the bench/ harness parses:
///   {"summary":true,"frames":N,"median_s_per_frame":..,"total_s":..,"peak_rss_mb":..,"cpu_s":..,
///    "threads":..,"machine":".."}
#pragma once

#include <turb/run/Reporter.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace vdbturb {

class RunReport
{
public:
    /// `start`: when the run began, for total_s (reading the inputs before the first frame counts too).
    RunReport(
        std::string command, bool json, std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now());

    /// Records a finished frame: `human` is appended to the "frame N (i/n) s" prefix on stderr and
    /// `extra` is merged into the frame's JSON line.
    void frameDone(int frame, int index, int count, double seconds, const std::string& human,
        const nlohmann::json& extra = nlohmann::json::object());
    /// Records a frame --skip-existing left as it was (`path` was written by the same settings): `madeAgain` when
    /// it was made anyway, for the frames after it.
    void frameSkipped(int frame, int index, int count, double seconds, const std::string& path, bool madeAgain);
    /// Prints the summary (JSON on stdout when enabled, a human line on stderr) with `extra` merged into
    /// the JSON. Returns it.
    nlohmann::json finish(int failed = 0, const nlohmann::json& extra = nlohmann::json::object());

private:
    std::string mCommand;
    bool mJson;
    std::vector<double> mSeconds;
    std::chrono::steady_clock::time_point mStart;
};

/// The console as the entry points' reporter: lines for people on stderr (or the host's hooks), data on stdout,
/// a progress bar on a TTY, the per-frame report and summary of RunReport. Test hook (tests/cli/test_faults.cc,
/// bench/kill_resume.sh): with VDBTURB_TEST_KILL_AT=WHERE:FRAME, killPoint sends the process SIGKILL when it reaches
/// `where` of frame `frame` (kill -9 at a reproducible point): a step's name ("seams": at its first progress update
/// after the step began), "after-state" (transfer: the frame's resume state written, the frame not yet) or
/// "after-frame" (the frame in place under its final name). Unset (every real run), it costs one getenv a process.
class ConsoleReporter : public turb::run::Reporter
{
public:
    ~ConsoleReporter() override;
    void log(Level level, const std::string& line) override;
    void printData(const std::string& text, bool toStderr) override;
    bool showsPlan() const override;
    std::unique_ptr<turb::run::FrameProgress> frameProgress(int index, int count, int frame) override;
    void runStarted(const std::string& command) override;
    void frameDone(const turb::run::FrameRecord& record) override;
    void frameSkipped(int frame, int index, int count, double seconds, const std::string& path, bool again) override;
    void runFinished(int failed, const nlohmann::json& extra) override;
    void memoryEstimate(double bytes) override;
    void killPoint(const std::string& where, int frame) override;

private:
    std::unique_ptr<RunReport> mReport;
};

} // namespace vdbturb
