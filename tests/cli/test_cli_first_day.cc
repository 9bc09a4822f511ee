// What a TD could not see on a first working day (issue 50): output velocity per second, the source-frame mapping,
// errors a wrapper can parse, exit codes, info over damaged sequences, stepped frames, y-up previews, the visible
// resume state, farm overlaps and the dry run's time estimate. Real Blender caches where it concerns caches.
#include "CliUtil.h"
#include "TestUtil.h"

#include <turb/Metadata.h>
#include <turb/Reorient.h>
#include <turb/Resample.h>
#include <turbio/ImageIO.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace {

namespace fs = std::filesystem;
using clitest::has;
using clitest::Result;

using clitest::plumeHi;
using clitest::plumeLo;
using clitest::run;
using clitest::runStdout;

// The last non-empty line of `text`.
std::string lastLine(const std::string& text)
{
    std::istringstream in(text);
    std::string line, last;
    while (std::getline(in, line))
        if (!line.empty()) last = line;
    return last;
}

} // namespace

// Wrong answer 1: a Blender input's velocity (world units per Mantaflow time unit, 0.4 s at time scale 1) was
// written for Houdini unchanged, so motion blur came out 2.5x short at 24 fps.
TEST(FirstDay, ABlenderCacheResampledForHoudiniHasVelocityPerSecond)
{
    testutil::TempDir dir;
    const Result r = run("resample " + plumeLo(10) + " --frames 10 --down 2 --out " + dir / "proxy.0010.vdb");
    ASSERT_EQ(r.code, 0) << r.out;
    const turb::Frame in = turbio::readFrame(plumeLo(10), 10, turbio::ReadOptions{});
    EXPECT_NEAR(in.timeUnit, 0.4, 1e-12) << "Blender: a frame is 1/24 s and 0.1 x 25/24 time units";
    const turb::Frame out = turbio::readFrame(dir / "proxy.0010.vdb", 20, turbio::ReadOptions{});
    EXPECT_EQ(out.timeUnit, 1.0);
    EXPECT_NEAR(out.dt, 1.0 / 24.0, 1e-12) << "dt per second too";
    EXPECT_EQ(out.metadata.at(turb::meta::kTimeUnit), "1");
    // The mean over 2^3 blocks of the input's velocity, divided by 0.4 s: world units per second.
    const turb::VectorField expect = turb::boxDownsample(in.velocity, 2);
    double peak = 0.0, worst = 0.0;
    size_t compared = 0;
    for (auto c = out.velocity.bbox().begin(); c; ++c) {
        if (!expect.bbox().isInside(*c)) continue;
        for (int a = 0; a < 3; ++a) {
            peak = std::max(peak, std::abs(double(expect[*c][a]) / 0.4));
            worst = std::max(worst, std::abs(double(out.velocity[*c][a]) - double(expect[*c][a]) / 0.4));
        }
        ++compared;
    }
    ASSERT_GT(compared, 100u);
    ASSERT_GT(peak, 0.1);
    EXPECT_LT(worst, 1e-5 * peak) << "peak " << peak;
    const Result info = run("info " + dir / "proxy.0010.vdb");
    EXPECT_TRUE(has(info.out, "time unit 1 s (per second)")) << info.out;
    const Result blenderInfo = run("info " + plumeLo(10));
    EXPECT_TRUE(has(blenderInfo.out, "time unit 0.4 s")) << blenderInfo.out;
}

