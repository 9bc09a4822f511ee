#include "Console.h"

#include "Validators.h"

#include <turb/Error.h>
#include <turbio/Sequence.h>

#include <climits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <algorithm>
#include <mutex>
#include <regex>
#include <map>
#include <set>
#include <stdexcept>
#include <unistd.h>

#include <nlohmann/json.hpp>

namespace vdbturb {

namespace {
std::atomic<bool> gInterrupted{false};
std::mutex gLogMutex;
std::atomic<const OutputHooks*> gHooks{nullptr};

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

namespace {

// What setting() and legacy() recorded: an option's tier and its settings-file key.
struct Tier
{
    bool legacy = false;
    std::string key;   ///< setting: its key; legacy: the key of the setting it sets
    std::string value; ///< legacy flags: the value they give that setting ("" = the option's own value)
};

std::map<const CLI::Option*, Tier>& tiers()
{
    static std::map<const CLI::Option*, Tier> t;
    return t;
}

// Enum options' names by the value CLI11 stores after the transform ("2" -> "rotation"), for --print-settings.
std::map<const CLI::Option*, std::map<std::string, std::string>>& enumNames()
{
    static std::map<const CLI::Option*, std::map<std::string, std::string>> n;
    return n;
}

const char* const kGroupSettings =
    "Settings (second tier: also from --settings FILE; docs name their measured effects)";
// Old spellings: never listed (--help-all names them beside their setting), but named in error messages, which
// CLI11 leaves nameless for options in the hidden group "".
const char* const kGroupLegacy = "Old spellings";

// --help lists the everyday groups; --help-all the second tier too. Settings sit in a named group, not in CLI11's
// hidden one, so that a bad value's error names its option.
class TieredFormatter : public CLI::Formatter
{
public:
    bool showSecondTier = false;
    std::string make_group(std::string group, bool positional, std::vector<const CLI::Option*> opts) const override
    {
        if (group == kGroupLegacy || (group == kGroupSettings && !showSecondTier)) return {};
        return CLI::Formatter::make_group(std::move(group), positional, std::move(opts));
    }
};

// A value as TOML: numbers and booleans bare, everything else a quoted string (frame patterns hold '#', which
// would start a comment, and lists hold ',').
std::string tomlValue(const std::string& v)
{
    if (v == "true" || v == "false") return v;
    char* end = nullptr;
    if (!v.empty() && v.find_first_of(", ") == std::string::npos) {
        (void)std::strtod(v.c_str(), &end);
        if (end && *end == '\0') return v;
    }
    std::string q = "\"";
    for (const char c : v) q += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
    return q + "\"";
}

// A settings file's text without its comments: '#' outside quotes to the end of the line (CLI11 2.1's TOML reader
// also cuts at a '#' inside quotes, so the file is handed to it without comments and with comments turned off).
std::string withoutComments(std::istream& in)
{
    std::string out, line;
    while (std::getline(in, line)) {
        char quote = 0;
        for (size_t i = 0; i < line.size(); ++i) {
            const char c = line[i];
            if (quote) {
                if (c == '\\' && quote == '"') ++i;
                else if (c == quote) quote = 0;
            } else if (c == '"' || c == '\'') {
                quote = c;
            } else if (c == '#') {
                line.erase(i);
                break;
            }
        }
        out += line + "\n";
    }
    return out;
}

// Whether a legacy option's keys ("seams.bandWidth,seams.bandWidth2D") include `key`.
bool sets(const Tier& legacy, const std::string& key)
{
    return ("," + legacy.key + ",").find("," + key + ",") != std::string::npos;
}

bool isSetting(const CLI::Option* o)
{
    const auto it = tiers().find(o);
    return it != tiers().end() && !it->second.legacy;
}

bool isLegacy(const CLI::Option* o)
{
    const auto it = tiers().find(o);
    return it != tiers().end() && it->second.legacy;
}

// The name an option has in settings files and --print-settings.
std::string settingsName(const CLI::Option* o)
{
    const auto it = tiers().find(o);
    return it != tiers().end() ? it->second.key : o->get_single_name();
}

// Every option as "# help" and "name=value": the ones given (on the command line or by --settings) as settings, the
// rest commented out with their defaults, so the file reads back as it was printed (some defaults are "auto"
// values outside the range a user may give). Everyday options first, then the second tier.
std::string settingsFile(const CLI::App* app)
{
    static const std::set<std::string> kNotSettings{
        "help", "help-all", "settings", "print-settings", "verbose", "quiet", "dry-run"};
    std::string out;
    for (const bool second : {false, true}) {
        out +=
            second ? "# --- second tier: solver and experimental settings ---\n\n" : "# --- everyday options ---\n\n";
        for (const CLI::Option* o : app->get_options()) {
            if (o->get_lnames().empty() || kNotSettings.count(o->get_single_name()) || isLegacy(o) ||
                isSetting(o) != second)
                continue;
            bool given = o->count() > 0;
            std::string value;
            // An old spelling given instead (--no-seams) sets this setting: print what it set.
            for (const CLI::Option* other : app->get_options())
                if (const auto t = tiers().find(other); !given && t != tiers().end() && t->second.legacy &&
                                                        sets(t->second, settingsName(o)) && other->count() > 0) {
                    const Tier& tier = t->second;
                    given = true;
                    for (const auto& r : other->results()) value += (value.empty() ? "" : ",") + r;
                    if (!tier.value.empty()) value = tier.value;
                }
            const auto names = enumNames().find(o);
            const auto named = [&](const std::string& v) {
                if (names == enumNames().end()) return tomlValue(v);
                const auto n = names->second.find(v);
                return tomlValue(n != names->second.end() ? n->second : v);
            };
            if (!value.empty()) {
                value = named(value);
            } else if (o->get_expected_max() == 0) { // a flag
                value = given ? "true" : "false";
            } else if (!given) {
                value = o->get_default_str().empty() ? "\"\"" : named(o->get_default_str());
            } else if (o->results().size() == 1) {
                value = named(o->results().front());
            } else { // a repeated option: a TOML array, one element per occurrence
                for (const auto& r : o->results()) value += (value.empty() ? "[" : ", ") + named(r);
                value += "]";
            }
            out += "# " + o->get_description() + "\n" + (given ? "" : "# ") + settingsName(o) + "=" + value + "\n\n";
        }
    }
    return out;
}

} // namespace

std::vector<std::string> spellingsOf(const CLI::App* app, const std::string& flag)
{
    const CLI::Option* found = nullptr;
    for (const CLI::Option* o : app->get_options())
        for (const auto& n : o->get_lnames())
            if ("--" + n == flag) found = o;
    if (!found) return {};
    std::vector<std::string> out;
    for (const auto& n : found->get_lnames()) out.push_back("--" + n);
    for (const auto& n : found->get_snames()) out.push_back("-" + n);
    // An old spelling of the same setting (--band for seams.bandWidth, --no-seams for seams.enabled) sets it too.
    if (isSetting(found))
        for (const CLI::Option* o : app->get_options())
            if (isLegacy(o) && sets(tiers().at(o), settingsName(found)))
                for (const auto& n : o->get_lnames()) out.push_back("--" + n);
    return out;
}

CLI::Option* setting(CLI::Option* o, const std::string& key)
{
    const auto& names = o->get_lnames();
    if (std::find(names.begin(), names.end(), key) == names.end())
        throw std::logic_error("setting " + key + " is not a long name of " + o->get_name());
    tiers()[o] = Tier{false, key};
    return o->group(kGroupSettings);
}

CLI::Option* legacy(CLI::Option* o, const std::string& setsKey, const std::string& value)
{
    tiers()[o] = Tier{true, setsKey, value};
    // A flag spelling sets its value when given: `--keep-divergence=false` would still set it (CLI11 passes the
    // function a count), so a value other than true is refused instead of read the wrong way round.
    if (o->get_expected_max() == 0) o->disable_flag_override();
    return o->group(kGroupLegacy);
}

namespace detail {
CLI::Option* addEnumOption(CLI::App* app, const std::string& names,
    const std::vector<std::pair<std::string, long long>>& choices, long long current,
    std::function<void(long long)> set, const std::string& help)
{
    std::map<std::string, std::string> toValue, toName; // "rotation" -> "2" (what CLI11 then converts), and back
    std::string type, currentName;
    for (const auto& [name, v] : choices) {
        const std::string number = std::to_string(v);
        toValue[name] = number;
        toName.emplace(number, name);
        type += (type.empty() ? "" : "|") + name;
        if (v == current && currentName.empty()) currentName = name;
    }
    CLI::Option* o = app->add_option_function<long long>(names, std::move(set), help)
                         ->transform(CLI::Validator(
                             [toValue, type](std::string& s) {
                                 const auto it = toValue.find(s);
                                 if (it == toValue.end()) return "'" + s + "' is not one of " + type;
                                 s = it->second;
                                 return std::string();
                             },
                             ""))
                         ->type_name(type)
                         ->default_str(currentName);
    enumNames()[o] = std::move(toName);
    return o;
}
} // namespace detail

void addGlobalOptions(CLI::App* app, unsigned which)
{
    auto formatter = std::make_shared<TieredFormatter>();
    app->formatter(formatter);
    app->add_flag_callback(
           "-v,--verbose", [] { globals().verbosity = 2; }, "Print details: solver iterations, timings")
        ->group(kGroupRun);
    app->add_flag_callback(
           "-q,--quiet", [] { globals().verbosity = 0; }, "Print errors only")
        ->group(kGroupRun);
    if (which & kThreads)
        app->add_option("--threads", globals().threads, "Worker threads (0 = all cores); results do not depend on it")
            ->check(finiteIn(0.0))
            ->group(kGroupRun);
    if (which & (kThreads | kDryRun)) // the commands that work frame by frame
        app->add_option("--progress", globals().progress,
               "auto (a bar on a terminal, a line a frame otherwise), lines, alf (Tractor: ALF_PROGRESS NN%), "
               "percent (Deadline: Progress: NN%)")
            ->check(CLI::IsMember({"auto", "lines", "alf", "percent"}))
            ->group(kGroupRun);
    if (which & kDryRun)
        app->add_flag("--dry-run", globals().dryRun,
               "Check everything the run needs (every input's headers, the output paths, memory), print the plan, "
               "write "
               "nothing")
            ->group(kGroupRun);
    // Read by expandSettingsFiles before parsing; declared here so --help lists it and the parser accepts it.
    app->add_option("--settings", "Read options from a TOML file of NAME = VALUE lines (the command line wins); "
                                  "--print-settings writes one with every option")
        ->type_name("FILE")
        ->group(kGroupRun);
    // Callbacks, so they run before the required options are checked: they need none of them.
    app->add_flag_callback(
           "--print-settings",
           [app] {
               writeData(settingsFile(app));
               throw CLI::Success();
           },
           "Print every option of this command with its value as a --settings file (TOML) on stdout, and exit")
        ->group(kGroupRun);
    app->add_flag_callback(
           "--help-all",
           [app, formatter] {
               // The second tier is listed, each old spelling named beside its setting.
               formatter->showSecondTier = true;
               for (CLI::Option* o : app->get_options()) {
                   if (!isSetting(o)) continue;
                   std::string spellings;
                   for (const auto& [other, tier] : tiers())
                       if (tier.legacy && sets(tier, settingsName(o))) spellings += " --" + other->get_lnames().front();
                   if (!spellings.empty()) o->description(o->get_description() + " (also:" + spellings + ")");
               }
               throw CLI::CallForHelp();
           },
           "Print the help with the second tier of settings too, and exit")
        ->group(kGroupRun);
    app->footer([app, formatter] {
        if (formatter->showSecondTier) return std::string();
        size_t n = 0;
        for (const CLI::Option* o : app->get_options()) n += isSetting(o);
        return n ? std::to_string(n) + " more settings (solvers, ablations, experiments): --help-all lists them, "
                                       "--print-settings writes them all as a --settings file."
                 : std::string();
    });
}

namespace {

// TOML forbids a key twice, and CLI11 would merge the two into a list; which one should win is a guess.
void refuseRepeatedKeys(const std::string& file, const std::string& body)
{
    std::istringstream lines(body);
    std::string line, section;
    std::map<std::string, int> firstLine;
    for (int n = 1; std::getline(lines, line); ++n) {
        const size_t start = line.find_first_not_of(" \t");
        if (start == std::string::npos) continue;
        if (line[start] == '[') {
            section = line.substr(start + 1, line.find(']', start) - start - 1) + ".";
            continue;
        }
        const size_t eq = line.find('=', start);
        if (eq == std::string::npos) continue;
        std::string key = line.substr(start, eq - start);
        key.erase(key.find_last_not_of(" \t") + 1);
        const auto [it, fresh] = firstLine.emplace(section + key, n);
        if (!fresh)
            throw turb::ValueError("--settings " + file + ": '" + section + key + "' is set on lines " +
                                   std::to_string(it->second) + " and " + std::to_string(n) + "; give it once");
    }
}

std::vector<CLI::ConfigItem> readSettingsFile(const std::string& file)
{
    try {
        std::ifstream in(file);
        if (!in) throw CLI::FileError::Missing(file);
        const std::string body = withoutComments(in);
        refuseRepeatedKeys(file, body);
        std::istringstream text(body);
        CLI::ConfigTOML toml;
        toml.comment('\0');
        return toml.from_config(text);
    } catch (const CLI::Error& e) {
        throw turb::ValueError("--settings " + file + ": " + e.what());
    }
}

using Spellings = std::function<std::vector<std::string>(const std::vector<std::string>&, const std::string&)>;

// The options a settings file gives, as "--name=value" words, less those the command line gives itself.
void addFileOptions(const std::string& file, const std::vector<std::string>& args,
    const std::vector<std::string>& command, const Spellings& spellings, std::vector<std::string>& fromFiles)
{
    for (const auto& item : readSettingsFile(file)) {
        // A dotted key (seams.gamma = 10) is a nested setting; CLI11 reads it as a TOML table. A [section] line
        // arrives the same way, so both name the setting "seams.gamma".
        std::string name = item.name;
        if (!(item.parents.size() == 1 && item.parents[0] == "default"))
            for (auto p = item.parents.rbegin(); p != item.parents.rend(); ++p) name = *p + "." + name;
        if (item.name.empty() || name == "settings" || name == "print-settings") continue;
        // An empty value (an unset path in a printed file) leaves the option to the command line.
        if (item.inputs.empty() || (item.inputs.size() == 1 && item.inputs[0].empty())) continue;
        // The command line wins: an option it gives is not taken from the file (giving both would be a repeat).
        const std::string flag = "--" + name;
        // Every spelling of the option counts: a file's detailEnergy is overridden by --detail-energy too.
        std::vector<std::string> names{flag};
        if (spellings) names = spellings(command, flag);
        if (names.empty())
            throw turb::ValueError("--settings " + file + ": '" + name + "' is not an option of vdbturb" + [&] {
                std::string c;
                for (const auto& w : command) c += " " + w;
                return c;
            }() + " (--print-settings lists them)");
        const bool given = std::any_of(args.begin(), args.end(), [&](const std::string& a) {
            return std::any_of(names.begin(), names.end(), [&](const std::string& n) {
                return a == n || a.rfind(n + "=", 0) == 0 || (n.size() == 2 && a.rfind(n, 0) == 0);
            });
        });
        if (given) continue;
        for (const auto& v : item.inputs) fromFiles.push_back(flag + "=" + v); // "=": flags take true/false too
    }
}

} // namespace

std::vector<std::string> expandSettingsFiles(const std::vector<std::string>& args, const Spellings& spellings)
{
    if (args.size() < 2) return args;
    std::vector<std::string> command; // "farm", "plan": the words before the first option
    for (size_t i = 1; i < args.size() && !args[i].empty() && args[i][0] != '-'; ++i) command.push_back(args[i]);
    std::vector<std::string> fromFiles, rest;
    for (size_t i = 1; i < args.size(); ++i) {
        std::string file;
        if (args[i] == "--settings" && i + 1 < args.size()) file = args[++i];
        else if (args[i].rfind("--settings=", 0) == 0) file = args[i].substr(11);
        else {
            rest.push_back(args[i]);
            continue;
        }
        addFileOptions(file, args, command, spellings, fromFiles);
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
    // Past `ulimit -f` the kernel kills the process with SIGXFSZ, silently and with a temporary file left behind;
    // ignored, the write fails with EFBIG, which the writers report (exit 75) after removing the temporary file.
    std::signal(SIGXFSZ, SIG_IGN);
}

bool interruptRequested() { return gInterrupted.load(); }

void requestInterrupt() { gInterrupted = true; }

void setOutputHooks(const OutputHooks* hooks) { gHooks = hooks; }

bool stderrIsTty()
{
    static const bool tty = ::isatty(STDERR_FILENO) == 1;
    return tty;
}

static void emit(OutputHooks::Level level, const std::string& prefix, const std::string& msg)
{
    std::lock_guard<std::mutex> lock(gLogMutex);
    if (const OutputHooks* h = gHooks.load(); h && h->log) {
        h->log(level, msg);
        return;
    }
    if (stderrIsTty()) std::fputs("\r\033[K", stderr);
    std::fprintf(stderr, "%s%s\n", prefix.c_str(), msg.c_str());
    std::fflush(stderr);
}

void logError(const std::string& msg) { emit(OutputHooks::Level::Error, "vdbturb: error: ", msg); }

void writeData(const std::string& text)
{
    std::lock_guard<std::mutex> lock(gLogMutex);
    if (const OutputHooks* h = gHooks.load(); h && h->data) {
        h->data(text);
        return;
    }
    std::fputs(text.c_str(), stdout);
    std::fflush(stdout);
}

void frameReported(int frame, int done, int total)
{
    if (const OutputHooks* h = gHooks.load(); h && h->frame) h->frame(frame, done, total);
}

void reportWrapperProgress(int done, int total)
{
    const std::string& how = globals().progress;
    if ((how != "alf" && how != "percent") || total <= 0) return;
    const int percent = int(100LL * done / total);
    const std::string line = (how == "alf" ? "ALF_PROGRESS " : "Progress: ") + std::to_string(percent) + "%";
    if (!globals().json) return writeData(line + "\n");
    std::lock_guard<std::mutex> lock(gLogMutex);
    if (const OutputHooks* h = gHooks.load(); h && h->log) return h->log(OutputHooks::Level::Info, line);
    std::fputs((line + "\n").c_str(), stderr);
    std::fflush(stderr);
}

int reportFailure(const std::string& message, int exitCode)
{
    logError(message);
    if (!globals().json) return exitCode;
    // Messages name what failed in a few fixed forms: "PATH: ...", "frame N", "grid 'NAME'".
    nlohmann::json j{{"error", message}, {"file", nullptr}, {"frame", nullptr}, {"grid", nullptr}, {"exit", exitCode}};
    std::smatch m;
    static const std::regex file(
        R"(^([^:\s][^:]*\.(?:vdb|nvdb|png|exr|jpg|jpeg|tif|tiff|json|toml|vdbturblib)):)", std::regex::icase);
    static const std::regex frame(R"(\bframe (-?\d+))");
    static const std::regex grid(R"(\bgrid '([^']*)')");
    if (std::regex_search(message, m, file)) {
        j["file"] = m[1].str();
        // A cache file's stem ends in its frame number (the rule every command reads file names by).
        if (const auto named = turbio::FramePattern::fromFileName(m[1].str())) j["frame"] = named->second;
    }
    if (std::regex_search(message, m, frame)) {
        const long long n = std::strtoll(m[1].str().c_str(), nullptr, 10); // saturates; never throws here
        if (n >= INT_MIN && n <= INT_MAX) j["frame"] = int(n);
    }
    if (std::regex_search(message, m, grid)) j["grid"] = m[1].str();
    writeData(j.dump() + "\n");
    return exitCode;
}

void consoleLog(turb::run::Reporter::Level level, const std::string& msg)
{
    switch (level) {
    case turb::run::Reporter::Level::Error: logError(msg); break;
    case turb::run::Reporter::Level::Warning:
        if (globals().verbosity >= 1) emit(OutputHooks::Level::Warning, "vdbturb: warning: ", msg);
        break;
    case turb::run::Reporter::Level::Info:
        if (globals().verbosity >= 1) emit(OutputHooks::Level::Info, "", msg);
        break;
    case turb::run::Reporter::Level::Verbose:
        if (globals().verbosity >= 2) emit(OutputHooks::Level::Verbose, "  ", msg);
        break;
    }
}

void consolePrintData(const std::string& text, bool toStderr)
{
    if (globals().verbosity < 1) return;
    if (globals().json) toStderr = true;
    if (!toStderr) return writeData(text.empty() || text.back() == '\n' ? text : text + "\n");
    std::lock_guard<std::mutex> lock(gLogMutex);
    if (const OutputHooks* h = gHooks.load(); h && h->log)
        return h->log(
            OutputHooks::Level::Info, text.empty() || text.back() != '\n' ? text : text.substr(0, text.size() - 1));
    if (stderrIsTty()) std::fputs("\r\033[K", stderr);
    std::fputs(text.c_str(), stderr);
    if (!text.empty() && text.back() != '\n') std::fputc('\n', stderr);
    std::fflush(stderr);
}

void resetRunState()
{
    globals() = Globals{};
    gInterrupted = false;
    turb::run::resetWarnOnce();
    // Keyed by option address: a later parser's options may reuse the addresses of a destroyed one's.
    tiers().clear();
    enumNames().clear();
}

ConsoleProgress::ConsoleProgress(int frameIndex, int frameCount, int frameNumber)
    : mIndex(frameIndex), mCount(frameCount), mFrame(frameNumber),
      mTty(stderrIsTty() && globals().verbosity >= 1 && globals().progress == "auto" && !gHooks.load())
{}

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
    testKillPoint(mStep, mFrame);
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
