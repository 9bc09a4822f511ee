// NanoVDB output (docs/nanovdb.md): frames and converted caches read back with NanoVDB's own reader and checked voxel
// by voxel against the VDB of the same frame; the header reader on damaged files; the CLI's convert, info, transfer
// and resample on .nvdb.
#include "CliUtil.h"
#include "TestUtil.h"

#include <turb/Error.h>
#include <turbio/NanoVdb.h>
#include <turbio/Vdb.h>

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <nanovdb/NanoVDB.h>
#include <nanovdb/util/GridValidator.h>
#include <nanovdb/util/IO.h>

#include <cfloat>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace fs = std::filesystem;
using clitest::has;
using clitest::run;

namespace {

openvdb::GridBase::Ptr readVdbGrid(const std::string& path, const std::string& name)
{
    openvdb::initialize();
    openvdb::io::File f(path);
    f.open();
    openvdb::GridBase::Ptr g = f.readGrid(name);
    f.close();
    return g;
}

// The bits of a quantisation, 0 for float.
int bitsOf(turbio::NanoQuantization q)
{
    return q == turbio::NanoQuantization::Fp16 ? 16 : q == turbio::NanoQuantization::Fp8 ? 8 : 0;
}

struct Compared
{
    uint64_t voxels = 0;
    double maxError = 0.0;    ///< largest |nano - vdb|
    double worstShare = 0.0;  ///< largest error / its leaf's bound
    double largestStep = 0.0; ///< largest quantisation step of a leaf
};

// Every active voxel of the VDB float grid against the NanoVDB grid of the same name: float exactly; fp16/fp8 within
// half a step of its leaf, where the step is (leaf max - leaf min) / (2^bits - 1) over the leaf's 512 values (what
// NanoVDB's converter quantises over), plus float rounding. The step stored in the file is checked against it too.
template<typename NanoBuildT>
Compared compareFloat(const openvdb::FloatGrid& vdb, const nanovdb::NanoGrid<NanoBuildT>& nano, int bits)
{
    Compared c;
    auto acc = nano.getAccessor();
    for (auto leaf = vdb.tree().cbeginLeaf(); leaf; ++leaf) {
        float lo = FLT_MAX, hi = -FLT_MAX;
        for (openvdb::Index i = 0; i < openvdb::FloatTree::LeafNodeType::SIZE; ++i) {
            lo = std::min(lo, leaf->getValue(i));
            hi = std::max(hi, leaf->getValue(i));
        }
        const double step = bits ? double(hi - lo) / double((1 << bits) - 1) : 0.0;
        const double bound = 0.5 * step + 4.0 * FLT_EPSILON * std::max(std::abs(lo), std::abs(hi));
        const openvdb::Coord o = leaf->origin();
        if constexpr (!std::is_same_v<NanoBuildT, float>) {
            const auto* nl = nano.tree().root().probeLeaf(nanovdb::Coord(o.x(), o.y(), o.z()));
            EXPECT_NE(nl, nullptr);
            if (nl) EXPECT_LE(double(nl->data()->mQuantum), step * (1.0 + 1e-5) + 1e-12) << "leaf at " << o;
        }
        c.largestStep = std::max(c.largestStep, step);
        for (auto it = leaf->cbeginValueOn(); it; ++it) {
            const openvdb::Coord ijk = it.getCoord();
            const nanovdb::Coord n(ijk.x(), ijk.y(), ijk.z());
            EXPECT_TRUE(acc.isActive(n)) << ijk;
            const double err = std::abs(double(acc.getValue(n)) - double(*it));
            c.maxError = std::max(c.maxError, err);
            if (bits == 0) {
                EXPECT_EQ(acc.getValue(n), *it) << ijk;
            } else {
                EXPECT_LE(err, bound) << ijk << ": " << *it << " read back as " << acc.getValue(n);
                c.worstShare = std::max(c.worstShare, bound > 0 ? err / bound : 0.0);
            }
            ++c.voxels;
        }
    }
    return c;
}

// The transform: the voxel size and where index points land in the world, to double rounding.
void expectSameTransform(const openvdb::GridBase& vdb, const nanovdb::GridMetaData& nano, const nanovdb::Map& map)
{
    const openvdb::Vec3d vs = vdb.voxelSize();
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(nano.voxelSize()[a], vs[a], 1e-12 * vs[a]);
    for (const openvdb::Vec3d ijk : {openvdb::Vec3d(0.0), openvdb::Vec3d(7, -3, 120), openvdb::Vec3d(-1.5, 2.25, 9)}) {
        const openvdb::Vec3d w = vdb.transform().indexToWorld(ijk);
        const nanovdb::Vec3d wn = map.applyMap(nanovdb::Vec3d(ijk.x(), ijk.y(), ijk.z()));
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(wn[a], w[a], 1e-9);
    }
}

long long sizeOf(const std::string& path) { return (long long)fs::file_size(path); }

const char* const kPlume2Hi = "blender-plume2-128/fluid_data_0020.vdb";

} // namespace