// Wrong answer 2: a source numbered 1001-1003 for a target at 1-3 was wrapped silently (target 1 read source 1002).
TEST(FirstDay, ASourceNumberedOtherwiseIsMappedAloudAndInfoShowsTheSourceFrame)
{
    testutil::TempDir dir;
    fs::create_directories(fs::path(dir.path()) / "src");
    for (int f = 1; f <= 3; ++f) {
        char from[32], to[32];
        std::snprintf(from, sizeof(from), "fluid_data_%04d.vdb", f);
        std::snprintf(to, sizeof(to), "hi.%04d.vdb", 1000 + f);
        fs::create_symlink(
            testutil::dataPath(std::string("blender-plume-128/") + from), fs::path(dir.path()) / "src" / to);
    }
    const std::string base =
        "transfer --target " + plumeLo() + " --source " + dir / "src/hi.####.vdb" + " --out " + dir / "o.####.vdb";
    const Result plain = run(base + " --frames 1-3 --dry-run");
    ASSERT_EQ(plain.code, 0) << plain.out;
    EXPECT_TRUE(has(plain.out, "source frames: source = target + 0")) << plain.out;
    EXPECT_TRUE(has(plain.out, "3 of 3 wrapped by --source-wrap loop into the source's 1001-1003")) << plain.out;
    EXPECT_TRUE(has(plain.out, "do not overlap the target's 1-3")) << plain.out;
    EXPECT_TRUE(has(plain.out, "--source-offset 1000 lines up the caches' first frames (target 1, source 1001)"))
        << plain.out;
    // The same offset whichever frames the run takes.
    const Result later = run(base + " --frames 8-10 --dry-run");
    EXPECT_TRUE(has(later.out, "--source-offset 1000 lines up")) << later.out;

    const Result offset = run(base + " --source-offset 1000 --frames 1 --velocity-margin 1");
    ASSERT_EQ(offset.code, 0) << offset.out;
    EXPECT_TRUE(has(offset.out, "target 1 -> source 1001")) << offset.out;
    EXPECT_FALSE(has(offset.out, "do not overlap")) << offset.out;
    // The trimmed output's exact resume state has a visible name the log gives.
    EXPECT_TRUE(
        has(offset.out, "resume state: " + dir / "o.resume-state-odd.vdb and " + dir / "o.resume-state-even.vdb"))
        << offset.out;
    EXPECT_TRUE(fs::exists(fs::path(dir.path()) / "o.resume-state-odd.vdb"));
    const Result info = run("info " + dir / "o.0001.vdb");
    EXPECT_TRUE(has(info.out, "made from source frame 1001 (vdbturb_source_frame)")) << info.out;
    const Result infoJson = runStdout("info " + dir / "o.0001.vdb --json");
    EXPECT_EQ(nlohmann::json::parse(infoJson.out)["files"][0]["source_frame"], "1001");
}

TEST(FirstDay, SteppedFramesAreNamedInThePlan)
{
    testutil::TempDir dir;
    const Result r = run(
        "transfer --target " + plumeLo() + " --source " + plumeHi() + " --frames 1-5x2 --dry-run --out " + dir / "o.####.vdb");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(has(r.out, "frames step by up to 2: the detail and density are carried across the skipped frames"))
        << r.out;
    const Result every =
        run("transfer --target " + plumeLo() + " --source " + plumeHi() + " --frames 1-3 --dry-run --out " + dir / "o.####.vdb");
    EXPECT_FALSE(has(every.out, "frames step by")) << every.out;
}

// Usage errors exit 2 on every command, with the prefix, CLI11's own messages included.
TEST(FirstDay, UsageErrorsExitTwoWithThePrefixEverywhere)
{
    testutil::TempDir dir;
    const Result noToken =
        run("transfer --target " + plumeLo() + " --source " + plumeHi() + " --frames 1-3 --out " + dir / "out/turb.vdb");
    EXPECT_EQ(noToken.code, 2) << noToken.out;
    EXPECT_TRUE(has(noToken.out, "vdbturb: error: --out")) << noToken.out;
    const Result preview = run("preview " + plumeLo() + " --frames 1-3 --out " + dir / "p.png");
    EXPECT_EQ(preview.code, 2) << preview.out;
    const Result frames = run("info " + plumeLo() + " --frames 10-1");
    EXPECT_EQ(frames.code, 2) << frames.out;
    EXPECT_TRUE(has(frames.out, "vdbturb: error: ")) << frames.out;
    const Result range = run("preview " + plumeLo() + " --width abc");
    EXPECT_EQ(range.code, 2) << range.out;
    EXPECT_EQ(range.out.rfind("vdbturb: error: ", 0), 0u) << range.out;
    EXPECT_EQ(testutil::countEntries(dir.path()), 0u) << "nothing written";
}

