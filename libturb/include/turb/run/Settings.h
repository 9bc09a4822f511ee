/// @file Settings.h
/// @brief The entry points' second-tier settings as tables (turb::run, the entry points' layer): one row per field
///        of a job, naming it as settings files, the command line and the Python module do, with its help, type and
///        valid range. The CLI declares its options from these rows (tools/Options.cc) and the Python module its
///        settings objects (vdbturb.TransferSettings), so the three cannot drift apart.
///
/// @code
/// turb::run::TransferJob job;
/// for (const auto& s : turb::run::transferSettings())
///     if (s.key == "seams.gamma") s.set(job, 4.0); // throws turb::ValueError outside [0, inf)
/// @endcode
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <variant>
#include <vector>

namespace turb::run {

struct TransferJob;

/// An enum field seen as its number.
struct EnumField
{
    std::function<int()> get;
    std::function<void(int)> set;
};
/// Where one setting lives in a job, as its type.
using FieldRef = std::variant<bool*, int*, float*, double*, EnumField>;

/// One name of an enum setting's value; the first name of a value is the one printed.
struct Choice
{
    std::string name;
    int value;
};

/// One setting: everything but where it lives.
struct SettingRow
{
    std::string key;   ///< the field's path ("seams.gamma"): the settings-file key and the long option --seams.gamma
    std::string alias; ///< older long options, comma-separated, without "--" ("gamma"): listed before the key
    std::string help;
    double lo = -std::numeric_limits<double>::infinity(); ///< valid values of a number, inclusive
    double hi = std::numeric_limits<double>::infinity();
    bool positive = false;       ///< a number must be > 0 (lo and hi unused)
    std::vector<Choice> choices; ///< an enum's names
    bool flag = false;           ///< a bool given as a bare flag (--whole-fresh-patches), not as KEY=true|false

    /// Whether a number is range-checked: lo or hi is finite, or `positive`.
    bool checked() const;
    /// `v` as this setting's message: empty when it is valid, else "KEY: V is not in [LO, HI]" or the like.
    std::string whyInvalid(double v) const;
};

/// A setting of the job type `Job`: its row and its field in a job.
template<typename Job>
struct Setting : SettingRow
{
    std::function<FieldRef(Job&)> field;

    /// Sets the field of `job` to `v` (a bool: v != 0; an enum: one of `choices`' values). Throws turb::ValueError
    /// naming the key when `v` is not a valid value (outside the range, not an integer for an int, not a choice).
    void set(Job& job, double v) const;
    /// The field's value in `job` as a number (a bool 0 or 1, an enum its value).
    double get(const Job& job) const;
};

/// `Job`'s settings as a table, in the order --help-all lists them.
template<typename Job>
using SettingsTable = std::vector<Setting<Job>>;

/// An older command-line option kept for scripts, that sets one or more settings: `--band 4` sets seams.bandWidth and
/// seams.bandWidth2D; `--no-seams` sets seams.enabled to false. Accepted, never listed; a setting's own option wins
/// over it when both are given.
struct OldSpelling
{
    std::string name;  ///< without "--"
    std::string keys;  ///< the settings it sets, comma-separated
    std::string value; ///< a flag's value for them ("false"); empty: the option takes one
    std::string help;
};

/// `text` as the value of `row`: a number, true/false for a bool, one of `choices`' names for an enum. Throws
/// turb::ValueError naming the key when it is none of these or not a valid value (SettingRow::whyInvalid).
double parseSettingValue(const SettingRow& row, const std::string& text);

/// The second tier of TransferJob: every solver and experimental knob of turb::TransferSettings under its field's
/// name (sourceRead.extendVelocity besides), with the spellings scripts used before (`--gamma` for seams.gamma).
/// The measured effects are docs/transfer.md's. Made once; valid for the process's life.
const SettingsTable<TransferJob>& transferSettings();
/// transfer's older spellings of those settings.
const std::vector<OldSpelling>& transferOldSpellings();

/// Sets or reads a field through its reference (the implementation of Setting::set and get).
void setField(const SettingRow& row, const FieldRef& ref, double v);
double getField(const FieldRef& ref);

template<typename Job>
void Setting<Job>::set(Job& job, double v) const
{
    setField(*this, field(job), v);
}

template<typename Job>
double Setting<Job>::get(const Job& job) const
{
    return getField(field(const_cast<Job&>(job)));
}

} // namespace turb::run
