// The vdbturb executable end to end: exit codes, atomic outputs, --resume, --dry-run, --no-clobber.
#include "CliUtil.h"
#include "TestUtil.h"

#include <turb/Metadata.h>
#include <turbio/ImageIO.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>

namespace {

using CmdResult = clitest::Result;

// `env` prefixes the command ("PATH=/x" runs it with another environment).
CmdResult run(const std::string& args, const std::string& env = "")
{
    return clitest::shell(env + (env.empty() ? "" : " ") + std::string(VDBTURB_EXE) + " " + args + " 2>&1");
}

std::string lo() { return testutil::dataPath("blender-plume-32/fluid_data_####.vdb"); }
std::string hi() { return testutil::dataPath("blender-plume-128/fluid_data_####.vdb"); }

} // namespace

TEST(Cli, UsageErrorsExitTwoAndMissingInputsExitOne)
{
    EXPECT_EQ(run("").code, 2);
    EXPECT_EQ(run("transfer --target x").code, 2);
    EXPECT_EQ(run("info --frames 1-3 --no-such-flag x").code, 2);
    // A malformed frame list is a usage error on every command that takes one, naming the bad piece, before
    // any file is looked at.
    for (const std::string cmd :
        {"info " + lo(), "measure --output o.####.vdb --target " + lo(), "resample " + lo() + " --out r.####.vdb",
            "transfer --target " + lo() + " --source " + hi() + " --out o.####.vdb", "preview " + lo()}) {
        const CmdResult bad = run(cmd + " --frames 10-1");
        EXPECT_EQ(bad.code, 2) << cmd << "\n" << bad.out;
        EXPECT_NE(bad.out.find("'10-1'"), std::string::npos) << bad.out;
    }
    EXPECT_EQ(
        run("transfer --target " + lo() + " --source " + hi() + " --out o.####.vdb --source-frames 1-4x0").code, 2);
    // Numbers the library would refuse only at frame 1 (NaN passes CLI11's own range checks) are usage errors.
    for (const std::string bad : {"--density-threshold -1", "--density-guide nan", "--alpha inf", "--beta -0.5"})
        EXPECT_EQ(run("transfer --target " + lo() + " --source " + hi() + " --out o.####.vdb --dry-run " + bad).code, 2)
            << bad;
    // NaN for any number of any command: refused after parsing, naming the option (2026-12-04: synth's solenoidal
    // tolerance and stylize's vote weight let it through to the first frame or to the settings file).
    for (const std::string cmd : {"synth --flow vortex --flow-res 8x8x1 --dry-run --combine.solenoidalTolerance nan",
             "stylize --scene rotate --scene-size 64x64 --frames 1 --exemplar builtin:fire:32 --dry-run --vote-weight "
             "NaN",
             "synth --flow vortex --flow-res 8x8x1 --dry-run --omega nan"}) {
        const CmdResult r = run(cmd);
        EXPECT_EQ(r.code, 2) << cmd << "\n" << r.out;
        EXPECT_NE(r.out.find("is not a number"), std::string::npos) << r.out;
    }
    // A bad --hm-grid is a usage error, caught while parsing like any other bad value.
    for (const char* grid : {"0x0", "abc", "2.5x2"})
        EXPECT_EQ(run(std::string("animate --example x.####.png --target y.png --hm-grid ") + grid).code, 2) << grid;
    // A flag spelling given the value false would have set the flag all the same: refused (2026-12-04).
    const CmdResult flagFalse = run("synth --flow vortex --flow-res 8x8x1 --dry-run --keep-divergence=false");
    EXPECT_EQ(flagFalse.code, 2) << flagFalse.out;
    EXPECT_NE(flagFalse.out.find("keep-divergence"), std::string::npos) << flagFalse.out;
    EXPECT_EQ(run("synth --flow vortex --flow-res 8x8x1 --dry-run --keep-divergence=true").code, 0);
    const CmdResult missing = run("info /nonexistent/cache.vdb");
    EXPECT_EQ(missing.code, 1);
    EXPECT_NE(missing.out.find("/nonexistent/cache.vdb"), std::string::npos) << missing.out;
}

TEST(Cli, ASourceWithAGapSaysHowToSkipIt)
{
    // --source-wrap maps only frames past the source's ends: for a frame missing inside its range the hint names
    // --source-frames (2026-12-05: it named --source-wrap, which cannot help there).
    testutil::TempDir dir;
    for (int f : {1, 2, 3, 5})
        std::filesystem::create_symlink(
            testutil::dataPath("blender-plume-128/fluid_data_000" + std::to_string(f) + ".vdb"),
            dir / ("s." + std::to_string(f) + ".vdb"));
    const std::string base = "transfer --target " + lo() + " --source '" + dir.path() + "/s.@.vdb' --out " +
                             dir / "o/o.####.vdb --frames 4 --dry-run";
    const CmdResult gap = run(base);
    EXPECT_EQ(gap.code, 1) << gap.out;
    EXPECT_NE(gap.out.find("has a gap there: give --source-frames"), std::string::npos) << gap.out;
    const CmdResult skipped = run(base + " --source-frames 1-3");
    EXPECT_EQ(skipped.code, 0) << skipped.out;
    // Past the end with --source-wrap error, the hint is the wrap's.
    const CmdResult past = run("transfer --target " + lo() + " --source '" + dir.path() + "/s.@.vdb' --out " +
                               dir / "o/o.####.vdb --frames 6 --source-wrap error --dry-run");
    EXPECT_EQ(past.code, 1) << past.out;
    EXPECT_NE(past.out.find("another --source-wrap maps it"), std::string::npos) << past.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));
}

TEST(Cli, TransferKeepsEightTargetVoxelsAroundTheSourcesSmoke)
{
    // Ratio 4: 8 target voxels are 32 source voxels (docs/design.md: 8 source voxels moved block and tcoh at
    // ratio 8); an explicit margin wins.
    const std::string args =
        "transfer --target " + lo() + " --source " + hi() + " --out /tmp/unused/o.####.vdb --frames 1 --dry-run -v";
    const CmdResult byRatio = run(args);
    EXPECT_EQ(byRatio.code, 0) << byRatio.out;
    EXPECT_NE(byRatio.out.find("source crop margin: 32 source voxels"), std::string::npos) << byRatio.out;
    const CmdResult given = run(args + " --source-crop-margin 5");
    EXPECT_NE(given.out.find("source crop margin: 5 source voxels"), std::string::npos) << given.out;
}

TEST(Cli, FrameRatesTakeARatioAsEditorialWritesThem)
{
    // 23.976 and 24000/1001 both name NTSC film: the ratio is read as its value; a ratio that is not one is a usage
    // error naming it.
    const std::string file = testutil::dataPath("blender-plume-32/fluid_data_0002.vdb");
    const auto fps = [&](const std::string& value) {
        const CmdResult r = clitest::runStdout("info " + file + " --fps " + value + " --json -q");
        const nlohmann::json j = nlohmann::json::parse(r.out);
        return j.at("timing").at("fps").get<double>();
    };
    EXPECT_DOUBLE_EQ(fps("24000/1001"), 24000.0 / 1001.0);
    EXPECT_DOUBLE_EQ(fps("23.976"), 23.976);
    EXPECT_DOUBLE_EQ(fps("25"), 25.0);
    for (const char* bad : {"24/0", "abc/2", "24/", "-24000/1001"}) {
        const CmdResult r = run("info " + file + " --fps " + bad);
        EXPECT_EQ(r.code, 2) << bad << ": " << r.out;
        EXPECT_NE(r.out.find("--fps"), std::string::npos) << r.out;
    }
}

TEST(Cli, InfoJsonGoesToStdoutAndReportsMissingFrames)
{
    testutil::TempDir dir;
    for (int f : {1, 2, 4})
        std::filesystem::copy_file(testutil::dataPath("blender-plume-32/fluid_data_000" + std::to_string(f) + ".vdb"),
            dir / ("p." + std::to_string(f) + ".vdb"));
    const std::string cmd = std::string(VDBTURB_EXE) + " info '" + dir.path() + "/p.@.vdb' --json -q 2>/dev/null";
    const clitest::Result r = clitest::shell(cmd);
    const std::string& json = r.out;
    EXPECT_EQ(r.code, 0);
    EXPECT_NE(json.find("\"missing\": [\n  3\n ]"), std::string::npos) << json.substr(0, 400);
    EXPECT_NE(json.find("\"units\": \"cells\""), std::string::npos);
}

TEST(Cli, WithJsonStdoutCarriesJsonLinesOnlyAlsoOnADryRun)
{
    // A farm wrapper parses stdout line by line: the plan and timing lines of a --dry-run belong on stderr then
    // (2026-12-05: synth's lattice lines and measure's timing lines came out on stdout, read before the command set
    // its own flag).
    testutil::TempDir dir;
    const std::vector<std::string> commands = {"synth --flow vortex --flow-res 8x8x8 --out " + dir / "y.####.vdb",
        "measure --output " + hi() + " --target " + lo() + " --frames 1",
        "transfer --target " + lo() + " --source " + hi() + " --out " + dir / "o.####.vdb --frames 1-2",
        "stylize --scene rotate --scene-size 64x64 --frames 1 --exemplar builtin:fire:32 --out " + dir / "s.####.png"};
    for (const std::string& cmd : commands) {
        const clitest::Result stdoutOnly =
            clitest::shell(std::string(VDBTURB_EXE) + " " + cmd + " --dry-run --json 2>/dev/null");
        const CmdResult both = run(cmd + " --dry-run --json");
        EXPECT_EQ(stdoutOnly.code, 0) << cmd << "\n" << both.out;
        std::istringstream lines(stdoutOnly.out);
        for (std::string line; std::getline(lines, line);)
            EXPECT_TRUE(nlohmann::json::accept(line)) << cmd << ": not JSON on stdout: " << line;
        // The plan is still printed, on stderr.
        EXPECT_GT(both.out.size(), stdoutOnly.out.size() + 40) << cmd << "\n" << both.out;
    }
    EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(Cli, EveryCommandsJsonIsOnStdoutOnly)
{
    // Issue 47: a pipeline reads stdout as JSON whatever the command; the human lines go to stderr. (resample and
    // farm plan had no --json; preview had no --dry-run.)
    testutil::TempDir dir;
    const std::string data = testutil::dataPath("blender-plume-32/fluid_data_####.vdb");
    const std::vector<std::string> commands = {"sim plume --res 8x8x12 --frames 2 --out " + dir / "s.####.vdb",
        "preview " + dir / "s.####.vdb" + " --mode density,vorticity --width 32 --sheet " + dir / "s.png",
        "preview " + dir / "s.####.vdb" + " --width 32 --out " + dir / "p.####.png" + " --dry-run",
        "resample " + data + " --frames 1-2 --down 2 --out " + dir / "r.####.vdb",
        "convert " + dir / "s.####.vdb" + " --out " + dir / "c.####.nvdb",
        "farm plan --dir " + dir / "farm" + " --target " + lo() + " --source " + hi() + " --out " + dir / "f.####.vdb" +
            " --frames 1-6 --chunks 2 --overlap 1 --preroll 1"};
    for (const std::string& cmd : commands) {
        const clitest::Result stdoutOnly = clitest::shell(std::string(VDBTURB_EXE) + " " + cmd + " --json 2>/dev/null");
        EXPECT_EQ(stdoutOnly.code, 0) << cmd << "\n" << run(cmd + " --json").out;
        std::istringstream lines(stdoutOnly.out);
        int n = 0;
        for (std::string line; std::getline(lines, line); ++n)
            EXPECT_TRUE(nlohmann::json::accept(line)) << cmd << ": not JSON on stdout: " << line;
        const bool dry = cmd.find("--dry-run") != std::string::npos;
        if (!dry) EXPECT_GE(n, 1) << cmd;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "p.0001.png")) << "a dry run writes nothing";
    // info prints one JSON document (indented for people), and nothing else on stdout.
    const clitest::Result info =
        clitest::shell(std::string(VDBTURB_EXE) + " info " +
                       testutil::dataPath("blender-plume-32/fluid_data_0002.vdb") + " --json 2>/dev/null");
    EXPECT_EQ(info.code, 0);
    EXPECT_TRUE(nlohmann::json::accept(info.out)) << info.out;
}

