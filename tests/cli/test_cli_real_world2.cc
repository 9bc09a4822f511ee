// The next round of real-world caches (issue 49, item 5): conditions found in renderers' and DCCs' issue threads and
// documentation (docs/reliability.md lists each with its source), each reproduced in a small file written with the C++
// API, and checked through the reader and the vdbturb executable against analytic values.
#include "CliUtil.h"

#include <turb/Metadata.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <turb/NewGrid.h>
#include <openvdb/points/PointConversion.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <filesystem>
#include <map>

namespace {

namespace fs = std::filesystem;
using clitest::has;
using clitest::Result;
using clitest::run;

const openvdb::CoordBBox kBox16({0, 0, 0}, {15, 15, 15});

openvdb::math::Transform::Ptr xform(double voxel) { return openvdb::math::Transform::createLinearTransform(voxel); }

openvdb::FloatGrid::Ptr fog(const std::string& name, float value, const openvdb::CoordBBox& box = kBox16,
    double voxel = 0.1, float background = 0.0f)
{
    auto g = turb::newGrid<openvdb::FloatGrid>(background);
    g->setName(name);
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setTransform(xform(voxel));
    g->denseFill(box, value, true); // voxels, not tiles (the tiles test makes its own)
    return g;
}

openvdb::Vec3SGrid::Ptr vec(const std::string& name, const openvdb::Vec3s& value,
    const openvdb::CoordBBox& box = kBox16, double voxel = 0.1, const openvdb::Vec3s& background = openvdb::Vec3s(0.0f))
{
    auto g = turb::newGrid<openvdb::Vec3SGrid>(background);
    g->setName(name);
    g->setTransform(xform(voxel));
    g->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    g->denseFill(box, value, true);
    return g;
}

void write(const std::string& path, const openvdb::GridPtrVec& grids,
    uint32_t compression = openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK)
{
    openvdb::initialize();
    openvdb::io::File f(path);
    f.setCompression(compression);
    f.write(grids);
    f.close();
}

// A plain smoke frame: density `d` and vel (1, 0, 0) over 16^3 voxels of 0.1.
void smokeFrame(const std::string& path, float d) { write(path, {fog("density", d), vec("vel", {1.0f, 0.0f, 0.0f})}); }

std::vector<int> jsonFrames(const Result& r)
{
    const auto j = nlohmann::json::parse(r.out, nullptr, false);
    return j.is_discarded() ? std::vector<int>{} : j.at("frames").get<std::vector<int>>();
}

turb::Frame read(
    const std::string& path, turbio::ReadReport* report = nullptr, turbio::ReadOptions options = turbio::ReadOptions{})
{
    return turbio::readFrame(path, 1, options, report);
}

} // namespace

// Houdini's $F4 (printf's %04d, Nuke, 3ds Max) names frame -2 "smoke.-002.vdb", the sign counted in the width.
// Before: "smoke.####.vdb" took only frames 0 and 1 without a word, and "smoke.-001.vdb" alone read as frame 1.
TEST(RealWorld2, NegativeFramesPaddedAsHoudiniWritesThemKeepTheirSign)
{
    testutil::TempDir dir;
    const std::map<int, std::string> names{{-2, "-002"}, {-1, "-001"}, {0, "0000"}, {1, "0001"}};
    for (const auto& [f, n] : names) smokeFrame(dir / ("smoke." + n + ".vdb"), 0.1f * float(f + 3));
    EXPECT_EQ(jsonFrames(run("info '" + dir / "smoke.####.vdb' --headers-only --json", false)),
        (std::vector<int>{-2, -1, 0, 1}));
    EXPECT_EQ(jsonFrames(run("info " + dir / "smoke.-001.vdb --headers-only --json", false)), std::vector<int>{-1});

    // Each frame reads its own file and is written under its own number, as Houdini names it.
    const Result rs = run("resample '" + dir / "smoke.####.vdb' --out '" + dir / "r.####.vdb' -q");
    ASSERT_EQ(rs.code, 0) << rs.out;
    for (const auto& [f, n] : names) {
        const turb::Frame out = read(dir / ("r." + n + ".vdb"));
        EXPECT_NEAR(out.density(4, 4, 4), 0.1f * float(f + 3), 1e-6) << n;
    }
    // vdbturb wrote frame -2 as "-0002" before: such a sequence reads too, from its own names.
    for (const std::string n : {"-0002", "-0001", "0000"}) smokeFrame(dir / ("old." + n + ".vdb"), 0.5f);
    EXPECT_EQ(
        jsonFrames(run("info '" + dir / "old.####.vdb' --headers-only --json", false)), (std::vector<int>{-2, -1, 0}));
    EXPECT_EQ(run("info '" + dir / "old.####.vdb' --all-values").code, 0);
}

