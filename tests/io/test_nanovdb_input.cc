// NanoVDB input (docs/nanovdb.md, "Reading"): a NanoVDB file, .nvdb or named .vdb, read by every command through the
// guarded reader, NanoVDB's own reader and nanoToOpenVDB: a real frame round-trips through the frame reader (float
// exactly, fp16 within its bound), the grid types a smoke cache uses read and the others are refused naming the grid,
// damaged files are errors naming them; transfer, measure and preview on a .nvdb sequence give the VDB's results.
#include "CliUtil.h"
#include "TestUtil.h"

#include <turb/Error.h>
#include <turbio/NanoVdb.h>
#include <turbio/Vdb.h>

#include <openvdb/openvdb.h>
#include <turb/NewGrid.h>
#include <openvdb/io/File.h>

#include <nanovdb/NanoVDB.h>
#include <nanovdb/util/GridBuilder.h>
#include <nanovdb/util/IO.h>
#include <nanovdb/util/OpenToNanoVDB.h>

#include <cfloat>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <regex>

namespace fs = std::filesystem;
using clitest::has;
using clitest::run;

namespace {

const char* const kLo = "blender-plume2-32/fluid_data_%04d.vdb";

std::string plume2Lo(int frame)
{
    char name[64];
    std::snprintf(name, sizeof name, kLo, frame);
    return testutil::dataPath(name);
}

// The largest |a - b| over the union of both fields' boxes (a field is zero outside its box); `bound` (optional) gives
// each voxel's allowed error, and `worst` gets the largest error / bound.
double maxDifference(const turb::ScalarField& a, const turb::ScalarField& b,
    const std::function<double(const turb::Coord&)>& bound = {}, double* worst = nullptr)
{
    turb::CoordBBox box = a.bbox();
    box.expand(b.bbox());
    double largest = 0.0;
    for (int i = box.min().x(); i <= box.max().x(); ++i)
        for (int j = box.min().y(); j <= box.max().y(); ++j)
            for (int k = box.min().z(); k <= box.max().z(); ++k) {
                const turb::Coord c(i, j, k);
                const double va = a.bbox().isInside(c) ? a(i, j, k) : 0.0;
                const double vb = b.bbox().isInside(c) ? b(i, j, k) : 0.0;
                const double d = std::abs(va - vb);
                largest = std::max(largest, d);
                if (bound && worst) *worst = std::max(*worst, d > 0.0 ? d / bound(c) : 0.0);
            }
    return largest;
}

turb::ScalarField component(const turb::VectorField& v, int a)
{
    turb::ScalarField c(v.bbox(), v.lattice());
    for (size_t n = 0; n < v.size(); ++n) c.data()[n] = v.data()[n][a];
    return c;
}

long long nonZero(const turb::ScalarField& f)
{
    long long n = 0;
    for (float v : f.values()) n += v != 0.0f;
    return n;
}

// fp16's bound (docs/nanovdb.md): half a step of the voxel's 8^3 leaf, (leaf max - leaf min) / 65535 / 2 over the
// leaf's 512 values (the written grid's inactive ones are 0), plus float rounding.
std::function<double(const turb::Coord&)> fp16Bound(const turb::ScalarField& f)
{
    auto leafOf = [](const turb::Coord& c) { return turb::Coord(c.x() & ~7, c.y() & ~7, c.z() & ~7); };
    auto ranges = std::make_shared<std::map<std::tuple<int, int, int>, std::pair<float, float>>>();
    for (int i = f.bbox().min().x(); i <= f.bbox().max().x(); ++i)
        for (int j = f.bbox().min().y(); j <= f.bbox().max().y(); ++j)
            for (int k = f.bbox().min().z(); k <= f.bbox().max().z(); ++k) {
                const turb::Coord l = leafOf(turb::Coord(i, j, k));
                auto& r = ranges->try_emplace({l.x(), l.y(), l.z()}, 0.0f, 0.0f).first->second;
                r.first = std::min(r.first, f(i, j, k));
                r.second = std::max(r.second, f(i, j, k));
            }
    return [ranges, leafOf](const turb::Coord& c) {
        const turb::Coord l = leafOf(c);
        const auto it = ranges->find({l.x(), l.y(), l.z()});
        const auto r = it == ranges->end() ? std::make_pair(0.0f, 0.0f) : it->second;
        return 0.5 * double(r.second - r.first) / 65535.0 +
               4.0 * FLT_EPSILON * std::max(std::abs(r.first), std::abs(r.second)) + 1e-30;
    };
}

void writeVdb(const std::string& path, const openvdb::GridPtrVec& grids, const openvdb::MetaMap& meta = {})
{
    openvdb::io::File f(path);
    f.write(grids, meta);
    f.close();
}

} // namespace