// With --json, a wrapper that parses stdout gets the error as one JSON line, naming the file, frame and grid.
TEST(FirstDay, JsonRunsEndAnErrorWithOneJsonLineOnStdout)
{
    testutil::TempDir dir;
    fs::create_directories(fs::path(dir.path()) / "t");
    for (int f = 1; f <= 2; ++f) {
        char to[32];
        std::snprintf(to, sizeof(to), "t.%04d.vdb", f);
        fs::copy_file(plumeLo(f), fs::path(dir.path()) / "t" / to);
    }
    fs::resize_file(fs::path(dir.path()) / "t/t.0002.vdb", 3000); // a damaged frame 2
    const Result r = runStdout(
        "transfer --target " + dir / "t/t.####.vdb" + " --source " + plumeHi() + " --out " + dir / "o.####.vdb --json");
    EXPECT_EQ(r.code, 1) << r.out;
    const nlohmann::json j = nlohmann::json::parse(lastLine(r.out));
    EXPECT_EQ(j["exit"], 1);
    EXPECT_EQ(j["file"], dir / "t/t.0002.vdb") << j.dump();
    EXPECT_EQ(j["frame"], 2) << "the file's frame: " << j.dump();
    EXPECT_TRUE(has(j["error"].get<std::string>(), "t.0002.vdb")) << j.dump();

    const Result grid = runStdout("info " + plumeLo(1) + " --density-grid smoke --validate --json");
    EXPECT_EQ(grid.code, 1);
    const Result usage = runStdout("transfer --json --target " + plumeLo() + " --source " + plumeHi() + " --frames 5-1");
    EXPECT_EQ(usage.code, 2);
    const nlohmann::json u = nlohmann::json::parse(lastLine(usage.out));
    EXPECT_EQ(u["exit"], 2);
    EXPECT_TRUE(u["file"].is_null());
}

// Under `ulimit -f` the process was killed by SIGXFSZ (rc 153) with a temporary file left: now a message, exit 75.
TEST(FirstDay, AFileSizeLimitExitsSeventyFiveAndLeavesNoTemporaryFile)
{
    testutil::TempDir dir;
    const Result r = clitest::shell("ulimit -f 16; " + std::string(VDBTURB_EXE) + " resample " +
                                    testutil::dataPath("blender-plume-128/fluid_data_0010.vdb") +
                                    " --frames 10 --down 1 --out " + dir / "big.0010.vdb 2>&1");
    EXPECT_EQ(r.code, 75) << r.out;
    EXPECT_TRUE(has(r.out, "file size limit reached: ulimit -f allows")) << r.out;
    EXPECT_TRUE(has(r.out, "big.0010.vdb")) << r.out;
    EXPECT_EQ(testutil::countEntries(dir.path()), 0u) << "no temporary or partial file";
}

TEST(FirstDay, InfoOnADamagedSequenceListsEveryFrameAndExitsOne)
{
    testutil::TempDir dir;
    for (int f = 1; f <= 4; ++f) {
        char to[32];
        std::snprintf(to, sizeof(to), "c.%04d.vdb", f);
        fs::copy_file(plumeLo(f), fs::path(dir.path()) / to);
    }
    fs::resize_file(fs::path(dir.path()) / "c.0002.vdb", 2000);
    {
        std::ofstream garbage(fs::path(dir.path()) / "c.0003.vdb", std::ios::binary | std::ios::trunc);
        garbage << "not a vdb file at all";
    }
    const Result r = run("info " + dir / "c.####.vdb");
    EXPECT_EQ(r.code, 1) << r.out;
    for (const std::string f : {"frame 1", "frame 4"}) EXPECT_TRUE(has(r.out, f + ":")) << r.out;
    EXPECT_TRUE(has(r.out, "c.0002.vdb")) << r.out;
    EXPECT_TRUE(has(r.out, "c.0003.vdb")) << r.out;
    EXPECT_TRUE(has(r.out, "2 of 4 frames failed to read: 2,3")) << r.out;
    const nlohmann::json j = nlohmann::json::parse(runStdout("info " + dir / "c.####.vdb --json").out);
    ASSERT_EQ(j["files"].size(), 4u);
    EXPECT_FALSE(j["files"][0].contains("error"));
    EXPECT_TRUE(j["files"][1].contains("error"));
    EXPECT_TRUE(j["files"][2].contains("error"));
    EXPECT_FALSE(j["files"][3].contains("error"));
}