// Houdini's $FF writes sub-frames as "pyro.1001.5.vdb" beside "pyro.1001.vdb". Before: that file alone read as frame
// 5 (resample wrote r.0005.vdb), and the pattern left the sub-frame files out without a word.
TEST(RealWorld2, ASubFrameFileIsNotReadAsAnotherWholeFrame)
{
    testutil::TempDir dir;
    smokeFrame(dir / "pyro.1001.vdb", 0.1f);
    smokeFrame(dir / "pyro.1001.5.vdb", 0.2f);
    smokeFrame(dir / "pyro.1002.vdb", 0.3f);
    const Result lone = run("resample " + dir / "pyro.1001.5.vdb --out '" + dir / "r.####.vdb'");
    EXPECT_EQ(lone.code, 1) << lone.out;
    EXPECT_TRUE(has(lone.out, "pyro.1001.5.vdb: sub-frame 1001.5 of a cache written at sub-frames")) << lone.out;
    EXPECT_TRUE(has(lone.out, "Give " + dir / "pyro.####.vdb")) << lone.out;
    EXPECT_FALSE(fs::exists(dir / "r.0005.vdb"));

    const Result seq = run("resample '" + dir / "pyro.####.vdb' --out '" + dir / "r.####.vdb'");
    ASSERT_EQ(seq.code, 0) << seq.out;
    EXPECT_EQ(clitest::count(seq.out, "leaves out 1 sub-frame file (pyro.1001.5.vdb"), 1u) << seq.out;
    EXPECT_NEAR(read(dir / "r.1002.vdb").density(4, 4, 4), 0.3f, 1e-6);
    EXPECT_FALSE(fs::exists(dir / "r.0005.vdb"));
}

// Houdini's unpadded $F names frames smoke.998.vdb ... smoke.1000.vdb. Before: "smoke.####.vdb" and the file
// smoke.1000.vdb alone took frames 1000 and 1001 as the whole sequence, skipping 998 and 999 without a word.
TEST(RealWorld2, UnpaddedFrameNumbersAcross1000AreNotSkippedSilently)
{
    testutil::TempDir dir;
    for (int f = 998; f <= 1001; ++f) smokeFrame(dir / ("smoke." + std::to_string(f) + ".vdb"), 0.5f);
    const Result padded = run("resample '" + dir / "smoke.####.vdb' --out '" + dir / "r.####.vdb'");
    ASSERT_EQ(padded.code, 0) << padded.out;
    EXPECT_EQ(clitest::count(padded.out, "does not take 2 files of this name numbered with another padding"), 1u)
        << padded.out;
    EXPECT_TRUE(has(padded.out, "frames 998,999): the cache is numbered without padding (Houdini's $F); give " +
                                    dir / "smoke.$F.vdb to read every frame"))
        << padded.out;
    EXPECT_EQ(jsonFrames(run("info '" + dir / "smoke.$F.vdb' --headers-only --json", false)),
        (std::vector<int>{998, 999, 1000, 1001}));
    const Result lone = run("info " + dir / "smoke.1000.vdb --headers-only");
    EXPECT_TRUE(has(lone.out, "smoke.1000.vdb is frame 1000 of " + dir / "smoke.@.vdb (frames 998-1001 on disk)"))
        << lone.out;
}

