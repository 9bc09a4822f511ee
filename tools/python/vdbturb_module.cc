// The Python module vdbturb (docs/python.md). The commands run the command line's own code in this process
// (runCommandLine): the same parser fills the same settings, so keywords have the CLI's names and defaults and the
// files written are the CLI's, bit for bit. measure_arrays calls libturb's measureFrame on numpy arrays.
#include "CommandLine.h"
#include "Console.h"

#include <turb/Error.h>
#include <turb/Measure.h>
#include <turb/run/Measure.h>
#include <turb/run/Preview.h>
#include <turb/run/Settings.h>
#include <turb/run/Sim.h>
#include <turb/run/Transfer.h>
#include <turbio/Vdb.h>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <dlfcn.h>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace py = pybind11;
using vdbturb::OutputHooks;

namespace {

// The exception and warning classes, made at import and kept for the interpreter's life.
struct Classes
{
    PyObject *error = nullptr, *usage = nullptr, *input = nullptr, *temporary = nullptr, *cancelled = nullptr,
             *warning = nullptr;
};
Classes gClasses;

// The command line keeps its state in process globals (Console.h): one at a time. Taken only without the GIL, so
// that a run waiting for the GIL in its progress callback never waits on a thread that waits for this.
std::mutex gRunMutex;

// What a command line printed, gathered while it runs without the GIL, handed to Python with it.
struct Capture
{
    std::mutex mutex;
    std::vector<std::string> data;                                   // stdout documents
    std::vector<std::pair<OutputHooks::Level, std::string>> pending; // info and -v lines for `logging`
    std::vector<std::string> errors, warnings;
};

// Info lines go to logging.getLogger("vdbturb") (silent unless the host configures logging), -v lines at DEBUG.
void handOverLog(Capture& c)
{
    std::vector<std::pair<OutputHooks::Level, std::string>> lines;
    {
        std::lock_guard<std::mutex> lock(c.mutex);
        lines.swap(c.pending);
    }
    if (lines.empty()) return;
    py::object logger = py::module_::import("logging").attr("getLogger")("vdbturb");
    for (const auto& [level, text] : lines) logger.attr(level == OutputHooks::Level::Verbose ? "debug" : "info")(text);
}

// Each stdout document as Python data: JSON parsed, anything else (sim --list's table) as text.
py::list parseDocuments(const std::vector<std::string>& docs)
{
    py::object loads = py::module_::import("json").attr("loads");
    py::list out;
    for (const std::string& d : docs) {
        try {
            out.append(loads(d));
        } catch (py::error_already_set&) {
            out.append(py::str(d));
        }
    }
    return out;
}

[[noreturn]] void raiseFailure(
    int code, bool onInput, const Capture& c, py::list docs, std::optional<py::error_already_set>& cause)
{
    PyObject* cls = code == vdbturb::kInterrupted ? gClasses.cancelled
                    : code == vdbturb::kUsage     ? gClasses.usage
                    : code == vdbturb::kTempFail  ? gClasses.temporary
                    : onInput                     ? gClasses.input
                                                  : gClasses.error;
    std::string message;
    for (const std::string& e : c.errors) message += (message.empty() ? "" : "\n") + e;
    if (message.empty()) message = "vdbturb exited with " + std::to_string(code);
    py::object exc = py::reinterpret_borrow<py::object>(cls)(message);
    exc.attr("exit_code") = code;
    for (const char* k : {"file", "frame", "grid"}) exc.attr(k) = py::none();
    // The command's JSON error line names the file, frame and grid; the rest is what it had made by then.
    py::list result;
    for (py::handle d : docs) {
        if (py::isinstance<py::dict>(d) && d.contains("error") && d.contains("exit")) {
            for (const char* k : {"file", "frame", "grid"}) exc.attr(k) = d[k];
            continue;
        }
        result.append(d);
    }
    exc.attr("result") = result;
    if (cause) exc.attr("__cause__") = cause->value();
    PyErr_SetObject(cls, exc.ptr());
    throw py::error_already_set();
}

// Runs one command line; returns its stdout documents, or raises as docs/python.md says.
py::list runWords(const std::vector<std::string>& words, const py::object& progress)
{
    Capture cap;
    std::optional<py::error_already_set> raised; // from the callback, or a Ctrl-C seen at a frame's end
    OutputHooks hooks;
    hooks.data = [&cap](const std::string& text) {
        std::lock_guard<std::mutex> lock(cap.mutex);
        cap.data.push_back(text);
    };
    hooks.log = [&cap](OutputHooks::Level level, const std::string& text) {
        std::lock_guard<std::mutex> lock(cap.mutex);
        if (level == OutputHooks::Level::Error) cap.errors.push_back(text);
        else if (level == OutputHooks::Level::Warning) cap.warnings.push_back(text);
        else cap.pending.emplace_back(level, text);
    };
    // Called where the CLI reports a frame: a stop asked here drops the next frame whole, as Ctrl-C does.
    // Nothing Python raises here may unwind through the command: it becomes the stop's reason.
    hooks.frame = [&](int frame, int done, int total) {
        py::gil_scoped_acquire gil;
        if (raised) return;
        try {
            // Ctrl-C in the host: Python runs its handler only now, while it holds the GIL.
            if (PyErr_CheckSignals() != 0) throw py::error_already_set();
            handOverLog(cap);
            if (!progress.is_none() && progress(frame, done, total).ptr() == Py_False) vdbturb::requestInterrupt();
        } catch (py::error_already_set& e) {
            raised.emplace(std::move(e));
            vdbturb::requestInterrupt();
        } catch (const std::exception& e) { // pybind11's own (a cast that failed)
            PyErr_SetString(PyExc_RuntimeError, e.what());
            raised.emplace();
            vdbturb::requestInterrupt();
        }
    };
    int code = 0;
    bool onInput = false;
    {
        py::gil_scoped_release nogil;
        std::lock_guard<std::mutex> one(gRunMutex);
        code = vdbturb::runCommandLine(words, &hooks);
        onInput = vdbturb::globals().failedOnInput;
    }
    handOverLog(cap);
    py::list docs = parseDocuments(cap.data);
    py::object warn = py::module_::import("warnings").attr("warn");
    for (const std::string& w : cap.warnings) warn(w, py::handle(gClasses.warning));
    if (raised && (code == 0 || raised->matches(PyExc_KeyboardInterrupt))) {
        // A finished run keeps its frames, but the callback's own error is not swallowed; Ctrl-C stays Ctrl-C.
        raised->restore();
        throw py::error_already_set();
    }
    if (code != 0) raiseFailure(code, onInput, cap, docs, raised);
    return docs;
}

// ---------------------------------------------------------------------------------------------------------------
// Keywords -> command-line words, through the command's own parser.

struct Spec
{
    std::string name;         // the long name given on the command line, without "--"
    std::string trueName;     // a flag: the name that sets it (--half)
    std::string falseName;    // a flag: the name that clears it (--full-float), if any
    bool isFalseName = false; // `name` is the clearing one
    bool flag = false, multiple = false, positional = false;
    std::string help, defaultValue;
};
// A command's keywords, and whether it takes --json.
struct Specs : std::map<std::string, Spec>
{
    bool json = false;
};

// The command line's own options, or the module's: asking for help or settings files prints instead of running,
// JSON is always asked for, and `progress` is the callback.
bool reserved(const std::string& keyword)
{
    for (const char* r : {"help", "help_all", "print_settings", "json", "version", "progress"})
        if (keyword == r) return true;
    return false;
}

std::string keywordOf(std::string name)
{
    for (char& c : name)
        if (c == '-' || c == '.') c = '_';
    return name;
}

const Specs& specsOf(const std::string& command)
{
    static std::map<std::string, Specs> cache; // touched with the GIL held only
    if (auto it = cache.find(command); it != cache.end()) return it->second;
    std::vector<vdbturb::OptionInfo> options;
    {
        py::gil_scoped_release nogil;
        std::lock_guard<std::mutex> one(gRunMutex);
        options = vdbturb::commandOptions(command);
    }
    Specs specs;
    for (const auto& o : options) {
        Spec s;
        s.flag = o.flag;
        s.multiple = o.multiple;
        s.help = o.help;
        s.defaultValue = o.defaultValue;
        if (!o.positional.empty()) {
            s.positional = true;
            s.name = o.positional;
            specs.emplace(keywordOf(o.positional), s);
            continue;
        }
        for (const auto& n : o.longNames) {
            const bool negation = std::find(o.falseNames.begin(), o.falseNames.end(), n) != o.falseNames.end();
            if (negation) {
                if (s.falseName.empty()) s.falseName = n;
            } else if (s.trueName.empty()) {
                s.trueName = n;
            }
        }
        for (const auto& n : o.longNames) {
            if (n == "json") specs.json = true;
            Spec named = s;
            named.name = n;
            named.isFalseName = n == s.falseName;
            if (!reserved(keywordOf(n))) specs.emplace(keywordOf(n), named); // the first of a keyword wins
        }
    }
    return cache.emplace(command, std::move(specs)).first->second;
}

bool isSequence(py::handle v)
{
    return !py::isinstance<py::str>(v) && !py::isinstance<py::bytes>(v) && !py::isinstance<py::dict>(v) &&
           (py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v) ||
               py::isinstance(v, py::module_::import("builtins").attr("range")));
}

