// Faults that lose nothing: Ctrl-C / SIGTERM mid-frame, kill -9 mid-write, a full disk and a file-size limit.
// Each run's files are compared with an uninterrupted run's.
#include "CliUtil.h"

#include <turbio/Vdb.h>

#include <cerrno>
#include <cstring>
#include <sys/mount.h>

namespace {

std::string lo() { return testutil::dataPath("blender-plume-32/fluid_data_####.vdb"); }
std::string hi() { return testutil::dataPath("blender-plume-128/fluid_data_####.vdb"); }

std::string transferArgs(const std::string& out, const std::string& frames = "1-2")
{
    return "transfer --target " + lo() + " --source " + hi() + " --out " + out + " --frames " + frames;
}

void expectSameFrame(const std::string& a, const std::string& b, int frame)
{
    const turb::Frame fa = turbio::readFrame(a, frame, turbio::ReadOptions{});
    const turb::Frame fb = turbio::readFrame(b, frame, turbio::ReadOptions{});
    EXPECT_EQ(fa.velocity.values(), fb.velocity.values()) << a << " vs " << b;
    EXPECT_EQ(fa.density.values(), fb.density.values()) << a << " vs " << b;
}

// Names in `dir` that start with '.' (temporary files of unfinished writes), less the frame lock file a killed run
// leaves (.PATTERN.lock: the next run takes it over).
size_t temporaries(const std::string& dir)
{
    size_t n = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
        const std::string name = e.path().filename().string();
        n += name[0] == '.' && !(name.size() > 5 && name.compare(name.size() - 5, 5, ".lock") == 0);
    }
    return n;
}

} // namespace

TEST(Faults, InterruptOrTerminateMidFrameLeavesWholeFramesAndResumesBitIdentically)
{
    testutil::TempDir dir;
    const auto ref = clitest::run(transferArgs(dir / "ref/o.####.vdb") + " -q");
    ASSERT_EQ(ref.code, 0) << ref.out;
    for (int sig : {SIGINT, SIGTERM}) {
        const std::string sub = sig == SIGINT ? "int" : "term";
        clitest::Process p(transferArgs(dir / (sub + "/o.####.vdb")), dir / (sub + ".log"));
        // The signal arrives while frame 2 is being made: frame 1 is on disk.
        ASSERT_TRUE(p.waitForFile(dir / (sub + "/o.0001.vdb"), 300)) << clitest::slurp(dir / (sub + ".log"));
        p.signal(sig);
        const int status = p.wait();
        ASSERT_TRUE(WIFEXITED(status)) << "signal death " << WTERMSIG(status);
        EXPECT_EQ(WEXITSTATUS(status), 130) << clitest::slurp(dir / (sub + ".log"));
        EXPECT_NE(clitest::slurp(dir / (sub + ".log")).find("interrupted"), std::string::npos);
        EXPECT_FALSE(std::filesystem::exists(dir / (sub + "/o.0002.vdb")));
        EXPECT_EQ(temporaries(dir / sub), 0u) << "no partial file";
        expectSameFrame(dir / (sub + "/o.0001.vdb"), dir / "ref/o.0001.vdb", 1);

        const auto resumed = clitest::run(transferArgs(dir / (sub + "/o.####.vdb")) + " --resume");
        ASSERT_EQ(resumed.code, 0) << resumed.out;
        EXPECT_NE(resumed.out.find("continuing after frame 1"), std::string::npos) << resumed.out;
        expectSameFrame(dir / (sub + "/o.0002.vdb"), dir / "ref/o.0002.vdb", 2);
    }
}

TEST(Faults, KillNineMidWriteLeavesNoPartialFileAndResumeContinues)
{
    testutil::TempDir dir;
    const auto ref = clitest::run(transferArgs(dir / "ref/o.####.vdb") + " -q");
    ASSERT_EQ(ref.code, 0) << ref.out;
    // SIGKILL arrives in the middle of frame 2's write (a test hook in the writer sends it after the first
    // part of the temporary file reached the disk). Each frame of this Blender target writes its exact resume state
    // first (its frames are per second, the target per 0.4 s): write 4 is frame 2's, after its state.
    clitest::Process p(transferArgs(dir / "k/o.####.vdb"), dir / "k.log", "VDBTURB_TEST_KILL_IN_WRITE=4");
    const int status = p.wait();
    ASSERT_TRUE(WIFSIGNALED(status)) << clitest::slurp(dir / "k.log");
    EXPECT_EQ(WTERMSIG(status), SIGKILL);
    EXPECT_FALSE(std::filesystem::exists(dir / "k/o.0002.vdb")) << "no partial file under the final name";
    EXPECT_EQ(temporaries(dir / "k"), 1u) << "the write was cut: its temporary file is there";
    expectSameFrame(dir / "k/o.0001.vdb", dir / "ref/o.0001.vdb", 1);

    const auto resumed = clitest::run(transferArgs(dir / "k/o.####.vdb") + " --resume");
    ASSERT_EQ(resumed.code, 0) << resumed.out;
    expectSameFrame(dir / "k/o.0002.vdb", dir / "ref/o.0002.vdb", 2);
    EXPECT_EQ(temporaries(dir / "k"), 0u) << "the dead run's temporary file is cleaned up";
}

