// The vdbturb executable on real-world cache conditions and on what a TD trips over first:
// dry runs that fail where the run would, time steps and units with their sources, messages
// that point at the fix, and info's data on stdout.
#include "CliUtil.h"

#include <turb/Metadata.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <openvdb/openvdb.h>
#include <turb/NewGrid.h>
#include <openvdb/io/File.h>

#include <fstream>
#include <iostream>
#include <sstream>
#include <map>
#include <memory>
#include <regex>
#include <system_error>

#include <unistd.h>

using clitest::run;

namespace {

std::string lo() { return testutil::dataPath("blender-plume-32/fluid_data_####.vdb"); }
std::string hi() { return testutil::dataPath("blender-plume-128/fluid_data_####.vdb"); }
std::string loFrame(int f)
{
    return testutil::dataPath(
        "blender-plume-32/fluid_data_00" + std::string(f < 10 ? "0" : "") + std::to_string(f) + ".vdb");
}

void writeGrids(const std::string& path, openvdb::GridPtrVec grids)
{
    openvdb::initialize();
    openvdb::io::File f(path);
    f.write(grids);
    f.close();
}

double numberAfter(const std::string& text, const std::string& key)
{
    const size_t at = text.find(key);
    return at == std::string::npos ? -1.0 : std::stod(text.substr(at + key.size()));
}

// A size as turbio::formatBytes prints it ("515 kB", "14 MB", "1.2 GB") after `key`, in MB; -1 without one.
double megabytesAfter(const std::string& text, const std::string& key)
{
    const size_t at = text.find(key);
    if (at == std::string::npos) return -1.0;
    std::istringstream in(text.substr(at + key.size()));
    double v = 0.0;
    std::string unit;
    if (!(in >> v >> unit)) return -1.0;
    return unit == "GB" ? v * 1e3 : unit == "MB" ? v : unit == "kB" ? v * 1e-3 : unit == "B" ? v * 1e-6 : -1.0;
}

} // namespace

TEST(CliReliability, ALoneNumberedFileKeepsItsFrameNumber)
{
    testutil::TempDir dir;
    std::filesystem::copy_file(loFrame(5), dir / "pyro.1001.vdb");
    const auto r = run("resample " + dir / "pyro.1001.vdb" + " --out '" + dir / "r.####.vdb'");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "r.1001.vdb")) << r.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "r.0000.vdb"));
    const auto info = run("info " + dir / "pyro.1001.vdb" + " --json --headers-only", false);
    EXPECT_NE(info.out.find("\"frame\": 1001"), std::string::npos) << info.out.substr(0, 300);
}

TEST(CliReliability, UnnamedGridsAreListedWithTheirOwnValuesAndCanBeChosen)
{
    testutil::TempDir dir;
    openvdb::initialize();
    auto d = turb::newGrid<openvdb::FloatGrid>(0.0f);
    d->fill(openvdb::CoordBBox({0, 0, 0}, {7, 7, 7}), 0.5f, true);
    d->setGridClass(openvdb::GRID_FOG_VOLUME);
    auto v = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    v->fill(openvdb::CoordBBox({0, 0, 0}, {7, 7, 7}), openvdb::Vec3s(0.0f, 0.0f, 2.0f), true);
    writeGrids(dir / "convert.vdb", {d, v});

    const auto info = run("info " + dir / "convert.vdb", false);
    ASSERT_EQ(info.code, 0) << info.out;
    EXPECT_NE(info.out.find("[0.5, 0.5]"), std::string::npos) << info.out;
    EXPECT_NE(info.out.find("[2, 2] |v|"), std::string::npos) << "the vec3 grid's own magnitudes\n" << info.out;
    const auto refused = run("info " + dir / "convert.vdb" + " --validate --vel-grid vel");
    EXPECT_EQ(refused.code, 1);
    EXPECT_NE(refused.out.find("#0 (unnamed) ([0]) float fog volume, #1 (unnamed) ([1]) vec3s"), std::string::npos)
        << refused.out;
    const auto chosen = run("info " + dir / "convert.vdb" + " --validate --density-grid '#0' --vel-grid '[1]'");
    EXPECT_EQ(chosen.code, 0) << chosen.out;
    EXPECT_NE(chosen.out.find("velocity and density"), std::string::npos) << chosen.out;
    const auto empty = run("info " + dir / "convert.vdb" + " --density-grid ''");
    EXPECT_EQ(empty.code, 2) << "'' cannot select an unnamed grid: the message says what does\n" << empty.out;
    EXPECT_NE(empty.out.find("'#N'"), std::string::npos) << empty.out;
}

TEST(CliReliability, LatticeChangesAreReportedUpFrontAndTransferRefusesBeforeWriting)
{
    testutil::TempDir dir;
    std::filesystem::create_directories(dir / "t");
    for (int f = 1; f <= 2; ++f) std::filesystem::copy_file(loFrame(f), dir / ("t/t." + std::to_string(f) + ".vdb"));
    // A re-cached frame 3 at twice the voxel size.
    ASSERT_EQ(run("resample " + loFrame(3) + " --frames 3 --down 2 --out " + dir / "t/t.3.vdb -q").code, 0);

    const std::string want =
        "voxel size changes from 0.125 at frame 2 (" + dir / "t/t.2.vdb) to 0.25 at frame 3 (" + dir / "t/t.3.vdb)";
    const auto info = run("info '" + dir / "t/t.@.vdb' --headers-only", false);
    EXPECT_NE(info.out.find(want), std::string::npos) << info.out;
    const auto json = run("info '" + dir / "t/t.@.vdb' --headers-only --json", false);
    EXPECT_NE(json.out.find("\"to_voxel\": 0.25"), std::string::npos) << json.out.substr(0, 600);

    const auto dry =
        run("transfer --target '" + dir / "t/t.@.vdb' --source " + hi() + " --out " + dir / "o/o.####.vdb --dry-run");
    EXPECT_EQ(dry.code, 1) << dry.out;
    EXPECT_NE(dry.out.find(want), std::string::npos) << dry.out;
    const auto real =
        run("transfer --target '" + dir / "t/t.@.vdb' --source " + hi() + " --out " + dir / "o/o.####.vdb");
    EXPECT_EQ(real.code, 1) << real.out;
    EXPECT_NE(real.out.find(want), std::string::npos) << real.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o")) << "refused before writing anything";

    // Per-frame commands read each frame on its own lattice, and say so once.
    const auto rs = run("resample '" + dir / "t/t.@.vdb' --out " + dir / "r/r.####.vdb");
    EXPECT_EQ(rs.code, 0) << rs.out;
    EXPECT_EQ(clitest::count(rs.out, "the lattice is not the same in every frame"), 1u) << rs.out;
    EXPECT_NEAR(turbio::readFrame(dir / "r/r.0003.vdb", 3, turbio::ReadOptions{}).lattice().voxelSize, 0.25, 1e-9);
}

