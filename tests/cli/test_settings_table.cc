// turb::run's settings tables (turb/run/Settings.h): each row reaches its own field, checks its range, and is the
// option the command line declares (the CLI and the Python module both build on these rows). transfer's and synth's
// here, animate's in test_settings_table_animate.cc (its headers cannot meet transfer's); the tests every table
// passes are SettingsTableTests.h's.
#include "SettingsTableTests.h"

#include <turb/run/Synth.h>
#include <turb/run/Transfer.h>

#include <limits>

namespace {

using turb::run::SynthJob;
using turb::run::TransferJob;

template<>
struct TableOf<TransferJob>
{
    static const turb::run::SettingsTable<TransferJob>& rows() { return turb::run::transferSettings(); }
    static constexpr const char* kName = "Transfer";
    static constexpr const char* kCommand = "transfer --target t --source s --out o";
    static constexpr size_t kMinRows = 40;
    static constexpr const char* kOldSpellings = "--band 5 --no-seams --detail-energy pasted";
    static std::vector<std::string> oldLines()
    {
        return {"\nseams.bandWidth=5\n", "\nseams.bandWidth2D=5\n", "\nseams.enabled=false\n",
            "\ndetailEnergy=\"pasted\"\n", "\ndetailEnergy2D=\"pasted\"\n"};
    }
};

template<>
struct TableOf<SynthJob>
{
    static const turb::run::SettingsTable<SynthJob>& rows() { return turb::run::synthSettings(); }
    static constexpr const char* kName = "Synth";
    static constexpr const char* kCommand = "synth";
    static constexpr size_t kMinRows = 45;
    static constexpr const char* kOldSpellings = "--no-density --keep-coarse --omega-absolute --no-orient";
    static std::vector<std::string> oldLines()
    {
        return {"\ndensity=false\n", "\ncombine.removeCoarsePart=false\n", "\ncombine.relative=false\n",
            "\nsynth.orientation.follow=false\n"};
    }
};

using Jobs = ::testing::Types<TransferJob, SynthJob>;
INSTANTIATE_TYPED_TEST_SUITE_P(Tables, SettingsTable, Jobs, TableName);

TEST(TransferSettingsTable, RowsNameTheFieldsOfTheirKeys)
{
    const auto rowOf = ::rowOf<TransferJob>;
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
    const auto rowOf = ::rowOf<TransferJob>;
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

TEST(SynthSettingsTable, RowsNameTheFieldsOfTheirKeys)
{
    const auto rowOf = ::rowOf<SynthJob>;
    SynthJob job;
    rowOf("synth.boundary.lambda").set(job, 7.0);
    rowOf("combine.weighting").setText(job, "vorticity");
    rowOf("scene-res").setText(job, "16x16x8");
    rowOf("synth.seed").setText(job, "18446744073709551615"); // every 64-bit seed, beyond a double's integers
    rowOf("density").setText(job, "false");
    rowOf("combine.smokeFalloff").setText(job, "3.5");
    EXPECT_EQ(job.seq.synth.boundary.lambda, 7.0);
    EXPECT_EQ(job.seq.combine.weighting, turb::CombineSettings::Weighting::Vorticity);
    EXPECT_EQ(job.sceneRes, "16x16x8");
    EXPECT_EQ(job.seq.synth.seed, std::numeric_limits<std::uint64_t>::max());
    EXPECT_FALSE(job.seq.density);
    EXPECT_EQ(job.seq.combine.smokeFalloff, 3.5);
    // The margins' own check: a falloff must be > 0, a margin may be 0; neither beyond 1e6 coarse cells.
    EXPECT_THROW(rowOf("combine.smokeFalloff").setText(job, "0"), turb::ValueError);
    EXPECT_NO_THROW(rowOf("combine.smokeMargin").setText(job, "0"));
    EXPECT_THROW(rowOf("combine.smokeMargin").setText(job, "2e6"), turb::ValueError);
    // slice-z's default, -1 (3D), reads as it is, though no layer below 0 may be given.
    const SynthJob defaults;
    EXPECT_EQ(rowOf("slice-z").text(defaults), "-1");
    EXPECT_THROW(rowOf("slice-z").setText(job, "-1"), turb::ValueError);
    EXPECT_EQ(rowOf("synth.robustExponent").get(defaults), turb::SynthSettings{}.robustExponent);
}

} // namespace