namespace {

// The files a run left in `dir`, less the frame lock file (a killed run leaves it; the next run takes it over).
std::vector<std::string> filesBesideTheLock(const std::string& dir)
{
    std::vector<std::string> names = clitest::listing(dir);
    names.erase(std::remove(names.begin(), names.end(), ".o.####.vdb.lock"), names.end());
    return names;
}

// Every frame file in `dir` is the reference's, bit for bit (less the header's random UUID).
void expectFramesAsReference(const std::string& dir, const std::string& ref)
{
    for (const std::string& name : clitest::listing(dir))
        if (name.compare(0, 2, "o.") == 0 && name.find("resume-state") == std::string::npos)
            EXPECT_TRUE(clitest::sameVdbButUuid(dir + "/" + name, ref + "/" + name)) << dir << "/" << name;
}

} // namespace

// Issue 49, item 2: kill -9 at the points of a frame where a kill loses the most: in the middle of the seam solve,
// after the frame's resume state is in place but before the frame (a Blender target's frames are written per second,
// so the exact state goes beside them), and between two frames. A test hook (VDBTURB_TEST_KILL_AT=WHERE:FRAME,
// the CLI's) sends the SIGKILL at that point. Each time only whole frames are on disk, equal to an uninterrupted
// run's, and `--resume` continues exactly (no "cannot be used" warning): every frame bit-identical, the checksums
// of every grid equal (`info --checksum`), no temporary or lock file left.
TEST(Faults, KillNineInTheSeamSolveBetweenStateAndFrameOrBetweenFramesResumesBitIdentically)
{
    testutil::TempDir dir;
    ASSERT_EQ(clitest::run(transferArgs(dir / "ref/o.####.vdb") + " -q").code, 0);
    const std::string refSums = clitest::gridChecksums(dir / "ref/o.####.vdb");
    ASSERT_NE(refSums.find("frame 2"), std::string::npos) << refSums;
    const std::vector<std::string> all = {
        "o.0001.vdb", "o.0002.vdb", "o.resume-state-even.vdb", "o.resume-state-odd.vdb"};
    struct Case
    {
        const char* at;
        std::vector<std::string> left; // the files on disk after the kill
        int resumesAfter;
    };
    const Case cases[] = {
        {"seams:2", {"o.0001.vdb", "o.resume-state-odd.vdb"}, 1},
        {"after-state:2", {"o.0001.vdb", "o.resume-state-even.vdb", "o.resume-state-odd.vdb"}, 1},
        {"after-frame:1", {"o.0001.vdb", "o.resume-state-odd.vdb"}, 1},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.at);
        const std::string sub = std::string(c.at).substr(0, std::string(c.at).find(':'));
        const std::string out = dir / (sub + "/o.####.vdb");
        const std::string run = transferArgs(out);
        clitest::Process p(run, dir / (sub + ".log"), std::string("VDBTURB_TEST_KILL_AT=") + c.at);
        const int status = p.wait();
        ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << clitest::slurp(dir / (sub + ".log"));
        EXPECT_EQ(filesBesideTheLock(dir / sub), c.left) << "only whole frames and states, nothing partial";
        expectFramesAsReference(dir / sub, dir / "ref");

        const auto resumed = clitest::run(run + " --resume");
        ASSERT_EQ(resumed.code, 0) << resumed.out;
        EXPECT_NE(
            resumed.out.find("resume: continuing after frame " + std::to_string(c.resumesAfter)), std::string::npos)
            << resumed.out;
        EXPECT_EQ(resumed.out.find("cannot be used"), std::string::npos) << "the exact state: " << resumed.out;
        EXPECT_EQ(clitest::listing(dir / sub), all) << "no temporary file, no lock file left";
        expectFramesAsReference(dir / sub, dir / "ref");
        EXPECT_EQ(clitest::gridChecksums(out), refSums);
    }
}