TEST(Cli, TransferWritesResumesAndNeverClobbers)
{
    testutil::TempDir dir;
    const std::string out = dir / "up/turb.####.vdb";
    // Dry run: resolves, prints the plan, writes nothing.
    const CmdResult dry =
        run("transfer --target " + lo() + " --source " + hi() + " --out " + out + " --frames 1-3 --dry-run");
    EXPECT_EQ(dry.code, 0) << dry.out;
    EXPECT_NE(dry.out.find("ratio 4 (target voxel 0.125, source voxel 0.03125)"), std::string::npos) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "up"));

    // Frames 1-2, then --resume to 3; compare with an uninterrupted 1-3 run.
    // The resumed run writes velocity only near the smoke (--velocity-margin) and keeps the last frame's full state
    // beside the outputs; the reference writes the whole box. Where both wrote velocity, frame 3 must agree.
    const CmdResult a = run(
        "transfer --target " + lo() + " --source " + hi() + " --out " + out + " --frames 1-2 -q --velocity-margin 2");
    ASSERT_EQ(a.code, 0) << a.out;
    const CmdResult b = run("transfer --target " + lo() + " --source " + hi() + " --out " + out +
                            " --frames 1-3 --resume --velocity-margin 2");
    ASSERT_EQ(b.code, 0) << b.out;
    EXPECT_NE(b.out.find("continuing after frame 2"), std::string::npos) << b.out;
    const std::string ref = dir / "ref/turb.####.vdb";
    const CmdResult whole3 =
        run("transfer --target " + lo() + " --source " + hi() + " --out " + ref + " --frames 1-3 -q --json");
    ASSERT_EQ(whole3.code, 0) << whole3.out;
    // On a real Blender pair: the density keeps the target's mass, peak and coarse means, and its
    // edge shows no coarse cells (the per-cell density guide drew them into the silhouette: density_imprint 2.1 on
    // these frames, now 0.88-1.03).
    const CmdResult m =
        run("measure --output " + ref + " --target " + lo() + " --source " + hi() + " --no-spectra --json");
    ASSERT_EQ(m.code, 0) << m.out;
    int measured = 0;
    std::istringstream jsonLines(m.out);
    for (std::string line; std::getline(jsonLines, line);) {
        if (line.empty() || line[0] != '{') continue;
        const nlohmann::json j = nlohmann::json::parse(line);
        if (!j.contains("frame")) continue; // the summary line
        SCOPED_TRACE("frame " + j.at("frame").dump());
        EXPECT_GE(j.at("mass_ratio").get<double>(), 0.9);
        EXPECT_LE(j.at("mass_ratio").get<double>(), 1.1);
        EXPECT_LE(j.at("peak_ratio").get<double>(), 1.05);
        EXPECT_LE(j.at("density_err").get<double>(), 0.1);
        EXPECT_LE(j.at("density_imprint").get<double>(), 1.2);
        ++measured;
    }
    EXPECT_EQ(measured, 3) << m.out;
    // Per-frame JSON carries the transfer's own lf_err and, from frame 2, its frame-to-frame change (tcoh).
    EXPECT_NE(whole3.out.find("\"lf_err\":"), std::string::npos) << whole3.out;
    EXPECT_NE(whole3.out.find("\"detail_change\":"), std::string::npos) << whole3.out;
    // The coarse-part options reach the library: lf_err stays within the tolerance asked for.
    const CmdResult tight =
        run("transfer --target " + lo() + " --source " + hi() + " --out " + dir / "tight/t.####.vdb" +
            " --frames 1-2 -q --json --coarse-tolerance 0.01 --box-keep 0.5 --whole-fresh-patches");
    ASSERT_EQ(tight.code, 0) << tight.out;
    size_t at = 0, lines = 0;
    while ((at = tight.out.find("\"lf_err\":", at)) != std::string::npos) {
        at += 9;
        EXPECT_LE(std::stod(tight.out.substr(at)), 0.01 + 1e-6) << tight.out;
        ++lines;
    }
    EXPECT_EQ(lines, 2u) << tight.out;
    EXPECT_NE(
        run("transfer --target " + lo() + " --source " + hi() + " --out " + dir / "bad/t.####.vdb" + " --box-keep 2")
            .code,
        0);
    turbio::ReadOptions whole_box; // the whole recorded domain, not only the smoke's neighbourhood
    whole_box.cropToSmoke = false;
    const turb::Frame resumed = turbio::readFrame(dir / "up/turb.0003.vdb", 3, whole_box);
    const turb::Frame whole = turbio::readFrame(dir / "ref/turb.0003.vdb", 3, whole_box);
    ASSERT_EQ(resumed.velocity.bbox(), whole.velocity.bbox());
    size_t written = 0, differ = 0;
    for (size_t n = 0; n < whole.velocity.size(); ++n) {
        const turb::Vec3f& r = resumed.velocity.data()[n];
        if (r == turb::Vec3f(0.0f)) continue; // not written
        ++written;
        differ += r != whole.velocity.data()[n];
    }
    EXPECT_EQ(differ, 0u) << "the resumed frame differs from the uninterrupted run";
    EXPECT_LT(double(written), 0.8 * double(whole.velocity.size())) << "velocity written over (nearly) the whole box";
    EXPECT_GT(written, 0u);
    EXPECT_EQ(resumed.density.values(), whole.density.values());
    EXPECT_EQ(resumed.metadata.at("vdbturb_patch_size"), "8");
    EXPECT_NEAR(resumed.lattice().voxelSize, 0.03125, 1e-9);

    // --no-clobber refuses and keeps the file.
    const auto before = std::filesystem::last_write_time(dir / "up/turb.0001.vdb");
    const CmdResult c =
        run("transfer --target " + lo() + " --source " + hi() + " --out " + out + " --frames 1 --no-clobber");
    EXPECT_EQ(c.code, 1);
    EXPECT_NE(c.out.find("no-clobber"), std::string::npos) << c.out;
    EXPECT_EQ(std::filesystem::last_write_time(dir / "up/turb.0001.vdb"), before);
    // Three frames and the trimmed run's resume state, odd and even frames; no temporary files.
    EXPECT_EQ(testutil::countEntries(dir / "up"), 5u) << "no temporary files may remain";
    EXPECT_TRUE(std::filesystem::exists(dir / "up/turb.resume-state-odd.vdb"));
    EXPECT_TRUE(std::filesystem::exists(dir / "up/turb.resume-state-even.vdb"));
}

TEST(Cli, TrimmedHalfFramesResumeExactlyFromTheStateKeptBesideThem)
{
    // Frames written small (velocity near the smoke, temperature and flame at it, half floats, density
    // clipped) still resume bit-identically, from the full-precision state of the last frame kept beside them.
    testutil::TempDir dir;
    const std::string base =
        "transfer --target " + lo() + " --source " + hi() + " --velocity-margin 1 --half --clipping 1e-3";
    ASSERT_EQ(run(base + " --out " + dir / "a/t.####.vdb --frames 1-3 -q").code, 0);
    ASSERT_EQ(run(base + " --out " + dir / "b/t.####.vdb --frames 1-2 -q").code, 0);
    const CmdResult resumed = run(base + " --out " + dir / "b/t.####.vdb --frames 1-3 --resume");
    ASSERT_EQ(resumed.code, 0) << resumed.out;
    EXPECT_EQ(resumed.out.find("cannot be used"), std::string::npos) << resumed.out;
    turbio::ReadOptions whole;
    whole.cropToSmoke = false;
    const auto read = [&](const std::string& rel, int frame) { return turbio::readFrame(dir / rel, frame, whole); };
    const turb::Frame a3 = read("a/t.0003.vdb", 3), b3 = read("b/t.0003.vdb", 3);
    EXPECT_EQ(a3.velocity.values(), b3.velocity.values());
    EXPECT_EQ(a3.density.values(), b3.density.values());
    EXPECT_EQ(
        read("a/t.resume-state-odd.vdb", 3).velocity.values(), read("b/t.resume-state-odd.vdb", 3).velocity.values());
    // Written otherwise, the sequence would hold two formats: refused, naming each write setting that differs.
    const CmdResult other =
        run("transfer --target " + lo() + " --source " + hi() +
            " --full-float --velocity-margin 2 --clipping 1e-3 --out " + dir / "b/t.####.vdb --frames 1-4 --resume");
    EXPECT_EQ(other.code, 1) << other.out;
    EXPECT_NE(other.out.find("half: 1 -> 0"), std::string::npos) << other.out;
    EXPECT_NE(other.out.find("velocity-margin: 1 -> 2"), std::string::npos) << other.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "b/t.0004.vdb"));

    // What the small file holds: half floats, velocity near the smoke, temperature at it, no faint density.
    const turbio::FileInfo info = turbio::inspectFile(dir / "a/t.0003.vdb", true);
    long long densityVoxels = -1, velocityVoxels = -1, temperatureVoxels = -1;
    for (const turbio::GridInfo& g : info.grids) {
        EXPECT_TRUE(g.halfFloat) << g.name;
        if (g.name == "density") {
            densityVoxels = g.activeVoxels;
            EXPECT_GT(g.minValue, 1e-3) << "density at or below --clipping is written";
        }
        if (g.name == "vel") velocityVoxels = g.activeVoxels;
        if (g.name == "temperature") temperatureVoxels = g.activeVoxels;
    }
    const turb::Frame state = read("a/t.resume-state-odd.vdb", 3);
    ASSERT_GT(densityVoxels, 0);
    EXPECT_LT(velocityVoxels, (long long)(state.velocity.size()) / 2) << "velocity written over (nearly) the whole box";
    EXPECT_GE(velocityVoxels, densityVoxels);
    EXPECT_GT(temperatureVoxels, 0);
    EXPECT_LE(temperatureVoxels, densityVoxels) << "temperature is written at the smoke only, as Blender writes it";
    const CmdResult shown = run("info " + dir / "a/t.0003.vdb");
    EXPECT_NE(shown.out.find("velocity written only within 1 voxel of the smoke, 16-bit floats"), std::string::npos)
        << shown.out;

    // Without the state (deleted, or holding another frame) the run goes on from the small file, says so, and the
    // frame is no longer the uninterrupted run's.
    std::filesystem::remove(dir / "b/t.0003.vdb");
    std::filesystem::remove(dir / "b/t.resume-state-even.vdb");
    const CmdResult lost = run(base + " --out " + dir / "b/t.####.vdb --frames 1-3 --resume");
    ASSERT_EQ(lost.code, 0) << lost.out;
    EXPECT_NE(lost.out.find("b/t.resume-state-even.vdb cannot be used: it is missing"), std::string::npos) << lost.out;
    EXPECT_NE(read("b/t.0003.vdb", 3).velocity.values(), a3.velocity.values());
    std::filesystem::remove(dir / "b/t.0003.vdb");
    std::filesystem::copy_file(dir / "b/t.resume-state-odd.vdb", dir / "b/t.resume-state-even.vdb");
    const CmdResult ahead = run(base + " --out " + dir / "b/t.####.vdb --frames 1-3 --resume");
    ASSERT_EQ(ahead.code, 0) << ahead.out;
    EXPECT_NE(ahead.out.find("it holds frame 3, not 2"), std::string::npos) << ahead.out;

    EXPECT_EQ(run(base + " --out " + dir / "c/t.####.vdb --frames 1 --clipping nan").code, 2);
}

