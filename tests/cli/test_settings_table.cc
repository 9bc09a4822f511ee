// turb::run's settings tables (turb/run/Settings.h): each row reaches its own field, checks its range, and is the
// option the command line declares (the CLI and the Python module both build on these rows).
#include "CliUtil.h"

#include <turb/Error.h>
#include <turb/run/CacheCamera.h>
#include <turb/run/Measure.h>
#include <turb/run/Preview.h>
#include <turb/run/Settings.h>
#include <turb/run/Sim.h>
#include <turb/run/Stylize.h>
#include <turb/run/Transfer.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>
#include <stdexcept>
#include <variant>

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

// ---- Every table, one typed test: measure, sim, preview, stylize, the cache camera (and transfer's again) ----------

namespace {

using turb::run::CacheCamera;
using turb::run::MeasureJob;
using turb::run::OldSpelling;
using turb::run::PreviewJob;
using turb::run::Setting;
using turb::run::SimJob;
using turb::run::StylizeJob;

// Each job's table, its old spellings and a command line that lists them (--print-settings).
template<typename Job>
struct TableOf;
template<>
struct TableOf<MeasureJob>
{
    static const auto& rows() { return turb::run::measureSettings(); }
    static const auto& old() { return turb::run::measureOldSpellings(); }
    static constexpr const char* command = "measure --output o --target t";
};
template<>
struct TableOf<SimJob>
{
    static const auto& rows() { return turb::run::simSettings(); }
    static std::vector<OldSpelling> old() { return {}; }
    static constexpr const char* command = "sim plume";
};
template<>
struct TableOf<PreviewJob>
{
    static const auto& rows() { return turb::run::previewSettings(); }
    static std::vector<OldSpelling> old() { return {}; }
    static constexpr const char* command = "preview a.####.vdb";
};
template<>
struct TableOf<CacheCamera>
{
    static const auto& rows() { return turb::run::cacheCameraSettings(); }
    static std::vector<OldSpelling> old() { return {}; }
    static constexpr const char* command = "stylize --exemplar e"; // animate declares them too
};
template<>
struct TableOf<StylizeJob>
{
    static const auto& rows() { return turb::run::stylizeSettings(); }
    static const auto& old() { return turb::run::stylizeOldSpellings(); }
    static constexpr const char* command = "stylize --exemplar e";
};
template<>
struct TableOf<TransferJob>
{
    static const auto& rows() { return turb::run::transferSettings(); }
    static const auto& old() { return turb::run::transferOldSpellings(); }
    static constexpr const char* command = "transfer --target t --source s --out o";
};

// Values as text for `s` unlike `current`, valid ones first: a choice, a word, a number in the range.
template<typename Job>
std::vector<std::string> otherTexts(const Setting<Job>& s, const std::string& current, int index)
{
    std::vector<std::string> out;
    for (const turb::run::Choice& c : s.choices) out.push_back(c.name);
    for (const std::string& w : s.oneOf) out.push_back(w);
    Job job;
    const turb::run::FieldRef ref = s.field(job);
    if (std::holds_alternative<bool*>(ref)) out = {"true", "false"};
    if (std::holds_alternative<std::string*>(ref) && s.oneOf.empty()) out.push_back("v" + std::to_string(index));
    if (s.choices.empty() && !std::holds_alternative<bool*>(ref) && !std::holds_alternative<std::string*>(ref)) {
        const double lo = std::isfinite(s.lo) ? s.lo : 0.0;
        const double hi = std::isfinite(s.hi) ? s.hi : lo + 1000.0;
        for (const double v : {std::floor(lo + 1.0 + index), hi, std::floor((lo + hi) / 2.0), lo}) {
            char b[32];
            std::snprintf(b, sizeof(b), "%.17g", v);
            out.push_back(b);
        }
    }
    out.erase(std::remove(out.begin(), out.end(), current), out.end());
    return out;
}

template<typename Job>
class SettingsTables : public ::testing::Test
{};
using Jobs = ::testing::Types<MeasureJob, SimJob, PreviewJob, CacheCamera, StylizeJob, TransferJob>;
TYPED_TEST_SUITE(SettingsTables, Jobs);

TYPED_TEST(SettingsTables, KeysAreUniqueAndEachReachesItsOwnField)
{
    using Job = TypeParam;
    const auto& table = TableOf<Job>::rows();
    ASSERT_FALSE(table.empty());
    std::set<std::string> keys;
    for (const auto& s : table) EXPECT_TRUE(keys.insert(s.key).second) << s.key;
    // Changing one row changes that row only: no two rows share a field, and no row writes beside its own. Rows are
    // compared as text, which every type has (a text setting's number is NaN).
    const Job defaults;
    for (size_t i = 0; i < table.size(); ++i) {
        Job job;
        const std::string before = table[i].text(job);
        bool set = false;
        for (const std::string& v : otherTexts(table[i], before, int(i))) {
            try {
                table[i].setText(job, v);
            } catch (const turb::ValueError&) {
                continue; // not valid for this row (1 for measure's patchSize): the next
            }
            set = true;
            break;
        }
        ASSERT_TRUE(set) << table[i].key;
        EXPECT_NE(table[i].text(job), before) << table[i].key;
        for (size_t j = 0; j < table.size(); ++j)
            if (j != i)
                EXPECT_EQ(table[j].text(job), table[j].text(defaults)) << table[i].key << " vs " << table[j].key;
    }
    // Each old spelling sets rows of this table.
    for (const OldSpelling& o : TableOf<Job>::old()) {
        std::stringstream names(o.keys);
        for (std::string k; std::getline(names, k, ',');) EXPECT_TRUE(keys.count(k)) << o.name << " sets " << k;
    }
}

// The command line declares every row under its key, with the row's default.
TYPED_TEST(SettingsTables, EveryRowIsAnOptionWithItsDefault)
{
    using Job = TypeParam;
    const clitest::Result r = clitest::run(std::string(TableOf<Job>::command) + " --print-settings", false);
    ASSERT_EQ(r.code, 0) << r.out;
    const Job defaults;
    for (const auto& s : TableOf<Job>::rows()) {
        const std::string line = "# " + s.key + "=";
        const auto at = r.out.find("\n" + line);
        ASSERT_NE(at, std::string::npos) << s.key;
        const std::string printed = r.out.substr(at + 1 + line.size(), r.out.find('\n', at + 1) - at - 1 - line.size());
        const std::string unquoted =
            printed.size() > 1 && printed[0] == '"' ? printed.substr(1, printed.size() - 2) : printed;
        Job job;
        const turb::run::FieldRef ref = s.field(job);
        if (std::holds_alternative<std::string*>(ref)) {
            EXPECT_EQ(unquoted, s.text(defaults)) << s.key;
            continue;
        }
        // As a number of the field's own type (0.15 printed is the float 0.15f); a default outside what may be given
        // (preview's speed-max 0: "from the picture") is printed all the same.
        double v = 0.0;
        for (const turb::run::Choice& c : s.choices)
            if (c.name == unquoted) v = c.value;
        if (s.choices.empty()) v = unquoted == "true" ? 1.0 : unquoted == "false" ? 0.0 : std::stod(unquoted);
        if (std::holds_alternative<float*>(ref)) EXPECT_EQ(float(v), float(s.get(defaults))) << s.key << " " << printed;
        else EXPECT_EQ(v, s.get(defaults)) << s.key << " printed " << printed;
    }
}

template<typename Job>
const Setting<Job>& row(const std::string& key)
{
    for (const auto& s : TableOf<Job>::rows())
        if (s.key == key) return s;
    throw std::runtime_error("no setting " + key);
}

// `key` refuses `text`, naming itself.
template<typename Job>
bool refuses(const std::string& key, const std::string& text)
{
    Job job;
    try {
        row<Job>(key).setText(job, text);
    } catch (const turb::ValueError& e) {
        EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
        return true;
    }
    return false;
}

TEST(MeasureSettingsTable, RowsNameTheirFieldsAndRefuseWhatTheOptionsRefuse)
{
    MeasureJob job;
    row<MeasureJob>("patchSize").setText(job, "8");
    row<MeasureJob>("sourceRead.extendVelocity").setText(job, "3");
    row<MeasureJob>("computeSpectra").setText(job, "false");
    row<MeasureJob>("alignment").setText(job, "index");
    row<MeasureJob>("plot-format").setText(job, "svg");
    EXPECT_EQ(job.settings.patchSize, 8);
    EXPECT_EQ(job.sourceExtend, 3);
    EXPECT_FALSE(job.spectra);
    EXPECT_EQ(job.settings.alignment, turb::Alignment::Index);
    EXPECT_EQ(job.plotFormat, "svg");
    EXPECT_TRUE(refuses<MeasureJob>("patchSize", "1")); // 0 (the metadata's) or 2..4096
    EXPECT_TRUE(refuses<MeasureJob>("patchSize", "4097"));
    EXPECT_FALSE(refuses<MeasureJob>("patchSize", "0"));
    EXPECT_TRUE(refuses<MeasureJob>("tile-border-width", "-1"));
    EXPECT_TRUE(refuses<MeasureJob>("sourceRead.extendVelocity", "65"));
    EXPECT_TRUE(refuses<MeasureJob>("alignment", "sideways"));
    EXPECT_TRUE(refuses<MeasureJob>("plot-format", "gif"));
    // The old spellings still set them.
    const clitest::Result old =
        clitest::run("measure --output o --target t --no-spectra --no-structure --print-settings", false);
    ASSERT_EQ(old.code, 0) << old.out;
    for (const char* set : {"\ncomputeSpectra=false\n", "\nstructure=false\n"})
        EXPECT_NE(old.out.find(set), std::string::npos) << set << "\n" << old.out;
}

TEST(SimSettingsTable, RowsNameTheirFieldsAndRefuseWhatTheOptionsRefuse)
{
    SimJob job;
    row<SimJob>("preconditioner").setText(job, "jacobi");
    row<SimJob>("scheme").setText(job, "bfecc");
    row<SimJob>("pressureTolerance").setText(job, "0.001");
    EXPECT_FALSE(job.incompleteCholesky);
    EXPECT_EQ(job.scheme, turb::AdvectSettings::Scheme::BFECC);
    EXPECT_EQ(job.pressureTolerance, 0.001);
    EXPECT_EQ(row<SimJob>("preconditioner").text(SimJob{}), "ic");
    EXPECT_TRUE(refuses<SimJob>("pressureTolerance", "0.6"));
    EXPECT_TRUE(refuses<SimJob>("cfl", "0")); // > 0
    EXPECT_TRUE(refuses<SimJob>("cfl", "nan"));
    EXPECT_TRUE(refuses<SimJob>("maxSubsteps", "65"));
    EXPECT_TRUE(refuses<SimJob>("preconditioner", "gauss"));
}

TEST(PreviewSettingsTable, RowsNameTheirFieldsAndRefuseWhatTheOptionsRefuse)
{
    PreviewJob job;
    row<PreviewJob>("slice").setText(job, "0.25");
    row<PreviewJob>("speed-max").setText(job, "4");
    row<PreviewJob>("match-density").setText(job, "true");
    EXPECT_EQ(job.slice, 0.25);
    EXPECT_EQ(job.speedMax, 4.0f);
    EXPECT_TRUE(job.matchDensity);
    EXPECT_TRUE(refuses<PreviewJob>("slice", "1.5"));
    EXPECT_TRUE(refuses<PreviewJob>("exposure", "0"));
    EXPECT_TRUE(refuses<PreviewJob>("speed-max", "0")); // its default, "from the picture", is not given
    EXPECT_TRUE(refuses<PreviewJob>("vorticity-max", "inf"));
}

TEST(StylizeSettingsTable, RowsNameTheirFieldsAndRefuseWhatTheOptionsRefuse)
{
    StylizeJob job;
    row<StylizeJob>("camera-pos").setText(job, "1,2,3");
    row<StylizeJob>("step").setText(job, "0.25");
    row<StylizeJob>("patchSize").setText(job, "7");
    row<StylizeJob>("fluidy.patchSize").setText(job, "9");
    row<StylizeJob>("seed").setText(job, "18446744073709551615");
    row<StylizeJob>("fluidy.reusePrevious").setText(job, "false");
    EXPECT_EQ(job.camera.position, "1,2,3");
    EXPECT_EQ(job.camera.step, 0.25f);
    EXPECT_EQ(job.settings.patchSize, 7);
    EXPECT_EQ(job.fluidy.settings.patchSize, 9);
    EXPECT_EQ(job.settings.seed, 18446744073709551615ull);
    EXPECT_FALSE(job.fluidy.settings.reusePrevious);
    // The camera's rows are the cache camera's table's, on StylizeJob::camera.
    const auto& camera = turb::run::cacheCameraSettings();
    for (size_t i = 0; i < camera.size(); ++i) EXPECT_EQ(turb::run::stylizeSettings()[i].key, camera[i].key);
    EXPECT_TRUE(refuses<StylizeJob>("fov", "0.5"));
    EXPECT_TRUE(refuses<StylizeJob>("extinction", "0"));
    EXPECT_TRUE(refuses<StylizeJob>("patchSize", "2"));
    EXPECT_TRUE(refuses<StylizeJob>("blurRadius", "0"));
    EXPECT_TRUE(refuses<StylizeJob>("nnf", "other"));
    EXPECT_TRUE(refuses<StylizeJob>("mask-threshold", "0"));
    EXPECT_TRUE(refuses<StylizeJob>("fluidy.boundaryBlur", "0.05"));
    EXPECT_TRUE(refuses<StylizeJob>("fluidy.dirClamp", "0"));
    EXPECT_TRUE(refuses<StylizeJob>("fluidy.fineSweeps", "33"));
    const clitest::Result old = clitest::run("stylize --exemplar e --no-reuse --print-settings", false);
    ASSERT_EQ(old.code, 0) << old.out;
    EXPECT_NE(old.out.find("\nfluidy.reusePrevious=false\n"), std::string::npos) << old.out;
}

} // namespace
