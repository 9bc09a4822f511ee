#include "Console.h"

#include <turb/Error.h>

#include <csignal>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <algorithm>
#include <mutex>
#include <set>
#include <unistd.h>

namespace vdbturb {

namespace {
std::atomic<bool> gInterrupted{false};
std::mutex gLogMutex;

extern "C" void onSignal(int)
{
    // A second Ctrl-C kills at once, as users expect.
    if (gInterrupted.exchange(true)) std::_Exit(kInterrupted);
}
} // namespace

Globals& globals()
{
    static Globals g;
    return g;
}

void addGlobalOptions(CLI::App* app, unsigned which)
{
    app->add_flag_callback("-v,--verbose", [] { globals().verbosity = 2; }, "Print details: solver iterations, timings");
    app->add_flag_callback("-q,--quiet", [] { globals().verbosity = 0; }, "Print errors only");
    if (which & kThreads)
        app->add_option("--threads", globals().threads, "Worker threads (0 = all cores); results do not depend on it")
            ->check(CLI::NonNegativeNumber);
    if (which & kDryRun)
        app->add_flag("--dry-run", globals().dryRun,
            "Check everything the run needs (every input's headers, the output paths, memory), print the plan, write nothing");
    // Two tiers, as pbrt's: everyday flags on the command line, every knob also from a TOML file.
    // Read by expandSettingsFiles before parsing; declared here so --help lists it and the parser accepts it.
    app->add_option("--settings", "Read options from a TOML file of NAME = VALUE lines (long option names without the "
                                  "dashes; the command line wins). --print-settings writes one with every option")
        ->type_name("FILE");
    // A callback, so it runs before the required options are checked: it needs none of them.
    app->add_flag_callback(
        "--print-settings",
        [app] {
            // Every option as "# help" and "name=value": the ones given (on the command line or by --settings)
            // as settings, the rest commented out with their defaults, so the file reads back as it was printed
            // (some defaults are "auto" values outside the range a user may give).
            std::string out;
            for (const CLI::Option* o : app->get_options()) {
                const std::string name = o->get_single_name();
                if (o->get_lnames().empty() || name == "help" || name == "settings" || name == "print-settings" ||
                    name == "verbose" || name == "quiet" || name == "dry-run")
                    continue;
                const bool given = o->count() > 0;
                std::string value;
                if (o->get_expected_max() == 0) { // a flag
                    value = given ? "true" : "false";
                } else {
                    for (const auto& r : o->results()) value += (value.empty() ? "" : ",") + r;
                    if (!given) value = o->get_default_str();
                    if (value.empty()) value = "\"\"";
                }
                out += "# " + o->get_description() + "\n" + (given ? "" : "# ") + name + "=" + value + "\n\n";
            }
            std::fputs(out.c_str(), stdout);
            throw CLI::Success();
        },
        "Print every option of this command with its value as a --settings file (TOML) on stdout, and exit");
}

std::vector<std::string> expandSettingsFiles(const std::vector<std::string>& args)
{
    if (args.size() < 2) return args;
    std::vector<std::string> fromFiles, rest;
    for (size_t i = 1; i < args.size(); ++i) {
        std::string file;
        if (args[i] == "--settings" && i + 1 < args.size()) file = args[++i];
        else if (args[i].rfind("--settings=", 0) == 0) file = args[i].substr(11);
        else {
            rest.push_back(args[i]);
            continue;
        }
        std::vector<CLI::ConfigItem> items;
        try {
            items = CLI::ConfigTOML().from_file(file);
        } catch (const CLI::Error& e) {
            throw turb::ValueError("--settings " + file + ": " + e.what());
        }
        for (const auto& item : items) {
            if (!item.parents.empty() && !(item.parents.size() == 1 && item.parents[0] == "default"))
                throw turb::ValueError("--settings " + file + ": sections ([" + item.parents.back() +
                                       "]) are not read; give one command's options as NAME = VALUE lines");
            if (item.name.empty() || item.name == "settings" || item.name == "print-settings") continue;
            // An empty value (an unset path in a printed file) leaves the option to the command line.
            if (item.inputs.empty() || (item.inputs.size() == 1 && item.inputs[0].empty())) continue;
            // The command line wins: an option it gives is not taken from the file (giving both would be a repeat).
            const std::string flag = "--" + item.name;
            const bool given = std::any_of(args.begin(), args.end(),
                [&](const std::string& a) { return a == flag || a.rfind(flag + "=", 0) == 0; });
            if (given) continue;
            for (const auto& v : item.inputs) fromFiles.push_back(flag + "=" + v); // "=": flags take true/false too
        }
    }
    std::vector<std::string> out{args[0]};
    size_t k = 0;
    // Keep the command (and a nested command such as "farm plan") before the inserted options.
    while (k < rest.size() && !rest[k].empty() && rest[k][0] != '-') out.push_back(rest[k++]);
    out.insert(out.end(), fromFiles.begin(), fromFiles.end());
    out.insert(out.end(), rest.begin() + long(k), rest.end());
    return out;
}

void installSignalHandlers()
{
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
}

bool interruptRequested() { return gInterrupted.load(); }

bool stderrIsTty()
{
    static const bool tty = ::isatty(STDERR_FILENO) == 1;
    return tty;
}

static void emit(const std::string& prefix, const std::string& msg)
{
    std::lock_guard<std::mutex> lock(gLogMutex);
    if (stderrIsTty()) std::fputs("\r\033[K", stderr);
    std::fprintf(stderr, "%s%s\n", prefix.c_str(), msg.c_str());
    std::fflush(stderr);
}

void logError(const std::string& msg) { emit("vdbturb: error: ", msg); }
void logWarning(const std::string& msg)
{
    if (globals().verbosity >= 1) emit("vdbturb: warning: ", msg);
}
void logInfo(const std::string& msg)
{
    if (globals().verbosity >= 1) emit("", msg);
}
void logVerbose(const std::string& msg)
{
    if (globals().verbosity >= 2) emit("  ", msg);
}

void printData(const std::string& text, bool toStderr)
{
    if (globals().verbosity < 1) return;
    std::lock_guard<std::mutex> lock(gLogMutex);
    if (globals().json) toStderr = true;
    std::FILE* out = toStderr ? stderr : stdout;
    if (toStderr && stderrIsTty()) std::fputs("\r\033[K", stderr);
    std::fputs(text.c_str(), out);
    if (!text.empty() && text.back() != '\n') std::fputc('\n', out);
    std::fflush(out);
}

std::string alignColumns(const std::vector<std::vector<std::string>>& rows, const std::string& indent)
{
    std::vector<size_t> width;
    for (const auto& r : rows)
        for (size_t c = 0; c < r.size(); ++c) {
            if (width.size() <= c) width.resize(c + 1, 0);
            width[c] = std::max(width[c], r[c].size());
        }
    std::string out;
    for (const auto& r : rows) {
        std::string line = indent;
        for (size_t c = 0; c < r.size(); ++c) {
            line += r[c];
            if (c + 1 < r.size()) line += std::string(width[c] - r[c].size() + 2, ' ');
        }
        while (!line.empty() && line.back() == ' ') line.pop_back();
        out += line + "\n";
    }
    return out;
}

void warnOnce(const std::string& key, const std::string& warning)
{
    static std::mutex m;
    static std::set<std::string> seen;
    {
        std::lock_guard<std::mutex> lock(m);
        if (!seen.insert(key).second) return;
    }
    logWarning(warning);
}

ConsoleProgress::ConsoleProgress(int frameIndex, int frameCount, int frameNumber)
    : mIndex(frameIndex), mCount(frameCount), mFrame(frameNumber), mTty(stderrIsTty() && globals().verbosity >= 1)
{
}

ConsoleProgress::~ConsoleProgress() { clear(); }

void ConsoleProgress::begin(const std::string& step)
{
    mStep = step;
    mFraction = 0.0;
    logVerbose("frame " + std::to_string(mFrame) + ": " + step);
    draw();
}

void ConsoleProgress::update(double fraction)
{
    mFraction = fraction;
    const auto now = std::chrono::steady_clock::now();
    if (now - mLastDraw > std::chrono::milliseconds(100)) draw();
}

void ConsoleProgress::note(const std::string& text) { logVerbose("frame " + std::to_string(mFrame) + ": " + text); }

bool ConsoleProgress::cancelled() const { return interruptRequested(); }

void ConsoleProgress::draw()
{
    if (!mTty) return;
    mLastDraw = std::chrono::steady_clock::now();
    const int width = 30;
    const double overall = (mIndex + std::min(1.0, std::max(0.0, mFraction))) / std::max(1, mCount);
    const int filled = int(overall * width + 0.5);
    std::lock_guard<std::mutex> lock(gLogMutex);
    std::fprintf(stderr, "\r\033[K[%s%s] %3d%%  frame %d (%d/%d)  %s", std::string(size_t(filled), '#').c_str(),
        std::string(size_t(width - filled), '.').c_str(), int(overall * 100), mFrame, mIndex + 1, mCount,
        mStep.c_str());
    std::fflush(stderr);
    mDrawn = true;
}

void ConsoleProgress::clear()
{
    if (!mDrawn) return;
    std::lock_guard<std::mutex> lock(gLogMutex);
    std::fputs("\r\033[K", stderr);
    std::fflush(stderr);
    mDrawn = false;
}

double secondsSince(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace vdbturb