// One value as the command line spells it: numbers as Python prints them (shortest exact float), paths by os.fspath.
std::string valueText(py::handle v, const std::string& keyword)
{
    if (py::isinstance<py::str>(v)) return v.cast<std::string>();
    if (py::isinstance<py::bool_>(v)) return v.cast<bool>() ? "true" : "false";
    if (py::hasattr(v, "__fspath__")) return py::str(py::module_::import("os").attr("fsdecode")(v));
    if (py::hasattr(v, "__index__")) return py::str(py::module_::import("operator").attr("index")(v));
    if (py::isinstance<py::float_>(v) || py::hasattr(v, "__float__"))
        return py::repr(py::float_(py::reinterpret_borrow<py::object>(v)));
    throw py::type_error(keyword + "=: expected a string, number, path or bool, not " +
                         std::string(py::str(py::type::of(v).attr("__name__"))));
}

std::vector<std::string> commandWords(
    const std::string& command, const std::vector<py::object>& positionals, const py::kwargs& kwargs)
{
    const Specs& specs = specsOf(command);
    std::vector<std::string> words{command}, options;
    for (const py::object& p : positionals) words.push_back(valueText(p, "positional"));
    for (auto item : kwargs) {
        const std::string key = py::str(item.first);
        const py::handle value = item.second;
        const auto it = specs.find(key);
        if (it == specs.end()) {
            std::vector<std::string> names;
            for (const auto& [k, s] : specs) names.push_back(k);
            const std::string near = turbio::nearestName(key, names);
            throw py::type_error(command + "() got an unexpected keyword argument '" + key + "'" +
                                 (near.empty() ? "" : "; did you mean '" + near + "'?") + " (vdbturb.options('" +
                                 command + "') lists them)");
        }
        const Spec& s = it->second;
        if (value.is_none()) continue; // the command's default
        if (s.positional) {
            if (isSequence(value))
                for (py::handle v : value) words.push_back(valueText(v, key));
            else words.push_back(valueText(value, key));
        } else if (s.flag) {
            if (!py::isinstance<py::bool_>(value))
                throw py::type_error(key + "=: a flag takes True or False, not " +
                                     std::string(py::str(py::type::of(value).attr("__name__"))));
            // False is the other polarity where the flag has one (half=False: --full-float), else the default.
            const bool on = value.cast<bool>() != s.isFalseName;
            const std::string& name = on ? s.trueName : s.falseName;
            if (!name.empty()) options.push_back("--" + name);
        } else if (isSequence(value)) {
            if (s.multiple) {
                for (py::handle v : value) options.push_back("--" + s.name + "=" + valueText(v, key));
            } else { // one value made of several: frames=[1, 5, 9], patch_origin=(0, 0, 4)
                std::string joined;
                for (py::handle v : value) joined += (joined.empty() ? "" : ",") + valueText(v, key);
                options.push_back("--" + s.name + "=" + joined);
            }
        } else {
            options.push_back("--" + s.name + "=" + valueText(value, key));
        }
    }
    words.insert(words.end(), options.begin(), options.end());
    if (specs.json) words.push_back("--json");
    return words;
}