// A fog volume's background is 0 (OpenVDB's CheckFogVolume); Blender's Set Grid Background node and pyopenvdb write
// others. Background 0.2 means smoke everywhere: before, `resample` wrote the held box (smoke and margin) filled with
// density 0.2, a block of fog with a hard edge, and `info --validate` passed.
TEST(RealWorld2, ADensityWithANonZeroBackgroundIsRefusedNotWrittenAsABoxOfFog)
{
    testutil::TempDir dir;
    const openvdb::CoordBBox puff({8, 8, 8}, {11, 11, 11});
    write(dir / "bg.vdb", {fog("density", 0.5f, puff, 0.1, 0.2f),
                              vec("vel", {1.0f, 0.0f, 0.0f}, openvdb::CoordBBox({0, 0, 0}, {31, 31, 31}))});
    const Result rs = run("resample " + dir / "bg.vdb --out " + dir / "r.vdb");
    EXPECT_EQ(rs.code, 1) << rs.out;
    EXPECT_TRUE(has(rs.out, "bg.vdb: grid 'density' has background 0.2, not 0")) << rs.out;
    EXPECT_FALSE(fs::exists(dir / "r.vdb"));
    EXPECT_EQ(run("info " + dir / "bg.vdb --validate").code, 1);
    // Background 0: the inactive voxels read 0, the puff 0.5.
    write(dir / "ok.vdb",
        {fog("density", 0.5f, puff), vec("vel", {1.0f, 0.0f, 0.0f}, openvdb::CoordBBox({0, 0, 0}, {31, 31, 31}))});
    const turb::Frame f = read(dir / "ok.vdb");
    EXPECT_EQ(f.density(9, 9, 9), 0.5f);
    EXPECT_EQ(f.density(3, 3, 3), 0.0f);
}

// A velocity whose background is a wind (0, 0, 3): OpenVDB and renderers read every voxel it does not store as the
// wind. Before: a cell-centred `vel` read so without a word, and a staggered one read 0 there.
TEST(RealWorld2, AVelocityWithAWindBackgroundReadsTheWindInsideTheHeldBoxAndSaysSo)
{
    testutil::TempDir dir;
    const openvdb::Vec3s wind(0.0f, 0.0f, 3.0f);
    const openvdb::CoordBBox core({8, 8, 8}, {11, 11, 11}), all({0, 0, 0}, {23, 23, 23});
    for (int f = 1; f <= 2; ++f)
        write(dir / ("w.000" + std::to_string(f) + ".vdb"),
            {fog("density", 0.5f, all), vec("vel", {1.0f, 0.0f, 0.0f}, core, 0.1, wind)});
    turbio::ReadReport report;
    const turb::Frame f = read(dir / "w.0001.vdb", &report);
    EXPECT_EQ(f.velocity(9, 9, 9), turb::Vec3f(1.0f, 0.0f, 0.0f));
    EXPECT_EQ(f.velocity(20, 3, 17), turb::Vec3f(0.0f, 0.0f, 3.0f)) << "not stored: the background";
    ASSERT_EQ(report.notes.size(), 1u);
    EXPECT_TRUE(has(report.notes[0], "grid 'vel' has background [0, 0, 3], not zero")) << report.notes[0];

    auto mac = vec("vel", {1.0f, 0.0f, 0.0f}, core, 0.1, wind);
    mac->setGridClass(openvdb::GRID_STAGGERED);
    write(dir / "mac.vdb", {fog("density", 0.5f, all), mac});
    EXPECT_EQ(read(dir / "mac.vdb").velocity(20, 3, 17), turb::Vec3f(0.0f, 0.0f, 3.0f));

    const Result rs = run("resample '" + dir / "w.####.vdb' --out '" + dir / "r.####.vdb'");
    ASSERT_EQ(rs.code, 0) << rs.out;
    EXPECT_EQ(clitest::count(rs.out, "has background [0, 0, 3], not zero"), 1u) << "said once per input\n" << rs.out;
    EXPECT_EQ(read(dir / "r.0002.vdb").velocity(20, 3, 17), turb::Vec3f(0.0f, 0.0f, 3.0f));
}

// A level set named density (a surface written where the pipeline expects smoke; OpenVDB's CheckFogVolume rejects the
// level set class). Before: `info --validate` passed and `resample` wrote its signed distances, -0.3 to 0.3, as
// density.
TEST(RealWorld2, ALevelSetNamedDensityIsRefused)
{
    testutil::TempDir dir;
    openvdb::initialize();
    auto ls = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.8f, openvdb::Vec3f(0.0f), 0.1f);
    ls->setName("density");
    write(dir / "ls.vdb", {ls, vec("vel", {1.0f, 0.0f, 0.0f})});
    const Result rs = run("resample " + dir / "ls.vdb --out " + dir / "r.vdb");
    EXPECT_EQ(rs.code, 1) << rs.out;
    EXPECT_TRUE(has(rs.out, "ls.vdb: grid 'density' is a level set")) << rs.out;
    EXPECT_FALSE(fs::exists(dir / "r.vdb"));
    const Result validate = run("info " + dir / "ls.vdb --validate");
    EXPECT_EQ(validate.code, 1) << validate.out;
    EXPECT_TRUE(has(validate.out, "is a level set")) << validate.out;
}