// A real cache frame (Blender's 128^3 plume2, frame 20) written as VDB in 32-bit floats and as NanoVDB in float, Fp16
// and Fp8: NanoVDB's own reader gives every active voxel of density and temperature back exactly (float) or within
// half a quantisation step of its leaf (Fp16, Fp8), the empty flame grid empty, vel exactly (Vec3f), with the VDB's
// active voxel counts, grid class, voxel size and transform, and NanoVDB's validator (full checksum) passes every grid.
TEST(NanoVdb, ARealFrameReadsBackWithNanoVdbsReaderWithinItsQuantisation)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const turb::Frame frame = turbio::readFrame(testutil::dataPath(kPlume2Hi), 20, turbio::ReadOptions{});
    turbio::WriteOptions vdbOpt;
    vdbOpt.format = turbio::OutputFormat::Vdb;
    const std::string vdbPath = dir / "frame.vdb";
    turbio::writeFrame(vdbPath, frame, vdbOpt);
    vdbOpt.halfFloat = true;
    turbio::writeFrame(dir / "half.vdb", frame, vdbOpt);
    std::cout << "plume2-128 frame 20: VDB float " << sizeOf(vdbPath) << " bytes, VDB half "
              << sizeOf(dir / "half.vdb");

    for (const auto q :
        {turbio::NanoQuantization::Float, turbio::NanoQuantization::Fp16, turbio::NanoQuantization::Fp8}) {
        SCOPED_TRACE(turbio::quantizationName(q));
        turbio::WriteOptions w;
        w.nanoQuantization = q;
        const std::string path = dir / (std::string("frame.") + turbio::quantizationName(q) + ".nvdb");
        turbio::writeFrame(path, frame, w); // NanoVDB by the name's extension
        std::cout << ", NanoVDB " << turbio::quantizationName(q) << " " << sizeOf(path);
        EXPECT_EQ(turbio::quantizationName(q), std::string(turbio::quantizationName(q)));

        const auto metas = nanovdb::io::readGridMetaData(path);
        ASSERT_EQ(metas.size(), 4u); // density, vel, temperature, flame (empty in this cache)
        for (const char* name : {"density", "temperature", "flame"}) {
            SCOPED_TRACE(name);
            const auto vdb = openvdb::GridBase::grid<openvdb::FloatGrid>(readVdbGrid(vdbPath, name));
            ASSERT_TRUE(vdb);
            nanovdb::GridHandle<> h = nanovdb::io::readGrid(path, std::string(name));
            ASSERT_TRUE(h) << name << " missing";
            const nanovdb::GridMetaData& m = *h.gridMetaData();
            EXPECT_EQ(m.gridClass(), nanovdb::GridClass::FogVolume);
            EXPECT_EQ(m.activeVoxelCount(), vdb->activeVoxelCount());
            Compared c;
            if (q == turbio::NanoQuantization::Float) {
                ASSERT_TRUE(h.grid<float>());
                EXPECT_TRUE(nanovdb::isValid(*h.grid<float>(), true, true));
                expectSameTransform(*vdb, m, h.grid<float>()->map());
                c = compareFloat(*vdb, *h.grid<float>(), 0);
            } else if (q == turbio::NanoQuantization::Fp16) {
                ASSERT_TRUE(h.grid<nanovdb::Fp16>());
                EXPECT_TRUE(nanovdb::isValid(*h.grid<nanovdb::Fp16>(), true, true));
                expectSameTransform(*vdb, m, h.grid<nanovdb::Fp16>()->map());
                c = compareFloat(*vdb, *h.grid<nanovdb::Fp16>(), 16);
            } else {
                ASSERT_TRUE(h.grid<nanovdb::Fp8>());
                EXPECT_TRUE(nanovdb::isValid(*h.grid<nanovdb::Fp8>(), true, true));
                expectSameTransform(*vdb, m, h.grid<nanovdb::Fp8>()->map());
                c = compareFloat(*vdb, *h.grid<nanovdb::Fp8>(), 8);
            }
            EXPECT_EQ(c.voxels, vdb->activeVoxelCount());
            std::cout << " [" << name << ": " << c.voxels << " voxels, max error " << c.maxError << ", largest step "
                      << c.largestStep << ", worst error/bound " << c.worstShare << "]";
        }
        // vel: Vec3f whatever the quantisation, every component exact.
        const auto vdbVel = openvdb::GridBase::grid<openvdb::Vec3SGrid>(readVdbGrid(vdbPath, "vel"));
        ASSERT_TRUE(vdbVel);
        nanovdb::GridHandle<> hv = nanovdb::io::readGrid(path, std::string("vel"));
        const auto* vel = hv.grid<nanovdb::Vec3f>();
        ASSERT_TRUE(vel);
        EXPECT_TRUE(nanovdb::isValid(*vel, true, true));
        EXPECT_EQ(vel->activeVoxelCount(), vdbVel->activeVoxelCount());
        expectSameTransform(*vdbVel, *hv.gridMetaData(), vel->map());
        auto acc = vel->getAccessor();
        uint64_t mismatched = 0;
        for (auto it = vdbVel->cbeginValueOn(); it; ++it) {
            const openvdb::Coord ijk = it.getCoord();
            const nanovdb::Vec3f v = acc.getValue(nanovdb::Coord(ijk.x(), ijk.y(), ijk.z()));
            mismatched += !(v[0] == (*it)[0] && v[1] == (*it)[1] && v[2] == (*it)[2]);
        }
        EXPECT_EQ(mismatched, 0u);
    }
    std::cout << std::endl;
}