// A real cache frame (Blender's plume2 32^3, frame 5) written by vdbturb's own writer as NanoVDB in float and fp16
// (its velocity in the frame's own time unit, so the values are the frame's), read back through the normal frame
// reader and compared with the frame read from the original VDB: the same lattice, the same voxels holding smoke and
// velocity, density and velocity equal (float: bit for bit; fp16: density within half a leaf step, velocity exact,
// as NanoVDB does not quantise vectors); the grids' active voxel counts and boxes those of the VDB written alike.
TEST(NanoVdbInput, ARealFrameRoundTripsThroughTheFrameReader)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const turb::Frame original = turbio::readFrame(plume2Lo(5), 5, turbio::ReadOptions{});
    turbio::WriteOptions w;
    w.keepTimeUnit = true;
    w.format = turbio::OutputFormat::Vdb;
    turbio::writeFrame(dir / "f.vdb", original, w);
    const turbio::FileInfo vdbInfo = turbio::inspectFile(dir / "f.vdb", true);
    std::cout << "plume2-32 frame 5: VDB (32-bit) " << fs::file_size(dir / "f.vdb") << " bytes";
    for (const auto q : {turbio::NanoQuantization::Float, turbio::NanoQuantization::Fp16}) {
        const std::string name = turbio::quantizationName(q);
        SCOPED_TRACE(name);
        const std::string path = dir / ("f." + name + ".nvdb");
        w.format = turbio::OutputFormat::Auto;
        w.nanoQuantization = q;
        turbio::writeFrame(path, original, w);
        const turb::Frame back = turbio::readFrame(path, 5, turbio::ReadOptions{});
        EXPECT_DOUBLE_EQ(back.lattice().voxelSize, original.lattice().voxelSize);
        for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(back.lattice().origin[a], original.lattice().origin[a]);
        // fp16 rounds the faintest density (below half its leaf's step) to the leaf's lowest value, 0: the grids'
        // active voxels are compared below.
        if (q == turbio::NanoQuantization::Float) EXPECT_EQ(nonZero(back.density), nonZero(original.density));
        for (int a = 0; a < 3; ++a)
            EXPECT_EQ(maxDifference(component(back.velocity, a), component(original.velocity, a)), 0.0) << "axis " << a;
        double worst = 0.0;
        const double density = q == turbio::NanoQuantization::Float
                                   ? maxDifference(back.density, original.density)
                                   : maxDifference(back.density, original.density, fp16Bound(original.density), &worst);
        ASSERT_TRUE(back.temperature && original.temperature);
        const double temperature = maxDifference(*back.temperature, *original.temperature);
        if (q == turbio::NanoQuantization::Float) {
            EXPECT_EQ(density, 0.0);
            EXPECT_EQ(temperature, 0.0);
        } else {
            EXPECT_LE(worst, 1.0);
            EXPECT_GT(density, 0.0) << "fp16 stored the values exactly?";
            EXPECT_LT(temperature, 1.0 / 65535.0);
        }
        std::cout << ", NanoVDB " << name << " " << fs::file_size(path) << " bytes (density max error " << density
                  << ", error/bound " << worst << ", temperature " << temperature << ")";

        const turbio::FileInfo info = turbio::inspectFile(path, true);
        EXPECT_TRUE(info.nanoVdb);
        ASSERT_EQ(info.grids.size(), vdbInfo.grids.size());
        for (size_t i = 0; i < info.grids.size(); ++i) {
            const turbio::GridInfo &n = info.grids[i], &v = vdbInfo.grids[i];
            SCOPED_TRACE(v.name);
            EXPECT_EQ(n.name, v.name);
            EXPECT_EQ(n.valueType, v.valueType);
            EXPECT_EQ(n.gridClass, v.gridClass);
            EXPECT_EQ(n.activeVoxels, v.activeVoxels);
            EXPECT_EQ(n.activeBBox, v.activeBBox);
            EXPECT_EQ(n.voxelSize, v.voxelSize);
            if (q == turbio::NanoQuantization::Float || v.valueType == "vec3s") {
                EXPECT_EQ(n.minValue, v.minValue);
                EXPECT_EQ(n.maxValue, v.maxValue);
            }
        }
    }
    std::cout << std::endl;
}

