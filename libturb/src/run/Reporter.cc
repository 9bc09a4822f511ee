#include <turb/run/Reporter.h>

#include <atomic>
#include <mutex>
#include <set>

namespace turb::run {

namespace {

class Silent : public Reporter
{
public:
    void log(Level, const std::string&) override {}
    void printData(const std::string&, bool) override {}
};

Silent gSilent;
std::atomic<Reporter*> gReporter{&gSilent};
std::mutex gOnceMutex;
std::set<std::string> gSaidOnce;

} // namespace

std::unique_ptr<FrameProgress> Reporter::frameProgress(int, int, int) { return std::make_unique<FrameProgress>(); }

Reporter& reporter() { return *gReporter.load(); }

ReporterScope::ReporterScope(Reporter& r) : mPrevious(gReporter.exchange(&r)) {}

ReporterScope::~ReporterScope() { gReporter = mPrevious; }

void logWarning(const std::string& msg) { reporter().log(Reporter::Level::Warning, msg); }
void logInfo(const std::string& msg) { reporter().log(Reporter::Level::Info, msg); }
void logVerbose(const std::string& msg) { reporter().log(Reporter::Level::Verbose, msg); }
void printData(const std::string& text, bool toStderr) { reporter().printData(text, toStderr); }

void warnOnce(const std::string& key, const std::string& warning)
{
    {
        std::lock_guard<std::mutex> lock(gOnceMutex);
        if (!gSaidOnce.insert(key).second) return;
    }
    logWarning(warning);
}

void resetWarnOnce()
{
    std::lock_guard<std::mutex> lock(gOnceMutex);
    gSaidOnce.clear();
}

void testKillPoint(const std::string& where, int frame) { reporter().killPoint(where, frame); }

} // namespace turb::run
