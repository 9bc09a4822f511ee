#include "RunReport.h"

#include "Console.h"

#include <unistd.h>

#include <cstdlib>

#include <csignal>

#include <turbio/System.h>

#include <tbb/info.h>

#include <algorithm>
#include <cstdio>

namespace vdbturb {

RunReport::RunReport(std::string command, bool json, std::chrono::steady_clock::time_point start)
    : mCommand(std::move(command)), mJson(json), mStart(start)
{}

void RunReport::frameDone(
    int frame, int index, int count, double seconds, const std::string& human, const nlohmann::json& extra)
{
    mSeconds.push_back(seconds);
    char head[96];
    std::snprintf(head, sizeof(head), "frame %d (%d/%d) %.2f s", frame, index + 1, count, seconds);
    logInfo(std::string(head) + (human.empty() ? "" : "  " + human));
    reportWrapperProgress(index + 1, count);
    if (mJson) {
        nlohmann::json j = extra;
        j["frame"] = frame;
        j["seconds"] = seconds;
        writeData(j.dump() + "\n");
    }
    frameReported(frame, index + 1, count);
}

void RunReport::frameSkipped(int frame, int index, int count, double seconds, const std::string& path, bool madeAgain)
{
    frameDone(frame, index, count, seconds,
        "skipped: " + path + " was written by the same settings" +
            (madeAgain ? " (made again for the next frames)" : ""),
        {{"out", path}, {"skipped", true}});
}

nlohmann::json RunReport::finish(int failed, const nlohmann::json& extra)
{
    std::vector<double> s = mSeconds;
    std::sort(s.begin(), s.end());
    const double median =
        s.empty() ? 0.0 : (s.size() % 2 ? s[s.size() / 2] : 0.5 * (s[s.size() / 2 - 1] + s[s.size() / 2]));
    const int threads = globals().threads > 0 ? globals().threads : tbb::info::default_concurrency();
    nlohmann::json j = extra;
    j["summary"] = true;
    j["command"] = mCommand;
    j["frames"] = mSeconds.size();
    j["failed"] = failed;
    j["median_s_per_frame"] = median;
    j["total_s"] = secondsSince(mStart);
    j["peak_rss_mb"] = double(turbio::peakRssBytes()) / (1024.0 * 1024.0);
    j["cpu_s"] = turbio::cpuSeconds();
    j["threads"] = threads;
    j["machine"] = turbio::machineDescription();
    char line[256];
    std::snprintf(line, sizeof(line),
        "%s: %zu frame%s, median %.2f s/frame, total %.1f s (CPU %.1f s), peak RSS %.0f MB, %d threads",
        mCommand.c_str(), mSeconds.size(), mSeconds.size() == 1 ? "" : "s", median, j["total_s"].get<double>(),
        j["cpu_s"].get<double>(), j["peak_rss_mb"].get<double>(), threads);
    logInfo(line);
    if (mJson) writeData(j.dump() + "\n");
    return j;
}

void ConsoleReporter::log(Level level, const std::string& line) { consoleLog(level, line); }

void ConsoleReporter::printData(const std::string& text, bool toStderr) { consolePrintData(text, toStderr); }

bool ConsoleReporter::showsPlan() const { return globals().dryRun || globals().verbosity >= 2; }

std::unique_ptr<turb::run::FrameProgress> ConsoleReporter::frameProgress(int index, int count, int frame)
{
    return std::make_unique<ConsoleProgress>(index, count, frame);
}

void ConsoleReporter::runStarted(const std::string& command)
{
    mReport = std::make_unique<RunReport>(command, globals().json);
}

void ConsoleReporter::frameDone(const turb::run::FrameRecord& r)
{
    if (mReport) mReport->frameDone(r.frame, r.index, r.count, r.seconds, r.line, r.extra);
}

void ConsoleReporter::frameSkipped(int frame, int index, int count, double seconds, const std::string& path, bool again)
{
    if (mReport) mReport->frameSkipped(frame, index, count, seconds, path, again);
}

void ConsoleReporter::runFinished(int failed, const nlohmann::json& extra)
{
    if (mReport) mReport->finish(failed, extra);
    mReport.reset();
}

void ConsoleReporter::memoryEstimate(double bytes) { globals().predictedPeakBytes = bytes; }

void ConsoleReporter::killPoint(const std::string& where, int frame)
{
    static const std::pair<std::string, int> at = [] {
        const char* env = std::getenv("VDBTURB_TEST_KILL_AT");
        const std::string s = env ? env : "";
        const size_t colon = s.rfind(':');
        if (colon == std::string::npos) return std::pair<std::string, int>();
        return std::pair<std::string, int>(s.substr(0, colon), std::atoi(s.c_str() + colon + 1));
    }();
    if (at.first.empty() || at.first != where || at.second != frame) return;
    ::kill(::getpid(), SIGKILL); // delivered before kill() returns
    for (;;) ::pause();
}

ConsoleReporter::~ConsoleReporter() = default;

} // namespace vdbturb
