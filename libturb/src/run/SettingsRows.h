// Writing a settings table (turb/run/Settings.h): a row per field, each file one job's table.
#pragma once

#include <turb/run/Settings.h>

#include <initializer_list>
#include <limits>
#include <type_traits>

namespace turb::run::detail {

/// A field's reference by its type: numbers, bools and text as pointers, enums as their number.
template<typename T>
FieldRef refTo(T& v)
{
    if constexpr (std::is_enum_v<T>) {
        return EnumField{[&v] { return static_cast<int>(v); }, [&v](int n) { v = static_cast<T>(n); }};
    } else {
        return &v;
    }
}

template<typename T>
struct Identity // keeps a parameter out of template deduction (C++20's std::type_identity)
{
    using type = T;
};

/// Appends a row to `table` and returns it, for its choices, flag or checks to be set.
template<typename Job>
Setting<Job>& add(SettingsTable<Job>& table, const char* key, const char* alias, const char* help,
    std::function<FieldRef(typename Identity<Job>::type&)> field, double lo = -std::numeric_limits<double>::infinity(),
    double hi = std::numeric_limits<double>::infinity())
{
    Setting<Job>& r = table.emplace_back();
    r.key = key;
    r.alias = alias;
    r.help = help;
    r.field = std::move(field);
    r.lo = lo;
    r.hi = hi;
    return r;
}

/// Appends `part`'s rows to `table`, each reaching its field in the part `of(job)` of a job: the cache camera's rows on
/// StylizeJob::camera.
template<typename Job, typename Part, typename Of>
void addPart(SettingsTable<Job>& table, const SettingsTable<Part>& part, Of of)
{
    for (const Setting<Part>& p : part) {
        Setting<Job>& r = table.emplace_back();
        static_cast<SettingRow&>(r) = p;
        r.field = [field = p.field, of](Job& job) { return field(of(job)); };
    }
}

/// A table made of its parts, each appending its rows in --help-all's order.
template<typename Job>
SettingsTable<Job> tableOf(std::initializer_list<void (*)(SettingsTable<Job>&)> parts)
{
    SettingsTable<Job> table;
    for (const auto& part : parts) part(table);
    return table;
}

} // namespace turb::run::detail

/// The field `path` of the job a table row describes ("settings.seams.gamma").
#define TURB_FIELD(path) [](auto& job) { return ::turb::run::detail::refTo(job.path); }
