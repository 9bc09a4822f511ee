// vdbturb's command line, run by main() (cli_main.cc) and the Python module. Table-driven: see Commands.h.
#include "CommandLine.h"
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"

#include <turb/Error.h>
#include <turbio/NanoVdb.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iostream>
#include <system_error>
#include <optional>
#include <regex>
#include <sstream>

using namespace vdbturb;

namespace vdbturb {

std::vector<Command> allCommands()
{
    return {infoCommand(), transferCommand(), measureCommand(), simCommand(), previewCommand(), synthCommand(),
        stylizeCommand(), animateCommand(), resampleCommand(), convertCommand(), farmCommand()};
}

} // namespace vdbturb

namespace {

// Whether the parsed command line asks for JSON on stdout (--json on the command or a nested one, or measure, whose
// stdout is always JSON); stdout then carries JSON lines only.
bool asksForJson(const CLI::App& app)
{
    if (app.get_name() == "measure") return true;
    if (const CLI::Option* o = app.get_option_no_throw("--json"); o && o->count() > 0) return true;
    for (const CLI::App* sub : app.get_subcommands())
        if (asksForJson(*sub)) return true;
    return false;
}

std::vector<std::string> longOptions(CLI::App* sub)
{
    std::vector<std::string> names;
    for (const CLI::Option* o : sub->get_options())
        for (const auto& n : o->get_lnames()) names.push_back("--" + n);
    return names;
}

bool isLongOption(CLI::App* sub, const std::string& name)
{
    const auto all = longOptions(sub);
    return std::find(all.begin(), all.end(), name) != all.end();
}

bool isShortOption(CLI::App* sub, char c)
{
    for (const CLI::Option* o : sub->get_options())
        for (const auto& n : o->get_snames())
            if (n.size() == 1 && n[0] == c) return true;
    return false;
}

// Typos CLI11 reports poorly ("A subcommand is required", "arguments were not expected", a missing
// --target after "-target"): checked before parsing, with the nearest command or option as a hint.
std::string checkSpelling(int argc, char** argv, CLI::App& app, const std::vector<std::pair<CLI::App*, Command*>>& subs)
{
    if (argc < 2) return "";
    const std::string first = argv[1];
    if (first.empty() || first[0] == '-') return "";
    CLI::App* sub = nullptr;
    std::vector<std::string> names;
    for (const auto& [s, c] : subs) {
        names.push_back(c->name);
        if (c->name == first) sub = s;
    }
    if (!sub) {
        const std::string near = turbio::nearestName(first, names);
        std::string all;
        for (const auto& n : names) all += (all.empty() ? "" : ", ") + n;
        return "unknown command '" + first + "'" + (near.empty() ? "" : "; did you mean '" + near + "'?") +
               " Commands: " + all + ".";
    }
    // A command with its own subcommands (farm plan): check the options against the one named, which also
    // takes the command's own (fallthrough).
    int from = 2;
    CLI::App* parent = nullptr;
    std::string label = first; // "farm plan" in messages about a nested subcommand's options
    if (argc > 2 && !sub->get_subcommands({}).empty()) {
        std::vector<std::string> nested;
        for (CLI::App* s : sub->get_subcommands({})) {
            nested.push_back(s->get_name());
            if (s->get_name() == argv[2]) {
                parent = sub;
                sub = s;
                from = 3;
                label = first + " " + argv[2];
            }
        }
        const std::string second = argv[2];
        if (!parent && !second.empty() && second[0] != '-') {
            const std::string near = turbio::nearestName(second, nested);
            std::string all;
            for (const auto& n : nested) all += (all.empty() ? "" : ", ") + n;
            return "'" + first + "' has no subcommand '" + second + "'" +
                   (near.empty() ? "" : "; did you mean '" + near + "'?") + " Subcommands: " + all + ".";
        }
    }
    for (int i = from; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "--") break;
        if (arg.size() < 2 || arg[0] != '-' || std::isdigit(static_cast<unsigned char>(arg[1])) || arg[1] == '.')
            continue;
        if (arg[1] == '-') {
            const std::string name = arg.substr(0, arg.find('='));
            if (name == "--help" || name == "--version" || isLongOption(sub, name) ||
                (parent && isLongOption(parent, name)))
                continue;
            const std::string near = turbio::nearestName(name, longOptions(sub));
            return "'" + label + "' has no option " + name + (near.empty() ? "." : "; did you mean " + near + "?") +
                   " See vdbturb " + label + " --help.";
        }
        // "-target": a long option with one dash (unless every letter is a short flag, as in -vq).
        bool allShort = true;
        for (size_t k = 1; k < arg.size(); ++k)
            allShort = allShort && (isShortOption(sub, arg[k]) || (parent && isShortOption(parent, arg[k])));
        if (arg.size() > 2 && !allShort) {
            const std::string dashed = "-" + arg.substr(0, arg.find('='));
            if (isLongOption(sub, dashed)) return "'" + arg + "' has one dash; long options take two: " + dashed;
            const std::string near = turbio::nearestName(dashed, longOptions(sub));
            return "'" + label + "' has no option " + arg + (near.empty() ? "." : "; did you mean " + near + "?");
        }
    }
    (void)app;
    return "";
}