TEST(CliReliability, HoudiniVelocityVoxelScaleIsReadAndSaidOnce)
{
    testutil::TempDir dir;
    openvdb::initialize();
    auto d = turb::newGrid<openvdb::FloatGrid>(0.0f);
    d->fill(openvdb::CoordBBox({0, 0, 0}, {15, 15, 15}), 0.5f, true);
    d->setName("density");
    d->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
    auto v = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    v->fill(openvdb::CoordBBox({0, 0, 0}, {7, 7, 7}), openvdb::Vec3s(1.0f, 0.0f, 0.0f), true);
    v->setName("vel");
    v->setTransform(openvdb::math::Transform::createLinearTransform(0.2));
    for (int f = 1; f <= 2; ++f) writeGrids(dir / ("pyro." + std::to_string(f) + ".vdb"), {d, v});
    const auto r = run("resample '" + dir / "pyro.$F.vdb' --out " + dir / "r/r.####.vdb");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(clitest::count(r.out, "resampled trilinearly onto the density's lattice"), 1u) << r.out;
    const turb::Frame f = turbio::readFrame(dir / "r/r.0001.vdb", 1, turbio::ReadOptions{});
    EXPECT_NEAR(f.lattice().voxelSize, 0.1, 1e-9);
    EXPECT_NEAR(f.velocity(8, 8, 8)[0], 1.0f, 1e-6);
}

TEST(CliReliability, DryRunFailsOnEveryFatalInputAsTheRunDoes)
{
    testutil::TempDir dir;
    const std::string out = " --out " + dir / "o/o.####.vdb";
    // A density-only target: the hint names transfer's own option.
    const std::string smoke = testutil::dataPath("houdini-smoke1/smoke.vdb");
    for (const std::string dry : {" --dry-run", ""}) {
        const auto r = run("transfer --target " + smoke + " --source " + hi() + " --out " + dir / "o/o.vdb" + dry);
        EXPECT_EQ(r.code, 1) << r.out;
        EXPECT_NE(r.out.find("smoke.vdb: no velocity"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find("--target-vel-grid"), std::string::npos) << r.out;
    }
    // A ratio whose output cannot fit: refused with the estimate and what would fit. Held whole (--target-no-crop):
    // by default only the smoke of this large Blender domain is held, and it fits (below).
    const std::string c42 = testutil::dataPath("blender-c42/fluid_data_####.vdb");
    const auto cropped = run("transfer --target " + c42 + " --source " + hi() + out + " --frames 1-2 --dry-run");
    // It needs about 20.6 GB: on a 24 GB machine whose other processes (a parallel ctest) hold some, the budget
    // (MemAvailable) may be short of it, which is exit 75, a retry's case, and not the whole domain's refusal.
    if (cropped.code == 75)
        EXPECT_NE(cropped.out.find("(MemAvailable: what other processes leave free)"), std::string::npos)
            << cropped.out;
    else EXPECT_EQ(cropped.code, 0) << cropped.out;
    EXPECT_EQ(cropped.out.find("3250x3250x1560"), std::string::npos) << cropped.out;
    for (const std::string dry : {" --dry-run", ""}) {
        const auto r =
            run("transfer --target " + c42 + " --target-no-crop --source " + hi() + out + " --frames 1-2" + dry);
        EXPECT_EQ(r.code, 1) << r.out;
        EXPECT_NE(r.out.find("3250x3250x1560"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find("not enough memory for this run"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find("A source box-downsampled by"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find("vdbturb resample"), std::string::npos) << r.out;
        EXPECT_EQ(r.out.find("bad_alloc"), std::string::npos) << r.out;
    }
    // --out through a regular file.
    std::ofstream(dir / "afile") << "x";
    for (const std::string dry : {" --dry-run", ""}) {
        const auto r = run(
            "transfer --target " + lo() + " --source " + hi() + " --out " + dir / "afile/o.####.vdb --frames 1" + dry);
        EXPECT_EQ(r.code, 1) << r.out;
        EXPECT_NE(r.out.find("afile is a file, not a directory"), std::string::npos) << r.out;
    }
    // An output that is an input.
    const auto same = run("resample " + dir / "afile" + " --out " + dir / "afile --dry-run");
    EXPECT_EQ(same.code, 1) << same.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));
}

TEST(CliReliability, DryRunPrintsTheLatticeRatioTimingAndEstimatesThatHold)
{
    testutil::TempDir dir;
    const std::string args =
        "transfer --target " + lo() + " --source " + hi() + " --out " + dir / "o/o.####.vdb --frames 1-2";
    const auto dry = run(args + " --dry-run", false);
    ASSERT_EQ(dry.code, 0) << dry.out;
    EXPECT_NE(dry.out.find("ratio 4 (target voxel 0.125, source voxel 0.03125)"), std::string::npos) << dry.out;
    // The output covers the target's smoke and margin; held whole, Blender's 32^3 domain.
    EXPECT_NE(dry.out.find("output lattice: "), std::string::npos) << dry.out;
    EXPECT_EQ(dry.out.find("output lattice: 128x128x128"), std::string::npos) << dry.out;
    const auto whole = run(args + " --target-no-crop --dry-run", false);
    EXPECT_NE(whole.out.find(
                  "output lattice: 128x128x128 voxels of 0.03125, world (-0.0625,-0.0625,-0.0625)-(3.938,3.938,3.938)"),
        std::string::npos)
        << whole.out;
    EXPECT_NE(dry.out.find(
                  "target dt: 0.104167 per frame (Blender's frame length 0.1 x 25/fps, time scale 1 assumed), fps 24 "
                  "(assumed: the cache records no frame rate)"),
        std::string::npos)
        << dry.out;
    EXPECT_NE(dry.out.find(
                  "target velocity: grid 'velocity', grid cells per time unit x voxel 0.125 = world units (detected"),
        std::string::npos)
        << dry.out;
    const double estimateMb = numberAfter(dry.out, "memory: about ");
    ASSERT_GT(estimateMb, 0.0) << dry.out;
    const double sizeMb = megabytesAfter(dry.out, "output size: about ");
    ASSERT_GT(sizeMb, 0.0) << dry.out;
    const double totalMb = megabytesAfter(dry.out, " for the largest frame, "); // the run's: summed over its frames
    ASSERT_GT(totalMb, sizeMb) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));

    // The run itself: its peak memory and file sizes against the estimates (both in MB above).
    const auto real = run(args + " --json -q", false);
    ASSERT_EQ(real.code, 0) << real.out;
    const double peakMb = numberAfter(real.out, "\"peak_rss_mb\":");
    ASSERT_GT(peakMb, 0.0) << real.out;
    EXPECT_GT(estimateMb, 0.5 * peakMb) << "estimate " << estimateMb << " MB, measured " << peakMb << " MB";
    EXPECT_LT(estimateMb, 2.0 * peakMb) << "estimate " << estimateMb << " MB, measured " << peakMb << " MB";
    const double fileMb = double(std::max(std::filesystem::file_size(dir / "o/o.0001.vdb"),
                              std::filesystem::file_size(dir / "o/o.0002.vdb"))) /
                          1e6;
    EXPECT_GT(sizeMb, fileMb / 3.0) << "estimate " << sizeMb << " MB, written " << fileMb << " MB";
    EXPECT_LT(sizeMb, fileMb * 3.0) << "estimate " << sizeMb << " MB, written " << fileMb << " MB";
    const double writtenMb =
        double(std::filesystem::file_size(dir / "o/o.0001.vdb") + std::filesystem::file_size(dir / "o/o.0002.vdb")) /
        1e6;
    EXPECT_GT(totalMb, writtenMb / 3.0) << "estimate " << totalMb << " MB, written " << writtenMb << " MB";
    EXPECT_LT(totalMb, writtenMb * 3.0) << "estimate " << totalMb << " MB, written " << writtenMb << " MB";
}

