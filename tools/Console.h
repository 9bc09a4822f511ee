/// @file Console.h
/// @brief What every vdbturb command shares: verbosity, threads, Ctrl-C, the progress display, and
///        the per-frame log line. Data (JSON) goes to stdout; everything for people goes to stderr.
#pragma once

#include <turb/Progress.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <chrono>
#include <string>
#include <vector>

namespace vdbturb {

/// Exit codes (design.md): 0 success, 1 some frame failed, 2 usage error, 130 interrupted.
enum ExitCode { kOk = 0, kFailed = 1, kUsage = 2, kInterrupted = 130 };

struct Globals
{
    int verbosity = 1;   ///< 0 = -q (errors only), 1 = normal, 2 = -v
    int threads = 0;     ///< 0 = all cores
    bool dryRun = false; ///< resolve inputs and print the plan, write nothing
    bool json = false;   ///< stdout carries JSON lines only: printData's text goes to stderr
};

Globals& globals();

/// Which of the shared options a command takes: only those that mean something for it.
enum GlobalOption : unsigned { kVerbosity = 1, kThreads = 2, kDryRun = 4, kAllGlobals = 7 };

/// Adds -v/-q and, as `which` says, --threads and --dry-run to a subcommand.
void addGlobalOptions(CLI::App* app, unsigned which = kAllGlobals);

/// argv with every `--settings FILE` replaced by the file's NAME = VALUE lines as `--NAME VALUE` arguments, placed
/// right after the command words so that the command line's own options, parsed later, win (options take their
/// last value). Throws turb::ValueError naming the file when it cannot be read or holds [sections].
std::vector<std::string> expandSettingsFiles(const std::vector<std::string>& args);

/// Installs the SIGINT/SIGTERM handler that turns Ctrl-C into a cancellation request.
void installSignalHandlers();
bool interruptRequested();

void logError(const std::string& msg);   ///< always printed: "vdbturb: error: msg"
void logWarning(const std::string& msg); ///< printed unless -q
void logInfo(const std::string& msg);    ///< printed unless -q
void logVerbose(const std::string& msg); ///< printed with -v
/// A command's data for people (info's tables, a dry run's plan): stdout unless -q; `toStderr` keeps stdout
/// free for JSON.
void printData(const std::string& text, bool toStderr = false);

/// Rows of cells as text with every column padded to its widest cell, one line per row, each prefixed by
/// `indent`.
std::string alignColumns(const std::vector<std::vector<std::string>>& rows, const std::string& indent = "  ");

/// Logs `warning` once per process for each distinct `key` (conventions assumed, conversions made).
void warnOnce(const std::string& key, const std::string& warning);

/// True when stderr is a terminal (progress bar) rather than a farm log (one line per frame).
bool stderrIsTty();

/// turb::Progress for the console: a redrawn bar on a TTY, silence otherwise (the per-frame line is
/// the farm log's unit). Cancellation follows Ctrl-C.
class ConsoleProgress : public turb::Progress
{
public:
    ConsoleProgress(int frameIndex, int frameCount, int frameNumber);
    ~ConsoleProgress() override;
    void begin(const std::string& step) override;
    void update(double fraction) override;
    void note(const std::string& text) override;
    bool cancelled() const override;
    void clear();

private:
    void draw();
    int mIndex, mCount, mFrame;
    std::string mStep;
    double mFraction = 0.0;
    bool mTty;
    bool mDrawn = false;
    std::chrono::steady_clock::time_point mLastDraw;
};

/// Seconds since `t0`.
double secondsSince(std::chrono::steady_clock::time_point t0);

} // namespace vdbturb
