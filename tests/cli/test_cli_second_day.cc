// A TD's second day (issue 45): one file name meaning that file, farm-wrapper progress lines and exit codes, and
// option errors that say what is allowed. Real Blender caches.
#include "CliUtil.h"
#include "TestUtil.h"

#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <turb/NewGrid.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using clitest::has;
using clitest::Result;

using clitest::plumeHi;
using clitest::plumeLo;
using clitest::run;
using clitest::runStdout;
using clitest::slurp;

// A file's inode: a frame written again is a new file renamed into place, a skipped one keeps its inode.
ino_t inode(const std::string& path)
{
    struct stat st
    {};
    return ::stat(path.c_str(), &st) == 0 ? st.st_ino : 0;
}

} // namespace

// `preview fluid_data_0010.vdb --out f10.png` exited 2 ("30 frames are requested") and `info fluid_data_0010.vdb`
// described frame 1: one file name means that file, in every command, and one line names the sequence it is part of.
TEST(SecondDay, OneFileNameMeansThatFileInEveryCommand)
{
    testutil::TempDir dir;
    const std::string note = "is frame 10 of ";
    const Result info = run("info " + plumeLo(10));
    ASSERT_EQ(info.code, 0) << info.out;
    EXPECT_TRUE(has(info.out, ": 1 frame (10)")) << info.out;
    EXPECT_TRUE(has(info.out, note + testutil::dataPath("blender-plume-32/fluid_data_####.vdb") +
                                  " (frames 1-10 on disk): give that pattern, or --frames"))
        << info.out;
    EXPECT_TRUE(has(info.out, "frame 10: ")) << info.out;

    const Result preview = run("preview " + plumeLo(10) + " --width 32 --out " + dir / "f10.png");
    EXPECT_EQ(preview.code, 0) << preview.out;
    EXPECT_TRUE(fs::exists(dir / "f10.png"));

    const Result resample = run("resample " + plumeLo(10) + " --down 2 --out " + dir / "r.vdb");
    EXPECT_EQ(resample.code, 0) << resample.out;
    EXPECT_TRUE(has(resample.out, note)) << resample.out;
    EXPECT_TRUE(fs::exists(dir / "r.vdb"));

    // A single target file is a one-frame shot; the source named by one file is that frame.
    const Result transfer =
        run("transfer --target " + plumeLo(2) + " --source " + plumeHi(2) + " --out " + dir / "up.0002.vdb --dry-run");
    EXPECT_EQ(transfer.code, 0) << transfer.out;
    EXPECT_TRUE(has(transfer.out, "target: " + plumeLo(2) + " is frame 2 of")) << transfer.out;
    EXPECT_TRUE(has(transfer.out, "would write " + dir / "up.0002.vdb")) << transfer.out;
    EXPECT_FALSE(has(transfer.out, "would write " + dir / "up.0003.vdb")) << transfer.out;

    // With --frames, the file names its sequence.
    const Result framed = run("info " + plumeLo(10) + " --frames 1-3 --headers-only");
    EXPECT_TRUE(has(framed.out, ": 3 frames (1-3)")) << framed.out;
}

// Tractor and Deadline read progress from a job's output; the default on a non-terminal stays a line a frame.
TEST(SecondDay, FarmWrapperProgressLines)
{
    testutil::TempDir dir;
    const std::string base = "resample " + plumeLo() + " --frames 1-4 --down 2 --out ";
    const Result alf = runStdout(base + dir / "a.####.vdb --progress alf");
    ASSERT_EQ(alf.code, 0) << alf.out;
    EXPECT_EQ(alf.out, "ALF_PROGRESS 25%\nALF_PROGRESS 50%\nALF_PROGRESS 75%\nALF_PROGRESS 100%\n");
    const Result percent = runStdout(base + dir / "p.####.vdb --progress percent");
    EXPECT_EQ(percent.out, "Progress: 25%\nProgress: 50%\nProgress: 75%\nProgress: 100%\n");
    const Result plain = run(base + dir / "l.####.vdb");
    EXPECT_EQ(clitest::count(plain.out, "/4) "), 4u) << "one line a frame: " << plain.out;
    EXPECT_FALSE(has(plain.out, "Progress:")) << plain.out;
    // With --json, stdout stays JSON: the wrapper lines go to stderr.
    const Result json = runStdout(base + dir / "j.####.vdb --progress alf --json");
    std::istringstream lines(json.out);
    std::string line;
    while (std::getline(lines, line)) EXPECT_NO_THROW((void)nlohmann::json::parse(line)) << line;
    EXPECT_EQ(run("info " + plumeLo() + " --progress bar").code, 2) << "info takes no --progress";
}