TEST(CliReliability, TimeStepFpsAndUnitsShowWhereTheyCameFrom)
{
    testutil::TempDir dir;
    const auto info = run("info " + loFrame(1) + " --headers-only", false);
    EXPECT_NE(
        info.out.find("dt: 0.104167 per frame (Blender's frame length 0.1 x 25/fps, time scale 1 assumed); fps 24 "
                      "(assumed: the cache records no frame rate)"),
        std::string::npos)
        << info.out;
    EXPECT_NE(info.out.find("velocity units: grid cells per time unit, x voxel 0.125 = world units (detected"),
        std::string::npos)
        << info.out;
    const auto fps = run("info " + loFrame(1) + " --headers-only --fps 25", false);
    EXPECT_NE(fps.out.find("dt: 0.1 per frame"), std::string::npos) << fps.out;
    EXPECT_NE(fps.out.find("fps 25 (--fps)"), std::string::npos) << fps.out;
    const auto houdini =
        run("info " + testutil::dataPath("houdini-vel/vel_VDB_bound_v02.vdb") + " --headers-only", false);
    EXPECT_NE(houdini.out.find("dt: 0.0416667 per frame (1/fps seconds)"), std::string::npos) << houdini.out;
    EXPECT_NE(houdini.out.find("velocity units: world units per time unit"), std::string::npos) << houdini.out;
    const auto flag = run("transfer --target " + lo() + " --source " + hi() + " --out " +
                              dir / "o.####.vdb --frames 1 --dry-run"
                                    " --target-fps 25 --source-dt 0.2",
        false);
    EXPECT_NE(flag.out.find("target dt: 0.1 per frame (Blender's frame length 0.1 x 25/fps, time scale 1 assumed), fps "
                            "25 (--target-fps)"),
        std::string::npos)
        << flag.out;
    EXPECT_NE(flag.out.find("source dt: 0.2 per frame (--source-dt)"), std::string::npos) << flag.out;

    // A run warns once per input when a convention is assumed; vdbturb's own output records its dt.
    const auto r = run("resample " + lo() + " --frames 1-3 --out " + dir / "r/r.####.vdb");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(clitest::count(r.out, "records no frame rate"), 1u) << r.out;
    const auto again = run("info '" + dir / "r/r.####.vdb' --headers-only");
    // Written for Houdini: per second, so 1/24 s a frame (the Blender input's 0.104167 units x 0.4 s).
    EXPECT_NE(again.out.find("dt: 0.0416667 per frame (vdbturb_dt metadata)"), std::string::npos) << again.out;
    EXPECT_NE(again.out.find("time unit 1 s (per second) (vdbturb_time_unit metadata)"), std::string::npos)
        << again.out;
    EXPECT_EQ(again.out.find("records no frame rate"), std::string::npos) << again.out;
}

TEST(CliReliability, TyposAndNearMissesGetTheFix)
{
    const auto cmd = run("tranfser --target x");
    EXPECT_EQ(cmd.code, 2);
    EXPECT_NE(cmd.out.find("did you mean 'transfer'?"), std::string::npos) << cmd.out;
    const auto flag = run("info --frmaes 1-3 x");
    EXPECT_EQ(flag.code, 2);
    EXPECT_NE(flag.out.find("did you mean --frames?"), std::string::npos) << flag.out;
    const auto dash = run("transfer -target x --source y --out z");
    EXPECT_EQ(dash.code, 2);
    EXPECT_NE(dash.out.find("long options take two: --target"), std::string::npos) << dash.out;
    EXPECT_EQ(dash.out.find("--target is required"), std::string::npos) << dash.out;
    // A command with subcommands (farm plan/submit/join): the subcommand and its options get the same help.
    const auto sub = run("farm plna --dir x");
    EXPECT_EQ(sub.code, 2);
    EXPECT_NE(sub.out.find("did you mean 'plan'?"), std::string::npos) << sub.out;
    const auto subFlag = run("farm plan --chunk 3 --target a --source b --out c");
    EXPECT_EQ(subFlag.code, 2);
    EXPECT_NE(subFlag.out.find("'farm plan' has no option --chunk; did you mean --chunks?"), std::string::npos)
        << subFlag.out;
    // Options that mean nothing for a command are not accepted.
    EXPECT_EQ(run("info --threads 2 " + loFrame(1)).code, 2);
    EXPECT_EQ(run("info --dry-run " + loFrame(1)).code, 2);
    EXPECT_EQ(run("resample --threads 2 " + loFrame(1) + " --out x.vdb").code, 2);
    // Patterns: a padding that is not on disk says which is; a directory is not "no such file".
    const auto pad = run("info '" + testutil::dataPath("blender-plume-32/fluid_data_###.vdb") + "'");
    EXPECT_EQ(pad.code, 1);
    EXPECT_NE(pad.out.find("fluid_data_####.vdb (10 files, 4-digit frame numbers)"), std::string::npos) << pad.out;
    const auto dirArg = run("info " + testutil::dataPath("blender-plume-32"));
    EXPECT_EQ(dirArg.code, 1);
    EXPECT_NE(dirArg.out.find("is a directory, not a cache"), std::string::npos) << dirArg.out;
    const auto houdini = run("info '" + testutil::dataPath("blender-plume-32/fluid_data_$F.vdb") + "'");
    EXPECT_NE(houdini.out.find("fluid_data_$F.vdb: no file matches"), std::string::npos) << houdini.out;
    EXPECT_EQ(houdini.out.find('@'), std::string::npos) << houdini.out;
    EXPECT_EQ(run("info '" + testutil::dataPath("blender-plume-32/fluid_data_${F4}.vdb") + "' --headers-only").code, 0);
}