// convert writes every grid of a Blender cache as it is stored: names, classes, values (int32 flags exactly), level
// sets left in float when 8 bits are asked, with nothing left out.
TEST(NanoVdb, ConvertKeepsEveryGridOfABlenderCache)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const std::string in = testutil::dataPath("blender-c42/fluid_data_0005.vdb");
    turbio::NanoConvertOptions opt;
    opt.quantization = turbio::NanoQuantization::Fp8;
    const turbio::NanoConvertReport r = turbio::convertToNanoVdb(in, dir / "c42.nvdb", opt);
    EXPECT_EQ(r.grids.size(), 24u);
    EXPECT_TRUE(r.skipped.empty());
    EXPECT_EQ(r.bytes, sizeOf(dir / "c42.nvdb"));
    const turbio::NanoFileInfo info = turbio::inspectNanoFile(dir / "c42.nvdb");
    ASSERT_EQ(info.grids.size(), 24u);
    for (const auto& g : info.grids) {
        if (g.name.rfind("phi_", 0) == 0) {
            EXPECT_EQ(g.valueType, "float") << g.name;
            EXPECT_EQ(g.gridClass, "level set") << g.name;
        }
        if (g.name == "density") EXPECT_EQ(g.valueType, "fp8");
        if (g.name == "velocity") {
            EXPECT_EQ(g.valueType, "vec3f");
            EXPECT_EQ(g.gridClass, "staggered");
        }
    }
    const auto flags = openvdb::GridBase::grid<openvdb::Int32Grid>(readVdbGrid(in, "flags"));
    ASSERT_TRUE(flags);
    nanovdb::GridHandle<> h = nanovdb::io::readGrid(dir / "c42.nvdb", std::string("flags"));
    const auto* nf = h.grid<int32_t>();
    ASSERT_TRUE(nf);
    EXPECT_EQ(nf->activeVoxelCount(), flags->activeVoxelCount());
    auto acc = nf->getAccessor();
    uint64_t differ = 0;
    for (auto it = flags->cbeginValueOn(); it; ++it)
        differ += acc.getValue(nanovdb::Coord(it.getCoord().x(), it.getCoord().y(), it.getCoord().z())) != *it;
    EXPECT_EQ(differ, 0u);
}