// Exit codes a wrapper can act on: 1 (a resume with other settings) was retried twice by farm's Slurm scripts; now
// only 75, an interruption and a kill are.
TEST(SecondDay, FarmScriptsRequeueOnlyWhatARetryCanFix)
{
    testutil::TempDir dir;
    const Result plan = run("farm plan --dir " + dir / "f" + " --target " + plumeLo() + " --source " + plumeHi() + " --out " +
                            dir / "o.####.vdb --chunks 2 --overlap 2");
    ASSERT_EQ(plan.code, 0) << plan.out;
    std::ifstream in(dir / "f/chunks.sbatch");
    const std::string script((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_TRUE(has(script, "  75|130|137|143) ;;\n  *) exit $rc ;;")) << script;
    std::ifstream pj(dir / "f/plan.json");
    const nlohmann::json j = nlohmann::json::parse(pj);
    EXPECT_EQ(j["tasks"][0]["retry_exit_codes"], nlohmann::json({75, 130, 137, 143})) << j.dump();
    const Result help = run("transfer --help");
    EXPECT_TRUE(has(help.out, "75 worth a retry on another node")) << help.out;
}

// CLI11's integer ranges printed "Value abc not in range 16 to 8192": the message says what is allowed.
TEST(SecondDay, OptionValueErrorsSayWhatIsAllowed)
{
    const Result width = run("preview " + plumeLo() + " --width abc");
    EXPECT_EQ(width.code, 2);
    EXPECT_TRUE(has(width.out, "vdbturb: error: --width must be a number from 16 to 8192, not 'abc'")) << width.out;
    const Result margin = run("transfer --target " + plumeLo() + " --source " + plumeHi() +
                              " --out o.####.vdb "
                              "--velocity-margin 99");
    EXPECT_EQ(margin.code, 2);
    EXPECT_TRUE(has(
        margin.out, "--velocity-margin: must be auto, -1 (the whole box) or a number of voxels from 0 to 64, not '99'"))
        << margin.out;
    EXPECT_FALSE(has(margin.out, "Value 99 not in range")) << margin.out;
    // A mistyped grid name gets the nearest of the file's grids.
    const Result grid = run("resample " + plumeLo(1) + " --vel-grid velocty --down 2 --out never.vdb");
    EXPECT_EQ(grid.code, 1);
    EXPECT_TRUE(has(grid.out, "no 'velocty' grid (did you mean 'velocity'?); the file has: #0 'velocity'")) << grid.out;
    const Result far = run("resample " + plumeLo(1) + " --density-grid smoke --down 2 --out never.vdb");
    EXPECT_FALSE(has(far.out, "did you mean")) << "nothing near 'smoke': " << far.out;
}

namespace {

// A frame file holding two grids named 'density' (a small and a large box) and a velocity, written with OpenVDB's
// C++ API (`writer` "cpp") or with pyopenvdb (`writer` "py", Debian's python3-openvdb).
void writeTwinDensities(const std::string& path, const std::string& writer)
{
    if (writer == "py") {
        const std::string script =
            "import pyopenvdb as vdb\n"
            "def dens(n, v):\n"
            "    g = vdb.FloatGrid(); g.name = 'density'; g.transform = vdb.createLinearTransform(0.1)\n"
            "    g.fill((0, 0, 0), (n - 1, n - 1, n - 1), v); return g\n"
            "vel = vdb.Vec3SGrid(); vel.name = 'vel'; vel.transform = vdb.createLinearTransform(0.1)\n"
            "vel.fill((0, 0, 0), (7, 7, 7), (0.0, 0.0, 1.0))\n"
            "vdb.write('" +
            path + "', grids=[dens(4, 0.25), vel, dens(8, 0.875)])\n";
        const Result r = clitest::shell("/usr/bin/python3 -c \"" + script + "\" 2>&1");
        ASSERT_EQ(r.code, 0) << r.out;
        return;
    }
    const auto dens = [](int n, float v) {
        auto g = turb::newGrid<openvdb::FloatGrid>(0.0f);
        g->setName("density");
        g->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
        g->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(n - 1)), v);
        return g;
    };
    auto vel = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    vel->setName("vel");
    vel->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
    vel->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(7)), openvdb::Vec3s(0.0f, 0.0f, 1.0f));
    openvdb::io::File(path).write({dens(4, 0.25f), vel, dens(8, 0.875f)});
}

} // namespace