// Float grids stored in any of NanoVDB's quantised forms read as float within their bound, vec3d velocity as vec3s,
// Blosc- and zip-compressed files as the uncompressed one, a NanoVDB file named .vdb as one named .nvdb. A grid of a
// type vdbturb does not read (int32) is an error naming it and its type when it is read, and nothing otherwise.
TEST(NanoVdbInput, QuantisedVectorAndCompressedGridsReadAndOtherTypesAreRefused)
{
    testutil::TempDir dir;
    openvdb::initialize();
    auto xf = openvdb::math::Transform::createLinearTransform(0.1);
    xf->postTranslate(openvdb::Vec3d(0.3, -0.2, 1.0));
    auto density = turb::newGrid<openvdb::FloatGrid>(0.0f);
    auto flags = turb::newGrid<openvdb::Int32Grid>(0);
    // NanoVDB 10.0.1 converts no OpenVDB vec3d grid: its own builder makes one.
    const auto velocity = [] {
        nanovdb::GridBuilder<nanovdb::Vec3d> builder(nanovdb::Vec3d(0.0));
        auto acc = builder.getAccessor();
        for (int i = 0; i < 20; ++i)
            for (int j = 0; j < 20; ++j)
                for (int k = 0; k < 20; ++k)
                    acc.setValue(nanovdb::Coord(i, j, k), nanovdb::Vec3d(0.1 * i, -0.05 * j, 1.0 + 0.01 * k));
        return builder.getHandle<>(0.1, nanovdb::Vec3d(0.3, -0.2, 1.0), "vel");
    };
    for (int i = 0; i < 20; ++i)
        for (int j = 0; j < 20; ++j)
            for (int k = 0; k < 20; ++k) {
                const openvdb::Coord c(i, j, k);
                density->tree().setValue(c, float(0.5 + 0.4 * std::sin(0.3 * i + 0.2 * j) * std::cos(0.25 * k)));
                flags->tree().setValue(c, i % 3);
            }
    density->setName("density");
    density->setGridClass(openvdb::GRID_FOG_VOLUME);
    flags->setName("flags");
    density->setTransform(xf->copy());
    flags->setTransform(xf->copy());
    const auto write = [&](const std::string& path, nanovdb::GridHandle<> d, nanovdb::io::Codec codec) {
        std::vector<nanovdb::GridHandle<>> handles;
        handles.push_back(std::move(d));
        handles.push_back(velocity());
        handles.push_back(nanovdb::openToNanoVDB(flags));
        nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(path, handles, codec);
    };
    // The full checksum here (as vdbturb writes it), NanoVDB's default partial one in the others.
    write(dir / "float.nvdb", nanovdb::openToNanoVDB(density, nanovdb::StatsMode::Default, nanovdb::ChecksumMode::Full),
        nanovdb::io::Codec::NONE);
    write(dir / "blosc.nvdb", nanovdb::openToNanoVDB(density), nanovdb::io::Codec::BLOSC);
    write(dir / "zip.vdb", nanovdb::openToNanoVDB(density), nanovdb::io::Codec::ZIP);
    write(dir / "fp4.nvdb", nanovdb::openToNanoVDB<nanovdb::HostBuffer, openvdb::FloatTree, nanovdb::Fp4>(*density),
        nanovdb::io::Codec::NONE);
    write(dir / "fpn.nvdb", nanovdb::openToNanoVDB<nanovdb::HostBuffer, openvdb::FloatTree, nanovdb::FpN>(*density),
        nanovdb::io::Codec::NONE);
    EXPECT_TRUE(turbio::isNanoVdbFile(dir / "zip.vdb"));
    EXPECT_FALSE(turbio::isNanoVdbFile(testutil::dataPath("houdini-smoke1/smoke.vdb")));

    const turb::Frame exact = turbio::readFrame(dir / "float.nvdb", 1, turbio::ReadOptions{});
    EXPECT_DOUBLE_EQ(exact.lattice().voxelSize, 0.1);
    EXPECT_NEAR(exact.lattice().origin.x(), 0.3, 1e-12);
    EXPECT_FLOAT_EQ(exact.density(3, 4, 5), density->tree().getValue(openvdb::Coord(3, 4, 5)));
    EXPECT_FLOAT_EQ(exact.velocity(19, 2, 7).x(), 1.9f);
    EXPECT_FLOAT_EQ(exact.velocity(19, 2, 7).z(), 1.07f);
    for (const char* other : {"blosc.nvdb", "zip.vdb"}) {
        const turb::Frame f = turbio::readFrame(dir / other, 1, turbio::ReadOptions{});
        EXPECT_TRUE(testutil::bitIdentical(f.density, exact.density)) << other;
        EXPECT_TRUE(testutil::bitIdentical(f.velocity, exact.velocity)) << other;
    }
    // Fp4: 15 steps over a leaf's range, at most 0.9 here (0.1 to 0.9, and a partial leaf's inactive voxels are 0):
    // half a step 0.03; FpN: within NanoVDB's own tolerance (0.01 for a fog volume), less.
    for (const char* q : {"fp4.nvdb", "fpn.nvdb"}) {
        const turb::Frame f = turbio::readFrame(dir / q, 1, turbio::ReadOptions{});
        EXPECT_EQ(f.density.bbox(), exact.density.bbox()) << q;
        EXPECT_LE(maxDifference(f.density, exact.density), 0.9 / 15.0 / 2.0 + 1e-6) << q;
        EXPECT_GT(maxDifference(f.density, exact.density), 0.0) << q;
        std::cout << q << ": density max error " << maxDifference(f.density, exact.density) << std::endl;
        EXPECT_EQ(turbio::inspectFile(dir / q, false).grids.at(0).valueType, "float") << q;
    }

    // 'flags' (int32): listed with its type, and refused by name where it is read.
    const turbio::FileInfo info = turbio::inspectFile(dir / "float.nvdb", true);
    ASSERT_EQ(info.grids.size(), 3u);
    EXPECT_EQ(info.grids[1].valueType, "vec3d");
    EXPECT_EQ(info.grids[2].valueType, "int32");
    EXPECT_EQ(info.grids[2].activeVoxels, 8000);
    turbio::ReadOptions byFlags;
    byFlags.densityGrid = "flags";
    try {
        turbio::readFrame(dir / "float.nvdb", 1, byFlags);
        ADD_FAILURE() << "an int32 density read";
    } catch (const turb::IoError& e) {
        EXPECT_TRUE(has(e.what(), dir / "float.nvdb") && has(e.what(), "'flags'") && has(e.what(), "int32"))
            << e.what();
    }
    EXPECT_THROW(turbio::OtherGrids::read(dir / "float.nvdb", turbio::ReadOptions{}, exact.lattice()), turb::IoError);
}