// Houdini's world is y up: a y-up cache is drawn upright, as the same smoke stored z up is.
TEST(FirstDay, PreviewDrawsAYUpCacheUpright)
{
    testutil::TempDir dir;
    const turb::Frame zUp = turbio::readFrame(plumeLo(10), 10, turbio::ReadOptions{});
    turb::Frame yUp = turb::reorientFrame(zUp, turb::AxisRotation::quarterTurns(0, -1)); // +z onto +y
    yUp.metadata[turb::meta::kUpAxis] = "y";
    turbio::writeFrame(dir / "z.0010.vdb", zUp, turbio::WriteOptions{});
    turbio::writeFrame(dir / "y.0010.vdb", yUp, turbio::WriteOptions{});
    const std::string opts = " --width 64 --mode density,vorticity";
    ASSERT_EQ(run("preview " + dir / "z.0010.vdb --out " + dir / "z.png" + opts).code, 0);
    const Result auto_ = run("preview " + dir / "y.0010.vdb --out " + dir / "auto.png" + opts);
    ASSERT_EQ(auto_.code, 0) << auto_.out;
    EXPECT_TRUE(has(auto_.out, "drawn with +y up (vdbturb_up_axis metadata")) << auto_.out;
    ASSERT_EQ(run("preview " + dir / "y.0010.vdb --up z --out " + dir / "asStored.png" + opts).code, 0);
    const turb::RgbaImage z = turbio::readImage(dir / "z.png"), a = turbio::readImage(dir / "auto.png"),
                          s = turbio::readImage(dir / "asStored.png");
    ASSERT_EQ(z.width(), a.width());
    ASSERT_EQ(z.height(), a.height());
    double diffUpright = 0.0, diffStored = 0.0;
    for (size_t i = 0; i < z.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            diffUpright += std::abs(z.pixels()[i][c] - a.pixels()[i][c]);
            diffStored += std::abs(z.pixels()[i][c] - s.pixels()[i][c]);
        }
    // Upright, the pictures agree to a few 1e-3 a pixel (measured 0.002: the held boxes' edges); as stored, they do
    // not.
    EXPECT_LT(diffUpright, 0.01 * double(z.size())) << "the y-up cache drawn upright is the z-up picture";
    EXPECT_GT(diffStored, 10.0 * (diffUpright + 1.0))
        << "drawn as stored, it lies on its side; upright " << diffUpright;
}

// A 10-frame shot in three chunks: the default overlap (20) shrinks to what fits; a given one that cannot is refused
// with the largest that can.
TEST(FirstDay, FarmPlanFitsTheOverlapToTheShot)
{
    testutil::TempDir dir;
    const std::string base = "farm plan --dir " + dir / "f" + " --target " + plumeLo() + " --source " + plumeHi() + " --out " +
                             dir / "o.####.vdb --chunks 3 --dry-run";
    const Result fit = run(base);
    EXPECT_EQ(fit.code, 0) << fit.out;
    EXPECT_TRUE(has(fit.out, "overlap 2 frames: the default 20 does not fit 10 frames in 3 chunks")) << fit.out;
    const Result given = run(base + " --overlap 5");
    EXPECT_EQ(given.code, 2) << given.out;
    EXPECT_TRUE(has(given.out, "--overlap 2 is the most that 3 chunks of this shot hold")) << given.out;
}

// The dry run gives a time estimate from the fitted model (docs/performance.md states its error).
TEST(FirstDay, TheDryRunEstimatesTheTime)
{
    testutil::TempDir dir;
    const Result r = run("transfer --target " + plumeLo() + " --source " + plumeHi() + " --dry-run --out " + dir / "o.####.vdb");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(has(r.out, "time: about ")) << r.out;
    EXPECT_TRUE(has(r.out, " s/frame on 2 cores")) << r.out;
    // Frame 1 carries the detail at full strength; the plan says why measure's default reading of it is low.
    EXPECT_TRUE(has(r.out, "Measure it so (vdbturb measure --source-extend-velocity 4)")) << r.out;
}

// Every column of a sheet on one world box: the Blender 128^3 source's small plume, inside the target's domain, was
// framed on its own box (zoomed in 2.8x beside the target).
TEST(FirstDay, SheetColumnsOfOneSceneShareOneWorldBox)
{
    testutil::TempDir dir;
    const Result r = runStdout(
        "preview target=" + plumeLo() + " source=" + plumeHi() + " --frames 5 --width 64 --sheet " + dir / "s.png --json");
    ASSERT_EQ(r.code, 0) << r.out;
    std::istringstream lines(r.out);
    std::string line;
    bool seen = false;
    while (std::getline(lines, line)) {
        const nlohmann::json j = nlohmann::json::parse(line);
        if (!j.contains("framed")) continue;
        seen = true;
        const auto& t = j["framed"]["target"];
        const auto& s = j["framed"]["source"];
        for (int k = 0; k < 6; ++k) EXPECT_NEAR(t[k].get<double>(), s[k].get<double>(), 0.07) << j.dump();
    }
    EXPECT_TRUE(seen) << r.out;
}