// Houdini writes two grids named 'density' when two primitives share a name: info lists both with their own ranges,
// a command reading by name says which one it reads and how to pick the other, and the selector picks it.
TEST(SecondDay, TwoGridsOfOneNameAreListedAndTheOneReadIsNamed)
{
    openvdb::initialize();
    testutil::TempDir dir;
    for (const std::string writer : {"cpp", "py"}) {
        const std::string file = dir / ("twins_" + writer + ".vdb");
        writeTwinDensities(file, writer);
        const Result info = run("info " + file);
        ASSERT_EQ(info.code, 0) << info.out;
        EXPECT_TRUE(has(info.out, "density[0]")) << info.out;
        EXPECT_TRUE(has(info.out, "density[1]")) << info.out;
        EXPECT_TRUE(has(info.out, "[0.25, 0.25]")) << "each its own range: " << info.out;
        EXPECT_TRUE(has(info.out, "[0.875, 0.875]")) << info.out;
        EXPECT_TRUE(has(info.out, "more than one grid named 'density': reading #0 (density[0]), the first, as "
                                  "OpenVDB's readGrid does; the grid selector density[1] reads another"))
            << writer << ": " << info.out;
        const Result first = run("resample " + file + " --down 2 --out " + dir / (writer + "_a.vdb"));
        ASSERT_EQ(first.code, 0) << first.out;
        EXPECT_TRUE(has(first.out, "more than one grid named 'density'")) << first.out;
        const Result second =
            run("resample " + file + " --density-grid 'density[1]' --down 2 --out " + dir / (writer + "_b.vdb"));
        ASSERT_EQ(second.code, 0) << second.out;
        EXPECT_TRUE(has(second.out, "reading #2 (density[1]); the grid selector density[0] reads another"))
            << second.out;
        const turb::Frame a = turbio::readFrame(dir / (writer + "_a.vdb"), 0, turbio::ReadOptions{});
        const turb::Frame b = turbio::readFrame(dir / (writer + "_b.vdb"), 0, turbio::ReadOptions{});
        EXPECT_NEAR(a.density(0, 0, 0), 0.25, 1e-6) << writer;
        EXPECT_NEAR(b.density(3, 3, 3), 0.875, 1e-6) << writer;
    }
}

namespace {

// A copy of a Blender cache frame with `n` stray voxels of density (0.5) and velocity at (600, 600, 600) onward, far
// outside Blender's 32^3 simulation box (a broken source or an explosion in a real cache).
void writeWithStrays(const std::string& from, const std::string& to, int n)
{
    openvdb::io::File in(from);
    in.open();
    openvdb::GridPtrVecPtr grids = in.getGrids();
    openvdb::MetaMap::Ptr meta = in.getMetadata();
    in.close();
    for (auto& g : *grids)
        for (int k = 0; k < n; ++k) {
            const openvdb::Coord c(600 + k % 10, 600 + (k / 10) % 10, 600 + k / 100);
            if (auto d = openvdb::gridPtrCast<openvdb::FloatGrid>(g); d && g->getName() == "density")
                d->tree().setValueOn(c, 0.5f);
            if (auto v = openvdb::gridPtrCast<openvdb::Vec3SGrid>(g); v && g->getName() == "velocity")
                v->tree().setValueOn(c, openvdb::Vec3s(0.1f, 0.2f, 0.3f));
        }
    openvdb::io::File(to).write(*grids, *meta);
}

std::string gridsChecksum(const Result& info)
{
    std::string keep;
    std::istringstream lines(info.out);
    std::string line;
    while (std::getline(lines, line))
        if (line.rfind("  density ", 0) == 0 || line.rfind("  vel ", 0) == 0 || line.rfind("  temperature ", 0) == 0)
            keep += line + "\n";
    return keep;
}

} // namespace