// A damaged NanoVDB file is an IoError naming it, never a crash or a hang: cut short, a damaged segment or grid header,
// a damaged value (NanoVDB's checksum, which vdbturb's writer records in full), and bytes flipped throughout.
TEST(NanoVdbInput, DamagedFilesAreErrorsNamingThem)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    const turb::Frame frame = turbio::readFrame(plume2Lo(5), 5, turbio::ReadOptions{});
    turbio::writeFrame(dir / "good.nvdb", frame, turbio::WriteOptions{});
    const std::string bytes = clitest::slurp(dir / "good.nvdb");
    turbio::ReadOptions opt;
    opt.readTimeout = 5.0;
    const auto refused = [&](const std::string& name, const std::string& content, const std::string& says) {
        const std::string p = dir / name;
        std::ofstream(p, std::ios::binary | std::ios::trunc) << content;
        try {
            turbio::readFrame(p, 5, opt);
            ADD_FAILURE() << name << ": read";
        } catch (const turb::IoError& e) {
            EXPECT_TRUE(has(e.what(), p)) << e.what();
            EXPECT_TRUE(says.empty() || has(e.what(), says)) << name << ": " << e.what();
        }
    };
    refused("cut.nvdb", bytes.substr(0, bytes.size() / 2), "truncated");
    refused("cut_header.vdb", bytes.substr(0, 40), "truncated");
    std::string codec = bytes;
    codec[14] = char(7); // the segment header's codec (bytes 14-15): none of NanoVDB's
    refused("codec.nvdb", codec, "damaged NanoVDB file");
    std::string newer = bytes;
    newer[7] = '2'; // NanoVDB 32.6's file magic
    refused("newer.nvdb", newer, "another layout");
    // A value inside the density's last leaf: only the checksum sees it.
    const turbio::NanoFileInfo info = turbio::inspectNanoFile(dir / "good.nvdb");
    long long densityEnd = 16;
    for (const auto& g : info.grids) densityEnd += 176 + (long long)g.name.size() + 1;
    densityEnd += info.grids.at(0).fileBytes;
    std::string value = bytes;
    value[size_t(densityEnd - 100)] ^= 0x10;
    refused("value.nvdb", value, "checksum");

    // Bytes flipped across the whole file, one copy each: read or refused naming the file. vdbturb's file, whose
    // full checksum covers every node, and the same grids with NanoVDB's default partial checksum (over the grid, tree
    // and root headers only, as nanovdb_convert and most writers leave it), where a damaged node reads or crashes the
    // reader child.
    turbio::WriteOptions vdb;
    vdb.format = turbio::OutputFormat::Vdb;
    turbio::writeFrame(dir / "frame.vdb", frame, vdb);
    openvdb::io::File in(dir / "frame.vdb");
    in.open();
    std::vector<nanovdb::GridHandle<>> handles;
    const openvdb::GridPtrVecPtr grids = in.getGrids();
    for (const auto& g : *grids) handles.push_back(nanovdb::openToNanoVDB(g));
    in.close();
    nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(dir / "partial.nvdb", handles);
    for (const std::string& name : {"good.nvdb", "partial.nvdb"}) {
        const std::string original = clitest::slurp(dir / name);
        int read = 0, errors = 0;
        for (size_t at = 0; at < original.size(); at += original.size() / 150) {
            std::string b = original;
            b[at] = char(b[at] ^ 0x5a);
            const std::string p = dir / "flip.nvdb";
            std::ofstream(p, std::ios::binary | std::ios::trunc) << b;
            try {
                turbio::readFrame(p, 5, opt);
                ++read;
            } catch (const turb::IoError& e) {
                ++errors;
                EXPECT_TRUE(has(e.what(), p)) << e.what();
            }
        }
        std::cout << name << ", 151 copies with a byte flipped: " << read << " read, " << errors << " refused"
                  << std::endl;
        EXPECT_GT(errors, 0);
    }
}

