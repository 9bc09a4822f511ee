// The options several commands share: read and write options, and error messages in the command line's words.
#include "Commands.h"
#include "Console.h"

#include <turb/Error.h>
#include <turbio/NanoVdb.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace vdbturb {

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

namespace {

std::vector<std::string> splitCommas(const std::string& text)
{
    std::vector<std::string> parts;
    std::stringstream in(text);
    for (std::string p; std::getline(in, p, ',');)
        if (!p.empty()) parts.push_back(p);
    return parts;
}

// An enum setting's option: addEnum without knowing the enum's type.
CLI::Option* addEnumField(
    CLI::App* app, const std::string& names, const turb::run::SettingRow& row, const turb::run::EnumField& field)
{
    std::vector<std::pair<std::string, long long>> choices;
    for (const turb::run::Choice& c : row.choices) choices.emplace_back(c.name, c.value);
    return detail::addEnumOption(
        app, names, choices, field.get(), [set = field.set](long long n) { set(int(n)); }, row.help);
}

// A number's range check: finiteIn's and finitePositive's messages where they fit, else the row's own.
CLI::Option* checkRange(CLI::Option* o, const turb::run::SettingRow& row)
{
    if (!row.checked()) return o;
    if (!row.lowOpen) return o->check(finiteIn(row.lo, std::isinf(row.hi) ? 1e30 : row.hi));
    if (row.lo == 0.0 && std::isinf(row.hi)) return o->check(finitePositive());
    return o->check(CLI::Validator(
        [&row](std::string& text) {
            double v = 0.0;
            if (!parseNumber(text, v)) return std::string("must be a number");
            const std::string why = row.whyInvalid(v);
            return why.empty() ? why : why.substr(why.find(' ') + 1); // without the key: CLI11 names the option
        },
        ""));
}

// A number's checks: the row's own (`validate`: a range with gaps, a message in the setting's words) where it has
// one, else an int's only values (`choices`) or its range: CLI11's INT in [LO - HI] where both ends are finite and
// closed, else finiteIn's or finitePositive's.
CLI::Option* checkNumber(CLI::Option* o, const turb::run::SettingRow& row, bool integer)
{
    if (row.validate)
        return o->check(CLI::Validator([&row](std::string& text) { return row.validate(text); }, row.typeName));
    if (integer && !row.choices.empty()) {
        std::vector<int> values;
        for (const turb::run::Choice& c : row.choices) values.push_back(c.value);
        return o->check(CLI::IsMember(values));
    }
    if (integer && row.checked() && !row.lowOpen && std::isfinite(row.hi))
        return o->check(CLI::Range(int(std::max(row.lo, -2e9)), int(std::min(row.hi, 2e9))));
    return checkRange(o, row);
}

// A text setting: its allowed values, its own check and its form in --help.
CLI::Option* checkText(CLI::Option* o, const turb::run::SettingRow& row)
{
    if (!row.oneOf.empty()) o->check(CLI::IsMember(row.oneOf));
    if (row.validate) o->check(CLI::Validator([&row](std::string& text) { return row.validate(text); }, row.typeName));
    return o;
}

// One row's option, bound to its field by the field's type.
CLI::Option* addSettingRow(CLI::App* app, const turb::run::SettingRow& row, const turb::run::FieldRef& ref)
{
    std::string names;
    for (const std::string& a : splitCommas(row.alias)) names += "--" + a + ",";
    names += "--" + row.key;
    if (auto* b = std::get_if<bool*>(&ref)) {
        if (row.flag) return setting(app->add_flag(names, **b, row.help), row.key);
        return boolSetting(app, names, **b, row.help, row.key);
    }
    if (auto* i = std::get_if<int*>(&ref))
        return setting(checkNumber(app->add_option(names, **i, row.help), row, true), row.key);
    if (auto* u = std::get_if<std::uint64_t*>(&ref)) return setting(app->add_option(names, **u, row.help), row.key);
    if (auto* f = std::get_if<float*>(&ref))
        return setting(checkNumber(app->add_option(names, **f, row.help), row, false), row.key);
    if (auto* d = std::get_if<double*>(&ref))
        return setting(checkNumber(app->add_option(names, **d, row.help), row, false), row.key);
    if (auto* s = std::get_if<std::string*>(&ref))
        return setting(checkText(app->add_option(names, **s, row.help), row), row.key);
    return setting(addEnumField(app, names, row, std::get<turb::run::EnumField>(ref)), row.key);
}

// An old spelling: a flag that sets its keys to its value, or an option whose value sets them all.
void addOldSpelling(CLI::App* app, const BoundSettings& rows, const turb::run::OldSpelling& old)
{
    BoundSettings sets;
    for (const std::string& key : splitCommas(old.keys))
        for (const auto& r : rows)
            if (r.first->key == key) sets.push_back(r);
    const auto assign = [sets](const std::string& text) {
        for (const auto& [row, ref] : sets) turb::run::setFieldText(*row, ref, text);
    };
    const std::string help = old.help.empty() ? old.keys + " = " + old.value : old.help;
    if (!old.value.empty()) {
        legacy(app->add_flag_function(
                   "--" + old.name, [assign, v = old.value](int64_t) { assign(v); }, help),
            old.keys, old.value);
        return;
    }
    legacy(app->add_option_function<std::string>("--" + old.name, assign, help)
               ->check(parsedBy(
                   [sets](const std::string& t) { turb::run::parseSettingValue(*sets.front().first, t); }, "VALUE")),
        old.keys);
}

} // namespace

void addSettingRows(CLI::App* app, const BoundSettings& rows, const std::vector<turb::run::OldSpelling>& old)
{
    for (const turb::run::OldSpelling& o : old) addOldSpelling(app, rows, o);
    for (const auto& [row, ref] : rows) addSettingRow(app, *row, ref);
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

} // namespace vdbturb