// info's header reader: what the file says, and a clear error, never a crash, for damaged files.
TEST(NanoVdb, HeadersAreReadAndDamagedFilesAreRefused)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const turb::Frame frame = turbio::readFrame(testutil::dataPath(kPlume2Hi), 20, turbio::ReadOptions{});
    turbio::WriteOptions w;
    w.nanoQuantization = turbio::NanoQuantization::Fp16;
    const std::string path = dir / "f.nvdb";
    turbio::writeFrame(path, frame, w);
    const turbio::NanoFileInfo info = turbio::inspectNanoFile(path);
    EXPECT_EQ(info.fileBytes, sizeOf(path));
    ASSERT_EQ(info.grids.size(), 4u);
    const turbio::NanoGridInfo& d = info.grids[0];
    EXPECT_EQ(d.name, "density");
    EXPECT_EQ(d.valueType, "fp16");
    EXPECT_EQ(d.gridClass, "fog volume");
    EXPECT_EQ(d.codec, "none");
    EXPECT_TRUE(d.hasTransform);
    EXPECT_DOUBLE_EQ(d.voxelSize.x(), frame.lattice().voxelSize);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(d.origin[a], frame.lattice().origin[a], 1e-12);
    long long smoke = 0;
    for (float v : frame.density.values()) smoke += v != 0.0f;
    EXPECT_EQ(d.activeVoxels, smoke);
    EXPECT_EQ(info.grids[1].name, "vel");
    EXPECT_EQ(info.grids[1].valueType, "vec3f");

    const std::string bytes = clitest::slurp(path);
    const auto damaged = [&](const std::string& name, const std::string& content, const std::string& expected) {
        const std::string p = dir / name;
        std::ofstream(p, std::ios::binary) << content;
        try {
            turbio::inspectNanoFile(p);
            ADD_FAILURE() << name << ": no error";
        } catch (const turb::IoError& e) {
            EXPECT_TRUE(has(e.what(), p)) << e.what();
            EXPECT_TRUE(has(e.what(), expected)) << e.what();
        }
    };
    damaged("cut.nvdb", bytes.substr(0, bytes.size() / 2), "truncated");
    damaged("header.nvdb", bytes.substr(0, 100), "truncated");
    damaged("text.nvdb", "not a volume at all", "not a NanoVDB file");
    damaged("empty.nvdb", "", "empty file");
    std::string name = bytes;
    name[16 + 136 + 3] = char(0x7f); // the first grid's name length (MetaData's bytes 136-139): 2 GB
    damaged("name.nvdb", name, "damaged");
    // Every byte of the segment and grid headers, and of the first grid's own header, flipped in turn: each copy
    // reads or is refused with an IoError, never a crash or a hang.
    const size_t headers = 16 + 4 * 176 + 64 + 672;
    int refused = 0;
    std::ofstream(dir / "flip.nvdb", std::ios::binary) << bytes;
    for (size_t i = 0; i < std::min(headers, bytes.size()); ++i) {
        const auto put = [&](char c) { // in place: the 3 MB file is not rewritten for each byte
            std::fstream f(dir / "flip.nvdb", std::ios::binary | std::ios::in | std::ios::out);
            f.seekp(std::streamoff(i));
            f.put(c);
        };
        put(char(bytes[i] ^ 0xa5));
        try {
            turbio::inspectNanoFile(dir / "flip.nvdb");
        } catch (const turb::IoError&) {
            ++refused;
        }
        put(bytes[i]);
    }
    EXPECT_GT(refused, 0);
    try {
        turbio::inspectNanoFile(dir / "missing.nvdb");
        ADD_FAILURE() << "a missing file read";
    } catch (const turb::IoError& e) {
        EXPECT_TRUE(has(e.what(), "cannot open")) << e.what();
    }
}

