/// @file Console.h
/// @brief What every vdbturb command shares: verbosity, threads, Ctrl-C, the progress display, and
///        the per-frame log line. Data (JSON) goes to stdout; everything for people goes to stderr.
#pragma once

#include <turb/Error.h>
#include <turb/Progress.h>
#include <turb/run/Output.h>
#include <turb/run/Reporter.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace vdbturb {

/// A command line that cannot run as given (exit 2, as CLI11's own parse errors): thrown by the entry points too.
using turb::run::UsageError;

/// Exit codes (README, --help): 0 success; 1 a failure a retry cannot fix (bad input, a frame failed); 2 a usage
/// error (an option's value or a combination of options); 75 (EX_TEMPFAIL) a failure worth a retry on another node
/// (disk full, a file-size limit, out of memory); 130 interrupted.
enum ExitCode { kOk = 0, kFailed = 1, kUsage = 2, kTempFail = 75, kInterrupted = 130 };

/// Ends a command with an error: "vdbturb: error: MESSAGE" on stderr and, when the command was asked for --json,
/// one JSON line on stdout, {"error", "file", "frame", "grid", "exit"} (file, frame and grid as the message names
/// them, else null), so a wrapper that parses stdout gets the reason too. Returns `exitCode`.
int reportFailure(const std::string& message, int exitCode);

/// A farm wrapper's progress line for `done` of `total` frames, as Globals::progress asks (nothing for auto and
/// lines).
void reportWrapperProgress(int done, int total);

struct Globals
{
    int verbosity = 1;   ///< 0 = -q (errors only), 1 = normal, 2 = -v
    int threads = 0;     ///< 0 = all cores
    bool dryRun = false; ///< resolve inputs and print the plan, write nothing
    bool json = false;   ///< stdout carries JSON lines only: printData's text goes to stderr
    /// How progress is shown: auto (a bar on a terminal, one line a frame otherwise), lines (one line a frame, also
    /// on a terminal), alf (also "ALF_PROGRESS NN%" a frame, Tractor's), percent (also "Progress: NN%", Deadline's
    /// stdout handler). The wrapper lines go to stdout, or to stderr with --json.
    std::string progress = "auto";
    double predictedPeakBytes = 0.0; ///< the run's memory estimate (checkMemory), named when memory runs out
    bool failedOnInput = false;      ///< the run ended on a turb::IoError (a file missing, unreadable, damaged)
};

Globals& globals();

/// Which of the shared options a command takes: only those that mean something for it.
enum GlobalOption : unsigned { kVerbosity = 1, kThreads = 2, kDryRun = 4, kAllGlobals = 7 };

/// Adds -v/-q and, as `which` says, --threads and --dry-run to a subcommand, and the two tiers' options:
/// --help-all, --settings FILE, --print-settings.
void addGlobalOptions(CLI::App* app, unsigned which = kAllGlobals);

/// Two tiers of options, as pbrt's: --help lists the everyday ones; setting() moves an option to the second
/// tier, the solver and experimental knobs, which --help-all and --print-settings list with their defaults and a
/// --settings file sets. `key` names the option in settings files: the settings struct's field ("temporalBlend",
/// "seams.gamma"); it must be one of the option's long names, so it works on the command line too, beside the
/// older spelling scripts use ("--temporal-blend"). Returns `o`.
CLI::Option* setting(CLI::Option* o, const std::string& key);
/// An old spelling kept working for scripts (a negation flag such as --no-seams for seams.enabled = false): accepted,
/// never listed; --help-all names it beside the setting it sets, and --print-settings prints that setting as `value`
/// (empty: the option's own value) when it was given. Returns `o`.
/// `setsKeys` lists the settings it sets, comma-separated.
CLI::Option* legacy(CLI::Option* o, const std::string& setsKeys, const std::string& value = "");

namespace detail {
/// addEnum without the enum's type: `choices` name the numbers `set` receives; `current` is the default's number.
CLI::Option* addEnumOption(CLI::App* app, const std::string& names,
    const std::vector<std::pair<std::string, long long>>& choices, long long current,
    std::function<void(long long)> set, const std::string& help);
} // namespace detail

/// An option bound to an enum setting: `choices` name its values (the first of a value's names is the one
/// printed as its default and by --print-settings). A name outside `choices` is refused with the list.
template<typename E>
CLI::Option* addEnum(CLI::App* app, const std::string& names, E& value,
    const std::vector<std::pair<std::string, E>>& choices, const std::string& help)
{
    std::vector<std::pair<std::string, long long>> numbered;
    for (const auto& [name, v] : choices) numbered.emplace_back(name, static_cast<long long>(v));
    return detail::addEnumOption(
        app, names, numbered, static_cast<long long>(value), [&value](long long n) { value = static_cast<E>(n); },
        help);
}