// A NanoVDB file (GPU renderers' format) or a gzip'd VDB handed to a command that reads voxels. Before: "not an OpenVDB
// file (bad magic number)"; then "a NanoVDB file, not OpenVDB"; now NanoVDB is read (docs/nanovdb.md), whatever its
// name.
TEST(RealWorld2, ANanoVdbOrGzipFileGivenAsACacheSaysWhatItIs)
{
    testutil::TempDir dir;
    smokeFrame(dir / "s.vdb", 0.5f);
    turbio::writeFrame(dir / "s.nvdb", read(dir / "s.vdb"), turbio::WriteOptions{});
    fs::copy_file(dir / "s.nvdb", dir / "n.vdb");
    ASSERT_EQ(run("resample " + dir / "s.vdb -q --out " + dir / "r.vdb").code, 0);
    for (const char* name : {"s.nvdb", "n.vdb"}) {
        const Result nano = run("resample " + dir / name + " -q --out " + dir / "rn.vdb");
        EXPECT_EQ(nano.code, 0) << nano.out;
        EXPECT_TRUE(testutil::bitIdentical(read(dir / "rn.vdb").density, read(dir / "r.vdb").density)) << name;
    }
    EXPECT_EQ(run("info " + dir / "s.nvdb").code, 0) << "info reads NanoVDB headers";

    ASSERT_EQ(clitest::shell("gzip -c " + dir / "s.vdb > " + dir / "s.vdb.gz").code, 0);
    const Result gz = run("resample " + dir / "s.vdb.gz --out " + dir / "r.vdb");
    EXPECT_EQ(gz.code, 1) << gz.out;
    EXPECT_TRUE(has(gz.out, "s.vdb.gz: a gzip-compressed file, not an OpenVDB file: decompress it first")) << gz.out;
}

// Houdini writes a file with no grids where the geometry holds no volume (before the source starts). Before: "none of
// the requested grids is present ... Choose grids with --density-grid", and `info` printed an empty table.
TEST(RealWorld2, AFileWithNoGridsIsNamedAnEmptyFrame)
{
    testutil::TempDir dir;
    smokeFrame(dir / "e.0001.vdb", 0.5f);
    write(dir / "e.0002.vdb", {});
    smokeFrame(dir / "e.0003.vdb", 0.5f);
    const Result info = run("info '" + dir / "e.####.vdb' --all-values");
    EXPECT_TRUE(has(info.out, "no grids: an empty frame")) << info.out;
    const Result rs = run("resample '" + dir / "e.####.vdb' --out '" + dir / "r.####.vdb'");
    EXPECT_EQ(rs.code, 1) << rs.out;
    EXPECT_TRUE(has(rs.out, "e.0002.vdb: the file holds no grids: an empty frame")) << rs.out;
    EXPECT_FALSE(fs::exists(dir / "r.0001.vdb")) << "refused before the first frame";
    EXPECT_EQ(run("resample '" + dir / "e.####.vdb' --frames 1,3 --out '" + dir / "r.####.vdb' -q").code, 0);
}

// VDB points (Houdini's VDB from Particles, OpenVDB 4's PointDataGrid) handed over as a cache. Before: "none of the
// requested grids is present ... Choose grids with --density-grid".
TEST(RealWorld2, AVdbPointsFileIsNamedParticlesNotVolumes)
{
    testutil::TempDir dir;
    openvdb::initialize();
    const std::vector<openvdb::Vec3R> positions{{0, 0, 0}, {0.1, 0.2, 0.3}, {1, 1, 1}};
    const openvdb::points::PointAttributeVector<openvdb::Vec3R> wrapper(positions);
    auto transform = xform(0.1);
    auto index = openvdb::tools::createPointIndexGrid<openvdb::tools::PointIndexGrid>(wrapper, *transform);
    auto points = openvdb::points::createPointDataGrid<openvdb::points::NullCodec, openvdb::points::PointDataGrid>(
        *index, wrapper, *transform);
    points->setName("points");
    write(dir / "p.vdb", {points});
    for (const std::string cmd :
        {"info " + dir / "p.vdb --validate", "resample " + dir / "p.vdb --out " + dir / "r.vdb"}) {
        const Result r = run(cmd);
        EXPECT_EQ(r.code, 1) << r.out;
        EXPECT_TRUE(has(r.out, "p.vdb: its grids are VDB points (#0 'points' ptdataidx32")) << r.out;
        EXPECT_TRUE(has(r.out, "particles, not volumes")) << r.out;
    }
}