TEST(Cli, PrerollMatchesALongerRunAndResumeRefusesOtherSettings)
{
    // A run asked for frame 2 starts its detail fresh there: it says so, and --preroll 1 runs
    // frame 1 first without writing it, which gives exactly the frame of a run over 1-2.
    testutil::TempDir dir;
    const std::string base = "transfer --target " + lo() + " --source " + hi();
    const CmdResult whole = run(base + " --out " + dir / "whole/t.####.vdb --frames 1-2 -q");
    ASSERT_EQ(whole.code, 0) << whole.out;
    const CmdResult fresh = run(base + " --out " + dir / "fresh/t.####.vdb --frames 2");
    ASSERT_EQ(fresh.code, 0) << fresh.out;
    EXPECT_NE(fresh.out.find("starts fresh at frame 2"), std::string::npos) << fresh.out;
    const CmdResult pre = run(base + " --out " + dir / "pre/t.####.vdb --frames 2 --preroll 1");
    ASSERT_EQ(pre.code, 0) << pre.out;
    EXPECT_NE(pre.out.find("pre-roll frame 1"), std::string::npos) << pre.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "pre/t.0001.vdb")) << "pre-roll frames are not written";
    const turb::Frame a = turbio::readFrame(dir / "whole/t.0002.vdb", 2, turbio::ReadOptions{});
    const turb::Frame b = turbio::readFrame(dir / "pre/t.0002.vdb", 2, turbio::ReadOptions{});
    const turb::Frame c = turbio::readFrame(dir / "fresh/t.0002.vdb", 2, turbio::ReadOptions{});
    EXPECT_EQ(a.velocity.values(), b.velocity.values());
    EXPECT_EQ(a.density.values(), b.density.values());
    EXPECT_NE(a.velocity.values(), c.velocity.values()) << "without the pre-roll frame 2 differs";

    // --resume with settings that change the output is refused, naming each setting; nothing is written.
    const std::string out = dir / "whole/t.####.vdb";
    const CmdResult other = run(base + " --out " + out + " --frames 1-3 --resume --temporal-blend 0.5 --gamma 0");
    EXPECT_EQ(other.code, 1) << other.out;
    EXPECT_NE(other.out.find("temporal-blend: 0.95 -> 0.5"), std::string::npos) << other.out;
    EXPECT_NE(other.out.find("gamma: 10 -> 0"), std::string::npos) << other.out;
    const CmdResult scheme = run(base + " --out " + out + " --frames 1-3 --resume --density-scheme maccormack");
    EXPECT_EQ(scheme.code, 1) << scheme.out;
    EXPECT_NE(scheme.out.find("density-scheme: bfecc -> maccormack"), std::string::npos) << scheme.out;
    // Settings recorded only when not their default (so older outputs still resume) are compared all the same. A
    // setting's 2D twin does not apply to these 3D frames, so it may differ (2026-12-05: a new user's resume with
    // --structureTolerance2D was refused, though the voxels would be the same).
    const CmdResult structure = run(base + " --out " + out + " --frames 1-3 --resume --structureTolerance 0.2");
    EXPECT_EQ(structure.code, 1) << structure.out;
    EXPECT_NE(structure.out.find("structure-tolerance: 0 -> 0.2"), std::string::npos) << structure.out;
    const CmdResult twins2D = run(base + " --out " + out +
                                  " --frames 1-3 --resume --dry-run --seams.bandWidth2D 5 --seams.cgTolerance2D 0.001"
                                  " --structureTolerance2D 0.5 --regenerateBlend2D 0.3 --detail-energy-2d none");
    EXPECT_EQ(twins2D.code, 0) << twins2D.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "whole/t.0003.vdb"));
    // The same settings (threads do not count) continue.
    const CmdResult same = run(base + " --out " + out + " --frames 1-3 --resume --threads 1");
    EXPECT_EQ(same.code, 0) << same.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "whole/t.0003.vdb"));
}

TEST(Cli, PreviewFramesASequenceWithOneCamera)
{
    // Smoke that grows over a sequence, written sparse (as vdbturb and Houdini write it). Every
    // frame is drawn over the union of the frames' domains: the pictures keep one size and the smoke stays put.
    testutil::TempDir dir;
    const turb::Lattice lat{0.1, {0.0, 0.0, 0.0}};
    turbio::WriteOptions w;
    w.densityTolerance = 1e-6f;
    std::filesystem::create_directories(dir / "in");
    for (int fr = 1; fr <= 2; ++fr) {
        const int top = fr == 1 ? 7 : 23;
        const turb::Frame f = testutil::makeFrame(
            fr, turb::CoordBBox({0, 0, 0}, {15, 15, top}), lat, [](const turb::Vec3d&) { return turb::Vec3f(0.0f); },
            [](const turb::Coord&) { return 1.0f; });
        turbio::writeFrame(dir / ("in/s." + std::to_string(fr) + ".vdb"), f, w);
    }
    const CmdResult r = run("preview " + dir / "in/s.#.vdb" + " --mode density --width 64 --out " + dir / "p/p.#.png");
    ASSERT_EQ(r.code, 0) << r.out;
    const turb::RgbaImage a = turbio::readImage(dir / "p/p.1.png"), b = turbio::readImage(dir / "p/p.2.png");
    EXPECT_EQ(a.width(), b.width());
    EXPECT_EQ(a.height(), b.height()) << "each frame framed to its own smoke";
    EXPECT_EQ(a.height(), 96) << "the union of the domains is 16 x 24 voxels: 64 x 96 pixels";
}

TEST(Cli, SheetColumnsOfOneSceneShareOneCamera)
{
    // A coarse cache (voxel 0.4, its smoke everywhere) and a fine one (voxel 0.1) with smoke in half of the same
    // world: each alone is framed to its smoke and margin, so an up-res came out zoomed beside its target. In one
    // sheet both are drawn over the union of their world boxes; a cache elsewhere in the world, or one of another
    // scale around the same origin, keeps its own.
    testutil::TempDir dir;
    const auto write = [&](const std::string& name, double voxel, double shift, turb::CoordBBox box) {
        std::filesystem::create_directories(dir / name);
        const turb::Frame f = testutil::makeFrame(
            1, box, turb::Lattice{voxel, turb::Vec3d(shift)}, [](const turb::Vec3d&) { return turb::Vec3f(0.0f); },
            [](const turb::Coord&) { return 1.0f; });
        turbio::writeFrame(dir / (name + "/c.1.vdb"), f, turbio::WriteOptions{});
    };
    write("coarse", 0.4, 0.2, turb::CoordBBox({0, 0, 0}, {7, 7, 7}));   // world 0 - 3.2
    write("fine", 0.1, 0.05, turb::CoordBBox({0, 0, 0}, {15, 15, 15})); // world 0 - 1.6
    write("far", 0.1, 100.05, turb::CoordBBox({0, 0, 0}, {3, 3, 3}));   // world 100 - 100.4
    write("tiny", 0.01, 0.005, turb::CoordBBox({0, 0, 0}, {3, 3, 3}));  // world 0 - 0.04: another scale
    const CmdResult r =
        run("preview a=" + dir / "coarse/c.#.vdb" + " b=" + dir / "fine/c.#.vdb" + " c=" + dir / "far/c.#.vdb" +
            " d=" + dir / "tiny/c.#.vdb" + " --mode density,speed --width 32 --sheet " + dir / "s.png" + " --json -q");
    ASSERT_EQ(r.code, 0) << r.out;
    const auto at = r.out.find("{\"");
    ASSERT_NE(at, std::string::npos) << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out.substr(at, r.out.find('\n', at) - at));
    const auto& framed = j.at("framed");
    for (int k = 0; k < 6; ++k)
        EXPECT_NEAR(framed.at("a")[k].get<double>(), framed.at("b")[k].get<double>(), 1e-6) << r.out;
    EXPECT_NEAR(framed.at("b")[3].get<double>(), 3.2, 1e-6) << "the coarse cache's whole box: " << r.out;
    EXPECT_NEAR(framed.at("c")[0].get<double>(), 100.0, 1e-6) << "a cache elsewhere keeps its own camera: " << r.out;
    EXPECT_NEAR(framed.at("d")[3].get<double>(), 0.04, 1e-6) << "a cache of another scale keeps its own: " << r.out;
    // A single unnumbered file beside a sequence is drawn in every row, and the rows are the sequence's frames.
    std::filesystem::copy_file(dir / "coarse/c.1.vdb", dir / "still.vdb");
    std::filesystem::copy_file(dir / "fine/c.1.vdb", dir / "fine/c.2.vdb");
    const CmdResult still = run("preview s=" + dir / "still.vdb" + " b=" + dir / "fine/c.#.vdb" +
                                " --mode density --width 32 --sheet " + dir / "s2.png" + " --json -q");
    ASSERT_EQ(still.code, 0) << still.out;
    EXPECT_EQ(still.out.find("missing"), std::string::npos) << still.out;
    EXPECT_NE(still.out.find("\"frame\":2"), std::string::npos) << "rows from the sequence: " << still.out;
    // A transfer output holds only its smoke's neighbourhood (here world 0 - 0.4, too small beside its target to
    // count as the same scene) but records its target's domain (vdbturb_sequence_domain, world 0 - 3.2): it is
    // framed over that domain, in line with its target.
    std::filesystem::create_directories(dir / "up");
    turb::Frame up = testutil::makeFrame(
        1, turb::CoordBBox({0, 0, 0}, {3, 3, 3}), turb::Lattice{0.1, turb::Vec3d(0.05)},
        [](const turb::Vec3d&) { return turb::Vec3f(0.0f); }, [](const turb::Coord&) { return 1.0f; });
    up.metadata[turb::meta::kSequenceDomain] = "0 0 0 31 31 31";
    turbio::writeFrame(dir / "up/u.1.vdb", up, turbio::WriteOptions{});
    const CmdResult aligned = run("preview t=" + dir / "coarse/c.#.vdb" + " o=" + dir / "up/u.#.vdb" +
                                  " --mode density --width 32 --sheet " + dir / "s3.png" + " --json -q");
    ASSERT_EQ(aligned.code, 0) << aligned.out;
    const auto at3 = aligned.out.find("{\"");
    ASSERT_NE(at3, std::string::npos) << aligned.out;
    const nlohmann::json j3 = nlohmann::json::parse(aligned.out.substr(at3, aligned.out.find('\n', at3) - at3));
    for (int k = 0; k < 6; ++k)
        EXPECT_NEAR(j3.at("framed").at("o")[k].get<double>(), j3.at("framed").at("t")[k].get<double>(), 1e-6)
            << aligned.out;
}