TEST(CliReliability, StylizeAnimateAndFarmListEverydayOptionsAndSettingsApart)
{
    // --help lists the everyday options; --help-all adds the second tier, each old spelling named beside its
    // setting; --print-settings writes a setting under its key whichever spelling gave it.
    const auto listed = [](const std::string& help, const std::string& option) {
        return help.find("\n  " + option) != std::string::npos;
    };
    const std::map<std::string, std::pair<std::vector<std::string>, std::vector<std::string>>> tiers{
        {"stylize",
            {{"--method", "--exemplar ", "--cache", "--camera ", "--width", "--scene ", "--target-mask", "--out"},
                {"--patch,--patchSize", "--lambda", "--nnf", "--camera-pos", "--n,--fluidy.patchSize",
                    "--fluidy.reusePrevious", "--out-rot"}}},
        {"animate",
            {{"--example ", "--example-cache", "--target ", "--flow-strokes", "--hm ", "--out"},
                {"--tau", "--shutter,--average.shutter", "--hm-rep,--hm.reps", "--hm.blendPixels", "--orient"}}},
        {"farm plan",
            {{"--target", "--chunks", "--preroll", "--overlap", "--cpus"}, {"--retries", "--vdbturb", "--name"}}},
        {"farm join", {{"--dir", "--json"}, {"--half", "--style", "--velocity-margin", "--target-vel-grid"}}}};
    for (const auto& [command, options] : tiers) {
        const auto help = run(command + " --help", false);
        const auto all = run(command + " --help-all", false);
        ASSERT_EQ(help.code, 0) << command;
        ASSERT_EQ(all.code, 0) << command;
        for (const auto& o : options.first)
            EXPECT_TRUE(listed(help.out, o)) << command << " --help lacks " << o << help.out;
        for (const auto& o : options.second) {
            EXPECT_FALSE(listed(help.out, o)) << command << " --help lists " << o;
            EXPECT_TRUE(listed(all.out, o)) << command << " --help-all lacks " << o << all.out;
        }
    }
    const auto stylizeAll = run("stylize --help-all", false).out;
    EXPECT_NE(stylizeAll.find("(also: --no-reuse)"), std::string::npos) << stylizeAll;
    EXPECT_NE(run("animate --help-all", false).out.find("(also: --hm-exact-cells)"), std::string::npos);

    const auto printed = run("stylize --patch 7 --b 12 --no-reuse --nnf standard --print-settings", false);
    ASSERT_EQ(printed.code, 0) << printed.out;
    for (const char* line : {"\npatchSize=7\n", "\nfluidy.boundaryBlur=12\n", "\nfluidy.reusePrevious=false\n"})
        EXPECT_NE(printed.out.find(line), std::string::npos) << line << printed.out;
    const auto farm = run("farm plan --target a --source b --out c.####.vdb --retries 3 --print-settings", false);
    EXPECT_NE(farm.out.find("\nretries=3\n"), std::string::npos) << farm.out;

    // A settings file sets what the old spelling set: tau 12 leaves 20 - 12 frames of the built-in river.
    testutil::TempDir dir;
    {
        std::ofstream f(dir / "a.toml");
        f << "tau = 12\nhm.blendPixels = false\n";
    }
    const std::string animate =
        "animate --example builtin:river:48x40x20 --target builtin:river:48x40 --flow-strokes " +
        std::string(VDBTURB_SOURCE_DIR) + "/scenes/animate/river_strokes.json --out " + dir / "o.####.exr --dry-run";
    const auto fromFile = run(animate + " --settings " + dir / "a.toml");
    const auto fromFlags = run(animate + " --tau 12 --hm-exact-cells");
    ASSERT_EQ(fromFile.code, 0) << fromFile.out;
    EXPECT_NE(fromFile.out.find("tau 12 -> 8 frames"), std::string::npos) << fromFile.out;
    EXPECT_EQ(fromFile.out, fromFlags.out);
}

TEST(CliReliability, InfoPutsAlignedTablesWithWorldBoundsOnStdout)
{
    const auto r = run("info " + loFrame(3) + " --frames 3", false); // stdout only
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("domain (frame 3): 32x32x32 voxels, world (-0.0625,-0.0625,-0.0625)-(3.938,3.938,3.938)"),
        std::string::npos)
        << r.out;
    // Every row of the grid table starts its columns where the header's do.
    std::vector<std::string> rows;
    size_t at = r.out.find("  #  grid");
    ASSERT_NE(at, std::string::npos) << r.out;
    for (size_t i = 0; i < 6; ++i) {
        const size_t end = r.out.find('\n', at);
        rows.push_back(r.out.substr(at, end - at));
        at = end + 1;
    }
    for (const char* column : {"class", "voxel", "world bounds"}) {
        const size_t c = rows[0].find(column);
        ASSERT_NE(c, std::string::npos);
        for (size_t i = 1; i < rows.size(); ++i) {
            EXPECT_EQ(rows[i][c - 1], ' ') << column << " misaligned in: " << rows[i];
            EXPECT_NE(rows[i][c], ' ') << column << " misaligned in: " << rows[i];
        }
    }
    // Density box (9,9,1)-(22,22,10) at voxel 0.125: cells from 8.5 x 0.125 to 22.5 x 0.125 (z: 0.5 to 10.5).
    EXPECT_NE(r.out.find("(1.062,1.062,0.0625)-(2.812,2.812,1.312)"), std::string::npos)
        << "world bounds of the smoke\n"
        << r.out;
}

TEST(CliReliability, ValidateSaysADensityOnlyFileCannotDriveTransfer)
{
    const auto r = run("info " + testutil::dataPath("houdini-smoke1/smoke.vdb") + " --validate --headers-only", false);
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("density only, no velocity grid: it cannot drive transfer"), std::string::npos) << r.out;
}

TEST(CliReliability, ResolutionsAreCellsAlongXYZForEveryOption)
{
    // --flow-res and --scene-res (and sim --res) read NXxNYxNZ the same way: a factor-2 synthesis doubles each.
    const auto flow = run("synth --flow uniform --flow-res 12x8x1 --factor 2 --dry-run --out x.####.vdb", false);
    ASSERT_EQ(flow.code, 0) << flow.out;
    EXPECT_NE(flow.out.find("output lattice: 24x16x1 voxels"), std::string::npos) << flow.out;
    const auto scene =
        run("synth --scene plume --scene-res 12x8x16 --frames 1 --factor 2 --dry-run --out x.####.vdb", false);
    ASSERT_EQ(scene.code, 0) << scene.out;
    EXPECT_NE(scene.out.find("output lattice: 24x16x32 voxels"), std::string::npos) << scene.out;
    // Both are second-tier settings of synth: --help-all lists them.
    const auto help = run("synth --help-all", false);
    EXPECT_EQ(clitest::count(help.out, "NXxNYxNZ"), 2u) << help.out;
    EXPECT_NE(run("sim --help", false).out.find("NXxNYxNZ"), std::string::npos);
}

