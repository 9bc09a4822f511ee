// Checks of option values shared by every command (CLI11 validators). A leaf: it depends on no other file of tools/.
#include "Validators.h"

#include <turb/Error.h>
#include <turbio/Sequence.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace vdbturb {

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

} // namespace vdbturb
