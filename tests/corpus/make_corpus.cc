// Writes the bad-input corpus (Cases.h) into a directory: `make_corpus DIR` makes DIR/CASE/{t,s}.####.vdb for
// every case, from small synthetic frames written here and from the real caches in ../shared/data, then
// DIR/done. Run by ctest as the fixture of test_corpus; nothing here is checked into the repository.
#include "Cases.h"

#include <turbio/NanoVdb.h>

#include <openvdb/openvdb.h>
#include <turb/NewGrid.h>
#include <openvdb/io/File.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <stdexcept>
#include <string>
#include <sys/stat.h>

namespace fs = std::filesystem;
using namespace corpus;

namespace {

std::string gData = VDBTURB_SHARED_DATA;

std::string slurp(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot read " + path);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void spit(const std::string& path, const std::string& bytes)
{
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

std::string frameName(const std::string& dir, char seq, int frame)
{
    char b[32];
    std::snprintf(b, sizeof(b), "/%c.%04d.vdb", seq, frame);
    return dir + b;
}

// --- Synthetic frames (world 1): target 8^3 at voxel 0.4, source 32^3 at 0.1 on the refined lattice ---

const double kCoarse = 0.4, kFine = 0.1;
const openvdb::Vec3d kOrigin(1.0, 0.5, 0.2); // world position of target voxel (0,0,0)'s centre

openvdb::math::Transform::Ptr xform(double voxel, const openvdb::Vec3d& origin)
{
    auto x = openvdb::math::Transform::createLinearTransform(voxel);
    x->postTranslate(origin);
    return x;
}

// Smoke moving +x by half a coarse voxel a frame, with a swirl; the source adds detail at its own scale.
float smoke(const openvdb::Vec3d& w, int frame)
{
    const openvdb::Vec3d c = kOrigin + openvdb::Vec3d(1.2 + 0.2 * frame, 1.4, 1.4);
    const double r2 = (w - c).lengthSqr();
    return float(std::exp(-r2 / 1.2));
}

openvdb::Vec3s flow(const openvdb::Vec3d& w, bool detail)
{
    openvdb::Vec3d v(0.5 + 0.2 * std::sin(w.y()), 0.2 * std::cos(w.x()), 0.1 * std::sin(w.x() + w.y()));
    if (detail)
        v += openvdb::Vec3d(0.15 * std::sin(9.0 * w.z()), 0.15 * std::sin(8.0 * w.x()), 0.15 * std::cos(7.0 * w.y()));
    return openvdb::Vec3s(v);
}

struct Grids
{
    openvdb::FloatGrid::Ptr density;
    openvdb::Vec3SGrid::Ptr vel;
    openvdb::GridPtrVec all() const { return {density, vel}; }
};

// One frame on an n^3 lattice of `voxel` whose voxel (0,0,0) sits at `origin`.
Grids makeFrame(int n, double voxel, const openvdb::Vec3d& origin, int frame, bool detail)
{
    Grids g;
    g.density = turb::newGrid<openvdb::FloatGrid>(0.0f);
    g.vel = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    auto da = g.density->getAccessor();
    auto va = g.vel->getAccessor();
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k) {
                const openvdb::Vec3d w = origin + openvdb::Vec3d(i, j, k) * voxel;
                const float d = smoke(w, frame);
                if (d > 1e-3f) da.setValue(openvdb::Coord(i, j, k), d);
                va.setValue(openvdb::Coord(i, j, k), flow(w, detail));
            }
    g.density->setName("density");
    g.density->setGridClass(openvdb::GRID_FOG_VOLUME);
    g.density->setTransform(xform(voxel, origin));
    g.vel->setName("vel");
    g.vel->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    g.vel->setTransform(xform(voxel, origin));
    return g;
}

Grids target(int frame) { return makeFrame(8, kCoarse, kOrigin, frame, false); }
openvdb::Vec3d fineOrigin(double voxel) { return kOrigin - openvdb::Vec3d(0.5 * kCoarse - 0.5 * voxel); }
Grids source(int frame, double voxel = kFine)
{
    return makeFrame(int(std::lround(8 * kCoarse / voxel)), voxel, fineOrigin(voxel), frame, true);
}

void write(const std::string& path, const openvdb::GridPtrVec& grids)
{
    openvdb::io::File f(path);
    f.write(grids);
    f.close();
}

// World 1 with `edit` applied to target frame `badFrame` (0: to every frame).
void world1(const std::string& dir, int frames, int badFrame, const std::function<void(Grids&, int)>& edit = {})
{
    for (int f = 1; f <= frames; ++f) {
        Grids t = target(f);
        if (edit && (badFrame == 0 || badFrame == f)) edit(t, f);
        openvdb::GridPtrVec grids;
        for (const auto& g : t.all())
            if (g) grids.push_back(g);
        write(frameName(dir, 't', f), grids);
        write(frameName(dir, 's', f), source(f).all());
    }
}

// --- Real caches (world 2): a Blender 32^3 target frame and its 128^3 source ---

void world2(const std::string& dir, const std::string& damaged)
{
    spit(frameName(dir, 't', 1), damaged);
    fs::copy_file(
        gData + "/blender-plume-128/fluid_data_0001.vdb", frameName(dir, 's', 1), fs::copy_options::overwrite_existing);
}

std::string blenderFrame() { return slurp(gData + "/blender-plume-32/fluid_data_0001.vdb"); }

template<typename T>
T at(const std::string& b, size_t off)
{
    T v;
    std::memcpy(&v, b.data() + off, sizeof(T));
    return v;
}

// Offsets in a VDB file (format >= 222 with grid offsets), as io::Archive lays them out.
struct Layout
{
    size_t fileMetaCount = 0;                      // offset of the file metadata's entry count
    size_t firstDescriptor = 0;                    // offset of the first grid descriptor
    size_t firstGridPosField = 0;                  // offset of that descriptor's gridPos field
    int64_t gridPos = 0, blockPos = 0, endPos = 0; // of the first grid
};

Layout layout(const std::string& b)
{
    Layout l;
    size_t p = 8 + 4 + 4 + 4 + 1 + 36;
    l.fileMetaCount = p;
    const uint32_t metas = at<uint32_t>(b, p);
    p += 4;
    for (uint32_t m = 0; m < metas; ++m)
        for (int s = 0; s < 3; ++s) p += 4 + at<uint32_t>(b, p);
    p += 4; // grid count
    l.firstDescriptor = p;
    for (int s = 0; s < 3; ++s) p += 4 + at<uint32_t>(b, p); // name, type, instance parent
    l.firstGridPosField = p;
    l.gridPos = at<int64_t>(b, p);
    l.blockPos = at<int64_t>(b, p + 8);
    l.endPos = at<int64_t>(b, p + 16);
    return l;
}

// The first Blosc chunk of the first grid's data: OpenVDB writes an int64 byte count, then the chunk, whose
// own header (version 2, versionlz 1, flags, typesize, nbytes, blocksize, cbytes) repeats the count.
size_t firstBloscChunk(const std::string& b, const Layout& l)
{
    for (size_t p = size_t(l.blockPos); p + 24 < size_t(l.endPos); ++p) {
        const int64_t n = at<int64_t>(b, p);
        if (n < 16 || n > l.endPos - int64_t(p)) continue;
        if (uint8_t(b[p + 8]) == 2 && uint8_t(b[p + 9]) == 1 && int64_t(at<uint32_t>(b, p + 8 + 12)) == n) return p + 8;
    }
    throw std::runtime_error("no Blosc chunk found");
}

void flip(std::string& b, size_t offset, uint8_t mask) { b[offset] = char(uint8_t(b[offset]) ^ mask); }

// World 1 with target frame 2 as NanoVDB (vdbturb convert's float), named t.0002.vdb; `damage` (optional) edits its
// bytes, given the offset where the first grid's (density's) data ends.
void nanoFrame2(const std::string& dir, const std::function<void(std::string&, size_t)>& damage = {})
{
    world1(dir, 3, 0);
    const std::string vdb = frameName(dir, 't', 2), nvdb = dir + "/t2.nvdb";
    turbio::convertToNanoVdb(vdb, nvdb, turbio::NanoConvertOptions{});
    std::string b = slurp(nvdb);
    const turbio::NanoFileInfo info = turbio::inspectNanoFile(nvdb);
    fs::remove(nvdb);
    size_t densityEnd = 16; // one segment: its header, every grid's header (176 bytes and the name), then the grids
    for (const auto& g : info.grids) densityEnd += 176 + g.name.size() + 1;
    densityEnd += size_t(info.grids.at(0).fileBytes);
    if (damage) damage(b, densityEnd);
    spit(vdb, b);
}

// --- The cases ---

void makeCase(const Case& c, const std::string& dir)
{
    const std::string name = c.name;
    const std::string bad = frameName(dir, 't', c.badFrame);
    if (name == "empty_file") {
        world1(dir, 3, 0);
        spit(bad, "");
    } else if (name == "not_vdb") {
        world1(dir, 3, 0);
        spit(bad, "density 0.5\nvel 1 0 0\n");
    } else if (name == "format_225") {
        world1(dir, 3, 0);
        std::string b = slurp(bad);
        const uint32_t v = 225;
        std::memcpy(&b[8], &v, 4);
        spit(bad, b);
    } else if (name == "directory") {
        world1(dir, 3, 0);
        fs::remove(bad);
        fs::create_directories(bad);
    } else if (name == "unreadable") {
        world1(dir, 3, 0);
        ::chmod(bad.c_str(), 0);
    } else if (name == "cut_in_header") {
        world1(dir, 3, 0);
        spit(bad, slurp(bad).substr(0, 20));
    } else if (name.rfind("cut_", 0) == 0) {
        const std::string b = blenderFrame();
        const size_t keep = name == "cut_last_byte" ? b.size() - 1 : b.size() * size_t(std::stoi(name.substr(4))) / 100;
        world2(dir, b.substr(0, keep));
    } else if (name == "flip_magic") {
        std::string b = blenderFrame();
        flip(b, 0, 0x01);
        world2(dir, b);
    } else if (name == "flip_grid_offset") {
        std::string b = blenderFrame();
        flip(b, layout(b).firstGridPosField + 7, 0x40);
        world2(dir, b);
    } else if (name == "flip_grid_meta_count") {
        std::string b = blenderFrame();
        flip(b, size_t(layout(b).gridPos) + 4 + 3, 0x10);
        world2(dir, b);
    } else if (name == "flip_meta_length") {
        std::string b = blenderFrame();
        flip(b, size_t(layout(b).gridPos) + 8 + 2, 0x01);
        world2(dir, b);
    } else if (name == "flip_file_meta") {
        std::string b = blenderFrame();
        flip(b, layout(b).fileMetaCount + 2, 0x01);
        world2(dir, b);
    } else if (name == "flip_blosc_size") {
        std::string b = blenderFrame();
        flip(b, firstBloscChunk(b, layout(b)) + 4 + 1, 0x01);
        world2(dir, b);
    } else if (name == "flip_topology") {
        world1(dir, 3, 0);
        std::string b = slurp(bad);
        flip(b, size_t(layout(b).blockPos) - 3, 0x04);
        spit(bad, b);
    } else if (name.rfind("flip_random_", 0) == 0) {
        world1(dir, 3, 0);
        std::string b = slurp(bad);
        std::mt19937 rng(unsigned(std::stoi(name.substr(12))));
        const size_t from = size_t(layout(b).gridPos);
        for (int k = 0; k < 4; ++k) flip(b, from + rng() % (b.size() - from), uint8_t(1u << (rng() % 8)));
        spit(bad, b);
    } else if (name == "reader_crash") {
        std::string b = slurp(gData + "/houdini-vel/vel_VDB_bound_v02.vdb");
        flip(b, 71344, 0x01);
        world2(dir, b);
    } else if (name == "reader_hang") {
        std::string b = slurp(gData + "/blender-plume-128/fluid_data_0010.vdb");
        flip(b, 172654, 0x08);
        fs::copy_file(gData + "/blender-plume-32/fluid_data_0001.vdb", frameName(dir, 't', 1));
        spit(frameName(dir, 's', 1), b);
    } else if (name == "nvdb_frame") {
        nanoFrame2(dir);
    } else if (name == "nvdb_cut") {
        nanoFrame2(dir, [](std::string& b, size_t) { b.resize(b.size() * 6 / 10); });
    } else if (name == "nvdb_header") {
        nanoFrame2(dir, [](std::string& b, size_t) { b[12] = b[13] = 0; }); // the segment's grid count
    } else if (name == "nvdb_checksum") {
        nanoFrame2(dir, [](std::string& b, size_t densityEnd) { flip(b, densityEnd - 100, 0x10); });
    } else if (name == "int32_density") {
        world1(dir, 3, 0);
        Grids t = target(2);
        auto i = turb::newGrid<openvdb::Int32Grid>(0);
        i->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(7)), 1, true);
        i->setName("density");
        i->setTransform(t.density->transform().copy());
        write(bad, {i, t.vel});
    } else if (name == "float_vel") {
        world1(dir, 3, 0);
        Grids t = target(2);
        auto f = turb::newGrid<openvdb::FloatGrid>(0.0f);
        f->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(7)), 1.0f, true);
        f->setName("vel");
        f->setTransform(t.vel->transform().copy());
        write(bad, {t.density, f});
    } else if (name == "nan_density") {
        world1(dir, 3, 2, [](Grids& g, int) { g.density->tree().setValue(openvdb::Coord(3, 3, 3), std::nanf("")); });
    } else if (name == "inf_velocity") {
        world1(dir, 3, 2, [](Grids& g, int) {
            g.vel->tree().setValue(
                openvdb::Coord(2, 5, 1), openvdb::Vec3s(0.0f, std::numeric_limits<float>::infinity(), 0.0f));
        });
    } else if (name == "empty_smoke") {
        world1(dir, 3, 0, [](Grids& g, int) {
            g.density->clear();
            g.vel->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(7)), openvdb::Vec3s(0.0f), true);
        });
    } else if (name == "frame_gap") {
        world1(dir, 4, 0);
        fs::remove(frameName(dir, 't', 3));
    } else if (name == "unnamed_grids") {
        world1(dir, 3, 2, [](Grids& g, int) {
            g.density->setName("");
            g.vel->setName("");
        });
    } else if (name == "density_only") {
        world1(dir, 3, 0, [](Grids& g, int) { g.vel = nullptr; });
    } else if (name == "velocity_only") {
        world1(dir, 3, 0, [](Grids& g, int) { g.density = nullptr; });
    } else if (name == "lattice_change") {
        world1(dir, 3, 3,
            [](Grids& g, int f) { g = makeFrame(4, 2 * kCoarse, kOrigin + openvdb::Vec3d(0.5 * kCoarse), f, false); });
    } else if (name == "vel_voxel_scale") {
        world1(dir, 3, 0, [](Grids& g, int f) {
            g.vel = makeFrame(4, 2 * kCoarse, kOrigin + openvdb::Vec3d(0.5 * kCoarse), f, false).vel;
        });
    } else if (name == "stray_voxel") {
        world1(dir, 3, 2, [](Grids& g, int) { g.density->tree().setValue(openvdb::Coord(20000, 20000, 20000), 0.5f); });
    } else if (name == "rotated" || name == "nonuniform_scale" || name == "frustum") {
        world1(dir, 3, 2, [&](Grids& g, int) {
            openvdb::math::Transform::Ptr x;
            if (name == "rotated") {
                x = xform(kCoarse, kOrigin);
                x->preRotate(0.3, openvdb::math::Z_AXIS);
            } else if (name == "nonuniform_scale") {
                x = openvdb::math::Transform::createLinearTransform(
                    openvdb::math::Mat4d(openvdb::math::Mat4d::identity()));
                x->preScale(openvdb::Vec3d(kCoarse, kCoarse, 2 * kCoarse));
            } else {
                x = openvdb::math::Transform::createFrustumTransform(
                    openvdb::BBoxd(openvdb::Vec3d(0.0), openvdb::Vec3d(7.0)), 0.5, 2.0, kCoarse);
            }
            g.density->setTransform(x);
            g.vel->setTransform(x->copy());
        });
    } else if (name == "component_lattices" || name == "double_half_components") {
        const bool mismatch = name == "component_lattices";
        world1(dir, 3, 0);
        // The Grids struct cannot hold double/component grids: rewrite the affected frames directly.
        for (int f = 1; f <= 3; ++f) {
            if (mismatch && f != 2) continue;
            Grids t = target(f);
            openvdb::GridPtrVec grids;
            if (mismatch) {
                grids.push_back(t.density);
            } else {
                auto d = turb::newGrid<openvdb::DoubleGrid>(0.0);
                for (auto it = t.density->cbeginValueOn(); it; ++it) d->tree().setValue(it.getCoord(), double(*it));
                d->setName("density");
                d->setGridClass(openvdb::GRID_FOG_VOLUME);
                d->setTransform(t.density->transform().copy());
                grids.push_back(d);
            }
            for (int a = 0; a < 3; ++a) {
                auto c = turb::newGrid<openvdb::FloatGrid>(0.0f);
                for (auto it = t.vel->cbeginValueOn(); it; ++it) c->tree().setValue(it.getCoord(), (*it)[a]);
                c->setName(std::string("vel.") + "xyz"[a]);
                c->setTransform(xform(mismatch && a == 2 ? 2 * kCoarse : kCoarse, kOrigin));
                c->setSaveFloatAsHalf(!mismatch);
                grids.push_back(c);
            }
            write(frameName(dir, 't', f), grids);
        }
    } else if (name == "duplicate_names") {
        world1(dir, 3, 0);
        for (int f = 1; f <= 3; ++f) {
            Grids t = target(f);
            auto other = t.density->deepCopy();
            other->tree().setValue(openvdb::Coord(0), 9.0f);
            write(frameName(dir, 't', f), {t.density, t.vel, other});
        }
    } else if (name == "source_ratio_1_2" || name == "source_ratio_2_5") {
        world1(dir, 3, 0);
        const double voxel = kCoarse / (name == "source_ratio_1_2" ? 1.2 : 2.5);
        for (int f = 1; f <= 3; ++f) write(frameName(dir, 's', f), source(f, voxel).all());
    } else if (name == "source_rotated") {
        world1(dir, 3, 0);
        Grids s = source(1);
        auto x = xform(kFine, fineOrigin(kFine));
        x->preRotate(0.2, openvdb::math::X_AXIS);
        s.density->setTransform(x);
        s.vel->setTransform(x->copy());
        write(frameName(dir, 's', 1), s.all());
    } else if (name == "out_read_only" || name == "out_is_input" || name == "out_under_file" ||
               name == "padding_mismatch" || name == "directory_as_cache") {
        world1(dir, 3, 0);
        if (name == "out_read_only") {
            fs::create_directories(dir + "/ro");
            ::chmod((dir + "/ro").c_str(), 0555);
        }
        if (name == "out_under_file") spit(dir + "/afile", "a file, not a directory\n");
        if (name == "directory_as_cache") {
            // Only the target files in their own directory.
            fs::create_directories(dir + "/tdir");
            for (int f = 1; f <= 3; ++f) fs::rename(frameName(dir, 't', f), frameName(dir + "/tdir", 't', f));
        }
    } else {
        throw std::runtime_error(std::string("no generator for case ") + c.name);
    }
}

} // namespace

int main(int argc, char** argv)
{
    if (argc != 2) {
        std::fprintf(stderr, "usage: make_corpus DIR\n");
        return 2;
    }
    openvdb::initialize();
    const std::string root = argv[1];
    // Permissions set by an earlier run (mode 000 files, read-only directories) must not stop the clean-up.
    if (fs::exists(root))
        for (const auto& e : fs::recursive_directory_iterator(root))
            fs::permissions(e.path(), fs::perms::owner_all | fs::perms::group_read | fs::perms::others_read |
                                          fs::perms::group_exec | fs::perms::others_exec);
    fs::remove_all(root);
    for (const Case& c : cases()) {
        const std::string dir = root + "/" + c.name;
        fs::create_directories(dir);
        makeCase(c, dir);
    }
    spit(root + "/done", std::to_string(cases().size()) + " cases\n");
    std::printf("%zu corpus cases written to %s\n", cases().size(), root.c_str());
    return 0;
}
