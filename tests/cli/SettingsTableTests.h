// The tests every settings table (turb/run/Settings.h) passes, as a typed test a test file instantiates for its
// tables. The file specialises TableOf for each job before it instantiates them:
//
//     using Jobs = ::testing::Types<TransferJob, SynthJob>;
//     INSTANTIATE_TYPED_TEST_SUITE_P(Tables, SettingsTable, Jobs, TableName);
#pragma once

#include "CliUtil.h"

#include <turb/Error.h>
#include <turb/run/Settings.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

/// What the tests over every table need of one: `rows()`, `kName` (the tests' name), `kCommand` (the command
/// that declares them, with its required options), `kMinRows`, and `kOldSpellings` given with `oldLines()`, the
/// lines --print-settings then prints.
template<typename Job>
struct TableOf;

template<typename Job>
const turb::run::Setting<Job>& rowOf(const std::string& key)
{
    for (const auto& s : TableOf<Job>::rows())
        if (s.key == key) return s;
    throw std::runtime_error("no setting " + key);
}

template<typename Job>
bool isText(const turb::run::Setting<Job>& s)
{
    Job job;
    return std::holds_alternative<std::string*>(s.field(job));
}

// A number valid for `s` and unlike its default, distinct per row where the type allows.
template<typename Job>
double otherValue(const turb::run::Setting<Job>& s, double current, int index)
{
    if (!s.choices.empty()) {
        for (const turb::run::Choice& c : s.choices)
            if (c.value != current) return c.value;
    }
    Job job;
    if (std::holds_alternative<bool*>(s.field(job))) return current == 0.0 ? 1.0 : 0.0;
    const double lo = std::isfinite(s.lo) ? s.lo : 0.0;
    const double hi = std::isfinite(s.hi) ? s.hi : lo + 1000.0;
    const double v = std::floor(lo + 1.0 + index);
    for (const double c : {v, v + 1.0, s.lowOpen ? hi : lo, hi, 0.5 * (lo + hi)}) // the first valid one unlike it
        if (c != current && s.whyInvalid(c).empty()) return c;
    return v;
}

// Sets `s` in `job` to a valid value unlike its default: a text one among its only values, or a grid ("2x2", valid
// free text too).
template<typename Job>
void setOther(const turb::run::Setting<Job>& s, Job& job, int index)
{
    const std::string current = s.text(job);
    if (!isText(s)) return s.set(job, otherValue(s, s.get(job), index));
    for (const std::string& v : s.oneOf)
        if (v != current) return s.setText(job, v);
    s.setText(job, current == "2x2" ? "3x3" : "2x2");
}

template<typename Job>
class SettingsTable : public ::testing::Test
{};
TYPED_TEST_SUITE_P(SettingsTable);

TYPED_TEST_P(SettingsTable, KeysAreUniqueAndEachReachesItsOwnField)
{
    using Job = TypeParam;
    const auto& table = TableOf<Job>::rows();
    ASSERT_GT(table.size(), TableOf<Job>::kMinRows);
    std::set<std::string> keys;
    for (const auto& s : table) EXPECT_TRUE(keys.insert(s.key).second) << s.key;
    // Changing one row changes that row only: no two rows share a field, and no row writes beside its own.
    const Job defaults;
    for (size_t i = 0; i < table.size(); ++i) {
        Job job;
        ASSERT_NO_THROW(setOther(table[i], job, int(i))) << table[i].key;
        EXPECT_NE(table[i].text(job), table[i].text(defaults)) << table[i].key;
        for (size_t j = 0; j < table.size(); ++j)
            if (j != i)
                EXPECT_EQ(table[j].text(job), table[j].text(defaults)) << table[i].key << " vs " << table[j].key;
    }
}