// Frames that step by 2 are all odd: their resume states took one slot, so a frame's state overwrote the last whole
// frame's before its own write, and a kill between the two resumed approximately ("it holds frame 3, not 1"). The
// slots now take turns by the frames written.
TEST(Faults, KillNineBetweenStateAndFrameOfFramesSteppingByTwoResumesBitIdentically)
{
    testutil::TempDir dir;
    const auto args = [&](const std::string& sub) { return transferArgs(dir / (sub + "/o.####.vdb"), "1-3x2"); };
    ASSERT_EQ(clitest::run(args("ref") + " -q").code, 0);
    clitest::Process p(args("k"), dir / "k.log", "VDBTURB_TEST_KILL_AT=after-state:3");
    const int status = p.wait();
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << clitest::slurp(dir / "k.log");
    EXPECT_EQ(filesBesideTheLock(dir / "k"),
        (std::vector<std::string>{"o.0001.vdb", "o.resume-state-even.vdb", "o.resume-state-odd.vdb"}));
    const auto resumed = clitest::run(args("k") + " --resume");
    ASSERT_EQ(resumed.code, 0) << resumed.out;
    EXPECT_NE(resumed.out.find("resume: continuing after frame 1"), std::string::npos) << resumed.out;
    EXPECT_EQ(resumed.out.find("cannot be used"), std::string::npos) << "the exact state: " << resumed.out;
    expectFramesAsReference(dir / "k", dir / "ref");
    EXPECT_TRUE(clitest::sameVdbButUuid(dir / "k/o.0003.vdb", dir / "ref/o.0003.vdb"));
}

namespace {

// Frames 1-30 of the 32^3 plume through `resample` (fast; the files grow with the smoke).
std::string resampleArgs(const std::string& out)
{
    return "resample " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") + " --out " + out;
}

// After a write failure: exit 75 (worth a retry on another node), the message names the file and the reason, every
// earlier frame is whole and identical to the reference, the failed frame and later ones are absent, no temporary file
// is left.
void expectCleanWriteFailure(
    const clitest::Result& r, const std::string& dir, const std::string& ref, const std::string& reason)
{
    EXPECT_EQ(r.code, 75) << r.out;
    EXPECT_NE(r.out.find(reason), std::string::npos) << r.out;
    int firstMissing = 0;
    for (int f = 1; f <= 30 && !firstMissing; ++f) {
        char name[32];
        std::snprintf(name, sizeof(name), "/r.%04d.vdb", f);
        if (!std::filesystem::exists(dir + name)) firstMissing = f;
        else expectSameFrame(dir + name, ref + name, f);
    }
    ASSERT_GT(firstMissing, 1) << "frame 1 fits";
    char failed[32];
    std::snprintf(failed, sizeof(failed), "r.%04d.vdb: write failed", firstMissing);
    EXPECT_NE(r.out.find(failed), std::string::npos) << r.out;
    EXPECT_EQ(testutil::countEntries(dir), size_t(firstMissing - 1)) << "only whole earlier frames, nothing partial";
}

} // namespace

TEST(Faults, AFileSizeLimitStopsTheRunCleanly)
{
    testutil::TempDir dir;
    ASSERT_EQ(clitest::run(resampleArgs(dir / "ref/r.####.vdb") + " -q").code, 0);
    const auto small = std::filesystem::file_size(dir / "ref/r.0001.vdb");
    const auto large = std::filesystem::file_size(dir / "ref/r.0030.vdb");
    ASSERT_GT(large, 2 * small);
    // ulimit -f with SIGXFSZ ignored: the write that crosses the limit fails with EFBIG.
    const auto r =
        clitest::shell("prlimit --fsize=" + std::to_string((small + large) / 2) + " sh -c \"trap '' XFSZ; exec " +
                       VDBTURB_EXE + " " + resampleArgs(dir / "lim/r.####.vdb") + "\" 2>&1");
    expectCleanWriteFailure(r, dir / "lim", dir / "ref", "file size limit reached: ulimit -f allows");
}

TEST(Faults, AFullDiskStopsTheRunCleanly)
{
    testutil::TempDir dir;
    ASSERT_EQ(clitest::run(resampleArgs(dir / "ref/r.####.vdb") + " -q").code, 0);
    uintmax_t half = 0;
    for (int f = 1; f <= 15; ++f) {
        char name[32];
        std::snprintf(name, sizeof(name), "ref/r.%04d.vdb", f);
        half += std::filesystem::file_size(dir / name);
    }
    std::filesystem::create_directories(dir / "disk");
    const std::string opts = "size=" + std::to_string(half + 64 * 1024);
    if (::mount("tmpfs", (dir / "disk").c_str(), "tmpfs", 0, opts.c_str()) != 0)
        GTEST_SKIP() << "cannot mount a small tmpfs here (needs root): " << std::strerror(errno);
    // Unmounted before `dir` is removed, also when a check below returns early. A plain umount can fail with
    // EBUSY while a just-exited reader child still holds a file (seen once in CI-like runs); a lazy detach then
    // still lets the directory go.
    struct Unmount
    {
        std::string path;
        ~Unmount()
        {
            if (::umount(path.c_str()) != 0) ::umount2(path.c_str(), MNT_DETACH);
        }
    } unmount{dir / "disk"};
    const auto r = clitest::run(resampleArgs(dir / "disk/r.####.vdb"));
    expectCleanWriteFailure(r, dir / "disk", dir / "ref", "the disk is full");
}