// ---------------------------------------------------------------------------------------------------------------
// Settings objects: a job's second tier (turb/run/Settings.h) as a Python object, keywords as the CLI's keys.

template<typename Job>
struct SettingsObject
{
    Job job;                        ///< its fields hold the values, defaults included
    std::vector<std::string> given; ///< keys set, in the order first set: what the command line is given
};

py::object fieldValue(const turb::run::SettingRow& row, const turb::run::FieldRef& ref)
{
    const std::string text = turb::run::fieldText(row, ref);
    if (!row.choices.empty() || std::holds_alternative<std::string*>(ref)) return py::str(text);
    if (std::holds_alternative<bool*>(ref)) return py::bool_(text == "true");
    if (std::holds_alternative<int*>(ref) || std::holds_alternative<std::uint64_t*>(ref))
        return py::int_(py::str(text));
    return py::float_(std::strtod(text.c_str(), nullptr));
}

template<typename Job>
const turb::run::Setting<Job>& settingOf(
    const turb::run::SettingsTable<Job>& table, const std::string& keyword, const char* className)
{
    std::vector<std::string> names;
    for (const turb::run::Setting<Job>& s : table) { // the key, or an older spelling as transfer()'s keywords take
        if (keywordOf(s.key) == keyword ||
            ("," + keywordOf(s.alias) + ",").find("," + keyword + ",") != std::string::npos)
            return s;
        names.push_back(keywordOf(s.key));
    }
    const std::string near = turbio::nearestName(keyword, names);
    throw py::attribute_error(std::string(className) + " has no setting '" + keyword + "'" +
                              (near.empty() ? "" : "; did you mean '" + near + "'?"));
}