// One stray voxel at (600,600,600) in each frame of a real Blender target changed the output (relative difference
// 1.07) and doubled memory; ten or a thousand were refused as needing 423 GB. Outside Blender's simulation box they
// are strays whatever their size: reported once, and the output is bit-identical to the run without them.
TEST(SecondDay, StrayVoxelsOutsideBlendersBoxCostNothing)
{
    openvdb::initialize();
    testutil::TempDir dir;
    const std::string args = " --source " + plumeHi() + " --frames 1-3 -q --out ";
    ASSERT_EQ(run("transfer --target " + plumeLo() + args + dir / "ref/o.####.vdb").code, 0);
    const std::string plan =
        run("transfer --target " + plumeLo() + " --source " + plumeHi() + " --frames 1-3 --dry-run --out " + dir / "x/o.####.vdb")
            .out;
    const auto memoryLine = [](const std::string& text) { // the estimate, not the free memory beside it
        const size_t at = text.find("memory: about ");
        return at == std::string::npos ? std::string() : text.substr(at, text.find("; this process may use", at) - at);
    };
    ASSERT_FALSE(memoryLine(plan).empty()) << plan;
    for (const int n : {1, 10, 1000}) {
        const std::string in = dir / ("in" + std::to_string(n));
        fs::create_directories(in);
        for (int f = 1; f <= 3; ++f) {
            char name[32];
            std::snprintf(name, sizeof(name), "/fluid_data_%04d.vdb", f);
            writeWithStrays(plumeLo(f), in + name, n);
        }
        const std::string target = in + "/fluid_data_####.vdb";
        const Result dry = run("transfer --target " + target + " --source " + plumeHi() + " --frames 1-3 --dry-run --out " +
                               dir / "x/o.####.vdb");
        ASSERT_EQ(dry.code, 0) << n << ": " << dry.out;
        EXPECT_EQ(memoryLine(dry.out), memoryLine(plan)) << n << " strays: the same memory estimate";
        EXPECT_EQ(clitest::count(dry.out, "has active voxels outside Blender's simulation box 32x32x32"), 1u)
            << n << ": reported once: " << dry.out;
        const std::string out = dir / ("o" + std::to_string(n));
        ASSERT_EQ(run("transfer --target " + target + args + out + "/o.####.vdb").code, 0) << n;
        for (int f = 1; f <= 3; ++f) {
            char name[32];
            std::snprintf(name, sizeof(name), "/o.%04d.vdb", f);
            const std::string a = gridsChecksum(run("info " + dir / "ref" + name + " --checksum"));
            EXPECT_FALSE(a.empty());
            EXPECT_EQ(gridsChecksum(run("info " + out + name + " --checksum")), a) << n << " strays, frame " << f;
        }
    }
}

// A Houdini cache has no simulation box to say what is a stray: a far cluster holding under 1% of the density's mass
// is one. Houdini's smoke1 sample (one density grid, 1.05 M voxels) with 1, 10 and 1000 voxels added at
// (600,600,600), 377 voxels beyond its box: said once, resampled bit-identically to the file without them;
// --keep-isolated holds them (the held box then reaches them).
TEST(SecondDay, StrayVoxelsFarFromAHoudiniCachesSmokeAreIgnoredUnlessKept)
{
    openvdb::initialize();
    testutil::TempDir dir;
    const std::string smoke = testutil::dataPath("houdini-smoke1/smoke.vdb");
    const std::string ref = dir / "ref.vdb";
    ASSERT_EQ(run("resample " + smoke + " --down 2 -q --out " + ref).code, 0);
    const std::string expected = gridsChecksum(run("info " + ref + " --checksum"));
    ASSERT_FALSE(expected.empty());
    const std::map<int, std::string> names = {{1, "one"}, {10, "ten"}, {1000, "thousand"}}; // no frame numbers
    for (const int n : {1, 10, 1000}) {
        const std::string in = dir / (names.at(n) + ".vdb");
        {
            openvdb::io::File file(smoke);
            file.open();
            openvdb::GridPtrVecPtr grids = file.getGrids();
            openvdb::MetaMap::Ptr meta = file.getMetadata();
            file.close();
            auto d = openvdb::gridPtrCast<openvdb::FloatGrid>(grids->front());
            ASSERT_TRUE(d);
            for (int k = 0; k < n; ++k)
                d->tree().setValueOn(openvdb::Coord(600 + k % 10, 600 + (k / 10) % 10, 600 + k / 100), 0.5f);
            openvdb::io::File(in).write(*grids, *meta);
        }
        const std::string out = dir / ("r_" + names.at(n) + ".vdb");
        const Result r = run("resample " + in + " --down 2 --out " + out);
        ASSERT_EQ(r.code, 0) << n << ": " << r.out;
        EXPECT_EQ(clitest::count(r.out, " of density far from the smoke"), 1u) << n << ": " << r.out;
        EXPECT_TRUE(has(r.out, std::to_string(n) + (n == 1 ? " voxel" : " voxels") + " of density far from the smoke"))
            << r.out;
        EXPECT_TRUE(has(r.out, "ignored: see --keep-isolated")) << r.out;
        EXPECT_EQ(gridsChecksum(run("info " + out + " --checksum")), expected) << n << " strays";
    }
    // A stray 49 voxels from the smoke: the header scan does not read the voxels for it (the box is not far larger
    // than the smoke), the frame's read finds it, and that is said too, once.
    {
        openvdb::io::File file(smoke);
        file.open();
        openvdb::GridPtrVecPtr grids = file.getGrids();
        openvdb::MetaMap::Ptr meta = file.getMetadata();
        file.close();
        openvdb::gridPtrCast<openvdb::FloatGrid>(grids->front())->tree().setValueOn(openvdb::Coord(160, 100, 50), 0.5f);
        openvdb::io::File(dir / "near.vdb").write(*grids, *meta);
    }
    const Result near = run("resample " + dir / "near.vdb --down 2 --out " + dir / "r_near.vdb");
    ASSERT_EQ(near.code, 0) << near.out;
    EXPECT_EQ(clitest::count(near.out, "1 voxel of density far from the smoke (49 voxels away"), 1u) << near.out;
    EXPECT_EQ(gridsChecksum(run("info " + dir / "r_near.vdb --checksum")), expected);
    const Result kept = run("info " + dir / "ten.vdb --keep-isolated");
    ASSERT_EQ(kept.code, 0) << kept.out;
    EXPECT_FALSE(has(kept.out, "far from the smoke")) << kept.out;
    EXPECT_TRUE(has(kept.out, "held in memory: 609x599x600 voxels")) << "from (1,2,1) to (609,600,600): " << kept.out;
    const Result ignored = run("info " + dir / "ten.vdb");
    EXPECT_TRUE(has(ignored.out, "held in memory: 111x222x112 voxels")) << ignored.out;
}

