// Frame patterns, frame lists, auto-detection and directory scanning.
#include "TestUtil.h"

#include <turb/Error.h>
#include <turbio/Sequence.h>

#include <fstream>
#include <tuple>

using turbio::FramePattern;

TEST(FramePattern, HashRunSetsPaddingWidth)
{
    const auto p = FramePattern::parse("cache/pyro.####.vdb");
    EXPECT_TRUE(p.numbered());
    EXPECT_EQ(p.width(), 4);
    EXPECT_EQ(p.format(7), "cache/pyro.0007.vdb");
    EXPECT_EQ(p.format(1001), "cache/pyro.1001.vdb");
    EXPECT_EQ(p.format(12345), "cache/pyro.12345.vdb");
    // Negative frames pad as printf's %04d, Houdini's $F4 and Nuke do: the sign counts in the width (issue 49).
    EXPECT_EQ(p.format(-3), "cache/pyro.-003.vdb");
}

// Houdini's $F4 writes frame -1 as "-001" (printf's %04d; 3ds Max and Nuke count the sign in the width too). Before
// issue 49, "####" formatted it "-0001", so a sequence of frames -2..1 read as frames 0 and 1 without a word, and
// "smoke.-001.vdb" alone was frame 1 (the '-' taken for a separator).
TEST(FramePattern, NegativeFramesCountTheSignInTheWidthAndMatchEitherPadding)
{
    const auto p = FramePattern::parse("s.####.vdb");
    EXPECT_EQ(p.format(-1), "s.-001.vdb");
    EXPECT_EQ(p.format(-1234), "s.-1234.vdb");
    EXPECT_EQ(p.match("s.-001.vdb"), -1);
    EXPECT_EQ(p.match("s.-0001.vdb"), -1) << "vdbturb's own negative frames before issue 49";
    EXPECT_FALSE(p.match("s.-01.vdb"));
    auto old = p;
    old.setNegativeDigitsPadded(true);
    EXPECT_EQ(old.format(-1), "s.-0001.vdb");

    const auto d = FramePattern::fromFileName("cache/smoke.-001.vdb");
    ASSERT_TRUE(d);
    EXPECT_EQ(d->second, -1);
    EXPECT_EQ(d->first.format(5), "cache/smoke.0005.vdb");
    EXPECT_EQ(d->first.format(-2), "cache/smoke.-002.vdb");
    EXPECT_EQ(FramePattern::fromFileName("foo -020.png")->second, -20) << "3ds Max's negative frames";
    EXPECT_EQ(FramePattern::fromFileName("smoke_-7.vdb")->second, -7);
    // A '-' after a letter separates: Blender's own example sequence is smoke-000.vdb, smoke-001.vdb, ...
    EXPECT_EQ(FramePattern::fromFileName("smoke-001.vdb")->second, 1);
    // There is no frame -0: a '-' before zeros alone is text, so the name formats back to itself (fuzz_frame_pattern).
    const auto zero = FramePattern::fromFileName("x.-000.vdb");
    ASSERT_TRUE(zero);
    EXPECT_EQ(zero->second, 0);
    EXPECT_EQ(zero->first.format(zero->second), "x.-000.vdb");
    EXPECT_EQ(zero->first.format(7), "x.-007.vdb");
}

TEST(FramePattern, PrintfHoudiniAndAtTokens)
{
    EXPECT_EQ(FramePattern::parse("a_%04d.vdb").format(12), "a_0012.vdb");
    EXPECT_EQ(FramePattern::parse("a_%d.vdb").format(12), "a_12.vdb");
    EXPECT_EQ(FramePattern::parse("a.$F4.vdb").format(12), "a.0012.vdb");
    EXPECT_EQ(FramePattern::parse("a.$F.vdb").format(12), "a.12.vdb");
    EXPECT_EQ(FramePattern::parse("a.@.vdb").format(12), "a.12.vdb");
    EXPECT_EQ(FramePattern::parse("a.@@@.vdb").format(12), "a.012.vdb");
}

TEST(FramePattern, NoTokenIsASingleFileAndTwoTokensAreRejected)
{
    const auto p = FramePattern::parse("smoke.vdb");
    EXPECT_FALSE(p.numbered());
    EXPECT_EQ(p.format(5), "smoke.vdb");
    EXPECT_THROW(FramePattern::parse("a.####.$F4.vdb"), turb::ValueError);
}

