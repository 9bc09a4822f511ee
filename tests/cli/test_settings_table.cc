// turb::run's settings tables (turb/run/Settings.h): each row reaches its own field, checks its range, and is the
// option the command line declares (the CLI and the Python module both build on these rows). The tests every table
// passes are SettingsTableTests.h's; each table's own spot checks follow.
#include "SettingsTableTests.h"

#include <turb/run/Animate.h>
#include <turb/run/CacheCamera.h>
#include <turb/run/Measure.h>
#include <turb/run/Preview.h>
#include <turb/run/Sim.h>
#include <turb/run/Stylize.h>
#include <turb/run/Synth.h>
#include <turb/run/Transfer.h>

#include <limits>

namespace {

using turb::run::AnimateJob;
using turb::run::CacheCamera;
using turb::run::MeasureJob;
using turb::run::PreviewJob;
using turb::run::SimJob;
using turb::run::StylizeJob;
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

template<>
struct TableOf<MeasureJob>
{
    static const turb::run::SettingsTable<MeasureJob>& rows() { return turb::run::measureSettings(); }
    static constexpr const char* kName = "Measure";
    static constexpr const char* kCommand = "measure --output o --target t";
    static constexpr size_t kMinRows = 8;
    static constexpr const char* kOldSpellings = "--no-spectra --no-structure";
    static std::vector<std::string> oldLines() { return {"\ncomputeSpectra=false\n", "\nstructure=false\n"}; }
};

template<>
struct TableOf<SimJob>
{
    static const turb::run::SettingsTable<SimJob>& rows() { return turb::run::simSettings(); }
    static constexpr const char* kName = "Sim";
    static constexpr const char* kCommand = "sim plume";
    static constexpr size_t kMinRows = 4;
    static constexpr const char* kOldSpellings = "";
    static std::vector<std::string> oldLines() { return {}; }
};

template<>
struct TableOf<PreviewJob>
{
    static const turb::run::SettingsTable<PreviewJob>& rows() { return turb::run::previewSettings(); }
    static constexpr const char* kName = "Preview";
    static constexpr const char* kCommand = "preview a.####.vdb";
    static constexpr size_t kMinRows = 5;
    static constexpr const char* kOldSpellings = "";
    static std::vector<std::string> oldLines() { return {}; }
};

template<>
struct TableOf<CacheCamera> // stylize's and animate's camera; stylize declares them too
{
    static const turb::run::SettingsTable<CacheCamera>& rows() { return turb::run::cacheCameraSettings(); }
    static constexpr const char* kName = "CacheCamera";
    static constexpr const char* kCommand = "stylize --exemplar e";
    static constexpr size_t kMinRows = 6;
    static constexpr const char* kOldSpellings = "";
    static std::vector<std::string> oldLines() { return {}; }
};

template<>
struct TableOf<StylizeJob>
{
    static const turb::run::SettingsTable<StylizeJob>& rows() { return turb::run::stylizeSettings(); }
    static constexpr const char* kName = "Stylize";
    static constexpr const char* kCommand = "stylize --exemplar e";
    static constexpr size_t kMinRows = 50;
    static constexpr const char* kOldSpellings = "--no-reuse";
    static std::vector<std::string> oldLines() { return {"\nfluidy.reusePrevious=false\n"}; }
};

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

using Jobs =
    ::testing::Types<TransferJob, SynthJob, AnimateJob, MeasureJob, SimJob, PreviewJob, CacheCamera, StylizeJob>;
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

// `key` refuses `text`, naming itself.
template<typename Job>
bool refuses(const std::string& key, const std::string& text)
{
    Job job;
    try {
        rowOf<Job>(key).setText(job, text);
    } catch (const turb::ValueError& e) {
        EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
        return true;
    }
    return false;
}

TEST(MeasureSettingsTable, RowsNameTheirFieldsAndRefuseWhatTheOptionsRefuse)
{
    MeasureJob job;
    rowOf<MeasureJob>("patchSize").setText(job, "8");
    rowOf<MeasureJob>("sourceRead.extendVelocity").setText(job, "3");
    rowOf<MeasureJob>("computeSpectra").setText(job, "false");
    rowOf<MeasureJob>("alignment").setText(job, "index");
    rowOf<MeasureJob>("plot-format").setText(job, "svg");
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
    rowOf<SimJob>("preconditioner").setText(job, "jacobi");
    rowOf<SimJob>("scheme").setText(job, "bfecc");
    rowOf<SimJob>("pressureTolerance").setText(job, "0.001");
    EXPECT_FALSE(job.incompleteCholesky);
    EXPECT_EQ(job.scheme, turb::AdvectSettings::Scheme::BFECC);
    EXPECT_EQ(job.pressureTolerance, 0.001);
    EXPECT_EQ(rowOf<SimJob>("preconditioner").text(SimJob{}), "ic");
    EXPECT_TRUE(refuses<SimJob>("pressureTolerance", "0.6"));
    EXPECT_TRUE(refuses<SimJob>("cfl", "0")); // > 0
    EXPECT_TRUE(refuses<SimJob>("cfl", "nan"));
    EXPECT_TRUE(refuses<SimJob>("maxSubsteps", "65"));
    EXPECT_TRUE(refuses<SimJob>("preconditioner", "gauss"));
}

TEST(PreviewSettingsTable, RowsNameTheirFieldsAndRefuseWhatTheOptionsRefuse)
{
    PreviewJob job;
    rowOf<PreviewJob>("slice").setText(job, "0.25");
    rowOf<PreviewJob>("speed-max").setText(job, "4");
    rowOf<PreviewJob>("match-density").setText(job, "true");
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
    rowOf<StylizeJob>("camera-pos").setText(job, "1,2,3");
    rowOf<StylizeJob>("step").setText(job, "0.25");
    rowOf<StylizeJob>("patchSize").setText(job, "7");
    rowOf<StylizeJob>("fluidy.patchSize").setText(job, "9");
    rowOf<StylizeJob>("seed").setText(job, "18446744073709551615");
    rowOf<StylizeJob>("fluidy.reusePrevious").setText(job, "false");
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