// CLI11's range check says "--width: Value abc not in range 16 to 8192": say what is allowed, in words.
std::string plainParseMessage(const std::string& message)
{
    static const std::regex range(R"(^(\S+): Value (.*) not in range (\S+) to (\S+)$)");
    std::smatch m;
    if (std::regex_match(message, m, range))
        return m[1].str() + " must be a number from " + m[3].str() + " to " + m[4].str() + ", not '" + m[2].str() + "'";
    return message;
}

// The parser: each command a subcommand with its options, as `vdbturb --help` lists them.
struct Parser
{
    CLI::App app{"vdbturb: turbulence up-res for smoke caches (VDB in, VDB out)"};
    std::vector<Command> commands = allCommands();
    std::vector<std::pair<CLI::App*, Command*>> subs;

    Parser()
    {
        app.require_subcommand(1);
        app.set_version_flag("--version", std::string("vdbturb ") + VDBTURB_VERSION_STRING);
        for (auto& c : commands) {
            CLI::App* sub = app.add_subcommand(c.name, c.help);
            sub->option_defaults()->always_capture_default(); // --help and --print-settings show each default
            c.setup(sub);
            addGlobalOptions(sub, c.globals); // after the command's own: --help lists them last
            sub->footer("Exit codes: 0 done; 1 a failure a retry cannot fix (bad input, a resume with other settings); "
                        "2 a usage error; 75 worth a retry on another node (disk full, a file-size limit, out of "
                        "memory); 130 interrupted.");
            subs.emplace_back(sub, &c);
        }
    }
};

// The command line as the executable's main() ran it, argv[0] its name; `ownProcess`: take Ctrl-C's signals.
// --settings files become command-line options before anything reads argv. Empty on a bad file (reported).
std::optional<std::vector<std::string>> expandedArguments(int argc, char** argv, const Parser& parser, int& failure)
{
    const auto& subs = parser.subs;
    try {
        return expandSettingsFiles(std::vector<std::string>(argv, argv + argc),
            [&subs](const std::vector<std::string>& words, const std::string& flag) -> std::vector<std::string> {
                for (const auto& [sub, cmd] : subs) {
                    if (words.empty() || cmd->name != words[0]) continue;
                    for (CLI::App* nested : sub->get_subcommands({}))
                        if (words.size() > 1 && nested->get_name() == words[1])
                            if (auto n = spellingsOf(nested, flag); !n.empty()) return n;
                    return spellingsOf(sub, flag);
                }
                return {flag}; // no such command: the parser says so
            });
    } catch (const turb::ValueError& e) {
        failure = reportFailure(messageWithFlags(e), kUsage);
        return std::nullopt;
    }
}

// Out of a resource another node has (memory, threads): exit 75, naming what this process may use.
int reportOutOfResources(const std::exception& e)
{
    if (dynamic_cast<const std::bad_alloc*>(&e)) {
        const double need = globals().predictedPeakBytes;
        return reportFailure("out of memory (std::bad_alloc): this process may use " +
                                 turbio::memoryLimit().describe() +
                                 (need > 0.0 ? " and the run was estimated to need about " + turbio::formatBytes(need)
                                             : std::string("; a --dry-run estimates what a run needs")) +
                                 "; no partial file is left (exit 75: worth a retry on a node with more)",
            kTempFail);
    }
    // A thread that cannot start under an address-space or task limit (std::thread's EAGAIN, TBB's
    // "pthread_create has failed") is out of a resource another node has, as std::bad_alloc is.
    const auto* sys = dynamic_cast<const std::system_error*>(&e);
    const std::string what = e.what();
    if ((sys && (sys->code() == std::errc::resource_unavailable_try_again ||
                    sys->code() == std::errc::not_enough_memory)) ||
        what.find("pthread_create") != std::string::npos)
        return reportFailure("out of memory or threads (" + what + "): this process may use " +
                                 turbio::memoryLimit().describe() + "; --threads 1 needs fewer" +
                                 " (exit 75: worth a retry on a node with more)",
            kTempFail);
    return reportFailure(std::string("unexpected: ") + what, kFailed);
}