TEST(CliReliability, SynthDetailStaysNearTheSmoke)
{
    // Synth's detail fills still air only with --detail-everywhere (the paper). measure's
    // air_detail (detail rms more than 4 coarse cells from the smoke over its rms in the smoke; whole boxes read).
    testutil::TempDir dir;
    ASSERT_EQ(run("sim plume --res 16x16x24 --frames 3 --out '" + dir / "t/p.####.vdb' -q").code, 0);
    const std::string synth = "synth --target '" + dir / "t/p.####.vdb' --factor 2 --frames 2-3 --no-crop -q --json";
    for (const auto& [out, extra, region] :
        {std::array<std::string, 3>{"a", "", "smoke"}, {"b", " --detail-everywhere", "everywhere"}}) {
        const auto r = run(synth + extra + " --out '" + dir / out + "/s.####.vdb'");
        ASSERT_EQ(r.code, 0) << r.out;
        EXPECT_NE(r.out.find("\"detail_region\":\"" + region + "\""), std::string::npos) << r.out;
    }
    const auto air = [&](const std::string& out) {
        const auto m = run("measure --output '" + dir / out + "/s.####.vdb' --target '" + dir / "t/p.####.vdb" +
                           "' --no-spectra --no-structure --no-crop");
        EXPECT_EQ(m.code, 0) << m.out;
        return numberAfter(m.out, "air_detail ");
    };
    const double a = air("a"), b = air("b");
    EXPECT_GE(a, 0.0);
    EXPECT_LT(a, 0.1);
    EXPECT_GT(b, 0.5);
}

TEST(CliReliability, SynthRefusesNonsenseOrientationAndMarginsAndSaysWhatItSkips)
{
    // Found by a fresh user: a non-finite --secondary crashed the synthesis, NaN margins ran the whole synthesis
    // before failing, and --trace-descent without --json did nothing without a word.
    testutil::TempDir dir;
    const std::string base = "synth --flow vortex --flow-res 8x8x4 --factor 2 --frames 1 --out '" + dir / "s.####.vdb'";
    for (const char* v : {"nan,0,1", "inf,0,1", "1e300,0,1", "0,0,0"}) {
        const auto r = run(base + " --secondary " + v);
        EXPECT_EQ(r.code, 1) << v << "\n" << r.out;
        EXPECT_NE(r.out.find("--secondary: X,Y,Z must be finite and not zero"), std::string::npos) << r.out;
    }
    for (const char* o : {"--detail-margin nan", "--detail-margin -1", "--detail-falloff 0", "--detail-falloff inf"}) {
        const auto r = run(base + " " + o);
        EXPECT_EQ(r.code, 2) << o << "\n" << r.out;
        EXPECT_NE(r.out.find("must be a number of coarse cells"), std::string::npos) << r.out;
        EXPECT_LT(r.out.size(), 400u) << "a short message, not CLI11's infinite bound: " << r.out;
    }
    const auto trace = run(base + " --trace-descent");
    EXPECT_EQ(trace.code, 0) << trace.out;
    EXPECT_NE(trace.out.find("--trace-descent reports in the JSON lines only"), std::string::npos) << trace.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "s.0002.vdb"));
}

TEST(CliReliability, ResampleCarriesTheOtherGridsUnlessAskedNotTo)
{
    // The 20 grids of a Blender cache that are not density, velocity, temperature or flame were dropped.
    testutil::TempDir dir;
    const std::string in = testutil::dataPath("blender-c42/fluid_data_0001.vdb");
    const auto gridCount = [](const std::string& path) { return turbio::inspectFile(path, false).grids.size(); };
    const auto all = run("resample " + in + " --frames 1 --down 5 --out " + dir / "all.####.vdb");
    ASSERT_EQ(all.code, 0) << all.out;
    EXPECT_EQ(gridCount(dir / "all.0001.vdb"), gridCount(in)); // 24
    // What is not exact is said: the staggered previous velocity is moved as cell values.
    EXPECT_NE(all.out.find("'velocity_previous' is staggered"), std::string::npos) << all.out;
    const auto four =
        run("resample " + in + " --frames 1 --down 5 --drop-other-grids --out " + dir / "four.####.vdb -q");
    ASSERT_EQ(four.code, 0) << four.out;
    EXPECT_EQ(gridCount(dir / "four.0001.vdb"), 4u);
    // The frame's own grids are the same either way.
    const turb::Frame a = turbio::readFrame(dir / "all.0001.vdb", 1, turbio::ReadOptions{});
    const turb::Frame b = turbio::readFrame(dir / "four.0001.vdb", 1, turbio::ReadOptions{});
    EXPECT_EQ(a.density.values(), b.density.values());
}

TEST(CliReliability, ResampleKeepsTheRecordedDomainRatioAndPatchLatticeTrue)
{
    // Found by a fresh user: resample --down 2 of an up-res kept its domain and patch size in output voxels of the
    // old lattice, so info framed it twice too big and measure's block looked for seams at the wrong spacing.
    testutil::TempDir dir;
    turb::Frame f;
    f.number = 1;
    f.dt = 1.0 / 24.0;
    const turb::Lattice lat{0.25, {0.0, 0.0, 0.0}};
    f.velocity = turb::VectorField(turb::CoordBBox({0, 0, 0}, {31, 31, 31}), lat, turb::Vec3f(0.0f, 0.0f, 1.0f));
    f.density = turb::ScalarField(f.velocity.bbox(), lat, 0.5f);
    f.metadata[turb::meta::kRatio] = "4";
    f.metadata[turb::meta::kDomain] = "0 0 0 31 31 31";
    f.metadata[turb::meta::kPatchSize] = "8";
    f.metadata[turb::meta::kPatchOrigin] = "4,4,4";
    turbio::writeFrame(dir / "u.0001.vdb", f, turbio::WriteOptions{});
    const auto meta = [&](const std::string& path) {
        return turbio::readFrame(path, 1, turbio::ReadOptions{}).metadata;
    };
    ASSERT_EQ(run("resample " + dir / "u.0001.vdb" + " --down 2 --out " + dir / "h.0001.vdb -q").code, 0);
    const auto h = meta(dir / "h.0001.vdb");
    EXPECT_EQ(h.at(turb::meta::kRatio), "2");
    EXPECT_EQ(h.at(turb::meta::kDomain), "0 0 0 15 15 15");
    EXPECT_EQ(h.at(turb::meta::kPatchSize), "4");
    EXPECT_EQ(h.at(turb::meta::kPatchOrigin), "2,2,2");
    // By 3 only the domain divides; the rest is dropped rather than kept wrong.
    ASSERT_EQ(run("resample " + dir / "u.0001.vdb" + " --down 3 --out " + dir / "t.0001.vdb -q").code, 0);
    const auto t = meta(dir / "t.0001.vdb");
    EXPECT_EQ(t.at(turb::meta::kDomain), "0 0 0 10 10 10");
    EXPECT_EQ(t.count(turb::meta::kRatio) + t.count(turb::meta::kPatchSize) + t.count(turb::meta::kPatchOrigin), 0u);
}