// Frame 30 of the paper-configuration up-res was 15.4x Blender's noise file: 32-bit floats and velocity over the
// whole held box. By default an up-res frame is 16-bit, with velocity within one target voxel of the smoke (4 output
// voxels at ratio 4); --full-float --velocity-margin -1 writes the whole frame. The measure numbers of the two stay
// within 1% (real Blender pair).
TEST(SecondDay, TransferWritesHalfFloatsNearTheSmokeByDefault)
{
    testutil::TempDir dir;
    const std::string base = "transfer --target " + plumeLo() + " --source " + plumeHi() + " --frames 1-3 -q --out ";
    ASSERT_EQ(run(base + dir / "d/o.####.vdb").code, 0);
    ASSERT_EQ(run(base + dir / "f/o.####.vdb --full-float --velocity-margin -1").code, 0);
    const Result info = run("info " + dir / "d/o.0003.vdb");
    EXPECT_TRUE(has(info.out, "velocity written only within 4 voxels of the smoke, 16-bit floats")) << info.out;
    EXPECT_FALSE(has(run("info " + dir / "f/o.0003.vdb").out, "16-bit floats"));
    for (const char* name : {"o.0001.vdb", "o.0002.vdb", "o.0003.vdb"})
        EXPECT_LT(double(fs::file_size(dir / ("d/" + std::string(name)))),
            0.4 * double(fs::file_size(dir / ("f/" + std::string(name)))))
            << name;
    const auto numbers = [&](const std::string& out) {
        std::vector<nlohmann::json> frames;
        std::istringstream lines(
            runStdout("measure --output " + out + " --target " + plumeLo() + " --source " + plumeHi() + " --frames 1-3").out);
        std::string line;
        while (std::getline(lines, line))
            if (!line.empty() && line[0] == '{') {
                nlohmann::json j = nlohmann::json::parse(line);
                if (j.contains("frame")) frames.push_back(j);
            }
        return frames;
    };
    // Houdini's velocity voxel scale: vel on a lattice twice as coarse, about an eighth of the voxels, each the mean
    // of its block; measure reads it back. --no-velocity: no velocity grid.
    const std::string one = "transfer --target " + plumeLo() + " --source " + plumeHi() + " --frames 3 -q --out ";
    ASSERT_EQ(run(one + dir / "s/o.####.vdb --vel-voxel-scale 2").code, 0);
    ASSERT_EQ(run(one + dir / "n/o.####.vdb --no-velocity").code, 0);
    ASSERT_EQ(run(one + dir / "f3/o.####.vdb --full-float --velocity-margin -1").code, 0); // the same frame 3, whole
    const auto grid = [](const std::string& path, const std::string& name) {
        for (const turbio::GridInfo& g : turbio::inspectFile(path, false).grids)
            if (g.name == name) return g;
        return turbio::GridInfo{};
    };
    const turbio::GridInfo fine = grid(dir / "d/o.0003.vdb", "vel"), coarse = grid(dir / "s/o.0003.vdb", "vel");
    EXPECT_DOUBLE_EQ(coarse.voxelSize, 2.0 * fine.voxelSize);
    EXPECT_GT(coarse.activeVoxels, fine.activeVoxels / 9);
    EXPECT_LT(coarse.activeVoxels, fine.activeVoxels / 4);
    EXPECT_TRUE(grid(dir / "n/o.0003.vdb", "vel").name.empty());
    EXPECT_FALSE(grid(dir / "n/o.0003.vdb", "density").name.empty());
    {
        // Each coarse voxel is its block's mean: the full-float velocity of the same run, averaged, where written.
        const auto readVel = [](const std::string& path) {
            openvdb::io::File file(path);
            file.open();
            const auto g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid("vel"));
            file.close();
            return g;
        };
        const auto full = readVel(dir / "f3/o.0003.vdb"), vel = readVel(dir / "s/o.0003.vdb");
        ASSERT_TRUE(full && vel);
        const auto acc = full->getConstAccessor();
        double worst = 0.0, peak = 0.0;
        for (auto it = vel->cbeginValueOn(); it; ++it) {
            openvdb::Vec3s mean(0.0f);
            const openvdb::Coord c = it.getCoord();
            for (int k = 0; k < 8; ++k)
                mean +=
                    acc.getValue(openvdb::Coord(2 * c.x() + (k & 1), 2 * c.y() + (k >> 1 & 1), 2 * c.z() + (k >> 2)));
            mean *= 0.125f;
            worst = std::max(worst, double((*it - mean).length()));
            peak = std::max(peak, double(mean.length()));
        }
        EXPECT_GT(peak, 0.0);
        EXPECT_LT(worst, 2e-3 * peak) << "half precision of the block mean";
    }
    const auto small = numbers(dir / "d/o.####.vdb"), full = numbers(dir / "f/o.####.vdb");
    ASSERT_EQ(small.size(), 3u);
    ASSERT_EQ(full.size(), 3u);
    for (size_t i = 0; i < 3; ++i)
        for (const char* k :
            {"lf_err", "hf_ratio", "div_rel", "block", "mass_ratio", "density_err", "vort_peak_ratio"}) {
            const double a = small[i][k].get<double>(), b = full[i][k].get<double>();
            EXPECT_NEAR(a, b, 0.01 * std::abs(b)) << k << " at frame " << i + 1;
        }
}