// Runs the parsed command and turns what it throws into its message and exit code.
int runParsed(const Command& cmd)
{
    try {
        return cmd.run();
    } catch (const turb::Cancelled&) {
        return reportFailure("interrupted", kInterrupted);
    } catch (const UsageError& e) {
        return reportFailure(messageWithFlags(e), kUsage);
    } catch (const turb::TransientError& e) {
        return reportFailure(messageWithFlags(e) + " (exit 75: worth a retry)", kTempFail);
    } catch (const turb::IoError& e) {
        globals().failedOnInput = true;
        return reportFailure(messageWithFlags(e), kFailed);
    } catch (const turb::Error& e) {
        return reportFailure(messageWithFlags(e), kFailed);
    } catch (const std::exception& e) {
        return reportOutOfResources(e);
    }
}

// Parses; on --help or --version prints them (stdout, through writeData for a host). Returns -1 when the command
// line parsed, else the exit code.
int parseCommandLine(CLI::App& app, int argc, char** argv)
{
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) {
            std::ostringstream out, err;
            const int code = app.exit(e, out, err);
            writeData(out.str());
            return code == 0 ? kOk : kUsage;
        }
        return reportFailure(plainParseMessage(e.what()) + " (--help lists the options)", kUsage);
    }
    if (const std::string nan = notANumber(app); !nan.empty()) return reportFailure(nan, kUsage);
    return -1;
}

int runArgv(int argc, char** argv, bool ownProcess)
{
    ConsoleReporter console; // the entry points' words, printed (or handed to a host's hooks)
    turb::run::ReporterScope reporting(console);
    Parser parser;
    CLI::App& app = parser.app;
    int failure = kUsage;
    std::optional<std::vector<std::string>> args = expandedArguments(argc, argv, parser, failure);
    if (!args) return failure;
    std::vector<char*> argvExpanded;
    for (auto& a : *args) argvExpanded.push_back(a.data());
    argc = int(argvExpanded.size());
    argvExpanded.push_back(nullptr);
    argv = argvExpanded.data();
    // Before parsing: a parse error of a command asked for --json ends with its JSON line too.
    globals().json = std::any_of(argv + 1, argv + argc, [](const char* w) { return std::string(w) == "--json"; }) ||
                     (argc > 1 && std::string(argv[1]) == "measure");
    if (const std::string typo = checkSpelling(argc, argv, app, parser.subs); !typo.empty())
        return reportFailure(typo, kUsage);
    if (const int code = parseCommandLine(app, argc, argv); code >= 0) return code;
    if (ownProcess) installSignalHandlers();
    // Read before the command runs: its preflight and --dry-run lines come before it would set this itself.
    globals().json = asksForJson(app);
    for (auto& [sub, cmd] : parser.subs)
        if (sub->parsed()) return runParsed(*cmd);
    return kUsage;
}

} // namespace

namespace vdbturb {

int runCommandLine(const std::vector<std::string>& words, const OutputHooks* hooks)
{
    resetRunState();
    setOutputHooks(hooks);
    // The hooks point into the caller's frame: never left installed, whatever escapes.
    struct Restore
    {
        ~Restore()
        {
            releaseOutputLocks();
            setOutputHooks(nullptr);
        }
    } restore;
    std::vector<std::string> args{"vdbturb"};
    args.insert(args.end(), words.begin(), words.end());
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    return runArgv(int(args.size()), argv.data(), hooks == nullptr);
}

std::vector<OptionInfo> commandOptions(const std::string& command)
{
    resetRunState(); // the tiers of the options registered below, not of an earlier parser's
    Parser parser;
    std::vector<OptionInfo> out;
    for (const auto& [sub, cmd] : parser.subs) {
        if (cmd->name != command) continue;
        for (const CLI::Option* o : sub->get_options()) {
            OptionInfo info;
            info.longNames = o->get_lnames();
            info.falseNames = o->get_fnames();
            if (o->get_positional()) info.positional = o->get_name();
            info.flag = o->get_expected_max() == 0;
            info.multiple = o->get_expected_max() > 1;
            info.help = o->get_description();
            info.defaultValue = o->get_default_str();
            out.push_back(std::move(info));
        }
    }
    return out;
}

} // namespace vdbturb