namespace {

// Frames 9 and 10 of Blender's plume2 32^3 as a cache without metadata, as Houdini or EmberGen write one (density,
// temperature and vel in world units per second), in `dir`/vdb/c.####.vdb, and converted to NanoVDB by `vdbturb
// convert` in float (`dir`/float/c.####.nvdb) and fp16 (`dir`/fp16/...).
void markerFreeCache(const std::string& dir)
{
    fs::create_directories(dir + "/vdb");
    for (int f : {9, 10}) {
        char name[32];
        std::snprintf(name, sizeof name, "/vdb/c.%04d.vdb", f);
        const std::string tmp = dir + "/tmp.vdb";
        turbio::WriteOptions w;
        w.format = turbio::OutputFormat::Vdb;
        turbio::writeFrame(tmp, turbio::readFrame(plume2Lo(f), f, turbio::ReadOptions{}), w);
        openvdb::io::File in(tmp);
        in.open();
        writeVdb(dir + name, *in.getGrids()); // the grids without vdbturb's file metadata
        in.close();
    }
    for (const std::string q : {"float", "fp16"}) {
        const auto r = run("convert '" + dir + "/vdb/c.####.vdb' -q --nanovdb-quant " + q + " --out '" + dir + "/" + q +
                           "/c.####.nvdb'");
        ASSERT_EQ(r.code, 0) << r.out;
    }
}

// transfer (against Blender's plume2 128^3), preview and measure of the cache `dir`/`kind` named as dir/run/in's VDB
// frames, run in dir/run: the same paths for every kind, since a transfer's file records them. Its outputs are moved
// to dir/out_`kind` and dir/pic_`kind`; returns measure's JSON line without its timing.
std::string commandsOn(const std::string& dir, const std::string& kind)
{
    fs::remove_all(dir + "/run");
    fs::create_directories(dir + "/run/in");
    for (const char* f : {"0009", "0010"})
        fs::copy_file(
            dir + "/" + kind + "/c." + f + (kind == "vdb" ? ".vdb" : ".nvdb"), dir + "/run/in/c." + f + ".vdb");
    const auto in = [&](const std::string& args) {
        return clitest::shell("cd " + clitest::shellQuote(dir + "/run") + " && " + VDBTURB_EXE + " " + args + " 2>&1");
    };
    const std::string hi = testutil::dataPath("blender-plume2-128/fluid_data_####.vdb");
    auto r = in("transfer --target 'in/c.####.vdb' --source '" + hi + "' -q --out 'out/t.####.vdb'");
    EXPECT_EQ(r.code, 0) << kind << ": " << r.out;
    r = in("preview 'in/c.####.vdb' --mode density,speed --frames 10 -q --out 'pic/p.####.png'");
    EXPECT_EQ(r.code, 0) << kind << ": " << r.out;
    r = in("measure --target 'in/c.####.vdb' --output 'out/t.####.vdb' --frames 10");
    EXPECT_EQ(r.code, 0) << kind << ": " << r.out;
    fs::rename(dir + "/run/out", dir + "/out_" + kind);
    fs::rename(dir + "/run/pic", dir + "/pic_" + kind);
    const size_t json = r.out.find("\n{\"");
    const std::string line = json == std::string::npos ? r.out : r.out.substr(json, r.out.find('\n', json + 1) - json);
    return std::regex_replace(line, std::regex(R"("seconds":[-+.0-9e]+,?)"), "");
}

} // namespace