// Issue 49: on a farm node the memory a run may use is the job's (Slurm's cgroup, a wrapper's ulimit -v), not the
// machine's. The pre-flight check compares its estimate with the smallest limit and names it; over it, the run
// exits 75 (a retry on a bigger node can run it) before writing anything.
TEST(FarmNode, AnAddressSpaceLimitIsTheBudgetAndARunOverItExits75)
{
    testutil::TempDir dir;
    const std::string args =
        "transfer --target " + lo() + " --source " + hi() + " --frames 1-2 --out '" + dir / "o/o.####.vdb'";
    const auto free = run(args + " --dry-run", false);
    ASSERT_EQ(free.code, 0) << free.out;
    EXPECT_NE(free.out.find("; this process may use "), std::string::npos) << free.out;
    // The run's estimate is about 324 MB; 300 MB of address space less what the libraries map is not enough.
    const auto limited = clitest::shell("prlimit --as=300000000 " + std::string(VDBTURB_EXE) + " " + args + " 2>&1");
    EXPECT_EQ(limited.code, 75) << limited.out;
    EXPECT_NE(limited.out.find("not enough memory for this run: it needs about "), std::string::npos) << limited.out;
    EXPECT_NE(limited.out.find("(RLIMIT_AS, ulimit -v, less "), std::string::npos) << limited.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o/o.0001.vdb")) << "nothing written";
    // With room to spare the limit is only said.
    const auto roomy = clitest::shell("prlimit --as=4000000000 " + std::string(VDBTURB_EXE) + " " + args + " -q 2>&1");
    EXPECT_EQ(roomy.code, 0) << roomy.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "o/o.0002.vdb"));
}

// The same with the memory cgroup a Slurm job (--mem) or a container sets. The limit is found from
// /proc/self/cgroup's path and each ancestor, in v2 (memory.max) and v1 (memory/memory.limit_in_bytes) layouts:
// checked on cgroup trees written here, then, where the test may create one (root, a memory controller), by a
// run inside a real child of its own cgroup with a 300 MB limit.
TEST(FarmNode, ACgroupMemoryLimitIsTheBudget)
{
    testutil::TempDir fake;
    const auto put = [&](const std::string& rel, const std::string& text) {
        std::filesystem::create_directories(std::filesystem::path(fake / rel).parent_path());
        std::ofstream(fake / rel) << text << "\n";
    };
    // v2: Slurm's limit on the job, the task in a step below it without one.
    put("memory.max", "max");
    put("slurm/job_7/memory.max", "300000000");
    put("slurm/job_7/step_0/memory.max", "max");
    const turbio::MemoryLimit v2 = turbio::detail::cgroupMemoryLimit("0::/slurm/job_7/step_0\n", fake.path());
    EXPECT_EQ(v2.bytes, 300000000);
    EXPECT_NE(v2.source.find(fake / "slurm/job_7/memory.max"), std::string::npos) << v2.source;
    // v1: the memory controller's line among others; v1 writes "no limit" as a huge number.
    put("memory/memory.limit_in_bytes", "9223372036854771712");
    put("memory/a/memory.limit_in_bytes", "9223372036854771712");
    put("memory/a/b/memory.limit_in_bytes", "200000000");
    const turbio::MemoryLimit v1 =
        turbio::detail::cgroupMemoryLimit("5:cpu,cpuacct:/x\n4:memory:/a/b\n0::/\n", fake.path());
    EXPECT_EQ(v1.bytes, 200000000);
    EXPECT_NE(v1.source.find("memory.limit_in_bytes, " + fake / "memory/a/b/"), std::string::npos) << v1.source;
    EXPECT_EQ(turbio::detail::cgroupMemoryLimit("4:cpu:/a\n", fake.path() + "/none").bytes, -1) << "no limit";

    std::string group;
    {
        std::ifstream in("/proc/self/cgroup");
        std::string line;
        while (std::getline(in, line)) {
            const size_t a = line.find(':'), b = line.find(':', a + 1);
            const std::string controllers = line.substr(a + 1, b - a - 1), path = line.substr(b + 1);
            if (("," + controllers + ",").find(",memory,") != std::string::npos)
                group = "/sys/fs/cgroup/memory" + (path == "/" ? std::string() : path);
            else if (controllers.empty() && group.empty() &&
                     std::filesystem::exists("/sys/fs/cgroup" + path + "/memory.max"))
                group = "/sys/fs/cgroup" + (path == "/" ? std::string() : path);
        }
    }
    const std::string child = group + "/vdbturb-test-" + std::to_string(::getpid());
    std::error_code ec;
    if (group.empty() || !std::filesystem::create_directory(child, ec)) {
        std::cout << "[ note     ] no real cgroup run: cannot create a child of this process's memory cgroup\n";
        return;
    }
    const bool v1Layout = std::filesystem::exists(child + "/memory.limit_in_bytes");
    {
        std::ofstream limit(child + (v1Layout ? "/memory.limit_in_bytes" : "/memory.max"));
        limit << 300000000;
    }
    testutil::TempDir dir;
    const std::string args =
        "transfer --target " + lo() + " --source " + hi() + " --frames 1-2 --out '" + dir / "o/o.####.vdb'";
    const auto r = clitest::shell("sh -c 'echo $$ > " + child + "/cgroup.procs && exec " + VDBTURB_EXE + " " + args +
                                  "' 2>&1");
    std::filesystem::remove(child, ec);
    EXPECT_EQ(r.code, 75) << r.out;
    EXPECT_NE(r.out.find("this process may use 300 MB (the cgroup's "), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(child), std::string::npos) << "names the limit's file: " << r.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o/o.0001.vdb"));
}

