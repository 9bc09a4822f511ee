#include <turb/run/Flags.h>

#include <cstddef>
#include <string>

namespace turb::run {

namespace {

// The flags addReadOptions and addWriteOptions declare, by the ReadOptions / WriteOptions field they set (the names
// turb::Error::settings and turbio::ReadReport use). A read option takes its prefix ("--target-vel-grid").
struct SettingFlag
{
    const char* setting;
    const char* flag;
    bool read;
};
constexpr SettingFlag kSettingFlags[] = {{"densityGrid", "density-grid", true}, {"velocityGrid", "vel-grid", true},
    {"velocityUnits", "vel-units", true}, {"dt", "dt", true}, {"cropToSmoke", "no-crop", true},
    {"cropMargin", "crop-margin", true}, {"keepIsolated", "keep-isolated", true}, {"fps", "fps", true},
    {"style", "style", false}, {"noClobber", "no-clobber", false}, {"halfFloat", "half", false},
    {"densityTolerance", "clipping", false}, {"format", "format", false}, {"nanoQuantization", "nanovdb-quant", false}};

bool isGridSelector(const std::string& setting)
{
    const std::string name = setting.substr(setting.find('.') + 1);
    return name == "densityGrid" || name == "velocityGrid";
}

} // namespace

std::string flagFor(const std::string& setting, const std::string& readPrefix)
{
    const size_t dot = setting.find('.');
    const std::string name = dot == std::string::npos ? setting : setting.substr(dot + 1);
    const std::string prefix = dot == std::string::npos ? readPrefix : setting.substr(0, dot);
    for (const SettingFlag& f : kSettingFlags)
        if (name == f.setting) return "--" + (f.read && !prefix.empty() ? prefix + "-" : std::string()) + f.flag;
    return "";
}

std::string messageWithFlags(const turb::Error& e)
{
    std::string flags;
    bool grids = true;
    size_t count = 0;
    for (const auto& s : e.settings()) {
        const std::string flag = flagFor(s);
        if (flag.empty()) continue;
        flags += (flags.empty() ? "" : " / ") + flag;
        grids = grids && isGridSelector(s);
        ++count;
    }
    if (flags.empty()) return e.what();
    // The message lists the file's grids, numbered: say how to pick one.
    if (grids)
        return std::string(e.what()) + (count == 1 ? " Use " : " Choose grids with ") + flags +
               " NAME, or '#N' for the N-th grid listed here.";
    return std::string(e.what()) + " (" + flags + ")";
}

bool parseNumber(const std::string& s, double& v)
{
    try {
        size_t pos = 0;
        v = std::stod(s, &pos);
        return pos == s.size();
    } catch (...) {
        return false;
    }
}

} // namespace turb::run