TEST(Cli, MeasureAndPreviewTakeADensityOnlyCacheAsBlendersNoiseWrites)
{
    // Blender's noise up-res writes density_noise and no velocity (issue 42 measured it by copying it into a file
    // with a zero vel). measure gives its density numbers; a sheet draws it beside velocity caches, its velocity
    // cells left empty and labelled; alone in a velocity mode it is refused, naming the file.
    testutil::TempDir dir;
    turb::Frame f = turbio::readFrame(testutil::dataPath("blender-plume-128/fluid_data_0002.vdb"), 2, {});
    f.velocity = turb::VectorField();
    std::filesystem::create_directories(dir / "noise");
    turbio::writeFrame(dir / "noise/n.0002.vdb", f, turbio::WriteOptions{});
    const CmdResult m = clitest::runStdout("measure --output " + dir / "noise/n.####.vdb" + " --target " + lo() +
                                           " --source " + hi() + " --frames 2 --no-spectra -q");
    ASSERT_EQ(m.code, 0) << m.out;
    const nlohmann::json j = nlohmann::json::parse(m.out.substr(0, m.out.find('\n')));
    EXPECT_TRUE(j.at("edge_crispness").is_number()) << m.out;
    EXPECT_TRUE(j.at("density_fray").is_number()) << m.out;
    EXPECT_TRUE(j.at("mass_ratio").is_number()) << m.out;
    EXPECT_TRUE(j.at("lf_err").is_null()) << m.out;
    EXPECT_EQ(j.at("ratio").get<int>(), 4);

    const CmdResult sheet = run("preview t=" + lo() + " n=" + dir / "noise/n.####.vdb" +
                                " --mode density,vorticity --frames 2 --width 32 --sheet " + dir / "s.png" + " -q");
    EXPECT_EQ(sheet.code, 0) << sheet.out;
    const CmdResult alone = run("preview " + dir / "noise/n.####.vdb" + " --mode vorticity --frames 2 --width 32 --out " +
                                dir / "v.####.png" + " -q");
    EXPECT_EQ(alone.code, 1) << alone.out;
    EXPECT_NE(alone.out.find("n.0002.vdb"), std::string::npos) << alone.out;
    EXPECT_NE(alone.out.find("no velocity"), std::string::npos) << alone.out;

    // Blender's noise writes about f times its base's density. --match-density draws each cache at the first one's
    // peak: the same smoke at 8 times the density is drawn as the original, pixel for pixel.
    for (auto& v : f.density.values()) v *= 8.0f;
    turbio::writeFrame(dir / "noise/n8.0002.vdb", f, turbio::WriteOptions{});
    const auto cell = [&](const std::string& second, const std::string& extra, const std::string& png) {
        const CmdResult r = run("preview a=" + dir / "noise/n.####.vdb" + " b=" + dir / second +
                                " --mode density --frames 2 --width 48 --sheet " + dir / png + " --json -q " + extra);
        EXPECT_EQ(r.code, 0) << r.out;
        const auto at = r.out.find("{\"");
        EXPECT_NE(at, std::string::npos) << r.out;
        const nlohmann::json js = nlohmann::json::parse(r.out.substr(at, r.out.find('\n', at) - at));
        return std::make_pair(js.at("density_scale").at("b").get<double>(), turbio::readImage(dir / png));
    };
    const auto same = cell("noise/n.####.vdb", "", "same.png");
    const auto matched = cell("noise/n8.####.vdb", "--match-density", "matched.png");
    const auto unmatched = cell("noise/n8.####.vdb", "", "unmatched.png");
    EXPECT_DOUBLE_EQ(same.first, 1.0);
    EXPECT_NEAR(matched.first, 0.125, 1e-6);
    EXPECT_DOUBLE_EQ(unmatched.first, 1.0);
    ASSERT_EQ(matched.second.width(), same.second.width());
    // The picture above the labels: equal with the scale, far from it without.
    double dMatched = 0.0, dUnmatched = 0.0;
    for (int y = 0; y < same.second.height() * 2 / 3; ++y)
        for (int x = same.second.width() / 2; x < same.second.width(); ++x) {
            dMatched = std::max(dMatched, double((matched.second.at(x, y) - same.second.at(x, y)).length()));
            dUnmatched = std::max(dUnmatched, double((unmatched.second.at(x, y) - same.second.at(x, y)).length()));
        }
    EXPECT_LT(dMatched, 0.01);
    EXPECT_GT(dUnmatched, 0.1);
}

TEST(Cli, MeasureCanReadTheSourceAsTransferReadsIt)
{
    // Frame 1 of the Blender plume: the clipped source's edge step dominates its high-frequency energy;
    // --source-extend-velocity reads it as transfer does, without the step.
    const auto hfSource = [](const std::string& extra) {
        const CmdResult r = run("measure --output " + hi() + " --target " + lo() + " --source " + hi() +
                                " --frames 1 --no-spectra -q " + extra);
        EXPECT_EQ(r.code, 0) << r.out;
        const std::string key = "\"hf_energy_source\":";
        const size_t at = r.out.find(key);
        return at == std::string::npos ? -1.0 : std::stod(r.out.substr(at + key.size()));
    };
    const double asWritten = hfSource(""), extended = hfSource("--source-extend-velocity 4");
    ASSERT_GT(asWritten, 0.0);
    ASSERT_GT(extended, 0.0);
    EXPECT_LT(extended, 0.5 * asWritten);
}

TEST(Cli, MeasurePlotsAreDrawnByGnuplotWithTheirScripts)
{
    // The figures are gnuplot's (a plotting package, not code of ours): each picture has its script beside it, and a
    // machine without gnuplot is told what to install before anything is measured.
    testutil::TempDir dir;
    const std::string base =
        "measure --output " + hi() + " --target " + lo() + " --source " + hi() + " --frames 2-3 -q";
    const CmdResult r = run(base + " --plot " + dir / "p");
    ASSERT_EQ(r.code, 0) << r.out;
    for (const char* f : {"metrics.png", "metrics.png.gp", "spectrum.0002.png", "spectrum.0003.png.gp"})
        EXPECT_TRUE(std::filesystem::exists(dir / "p/" + f)) << f;
    const turb::RgbaImage metrics = turbio::readImage(dir / "p/metrics.png");
    EXPECT_EQ(metrics.width(), 1920);
    EXPECT_EQ(metrics.height(), 860);
    // Not a blank canvas: the lines and labels darken some pixels.
    int dark = 0;
    for (int y = 0; y < metrics.height(); ++y)
        for (int x = 0; x < metrics.width(); ++x) dark += metrics.at(x, y).x() < 0.5f;
    EXPECT_GT(dark, 2000);
    std::ifstream gp(dir / "p/spectrum.0003.png.gp");
    const std::string script((std::istreambuf_iterator<char>(gp)), std::istreambuf_iterator<char>());
    EXPECT_NE(script.find("set logscale xy"), std::string::npos);
    EXPECT_NE(script.find("target Nyquist"), std::string::npos);
    // EXR through OpenImageIO from gnuplot's PNG.
    ASSERT_EQ(run(base + " --plot " + dir / "e" + " --plot-format exr").code, 0);
    EXPECT_EQ(turbio::readImage(dir / "e/metrics.exr").width(), 1920);
    EXPECT_FALSE(std::filesystem::exists(dir / "e/metrics.exr.png"));
    // Without gnuplot on the PATH: a clear error naming the package, before any measuring or writing.
    const CmdResult none = run(base + " --plot " + dir / "n", "PATH=/nonexistent");
    EXPECT_EQ(none.code, 1) << none.out;
    EXPECT_NE(none.out.find("gnuplot-nox"), std::string::npos) << none.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "n"));
}

TEST(Cli, ACorruptFrameStopsTheRunWithoutDamagingEarlierOutput)
{
    testutil::TempDir dir;
    std::filesystem::create_directories(dir / "lo");
    for (int f = 1; f <= 3; ++f)
        std::filesystem::copy_file(testutil::dataPath("blender-plume-32/fluid_data_000" + std::to_string(f) + ".vdb"),
            dir / ("lo/t_000" + std::to_string(f) + ".vdb"));
    // Frame 2 cut in half: the header check before the first frame finds it, and nothing is written.
    std::filesystem::resize_file(dir / "lo/t_0002.vdb", std::filesystem::file_size(dir / "lo/t_0002.vdb") / 2);
    const CmdResult r =
        run("transfer --target " + dir / "lo/t_####.vdb" + " --source " + hi() + " --out " + dir / "out/o.####.vdb");
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.out.find("t_0002.vdb"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("truncated"), std::string::npos) << r.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "out")) << "refused before writing anything";

    // Damaged compressed data in frame 2 (its headers are intact, so only reading its voxels finds it): frame 1
    // is written whole, frame 2 is not, and the message names the file and the grid.
    std::filesystem::remove(dir / "lo/t_0002.vdb");
    std::string bytes;
    {
        std::ifstream in(testutil::dataPath("blender-plume-32/fluid_data_0002.vdb"), std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    bytes[56451] ^= char(0x80);
    std::ofstream(dir / "lo/t_0002.vdb", std::ios::binary) << bytes;
    const CmdResult d =
        run("transfer --target " + dir / "lo/t_####.vdb" + " --source " + hi() + " --out " + dir / "out/o.####.vdb");
    EXPECT_EQ(d.code, 1) << d.out;
    EXPECT_NE(d.out.find("t_0002.vdb: grid 'temperature' could not be read"), std::string::npos) << d.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "out/o.0001.vdb"));
    EXPECT_FALSE(std::filesystem::exists(dir / "out/o.0002.vdb"));
    // Frame 1 and its exact resume state: the frames hold velocity per second, the Blender target's unit is 0.4 s.
    EXPECT_TRUE(std::filesystem::exists(dir / "out/o.resume-state-odd.vdb"));
    EXPECT_EQ(testutil::countEntries(dir / "out"), 2u) << "no partial or temporary file";
    EXPECT_NO_THROW(turbio::readFrame(dir / "out/o.0001.vdb", 1, turbio::ReadOptions{}));
}

// ---------------------------------------------------------------------------------------------
// stylize: inputs, outputs, and bad input refused before anything is written

namespace {

/// A 32x32 RGBA exemplar (soft disk alpha, striped colours), optionally without its alpha channel.
void writeExemplar(const std::string& path, int n, bool withAlpha)
{
    turb::RgbaImage z(n, n);
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            const float a =
                std::min(1.0f, std::max(0.0f, float(n * 0.42 - std::hypot(x - n / 2.0, y - n / 2.0)) / 3.0f + 0.5f));
            z.at(x, y) = turb::Rgba(0.5f + 0.4f * std::sin(0.9f * float(x)), 0.3f, 0.2f + 0.01f * float(y), a);
        }
    turbio::ImageWriteOptions o;
    o.alpha = withAlpha;
    turbio::writeImage(path, z, o);
}

/// Frames 1..n of a 2D target: R,G = (1, 0.5) pixels per frame in float EXR, a disk alpha in PNG.
void writeTarget(const std::string& dir, int n, int w, int h, bool emptySecond = false)
{
    std::filesystem::create_directories(dir);
    for (int f = 1; f <= n; ++f) {
        turb::RgbaImage flow(w, h, turb::Rgba(1.0f, 0.5f, 0.0f, 1.0f)), alpha(w, h);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const float a =
                    (emptySecond && f == 2) ? 0.0f : (std::hypot(x - w / 2.0 - f, y - h / 2.0) < w * 0.3 ? 1.0f : 0.0f);
                alpha.at(x, y) = turb::Rgba(a, a, a, 1.0f);
            }
        turbio::ImageWriteOptions fo;
        fo.bits = turbio::PixelBits::Float;
        fo.alpha = false;
        turbio::writeImage(dir + "/flow." + std::to_string(1000 + f).substr(1) + ".exr", flow, fo);
        turbio::ImageWriteOptions ao;
        ao.alpha = false;
        turbio::writeImage(dir + "/alpha." + std::to_string(1000 + f).substr(1) + ".png", alpha, ao);
    }
}

} // namespace

TEST(Cli, SynthGivesAFrameTheSameDetailWhicheverPartOfTheShotIsRendered)
{
    // The Blender plume's start-up grows every frame. Synth holds one box over the sequence; it used to be the union
    // over the requested frames, so frame 1 of a 1-2 run differed from frame 1 of a 1-4 run (another box, other
    // detail). Now the box spans every frame on disk and the two agree bit for bit.
    testutil::TempDir dir;
    const std::string synth = "synth --target " + lo() + " --factor 2 -q --threads 2 --frames ";
    const CmdResult a = run(synth + "1-2 --out " + dir / "a/s.####.vdb");
    ASSERT_EQ(a.code, 0) << a.out;
    const CmdResult b = run(synth + "1-4 --out " + dir / "b/s.####.vdb");
    ASSERT_EQ(b.code, 0) << b.out;
    turbio::ReadOptions ro;
    ro.cropToSmoke = false;
    const turb::Frame fa = turbio::readFrame(dir / "a/s.0001.vdb", 1, ro),
                      fb = turbio::readFrame(dir / "b/s.0001.vdb", 1, ro);
    ASSERT_EQ(fa.velocity.bbox(), fb.velocity.bbox());
    size_t differ = 0;
    for (size_t i = 0; i < fa.velocity.size(); ++i) differ += fa.velocity.data()[i] != fb.velocity.data()[i];
    EXPECT_EQ(differ, 0u);
}

TEST(Cli, StylizeFramesAfterACutAreTheSameWhicheverPartOfTheShotIsRendered)
{
    // A gap in the frames is a cut: frame 4 starts a shot in both runs. Its random draws follow its number, not its
    // place in the run, so frames 4-5 of a 1-2,4-5 run are those of a 4-5 run, bit for bit.
    testutil::TempDir dir;
    const std::string base = "stylize --scene rotate --scene-size 48x48 --exemplar builtin:fire:32 -q --frames ";
    ASSERT_EQ(run(base + "1-2,4-5 --out " + dir / "a/o.####.png").code, 0);
    ASSERT_EQ(run(base + "4-5 --out " + dir / "b/o.####.png").code, 0);
    for (const char* f : {"o.0004.png", "o.0005.png"})
        EXPECT_EQ(turbio::readImage(dir / (std::string("a/") + f)).pixels(),
            turbio::readImage(dir / (std::string("b/") + f)).pixels())
            << f;
}