// Sets a setting from Python: text and enums as str, bools as bool, ints as int, numbers as float; the value then
// goes through the command line's own reading and checks (a float as Python prints it: its shortest exact form).
template<typename Job>
void setSetting(SettingsObject<Job>& o, const turb::run::Setting<Job>& s, py::handle value)
{
    const turb::run::FieldRef ref = s.field(o.job);
    const std::string keyword = keywordOf(s.key);
    const auto expect = [&](bool ok, const char* want) {
        if (!ok)
            throw py::type_error(
                keyword + ": expected " + want + ", not " + std::string(py::str(py::type::of(value).attr("__name__"))));
    };
    const bool isBool = py::isinstance<py::bool_>(value);
    std::string text;
    if (!s.choices.empty() || std::holds_alternative<std::string*>(ref)) {
        expect(py::isinstance<py::str>(value), "a str");
        text = value.cast<std::string>();
    } else if (std::holds_alternative<bool*>(ref)) {
        expect(isBool, "a bool");
        text = value.cast<bool>() ? "true" : "false";
    } else if (std::holds_alternative<int*>(ref) || std::holds_alternative<std::uint64_t*>(ref)) {
        expect(!isBool && py::hasattr(value, "__index__"), "an int");
        text = py::str(py::module_::import("operator").attr("index")(value));
    } else {
        expect(!isBool && py::hasattr(value, "__float__"), "a number");
        text = py::repr(py::float_(py::reinterpret_borrow<py::object>(value)));
    }
    try {
        s.setText(o.job, text);
    } catch (const turb::Error& e) {
        std::string message = e.what(); // "seams.gamma: -1 must be..." in Python's spelling
        if (message.rfind(s.key + ":", 0) == 0) message = keyword + message.substr(s.key.size());
        throw py::value_error(message);
    }
    if (std::find(o.given.begin(), o.given.end(), s.key) == o.given.end()) o.given.push_back(s.key);
}

// The command-line words of what was set: --KEY=VALUE each.
template<typename Job>
std::vector<std::string> settingsWords(const SettingsObject<Job>& o, const turb::run::SettingsTable<Job>& table)
{
    std::vector<std::string> words;
    const Job& job = o.job;
    for (const std::string& key : o.given)
        for (const turb::run::Setting<Job>& s : table)
            if (s.key == key) words.push_back("--" + key + "=" + s.text(job));
    return words;
}

// vdbturb.NAME: a settings class over `table`.
template<typename Job>
void defineSettingsClass(py::module_& m, const char* name, const turb::run::SettingsTable<Job>& table, const char* doc)
{
    using Object = SettingsObject<Job>;
    py::class_<Object>(m, name, doc)
        .def(py::init([&table, name](py::kwargs kw) {
            Object o;
            for (auto item : kw) setSetting(o, settingOf(table, py::str(item.first), name), item.second);
            return o;
        }))
        .def("__getattr__",
            [&table, name](Object& o, const std::string& k) {
                const turb::run::Setting<Job>& s = settingOf(table, k, name);
                return fieldValue(s, s.field(o.job));
            })
        .def("__setattr__", [&table, name](Object& o, const std::string& k,
                                py::handle v) { setSetting(o, settingOf(table, k, name), v); })
        .def("__dir__",
            [&table](const Object&) {
                py::list keys;
                for (const turb::run::Setting<Job>& s : table) keys.append(keywordOf(s.key));
                return keys;
            })
        .def(
            "to_dict",
            [&table](Object& o, bool all) {
                py::dict d;
                for (const turb::run::Setting<Job>& s : table)
                    if (all || std::find(o.given.begin(), o.given.end(), s.key) != o.given.end())
                        d[py::str(keywordOf(s.key))] = fieldValue(s, s.field(o.job));
                return d;
            },
            py::arg("all") = false,
            "The settings given (all=True: every setting, defaults included) as {keyword: value}.")
        .def(
            "args",
            [&table](const Object& o) {
                py::list words;
                for (const std::string& w : settingsWords(o, table)) words.append(w);
                return words;
            },
            "The command-line options of the settings given: ['--seams.gamma=4', ...].")
        .def("__repr__",
            [&table, name](Object& o) {
                std::string text;
                for (const turb::run::Setting<Job>& s : table)
                    if (std::find(o.given.begin(), o.given.end(), s.key) != o.given.end())
                        text += (text.empty() ? "" : ", ") + keywordOf(s.key) + "=" +
                                std::string(py::repr(fieldValue(s, s.field(o.job))));
                return std::string(name) + "(" + text + ")";
            })
        .def_static(
            "describe",
            [&table]() {
                py::dict d;
                Job defaults;
                for (const turb::run::Setting<Job>& s : table) {
                    py::dict row(py::arg("option") = "--" + s.key, py::arg("help") = s.help,
                        py::arg("default") = fieldValue(s, s.field(defaults)));
                    if (s.checked()) row["range"] = py::make_tuple(s.lo, s.hi);
                    if (!s.choices.empty()) {
                        py::list names;
                        for (const turb::run::Choice& c : s.choices) names.append(c.name);
                        row["choices"] = names;
                    }
                    d[py::str(keywordOf(s.key))] = row;
                }
                return d;
            },
            "Every setting: {keyword: {'option', 'help', 'default', 'range' or 'choices' where it has one}}.");
}

