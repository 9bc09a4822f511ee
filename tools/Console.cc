#include "Console.h"

#include <csignal>
#include <cstdio>
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