// Farm wrappers: --skip-existing (their name for --resume) skips the frames written by the same settings and refuses
// others; info shows a space tile's metadata.
TEST(SecondDay, SkipExistingAndTileMetadataForFarmWrappers)
{
    testutil::TempDir dir;
    const std::string base =
        "transfer --target " + plumeLo() + " --source " + plumeHi() + " --tile-box 4,6,0,19,21,11 --out " + dir / "t/o.####.vdb";
    ASSERT_EQ(run(base + " --frames 1-2 -q").code, 0);
    const auto written = fs::last_write_time(dir / "t/o.0001.vdb");
    const Result again = run(base + " --frames 1-3 --skip-existing");
    ASSERT_EQ(again.code, 0) << again.out;
    EXPECT_EQ(fs::last_write_time(dir / "t/o.0001.vdb"), written) << "frame 1 skipped";
    EXPECT_TRUE(fs::exists(dir / "t/o.0003.vdb"));
    const Result other = run(base + " --frames 1-4 --skip-existing --gamma 0");
    EXPECT_EQ(other.code, 1) << "other settings: refused, never retried" << other.out;
    const Result info = run("info " + dir / "t/o.0003.vdb");
    EXPECT_TRUE(has(info.out, "a space tile of target box 4,6,0,19,21,11 (vdbturb_tile_box)")) << info.out;

    // resample, whose frames are each made from their input alone, skips the same way.
    const std::string rs = "resample " + plumeLo() + " --down 2 --out " + dir / "r/r.####.vdb";
    ASSERT_EQ(run(rs + " --frames 1-2 -q").code, 0);
    const auto r1 = fs::last_write_time(dir / "r/r.0001.vdb");
    const Result more = run(rs + " --frames 1-3 --skip-existing");
    ASSERT_EQ(more.code, 0) << more.out;
    EXPECT_TRUE(has(more.out, "skipped: " + dir / "r/r.0001.vdb" + " was written by the same settings")) << more.out;
    EXPECT_EQ(fs::last_write_time(dir / "r/r.0001.vdb"), r1);
    EXPECT_TRUE(fs::exists(dir / "r/r.0003.vdb"));
    const Result changed =
        run("resample " + plumeLo() + " --down 4 --frames 1-3 --skip-existing --out " + dir / "r/r.####.vdb");
    EXPECT_EQ(changed.code, 1) << changed.out;
    EXPECT_TRUE(has(changed.out, "down: 2 -> 4")) << changed.out;
    EXPECT_EQ(fs::last_write_time(dir / "r/r.0001.vdb"), r1) << "nothing written is replaced";
    const nlohmann::json j = nlohmann::json::parse(runStdout("info " + dir / "t/o.0003.vdb --json").out);
    EXPECT_EQ(j["files"][0]["tile_box"], "4,6,0,19,21,11");
}