// A `settings=` keyword holding a settings object: its options join the command line (a string stays the CLI's
// --settings FILE). A setting given both ways is refused rather than resolved silently.
template<typename Job>
void expandSettingsObject(
    py::kwargs& kwargs, const turb::run::SettingsTable<Job>& table, std::vector<std::string>& words)
{
    if (!kwargs.contains("settings") || !py::isinstance<SettingsObject<Job>>(kwargs["settings"])) return;
    const auto& o = kwargs["settings"].template cast<const SettingsObject<Job>&>();
    for (const turb::run::Setting<Job>& s : table) {
        if (std::find(o.given.begin(), o.given.end(), s.key) == o.given.end()) continue;
        std::string spellings = s.key + (s.alias.empty() ? "" : "," + s.alias);
        for (size_t a = 0, b = 0; a <= spellings.size(); a = b + 1) {
            b = std::min(spellings.find(',', a), spellings.size());
            if (kwargs.contains(keywordOf(spellings.substr(a, b - a))))
                throw py::type_error(
                    keywordOf(spellings.substr(a, b - a)) + "= is given as a keyword and in settings=");
        }
    }
    const std::vector<std::string> more = settingsWords(o, table);
    words.insert(words.end(), more.begin(), more.end());
    PyDict_DelItemString(kwargs.ptr(), "settings");
}

py::object progressOf(py::kwargs& kwargs)
{
    if (!kwargs.contains("progress")) return py::none();
    py::object p = kwargs["progress"];
    PyDict_DelItemString(kwargs.ptr(), "progress");
    if (!p.is_none() && !PyCallable_Check(p.ptr()))
        throw py::type_error("progress=: a callable(frame, done, total) (the CLI's --progress has no keyword here)");
    return p;
}

// transfer, sim, preview, measure: {"frames": [a dict per frame], "summary": dict or None}, and "text" for output
// that is not JSON.
py::dict frameCommand(const std::string& command, const std::vector<py::object>& positionals, py::kwargs kwargs)
{
    py::object progress = progressOf(kwargs);
    std::vector<std::string> fromObject;
    if (command == "transfer") expandSettingsObject(kwargs, turb::run::transferSettings(), fromObject);
    if (command == "measure") expandSettingsObject(kwargs, turb::run::measureSettings(), fromObject);
    if (command == "sim") expandSettingsObject(kwargs, turb::run::simSettings(), fromObject);
    if (command == "preview") expandSettingsObject(kwargs, turb::run::previewSettings(), fromObject);
    std::vector<std::string> words = commandWords(command, positionals, kwargs);
    // Before the keywords' options, whose JSON flag ends the line: the order is the settings object's.
    words.insert(words.begin() + 1, fromObject.begin(), fromObject.end());
    py::list docs = runWords(words, progress);
    py::list frames;
    py::object summary = py::none();
    std::string text;
    for (py::handle d : docs) {
        if (py::isinstance<py::str>(d)) text += d.cast<std::string>();
        else if (py::isinstance<py::dict>(d) && d.contains("summary")) summary = py::reinterpret_borrow<py::object>(d);
        else frames.append(d);
    }
    py::dict out;
    out["frames"] = frames;
    out["summary"] = summary;
    if (!text.empty()) out["text"] = text;
    return out;
}

// ---------------------------------------------------------------------------------------------------------------
// measure on arrays.

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

turb::Coord shapeOf(const FloatArray& a, int components, const char* name)
{
    const bool ok = components == 1 ? a.ndim() == 3 : (a.ndim() == 4 && a.shape(3) == components);
    if (!ok)
        throw py::value_error(std::string(name) + ": expected shape " +
                              (components == 1 ? "(X, Y, Z)" : "(X, Y, Z, 3)") + ", got ndim " +
                              std::to_string(a.ndim()));
    if (a.shape(0) < 1 || a.shape(1) < 1 || a.shape(2) < 1) throw py::value_error(std::string(name) + ": empty");
    return turb::Coord(int(a.shape(0)), int(a.shape(1)), int(a.shape(2)));
}