TEST(FramePattern, MatchInvertsFormat)
{
    const auto p = FramePattern::parse("dir/f_####.vdb");
    EXPECT_EQ(p.match("dir/f_0042.vdb"), 42);
    EXPECT_EQ(p.match("dir/f_12345.vdb"), 12345);
    EXPECT_FALSE(p.match("dir/f_42.vdb")); // not padded as the pattern says
    EXPECT_FALSE(p.match("dir/g_0042.vdb"));
    EXPECT_FALSE(p.match("dir/f_00a2.vdb"));
}

TEST(FramePattern, DetectsFrameNumberFromRealNames)
{
    // (name, frame, the sequence's pattern); frame -1: the name holds no frame number.
    const std::vector<std::tuple<std::string, int, std::string>> cases = {
        {"/x/blender-c42/fluid_data_0001.vdb", 1, "/x/blender-c42/fluid_data_####.vdb"},
        {"pyro.1001.vdb", 1001, "pyro.####.vdb"},
        {"cache/pyro.0042.bgeo.sc", 42, "cache/pyro.####.bgeo.sc"},
        // Digits in the directory are not the frame number, nor digits inside the stem.
        {"/cache42/smoke.vdb", -1, ""},
        {"smoke2_final.vdb", -1, ""},
        // Version tokens are not frames; a frame after the version still is, and so is a 'v' inside a word.
        {"/x/houdini-vel/vel_VDB_bound_v02.vdb", -1, ""},
        {"smoke.v3.vdb", -1, ""},
        {"V12.vdb", -1, ""},
        {"shot_v02.1001.vdb", 1001, "shot_v02.####.vdb"},
        {"dev42.vdb", 42, "dev##.vdb"},
    };
    for (const auto& [name, frame, pattern] : cases) {
        const auto d = FramePattern::fromFileName(name);
        ASSERT_EQ(bool(d), frame >= 0) << name;
        if (!d) continue;
        EXPECT_EQ(d->second, frame) << name;
        EXPECT_EQ(d->first.str(), pattern) << name;
    }
    EXPECT_EQ(FramePattern::fromFileName("pyro.1001.vdb")->first.format(1002), "pyro.1002.vdb");
}

TEST(FrameList, RangesStepsAndSingles)
{
    EXPECT_EQ(turbio::parseFrameList("1001-1010x3,1200"), (std::vector<int>{1001, 1004, 1007, 1010, 1200}));
    EXPECT_EQ(turbio::parseFrameList("5"), (std::vector<int>{5}));
    EXPECT_EQ(turbio::parseFrameList("3-5, 4-6"), (std::vector<int>{3, 4, 5, 6}));
    EXPECT_EQ(turbio::parseFrameList("-2-1"), (std::vector<int>{-2, -1, 0, 1}));
    EXPECT_EQ(turbio::parseFrameList("1001-1100x2").size(), 50u);
}

TEST(FrameList, BadPiecesAreNamed)
{
    try {
        turbio::parseFrameList("1-10,abc");
        FAIL() << "expected ValueError";
    } catch (const turb::ValueError& e) {
        EXPECT_NE(std::string(e.what()).find("abc"), std::string::npos);
    }
    EXPECT_THROW(turbio::parseFrameList("10-1"), turb::ValueError);
    EXPECT_THROW(turbio::parseFrameList("1-10x0"), turb::ValueError);
    EXPECT_THROW(turbio::parseFrameList(""), turb::ValueError);
}

TEST(FrameList, FormatIsCompactAndRoundTrips)
{
    const std::vector<int> f{1, 2, 3, 4, 7, 10, 12, 14, 16};
    const std::string s = turbio::formatFrameList(f);
    EXPECT_EQ(s, "1-4,7,10-16x2");
    EXPECT_EQ(turbio::parseFrameList(s), f);
}

TEST(Sequence, ScanFindsFramesAndReportsMissingOnes)
{
    testutil::TempDir dir;
    for (int f : {1001, 1002, 1004, 1005}) std::ofstream(dir / ("pyro." + std::to_string(f) + ".vdb")) << "x";
    std::ofstream(dir / "pyro.notes.txt") << "x";
    const auto seq = turbio::resolveSequence(dir / "pyro.####.vdb");
    EXPECT_EQ(seq.frames, (std::vector<int>{1001, 1002, 1004, 1005}));
    EXPECT_EQ(seq.missing, (std::vector<int>{1003}));

    // One real file name means that file (as oiiotool, vdb_print and Houdini's File SOP read it); the siblings on
    // disk are only mentioned, with the pattern that takes them all. With --frames it names its sequence.
    const auto fromFile = turbio::resolveSequence(dir / "pyro.1002.vdb");
    EXPECT_EQ(fromFile.frames, (std::vector<int>{1002}));
    EXPECT_EQ(fromFile.path(1002), dir / "pyro.1002.vdb");
    EXPECT_NE(fromFile.oneOfSequence.find("is frame 1002 of"), std::string::npos) << fromFile.oneOfSequence;
    EXPECT_NE(fromFile.oneOfSequence.find("pyro.####.vdb (frames 1001,1002,1004,1005 on disk)"), std::string::npos)
        << fromFile.oneOfSequence;
    EXPECT_EQ(turbio::resolveSequence(dir / "pyro.1002.vdb", "1001-1002").frames, (std::vector<int>{1001, 1002}));

    // An explicit list reports the frames it names that are absent.
    const auto listed = turbio::resolveSequence(dir / "pyro.$F4.vdb", "1001-1007x2");
    EXPECT_EQ(listed.frames, (std::vector<int>{1001, 1005}));
    EXPECT_EQ(listed.missing, (std::vector<int>{1003, 1007}));
}