namespace {

// A frame as Blender 3.4's Mantaflow writes it (measured on an Adaptive Domain bake of a 4-unit cube at resolution
// 16): the simulation box `res` recorded as file_base_resolution, and the voxel the domain's size over the box's
// largest side, so an adaptive box smaller than the domain is written scaled up to the domain's size.
void blenderFrame(const std::string& path, const openvdb::Coord& res, double domainSize)
{
    const double voxel = domainSize / double(std::max({res.x(), res.y(), res.z()}));
    const openvdb::CoordBBox smoke({2, 2, 1}, {res.x() - 3, res.y() - 3, res.z() - 3});
    auto d = fog("density", 0.5f, smoke, voxel);
    auto v = vec("velocity", {0.0f, 0.0f, 1.0f}, smoke, voxel);
    v->setGridClass(openvdb::GRID_STAGGERED);
    for (const openvdb::GridBase::Ptr& g : {openvdb::GridBase::Ptr(d), openvdb::GridBase::Ptr(v)})
        g->insertMeta("file_base_resolution", openvdb::Vec3IMetadata(openvdb::Vec3i(res.x(), res.y(), res.z())));
    write(path, {v, d});
}

} // namespace

// Blender's Adaptive Domain (RadeonProRender's Blender add-on: "adaptive domain causes transformation issue"). A
// Blender 3.4 bake showed the same 112 smoke voxels of frame 1 at voxel 0.3636 (11x11x7 box) against 0.25 without
// it: 1.45x too large, and moving as the box grows. Before: `resample`, `measure` and `preview` read each frame on that
// lattice with a lattice-change warning only; `transfer` refused for the lattice change, not for the scale.
TEST(RealWorld2, BlenderAdaptiveDomainIsRefusedForItsWrongScale)
{
    testutil::TempDir dir;
    fs::create_directories(dir / "a");
    blenderFrame(dir / "a/fluid_data_0001.vdb", openvdb::Coord(11, 11, 7), 4.0);
    blenderFrame(dir / "a/fluid_data_0002.vdb", openvdb::Coord(13, 13, 8), 4.0);
    const Result rs = run("resample '" + dir / "a/fluid_data_####.vdb' --out '" + dir / "r/r.####.vdb'");
    EXPECT_EQ(rs.code, 1) << rs.out;
    EXPECT_TRUE(has(rs.out, "Blender's Adaptive Domain: the simulation box changes from 11x11x7 voxels of 0.363636 at "
                            "frame 1"))
        << rs.out;
    EXPECT_TRUE(has(rs.out, "Bake the cache without Adaptive Domain")) << rs.out;
    EXPECT_FALSE(fs::exists(dir / "r"));
    const Result info = run("info '" + dir / "a/fluid_data_####.vdb' --headers-only");
    EXPECT_EQ(info.code, 0) << info.out;
    EXPECT_TRUE(has(info.out, "WRONG SCALE: Blender's Adaptive Domain")) << info.out;

    // A re-bake of the same domain at another resolution is a lattice change, not a wrong scale: 16^3 of 0.25, then
    // 32^3 of 0.125.
    fs::create_directories(dir / "b");
    blenderFrame(dir / "b/fluid_data_0001.vdb", openvdb::Coord(16, 16, 16), 4.0);
    blenderFrame(dir / "b/fluid_data_0002.vdb", openvdb::Coord(32, 32, 32), 4.0);
    const Result rebake = run("resample '" + dir / "b/fluid_data_####.vdb' --out '" + dir / "r/r.####.vdb'");
    EXPECT_EQ(rebake.code, 0) << rebake.out;
    EXPECT_FALSE(has(rebake.out, "Blender's Adaptive Domain")) << rebake.out;
    EXPECT_TRUE(has(rebake.out, "the lattice is not the same in every frame")) << rebake.out;
}