// The arrays of one frame (either may be None), on `lattice`; their shapes must agree.
turb::Frame frameOf(
    py::object velocity, py::object density, const turb::Lattice& lattice, const std::string& role, turb::Coord& dim)
{
    turb::Frame f;
    dim = turb::Coord(0);
    const auto box = [&](const turb::Coord& d, const char* name) {
        if (dim != turb::Coord(0) && d != dim)
            throw py::value_error(role + " velocity and density differ in shape (" + name + ")");
        dim = d;
        return turb::CoordBBox(turb::Coord(0), d - turb::Coord(1));
    };
    if (!velocity.is_none()) {
        const FloatArray a = velocity.cast<FloatArray>();
        const std::string name = role + "_velocity";
        f.velocity = turb::VectorField(box(shapeOf(a, 3, name.c_str()), "velocity"), lattice);
        static_assert(sizeof(turb::Vec3f) == 3 * sizeof(float), "Vec3f is three packed floats");
        std::memcpy(static_cast<void*>(f.velocity.values().data()), a.data(), size_t(a.size()) * sizeof(float));
    }
    if (!density.is_none()) {
        const FloatArray a = density.cast<FloatArray>();
        const std::string name = role + "_density";
        f.density = turb::ScalarField(box(shapeOf(a, 1, name.c_str()), "density"), lattice);
        std::memcpy(static_cast<void*>(f.density.values().data()), a.data(), size_t(a.size()) * sizeof(float));
    }
    return f;
}

turb::Coord dimOf(py::object velocity, py::object density, const char* role)
{
    const std::string r = role;
    if (!velocity.is_none()) return shapeOf(velocity.cast<FloatArray>(), 3, (r + "_velocity").c_str());
    if (!density.is_none()) return shapeOf(density.cast<FloatArray>(), 1, (r + "_density").c_str());
    throw py::value_error(r + ": give its velocity, its density or both");
}

// How many times finer `fine` is than `coarse`: the same integer along each axis (z of a 2D pair: both 1).
int ratioOf(const turb::Coord& fine, const turb::Coord& coarse, const std::string& what)
{
    int f = 0;
    for (int a = 0; a < 3; ++a) {
        if (a == 2 && fine[2] == 1 && coarse[2] == 1 && f > 0) continue;
        if (fine[a] % coarse[a] != 0 || (f && fine[a] / coarse[a] != f))
            throw py::value_error(what + ": the shapes must differ by one integer factor along every axis");
        f = fine[a] / coarse[a];
    }
    return f;
}

py::dict measureArrays(py::object outVelocity, py::object outDensity, py::object targetVelocity,
    py::object targetDensity, py::object sourceVelocity, py::object sourceDensity, double voxelSize, float threshold,
    int patchSize, bool spectra, bool structure, const std::string& up, double dt, int threads)
{
    if (!(voxelSize > 0.0)) throw py::value_error("voxel_size: the output's voxel edge in world units, > 0");
    const int upAxis = up == "x" ? 0 : up == "y" ? 1 : up == "z" ? 2 : -1;
    if (upAxis < 0) throw py::value_error("up: 'x', 'y' or 'z', not '" + up + "'");
    const turb::Coord outDim = dimOf(outVelocity, outDensity, "out");
    const turb::Coord targetDim = dimOf(targetVelocity, targetDensity, "target");
    const int f = ratioOf(outDim, targetDim, "out against target");
    // The target's cells start at the world origin; the output and the source refine them (Lattice::refined).
    turb::Lattice targetLattice;
    targetLattice.voxelSize = voxelSize * f;
    targetLattice.origin = turb::Vec3d(0.5 * targetLattice.voxelSize);
    turb::Coord dim;
    turb::Frame out = frameOf(outVelocity, outDensity, targetLattice.refined(f), "out", dim);
    turb::Frame target = frameOf(targetVelocity, targetDensity, targetLattice, "target", dim);
    out.dt = target.dt = dt;
    std::optional<turb::Frame> source;
    if (!sourceVelocity.is_none() || !sourceDensity.is_none()) {
        const int fs = ratioOf(dimOf(sourceVelocity, sourceDensity, "source"), targetDim, "source against target");
        source = frameOf(sourceVelocity, sourceDensity, targetLattice.refined(fs), "source", dim);
        source->dt = dt;
    }
    turb::MeasureSettings s;
    s.densityThreshold = threshold;
    s.patchSize = patchSize;
    s.spectra = spectra;
    s.structure = structure;
    s.upAxis = upAxis;
    s.threads = threads;
    s.dt = dt;
    turb::MeasureInput in;
    in.output = &out;
    in.target = &target;
    in.source = source ? &*source : nullptr;
    std::string json;
    try {
        py::gil_scoped_release nogil;
        json = vdbturb::measureJsonText(turb::measureFrame(in, s), spectra);
    } catch (const turb::Error& e) {
        PyErr_SetString(gClasses.error, e.what());
        throw py::error_already_set();
    }
    return py::module_::import("json").attr("loads")(json);
}