// A --settings file from a farm template: unknown keys, a key given twice (CLI11 merged the two into a list and
// printed "At Most 1 required but received 2"), NaN and huge values are refused with the file, the key and what
// is allowed (exit 2), before anything is read.
TEST(FarmNode, ASettingsFileWithUnknownDuplicateNaNOrHugeValuesIsRefused)
{
    testutil::TempDir dir;
    const std::string base = "transfer --target " + lo() + " --source " + hi() + " --frames 1 --dry-run --out '" +
                             dir / "o/o.####.vdb' --settings ";
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"bogus_key = 3\n", "'bogus_key' is not an option of vdbturb transfer"},
        {"gamma = 1\n# a comment\ngamma = 2\n", "'gamma' is set on lines 1 and 3; give it once"},
        {"[seams]\ngamma = 1\ngamma = 2\n", "'seams.gamma' is set on lines 2 and 3"},
        {"gamma = nan\n", "--gamma: nan is not a number"},
        {"gamma = 1e300\n", "--gamma: must be a finite NUMBER>=0 (at most 1e+30)"},
        {"velocity-margin = 1e12\n", "--velocity-margin: must be auto, -1 (the whole box) or a number of voxels"}};
    int n = 0;
    for (const auto& [text, says] : cases) {
        const std::string file = dir / ("s" + std::to_string(n++) + ".toml");
        std::ofstream(file) << text;
        const auto r = run(base + file);
        EXPECT_EQ(r.code, 2) << text << r.out;
        EXPECT_NE(r.out.find(says), std::string::npos) << text << r.out;
    }
    // The file --print-settings writes reads back whole: its sections hold no key twice.
    const std::string printed = dir / "printed.toml";
    std::ofstream(printed) << run("transfer --print-settings", false).out;
    const auto back = run(base + printed);
    EXPECT_EQ(back.code, 0) << back.out;
}

// Issue 49: a path is data. A folder named with spaces, $, ;, backquotes, both quotes and non-ASCII letters, and
// a cache whose file names begin with '-', through every command and through farm plan's Slurm scripts run as
// sh runs them: every frame lands where it should and nothing in a name is executed.
TEST(FarmNode, HostileNamesAreOnlyNames)
{
    testutil::TempDir dir;
    const std::string root = dir / "sp ace $(touch pwned1);`touch pwned2`'q\"\xc3\xb1";
    std::filesystem::create_directories(root);
    for (int f = 1; f <= 2; ++f)
        std::filesystem::copy_file(testutil::dataPath("blender-plume-32/fluid_data_000" + std::to_string(f) + ".vdb"),
            root + "/-lo.000" + std::to_string(f) + ".vdb");
    const auto q = [](const std::string& s) { return clitest::shellQuote(s); };
    const std::string lo = root + "/-lo.####.vdb", out = root + "/o;touch pwned3;.####.vdb";
    const auto ok = [&](const std::string& args) {
        const auto r = clitest::shell("cd " + q(dir.path()) + " && " + std::string(VDBTURB_EXE) + " " + args + " 2>&1");
        EXPECT_EQ(r.code, 0) << args << "\n" << r.out;
    };
    ok("info " + q(lo));
    ok("resample " + q(lo) + " --down 2 -q --out " + q(root + "/r $x.####.vdb"));
    ok("transfer --target " + q(lo) + " --source " + q(hi()) + " -q --out " + q(out));
    ok("measure --output " + q(out) + " --target " + q(lo) + " -q");
    ok("preview " + q(out) + " --frames 2 --width 64 -q --out " + q(root + "/p \xc3\xb1.png"));
    for (const char* name : {"r $x.0002.vdb", "o;touch pwned3;.0002.vdb", "p \xc3\xb1.png"})
        EXPECT_TRUE(std::filesystem::exists(root + "/" + name)) << name;

    ok("farm plan --target " + q(lo) + " --source " + q(hi()) +
        " --frames 1-2 --chunks 1 --overlap 0 --preroll 0 --out " + q(root + "/f `touch pwned4`.####.vdb") + " --dir " +
        q(root + "/farm $HOME"));
    const std::string farm = root + "/farm $HOME";
    const auto task = clitest::shell("cd " + q(dir.path()) + " && SLURM_ARRAY_TASK_ID=0 sh " +
                                     q(farm + "/chunks.sbatch") + " 2>&1 && sh " + q(farm + "/join.sbatch") + " 2>&1");
    EXPECT_EQ(task.code, 0) << task.out;
    EXPECT_TRUE(std::filesystem::exists(root + "/f `touch pwned4`.0002.vdb")) << task.out;
    const std::string script = clitest::slurp(farm + "/chunks.sbatch");
    EXPECT_NE(script.find("# --output is given by vdbturb farm submit"), std::string::npos) << script;
    for (const char* p : {"pwned1", "pwned2", "pwned3", "pwned4"}) {
        EXPECT_FALSE(std::filesystem::exists(dir / p)) << p << " was executed";
        EXPECT_FALSE(std::filesystem::exists(root + "/" + p)) << p << " was executed";
    }
    const auto name = run("farm plan --target " + q(lo) + " --source " + q(hi()) + " --out x.####.vdb --dir " +
                          q(dir / "f2") + " --name 'a\nb'");
    EXPECT_EQ(name.code, 2) << name.out;
    EXPECT_NE(name.out.find("only letters, digits and ._:,+=@%- may go into an #SBATCH line"), std::string::npos);
}

// Issue 49: two processes given the same frame must not both write it. A transfer holds its frames (an fcntl lock
// per frame in .o.####.vdb.lock beside them); a second run of overlapping frames exits 75 naming the first's pid,
// one of other frames into the same folder runs beside it, and the lock file is gone when both are done.
TEST(FarmNode, TwoTasksNeverWriteOneFrame)
{
    testutil::TempDir dir;
    const std::string out = dir / "o/o.####.vdb";
    const std::string pair = "transfer --target " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") +
                             " --source " + testutil::dataPath("blender-plume2-128/fluid_data_####.vdb") +
                             " --threads 1 --out ";
    clitest::Process first(pair + "'" + out + "' --frames 1-10 --progress lines", dir / "first.log");
    ASSERT_TRUE(first.waitForFile(dir / "o/o.0001.vdb", 120.0)) << clitest::slurp(dir / "first.log");
    const auto second = run(pair + "'" + out + "' --frames 5-6 -q");
    // Other frames of the shot into the same folder (the farm's case), and another folder, run beside it.
    const auto disjoint = run(pair + "'" + out + "' --frames 11-12 -q");
    const auto other = run(pair + "'" + dir / "p/o.####.vdb" + "' --frames 1-2 -q");
    const bool firstStillRunning = !std::filesystem::exists(dir / "o/o.0010.vdb");
    EXPECT_EQ(first.wait(), 0) << clitest::slurp(dir / "first.log");
    EXPECT_EQ(second.code, 75) << second.out;
    EXPECT_NE(second.out.find(dir / "o/o.0005.vdb: another vdbturb (pid "), std::string::npos) << second.out;
    EXPECT_NE(second.out.find("is writing this frame"), std::string::npos) << second.out;
    EXPECT_EQ(disjoint.code, 0) << disjoint.out;
    EXPECT_TRUE(firstStillRunning) << "frames 11-12 were written while 1-10 were (the runs overlapped)";
    EXPECT_EQ(other.code, 0) << other.out;
    for (const char* f : {"o.0001.vdb", "o.0010.vdb", "o.0011.vdb", "o.0012.vdb"})
        EXPECT_TRUE(std::filesystem::exists(dir / ("o/" + std::string(f)))) << f;
    EXPECT_FALSE(std::filesystem::exists(dir / "o/o.0005.vdb.tmp"));
    EXPECT_FALSE(std::filesystem::exists(dir / "o/.o.####.vdb.lock")) << "the last holder removes it";
}