// The library refuses what the command line refuses: every range's ends, NaN, a value outside the choices, text
// outside its only values or its form.
TYPED_TEST_P(SettingsTable, ValuesOutsideEachRangeAreRefusedNamingTheKey)
{
    using Job = TypeParam;
    for (const auto& s : TableOf<Job>::rows()) {
        Job job;
        const auto refused = [&](const auto& set) {
            try {
                set();
            } catch (const turb::ValueError& e) {
                EXPECT_NE(std::string(e.what()).find(s.key), std::string::npos) << e.what();
                return true;
            }
            return false;
        };
        if (isText(s)) {
            if (!s.oneOf.empty() || s.validate) EXPECT_TRUE(refused([&] { s.setText(job, "no such value"); })) << s.key;
            continue;
        }
        if (!s.choices.empty()) EXPECT_TRUE(refused([&] { s.set(job, 12345); })) << s.key;
        if (std::isfinite(s.lo)) EXPECT_TRUE(refused([&] { s.set(job, s.lowOpen ? s.lo : s.lo - 1.0); })) << s.key;
        if (std::isfinite(s.hi)) EXPECT_TRUE(refused([&] { s.set(job, s.hi + 1.0); })) << s.key;
        if (s.checked()) EXPECT_TRUE(refused([&] { s.set(job, std::nan("")); })) << s.key;
    }
}

// The command line refuses the same values as a usage error (exit 2) naming the option (by its first long name),
// one value per checked row.
TYPED_TEST_P(SettingsTable, TheCommandLineRefusesValuesOutsideEachRange)
{
    using Job = TypeParam;
    const auto number = [](double v) {
        char b[32];
        std::snprintf(b, sizeof(b), "%.17g", v);
        return std::string(b);
    };
    for (const auto& s : TableOf<Job>::rows()) {
        std::string bad;
        if (isText(s)) bad = !s.oneOf.empty() || s.validate ? "no-such-value" : "";
        else if (!s.choices.empty()) bad = s.choices.front().name == "1" ? "3" : "no-such-choice";
        else if (std::isfinite(s.hi)) bad = number(s.hi + 1.0);
        else if (std::isfinite(s.lo)) bad = number(s.lowOpen ? s.lo : s.lo - 1.0);
        if (bad.empty()) continue;
        const clitest::Result r =
            clitest::run(std::string(TableOf<Job>::kCommand) + " --" + s.key + "=" + bad + " --print-settings");
        EXPECT_EQ(r.code, 2) << s.key << "=" << bad << "\n" << r.out;
        const std::string name = "--" + (s.alias.empty() ? s.key : s.alias.substr(0, s.alias.find(',')));
        EXPECT_NE(r.out.find(name), std::string::npos) << r.out;
    }
}

// The command line declares every row under its key, with the row's default, and its older spellings still work.
TYPED_TEST_P(SettingsTable, EveryRowIsAnOptionOfItsCommandWithItsDefault)
{
    using Job = TypeParam;
    const std::string command = TableOf<Job>::kCommand;
    const clitest::Result r = clitest::run(command + " --print-settings", false);
    ASSERT_EQ(r.code, 0) << r.out;
    const Job defaults;
    for (const auto& s : TableOf<Job>::rows()) {
        const std::string line = "# " + s.key + "=";
        const auto at = r.out.find("\n" + line);
        ASSERT_NE(at, std::string::npos) << s.key;
        const std::string printed = r.out.substr(at + 1 + line.size(), r.out.find('\n', at + 1) - at - 1 - line.size());
        const std::string unquoted =
            printed.size() > 1 && printed[0] == '"' ? printed.substr(1, printed.size() - 2) : printed;
        if (unquoted == s.text(defaults)) continue; // as the library writes it; else read into the field's own type:
        Job job;                                    // 0.15 printed is the float 0.15f
        s.setText(job, unquoted);
        EXPECT_EQ(s.text(job), s.text(defaults)) << s.key << " printed " << printed;
    }
    const clitest::Result old = clitest::run(command + " " + TableOf<Job>::kOldSpellings + " --print-settings", false);
    ASSERT_EQ(old.code, 0) << old.out;
    for (const std::string& set : TableOf<Job>::oldLines()) EXPECT_NE(old.out.find(set), std::string::npos) << set;
}

REGISTER_TYPED_TEST_SUITE_P(SettingsTable, KeysAreUniqueAndEachReachesItsOwnField,
    ValuesOutsideEachRangeAreRefusedNamingTheKey, TheCommandLineRefusesValuesOutsideEachRange,
    EveryRowIsAnOptionOfItsCommandWithItsDefault);

struct TableName
{
    template<typename Job>
    static std::string GetName(int)
    {
        return TableOf<Job>::kName;
    }
};

} // namespace