/// A boolean setting given as `KEY=true|false` (on the command line --KEY=false), its default printed as a word.
inline CLI::Option* boolSetting(
    CLI::App* app, const std::string& names, bool& value, const std::string& help, const std::string& key)
{
    return setting(
        app->add_option(names, value, help)->type_name("true|false")->default_str(value ? "true" : "false"), key);
}

/// The option groups of --help, in the order they are listed.
inline constexpr const char* kGroupInput = "Input caches";
inline constexpr const char* kGroupOutput = "Output files";
inline constexpr const char* kGroupRun = "Run";

/// argv with every `--settings FILE` replaced by the file's NAME = VALUE lines as `--NAME VALUE` arguments, placed
/// right after the command words so that the command line's own options, parsed later, win (options take their
/// last value). Dotted keys (`seams.gamma = 10`) and [sections] name nested settings. `spellings(command words,
/// flag)` lists every spelling that sets the same option (its long and short names and old spellings of the
/// setting), empty when the command has no such option; a file's line is skipped when the command line gives any
/// of them. Throws turb::ValueError naming the file when it cannot be read or names an option the command does
/// not have.
std::vector<std::string> expandSettingsFiles(const std::vector<std::string>& args,
    const std::function<std::vector<std::string>(const std::vector<std::string>&, const std::string&)>& spellings =
        {});

/// Every command-line spelling of the option `flag` ("--detailEnergy") names in `app`: "--detail-energy",
/// "--detailEnergy", and the old spellings that set the same setting. Empty when `app` has no such long option.
std::vector<std::string> spellingsOf(const CLI::App* app, const std::string& flag);

/// Installs the SIGINT/SIGTERM handler that turns Ctrl-C into a cancellation request.
void installSignalHandlers();
bool interruptRequested();
/// Asks the running command to stop as Ctrl-C does: its stages throw turb::Cancelled at their next check, so the
/// frame in flight is dropped whole (a host's cancel button: the Python module's progress callback).
void requestInterrupt();

/// Where a command's output goes when it runs inside a host process (the Python module) rather than as vdbturb:
/// what would go to stdout, the lines for people that would go to stderr, and each finished frame. A hook left empty
/// keeps the console's own destination. Installed by runCommandLine for one command line.
struct OutputHooks
{
    enum class Level { Error, Warning, Info, Verbose };
    std::function<void(const std::string&)> data;              ///< one stdout document: a JSON line, info's report
    std::function<void(Level, const std::string&)> log;        ///< one line for people, without "vdbturb: error: "
    std::function<void(int frame, int done, int total)> frame; ///< after a frame's report: `done` of `total`
};
void setOutputHooks(const OutputHooks* hooks);
/// A command's data for programs (JSON lines, info's report) on stdout, or to the data hook.
void writeData(const std::string& text);
/// A finished frame, `done` of `total`, for the frame hook (RunReport and measure report theirs).
void frameReported(int frame, int done, int total);
/// Forgets what one command line left behind (globals, an interrupt, warnings said once, the options' tiers of a
/// parser now gone), so that a host process can run command lines one after another as separate processes would.
void resetRunState();

void logError(const std::string& msg); ///< always printed: "vdbturb: error: msg"
// The entry points' log (turb/run/Reporter.h), which the console prints (ConsoleReporter): warnings and information
// unless -q, detail with -v, data for people on stdout unless -q.
using turb::run::logInfo;
using turb::run::logVerbose;
using turb::run::logWarning;
using turb::run::printData;
using turb::run::testKillPoint;
using turb::run::warnOnce;

/// True when stderr is a terminal (progress bar) rather than a farm log (one line per frame).
bool stderrIsTty();

/// turb::Progress for the console: a redrawn bar on a TTY, silence otherwise (the per-frame line is
/// the farm log's unit). Cancellation follows Ctrl-C.
class ConsoleProgress : public turb::run::FrameProgress
{
public:
    ConsoleProgress(int frameIndex, int frameCount, int frameNumber);
    ~ConsoleProgress() override;
    void begin(const std::string& step) override;
    void update(double fraction) override;
    void note(const std::string& text) override;
    bool cancelled() const override;
    void clear() override;

private:
    void draw();
    int mIndex, mCount, mFrame;
    std::string mStep;
    double mFraction = 0.0;
    bool mTty;
    bool mDrawn = false;
    std::chrono::steady_clock::time_point mLastDraw;
};

/// What the console's reporter prints (RunReport.h's ConsoleReporter): a line for people at `level` (warnings and
/// information unless -q, detail with -v) on stderr or to the host's log hook; data for people on stdout unless -q
/// (`toStderr`, or --json, keeps stdout free for JSON).
void consoleLog(turb::run::Reporter::Level level, const std::string& line);
void consolePrintData(const std::string& text, bool toStderr);

/// Seconds since `t0`.
double secondsSince(std::chrono::steady_clock::time_point t0);

} // namespace vdbturb