// libturb_oiio.so, loaded on the first image read or write, resolves its calls into turb_io against the libraries
// already loaded globally, as the executable's are; Python loads an extension's libraries RTLD_LOCAL. Promoting
// turb_io (found by one of its functions) to global lets preview and the image commands work here too.
void exposeTurbIo()
{
    Dl_info self{};
    if (::dladdr(reinterpret_cast<void*>(&turbio::nearestName), &self) && self.dli_fname)
        ::dlopen(self.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_GLOBAL); // kept for the process's life
}

PyObject* newClass(py::module_& m, const char* name, PyObject* bases, const char* doc)
{
    PyObject* cls = PyErr_NewExceptionWithDoc((std::string("vdbturb.") + name).c_str(), doc, bases, nullptr);
    if (!cls) throw py::error_already_set();
    m.add_object(name, py::handle(cls)); // the module holds a reference; ours lives with the interpreter
    Py_INCREF(cls);
    return cls;
}

} // namespace

namespace {

// The commands that write or read frames: keywords are their options.
void defineCommands(py::module_& m)
{
    m.def(
        "transfer", [](py::kwargs kw) { return frameCommand("transfer", {}, std::move(kw)); },
        "transfer(*, target, source, out, frames=None, progress=None, **settings) -> dict\n\n"
        "vdbturb transfer (docs/transfer.md): keywords are its options (temporal_blend=0.9, threads=2, "
        "full_float=True). Returns {'frames': [one dict per frame written], 'summary': dict}.");
    m.def(
        "sim",
        [](py::object scene, py::kwargs kw) {
            std::vector<py::object> pos;
            if (!scene.is_none()) pos.push_back(scene);
            return frameCommand("sim", pos, std::move(kw));
        },
        py::arg("scene") = py::none(),
        "sim(scene, *, res=None, frames=None, out=None, progress=None, **settings) -> dict\n\n"
        "vdbturb sim SCENE (docs/scenes.md); frames is a count here, as in the CLI. Returns {'frames', 'summary'}.");
    m.def(
        "preview",
        [](py::args caches, py::kwargs kw) {
            std::vector<py::object> pos;
            for (py::handle c : caches) pos.push_back(py::reinterpret_borrow<py::object>(c));
            return frameCommand("preview", pos, std::move(kw));
        },
        "preview(*caches, out=None, sheet=None, mode=None, frames=None, progress=None, **settings) -> dict\n\n"
        "vdbturb preview CACHES... (docs/scenes.md). Returns {'frames', 'summary'}.");
    m.def(
        "measure", [](py::kwargs kw) { return frameCommand("measure", {}, std::move(kw)); },
        "measure(*, output, target, source=None, frames=None, progress=None, **settings) -> dict\n\n"
        "vdbturb measure (docs/measure.md). Returns {'frames': [the numbers of each frame], 'summary': "
        "{metric: {'mean', 'median', 'min', 'max', 'n'}, ...}}.");
    m.def(
        "info",
        [](py::object path, py::kwargs kw) {
            py::object progress = progressOf(kw);
            py::list docs = runWords(commandWords("info", {path}, kw), progress);
            for (py::handle d : docs)
                if (py::isinstance<py::dict>(d)) return py::reinterpret_borrow<py::object>(d);
            return py::object(py::none());
        },
        py::arg("path"),
        "info(path, *, frames=None, validate=False, checksum=False, **settings) -> dict\n\n"
        "vdbturb info PATTERN --json as a dict: the sequence, its lattice, and 'files', one dict per frame with "
        "its 'grids'.");
}

// Any command line, a command's keywords, and measure on arrays.
void defineTools(py::module_& m)
{
    m.def(
        "run",
        [](py::sequence words, py::object progress) {
            std::vector<std::string> args;
            for (py::handle w : words) args.push_back(valueText(w, "args"));
            if (!progress.is_none() && !PyCallable_Check(progress.ptr()))
                throw py::type_error("progress=: a callable(frame, done, total)");
            if (!args.empty() && args[0] == "farm")
                throw py::value_error("vdbturb.run: farm writes job scripts that call the running executable, here "
                                      "the Python interpreter: run the vdbturb executable for farm");
            return runWords(args, progress);
        },
        py::arg("args"), py::arg("progress") = py::none(),
        "run(args, progress=None) -> list\n\nAny command line, as a list of words without 'vdbturb' "
        "(['resample', 'in.####.vdb', '--out', 'o.####.vdb', '--factor', '2', '--json']). Returns what it printed on "
        "stdout, one item per JSON line (parsed) or text; raises as the other functions do.");
    m.def(
        "options",
        [](const std::string& command) {
            const Specs& specs = specsOf(command);
            if (specs.empty()) throw py::value_error("no command '" + command + "'");
            py::dict out;
            for (const auto& [key, s] : specs)
                out[py::str(key)] = py::dict(py::arg("option") = (s.positional ? s.name : "--" + s.name),
                    py::arg("flag") = s.flag, py::arg("default") = s.defaultValue, py::arg("help") = s.help);
            return out;
        },
        py::arg("command"),
        "options(command) -> dict: every keyword the command takes, with its option, default and help.");
    m.def("measure_arrays", &measureArrays, py::arg("out_velocity"), py::arg("out_density"), py::arg("target_velocity"),
        py::arg("target_density"), py::arg("source_velocity") = py::none(), py::arg("source_density") = py::none(),
        py::kw_only(), py::arg("voxel_size"), py::arg("threshold") = 0.01f, py::arg("patch_size") = 0,
        py::arg("spectra") = false, py::arg("structure") = true, py::arg("up") = "z", py::arg("dt") = 0.0,
        py::arg("threads") = 0,
        "measure_arrays(out_velocity, out_density, target_velocity, target_density, source_velocity=None, "
        "source_density=None, *, voxel_size, threshold=0.01, patch_size=0, spectra=False, structure=True, up='z', "
        "dt=0.0, threads=0) -> dict\n\n"
        "measure's numbers of one frame given as arrays indexed [x, y, z]: velocity (X, Y, Z, 3), density (X, Y, Z), "
        "float32 (others are converted). The output is f times finer than the target along every axis, the source "
        "any integer times finer; all cover the same box from the world origin. voxel_size is the output's voxel "
        "edge in world units; velocities in world units per one time unit. Returns the dict of measure's JSON line.");
}

} // namespace