// The Blender style's placement lives in metadata NanoVDB cannot hold: refused before anything is written. A write
// refused by noClobber leaves the file there as it was.
TEST(NanoVdb, TheBlenderStyleAndClobberingAreRefused)
{
    testutil::TempDir dir;
    const turb::CoordBBox box(turb::Coord(0), turb::Coord(9));
    const turb::Frame f = testutil::makeFrame(
        1, box, turb::Lattice{0.1, turb::Vec3d(0.0)}, [](const turb::Vec3d& p) { return turb::Vec3f(p.x(), 1, 0); },
        [](const turb::Coord& c) { return float(c.x()) * 0.1f; });
    turbio::WriteOptions w;
    w.style = turbio::WriteStyle::Blender;
    EXPECT_THROW(turbio::writeFrame(dir / "b.nvdb", f, w), turb::ValueError);
    EXPECT_FALSE(fs::exists(dir / "b.nvdb"));
    w.style = turbio::WriteStyle::Houdini;
    turbio::writeFrame(dir / "a.nvdb", f, w);
    const std::string before = clitest::slurp(dir / "a.nvdb");
    w.noClobber = true;
    w.nanoQuantization = turbio::NanoQuantization::Fp8;
    EXPECT_THROW(turbio::writeFrame(dir / "a.nvdb", f, w), turb::IoError);
    EXPECT_EQ(clitest::slurp(dir / "a.nvdb"), before);
    EXPECT_EQ(testutil::countEntries(dir.path()), 1u); // no temporary file left
    // --format nanovdb writes NanoVDB whatever the name.
    w.noClobber = false;
    w.format = turbio::OutputFormat::NanoVdb;
    turbio::writeFrame(dir / "c.bin", f, w);
    EXPECT_EQ(turbio::inspectNanoFile(dir / "c.bin").grids.at(0).valueType, "fp8");
}

// NanoVDB's own tools read what vdbturb writes (Debian libnanovdb-tools).
TEST(NanoVdbCli, NanovdbPrintAndValidateReadTheFiles)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    // tools/setup-debian12.sh installs them with the rest.
    ASSERT_EQ(clitest::shell("command -v nanovdb_print && command -v nanovdb_validate").code, 0)
        << "nanovdb_print / nanovdb_validate not installed (Debian libnanovdb-tools)";
    testutil::TempDir dir;
    for (const char* q : {"float", "fp16", "fp8"}) {
        const std::string out = dir / (std::string("c.") + q + ".####.nvdb");
        const auto r = run("convert " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") +
                           " --frames 20 -q --nanovdb-quant " + q + " --out " + out);
        ASSERT_EQ(r.code, 0) << r.out;
        const std::string file = dir / (std::string("c.") + q + ".0020.nvdb");
        const auto print = clitest::shell("nanovdb_print " + file + " 2>&1");
        EXPECT_EQ(print.code, 0) << print.out;
        for (const char* grid : {"density", "velocity", "temperature", "shadow", "flame"})
            EXPECT_TRUE(has(print.out, grid)) << print.out;
        EXPECT_TRUE(has(print.out, std::string(q) == "float"  ? "float"
                                   : std::string(q) == "fp16" ? "Float16"
                                                              : "Float8"))
            << print.out;
        const auto validate = clitest::shell("nanovdb_validate -v " + file + " 2>&1");
        EXPECT_EQ(validate.code, 0) << validate.out;
        EXPECT_EQ(clitest::count(validate.out, "passed"), 5u) << validate.out;
    }
}