// Sparse caches store constant regions as active tiles, not voxels (OpenVDB's topologyToLevelSet ignored them:
// openvdb#1397). Density 0.5 and velocity (0, 0, 1.5) over 64^3 voxels held as 8^3 tiles, in float and double
// precision, read and box-downsampled exactly.
TEST(RealWorld2, ActiveTilesReadAsTheirValues)
{
    testutil::TempDir dir;
    openvdb::initialize();
    const openvdb::CoordBBox box({0, 0, 0}, {63, 63, 63});
    auto d = turb::newGrid<openvdb::FloatGrid>(0.0f);
    d->setName("density");
    d->setGridClass(openvdb::GRID_FOG_VOLUME);
    d->setTransform(xform(0.1));
    d->fill(box, 0.5f, true);
    auto v = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    v->setName("vel");
    v->setTransform(xform(0.1));
    v->fill(box, openvdb::Vec3s(0.0f, 0.0f, 1.5f), true);
    auto vd = turb::newGrid<openvdb::Vec3DGrid>(openvdb::Vec3d(0.0));
    vd->setName("vel");
    vd->setTransform(xform(0.1));
    vd->fill(box, openvdb::Vec3d(0.0, 0.0, 1.5), true);
    ASSERT_EQ(d->tree().leafCount(), 0u) << "the condition: tiles only";
    ASSERT_GT(d->tree().activeTileCount(), 0u);
    write(dir / "t.vdb", {d, v});
    write(dir / "td.vdb", {d, vd});
    for (const std::string name : {"t.vdb", "td.vdb"}) {
        const turb::Frame f = read(dir / name);
        for (const turb::Coord c : {turb::Coord(0, 0, 0), turb::Coord(37, 5, 63), turb::Coord(63, 63, 63)}) {
            EXPECT_EQ(f.density(c.x(), c.y(), c.z()), 0.5f) << name << " " << c;
            EXPECT_EQ(f.velocity(c.x(), c.y(), c.z()), turb::Vec3f(0.0f, 0.0f, 1.5f)) << name << " " << c;
        }
        const Result rs = run("resample " + dir / name + " --down 2 --out " + dir / ("r" + name));
        ASSERT_EQ(rs.code, 0) << rs.out;
        const turb::Frame r = read(dir / ("r" + name));
        EXPECT_EQ(r.density(10, 20, 31), 0.5f) << name;
        EXPECT_EQ(r.velocity(10, 20, 31), turb::Vec3f(0.0f, 0.0f, 1.5f)) << name;
    }
}

// Grids of one frame on voxel sizes other than Houdini's velocity at twice the density's (the case tested since issue
// 11): a velocity finer than the density, a temperature coarser (Omniverse Flow sizes its density and velocity cells
// apart). Linear fields, so trilinear resampling onto the density's voxel centres is exact.
TEST(RealWorld2, GridsOnOtherVoxelSizesAreResampledOntoTheDensity)
{
    testutil::TempDir dir;
    openvdb::initialize();
    auto v = vec("vel", openvdb::Vec3s(0.0f), openvdb::CoordBBox({0, 0, 0}, {31, 31, 31}), 0.05);
    for (auto it = v->beginValueOn(); it; ++it)
        it.setValue(openvdb::Vec3s(float(it.getCoord().x()) * 0.05f, 0.0f, 0.0f));
    auto t = fog("temperature", 0.0f, openvdb::CoordBBox({0, 0, 0}, {7, 7, 7}), 0.2);
    for (auto it = t->beginValueOn(); it; ++it) it.setValue(float(it.getCoord().z()) * 0.2f);
    write(dir / "m.vdb", {fog("density", 0.5f), v, t});
    turbio::ReadReport report;
    const turb::Frame f = read(dir / "m.vdb", &report);
    ASSERT_TRUE(f.temperature);
    for (int i = 0; i <= 14; ++i) {
        EXPECT_NEAR(f.velocity(i, 7, 7)[0], 0.1 * i, 1e-5) << "u = x at voxel " << i;
        EXPECT_NEAR((*f.temperature)(7, 7, i), 0.1 * i, 1e-5) << "T = z at voxel " << i;
    }
    ASSERT_EQ(report.notes.size(), 2u);
    EXPECT_TRUE(has(report.notes[0], "grid 'vel' (voxel 0.05) resampled trilinearly")) << report.notes[0];
    EXPECT_TRUE(has(report.notes[1], "grid 'temperature' resampled trilinearly")) << report.notes[1];
}