TEST(Cli, StylizeLoopsAVideoExemplarShorterThanTheShot)
{
    // A 2-frame video exemplar (red, then blue) on a 3-frame target: frames 1, 2, 3 take exemplar frames 1, 2, 1.
    testutil::TempDir dir;
    writeExemplar(dir / "base.png", 32, true);
    const turb::RgbaImage base = turbio::readImage(dir / "base.png");
    std::filesystem::create_directories(dir / "v");
    for (int k = 1; k <= 2; ++k) {
        turb::RgbaImage z = base;
        for (auto& p : z.pixels())
            p = k == 1 ? turb::Rgba(p[0], 0.05f, 0.05f, p[3]) : turb::Rgba(0.05f, 0.05f, p[0], p[3]);
        turbio::writeImage(dir / ("v/ex.000" + std::to_string(k) + ".png"), z);
    }
    writeTarget(dir / "t", 3, 48, 40);
    const CmdResult r = run("stylize --flow " + dir / "t/flow.###.exr" + " --alpha " + dir / "t/alpha.###.png" +
                            " --exemplar " + dir / "v/ex.####.png" + " --out " + dir / "o/s.####.exr -q");
    ASSERT_EQ(r.code, 0) << r.out;
    for (int f = 1; f <= 3; ++f) {
        const turb::RgbaImage out = turbio::readImage(dir / ("o/s.000" + std::to_string(f) + ".exr"));
        double red = 0.0, blue = 0.0;
        for (const auto& p : out.pixels()) {
            red += p[0] * p[3];
            blue += p[2] * p[3];
        }
        if (f == 2) EXPECT_GT(blue, 3.0 * red) << "frame 2 takes exemplar frame 2";
        else EXPECT_GT(red, 3.0 * blue) << "frame " << f << " takes exemplar frame 1";
    }
}

TEST(Cli, StylizeWritesFramesAndJson)
{
    testutil::TempDir dir;
    writeExemplar(dir / "ex.png", 32, true);
    writeTarget(dir / "t", 3, 48, 40);
    const std::string in =
        " --flow " + dir / "t/flow.###.exr" + " --alpha " + dir / "t/alpha.###.png" + " --exemplar " + dir / "ex.png";
    const CmdResult dry = run("stylize" + in + " --out " + dir / "o/s.####.png --dry-run");
    EXPECT_EQ(dry.code, 0) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));
    EXPECT_NE(dry.out.find("would write " + dir / "o/s.0001.png"), std::string::npos) << dry.out;
    EXPECT_EQ(dry.out.find("does not read"), std::string::npos) << dry.out;
    // An option of the other method is not silently ignored.
    const CmdResult other = run("stylize" + in + " --out " + dir / "o/s.####.png --dry-run --w-dir 2");
    EXPECT_EQ(other.code, 0) << other.out;
    EXPECT_NE(
        other.out.find("--w-dir set Fluidymation's synthesis; --method lazyfluids (the default) does not read it"),
        std::string::npos)
        << other.out;
    const CmdResult r = run("stylize" + in + " --out " + dir / "o/s.####.exr --json -q --threads 2");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(testutil::countEntries(dir / "o"), 3u);
    EXPECT_NE(r.out.find("\"coverage\":1.0"), std::string::npos) << r.out.substr(0, 600);
    EXPECT_NE(r.out.find("\"temporal_change\":"), std::string::npos);
    EXPECT_NE(r.out.find("\"iou\":"), std::string::npos);
    EXPECT_NE(r.out.find("\"shot_start\":true"), std::string::npos) << "frame 1 starts the shot";
    EXPECT_NE(r.out.find("\"preroll\":4"), std::string::npos) << "with the default pre-roll";
    const turb::RgbaImage out = turbio::readImage(dir / "o/s.0002.exr");
    EXPECT_EQ(out.width(), 48);
    EXPECT_EQ(out.height(), 40);
    // The same run at one thread gives the same pixels.
    const CmdResult one = run("stylize" + in + " --out " + dir / "p/s.####.exr -q --threads 1");
    ASSERT_EQ(one.code, 0) << one.out;
    EXPECT_EQ(turbio::readImage(dir / "p/s.0003.exr").pixels(), turbio::readImage(dir / "o/s.0003.exr").pixels());
    // A cache through a camera.
    const CmdResult cache = run("stylize --cache " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") +
                                " --frames 20-21 --camera side --width 64 --exemplar " + dir / "ex.png" + " --out " +
                                dir / "c/c.####.png -q");
    ASSERT_EQ(cache.code, 0) << cache.out;
    EXPECT_EQ(turbio::readImage(dir / "c/c.0021.png").width(), 64);
}

TEST(Cli, StylizeRefusesBadInputBeforeWritingAnything)
{
    testutil::TempDir dir;
    writeExemplar(dir / "ex.png", 32, true);
    writeExemplar(dir / "tiny.png", 4, true);
    writeExemplar(dir / "opaque.png", 32, false);
    writeTarget(dir / "t", 3, 48, 40);
    writeTarget(dir / "e", 3, 48, 40, true);
    writeTarget(dir / "small", 3, 40, 40);
    const auto expectRefused = [&](const std::string& args, const std::string& names) {
        const CmdResult r = run("stylize " + args + " --out " + dir / "o/s.####.png");
        EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
        EXPECT_NE(r.out.find(names), std::string::npos) << "the message must name " << names << ":\n" << r.out;
        EXPECT_FALSE(std::filesystem::exists(dir / "o")) << "nothing may be written: " << args;
    };
    const std::string flow = " --flow " + dir / "t/flow.###.exr", alpha = " --alpha " + dir / "t/alpha.###.png";
    // An exemplar smaller than a patch.
    expectRefused(flow + alpha + " --exemplar " + dir / "tiny.png", "tiny.png");
    // An empty alpha everywhere (frame 2 of the target).
    expectRefused(" --flow " + dir / "e/flow.###.exr --alpha " + dir / "e/alpha.###.png --exemplar " + dir / "ex.png",
        "alpha.002.png");
    // Flow and alpha of different sizes.
    expectRefused(" --flow " + dir / "small/flow.###.exr" + alpha + " --exemplar " + dir / "ex.png", "flow.001.exr");
    // A missing frame.
    std::filesystem::remove(dir / "t/alpha.003.png");
    expectRefused(flow + alpha + " --exemplar " + dir / "ex.png", "alpha.003.png");
    // An exemplar with no alpha and no --exemplar-alpha; with the mask it runs.
    writeTarget(dir / "t", 3, 48, 40);
    expectRefused(flow + alpha + " --exemplar " + dir / "opaque.png", "opaque.png");
    turb::RgbaImage mask = turbio::readImage(dir / "ex.png");
    for (auto& p : mask.pixels()) p = turb::Rgba(p[3], p[3], p[3], 1.0f);
    turbio::ImageWriteOptions mo;
    mo.alpha = false;
    turbio::writeImage(dir / "mask.png", mask, mo);
    const CmdResult masked = run("stylize" + flow + alpha + " --exemplar " + dir / "opaque.png --exemplar-alpha " +
                                 dir / "mask.png" + " --frames 1 --out " + dir / "m/s.####.png -q");
    EXPECT_EQ(masked.code, 0) << masked.out;
    // An unknown output format is a usage error.
    EXPECT_EQ(run("stylize" + flow + alpha + " --exemplar " + dir / "ex.png --out " + dir / "o/s.####.bmpx").code, 2);
}

// ---------------------------------------------------------------------------------------------
// animate: outputs, dumps, the cache path, and bad input refused before anything is written

namespace {

std::string strokesPath() { return std::string(VDBTURB_SOURCE_DIR) + "/scenes/animate/river_strokes.json"; }

size_t countFiles(const std::string& dir, const std::string& prefix)
{
    size_t n = 0;
    if (!std::filesystem::exists(dir)) return 0;
    for (const auto& e : std::filesystem::directory_iterator(dir))
        if (e.path().filename().string().rfind(prefix, 0) == 0) ++n;
    return n;
}

// The built-in river exported into DIR/in (12 frames of 48x40, a 56x40 still and its matte) as animate's inputs,
// with the stroke design, tau 4 and 28-pixel cells; empty when the export fails.
std::string riverInputs(const testutil::TempDir& dir)
{
    if (run("animate --export-builtin " + dir / "in" + " --example builtin:river:48x40x12 --target builtin:river:56x40")
            .code != 0)
        return {};
    return " --example " + dir / "in/river.####.png" + " --target " + dir / "in/still.png" + " --target-alpha " +
           dir / "in/matte.png" + " --flow-strokes " + strokesPath() + " --tau 4 --hm-cell 28";
}

} // namespace

TEST(Cli, AnimateWritesNMinusTauFramesJsonAndDumps)
{
    testutil::TempDir dir;
    const std::string in = riverInputs(dir);
    ASSERT_FALSE(in.empty());
    const CmdResult dry = run("animate" + in + " --out " + dir / "o/a.####.exr --dry-run");
    ASSERT_EQ(dry.code, 0) << dry.out;
    EXPECT_NE(dry.out.find("-> 8 frames"), std::string::npos) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));
    const CmdResult r = run(
        "animate" + in + " --out " + dir / "o/a.####.exr --json --dump " + dir / "d" + " --sheet " + dir / "sheet.png");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(countFiles(dir / "o", "a."), 8u) << "N - tau frames";
    EXPECT_TRUE(std::filesystem::exists(dir / "o/a.0001.exr"));
    EXPECT_TRUE(std::filesystem::exists(dir / "o/a.0008.exr"));
    for (const char* f : {"A.exr", "v.exr", "rough.exr", "refined.exr", "Aprime.exr", "v.png"})
        EXPECT_TRUE(std::filesystem::exists(dir / "d/" + f)) << f;
    EXPECT_EQ(countFiles(dir / "d", "R."), 11u) << "N - 1 residuals";
    EXPECT_EQ(countFiles(dir / "d", "Rprime."), 11u);
    EXPECT_TRUE(std::filesystem::exists(dir / "sheet.png"));
    size_t lines = 0, at = 0;
    while ((at = r.out.find("\"cell_std_error\":", at)) != std::string::npos) {
        at += 17;
        ++lines;
    }
    EXPECT_EQ(lines, 8u) << r.out;
    EXPECT_NE(r.out.find("\"stages_s\":"), std::string::npos) << r.out;
    // The output keeps the still outside the matte: a corner pixel on the bank equals the still's.
    const turb::RgbaImage still = turbio::readImage(dir / "in/still.png"),
                          out = turbio::readImage(dir / "o/a.0005.exr");
    ASSERT_TRUE(out.sameSize(still));
    EXPECT_NEAR(out.at(1, 1)[1], still.at(1, 1)[1], 2e-3);
}

TEST(Cli, AnimateFromACacheThroughTheCamera)
{
    testutil::TempDir dir;
    ASSERT_EQ(
        run("animate --export-builtin " + dir / "in" + " --example builtin:river:48x40x2 --target builtin:river:64x48")
            .code,
        0);
    const CmdResult r =
        run("animate --example-cache " + lo() + " --camera front --width 48 --target " + dir / "in/still.png" +
            " --flow-strokes " + strokesPath() + " --tau 4 --hm laplacian --hm-apply sequence --measure --out " +
            dir / "o/a.####.png --json -q");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(countFiles(dir / "o", "a."), 6u) << "10 cache frames - tau";
    EXPECT_NE(r.out.find("\"flow_given\":true"), std::string::npos) << r.out;
    // --measure: the motion track by track and as the interpolated field, the example's calibration against the
    // cache's own flow, and how many example windows the transfer used.
    for (const char* key : {"\"track_median_angle_deg\":", "\"track_median_speed_ratio\":",
             "\"flow_median_angle_deg\":", "\"example_track_median_speed_ratio\":", "\"distinct_windows\":"})
        EXPECT_NE(r.out.find(key), std::string::npos) << key << "\n" << r.out;
}