// The commands on a NanoVDB sequence. A cache without metadata and the same frames converted to NanoVDB float, named
// as the VDB frames (markerFreeCache): transfer, measure and preview give the same bytes (transfer's files but for
// OpenVDB's UUID), the same figures and the same pictures. fp16 transfers too, to other bytes. A NanoVDB converted
// from Blender's own cache reads, with a note that Blender's markers are gone.
TEST(NanoVdbInputCli, TransferMeasureAndPreviewReadANanoVdbSequenceAsTheVdbOne)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    markerFreeCache(dir.path());
    const std::string fromVdb = commandsOn(dir.path(), "vdb");
    EXPECT_TRUE(has(fromVdb, "lf_err")) << fromVdb;
    EXPECT_EQ(commandsOn(dir.path(), "float"), fromVdb);
    EXPECT_NE(commandsOn(dir.path(), "fp16"), fromVdb);
    for (const char* f : {"0009", "0010"}) {
        const std::string t = std::string("/t.") + f + ".vdb";
        EXPECT_TRUE(clitest::sameVdbButUuid(dir / ("out_vdb" + t), dir / ("out_float" + t))) << t;
        EXPECT_FALSE(clitest::sameVdbButUuid(dir / ("out_vdb" + t), dir / ("out_fp16" + t))) << t;
    }
    size_t pictures = 0;
    for (const auto& e : fs::directory_iterator(dir / "pic_vdb")) {
        EXPECT_EQ(clitest::slurp(e.path()), clitest::slurp(dir / "pic_float" / e.path().filename()))
            << e.path().filename();
        ++pictures;
    }
    EXPECT_GE(pictures, 1u);

    // Blender's own cache as NanoVDB: read, with the note (its velocity reads as world units, not cells).
    const std::string hi = testutil::dataPath("blender-plume2-128/fluid_data_####.vdb");
    auto r = run("convert " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") +
                 " --frames 9-10 -q --out '" + (dir / "blender/b.####.nvdb") + "'");
    ASSERT_EQ(r.code, 0) << r.out;
    r = run("transfer --target '" + (dir / "blender/b.####.nvdb") + "' --source '" + hi + "' --out '" +
            (dir / "blender/t.####.vdb") + "'");
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(clitest::count(r.out, "keeps none of Blender's markers"), 1u) << r.out;
}