// convert end to end: frames, --json on stdout, info on the result; bad input fails before anything is written,
// naming the file, and a frame that fails mid-run leaves the frames before it whole and no partial file.
TEST(NanoVdbCli, ConvertWritesFramesAndRefusesBadInputWithoutPartialOutput)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const std::string cache = testutil::dataPath("blender-plume2-32/fluid_data_####.vdb");
    auto r = clitest::runStdout(
        "convert " + cache + " --frames 1-5x2 --nanovdb-quant fp16 --json --out " + (dir / "ok/p.####.nvdb"));
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(clitest::count(r.out, "\"frame\":"), 3u) << r.out;
    EXPECT_TRUE(has(r.out, "\"summary\":true")) << r.out;
    for (const char* f : {"p.0001.nvdb", "p.0003.nvdb", "p.0005.nvdb"})
        EXPECT_TRUE(fs::exists(dir / ("ok/" + std::string(f))));
    EXPECT_EQ(testutil::countEntries(dir / "ok"), 3u);

    // info reads .nvdb: grids, types, counts, sizes; --json on stdout only.
    r = clitest::runStdout("info '" + (dir / "ok/p.####.nvdb") + "' --json");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(has(r.out, "\"format\": \"nanovdb\"")) << r.out;
    EXPECT_TRUE(has(r.out, "\"type\": \"fp16\"")) << r.out;
    EXPECT_TRUE(has(r.out, "\"file_bytes\"")) << r.out;
    EXPECT_EQ(r.out.find("frame 1:"), std::string::npos) << "tables on stdout with --json";
    r = run("info " + (dir / "ok/p.0003.nvdb"));
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(has(r.out, "density") && has(r.out, "fp16") && has(r.out, "fog volume")) << r.out;
    // --validate reads every frame as the commands do (NanoVDB input, test_nanovdb_input.cc).
    r = run("info '" + (dir / "ok/p.####.nvdb") + "' --validate");
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(has(r.out, "validate: every frame reads")) << r.out;

    // Usage errors: exit 2, nothing written.
    EXPECT_EQ(run("convert " + cache + " --out " + (dir / "u/p.####.vdb")).code, 2);
    EXPECT_EQ(run("convert " + cache + " --frames 1-2 --out " + (dir / "u/p.nvdb")).code, 2);
    EXPECT_EQ(run("convert " + cache + " --frames 1-x --out " + (dir / "u/p.####.nvdb")).code, 2);
    EXPECT_EQ(run("convert " + cache + " --nanovdb-quant fp4 --out " + (dir / "u/p.####.nvdb")).code, 2);
    EXPECT_FALSE(fs::exists(dir / "u"));
    // A dry run writes nothing.
    r = run("convert " + cache + " --frames 1-2 --dry-run --out " + (dir / "u/p.####.nvdb"));
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(has(r.out, "would write")) << r.out;
    EXPECT_FALSE(fs::exists(dir / "u"));

    // A missing file: exit 1, named.
    r = run("convert " + (dir / "nowhere/x.0001.vdb") + " --out " + (dir / "m/x.####.nvdb"));
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_TRUE(has(r.out, "vdbturb: error:") && has(r.out, "nowhere/x.0001.vdb")) << r.out;
    EXPECT_FALSE(fs::exists(dir / "m"));
    r = run("convert " + cache + " --frames 29-31 --out " + (dir / "m/x.####.nvdb"));
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_TRUE(has(r.out, "missing frame 31")) << r.out;
    EXPECT_FALSE(fs::exists(dir / "m"));

    // A truncated frame among good ones: found by the header checks before any frame is written.
    fs::create_directories(dir / "in");
    for (int f : {1, 2, 3})
        fs::copy_file(testutil::dataPath("blender-plume2-32/fluid_data_000" + std::to_string(f) + ".vdb"),
            dir / ("in/s.000" + std::to_string(f) + ".vdb"));
    const std::string good = clitest::slurp(dir / "in/s.0002.vdb");
    std::ofstream(dir / "in/s.0002.vdb", std::ios::binary | std::ios::trunc) << good.substr(0, good.size() / 2);
    r = run("convert '" + (dir / "in/s.####.vdb") + "' --out " + (dir / "bad/s.####.nvdb"));
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_TRUE(has(r.out, "s.0002.vdb") && has(r.out, "truncated")) << r.out;
    EXPECT_FALSE(fs::exists(dir / "bad")) << "frames written before the bad one was found";

    // Damage the header checks cannot see (inside the grids' compressed data): frame 1 is written whole, frame 2
    // fails naming its file, frame 3 is not started, an existing frame 2 output is left as it was, no temporary file.
    std::string damaged = good;
    for (size_t i = damaged.size() / 2; i < damaged.size() / 2 + 4096 && i < damaged.size(); ++i)
        damaged[i] = char(0x5a ^ damaged[i]);
    std::ofstream(dir / "in/s.0002.vdb", std::ios::binary | std::ios::trunc) << damaged;
    fs::create_directories(dir / "bad");
    std::ofstream(dir / "bad/s.0002.nvdb") << "an earlier frame 2";
    r = run("convert '" + (dir / "in/s.####.vdb") + "' --out " + (dir / "bad/s.####.nvdb"),
        /*stderrToo=*/true);
    // This damage (fixed bytes of a fixed file) breaks the compressed stream; a flip inside a stored value would not
    // be detectable at all (VDB files carry no checksums).
    ASSERT_EQ(r.code, 1) << r.out;
    EXPECT_TRUE(has(r.out, "s.0002.vdb")) << r.out;
    EXPECT_TRUE(fs::exists(dir / "bad/s.0001.nvdb"));
    EXPECT_EQ(turbio::inspectNanoFile(dir / "bad/s.0001.nvdb").grids.size(), 5u);
    EXPECT_EQ(clitest::slurp(dir / "bad/s.0002.nvdb"), "an earlier frame 2");
    EXPECT_FALSE(fs::exists(dir / "bad/s.0003.nvdb"));
    EXPECT_EQ(testutil::countEntries(dir / "bad"), 2u) << "a temporary or partial file was left";
}