TEST(Cli, AnimateCloneStrokesPasteTheExamplesResidualsAndBadOnesAreRefused)
{
    // The built-in river's clone design (drawn on 320x240, scaled to the 48x40 example and the 56x40 still): the run
    // reports the pixels it cloned and dumps the brush matte; a pair outside the example is refused by file and line
    // before anything is written.
    testutil::TempDir dir;
    const std::string in = riverInputs(dir);
    ASSERT_FALSE(in.empty());
    const CmdResult r =
        run("animate" + in + " --clone-strokes builtin:river --out " + dir / "o/a.####.png --json --dump " + dir / "d");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(countFiles(dir / "o", "a."), 8u);
    EXPECT_NE(r.out.find("\"cloned\":"), std::string::npos) << r.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "d/clone.exr"));
    {
        std::ofstream f(dir / "clone.json");
        f << "{\n  \"clones\": [\n    {\"source\": [[2, 2], [40, 2]], \"destination\": [[2, 30], [40, 30]], \"size\": "
             "8},\n"
             "    {\"source\": [[2, 2], [50, 2]],\n     \"destination\": [[2, 30], [40, 30]], \"size\": 8}\n  ]\n}\n";
    }
    const CmdResult bad = run("animate" + in + " --clone-strokes " + dir / "clone.json --out " + dir / "b/a.####.png");
    EXPECT_EQ(bad.code, 1) << bad.out;
    EXPECT_NE(bad.out.find(dir / "clone.json:4: clone stroke 1 (source): point (50.000000, 2.000000) lies outside "
                                 "the 48x40 example"),
        std::string::npos)
        << bad.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "b"));
}

TEST(Cli, AnimateMeasureGivesNoMotionFigureWhenNothingMoves)
{
    // A flat still: eq. 8 scales the differences to its zero contrast, so nothing moves. No figure is not a perfect
    // figure: the motion keys are null, with a warning (and a warning under 8 output frames).
    testutil::TempDir dir;
    ASSERT_EQ(
        run("animate --export-builtin " + dir / "in" + " --example builtin:river:48x40x20 --target builtin:river:48x40")
            .code,
        0);
    turbio::writeImage(dir / "flat.png", turb::RgbaImage(48, 40, turb::Rgba(0.5f, 0.5f, 0.5f, 1.0f)));
    const std::string in = "animate --example " + dir / "in/river.####.png" + " --target " + dir / "flat.png" +
                           " --flow-strokes " + strokesPath() + " --measure --json --hm-cell 24 --out " +
                           dir / "o/a.####.png";
    const CmdResult r = run(in + " --tau 8");
    ASSERT_EQ(r.code, 0) << r.out;
    for (const char* key : {"\"track_median_angle_deg\":null", "\"track_median_speed_ratio\":null",
             "\"flow_median_angle_deg\":null", "nothing moving was tracked"})
        EXPECT_NE(r.out.find(key), std::string::npos) << key << "\n" << r.out;
    EXPECT_EQ(r.out.find("output frames; the motion"), std::string::npos) << "12 frames are enough";
    const CmdResult shortRun = run(in + " --tau 16 --no-clobber --start 101");
    ASSERT_EQ(shortRun.code, 0) << shortRun.out;
    EXPECT_NE(shortRun.out.find("4 output frames; the motion"), std::string::npos) << shortRun.out;
}

TEST(Cli, AnimateRefusesBadInputNamingTheFileAndWritesNothing)
{
    testutil::TempDir dir;
    ASSERT_EQ(
        run("animate --export-builtin " + dir / "in" + " --example builtin:river:48x40x20 --target builtin:river:48x40")
            .code,
        0);
    const std::string ex = dir / "in/river.####.png", still = dir / "in/still.png",
                      out = " --out " + dir / "o/a.####.png";
    const auto refused = [&](const std::string& args, const std::string& names, const std::string& also) {
        const CmdResult r = run("animate " + args + out);
        EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
        EXPECT_NE(r.out.find(names), std::string::npos) << r.out;
        EXPECT_NE(r.out.find(also), std::string::npos) << r.out;
        EXPECT_FALSE(std::filesystem::exists(dir / "o")) << args;
    };
    // An example shorter than tau + 2 frames.
    refused("--example " + ex + " --frames 1-10 --target " + still + " --flow-strokes " + strokesPath(), ex,
        "tau + 2 = 18");
    // A target without strokes or flow.
    refused("--example " + ex + " --target " + still, still, "no flow design");
    // A malformed strokes JSON: the line of the error.
    {
        std::ofstream f(dir / "bad.json");
        f << "{\n  \"strokes\": [\n    {\"brush\": \"orientation\", \"points\": [[1, 2], [30, 2]]},\n    {\"brush\": "
             "\"speed\" \"speed\": 1}\n  ]\n}\n";
    }
    refused("--example " + ex + " --target " + still + " --flow-strokes " + dir / "bad.json", dir / "bad.json:4",
        "malformed JSON");
    // A stroke outside the image: the stroke and its line.
    {
        std::ofstream f(dir / "out.json");
        f << "{\n  \"strokes\": [\n    {\"brush\": \"orientation\", \"points\": [[1, 2], [30, 2]]},\n"
             "    {\"brush\": \"speed\", \"speed\": 1,\n     \"points\": [[1, 2], [300, 4]]}\n  ]\n}\n";
    }
    refused("--example " + ex + " --target " + still + " --flow-strokes " + dir / "out.json", dir / "out.json:4",
        "stroke 1 (speed)");
    // A --sheet or --dump that cannot be written: refused before the first frame (and by --dry-run).
    std::ofstream(dir / "afile") << "x";
    for (const char* opt : {" --sheet ", " --dump "}) {
        const std::string args = "--example " + ex + " --target " + still + " --flow-strokes " + strokesPath() +
                                 " --tau 8" + opt + dir / "afile/x.png";
        refused(args, dir / "afile", "is a file, not a directory");
        refused(args + " --dry-run", dir / "afile", "is a file, not a directory");
    }
    // Example frames of different sizes (checked last: it replaces a frame).
    {
        turb::RgbaImage odd(50, 40, turb::Rgba(0.5f, 0.5f, 0.5f, 1.0f));
        turbio::writeImage(dir / "in/river.0007.png", odd);
    }
    refused("--example " + ex + " --target " + still + " --flow-strokes " + strokesPath(), dir / "in/river.0007.png",
        "50x40");
}

namespace {

/// A growing disc as binary PNG masks m.001.png ... (no flow: fluidymation estimates it).
void writeMasks(const std::string& dir, int frames, int W, int H, bool empty = false)
{
    std::filesystem::create_directories(dir);
    turbio::ImageWriteOptions o;
    o.alpha = false;
    for (int f = 1; f <= frames; ++f) {
        turb::RgbaImage m(W, H, turb::Rgba(0, 0, 0, 1));
        const double R = 9.0 + 1.5 * f;
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
                if (!empty && std::hypot(x - W / 2.0, y - H / 2.0) <= R) m.at(x, y) = turb::Rgba(1, 1, 1, 1);
        char name[32];
        std::snprintf(name, sizeof(name), "/m.%03d.png", f);
        turbio::writeImage(dir + name, m, o);
    }
}

} // namespace

TEST(Cli, FluidymationWritesFramesRotationNnfAndJson)
{
    testutil::TempDir dir;
    // The built-in moving exemplar on disk: frames, masks and flows.
    const CmdResult sim = run("sim ink --res 64x48 --frames 12 --out " + dir / "ink/ink.####.png -q");
    ASSERT_EQ(sim.code, 0) << sim.out;
    EXPECT_EQ(testutil::countEntries(dir / "ink"), 36u);
    EXPECT_TRUE(std::filesystem::exists(dir / "ink/ink_mask.0012.png"));
    EXPECT_TRUE(std::filesystem::exists(dir / "ink/ink_flow.0001.exr"));
    writeMasks(dir / "t", 4, 48, 48);
    const std::string in = " --method fluidymation --exemplar " + dir / "ink/ink.####.png" + " --exemplar-mask " +
                           dir / "ink/ink_mask.####.png" + " --target-mask " + dir / "t/m.###.png --b 8";
    const CmdResult dry = run("stylize" + in + " --out " + dir / "o/s.####.png --dry-run");
    EXPECT_EQ(dry.code, 0) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));
    const CmdResult r = run("stylize" + in + " --out " + dir / "o/s.####.png --out-rot " +
                            dir / "o/rot.####.exr --debug-nnf " + dir / "o/nnf" + " --json -q --threads 2");
    ASSERT_EQ(r.code, 0) << r.out;
    for (const char* key :
        {"\"mean_abs_sin\":", "\"speed_correlation\":", "\"coverage\":", "\"stationary_change\":", "\"energy\":"})
        EXPECT_NE(r.out.find(key), std::string::npos) << key << "\n" << r.out.substr(0, 600);
    const turb::RgbaImage out = turbio::readImage(dir / "o/s.0004.png");
    EXPECT_EQ(out.width(), 48);
    // The centre is painted (alpha from the exemplar's masks), a corner is not.
    EXPECT_GT(out.at(24, 24)[3], 0.5f);
    EXPECT_LT(out.at(1, 1)[3], 0.01f);
    // T^rot in radians where a patch is centred; the NNF names exemplar frames 0..11 and pixels inside it.
    const turb::RgbaImage rot = turbio::readImage(dir / "o/rot.0004.exr"),
                          nnf = turbio::readImage(dir / "o/nnf/nnf.0004.exr");
    EXPECT_GE(rot.at(24, 24)[0], 0.0f);
    EXPECT_LT(rot.at(24, 24)[0], 6.2832f);
    EXPECT_NEAR(std::hypot(rot.at(24, 24)[1], rot.at(24, 24)[2]), 1.0f, 1e-3);
    EXPECT_EQ(rot.at(1, 1)[1], 0.0f);
    EXPECT_GE(nnf.at(24, 24)[0], 0.0f);
    EXPECT_LE(nnf.at(24, 24)[0], 11.0f);
    EXPECT_LT(nnf.at(24, 24)[1], 64.0f);
    EXPECT_TRUE(std::filesystem::exists(dir / "o/nnf/nnf_vis.0004.png"));
    // One thread gives the same pixels.
    const CmdResult one = run("stylize" + in + " --out " + dir / "p/s.####.png -q --threads 1");
    ASSERT_EQ(one.code, 0) << one.out;
    EXPECT_EQ(turbio::readImage(dir / "p/s.0004.png").pixels(), out.pixels());
    // A cache through a camera, with the built-in exemplar.
    const CmdResult cache =
        run("stylize --method fluidymation --cache " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") +
            " --frames 20-21 --camera front --width 64 --exemplar builtin:ink:64x48x11 --b 8 --out " +
            dir / "c/c.####.png -q --json");
    ASSERT_EQ(cache.code, 0) << cache.out;
    EXPECT_EQ(turbio::readImage(dir / "c/c.0021.png").width(), 64);
    EXPECT_NE(cache.out.find("\"masked_pixels\":"), std::string::npos);
}

TEST(Cli, FluidymationRefusesBadInputBeforeWritingAnything)
{
    testutil::TempDir dir;
    ASSERT_EQ(run("sim ink --res 48x40 --frames 11 --out " + dir / "ink/ink.####.png -q").code, 0);
    ASSERT_EQ(run("sim ink --res 48x40 --frames 8 --out " + dir / "short/ink.####.png -q").code, 0);
    writeMasks(dir / "t", 3, 40, 40);
    writeMasks(dir / "e", 3, 40, 40, true);
    const auto expectRefused = [&](const std::string& args, const std::string& names) {
        const CmdResult r = run("stylize --method fluidymation " + args + " --out " + dir / "o/s.####.png");
        EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
        EXPECT_NE(r.out.find(names), std::string::npos) << "the message must name " << names << ":\n" << r.out;
        EXPECT_FALSE(std::filesystem::exists(dir / "o")) << "nothing may be written: " << args;
    };
    const std::string ex = " --exemplar " + dir / "ink/ink.####.png --exemplar-mask " + dir / "ink/ink_mask.####.png";
    // An exemplar shorter than 2r + 1 frames (8 < 11).
    expectRefused(" --exemplar " + dir / "short/ink.####.png --exemplar-mask " +
                      dir / "short/ink_mask.####.png --target-mask " + dir / "t/m.###.png",
        "2r + 1");
    // An empty target mask in every frame.
    expectRefused(ex + " --target-mask " + dir / "e/m.###.png", "empty in every frame");
    // Mask and frame counts that differ.
    std::filesystem::remove(dir / "ink/ink_mask.0011.png");
    expectRefused(ex + " --target-mask " + dir / "t/m.###.png", "ink_mask");
    // LazyFluids' target options are refused.
    expectRefused(" --exemplar builtin:ink:48x40x11 --alpha " + dir / "t/m.###.png", "--target-mask");
    // A target flow of another size than its masks.
    ASSERT_EQ(run("sim ink --res 48x40 --frames 11 --out " + dir / "ink/ink.####.png -q").code, 0);
    expectRefused(
        ex + " --target-mask " + dir / "t/m.###.png --target-flow " + dir / "ink/ink_flow.####.exr --frames 1-3",
        "ink_flow.0001.exr");
}