// Issue 49, item 3: four transfers of one shot at once on two cores, each on its own frames (1-2, 3-5, 6-7 with frame 5
// as pre-roll, computed and not written, and 8-9), all writing into one folder, as a farm's tasks do. A transfer
// carries its detail from frame to frame, so a task's frames are compared with the same task run alone: the four run
// one after another (2 threads; transfer's result is the same at any thread count) into folders of their own. The
// first task is killed (kill -9 after its frame 1, which names the resume state file of odd frames) while the others
// run on and write odd frames (5, 7, 9), and resumed when they are done. Each frame is written once (one JSON line
// across the runs), bit-identical to its task run alone, and the folder holds the 9 frames and each task's own resume
// states, no temporary file and no lock. (With one pair of state files for all, the others overwrote the killed task's
// and its resume continued approximately, with a warning.)
TEST(FarmNode, FourTasksOfOneShotInOneFolderWriteEachFrameOnceAsEachAloneDoesAndAKilledOneResumesExactly)
{
    testutil::TempDir dir;
    const std::string pair = "transfer --target " + lo() + " --source " + hi() + " --out ";
    const std::vector<std::string> tasks = {"--frames 1-2", "--frames 3-5", "--frames 6-7 --preroll 1", "--frames 8-9"};
    const int taskOf[10] = {-1, 0, 0, 1, 1, 1, 2, 2, 3, 3}; // frame -> task
    for (size_t k = 0; k < tasks.size(); ++k) {
        const auto alone = run(pair + dir / ("alone" + std::to_string(k) + "/o.####.vdb ") + tasks[k] + " -q");
        ASSERT_EQ(alone.code, 0) << alone.out;
    }
    std::vector<std::unique_ptr<clitest::Process>> at;
    for (size_t k = 0; k < tasks.size(); ++k)
        at.push_back(
            std::make_unique<clitest::Process>(pair + dir / "one/o.####.vdb " + tasks[k] + " --threads 1 --json",
                dir / ("task" + std::to_string(k)), k == 0 ? "VDBTURB_TEST_KILL_AT=after-frame:1" : ""));
    std::string logs;
    for (size_t k = 0; k < tasks.size(); ++k) {
        const int status = at[k]->wait();
        const std::string log = clitest::slurp(dir / ("task" + std::to_string(k)));
        logs += log;
        if (k == 0) EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << log;
        else EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log;
    }
    const auto resumed = run(pair + dir / "one/o.####.vdb " + tasks[0] + " --threads 1 --json --resume");
    ASSERT_EQ(resumed.code, 0) << resumed.out;
    EXPECT_NE(resumed.out.find("resume: continuing after frame 1"), std::string::npos) << resumed.out;
    EXPECT_EQ(resumed.out.find("cannot be used"), std::string::npos) << "the task's own exact state: " << resumed.out;
    logs += resumed.out;
    for (int f = 1; f <= 9; ++f) {
        char name[16];
        std::snprintf(name, sizeof(name), "o.%04d.vdb", f);
        EXPECT_EQ(clitest::count(logs, "\"out\":\"" + dir / ("one/" + std::string(name)) + "\""), 1u)
            << name << " is written once";
        EXPECT_TRUE(clitest::sameVdbButUuid(
            dir / ("one/" + std::string(name)), dir / ("alone" + std::to_string(taskOf[f]) + "/" + name)))
            << name << " differs from its task run alone";
    }
    EXPECT_EQ(clitest::listing(dir / "one"),
        (std::vector<std::string>{"o.0001.vdb", "o.0002.vdb", "o.0003.vdb", "o.0004.vdb", "o.0005.vdb", "o.0006.vdb",
            "o.0007.vdb", "o.0008.vdb", "o.0009.vdb", "o.resume-state-3-even.vdb", "o.resume-state-3-odd.vdb",
            "o.resume-state-6-even.vdb", "o.resume-state-6-odd.vdb", "o.resume-state-8-even.vdb",
            "o.resume-state-8-odd.vdb", "o.resume-state-even.vdb", "o.resume-state-odd.vdb"}))
        << "the frames and each task's resume states: no temporary file, no lock file";
}

// Issue 49: a file holding 10,000 grids. `info` read every grid for its value range and kept each (the guarded
// reader never frees in its child): 3.1 GB and 10.9 s. Now the ranges stop after 1 GB of grids, said in the table,
// and the roles are resolved once (the per-grid lookup was quadratic): it runs within a 2 GB address space.
TEST(FarmNode, AFileOfTenThousandGridsIsListedInBoundedMemory)
{
    openvdb::initialize();
    testutil::TempDir dir;
    {
        openvdb::GridPtrVec grids;
        auto density = turb::newGrid<openvdb::FloatGrid>(0.0f);
        density->setName("density");
        density->tree().setValueOn(openvdb::Coord(1, 1, 1), 1.0f);
        grids.push_back(density);
        for (int i = 0; i < 10000; ++i) {
            auto g = turb::newGrid<openvdb::FloatGrid>(0.0f);
            g->setName("g" + std::to_string(i));
            g->tree().setValueOn(openvdb::Coord(i % 10, 0, 0), 1.0f);
            grids.push_back(g);
        }
        openvdb::io::File(dir / "many.vdb").write(grids);
    }
    const auto r =
        clitest::shell("prlimit --as=2000000000 " + std::string(VDBTURB_EXE) + " info '" + dir / "many.vdb" + "' 2>&1");
    EXPECT_EQ(r.code, 0) << r.out.substr(0, 2000);
    EXPECT_NE(r.out.find("grids not read (1 GB of grids read for ranges already)"), std::string::npos)
        << r.out.substr(0, 2000);
    EXPECT_NE(r.out.find(" g9999 "), std::string::npos) << "every grid is listed";
}
