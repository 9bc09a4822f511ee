// animate's settings table (turb/run/Settings.h) through the tests every table passes (SettingsTableTests.h), in a
// file of its own: turb/ResidualTransfer.h, which turb/run/Animate.h includes, and turb/Transfer.h both define
// turb::TransferSettings.
#include "SettingsTableTests.h"

#include <turb/run/Animate.h>

namespace {

using turb::run::AnimateJob;

template<>
struct TableOf<AnimateJob>
{
    static const turb::run::SettingsTable<AnimateJob>& rows() { return turb::run::animateSettings(); }
    static constexpr const char* kName = "Animate";
    static constexpr const char* kCommand = "animate";
    static constexpr size_t kMinRows = 20;
    static constexpr const char* kOldSpellings = "--hm-exact-cells";
    static std::vector<std::string> oldLines() { return {"\nhm.blendPixels=false\n"}; }
};

INSTANTIATE_TYPED_TEST_SUITE_P(AnimateTable, SettingsTable, ::testing::Types<AnimateJob>, TableName);

TEST(AnimateSettingsTable, RowsNameTheFieldsOfTheirKeys)
{
    const auto rowOf = ::rowOf<AnimateJob>;
    AnimateJob job;
    rowOf("hm.reps").set(job, 5);
    rowOf("transfer.downsample").setText(job, "4");
    rowOf("hm-grid").setText(job, "4x3");
    rowOf("refine").setText(job, "off");
    rowOf("hmApply").setText(job, "sequence");
    rowOf("flow-y-up").set(job, 1);
    EXPECT_EQ(job.settings.hm.reps, 5);
    EXPECT_EQ(job.settings.transfer.downsample, 4);
    EXPECT_EQ(job.hmGrid, "4x3");
    EXPECT_EQ(job.refine, turb::run::AnimateRefine::Off);
    EXPECT_EQ(job.settings.hmApply, turb::HmApply::Sequence);
    EXPECT_TRUE(job.flowYUp);
    // The search's downsampling is 1, 2 or 4 only; the grid COLSxROWS, auto or off.
    EXPECT_THROW(rowOf("transfer.downsample").set(job, 3), turb::ValueError);
    EXPECT_THROW(rowOf("hm-grid").setText(job, "4x"), turb::ValueError);
    const AnimateJob defaults;
    EXPECT_EQ(rowOf("tau").get(defaults), turb::AnimateSettings{}.tau);
    EXPECT_EQ(rowOf("transfer.downsample").text(defaults), "2");
}

} // namespace
