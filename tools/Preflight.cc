// The settings text of a command line (tools/Preflight.h); the checks themselves are the entry points' layer's
// (turb/run/Preflight.h).
#include "Preflight.h"

#include <CLI/CLI.hpp>

#include <filesystem>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace vdbturb {

std::string commandSettingsText(const CLI::App& app, const std::vector<std::string>& inputs)
{
    // Options that say how or where to run, not what a frame holds. --skip-existing compares VDB frames only (NanoVDB
    // files hold no settings: checkOutputFormat), so the NanoVDB options say nothing here, and frames written before
    // they existed still compare equal.
    // The pictures, sheets, dumps and measures some commands make beside their frames change no frame either.
    static const std::set<std::string> kRunOnly = {"threads", "progress", "verbose", "quiet", "frames", "out", "input",
        "dry-run", "skip-existing", "no-clobber", "json", "settings", "print-settings", "help-all", "format",
        "nanovdb-quant", "preview", "preview-format", "preview-view", "preview-width", "stats", "sheet", "dump",
        "measure", "write-target"};
    std::ostringstream os;
    std::istringstream lines(app.config_to_str(true, false));
    std::string line;
    while (std::getline(lines, line)) {
        const size_t eq = line.find('=');
        if (eq == std::string::npos || line[0] == '#' || line[0] == '[') continue;
        std::string name = line.substr(0, eq), value = line.substr(eq + 1);
        const auto trim = [](std::string& t) {
            t.erase(0, t.find_first_not_of(" \t\""));
            t.erase(t.find_last_not_of(" \t\"") + 1);
        };
        trim(name);
        trim(value);
        if (kRunOnly.count(name)) continue;
        os << name << '=' << value << ';';
    }
    for (size_t i = 0; i < inputs.size(); ++i)
        os << "input" << (i ? std::to_string(i + 1) : std::string()) << '='
           << fs::absolute(inputs[i]).lexically_normal().string() << ';';
    return os.str();
}

} // namespace vdbturb
