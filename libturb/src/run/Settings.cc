// The settings tables' rows (turb/run/Settings.h): checks, and reading and writing a field as a number or as text.
#include <turb/Error.h>
#include <turb/run/Flags.h>
#include <turb/run/Settings.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <type_traits>

namespace turb::run {

namespace {

std::string trimmed(double v) // 0 -> "0", 1e-12 -> "1e-12", 0.999 -> "0.999"
{
    char b[32];
    std::snprintf(b, sizeof(b), "%g", v);
    return b;
}

std::string choiceNames(const SettingRow& row) // "source|pasted|none"
{
    std::string names;
    for (const Choice& c : row.choices) names += (names.empty() ? "" : "|") + c.name;
    for (const std::string& n : row.oneOf) names += (names.empty() ? "" : "|") + n;
    return names;
}

// A number as its shortest text that reads back as the same value of its type: 0.9f is "0.9", not 0.899999976.
template<typename T>
std::string shortestText(T v)
{
    char b[48];
    for (int digits = 6; digits <= 17; ++digits) {
        std::snprintf(b, sizeof(b), "%.*g", digits, double(v));
        if (T(std::strtod(b, nullptr)) == v) break;
    }
    return b;
}

} // namespace

bool SettingRow::checked() const { return std::isfinite(lo) || std::isfinite(hi); }

std::string SettingRow::whyInvalid(double v) const
{
    if (std::isnan(v)) return key + ": nan is not a number";
    if (!choices.empty()) {
        for (const Choice& c : choices)
            if (c.value == v) return {};
        return key + ": " + trimmed(v) + " is not one of " + choiceNames(*this);
    }
    const bool inRange = (lowOpen ? v > lo : v >= lo) && v <= hi && std::isfinite(v);
    if (checked() && !inRange) {
        const std::string low = (lowOpen ? "> " : ">= ") + trimmed(lo);
        return key + ": " + trimmed(v) + " must be a finite number " +
               (hi >= 1e30   ? low
                   : lowOpen ? low + " and <= " + trimmed(hi)
                             : "in [" + trimmed(lo) + ", " + trimmed(hi) + "]");
    }
    return {};
}

double parseSettingValue(const SettingRow& row, const std::string& text)
{
    for (const Choice& c : row.choices)
        if (c.name == text) return c.value;
    double v = 0.0;
    if (text == "true" || text == "false") v = text == "true";
    else if (!row.choices.empty() || !parseNumber(text, v))
        throw ValueError(row.key + ": '" + text + "' is not " +
                             (row.choices.empty() ? std::string("a number") : "one of " + choiceNames(row)),
            {row.key});
    if (const std::string why = row.whyInvalid(v); !why.empty()) throw ValueError(why, {row.key});
    return v;
}

void setField(const SettingRow& row, const FieldRef& ref, double v)
{
    if (std::holds_alternative<std::string*>(ref)) throw ValueError(row.key + ": a text setting", {row.key});
    if (const std::string why = row.whyInvalid(v); !why.empty()) throw ValueError(why, {row.key});
    const bool integer = std::holds_alternative<int*>(ref) || std::holds_alternative<std::uint64_t*>(ref);
    if (integer && v != std::floor(v)) throw ValueError(row.key + ": " + trimmed(v) + " is not an integer", {row.key});
    if (std::holds_alternative<std::uint64_t*>(ref) && v < 0.0)
        throw ValueError(row.key + ": " + trimmed(v) + " is negative", {row.key});
    std::visit(
        [v](auto&& r) {
            using R = std::decay_t<decltype(r)>;
            if constexpr (std::is_same_v<R, EnumField>) r.set(static_cast<int>(v));
            else if constexpr (std::is_same_v<R, bool*>) *r = v != 0.0;
            else if constexpr (!std::is_same_v<R, std::string*>) *r = static_cast<std::remove_pointer_t<R>>(v);
        },
        ref);
}

double getField(const FieldRef& ref)
{
    return std::visit(
        [](auto&& r) -> double {
            using R = std::decay_t<decltype(r)>;
            if constexpr (std::is_same_v<R, EnumField>) return r.get();
            else if constexpr (std::is_same_v<R, std::string*>) return std::nan("");
            else return static_cast<double>(*r);
        },
        ref);
}

void setFieldText(const SettingRow& row, const FieldRef& ref, const std::string& text)
{
    if (row.validate)
        if (const std::string why = row.validate(text); !why.empty())
            throw ValueError(row.key + ": '" + text + "' " + why, {row.key});
    if (auto* s = std::get_if<std::string*>(&ref)) {
        if (!row.oneOf.empty() && std::find(row.oneOf.begin(), row.oneOf.end(), text) == row.oneOf.end())
            throw ValueError(row.key + ": '" + text + "' is not one of " + choiceNames(row), {row.key});
        **s = text;
        return;
    }
    if (auto* u = std::get_if<std::uint64_t*>(&ref)) { // every 64-bit seed, not only those a double holds
        char* end = nullptr;
        const unsigned long long n = std::strtoull(text.c_str(), &end, 10);
        if (text.empty() || text[0] == '-' || *end != '\0')
            throw ValueError(row.key + ": '" + text + "' is not a whole number >= 0", {row.key});
        **u = n;
        return;
    }
    setField(row, ref, parseSettingValue(row, text));
}

std::string fieldText(const SettingRow& row, const FieldRef& ref)
{
    if (auto* s = std::get_if<std::string*>(&ref)) return **s;
    if (auto* u = std::get_if<std::uint64_t*>(&ref)) return std::to_string(**u);
    const double v = getField(ref);
    for (const Choice& c : row.choices)
        if (c.value == v) return c.name;
    if (std::holds_alternative<bool*>(ref)) return v != 0.0 ? "true" : "false";
    if (std::holds_alternative<int*>(ref)) return std::to_string(static_cast<long long>(v));
    if (auto* f = std::get_if<float*>(&ref)) return shortestText(**f);
    return shortestText(v);
}

} // namespace turb::run