// transfer and resample write NanoVDB for a .nvdb name; the options that need metadata NanoVDB cannot hold are usage
// errors; resample's float NanoVDB holds the VDB resample's values exactly.
TEST(NanoVdbCli, TransferAndResampleWriteNanoVdb)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const std::string lo = testutil::dataPath("blender-plume2-32/fluid_data_####.vdb");
    const std::string hi = testutil::dataPath("blender-plume2-128/fluid_data_####.vdb");
    auto r = run("transfer --target " + lo + " --source " + hi + " --frames 10-11 -q --nanovdb-quant fp8 --out " +
                 (dir / "up/t.####.nvdb"));
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(testutil::countEntries(dir / "up"), 2u) << "NanoVDB output keeps no resume state beside it";
    const turbio::NanoFileInfo up = turbio::inspectNanoFile(dir / "up/t.0010.nvdb");
    ASSERT_EQ(up.grids.size(), 4u); // density, vel, temperature, flame (empty)
    EXPECT_EQ(up.grids[0].name, "density");
    EXPECT_EQ(up.grids[0].valueType, "fp8");
    EXPECT_EQ(up.grids[1].name, "vel");
    EXPECT_EQ(up.grids[1].valueType, "vec3f");
    EXPECT_DOUBLE_EQ(up.grids[0].voxelSize.x(), 0.03125);

    const std::string upArgs = "transfer --target " + lo + " --source " + hi + " --frames 10-11 --out ";
    r = run(upArgs + (dir / "up/t.####.nvdb") + " --resume");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_TRUE(has(r.out, "vdbturb convert")) << r.out;
    EXPECT_EQ(run(upArgs + (dir / "x/t.####.nvdb") + " --style blender").code, 2);
    EXPECT_EQ(run(upArgs + (dir / "x/t.####.vdb") + " --nanovdb-quant fp16").code, 2);
    EXPECT_EQ(run(upArgs + (dir / "x/t.####.nvdb") + " --format vdb").code, 2);
    EXPECT_FALSE(fs::exists(dir / "x"));

    // resample: the same frame as VDB (32-bit) and as NanoVDB (float), voxel for voxel.
    ASSERT_EQ(run("resample " + lo + " --frames 20 -q --full-float --out " + (dir / "r/p.####.vdb")).code, 0);
    r = run("resample " + lo + " --frames 20 -q --out " + (dir / "r/p.####.nvdb"));
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(run("resample " + lo + " --frames 20 -q --skip-existing --out " + (dir / "r/p.####.nvdb")).code, 2);
    const auto vdb = openvdb::GridBase::grid<openvdb::FloatGrid>(readVdbGrid(dir / "r/p.0020.vdb", "density"));
    nanovdb::GridHandle<> h = nanovdb::io::readGrid(dir / "r/p.0020.nvdb", std::string("density"));
    ASSERT_TRUE(vdb && h.grid<float>());
    const Compared c = compareFloat(*vdb, *h.grid<float>(), 0);
    EXPECT_EQ(c.maxError, 0.0);
    EXPECT_GT(c.voxels, 1000u);
}