// Damaged .nvdb frames given to the commands: exit 1 and one error naming the file, before any output is written.
TEST(NanoVdbInputCli, DamagedNanoVdbFramesFailNamingTheFile)
{
    ASSERT_TRUE(testutil::haveData()) << "expected the real caches at " << testutil::dataDir();
    testutil::TempDir dir;
    auto r = run("convert " + testutil::dataPath("blender-plume2-32/fluid_data_####.vdb") +
                 " --frames 9-11 -q --out '" + (dir / "n/p.####.nvdb") + "'");
    ASSERT_EQ(r.code, 0) << r.out;
    const std::string good = clitest::slurp(dir / "n/p.0010.nvdb");
    const auto fails = [&](const std::string& content, const std::string& says) {
        std::ofstream(dir / "n/p.0010.nvdb", std::ios::binary | std::ios::trunc) << content;
        for (const std::string& cmd :
            {"resample '" + (dir / "n/p.####.nvdb") + "' --drop-other-grids --out '" + (dir / "o/r.####.vdb") + "'",
                "preview '" + (dir / "n/p.####.nvdb") + "' --out '" + (dir / "o/p.####.png") + "'",
                "info --validate '" + (dir / "n/p.####.nvdb") + "'"}) {
            const auto res = run(cmd);
            EXPECT_EQ(res.code, 1) << cmd << "\n" << res.out;
            EXPECT_TRUE(has(res.out, dir / "n/p.0010.nvdb") && has(res.out, says)) << cmd << "\n" << res.out;
        }
        EXPECT_FALSE(fs::exists(dir / "o")) << "output written before the bad frame was found";
    };
    fails(good.substr(0, good.size() * 2 / 3), "truncated");
    std::string header = good;
    header[11] = char(header[11] ^ 0x20); // the segment header's version: its major number (bits 21-31)
    fails(header, "major version");
    std::string count = good;
    count[12] = char(0); // the grid count
    count[13] = char(0);
    fails(count, "damaged NanoVDB file");
}