// --skip-existing in the commands that make frames in order (sim, synth, stylize) or all at once (animate): a frame
// written by the same settings is left as it is (the same inode), a missing one comes back byte for byte as the
// first run wrote it, a frame of other settings is refused naming the setting, and nothing is replaced.
TEST(SecondDay, SkipExistingInSimSynthStylizeAndAnimate)
{
    testutil::TempDir dir;
    struct Case
    {
        std::string command, pattern; ///< the run without --out, and its output pattern (#### = 4 digits)
        int frames;                   ///< frames it writes, numbered from 1
        std::string other, changed;   ///< an option that changes the frames, and the difference the refusal names
    };
    const std::vector<Case> cases = {
        {"sim plume --res 16 --frames 4", "sim/s.####.vdb", 4, "--seed 2", "seed: 1 -> 2"},
        {"synth --flow vortex --frames 3 --factor 2", "synth/s.####.vdb", 3, "--omega 0.7", "omega: 0.5 -> 0.7"},
        {"stylize --scene swirl --scene-size 48x48 --frames 4 --exemplar builtin:fire", "styl/f.####.png", 4,
            "--seed 7", "seed: 1 -> 7"},
        {"stylize --method fluidymation --scene swirl --scene-size 48x48 --frames 3 --exemplar builtin:ink:48x48x12",
            "fluidy/f.####.exr", 3, "--seed 7", "seed: 1 -> 7"},
        {"animate --example builtin:river:48x32x20 --target builtin:river:48x32 --flow-strokes builtin:river",
            "anim/a.####.png", 4, "--tau 15", "tau: 16 -> 15"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.command);
        const std::string pattern = dir / c.pattern;
        const auto frame = [&](int f) {
            std::string p = pattern;
            char num[8];
            std::snprintf(num, sizeof(num), "%04d", f);
            return p.replace(p.find("####"), 4, num);
        };
        const std::string base = c.command + " --out " + pattern;
        ASSERT_EQ(run(base + " -q").code, 0);
        // A VDB file holds a fresh UUID each write: its grids' checksums say whether they are the same.
        const auto content = [&](int f) {
            return frame(f).find(".vdb") != std::string::npos ? run("info --checksum " + frame(f)).out
                                                              : slurp(frame(f));
        };
        const std::string second = content(2);
        ASSERT_FALSE(second.empty());
        fs::remove(frame(2));
        std::vector<ino_t> before;
        for (int f = 1; f <= c.frames; ++f) before.push_back(inode(frame(f)));

        const Result plan = runStdout(base + " --skip-existing --dry-run");
        ASSERT_EQ(plan.code, 0) << plan.out;
        EXPECT_TRUE(has(plan.out, "would skip " + frame(1) + " (written by the same settings)")) << plan.out;
        EXPECT_TRUE(has(plan.out, "would write " + frame(2) + "\n")) << plan.out;

        const Result again = run(base + " --skip-existing");
        ASSERT_EQ(again.code, 0) << again.out;
        EXPECT_TRUE(has(again.out, "skipped: " + frame(1) + " was written by the same settings")) << again.out;
        EXPECT_TRUE(content(2) == second) << "the missing frame, as the first run made it";
        for (int f = 1; f <= c.frames; ++f)
            if (f != 2) EXPECT_EQ(inode(frame(f)), before[size_t(f - 1)]) << "frame " << f << " left as it was";

        const Result other = run(base + " --skip-existing " + c.other);
        EXPECT_EQ(other.code, 1) << other.out;
        EXPECT_TRUE(has(other.out, "exists and was made otherwise")) << other.out;
        EXPECT_TRUE(has(other.out, c.changed)) << other.out;
        for (int f = 1; f <= c.frames; ++f)
            if (f != 2) EXPECT_EQ(inode(frame(f)), before[size_t(f - 1)]) << "nothing replaced: frame " << f;
    }

    // A frame follows the one before it: a run that begins later would continue from frames it did not make.
    const Result later =
        run("synth --flow vortex --frames 2-3 --factor 2 --skip-existing --out " + dir / "synth/s.####.vdb");
    EXPECT_EQ(later.code, 1) << later.out;
    EXPECT_TRUE(has(later.out, "shot_frames: 1,2 -> 2")) << later.out;
    // NanoVDB files record no settings.
    EXPECT_EQ(run("sim plume --res 16 --frames 2 --skip-existing --out " + dir / "n/s.####.nvdb").code, 2);
}