// farm with a .nvdb output: the chunks write VDB (resumable, what the join reads) and the join writes NanoVDB, owned
// frames converted and overlaps blended; --nanovdb-quant after -- reaches the join only. The chunk scripts run by hand,
// as tests/farm/farm_test.sh local does.
TEST(NanoVdbCli, FarmJoinWritesNanoVdbFromVdbChunks)
{
    testutil::TempDir dir;
    ASSERT_EQ(run("sim plume --res 16x16x24 --frames 5 --seed 1 -q --out " + (dir / "t/p.####.vdb")).code, 0);
    ASSERT_EQ(run("sim swirl --res 64x64x96 --frames 5 --seed 2 -q --out " + (dir / "s/s.####.vdb")).code, 0);
    auto r = run("farm plan --dir " + (dir / "farm") + " --target '" + (dir / "t/p.####.vdb") + "' --source '" +
                 (dir / "s/s.####.vdb") + "' --out '" + (dir / "out/up.####.nvdb") +
                 "' --chunks 2 --overlap 1 --preroll 0 --cpus 1 -q -- --nanovdb-quant fp16");
    ASSERT_EQ(r.code, 0) << r.out;
    const std::string chunks = clitest::slurp(dir / "farm/chunks.sbatch");
    EXPECT_TRUE(has(chunks, "chunks/000/up.####.vdb")) << chunks;
    EXPECT_FALSE(has(chunks, "nanovdb-quant")) << chunks;
    EXPECT_TRUE(has(clitest::slurp(dir / "farm/join.sbatch"), "--nanovdb-quant fp16"));
    for (int k : {0, 1}) {
        r = clitest::shell("SLURM_ARRAY_TASK_ID=" + std::to_string(k) + " sh " + (dir / "farm/chunks.sbatch") + " 2>&1");
        ASSERT_EQ(r.code, 0) << r.out;
    }
    r = clitest::shell("sh " + (dir / "farm/join.sbatch") + " 2>&1");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(testutil::countEntries(dir / "out"), 5u);
    for (int f = 1; f <= 5; ++f) {
        const turbio::NanoFileInfo info = turbio::inspectNanoFile(dir / ("out/up.000" + std::to_string(f) + ".nvdb"));
        ASSERT_GE(info.grids.size(), 2u);
        EXPECT_EQ(info.grids[0].name, "density");
        EXPECT_EQ(info.grids[0].valueType, "fp16") << "frame " << f;
        EXPECT_EQ(info.grids[1].valueType, "vec3f");
    }
    // A Blender-style NanoVDB output is refused when planned, not after every chunk ran.
    r = run("farm plan --dir " + (dir / "farm2") + " --target '" + (dir / "t/p.####.vdb") + "' --source '" +
            (dir / "s/s.####.vdb") + "' --out '" + (dir / "out2/up.####.nvdb") + "' --chunks 2 -q -- --style blender");
    EXPECT_EQ(r.code, 2) << r.out;
}
