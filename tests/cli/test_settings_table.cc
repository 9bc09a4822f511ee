// turb::run's settings tables (turb/run/Settings.h): each row reaches its own field, checks its range, and is the
// option the command line declares (the CLI and the Python module both build on these rows).
#include "CliUtil.h"

#include <turb/Error.h>
#include <turb/run/Settings.h>
#include <turb/run/Transfer.h>

#include <gtest/gtest.h>

#include <cmath>
#include <set>

namespace {

using turb::run::TransferJob;

const turb::run::Setting<TransferJob>& rowOf(const std::string& key)
{
    for (const auto& s : turb::run::transferSettings())
        if (s.key == key) return s;
    throw std::runtime_error("no setting " + key);
}

// A value valid for `s` and unlike its default, distinct per row where the type allows.
double otherValue(const turb::run::Setting<TransferJob>& s, double current, int index)
{
    if (!s.choices.empty()) {
        for (const turb::run::Choice& c : s.choices)
            if (c.value != current) return c.value;
    }
    TransferJob job;
    if (std::holds_alternative<bool*>(s.field(job))) return current == 0.0 ? 1.0 : 0.0;
    const double lo = std::isfinite(s.lo) ? s.lo : 0.0;
    const double hi = std::isfinite(s.hi) ? s.hi : lo + 1000.0;
    const double v = std::floor(lo + 1.0 + index);
    return v <= hi && v != current ? v : (current == lo ? hi : lo);
}

TEST(TransferSettingsTable, KeysAreUniqueAndEachReachesItsOwnField)
{
    const auto& table = turb::run::transferSettings();
    ASSERT_GT(table.size(), 40u);
    std::set<std::string> keys;
    for (const auto& s : table) EXPECT_TRUE(keys.insert(s.key).second) << s.key;
    // Changing one row changes that row only: no two rows share a field, and no row writes beside its own.
    for (size_t i = 0; i < table.size(); ++i) {
        TransferJob job;
        const TransferJob defaults;
        const double before = table[i].get(job);
        const double v = otherValue(table[i], before, int(i));
        ASSERT_NE(v, before) << table[i].key;
        table[i].set(job, v);
        EXPECT_NE(table[i].get(job), before) << table[i].key;
        for (size_t j = 0; j < table.size(); ++j)
            if (j != i) EXPECT_EQ(table[j].get(job), table[j].get(defaults)) << table[i].key << " vs " << table[j].key;
    }
}

TEST(TransferSettingsTable, RowsNameTheFieldsOfTheirKeys)
{
    TransferJob job;
    rowOf("seams.gamma").set(job, 3.5);
    rowOf("sourceRead.extendVelocity").set(job, 7);
    rowOf("alignment").set(job, turb::run::parseSettingValue(rowOf("alignment"), "rotate"));
    rowOf("seams.enabled").set(job, 0);
    EXPECT_EQ(job.settings.seams.gamma, 3.5f);
    EXPECT_EQ(job.sourceRead.extendVelocity, 7);
    EXPECT_EQ(job.settings.alignment, turb::FlowAlignment::Rotate);
    EXPECT_FALSE(job.settings.seams.enabled);
    // The defaults read through the table are the structs' own.
    const TransferJob defaults;
    EXPECT_EQ(rowOf("temporalBlend").get(defaults), double(turb::TransferSettings{}.temporalBlend));
    EXPECT_EQ(rowOf("detailEnergy").get(defaults), double(int(turb::TransferSettings{}.detailEnergy)));
}

TEST(TransferSettingsTable, ValuesOutsideTheRangeAreRefusedNamingTheKey)
{
    TransferJob job;
    const auto refused = [&](const std::string& key, double v) {
        try {
            rowOf(key).set(job, v);
        } catch (const turb::ValueError& e) {
            EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
            return true;
        }
        return false;
    };
    EXPECT_TRUE(refused("localPatch", 1));     // below [2, 64]
    EXPECT_TRUE(refused("localPatch", 65));    // above it
    EXPECT_TRUE(refused("localPatch", 8.5));   // not an integer
    EXPECT_TRUE(refused("seams.gamma", -1.0)); // >= 0
    EXPECT_TRUE(refused("temporalBlend", NAN));
    EXPECT_TRUE(refused("alignment", 17)); // no such choice
    EXPECT_FALSE(refused("localPatch", 64));
    EXPECT_FALSE(refused("seams.emTolerance", -3.0)); // unchecked, as on the command line
    EXPECT_EQ(job.settings.localPatch, 64);
    EXPECT_THROW(turb::run::parseSettingValue(rowOf("alignment"), "sideways"), turb::ValueError);
    EXPECT_THROW(turb::run::parseSettingValue(rowOf("alpha"), "0.1x"), turb::ValueError);
    EXPECT_EQ(turb::run::parseSettingValue(rowOf("trackGlobalPatches"), "false"), 0.0);
    EXPECT_EQ(turb::run::parseSettingValue(rowOf("seams.cgTolerance"), "1e-5"), 1e-5);
}

// The command line declares every row under its key, with the row's default, and its older spellings still work.
TEST(TransferSettingsTable, EveryRowIsAnOptionOfTransferWithItsDefault)
{
    const clitest::Result r = clitest::run("transfer --target t --source s --out o --print-settings", false);
    ASSERT_EQ(r.code, 0) << r.out;
    const TransferJob defaults;
    for (const auto& s : turb::run::transferSettings()) {
        const std::string line = "# " + s.key + "=";
        const auto at = r.out.find("\n" + line);
        ASSERT_NE(at, std::string::npos) << s.key;
        const std::string printed = r.out.substr(at + 1 + line.size(), r.out.find('\n', at + 1) - at - 1 - line.size());
        const std::string unquoted =
            printed.size() > 1 && printed[0] == '"' ? printed.substr(1, printed.size() - 2) : printed;
        TransferJob job; // read into the field's own type: 0.15 printed is the float 0.15f
        s.set(job, turb::run::parseSettingValue(s, unquoted));
        EXPECT_EQ(s.get(job), s.get(defaults)) << s.key << " printed " << printed;
    }
    const clitest::Result old = clitest::run(
        "transfer --target t --source s --out o --band 5 --no-seams --detail-energy pasted --print-settings", false);
    ASSERT_EQ(old.code, 0) << old.out;
    for (const char* set : {"\nseams.bandWidth=5\n", "\nseams.bandWidth2D=5\n", "\nseams.enabled=false\n",
             "\ndetailEnergy=\"pasted\"\n", "\ndetailEnergy2D=\"pasted\"\n"})
        EXPECT_NE(old.out.find(set), std::string::npos) << set << "\n" << old.out;
}

} // namespace