// stylize and animate take the frame locks transfer, resample, sim and synth take: with frame 2's lock held by
// another process (here the test itself, through the lock file's byte for frame 2), a run given frame 2 stops
// before writing anything, exit 75, naming the holder; a run given other frames of the shot goes on.
TEST(FarmNode, StylizeAndAnimateLockTheFramesTheyWrite)
{
    testutil::TempDir dir;
    const struct
    {
        std::string command, folder, name;
    } cases[] = {
        {"stylize --scene swirl --scene-size 32x32 --exemplar builtin:fire", "styl", "f.####.png"},
        {"animate --example builtin:river:48x32x20 --target builtin:river:48x32 --flow-strokes builtin:river", "anim",
            "a.####.png"},
    };
    for (const auto& c : cases) {
        SCOPED_TRACE(c.command);
        const fs::path folder(dir / c.folder);
        fs::create_directories(folder);
        const std::string lockPath = (folder / ("." + c.name + ".lock")).string();
        const int fd = ::open(lockPath.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        ASSERT_GE(fd, 0);
        struct flock l
        {};
        l.l_type = F_WRLCK;
        l.l_whence = SEEK_SET;
        l.l_start = off_t(2 + (int64_t(1) << 31)); // frame 2's byte (turbio's frame locks)
        l.l_len = 1;
        ASSERT_EQ(::fcntl(fd, F_SETLK, &l), 0);
        const std::string out = (folder / c.name).string();
        // animate writes frames 1-4 (20 example frames, tau 16); stylize is given frames 1-3.
        const Result held = run(c.command + (c.folder == "styl" ? " --frames 3" : "") + " --out " + out);
        EXPECT_EQ(held.code, 75) << held.out;
        EXPECT_TRUE(has(held.out, "is writing this frame")) << held.out;
        EXPECT_TRUE(has(held.out, "(pid " + std::to_string(::getpid()) + ")")) << held.out;
        EXPECT_FALSE(fs::exists(folder / (c.name.substr(0, 2) + "0001.png"))) << "nothing written";
        if (c.folder == "styl") {
            const Result other = run(c.command + " --frames 3-4 -q --out " + out);
            EXPECT_EQ(other.code, 0) << other.out;
            EXPECT_TRUE(fs::exists(folder / "f.0004.png"));
        }
        ::close(fd);
    }
}

// A tree of active tiles whose box spans 1290^3 (2.1e9) voxels, as pyopenvdb's fill writes one: info lists it and
// resample refuses it with the span and the memory it would need, in bounded memory (a 4 GB address-space limit).
// The smoke clustering compared every tile with every node: info took 272 s and resample 122 s before the refusal.
TEST(FarmNode, ATreeOfActiveTilesOverTwoBillionVoxelsIsListedAndRefusedClearly)
{
    openvdb::initialize();
    testutil::TempDir dir;
    {
        const openvdb::CoordBBox box(openvdb::Coord(0), openvdb::Coord(1289));
        auto density = turb::newGrid<openvdb::FloatGrid>(0.0f);
        density->setName("density");
        density->tree().fill(box, 0.5f, true);
        auto vel = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
        vel->setName("vel");
        vel->tree().fill(box, openvdb::Vec3s(0, 0, 1), true);
        ASSERT_EQ(density->activeVoxelCount(), openvdb::Index64(1290) * 1290 * 1290);
        openvdb::io::File(dir / "tiles.vdb").write({density, vel});
    }
    const std::string limit = "prlimit --as=4000000000 " + std::string(VDBTURB_EXE);
    const auto info = clitest::shell(limit + " info '" + dir / "tiles.vdb" + "' 2>&1");
    EXPECT_EQ(info.code, 0) << info.out;
    EXPECT_TRUE(has(info.out, "2146689000")) << "the active voxel count: " << info.out;
    const auto resample =
        clitest::shell(limit + " resample '" + dir / "tiles.vdb" + "' --down 2 --out '" + dir / "r.vdb" + "' 2>&1");
    EXPECT_EQ(resample.code, 1) << resample.out;
    EXPECT_TRUE(has(resample.out, "not enough memory to load the frame: its grids span [0, 0, 0]-[1289, 1289, 1289]"))
        << resample.out;
    EXPECT_FALSE(fs::exists(dir / "r.vdb"));
}