TEST(Cli, SynthProjectionThatStopsShortWarnsNamingTheFrameAndFailsUnderStrict)
{
    // A projection that does not converge is a warning naming the frame (-v: the solver's numbers),
    // and exit 1 under --strict. One CG iteration cannot converge; the default cap does, walls included.
    testutil::TempDir dir;
    const std::string base =
        "synth --flow vortex --flow-res 16x16x1 --factor 2 --walls x-,x+,y-,y+ --project --frames 2 --out '" +
        dir.path() + "/s.####.vdb'";
    const CmdResult shortRun = run(base + " --project-iterations 1 -v");
    EXPECT_EQ(shortRun.code, 0) << shortRun.out;
    EXPECT_NE(shortRun.out.find("frame 1: the projection did not converge"), std::string::npos) << shortRun.out;
    EXPECT_NE(shortRun.out.find("frame 2: the projection did not converge"), std::string::npos) << shortRun.out;
    EXPECT_NE(shortRun.out.find("frame 1: projection max|div|"), std::string::npos) << shortRun.out; // -v details
    const CmdResult strict = run(base + " --project-iterations 1 --strict");
    EXPECT_EQ(strict.code, 1) << strict.out;
    EXPECT_NE(strict.out.find("did not converge: 1, 2"), std::string::npos) << strict.out;
    const CmdResult converged = run(base + " --strict");
    EXPECT_EQ(converged.code, 0) << converged.out;
    EXPECT_EQ(converged.out.find("did not converge"), std::string::npos) << converged.out;
}

TEST(Cli, TwoDCachesThroughSimTransferMeasureAndPreview)
{
    // The 2D path end to end through the commands: one-z-layer sims, a transfer, its measures and a
    // picture sheet (small: a 12x16 plume and a 48x64 swirl, ratio 4).
    testutil::TempDir dir;
    const std::string d = dir.path();
    const CmdResult t = run("sim plume --res 12x16x1 --frames 4 --out '" + d + "/t/p.####.vdb' -q");
    ASSERT_EQ(t.code, 0) << t.out;
    const CmdResult s = run("sim swirl --res 48x64x1 --frames 4 --out '" + d + "/s/s.####.vdb' -q");
    ASSERT_EQ(s.code, 0) << s.out;
    // A transfer of this pair into out/o.####.vdb, from the given source sequence.
    const auto transferTo = [&](const std::string& out, const std::string& source = "s/s") {
        return "transfer --target '" + d + "/t/p.####.vdb' --source '" + d + "/" + source + ".####.vdb' --out '" + d +
               "/" + out + "/o.####.vdb'";
    };
    // The dry run says the cache is 2D and which of the settings with a 2D twin apply.
    const CmdResult dry = run(transferTo("o") + " --dry-run --detail-energy-2d pasted --seams.bandWidth2D 4" +
                              " --seams.cgTolerance 0.5 --structureTolerance 0.3");
    ASSERT_EQ(dry.code, 0) << dry.out;
    EXPECT_NE(dry.out.find("2D cache (one z layer): B^2 patches; detail energy pasted, seam band 4"), std::string::npos)
        << dry.out;
    // The 3D tolerances given do not apply to a 2D cache; the 2D defaults do, and a warning names each one given.
    EXPECT_NE(
        dry.out.find("regenerate blend 0.6, seam CG tolerance 0.01, structure tolerance 0.05 ("), std::string::npos)
        << dry.out;
    EXPECT_NE(dry.out.find("--structureTolerance is for 3D caches and has no effect on this 2D target: "
                           "--structureTolerance2D is the one that applies"),
        std::string::npos)
        << dry.out;
    EXPECT_NE(dry.out.find("--seams.cgTolerance is for 3D caches"), std::string::npos) << dry.out;
    EXPECT_EQ(dry.out.find("--seams.bandWidth2D is for"), std::string::npos) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(d + "/o"));
    const CmdResult x = run(transferTo("o") + " -q");
    ASSERT_EQ(x.code, 0) << x.out;
    // --resume over these 2D frames compares the 2D twins of the settings and not the 3D ones.
    const std::string again = transferTo("o") + " --resume";
    const CmdResult threeD = run(again + " --band 3 --structureTolerance 0.3 --regenerateBlend 0.3");
    EXPECT_EQ(threeD.code, 0) << threeD.out;
    EXPECT_NE(threeD.out.find("nothing to do"), std::string::npos) << threeD.out;
    const CmdResult twoD = run(again + " --structureTolerance2D 0.3");
    EXPECT_EQ(twoD.code, 1) << twoD.out;
    EXPECT_NE(twoD.out.find("structure-tolerance-2d: 0.05 -> 0.3"), std::string::npos) << twoD.out;
    turbio::ReadOptions wholeBox; // the domain the output records, not only the smoke's neighbourhood
    wholeBox.cropToSmoke = false;
    const turb::Frame o = turbio::readFrame(d + "/o/o.0004.vdb", 4, wholeBox);
    // One layer at z = 0, inside the 48 x 64 refined domain (the transfer holds the target over its smoke).
    EXPECT_EQ(o.velocity.bbox().min().z(), 0);
    EXPECT_EQ(o.velocity.bbox().max().z(), 0);
    EXPECT_TRUE(turb::CoordBBox(turb::Coord(0), turb::Coord(47, 63, 0)).isInside(o.velocity.bbox()))
        << o.velocity.bbox();
    for (const turb::Vec3f& v : o.velocity.values()) ASSERT_EQ(v.z(), 0.0f);
    // A 2D sequence resumes bit-identically (the state and the one-layer lattice read back from the last output).
    const std::string pair = transferTo("r") + " -q";
    ASSERT_EQ(run(pair + " --frames 1-2").code, 0);
    const CmdResult resumed = run(pair + " --frames 1-4 --resume");
    ASSERT_EQ(resumed.code, 0) << resumed.out;
    const turb::Frame r = turbio::readFrame(d + "/r/o.0004.vdb", 4, wholeBox);
    ASSERT_EQ(r.velocity.bbox(), o.velocity.bbox());
    EXPECT_EQ(r.velocity.values(), o.velocity.values());
    EXPECT_EQ(r.density.values(), o.density.values());
    // A setting recorded only when changed, resumed at its default: the message names both values (2026-12-05: a
    // new user read "structure-tolerance-2d: 0 -> (unknown to this version)").
    const std::string zero = transferTo("z") + " -q";
    ASSERT_EQ(run(zero + " --frames 1-2 --structureTolerance2D 0").code, 0);
    const CmdResult toDefault = run(zero + " --frames 1-3 --resume");
    EXPECT_EQ(toDefault.code, 1) << toDefault.out;
    EXPECT_NE(toDefault.out.find("structure-tolerance-2d: 0 -> 0.05"), std::string::npos) << toDefault.out;
    const CmdResult m = run("measure --output '" + d + "/o/o.####.vdb' --target '" + d + "/t/p.####.vdb' --source '" +
                            d + "/s/s.####.vdb' --frames 3-4 --no-spectra");
    ASSERT_EQ(m.code, 0) << m.out;
    for (const char* key : {"\"lf_err\":", "\"hf_ratio\":", "\"div_rel\":", "\"block\":", "\"isotropy\":"})
        EXPECT_NE(m.out.find(key), std::string::npos) << key << "\n" << m.out;
    const CmdResult p = run("preview 'target=" + d + "/t/p.####.vdb' 'output=" + d +
                            "/o/o.####.vdb' --mode density,vorticity --frames 4 --sheet '" + d + "/sheet.png' -q");
    ASSERT_EQ(p.code, 0) << p.out;
    EXPECT_TRUE(std::filesystem::exists(d + "/sheet.png"));
    // A 3D source at the same voxel (2026-12-05: a new user's dry run printed a plan and exited 0, and `measure`
    // printed meaningless ratios): refused by both, naming the mismatch.
    ASSERT_EQ(run("sim plume --res 48x64x8 --frames 1 --out '" + d + "/s3/s.####.vdb' -q").code, 0);
    const CmdResult dry3 = run(transferTo("o3", "s3/s") + " --frames 1 --dry-run");
    EXPECT_EQ(dry3.code, 1) << dry3.out;
    EXPECT_NE(dry3.out.find("the target is 2D (one z layer) but the source is not"), std::string::npos) << dry3.out;
    const CmdResult m3 = run("measure --output '" + d + "/o/o.####.vdb' --target '" + d + "/t/p.####.vdb' --source '" +
                             d + "/s3/s.####.vdb' --frames 1 --no-spectra");
    EXPECT_EQ(m3.code, 1) << m3.out;
    EXPECT_NE(m3.out.find("the output is 2D (one z layer) but the source is 3D"), std::string::npos) << m3.out;
}

TEST(Cli, EveryPrintedDefaultReadsBack)
{
    // --print-settings with every default uncommented is a valid settings file (2026-12-05: the fps and dt of the
    // readers and measure's patch size printed 0, "from metadata", which their range checks refused). The inputs
    // and outputs come from the command line, the rest from the file.
    testutil::TempDir dir;
    const struct
    {
        std::string command, paths;
    } cases[] = {{"transfer", "--target " + lo() + " --source " + hi() + " --out " + dir / "o/o.####.vdb"},
        {"measure", "--output " + hi() + " --target " + lo()}};
    for (const auto& c : cases) {
        const CmdResult printed = run(c.command + " --print-settings");
        ASSERT_EQ(printed.code, 0) << printed.out;
        std::istringstream in(printed.out);
        std::ofstream file(dir / (c.command + ".toml"));
        int lines = 0;
        for (std::string line; std::getline(in, line);) {
            if (line.rfind("# ", 0) == 0 && line.find('=') != std::string::npos && line.find(' ', 2) > line.find('=') &&
                line.find("=\"\"") == std::string::npos) {
                line = line.substr(2); // a default, uncommented; empty strings (the paths) stay commented
                ++lines;
            }
            file << line << "\n";
        }
        file.close();
        EXPECT_GT(lines, 10) << c.command;
        const CmdResult r =
            run(c.command + " --settings " + dir / (c.command + ".toml") + " " + c.paths + " --frames 1 --dry-run -q");
        EXPECT_EQ(r.code, 0) << c.command << "\n" << r.out;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "o"));
}