// EmberGen writes its VDBs uncompressed, in 16-bit floats, grid class unknown (vdb_print of an EmberGen 0.5.5 file:
// file_compression none, is_saved_as_half_float); Houdini's Save 16-bit and zip compression likewise. Each reads the
// same values: density 0.25 and |vel| = |(0, 3, 4)| = 5, both exact in half precision.
TEST(RealWorld2, UncompressedZipAndHalfFloatCachesReadTheSameValues)
{
    testutil::TempDir dir;
    auto d = fog("density", 0.25f);
    d->setGridClass(openvdb::GRID_UNKNOWN);
    d->insertMeta("embergen_version", openvdb::StringMetadata("0.5.5.2"));
    auto v = vec("vel", {0.0f, 3.0f, 4.0f});
    for (const openvdb::GridBase::Ptr& g : {openvdb::GridBase::Ptr(d), openvdb::GridBase::Ptr(v)})
        g->setSaveFloatAsHalf(true);
    const std::map<std::string, uint32_t> files{{"none.vdb", openvdb::io::COMPRESS_NONE},
        {"zip.vdb", openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK},
        {"blosc.vdb", openvdb::io::COMPRESS_BLOSC}};
    for (const auto& [name, compression] : files) {
        write(dir / name, {d, v}, compression);
        const turb::Frame f = read(dir / name);
        EXPECT_EQ(f.density(3, 4, 5), 0.25f) << name;
        EXPECT_EQ(f.velocity(3, 4, 5), turb::Vec3f(0.0f, 3.0f, 4.0f)) << name;
    }
    const Result info = run("info " + dir / "none.vdb --validate");
    EXPECT_EQ(info.code, 0) << info.out;
    EXPECT_TRUE(has(info.out, "16-bit floats")) << info.out;
    EXPECT_TRUE(has(info.out, "[5, 5] |v|")) << info.out;
}

// Redshift (and Cinema 4D's pyro) take velocity as one vector grid or three float grids velocity.x/.y/.z. The
// components (1, 2, 2) form a velocity of magnitude 3, written back as one `vel` grid.
TEST(RealWorld2, RedshiftsVelocityXYZComponentsFormTheVelocity)
{
    testutil::TempDir dir;
    write(dir / "c.vdb",
        {fog("density", 0.5f), fog("velocity.x", 1.0f), fog("velocity.y", 2.0f), fog("velocity.z", 2.0f)});
    EXPECT_EQ(read(dir / "c.vdb").velocity(5, 5, 5), turb::Vec3f(1.0f, 2.0f, 2.0f));
    const Result rs = run("resample " + dir / "c.vdb --out " + dir / "r.vdb");
    ASSERT_EQ(rs.code, 0) << rs.out;
    const Result info = run("info " + dir / "r.vdb");
    EXPECT_TRUE(has(info.out, "[3, 3] |v|")) << info.out;
}

// Velocity in world units per frame: Blender's volume objects take "Velocity Unit: Frame", Katana's VelocityApply
// "units / frame", Arnold scales by velocity_fps. No file records it, so it is said with --vel-units frame. Before:
// there was no way to say it (--dt 1 left the time unit at a second), and 0.1 a frame was written as 0.1 a second.
TEST(RealWorld2, AVelocityPerFrameIsWrittenPerSecondWithVelUnitsFrame)
{
    testutil::TempDir dir;
    write(dir / "pf.vdb", {fog("density", 0.5f), vec("vel", {0.0f, 0.0f, 0.1f})});
    const Result rs = run("resample " + dir / "pf.vdb --vel-units frame --fps 25 --out " + dir / "r.vdb");
    ASSERT_EQ(rs.code, 0) << rs.out;
    const turb::Frame out = read(dir / "r.vdb");
    EXPECT_NEAR(out.velocity(5, 5, 5)[2], 2.5, 1e-5) << "0.1 a frame at 25 fps is 2.5 a second";
    EXPECT_NEAR(out.dt, 0.04, 1e-9);
    const Result info = run("info " + dir / "pf.vdb --vel-units frame --fps 25");
    EXPECT_TRUE(has(info.out, "time unit 0.04 s (a frame, 1/fps s (the velocity is per frame), fps given)"))
        << info.out;
    // Without the flag the file is read as every non-Blender cache is: world units per second.
    ASSERT_EQ(run("resample " + dir / "pf.vdb --out " + dir / "r2.vdb -q").code, 0);
    EXPECT_NEAR(read(dir / "r2.vdb").velocity(5, 5, 5)[2], 0.1, 1e-6);
}
