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

#include <cstdint>
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
using FieldRef = std::variant<bool*, int*, std::uint64_t*, float*, double*, std::string*, EnumField>;

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
    bool lowOpen = false;           ///< a number must be > lo, not >= lo
    std::vector<Choice> choices;    ///< an enum's names; an int's only values, each named by its number
    std::vector<std::string> oneOf; ///< a text setting's only values ("png", "exr", "tif"); empty: any
    /// A further check of the value as text: empty when valid, else what is wrong ("must be NXxNYxNZ").
    std::function<std::string(const std::string&)> validate;
    std::string typeName; ///< a text setting's form in --help ("NXxNYxNZ"); empty: the type's
    bool flag = false;    ///< a bool given as a bare flag (--whole-fresh-patches), not as KEY=true|false

    /// Whether a number is range-checked: lo or hi is finite.
    bool checked() const;
    /// A number `v` as this setting's message: empty when it is valid, else "KEY: V must be a finite number in
    /// [LO, HI]" or the like.
    std::string whyInvalid(double v) const;
};

/// A setting of the job type `Job`: its row and its field in a job.
template<typename Job>
struct Setting : SettingRow
{
    std::function<FieldRef(Job&)> field;

    /// Sets the field of `job` to `v` (a bool: v != 0; an enum: one of `choices`' values). Throws turb::ValueError
    /// naming the key when `v` is not a valid value (outside the range, not an integer for an int, not a choice, a
    /// text setting).
    void set(Job& job, double v) const;
    /// The field's value in `job` as a number (a bool 0 or 1, an enum its value; NaN for text).
    double get(const Job& job) const;
    /// Sets the field from the text the command line takes ("0.9", "true", "rotate", "32x32x48"). Throws
    /// turb::ValueError naming the key when it is not a valid value.
    void setText(Job& job, const std::string& text) const;
    /// The field's value as that text, exact: a float as its shortest text that reads back as the same float.
    std::string text(const Job& job) const;
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
    std::string help;  ///< empty: "KEYS = VALUE"
};

/// `text` as the number of `row`'s value: a number, true/false for a bool, one of `choices`' names for an enum.
/// Throws turb::ValueError naming the key when it is none of these or not a valid value (SettingRow::whyInvalid).
double parseSettingValue(const SettingRow& row, const std::string& text);

/// The second tier of TransferJob: every solver and experimental knob of turb::TransferSettings under its field's
/// name (sourceRead.extendVelocity besides), with the spellings scripts used before (`--gamma` for seams.gamma).
/// The measured effects are docs/transfer.md's. Made once; valid for the process's life.
const SettingsTable<TransferJob>& transferSettings();
/// transfer's older spellings of those settings.
const std::vector<OldSpelling>& transferOldSpellings();

struct SynthJob;
struct AnimateJob;
/// The second tier of SynthJob: the coarse motion's and the exemplars' shape, the texture optimisation
/// (turb::SynthSettings) and F's combination, projection, density and pictures (turb::CombineSettings,
/// turb::SynthSequenceSettings), as `vdbturb synth --help-all` lists them. docs/synth.md has their effects.
const SettingsTable<SynthJob>& synthSettings();
/// synth's older spellings of those settings (`--no-density` for density = false).
const std::vector<OldSpelling>& synthOldSpellings();
/// The second tier of AnimateJob: the flow image's orientation, the stage dumps and measurement, and the method's
/// knobs (turb::AnimateSettings: refinement, residual transfer, analysis, histogram matching), as `vdbturb animate
/// --help-all` lists them. docs/animate.md has their measurements.
const SettingsTable<AnimateJob>& animateSettings();
/// animate's older spellings of those settings (`--hm-exact-cells` for hm.blendPixels = false).
const std::vector<OldSpelling>& animateOldSpellings();

// measure, sim, preview and stylize, and the cache camera stylize and animate share.
struct MeasureJob;
struct SimJob;
struct PreviewJob;
struct StylizeJob;
struct CacheCamera;

/// The second tier of MeasureJob: the region and lattice a metric uses when the metadata does not say, what to skip,
/// and the plots' format (docs/measure.md). Made once; valid for the process's life.
const SettingsTable<MeasureJob>& measureSettings();
/// measure's older spellings: --no-spectra, --no-structure.
const std::vector<OldSpelling>& measureOldSpellings();
/// The second tier of SimJob: the solver's advection and pressure projection (docs/scenes.md).
const SettingsTable<SimJob>& simSettings();
/// The second tier of PreviewJob: the slice, the density render's light and the colour ranges (docs/scenes.md).
const SettingsTable<PreviewJob>& previewSettings();
/// The cache camera's second tier (the perspective camera's placement, the image height, the ray march): stylize's
/// and animate's, under the same keys.
const SettingsTable<CacheCamera>& cacheCameraSettings();
/// The second tier of StylizeJob, in the order --help-all lists it: the cache camera's rows (cacheCameraSettings()
/// on StylizeJob::camera), the built-in target, LazyFluids' knobs (docs/stylize.md) and Fluidymation's
/// (docs/fluidymation.md, their help marked "[fluidymation]").
const SettingsTable<StylizeJob>& stylizeSettings();
/// stylize's older spellings: --no-reuse.
const std::vector<OldSpelling>& stylizeOldSpellings();

/// Sets or reads a field through its reference (the implementation of Setting's members).
void setField(const SettingRow& row, const FieldRef& ref, double v);
double getField(const FieldRef& ref);
void setFieldText(const SettingRow& row, const FieldRef& ref, const std::string& text);
std::string fieldText(const SettingRow& row, const FieldRef& ref);

template<typename Job>
void Setting<Job>::set(Job& job, double v) const
{
    setField(*this, field(job), v);
}

template<typename Job>
double Setting<Job>::get(const Job& job) const
{
    return getField(field(const_cast<Job&>(job))); // the reference is only read
}

template<typename Job>
void Setting<Job>::setText(Job& job, const std::string& text) const
{
    setFieldText(*this, field(job), text);
}

template<typename Job>
std::string Setting<Job>::text(const Job& job) const
{
    return fieldText(*this, field(const_cast<Job&>(job)));
}

} // namespace turb::run
