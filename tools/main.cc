// vdbturb's command line, run by main() (cli_main.cc) and the Python module. Table-driven: see Commands.h.
#include "CommandLine.h"
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"

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
#include <regex>
#include <sstream>

using namespace vdbturb;

namespace vdbturb {

void warnIfClippedAway(
    const turb::Frame& frame, const turbio::WriteOptions& options, const std::string& path, bool& warned)
{
    if (warned || !(options.densityTolerance > 0.0f) || !frame.hasDensity()) return;
    const auto& v = frame.density.values();
    const float peak = v.empty() ? 0.0f : *std::max_element(v.begin(), v.end());
    if (!(peak > 0.0f) || peak > options.densityTolerance) return;
    warned = true;
    std::ostringstream os;
    os << path << ": --clipping " << options.densityTolerance << " is at or above every density value (peak " << peak
       << "): the density grid is written empty";
    logWarning(os.str());
}

// CLI11's range checks let NaN through (every comparison with it is false), and a NaN setting would only fail, or
// quietly misbehave, deep in a run: refused for every option of every command, after parsing.
std::string notANumber(const CLI::App& app)
{
    for (const CLI::Option* o : app.get_options()) {
        // Numbers only: a file or pattern may be called "nan".
        if (o->get_type_name().rfind("FLOAT", 0) != 0 && o->get_type_name().rfind("DOUBLE", 0) != 0) continue;
        for (const std::string& r : o->results()) {
            char* end = nullptr;
            const double v = std::strtod(r.c_str(), &end);
            if (end != r.c_str() && *end == '\0' && std::isnan(v)) return o->get_name() + ": " + r + " is not a number";
        }
    }
    for (const CLI::App* sub : app.get_subcommands())
        if (const std::string m = notANumber(*sub); !m.empty()) return m;
    return {};
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

CLI::Validator parsedBy(std::function<void(const std::string&)> parse, const std::string& name)
{
    return CLI::Validator(
        [parse](std::string& v) {
            try {
                parse(v);
            } catch (const turb::Error& e) {
                return std::string(e.what());
            }
            return std::string();
        },
        name);
}

CLI::Validator frameListCheck()
{
    return parsedBy([](const std::string& v) { turbio::parseFrameList(v); }, "FRAMES");
}

void addReadOptions(CLI::App* app, turbio::ReadOptions& opt, const std::string& prefix)
{
    const std::string p = prefix.empty() ? "--" : "--" + prefix + "-";
    // An empty name cannot select an unnamed grid (it means "the default" everywhere else): say what does.
    const auto selector = [p](const char* what) {
        return CLI::Validator(
            [p, what](std::string& v) {
                return v.empty() ? p + what +
                                       " '': give a grid name, OpenVDB's NAME[N] ('[0]' is the first unnamed grid) "
                                       "or '#N' (the N-th grid as `vdbturb info` lists them)"
                                 : std::string();
            },
            "GRID");
    };
    app->add_option(p + "density-grid", opt.densityGrid,
           "Density grid: NAME, NAME[N] or #N as `vdbturb info` numbers grids (docs/io.md); empty: density, "
           "density_noise")
        ->check(selector("density-grid"))
        ->group(kGroupInput);
    app->add_option(p + "vel-grid", opt.velocityGrid,
           "Velocity grid: as --" + prefix + (prefix.empty() ? "" : "-") +
               "density-grid, or the stem of NAME.x/.y/.z; empty: vel, velocity, v")
        ->check(selector("vel-grid"))
        ->group(kGroupInput);
    app->add_option(p + "fps", opt.fps,
           "Frames per second of the shot, for the default time per frame: 23.976 or 24000/1001 (0: 24, with a "
           "warning)")
        ->transform(rationalNumber())
        ->check(finiteIn(0.0))
        ->group(kGroupInput);
    setting(addEnum<turbio::VelocityUnits>(app, p + "vel-units", opt.velocityUnits,
                {{"auto", turbio::VelocityUnits::Auto}, {"world", turbio::VelocityUnits::World},
                    {"cells", turbio::VelocityUnits::Cells}, {"frame", turbio::VelocityUnits::Frame}},
                "Velocity units: world (per second), cells (grid cells per time unit, Blender), frame (world units per "
                "frame), auto (detect)"),
        p.substr(2) + "vel-units");
    setting(
        app->add_option(p + "dt", opt.dt,
               "Time per frame in the velocity's time unit (0: from metadata or the writer's convention, docs/io.md)")
            ->check(finiteIn(0.0)),
        p.substr(2) + "dt");
    setting(app->add_flag_function(
                p + "no-crop", [&opt](int64_t) { opt.cropToSmoke = false; },
                "Hold the grids' whole active boxes, stray voxels included (default: the smoke and a margin)"),
        p.substr(2) + "no-crop");
    // Strays a frame's read leaves out are said once per input, as the header scan's are (reportTiming's key): the
    // scan sees them only where the density's box is far larger than its voxels.
    const std::string role = prefix.empty() ? "cache" : prefix;
    opt.strayNote = [role](const std::string& note) { warnOnce("strays " + role, role + " " + note); };
    opt.readNote = [role](const std::string& path, const std::string& note) {
        warnOnce("read note " + role + " " + note, role + " " + path + ": " + note);
    };
    setting(app->add_flag(p + "keep-isolated", opt.keepIsolated,
                "Hold stray voxels far from the smoke (and a Blender cache's voxels outside its simulation box) "
                "instead of ignoring them; the held box then spans them"),
        p.substr(2) + "keep-isolated");
    setting(app->add_option(p + "crop-margin", opt.cropMargin, "Voxels kept around the smoke when cropping")
                ->check(finiteIn(0.0)),
        p.substr(2) + "crop-margin");
}

turbio::WriteOptions upResWriteDefaults()
{
    turbio::WriteOptions w;
    w.halfFloat = true;
    w.velocityMargin = kVelocityMarginAuto;
    return w;
}

void addVelocityWriteOptions(CLI::App* app, turbio::WriteOptions& opt)
{
    app->add_option("--velocity-margin", opt.velocityMargin,
           "Write velocity only within N output voxels of the smoke (1 covers motion blur; re-advection needs about "
           "the smoke's travel a frame); -1 = the whole box; auto (-2, the default) = one target voxel, the ratio: "
           "measure's numbers then stay within 1% of the whole frame's. --resume stays exact")
        ->transform(CLI::Transformer(std::map<std::string, int>{{"auto", kVelocityMarginAuto}}))
        ->check(CLI::Validator(
            [](std::string& text) -> std::string {
                double v = 0.0;
                const bool ok = parseNumber(text, v) && v == std::floor(v) && v >= kVelocityMarginAuto && v <= 64.0;
                return ok ? std::string()
                          : "must be auto, -1 (the whole box) or a number of voxels from 0 to 64, not '" + text + "'";
            },
            "auto|-1|0..64"))
        ->group(kGroupOutput);
    app->add_option("--vel-voxel-scale", opt.velocityVoxelScale,
           "Write vel on an N times coarser lattice, each voxel its block's mean (Houdini's Velocity Voxel Scale): "
           "an eighth of the velocity bytes at 2, enough for motion blur; measure then sees no finest-octave detail")
        ->check(CLI::Range(1, 8))
        ->group(kGroupOutput);
    app->add_flag_function(
           "--no-velocity", [&opt](int64_t) { opt.writeVelocity = false; },
           "Write no velocity grid (density, temperature and flame only, as Blender's noise cache)")
        ->group(kGroupOutput);
}

void addWriteOptions(CLI::App* app, turbio::WriteOptions& opt)
{
    addEnum<turbio::WriteStyle>(app, "--style", opt.style,
        {{"houdini", turbio::WriteStyle::Houdini}, {"blender", turbio::WriteStyle::Blender}},
        "Output grid convention: houdini (vel, world units) or blender (staggered vel in cells)")
        ->group(kGroupOutput);
    app->add_flag("--no-clobber", opt.noClobber, "Never replace an existing output file")->group(kGroupOutput);
    app->add_flag("--half,!--full-float", opt.halfFloat,
           std::string("Store floats as 16-bit halves (smaller files; ~3 significant digits), or as 32-bit floats (") +
               (opt.halfFloat ? "default: --half" : "default: --full-float") + ")")
        ->group(kGroupOutput);
    app->add_option("--clipping", opt.densityTolerance,
           "Density at or below this is written as empty space, as Blender's Clipping (0: every non-zero voxel)")
        ->check(CLI::Validator(
            [](std::string& text) -> std::string {
                double v = 0.0; // CLI11's number checks let NaN through
                return parseNumber(text, v) && std::isfinite(v) && v >= 0.0 ? std::string()
                                                                            : "must be a finite density >= 0";
            },
            "DENSITY>=0"))
        ->group(kGroupOutput);
}

void addFormatOptions(CLI::App* app, turbio::WriteOptions& opt)
{
    addEnum<turbio::OutputFormat>(app, "--format", opt.format,
        {{"auto", turbio::OutputFormat::Auto}, {"vdb", turbio::OutputFormat::Vdb},
            {"nanovdb", turbio::OutputFormat::NanoVdb}},
        "Output file format: auto (by --out's extension: .nvdb is NanoVDB), vdb (OpenVDB) or nanovdb (NanoVDB, as GPU "
        "renderers load it; docs/nanovdb.md)")
        ->group(kGroupOutput);
    addEnum<turbio::NanoQuantization>(app, "--nanovdb-quant", opt.nanoQuantization,
        {{"float", turbio::NanoQuantization::Float}, {"fp16", turbio::NanoQuantization::Fp16},
            {"fp8", turbio::NanoQuantization::Fp8}},
        "NanoVDB float grids (density, temperature, flame): float (exact), fp16 or fp8 (16 or 8 bits a voxel, each 8^3 "
        "leaf quantised over its range: off by at most range/131070 or range/510); vel is always Vec3f")
        ->group(kGroupOutput);
}

void checkOutputFormat(const turbio::WriteOptions& w, const std::string& out, const std::string& resumeFlag)
{
    const bool nvdbName = turbio::outputFormatFor(out) == turbio::OutputFormat::NanoVdb;
    if (w.format == turbio::OutputFormat::Vdb && nvdbName)
        throw UsageError("--format vdb but --out '" + out + "' ends in .nvdb: give a .vdb name, or --format nanovdb");
    if (w.format == turbio::OutputFormat::NanoVdb && !nvdbName && out.size() >= 4 &&
        out.compare(out.size() - 4, 4, ".vdb") == 0)
        throw UsageError("--format nanovdb but --out '" + out + "' ends in .vdb: give a .nvdb name");
    const bool nano = turbio::outputFormatFor(out, w.format) == turbio::OutputFormat::NanoVdb;
    if (!nano) {
        if (w.nanoQuantization != turbio::NanoQuantization::Float)
            throw UsageError(std::string("--nanovdb-quant ") + turbio::quantizationName(w.nanoQuantization) +
                             " applies to NanoVDB output; --out '" + out +
                             "' is written as OpenVDB (--half stores 16-bit floats there)");
        return;
    }
    if (w.style == turbio::WriteStyle::Blender)
        throw UsageError("--style blender cannot be written as NanoVDB (Blender's placement and domain live in "
                         "metadata NanoVDB cannot hold; Blender reads OpenVDB): write .vdb, or the default style");
    if (!resumeFlag.empty())
        throw UsageError(resumeFlag +
                         " needs the settings and state a frame records, and NanoVDB files hold no vdbturb metadata: "
                         "write .vdb, and turn the finished frames into NanoVDB with vdbturb convert");
}

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

namespace {

// A check for a finite number that `accept` takes; "nan" is named as not a number, the rest get "must be a finite
// TEXT".
CLI::Validator finiteNumber(std::function<bool(double)> accept, const std::string& text)
{
    return CLI::Validator(
        [accept, text](std::string& s) -> std::string {
            double v = 0.0;
            if (parseNumber(s, v) && std::isnan(v)) return s + " is not a number";
            return parseNumber(s, v) && std::isfinite(v) && accept(v) ? std::string() : "must be a finite " + text;
        },
        text);
}

} // namespace

CLI::Validator finiteIn(double lo, double hi)
{
    const auto trimmed = [](double v) { // 0 -> "0", 1e-12 -> "1e-12", 0.999 -> "0.999"
        char b[32];
        std::snprintf(b, sizeof(b), "%g", v);
        return std::string(b);
    };
    const std::string text = hi >= 1e30 ? "NUMBER>=" + trimmed(lo) + " (at most " + trimmed(hi) + ")"
                                        : "NUMBER in [" + trimmed(lo) + ", " + trimmed(hi) + "]";
    return finiteNumber([lo, hi](double v) { return v >= lo && v <= hi; }, text);
}

CLI::Validator rationalNumber()
{
    // Frame rates come as ratios in editorial and in OpenTimelineIO (24000/1001): the ratio becomes its value, which
    // the option's range check then reads; anything else is left to that check.
    return CLI::Validator(
        [](std::string& text) {
            const auto slash = text.find('/');
            if (slash == std::string::npos) return std::string();
            const auto number = [](const std::string& t, double& v) {
                char* end = nullptr;
                v = std::strtod(t.c_str(), &end);
                return !t.empty() && end == t.c_str() + t.size() && std::isfinite(v);
            };
            double n = 0.0, d = 0.0;
            if (!number(text.substr(0, slash), n) || !number(text.substr(slash + 1), d) || !(d > 0.0))
                return "'" + text + "' is not a ratio of two numbers such as 24000/1001";
            char b[40];
            std::snprintf(b, sizeof(b), "%.17g", n / d);
            text = b;
            return std::string();
        },
        "", "");
}

CLI::Validator finitePositive()
{
    return finiteNumber([](double v) { return v > 0.0; }, "NUMBER>0");
}

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
int runArgv(int argc, char** argv, bool ownProcess)
{
    Parser parser;
    CLI::App& app = parser.app;
    const auto& subs = parser.subs;
    // --settings files become command-line options before anything reads argv.
    std::vector<std::string> args;
    try {
        args = expandSettingsFiles(std::vector<std::string>(argv, argv + argc),
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
        return reportFailure(messageWithFlags(e), kUsage);
    }
    std::vector<char*> argvExpanded;
    for (auto& a : args) argvExpanded.push_back(a.data());
    argc = int(argvExpanded.size());
    argvExpanded.push_back(nullptr);
    argv = argvExpanded.data();
    // Before parsing: a parse error of a command asked for --json ends with its JSON line too.
    globals().json = std::any_of(argv + 1, argv + argc, [](const char* w) { return std::string(w) == "--json"; }) ||
                     (argc > 1 && std::string(argv[1]) == "measure");
    if (const std::string typo = checkSpelling(argc, argv, app, subs); !typo.empty())
        return reportFailure(typo, kUsage);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) { // --help, --version: stdout, through writeData for a host
            std::ostringstream out, err;
            const int code = app.exit(e, out, err);
            writeData(out.str());
            return code == 0 ? kOk : kUsage;
        }
        return reportFailure(plainParseMessage(e.what()) + " (--help lists the options)", kUsage);
    }
    if (const std::string nan = notANumber(app); !nan.empty()) return reportFailure(nan, kUsage);
    if (ownProcess) installSignalHandlers();
    // Read before the command runs: its preflight and --dry-run lines come before it would set this itself.
    globals().json = asksForJson(app);
    for (auto& [sub, cmd] : subs) {
        if (!sub->parsed()) continue;
        try {
            return cmd->run();
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
        } catch (const std::bad_alloc&) {
            const double need = globals().predictedPeakBytes;
            return reportFailure(
                "out of memory (std::bad_alloc): this process may use " + turbio::memoryLimit().describe() +
                    (need > 0.0 ? " and the run was estimated to need about " + turbio::formatBytes(need)
                                : std::string("; a --dry-run estimates what a run needs")) +
                    "; no partial file is left (exit 75: worth a retry on a node with more)",
                kTempFail);
        } catch (const std::exception& e) {
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
    }
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