PYBIND11_MODULE(vdbturb, m)
{
    m.doc() = "vdbturb: turbulence up-res for smoke caches, from Python (docs/python.md). The commands run the "
              "command line's own code in this process: keywords are its options with '-' and '.' as '_'.";
    m.attr("__version__") = VDBTURB_VERSION_STRING;
    exposeTurbIo();

    gClasses.error = newClass(m, "Error", PyExc_Exception,
        "A command failed (the CLI's exit 1); str() is the CLI's message. Attributes: exit_code, file, frame, grid "
        "(None where the message names none), result (what the command had reported by then).");
    py::tuple usageBases = py::make_tuple(py::handle(gClasses.error), py::handle(PyExc_ValueError));
    gClasses.usage = newClass(
        m, "UsageError", usageBases.ptr(), "An option's value or a combination of options (the CLI's exit 2).");
    py::tuple inputBases = py::make_tuple(py::handle(gClasses.error), py::handle(PyExc_OSError));
    gClasses.input = newClass(m, "InputError", inputBases.ptr(),
        "An input file missing, unreadable or damaged, or a grid missing (exit 1); the message names the file.");
    gClasses.temporary = newClass(m, "TemporaryError", gClasses.error,
        "Worth a retry elsewhere: disk full, a file-size limit, memory or threads exhausted (exit 75).");
    gClasses.cancelled = newClass(m, "Cancelled", gClasses.error,
        "The progress callback returned False or raised (exit 130): whole frames only were written.");
    gClasses.warning = newClass(m, "Warning", PyExc_UserWarning, "A warning the CLI prints as 'vdbturb: warning:'.");

    defineCommands(m);
    defineTools(m);
    defineSettingsClass(m, "TransferSettings", turb::run::transferSettings(),
        "transfer's solver and experimental settings (vdbturb transfer --help-all's second tier) as an object: "
        "TransferSettings(temporalBlend=0.9, seams_gamma=4.0, alignment='rotate'). Keywords and attributes are the "
        "settings' keys with '.' as '_'; values are checked as the CLI checks them (ValueError, TypeError). "
        "Pass it as transfer(..., settings=obj); describe() lists every setting with its default and range.");
    defineSettingsClass(m, "MeasureSettings", turb::run::measureSettings(),
        "measure's second tier (vdbturb measure --help-all) as an object, as TransferSettings: "
        "measure(..., settings=MeasureSettings(patchSize=8, alignment='index')).");
    defineSettingsClass(m, "SimSettings", turb::run::simSettings(),
        "sim's solver settings (vdbturb sim --help-all) as an object, as TransferSettings: "
        "sim('plume', settings=SimSettings(scheme='bfecc', cfl=2.0)).");
    defineSettingsClass(m, "PreviewSettings", turb::run::previewSettings(),
        "preview's second tier (vdbturb preview --help-all) as an object, as TransferSettings.");
}