TEST(Sequence, EveryNthFrameCacheIsNotMissingFrames)
{
    testutil::TempDir dir;
    for (int f : {10, 12, 14, 18}) std::ofstream(dir / ("s_" + std::to_string(f) + ".vdb")) << "x";
    const auto seq = turbio::resolveSequence(dir / "s_%d.vdb");
    EXPECT_EQ(seq.missing, (std::vector<int>{16}));
}

TEST(Sequence, NothingOnDiskIsAnIoError)
{
    testutil::TempDir dir;
    EXPECT_THROW(turbio::resolveSequence(dir / "none.####.vdb"), turb::IoError);
    EXPECT_THROW(turbio::resolveSequence(dir / "none.vdb"), turb::IoError);
}

TEST(FramePattern, BracedHoudiniTokenAndMessagesInTheUsersOwnForm)
{
    EXPECT_EQ(FramePattern::parse("a.${F4}.vdb").format(12), "a.0012.vdb");
    EXPECT_EQ(FramePattern::parse("a.${F}.vdb").format(12), "a.12.vdb");
    EXPECT_FALSE(FramePattern::parse("a.${X}.vdb").numbered());
    EXPECT_EQ(FramePattern::parse("a.$F.vdb").str(), "a.$F.vdb") << "never the internal '@' form";
    testutil::TempDir dir;
    try {
        turbio::resolveSequence(dir / "none.$F.vdb");
        FAIL();
    } catch (const turb::IoError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("none.$F.vdb"), std::string::npos) << m;
        EXPECT_EQ(m.find('@'), std::string::npos) << m;
    }
}

TEST(Sequence, ALoneNumberedFileKeepsItsFrameNumber)
{
    testutil::TempDir dir;
    std::ofstream(dir / "pyro.1001.vdb") << "x";
    const auto seq = turbio::resolveSequence(dir / "pyro.1001.vdb");
    ASSERT_EQ(seq.frames, (std::vector<int>{1001}));
    EXPECT_EQ(seq.path(1001), dir / "pyro.1001.vdb");
    EXPECT_TRUE(seq.missing.empty());
    EXPECT_TRUE(seq.oneOfSequence.empty()) << "alone on disk: nothing to mention";
    // A file without a frame number stays frame 0.
    std::ofstream(dir / "smoke.vdb") << "x";
    EXPECT_EQ(turbio::resolveSequence(dir / "smoke.vdb").frames, (std::vector<int>{0}));
}

TEST(Sequence, NoMatchSaysWhichPaddingsExist)
{
    testutil::TempDir dir;
    for (int f = 1; f <= 3; ++f) std::ofstream(dir / ("fluid_data_000" + std::to_string(f) + ".vdb")) << "x";
    try {
        turbio::resolveSequence(dir / "fluid_data_###.vdb");
        FAIL();
    } catch (const turb::IoError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("fluid_data_####.vdb (3 files, 4-digit"), std::string::npos) << m;
        EXPECT_NE(m.find("$F4"), std::string::npos) << m;
    }
    // A directory given as the cache names the sequences it holds.
    try {
        turbio::resolveSequence(dir.path());
        FAIL();
    } catch (const turb::IoError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("is a directory"), std::string::npos) << m;
        EXPECT_NE(m.find("fluid_data_####.vdb (3 files)"), std::string::npos) << m;
        EXPECT_EQ(m.find("no such file"), std::string::npos) << m;
    }
    // Another name in the same directory: the sequences that are there.
    try {
        turbio::resolveSequence(dir / "density_####.vdb");
        FAIL();
    } catch (const turb::IoError& e) {
        EXPECT_NE(std::string(e.what()).find("holds " + dir.path() + "/fluid_data_####.vdb"), std::string::npos)
            << e.what();
    }
}