TEST(Cli, SettingsFilesGiveEveryOptionAndTheCommandLineWins)
{
    // The second tier: every knob from a file CLI11 reads as TOML, printed by the command itself.
    testutil::TempDir dir;
    const CmdResult printed = run("sim plume --print-settings");
    ASSERT_EQ(printed.code, 0) << printed.out;
    EXPECT_NE(printed.out.find("# res=\"32x32x48\""), std::string::npos) << printed.out; // defaults, commented out
    std::string text = printed.out;
    const auto set = [&](const std::string& from, const std::string& to) {
        const size_t at = text.find(from);
        ASSERT_NE(at, std::string::npos) << from;
        text.replace(at, from.size(), to);
    };
    set("# res=\"32x32x48\"", "res=\"8x8x12\"");
    set("# frames=60", "frames=2");
    {
        std::ofstream f(dir / "sim.toml");
        f << text;
    }
    // The file's res and the command line's frames (which wins over the file's 2).
    const CmdResult r = run("sim plume --settings " + dir / "sim.toml" + " --frames 3 --out " + dir / "p.####.vdb -q");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "p.0003.vdb"));
    EXPECT_FALSE(std::filesystem::exists(dir / "p.0004.vdb"));
    turbio::ReadOptions ro;
    ro.cropToSmoke = false;
    EXPECT_EQ(turbio::readFrame(dir / "p.0001.vdb", 1, ro).velocity.bbox().dim(), turb::Coord(8, 8, 12));
    // What was read back prints as given.
    const CmdResult again = run("sim plume --settings " + dir / "sim.toml" + " --print-settings");
    EXPECT_NE(again.out.find("\nres=\"8x8x12\"\n"), std::string::npos) << again.out;
    // Values that TOML would cut or split unquoted come back whole: a frame pattern's '#' (a comment outside
    // quotes), a list's commas; enum settings print by name; a comment after a value is one.
    const std::string given = "transfer --out 'o/up.####.vdb' --frames 1,3 --align rotate --print-settings";
    const CmdResult first = run(given);
    ASSERT_EQ(first.code, 0) << first.out;
    EXPECT_NE(first.out.find("\nout=\"o/up.####.vdb\"\n"), std::string::npos) << first.out;
    EXPECT_NE(first.out.find("\nframes=\"1,3\"\n"), std::string::npos) << first.out;
    EXPECT_NE(first.out.find("\nalignment=\"rotate\"\n"), std::string::npos) << first.out;
    {
        std::ofstream f(dir / "transfer.toml");
        f << first.out << "temporalBlend = 0.9 # a note\n";
    }
    const CmdResult second = run("transfer --settings " + dir / "transfer.toml" + " --print-settings");
    ASSERT_EQ(second.code, 0) << second.out;
    EXPECT_EQ(second.out, [&] {
        std::string t = first.out;
        const size_t at = t.find("# temporalBlend=");
        EXPECT_NE(at, std::string::npos);
        t.replace(at, t.find('\n', at) - at, "temporalBlend=0.9");
        return t;
    }());
    // The command line wins in any spelling: a dash name, an old spelling, or one that sets both 3D and 2D values.
    {
        std::ofstream f(dir / "spell.toml");
        f << "detailEnergy = \"pasted\"\ndetailEnergy2D = \"none\"\nlocalPatch = 6\ntemporalBlend = 0.5\n"
             "seams.bandWidth = 4\n";
    }
    const CmdResult spelled = run("transfer --settings " + dir / "spell.toml" +
                                  " --detail-energy source --patch 8 --temporal-blend 0.7 --band 3 --print-settings");
    ASSERT_EQ(spelled.code, 0) << spelled.out;
    EXPECT_NE(spelled.out.find("\ndetailEnergy=\"source\"\n"), std::string::npos) << spelled.out;
    EXPECT_NE(spelled.out.find("\ndetailEnergy2D=\"source\"\n"), std::string::npos) << spelled.out;
    EXPECT_NE(spelled.out.find("\nlocalPatch=8\n"), std::string::npos) << spelled.out;
    EXPECT_NE(spelled.out.find("\ntemporalBlend=0.7\n"), std::string::npos) << spelled.out;
    EXPECT_NE(spelled.out.find("\nseams.bandWidth=3\n"), std::string::npos) << spelled.out;
    // The specific setting given beside the one that sets both wins on its own kind of cache.
    const CmdResult both = run("transfer --detail-energy pasted --detail-energy-2d none --print-settings");
    ASSERT_EQ(both.code, 0) << both.out;
    EXPECT_NE(both.out.find("\ndetailEnergy=\"pasted\"\n"), std::string::npos) << both.out;
    EXPECT_NE(both.out.find("\ndetailEnergy2D=\"none\"\n"), std::string::npos) << both.out;
    // A file that cannot be read, or holds sections for several commands, is a usage error naming it.
    EXPECT_EQ(run("sim plume --settings " + dir / "missing.toml").code, 2);
    {
        std::ofstream f(dir / "sections.toml");
        f << "[sim]\nres = 8x8x12\n";
    }
    const CmdResult sections = run("sim plume --settings " + dir / "sections.toml");
    EXPECT_EQ(sections.code, 2);
    EXPECT_NE(sections.out.find("sections.toml"), std::string::npos) << sections.out;
    // A value the option refuses is refused from the file as from the command line.
    {
        std::ofstream f(dir / "bad.toml");
        f << "res = banana\n";
    }
    EXPECT_EQ(run("sim plume --settings " + dir / "bad.toml" + " --out " + dir / "b.####.vdb").code, 2);
}

TEST(Cli, MeasurePreviewInfoSimResampleListTheirSettingsOnlyInHelpAll)
{
    // Two tiers: --help lists the everyday options, --help-all the settings too (each beside its old spelling), and
    // the old spellings still set them.
    const std::vector<std::pair<std::string, std::vector<std::string>>> settings{
        {"measure", {"--patchSize", "--patchOrigin", "--alignment", "--sourceRead.extendVelocity", "--computeSpectra",
                        "--structure", "--plot-format"}},
        {"preview", {"--slice", "--exposure", "--extinction", "--speed-max", "--vorticity-max"}},
        {"info", {"--checksum"}},
        {"sim", {"--scheme", "--pressureTolerance", "--preconditioner", "--cfl", "--maxSubsteps"}},
        {"resample", {"--drop-other-grids"}}};
    for (const auto& [command, names] : settings) {
        const CmdResult help = run(command + " --help"), all = run(command + " --help-all");
        ASSERT_EQ(help.code, 0) << help.out;
        ASSERT_EQ(all.code, 0) << all.out;
        for (const auto& name : names) {
            EXPECT_EQ(help.out.find(name), std::string::npos) << command << " --help lists " << name;
            EXPECT_NE(all.out.find(name), std::string::npos) << command << " --help-all misses " << name;
        }
    }
    EXPECT_NE(run("measure --help-all").out.find("(also: --no-spectra)"), std::string::npos);
    const CmdResult printed =
        run("measure --output a --target b --no-spectra --no-structure --align index --print-settings");
    ASSERT_EQ(printed.code, 0) << printed.out;
    for (const char* line : {"\ncomputeSpectra=false\n", "\nstructure=false\n", "\nalignment="})
        EXPECT_NE(printed.out.find(line), std::string::npos) << line << "\n" << printed.out;
}

TEST(Cli, ATileBoxHoldsThatBoxOfTheTargetAndResumesOnlyOnIt)
{
    // A space tile's transfer (farm plan --tiles writes --tile-box): the output covers the box's refined lattice box
    // on every frame, smoke or not, and records the box; --resume with another box is refused, naming it.
    testutil::TempDir dir;
    const std::string base = "transfer --target " + lo() + " --source " + hi();
    const std::string out = dir / "tile/t.####.vdb";
    const CmdResult a = run(base + " --out " + out + " --frames 1-2 --tile-box 4,6,0,19,21,11 -q");
    ASSERT_EQ(a.code, 0) << a.out;
    turbio::ReadOptions ro;
    ro.cropToSmoke = false;
    for (int fr : {1, 2}) {
        const turb::Frame f = turbio::readFrame(dir / ("tile/t.000" + std::to_string(fr) + ".vdb"), fr, ro);
        EXPECT_EQ(f.velocity.bbox(), turb::CoordBBox(turb::Coord(16, 24, 0), turb::Coord(79, 87, 47))) << fr;
        EXPECT_EQ(f.metadata.at(turb::meta::kTileBox), "4,6,0,19,21,11");
    }
    const CmdResult other = run(base + " --out " + out + " --frames 1-3 --resume --tile-box 4,6,0,19,21,12");
    EXPECT_EQ(other.code, 1) << other.out;
    EXPECT_NE(other.out.find("tile-box: 4,6,0,19,21,11 -> 4,6,0,19,21,12"), std::string::npos) << other.out;
    const CmdResult untiled = run(base + " --out " + out + " --frames 1-3 --resume");
    EXPECT_EQ(untiled.code, 1) << untiled.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "tile/t.0003.vdb"));
    const CmdResult same = run(base + " --out " + out + " --frames 1-3 --resume --tile-box 4,6,0,19,21,11 -q");
    EXPECT_EQ(same.code, 0) << same.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "tile/t.0003.vdb"));
    // Every frame exists: --resume still checks that they are this run's (a farm plan rewritten with other options
    // over the same scratch would otherwise hand on another run's frames).
    const CmdResult done = run(base + " --out " + out + " --frames 1-3 --resume --tile-box 4,6,0,19,21,11 --gamma 0");
    EXPECT_EQ(done.code, 1) << done.out;
    EXPECT_NE(done.out.find("gamma: 10 -> 0"), std::string::npos) << done.out;
    // Malformed boxes are usage errors (exit 2); boxes off the domain or one voxel thick in a 3D cache are refused.
    for (const char* bad : {"1,2,3", "4,6,0,3,21,11", "a,6,0,19,21,11"}) {
        const CmdResult r = run(base + " --out " + dir / "bad/t.####.vdb" + " --frames 1 --tile-box " + bad);
        EXPECT_EQ(r.code, 2) << bad;
        EXPECT_NE(r.out.find("--tile-box"), std::string::npos) << r.out;
    }
    for (const char* bad : {"0,0,0,100,100,100", "-10,-10,-10,-1,-1,-1", "0,0,3,15,15,3"}) {
        const CmdResult r = run(base + " --out " + dir / "bad/t.####.vdb" + " --frames 1 --tile-box " + bad);
        EXPECT_EQ(r.code, 1) << bad;
        EXPECT_NE(r.out.find("--tile-box " + std::string(bad)), std::string::npos) << r.out;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "bad"));
}

TEST(Cli, FarmPlanRefusesAnOutputItWouldReadAndOptionsItSetsItself)
{
    testutil::TempDir dir;
    const std::string base = "farm plan --dir " + dir / "f" + " --target " + lo() + " --source " + hi() + " --tiles 2";
    const CmdResult input = run(base + " --out " + lo());
    EXPECT_EQ(input.code, 1) << input.out;
    EXPECT_NE(input.out.find("is the target cache"), std::string::npos) << input.out;
    const CmdResult scratch = run(base + " --out " + dir / "f/tiles/000/x.####.vdb");
    EXPECT_EQ(scratch.code, 1) << scratch.out;
    EXPECT_NE(scratch.out.find("scratch"), std::string::npos) << scratch.out;
    const CmdResult box = run(base + " --out " + dir / "o/x.####.vdb -- --tile-box 0,0,0,3,3,3");
    EXPECT_EQ(box.code, 1) << box.out;
    const CmdResult threads = run(base + " --out " + dir / "o/x.####.vdb -- --threads 1");
    EXPECT_NE(threads.out.find("--cpus"), std::string::npos) << threads.out;
    for (const char* bad : {"0", "2x", "abc", "2x2x2x2"}) {
        const CmdResult r = run("farm plan --dir " + dir / "f" + " --target " + lo() + " --source " + hi() +
                                " --out " + dir / "o/x.####.vdb --tiles " + bad);
        EXPECT_EQ(r.code, 2) << bad << r.out;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "f/plan.json"));
    // A dry run prints the tiles and writes nothing.
    const CmdResult dry = run(base + " --out " + dir / "o/x.####.vdb --dry-run");
    EXPECT_EQ(dry.code, 0) << dry.out;
    EXPECT_NE(dry.out.find("tile 1: core"), std::string::npos) << dry.out;
    EXPECT_FALSE(std::filesystem::exists(dir / "f"));
    // One tile is a plan too (a farm task over the whole box), and the plan.json says so.
    const CmdResult one = run(base.substr(0, base.size() - 1) + "1 --out " + dir / "o/x.####.vdb");
    ASSERT_EQ(one.code, 0) << one.out;
    std::ifstream plan(dir / "f/plan.json");
    const std::string text((std::istreambuf_iterator<char>(plan)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("\"space_tiles\""), std::string::npos);
    EXPECT_NE(text.find("\"137\""), std::string::npos) << "plan.json lists every exit code";
}
