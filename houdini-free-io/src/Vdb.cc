// The VDB reader/writer. All OpenVDB file handling and cache conventions live here.
#include <turbio/Vdb.h>

#include "GridSet.h"
#include "GuardedRead.h"
#include "OtherGrids.h"
#include "ReadChecks.h"

#include <turb/Metadata.h>
#include <turb/Error.h>
#include <turb/NewGrid.h>
#include <turb/Parallel.h>
#include <turb/Operators.h>
#include <turb/Resample.h>
#include <turbio/NanoVdb.h>
#include <turbio/System.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/Dense.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <unordered_map>
#include <sstream>
#include <dirent.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

namespace turbio {

using detail::cleanMessage;
using turb::IoError;
using turb::newGrid;

namespace {

// Metadata keys the reader child uses to label what it sends back.
const char* const kRoleKey = "__turb_role";
const char* const kHalfKey = "__turb_half";

void initOpenVdb()
{
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

std::string quoted(const std::string& s) { return "'" + s + "'"; }

int64_t fileSize(const std::string& path)
{
    struct stat st;
    return ::stat(path.c_str(), &st) == 0 ? int64_t(st.st_size) : -1;
}

// Reads the 12-byte header ourselves so that "not a VDB" and "newer than this OpenVDB" get a clear
// message before OpenVDB's own reader sees the file.
void checkHeader(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IoError(path + ": cannot open (" + std::strerror(errno) + ")");
    int64_t magic = 0;
    uint32_t version = 0;
    in.read(reinterpret_cast<char*>(&magic), sizeof(magic));
    in.read(reinterpret_cast<char*>(&version), sizeof(version));
    if (!in) throw IoError(path + ": file is too short to be a VDB file (truncated?)");
    if (magic != int64_t(0x56444220)) {
        char head[8];
        std::memcpy(head, &magic, sizeof(head));
        // A cache folder may hold a VDB gzip-compressed for transfer (.vdb.gz). (NanoVDB files, whatever their name,
        // never get here: guarded() reads them with NanoVDB's reader.)
        if (static_cast<unsigned char>(head[0]) == 0x1f && static_cast<unsigned char>(head[1]) == 0x8b)
            throw IoError(path + ": a gzip-compressed file, not an OpenVDB file: decompress it first (gunzip)");
        throw IoError(path + ": not an OpenVDB file (bad magic number)");
    }
    if (version > openvdb::OPENVDB_FILE_VERSION) {
        std::ostringstream os;
        os << path << ": written by a newer OpenVDB (file format " << version << "); this build uses OpenVDB "
           << openvdb::getLibraryVersionString() << ", which reads formats up to " << openvdb::OPENVDB_FILE_VERSION
           << ". Re-save the cache from the application that wrote it with an "
           << "OpenVDB 10 compatible format.";
        throw IoError(os.str());
    }
}

// One grid as the file's header lists it, in file order.
struct Descriptor
{
    std::string unique; // OpenVDB's unique name, printable: "density", "[0]" (unnamed), "vel[1]" (second 'vel')
    std::string type;   // tree type, e.g. "Tree_float_5_4_3"
};

// OpenVDB's unique names carry a record separator before the index; it prints them as "name[N]".
std::string printableUnique(const std::string& raw)
{
    const size_t sep = raw.find('\x1e');
    if (sep == std::string::npos) return raw;
    return raw.substr(0, sep) + "[" + raw.substr(sep + 1) + "]";
}

// The raw reads of the header walk: a read past the end or a length beyond the file is a "truncated or corrupt"
// IoError naming `path`.
struct HeaderReader
{
    const std::string& path;
    std::ifstream& in;
    int64_t size;

    IoError corrupt(const std::string& why) const
    {
        return IoError(path + ": truncated or corrupt file (" + why + ")");
    }
    void raw(void* p, size_t n)
    {
        in.read(static_cast<char*>(p), std::streamsize(n));
        if (!in) throw corrupt("header ends early");
    }
    std::string string()
    {
        uint32_t n = 0;
        raw(&n, 4);
        if (int64_t(n) > size) throw corrupt("bad string length in header");
        std::string str(n, '\0');
        if (n) raw(&str[0], n);
        return str;
    }
};

// The archive header (io::Archive::readHeader): magic, version, library version, offsets flag, UUID and the file's
// metadata. True when the grid descriptors follow with their offsets (layouts without are not walked).
bool readArchiveHeader(HeaderReader& r)
{
    int64_t magic = 0;
    uint32_t version = 0, major = 0, minor = 0;
    r.raw(&magic, 8);
    r.raw(&version, 4);
    if (version < 222) return false; // older layouts are not walked; the guarded reader still applies
    r.raw(&major, 4);
    r.raw(&minor, 4);
    char hasOffsets = 0;
    r.raw(&hasOffsets, 1);
    char uuid[36];
    r.raw(uuid, 36);
    uint32_t metaCount = 0;
    r.raw(&metaCount, 4);
    for (uint32_t m = 0; m < metaCount; ++m) {
        r.string(); // name
        r.string(); // type
        r.string(); // value, stored as size + bytes
    }
    return hasOffsets != 0;
}

// The grid's own metadata (after its compression flags) must lie before its data blocks: a damaged entry count or
// length makes OpenVDB read (and allocate) for minutes.
void checkGridMetadata(HeaderReader& r, const std::string& name, int64_t gridPos, int64_t blockPos)
{
    std::ifstream& in = r.in;
    in.seekg(gridPos);
    uint32_t compression = 0;
    int32_t count = 0;
    r.raw(&compression, 4);
    r.raw(&count, 4);
    const auto damaged = [&](const std::string& why) {
        return IoError(r.path + ": corrupt file: grid '" + cleanMessage(printableUnique(name)) +
                       "' has damaged metadata (" + why + ")");
    };
    if (count < 0 || int64_t(count) * 12 > blockPos - gridPos) throw damaged("entry count " + std::to_string(count));
    for (int32_t m = 0; m < count; ++m)
        for (int part = 0; part < 3; ++part) { // name, type name, value
            uint32_t n = 0;
            r.raw(&n, 4);
            if (int64_t(in.tellg()) + int64_t(n) > blockPos) throw damaged("an entry runs past the grid's header");
            if (part == 0 && n == 0) throw damaged("an entry without a name");
            in.seekg(n, std::ios::cur);
        }
}

// OpenVDB reads raw and compressed chunks without checking for end of file, so a file cut short
// inside its last grid reads "successfully" with garbage. Walk the grid descriptors (the layout of
// io::Archive::readHeader and io::GridDescriptor::read), check every grid ends inside the file, and
// return the grids in file order (empty for layouts without offsets, which are not walked).
std::vector<Descriptor> walkDescriptors(const std::string& path)
{
    std::vector<Descriptor> out;
    std::ifstream in(path, std::ios::binary);
    if (!in) return out;
    const int64_t size = fileSize(path);
    HeaderReader r{path, in, size};
    if (!readArchiveHeader(r)) return out;
    uint32_t gridCount = 0;
    r.raw(&gridCount, 4);
    if (int64_t(gridCount) > size / 16)
        throw r.corrupt("grid count " + std::to_string(gridCount) + " cannot fit in the file");
    for (uint32_t g = 0; g < gridCount; ++g) {
        const std::string name = r.string();
        const std::string type = r.string();
        r.string(); // instance parent
        int64_t gridPos = 0, blockPos = 0, endPos = 0;
        r.raw(&gridPos, 8);
        r.raw(&blockPos, 8);
        r.raw(&endPos, 8);
        const int64_t here = int64_t(in.tellg());
        if (gridPos < here || blockPos < gridPos || endPos < blockPos)
            throw r.corrupt("grid descriptor " + std::to_string(g) + " has inconsistent offsets");
        if (endPos > size)
            throw IoError(path + ": truncated file: grid '" + cleanMessage(printableUnique(name)) + "' ends at byte " +
                          std::to_string(endPos) + " but the file has " + std::to_string(size) + " bytes");
        checkGridMetadata(r, name, gridPos, blockPos);
        out.push_back({printableUnique(name), type});
        in.seekg(endPos);
    }
    return out;
}

// Runs a read body on `path` in the guarded child after the cheap in-process checks. The body gets the
// file's grids in file order (from the header walk) so that "#N" and listings agree with `info`.
using OrderedBody =
    std::function<void(detail::GridSource&, const std::vector<Descriptor>&, openvdb::GridPtrVec&, openvdb::MetaMap&)>;

detail::GuardedResult guarded(const std::string& path, const OrderedBody& body, double baseTimeout = 0.0)
{
    initOpenVdb();
    struct stat st;
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) throw IoError(path + ": is a directory, not a VDB file");
    // A NanoVDB file (EmberGen's and renderers' caches; .nvdb, or named .vdb) by its magic number: its headers are
    // checked here, every size against the file, as `info` reads them; the child reads it with NanoVDB's reader and
    // converts its grids, which the body then reads as an OpenVDB file's, in file order.
    const bool nano = isNanoVdbFile(path);
    if (nano) inspectNanoFile(path);
    else checkHeader(path);
    const std::vector<Descriptor> order = nano ? std::vector<Descriptor>() : walkDescriptors(path);
    // Generous: a healthy read runs at hundreds of MB/s, even slow farm storage at 5 MB/s passes; only a
    // reader stuck in a loop hits this.
    // VDBTURB_READ_TIMEOUT_S replaces the 10 s base (tests of damaged files use a short one).
    static const double base = [] {
        const char* e = std::getenv("VDBTURB_READ_TIMEOUT_S");
        const double v = e ? std::atof(e) : 0.0;
        return v > 0.0 ? v : 10.0;
    }();
    const double timeout =
        (baseTimeout > 0.0 ? baseTimeout : base) + double(std::max<int64_t>(fileSize(path), 0)) / 5.0e6;
    return detail::guardedRead(
        path,
        [&](detail::GridSource& file, openvdb::GridPtrVec& grids, openvdb::MetaMap& meta) {
            body(file, order, grids, meta);
        },
        timeout);
}

// --- helpers that run inside the reader child (no TBB) ---

// One grid of the file, for choosing and listing: its unique name and what its header says.
struct GridEntry
{
    std::string unique; // what io::File::readGrid accepts
    std::string name;   // the grid's own name ("" when unnamed)
    std::string type;   // value type: "float", "vec3s", ...
    std::string gridClass;
};

// A grid's value type as its file has it: a NanoVDB grid of a type vdbturb does not read (int16, vec4f, ...) comes as
// a header of another type that records its own (NanoRead.cc).
std::string valueTypeOf(const openvdb::GridBase& g)
{
    const auto recorded = g.getMetadata<openvdb::StringMetadata>("__turb_value_type");
    return recorded ? recorded->value() : g.valueType();
}

// The file's grids in file order (the header walk's), else in OpenVDB's name order.
std::vector<GridEntry> listGrids(detail::GridSource& file, const std::vector<Descriptor>& order)
{
    std::vector<std::string> uniques = file.names();
    if (order.size() == uniques.size()) {
        std::vector<std::string> byFile;
        for (const auto& d : order)
            if (std::find(uniques.begin(), uniques.end(), d.unique) != uniques.end()) byFile.push_back(d.unique);
        if (byFile.size() == uniques.size()) uniques = byFile;
    }
    std::vector<GridEntry> out;
    for (const auto& u : uniques) {
        GridEntry e;
        e.unique = u;
        try {
            auto g = file.readGridMetadata(u);
            e.name = g->getName();
            e.type = valueTypeOf(*g);
            e.gridClass = openvdb::GridBase::gridClassToString(g->getGridClass());
        } catch (const std::exception&) {
            e.name = u;
            e.type = "?";
        }
        out.push_back(e);
    }
    return out;
}

std::string describeEntry(size_t i, const GridEntry& e)
{
    const std::string name = e.name.empty() ? std::string("(unnamed)") : "'" + cleanMessage(e.name) + "'";
    std::string s = "#" + std::to_string(i) + " " + name;
    if (!e.name.empty() && e.unique != e.name) s += " (" + cleanMessage(e.unique) + ")";
    else if (e.name.empty()) s += " (" + cleanMessage(e.unique) + ")";
    return s + " " + e.type + " " + e.gridClass;
}

std::string describeEntries(const std::vector<GridEntry>& grids)
{
    std::string s;
    for (size_t i = 0; i < grids.size(); ++i) s += (i ? ", " : "") + describeEntry(i, grids[i]);
    return s.empty() ? "no grids" : s;
}

std::vector<std::string> uniqueNames(const std::vector<GridEntry>& grids)
{
    std::vector<std::string> n;
    for (const auto& g : grids) n.push_back(g.unique);
    return n;
}

openvdb::GridBase::Ptr readGridNamed(detail::GridSource& file, const std::string& path, const std::string& name)
{
    try {
        auto g = file.readGrid(name);
        detail::keepInChild(g);
        g->insertMeta(kHalfKey, openvdb::BoolMetadata(g->saveFloatAsHalf()));
        g->setSaveFloatAsHalf(false); // full precision over the pipe
        return g;
    } catch (const turb::Error&) {
        throw;
    } catch (const std::exception& e) {
        throw IoError(path + ": grid " + quoted(name) + " could not be read; truncated or corrupt file (" +
                      cleanMessage(e.what()) + ")");
    }
}

bool hasName(const std::vector<std::string>& names, const std::string& n)
{
    return std::find(names.begin(), names.end(), n) != names.end();
}

// --- helpers that run in the parent, on grids that came through the trusted stream ---

bool uniformTransform(const openvdb::math::Transform& xf, double& voxelSize, turb::Vec3d& origin)
{
    if (!xf.isLinear()) return false;
    const openvdb::math::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
    const double s = m(0, 0);
    if (!(s > 0.0)) return false;
    const double tol = 1e-6 * s;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
            const double expect = (r == c) ? s : 0.0;
            if (std::abs(m(r, c) - expect) > tol) return false;
        }
    voxelSize = s;
    origin = xf.indexToWorld(openvdb::Vec3d(0.0));
    return true;
}

turb::Lattice latticeOf(const std::string& path, const openvdb::GridBase& g)
{
    double vs = 0;
    turb::Vec3d o(0.0);
    if (!uniformTransform(g.transform(), vs, o))
        throw IoError(detail::unsupportedTransformMessage(path, g.getName(), g.transform().mapType()));
    return turb::Lattice{vs, o};
}

std::optional<turb::Coord> baseResolution(const openvdb::GridBase& g)
{
    if (auto m = g.getMetadata<openvdb::Vec3IMetadata>("file_base_resolution")) {
        const auto v = m->value();
        return turb::Coord(v.x(), v.y(), v.z());
    }
    return std::nullopt;
}

// detail::blenderSimulationBox for grid `g` of a file with metadata `fileMeta`.
std::optional<turb::CoordBBox> blenderSimulationBox(const openvdb::GridBase& g, const openvdb::MetaMap& fileMeta)
{
    const auto creator = fileMeta.getMetadata<openvdb::StringMetadata>("creator");
    return detail::blenderSimulationBox(baseResolution(g), creator ? creator->value() : std::string());
}

bool isBlenderVelocity(const openvdb::GridBase& g)
{
    return g.getName() == "velocity" && g.getGridClass() == openvdb::GRID_STAGGERED && baseResolution(g).has_value();
}

/// kBlenderOffset of a file written in Blender's style by vdbturb, or zero.
openvdb::Vec3d blenderOffset(const openvdb::MetaMap& meta)
{
    openvdb::Vec3d o(0.0);
    if (auto m = meta.getMetadata<openvdb::StringMetadata>(turb::meta::kBlenderOffset)) {
        std::istringstream in(m->value());
        in >> o[0] >> o[1] >> o[2];
        if (!in) o = openvdb::Vec3d(0.0);
    }
    return o;
}

openvdb::FloatGrid::Ptr asFloatGrid(const std::string& path, const openvdb::GridBase::Ptr& g, const char* role)
{
    if (auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(g)) return fg;
    if (auto dg = openvdb::gridPtrCast<openvdb::DoubleGrid>(g)) {
        auto out = openvdb::FloatGrid::create(std::make_shared<openvdb::FloatTree>(dg->tree()));
        out->setTransform(dg->transform().copy());
        out->setName(dg->getName());
        out->setGridClass(dg->getGridClass());
        return out;
    }
    throw IoError(path + ": grid " + quoted(g->getName()) + " has type " + g->valueType() + "; a " + role +
                  " grid must be float or double");
}

openvdb::Vec3SGrid::Ptr asVec3Grid(const std::string& path, const openvdb::GridBase::Ptr& g)
{
    if (auto vg = openvdb::gridPtrCast<openvdb::Vec3SGrid>(g)) return vg;
    if (auto dg = openvdb::gridPtrCast<openvdb::Vec3DGrid>(g)) {
        // OpenVDB's converting tree constructor refuses vec3d -> vec3s; copy values instead.
        auto out = newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(dg->background()));
        auto acc = out->getAccessor();
        for (auto it = dg->cbeginValueOn(); it; ++it) {
            if (it.isVoxelValue()) acc.setValue(it.getCoord(), openvdb::Vec3s(*it));
            else out->tree().fill(it.getBoundingBox(), openvdb::Vec3s(*it), true);
        }
        out->setTransform(dg->transform().copy());
        out->setName(dg->getName());
        out->setGridClass(dg->getGridClass());
        out->setVectorType(dg->getVectorType());
        for (auto it = dg->beginMeta(); it != dg->endMeta(); ++it) out->insertMeta(it->first, *it->second);
        return out;
    }
    throw IoError(path + ": grid " + quoted(g->getName()) + " has type " + g->valueType() +
                  "; a velocity grid must be vec3s or vec3d (or three float grids name.x/.y/.z)");
}

template<typename GridT, typename T>
void copyToField(const GridT& grid, turb::Field<T>& field)
{
    openvdb::tools::Dense<T, openvdb::tools::LayoutZYX> dense(field.bbox(), field.data());
    openvdb::tools::copyToDense(grid, dense);
}

// Cell-centred velocity from a MAC grid: x component of voxel i sits on the face at i-1/2, so the
// centre value averages the faces i-1/2 and i+1/2. Where the upper face belongs to an inactive voxel
// (Blender clips velocity to the smoke region) only the lower face is known and is used alone.
void staggeredToCentred(const openvdb::Vec3SGrid& mac, turb::VectorField& out)
{
    auto acc = mac.getConstAccessor();
    const turb::CoordBBox box = out.bbox();
    for (auto it = mac.cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox vb = it.getBoundingBox();
        vb.intersect(box);
        if (vb.empty()) continue;
        for (auto c = vb.begin(); c; ++c) {
            const openvdb::Vec3s v0 = acc.getValue(*c);
            openvdb::Vec3s r;
            for (int a = 0; a < 3; ++a) {
                openvdb::Coord n = *c;
                n[a] += 1;
                openvdb::Vec3s v1;
                r[a] = acc.probeValue(n, v1) ? 0.5f * (v0[a] + v1[a]) : v0[a];
            }
            out[*c] = r;
        }
    }
}

using CoordBBoxCallback = std::function<void(const openvdb::CoordBBox&)>;

// Calls `cb` with the box of every active voxel or tile of a float or vector grid.
void forEachActiveBox(const openvdb::GridBase& g, const CoordBBoxCallback& cb)
{
    if (const auto* v = dynamic_cast<const openvdb::Vec3SGrid*>(&g))
        for (auto it = v->cbeginValueOn(); it; ++it) cb(it.getBoundingBox());
    else if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&g))
        for (auto it = f->cbeginValueOn(); it; ++it) cb(it.getBoundingBox());
}

// Fills unknown voxels within `layers` 6-neighbour steps of known ones with the mean of their known (or
// already filled) neighbours, one layer at a time, so values continue smoothly past a clipped region.
void extendIntoUnknown(turb::VectorField& f, std::vector<uint8_t>& known, int layers)
{
    // Each layer gives every unknown voxel beside a known one the mean of its known face neighbours. A layer reads
    // only voxels known before it, so its voxels are independent: written in place (an unknown voxel's value is
    // never read within its layer) in parallel over x, and marked known once the layer is done.
    const turb::Coord d = f.dim();
    const size_t sx = size_t(d.y()) * size_t(d.z()), sy = size_t(d.z());
    const size_t stride[3] = {sx, sy, 1};
    std::vector<uint8_t> added(f.size(), 0);
    for (int layer = 0; layer < layers; ++layer) {
        std::vector<size_t> count(size_t(d.x()), 0);
        turb::parallelFor(size_t(d.x()), 1, [&](size_t x0, size_t x1) {
            for (int x = int(x0); x < int(x1); ++x)
                for (int y = 0; y < d.y(); ++y)
                    for (int z = 0; z < d.z(); ++z) {
                        const size_t n = size_t(x) * sx + size_t(y) * sy + size_t(z);
                        if (known[n]) continue;
                        const int c[3] = {x, y, z};
                        const int hi[3] = {d.x() - 1, d.y() - 1, d.z() - 1};
                        turb::Vec3f sum(0.0f);
                        int cnt = 0;
                        for (int a = 0; a < 3; ++a) {
                            if (c[a] > 0 && known[n - stride[a]]) {
                                sum += f.data()[n - stride[a]];
                                ++cnt;
                            }
                            if (c[a] < hi[a] && known[n + stride[a]]) {
                                sum += f.data()[n + stride[a]];
                                ++cnt;
                            }
                        }
                        if (cnt) {
                            f.data()[n] = sum / float(cnt);
                            added[n] = 1;
                            ++count[size_t(x)];
                        }
                    }
        });
        size_t total = 0;
        for (size_t c : count) total += c;
        if (total == 0) break;
        for (size_t n = 0; n < f.size(); ++n)
            if (added[n]) {
                known[n] = 1;
                added[n] = 0;
            }
    }
}

template<typename T>
void requireFinite(const std::string& path, const std::string& grid, const turb::Field<T>& f)
{
    size_t bad = 0, first = 0;
    const T* d = f.data();
    for (size_t n = 0; n < f.size(); ++n) {
        bool ok;
        if constexpr (std::is_same<T, float>::value) ok = std::isfinite(d[n]);
        else ok = std::isfinite(d[n][0]) && std::isfinite(d[n][1]) && std::isfinite(d[n][2]);
        if (!ok) {
            if (bad == 0) first = n;
            ++bad;
        }
    }
    if (bad) {
        const turb::Coord c = f.coordOf(first);
        std::ostringstream os;
        os << path << ": grid " << quoted(grid) << " has " << bad << " NaN/Inf voxel" << (bad > 1 ? "s" : "")
           << " (first at " << c << ")";
        throw IoError(os.str());
    }
}

double metaDouble(const openvdb::MetaMap& m, const std::string& key, double fallback)
{
    if (auto d = m.getMetadata<openvdb::DoubleMetadata>(key)) return d->value();
    if (auto f = m.getMetadata<openvdb::FloatMetadata>(key)) return f->value();
    if (auto s = m.getMetadata<openvdb::StringMetadata>(key)) {
        try {
            return std::stod(s->value());
        } catch (...) {}
    }
    return fallback;
}

std::optional<turb::CoordBBox> recordedDomain(const openvdb::MetaMap& m, const char* key = turb::meta::kDomain)
{
    const auto s = m.getMetadata<openvdb::StringMetadata>(key);
    if (!s) return std::nullopt;
    std::istringstream is(s->value());
    int v[6];
    for (int& x : v)
        if (!(is >> x) || std::abs(x) > (1 << 28)) return std::nullopt; // damaged: ignored, the grids' boxes rule
    const turb::CoordBBox b(turb::Coord(v[0], v[1], v[2]), turb::Coord(v[3], v[4], v[5]));
    if (b.empty()) return std::nullopt;
    return b;
}

// A density must be a fog volume, as OpenVDB's CheckFogVolume has it: no level set, background 0. A level set's
// distances read as density would be smoke with negative mass; a background of 0.2 is smoke filling all space, which
// no held box holds (the box would be written as a block of fog with a hard edge).
void checkDensity(const std::string& path, const openvdb::FloatGrid& g)
{
    if (g.getGridClass() == openvdb::GRID_LEVEL_SET) throw IoError(detail::levelSetDensityMessage(path, g.getName()));
    if (g.background() != 0.0f) {
        std::ostringstream os;
        os << path << ": grid " << quoted(g.getName()) << " has background " << g.background()
           << ", not 0: OpenVDB reads every voxel the grid does not store as " << g.background()
           << ", smoke filling all space, which no box can hold (a fog volume's background is 0, as OpenVDB's "
              "CheckFogVolume requires). Re-save it with background 0 (pyopenvdb: grid.background = 0.0; Blender: "
              "Set Grid Background)";
        throw IoError(os.str());
    }
}

std::string roleOf(const openvdb::GridBase& g)
{
    auto m = g.getMetadata<openvdb::StringMetadata>(kRoleKey);
    return m ? m->value() : std::string();
}

} // namespace

const char* roleName(GridRole role)
{
    switch (role) {
    case GridRole::Density: return "density";
    case GridRole::Velocity: return "velocity";
    case GridRole::Temperature: return "temperature";
    case GridRole::Flame: return "flame";
    default: return "other";
    }
}

const std::vector<std::string>& gridAliases(GridRole role)
{
    static const std::vector<std::string> density{"density", "density_noise"};
    static const std::vector<std::string> velocity{"vel", "velocity", "v"};
    static const std::vector<std::string> temperature{"temperature", "heat"};
    static const std::vector<std::string> flame{"flame", "flames"};
    static const std::vector<std::string> none;
    switch (role) {
    case GridRole::Density: return density;
    case GridRole::Velocity: return velocity;
    case GridRole::Temperature: return temperature;
    case GridRole::Flame: return flame;
    default: return none;
    }
}

std::string nearestName(const std::string& word, const std::vector<std::string>& candidates)
{
    const auto distance = [](const std::string& a, const std::string& b) {
        std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
        for (size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
        for (size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
        for (size_t i = 1; i <= a.size(); ++i)
            for (size_t j = 1; j <= b.size(); ++j) {
                d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1])});
                if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
                    d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
            }
        return d[a.size()][b.size()];
    };
    std::string best;
    size_t bestDistance = std::string::npos;
    for (const auto& c : candidates)
        if (const size_t d = distance(word, c); d < bestDistance) {
            bestDistance = d;
            best = c;
        }
    return bestDistance <= std::max<size_t>(2, word.size() / 3) ? best : std::string();
}

std::vector<std::string> resolveGrid(
    const std::vector<std::string>& names, GridRole role, const std::string& overrideName)
{
    // A name shared by several grids appears as "name[0]", "name[1]", ... (OpenVDB's unique names): the name
    // alone means the first of them, as in OpenVDB's own readGrid(name).
    const auto find = [&](const std::string& n) -> std::string {
        if (hasName(names, n)) return n;
        if (hasName(names, n + "[0]")) return n + "[0]";
        return "";
    };
    const auto components = [&](const std::string& stem) -> std::vector<std::string> {
        const std::vector<std::string> c{find(stem + ".x"), find(stem + ".y"), find(stem + ".z")};
        if (!c[0].empty() && !c[1].empty() && !c[2].empty()) return c;
        return {};
    };
    if (!overrideName.empty()) {
        if (const std::string n = find(overrideName); !n.empty()) return {n};
        // "#N": the N-th grid in file order.
        if (overrideName.size() > 1 && overrideName[0] == '#' &&
            std::all_of(overrideName.begin() + 1, overrideName.end(),
                [](char c) { return std::isdigit(static_cast<unsigned char>(c)); })) {
            const std::string digits = overrideName.substr(1);
            if (digits.size() < 7 && size_t(std::stoi(digits)) < names.size())
                return {names[size_t(std::stoi(digits))]};
            return {};
        }
        // "name[0]" is the first grid of that name, whose unique name carries no index.
        if (overrideName.size() > 3 && overrideName.compare(overrideName.size() - 3, 3, "[0]") == 0) {
            const std::string plain = overrideName.substr(0, overrideName.size() - 3);
            if (!plain.empty() && hasName(names, plain)) return {plain};
        }
        if (role == GridRole::Velocity) return components(overrideName);
        return {};
    }
    for (const auto& a : gridAliases(role))
        if (const std::string n = find(a); !n.empty()) return {n};
    if (role == GridRole::Velocity)
        for (const auto& a : gridAliases(role))
            if (auto c = components(a); !c.empty()) return c;
    return {};
}

std::string describeGrids(const std::vector<GridInfo>& grids)
{
    std::string s;
    for (const auto& g : grids) {
        const std::string name = g.name.empty() ? std::string("(unnamed)") : "'" + g.name + "'";
        s += (s.empty() ? "" : ", ") + ("#" + std::to_string(g.index) + " " + name);
        if (g.selector != g.name) s += " (" + g.selector + ")";
        s += " " + g.valueType + " " + g.gridClass;
    }
    return s.empty() ? "no grids" : s;
}

namespace detail {

std::optional<turb::CoordBBox> blenderSimulationBox(
    const std::optional<turb::Coord>& baseResolution, const std::string& creator)
{
    if (!baseResolution || creator.rfind("vdbturb", 0) == 0) return std::nullopt;
    return turb::CoordBBox(turb::Coord(0), *baseResolution - turb::Coord(1));
}

turb::IoError missingGrid(const std::string& path, GridRole role, const ReadOptions& options, const std::string& listing,
    const std::vector<std::string>& names)
{
    const bool density = role == GridRole::Density;
    const std::string& chosen = density ? options.densityGrid : options.velocityGrid;
    const std::string nearest = chosen.empty() ? std::string() : nearestName(chosen, names);
    const std::string wanted = !chosen.empty() ? "'" + chosen + "'"
                               : density       ? std::string("density (density, density_noise)")
                                               : std::string("velocity (vel, velocity, v, or vel.x/vel.y/vel.z)");
    return turb::IoError(path + ": no " + wanted + " grid" +
                             (nearest.empty() ? "" : " (did you mean '" + nearest + "'?)") +
                             "; the file has: " + listing + ".",
        {density ? "densityGrid" : "velocityGrid"});
}

std::string noVolumeProblem(const std::string& path, const std::vector<std::string>& types, const std::string& listing)
{
    if (types.empty())
        return path +
               ": the file holds no grids: an empty frame (Houdini writes one where the geometry holds no volume, "
               "e.g. before the source starts). vdbturb needs the frame's grids, even empty ones: leave the frame "
               "out with --frames, or write it with empty grids";
    if (std::all_of(types.begin(), types.end(), [](const std::string& t) { return t.rfind("ptdata", 0) == 0; }))
        return path + ": its grids are VDB points (" + listing +
               "): particles, not volumes. Rasterise them into density and velocity volumes first (Houdini: VDB from "
               "Particles, VDB Rasterize Points)";
    return "";
}

std::string levelSetDensityMessage(const std::string& path, const std::string& grid)
{
    return path + ": grid '" + grid +
           "' is a level set (signed distances: negative inside, zero at the surface, the band width outside), not a "
           "fog volume of density. Convert it to a fog volume first (Houdini: Convert VDB to Fog Volume; OpenVDB: "
           "tools::sdfToFogVolume), or choose the density grid with --density-grid";
}

turb::IoError noRequestedGrid(const std::string& path, const std::string& listing)
{
    return turb::IoError(path + ": none of the requested grids is present; the file has: " + listing + ".",
        {"densityGrid", "velocityGrid"});
}

std::string unsupportedTransformMessage(const std::string& path, const std::string& grid, const std::string& mapType)
{
    return path + ": grid '" + grid + "' has a " + mapType +
           " transform with non-uniform scale, rotation, shear or perspective; vdbturb supports only uniform voxels "
           "with a translation. Resample the cache (e.g. Houdini VDB Resample) first.";
}

turb::CoordBBox boxOnLattice(const turb::CoordBBox& b, const turb::Lattice& own, const turb::Lattice& target)
{
    if (b.empty()) return b;
    if (own.approxEqual(target)) return b;
    const turb::Vec3d lo = target.worldToIndex(own.indexToWorld(b.min().asVec3d() - turb::Vec3d(0.5)));
    const turb::Vec3d hi = target.worldToIndex(own.indexToWorld(b.max().asVec3d() + turb::Vec3d(0.5)));
    turb::Coord a, c;
    for (int k = 0; k < 3; ++k) {
        a[k] = int(std::ceil(std::max(lo[k] - 1e-9, -2.0e9)));
        c[k] = int(std::floor(std::min(hi[k] + 1e-9, 2.0e9)));
    }
    return turb::CoordBBox(a, c);
}

std::string denseSizeProblem(const std::string& path, const turb::CoordBBox& domain,
    const std::vector<std::pair<std::string, turb::CoordBBox>>& spans, double bytesPerVoxel, const ReadOptions& options)
{
    const double voxels = double(domain.dim().x()) * double(domain.dim().y()) * double(domain.dim().z());
    const double bytes = voxels * bytesPerVoxel;
    const MemoryLimit limit = memoryLimit();
    const long long usable = limit.bytes;
    const bool tooMany = voxels > options.maxVoxels;
    const bool tooBig = usable > 0 && bytes > 0.8 * double(usable);
    if (!tooMany && !tooBig) return "";
    const auto span = [](const turb::CoordBBox& b) {
        std::ostringstream os;
        const turb::Coord d = b.dim();
        os << b.min() << "-" << b.max() << " (" << d.x() << "x" << d.y() << "x" << d.z() << " voxels)";
        return os.str();
    };
    std::ostringstream os;
    os << path << ": not enough memory to load the frame: its grids span " << span(domain) << ", " << formatBytes(bytes)
       << " as dense fields";
    if (tooMany) os << "; vdbturb holds at most " << options.maxVoxels << " voxels";
    if (usable > 0) os << "; this process may use " << limit.describe();
    os << ". Spans:";
    for (size_t i = 0; i < spans.size(); ++i)
        os << (i ? "," : "") << " grid '" << spans[i].first << "' "
           << (spans[i].second.empty() ? "(empty)" : span(spans[i].second));
    os << ". A grid whose span is far larger than the others' holds stray voxels or a damaged bounding box;"
          " clip or resample it.";
    return os.str();
}

void checkDenseSize(const std::string& path, const turb::CoordBBox& domain,
    const std::vector<std::pair<std::string, turb::CoordBBox>>& spans, double bytesPerVoxel, const ReadOptions& options)
{
    const std::string problem = denseSizeProblem(path, domain, spans, bytesPerVoxel, options);
    if (problem.empty()) return;
    const double voxels = double(domain.dim().x()) * double(domain.dim().y()) * double(domain.dim().z());
    if (voxels <= options.maxVoxels && voxels * bytesPerVoxel < 0.8 * double(machineMemoryBytes()))
        throw turb::TransientError(problem + " It fits this machine's memory where more is free.");
    throw IoError(problem);
}

} // namespace detail

ReadReport resolveTiming(
    bool blenderVelocity, bool blenderCache, double recordedDt, const ReadOptions& options, double recordedTimeUnit)
{
    ReadReport r;
    switch (options.velocityUnits) {
    case VelocityUnits::Cells:
        r.cells = true;
        r.unitsSource = "ReadOptions::velocityUnits cells";
        r.unitsSetting = "velocityUnits";
        break;
    case VelocityUnits::World:
        r.unitsSource = "ReadOptions::velocityUnits world";
        r.unitsSetting = "velocityUnits";
        break;
    case VelocityUnits::Frame:
        r.unitsSource = "ReadOptions::velocityUnits frame";
        r.unitsSetting = "velocityUnits";
        break;
    case VelocityUnits::Auto:
        r.cells = blenderVelocity;
        r.unitsSource = blenderVelocity
                            ? "detected: Blender's staggered 'velocity' with file_base_resolution is in grid cells "
                              "per time unit"
                            : "no Blender markers: Houdini, EmberGen and vdbturb write world units";
        break;
    }
    r.fps = options.fps > 0.0 ? options.fps : 24.0;
    const std::string fpsText = options.fps > 0.0 ? "ReadOptions::fps" : "assumed: the cache records no frame rate";
    const std::string fpsSetting = options.fps > 0.0 ? "fps" : "";
    const bool perFrame = options.velocityUnits == VelocityUnits::Frame;
    if (options.dt > 0.0) {
        r.dt = options.dt;
        r.dtSource = "ReadOptions::dt";
        r.dtSetting = "dt";
        r.fpsSource = "not used";
    } else if (perFrame) {
        // World units per frame: the time unit is the frame (its seconds follow from fps, below).
        r.dt = 1.0;
        r.dtSource = "one frame: the velocity is per frame";
        r.fpsSource = "not used";
    } else if (recordedDt > 0.0) {
        r.dt = recordedDt;
        r.dtSource = "vdbturb_dt metadata";
        r.fpsSource = "not used";
    } else if (blenderCache) {
        // Blender/Mantaflow: frame_length = 0.1 * (25 / fps) * time_scale, in Mantaflow time units. Its VDB
        // caches record neither the frame rate nor the time scale (checked on Blender 3.2 and 3.4 caches).
        r.dt = 0.1 * 25.0 / r.fps;
        r.dtSource = "Blender's frame length 0.1 x 25/fps, time scale 1 assumed";
        r.fpsSource = fpsText;
        r.fpsSetting = fpsSetting;
        r.conventionAssumed = options.fps <= 0.0;
    } else {
        r.dt = 1.0 / r.fps;
        r.dtSource = "1/fps seconds";
        r.fpsSource = fpsText;
        r.fpsSetting = fpsSetting;
        r.conventionAssumed = options.fps <= 0.0;
    }
    // Seconds per time unit. A frame lasts 1/fps seconds and dt time units, so one unit is 1 / (fps x dt) seconds:
    // 0.4 for Mantaflow at time scale 1 (0.1 x 25/fps units a frame), whatever the frame rate. vdbturb records it;
    // other writers (Houdini, EmberGen) write world units per second.
    if (perFrame) {
        r.timeUnit = 1.0 / r.fps;
        r.timeUnitSource = std::string("a frame, 1/fps s (the velocity is per frame), fps ") +
                           (options.fps > 0.0 ? "given" : "24 assumed");
        r.fpsSource = fpsText;
        r.fpsSetting = fpsSetting;
        r.conventionAssumed = options.fps <= 0.0;
    } else if (recordedTimeUnit > 0.0) {
        r.timeUnit = recordedTimeUnit;
        r.timeUnitSource = "vdbturb_time_unit metadata";
    } else if (blenderCache) {
        r.timeUnit = 1.0 / (r.fps * r.dt);
        r.timeUnitSource = std::string("Blender's time unit: a frame is 1/fps s and dt units, fps ") +
                           (options.fps > 0.0 ? "given" : "24 assumed");
    } else {
        r.timeUnit = 1.0;
        r.timeUnitSource = "seconds (Houdini, EmberGen and vdbturb write world units per second)";
    }
    return r;
}

namespace {

// The child's part of readFrame: resolve the selectors and read just the grids needed, labelled by role.
void readRoles(detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
    openvdb::MetaMap& meta, const std::string& path, const ReadOptions& options)
{
    const std::vector<GridEntry> entries = listGrids(file, order);
    const std::vector<std::string> names = uniqueNames(entries);
    std::vector<std::string> types;
    for (const auto& e : entries) types.push_back(e.type);
    if (const std::string problem = detail::noVolumeProblem(path, types, describeEntries(entries)); !problem.empty())
        throw IoError(problem);
    const auto densName = resolveGrid(names, GridRole::Density, options.densityGrid);
    const auto velName = resolveGrid(names, GridRole::Velocity, options.velocityGrid);
    if (densName.empty() && (options.requireDensity || !options.densityGrid.empty()))
        throw detail::missingGrid(path, GridRole::Density, options, describeEntries(entries), names);
    if (velName.empty() && (options.requireVelocity || !options.velocityGrid.empty()))
        throw detail::missingGrid(path, GridRole::Velocity, options, describeEntries(entries), names);
    const auto take = [&](const std::string& name, const std::string& role) {
        auto g = readGridNamed(file, path, name);
        g->insertMeta(kRoleKey, openvdb::StringMetadata(role));
        out.push_back(g);
    };
    if (!densName.empty()) take(densName[0], "density");
    if (velName.size() == 1) take(velName[0], "velocity");
    else if (velName.size() == 3) {
        take(velName[0], "velocity.x");
        take(velName[1], "velocity.y");
        take(velName[2], "velocity.z");
    }
    if (options.readExtras) {
        if (auto n = resolveGrid(names, GridRole::Temperature); !n.empty()) take(n[0], "temperature");
        if (auto n = resolveGrid(names, GridRole::Flame); !n.empty()) take(n[0], "flame");
    }
    if (out.empty()) throw detail::noRequestedGrid(path, describeEntries(entries));
    meta.insertMeta("__turb_grid_list", openvdb::StringMetadata(describeEntries(entries)));
    if (auto fm = file.getMetadata())
        for (auto it = fm->beginMeta(); it != fm->endMeta(); ++it) meta.insertMeta(it->first, *it->second);
}

// The unique names readRoles takes with these options (none of its errors: OtherGrids reads after readFrame).
std::vector<std::string> takenNames(const std::vector<std::string>& names, const ReadOptions& options)
{
    std::vector<std::string> taken = resolveGrid(names, GridRole::Density, options.densityGrid);
    for (const auto& n : resolveGrid(names, GridRole::Velocity, options.velocityGrid)) taken.push_back(n);
    if (options.readExtras)
        for (GridRole role : {GridRole::Temperature, GridRole::Flame})
            if (auto n = resolveGrid(names, role); !n.empty()) taken.push_back(n[0]);
    return taken;
}

// The grids of one frame, from the trusted stream, by role.
struct RoleGrids
{
    openvdb::FloatGrid::Ptr density, temperature, flame;
    openvdb::Vec3SGrid::Ptr vel;
    openvdb::FloatGrid::Ptr comp[3];

    std::vector<openvdb::GridBase::ConstPtr> all() const
    {
        std::vector<openvdb::GridBase::ConstPtr> v;
        for (const auto& g : {openvdb::GridBase::ConstPtr(density), openvdb::GridBase::ConstPtr(vel),
                 openvdb::GridBase::ConstPtr(comp[0]), openvdb::GridBase::ConstPtr(comp[1]),
                 openvdb::GridBase::ConstPtr(comp[2]), openvdb::GridBase::ConstPtr(temperature),
                 openvdb::GridBase::ConstPtr(flame)})
            if (g) v.push_back(g);
        return v;
    }
};

turb::CoordBBox activeBoxOn(const openvdb::GridBase& g, const turb::Lattice& own, const turb::Lattice& target)
{
    return detail::boxOnLattice(g.evalActiveVoxelBoundingBox(), own, target);
}

// `src` sampled trilinearly at the voxel centres of `box` on `lattice`; zero more than half a voxel
// outside src's box (where the file has no values).
template<typename T>
turb::Field<T> resampledOnto(const turb::Field<T>& src, const turb::CoordBBox& box, const turb::Lattice& lattice)
{
    turb::Field<T> out(box, lattice);
    const turb::CoordBBox& sb = src.bbox();
    for (size_t n = 0; n < out.size(); ++n) {
        const turb::Vec3d p = src.lattice().worldToIndex(lattice.indexToWorld(out.coordOf(n).asVec3d()));
        bool inside = true;
        for (int k = 0; k < 3; ++k) inside = inside && p[k] >= sb.min()[k] - 0.5 && p[k] <= sb.max()[k] + 0.5;
        if (inside) out.data()[n] = turb::sampleTrilinear(src, p);
    }
    return out;
}

std::string spanText(const turb::CoordBBox& b)
{
    std::ostringstream os;
    const turb::Coord d = b.dim();
    os << b.min() << "-" << b.max() << " = " << d.x() << "x" << d.y() << "x" << d.z() << " voxels";
    return os.str();
}

// Velocity of the frame on its own lattice over `box`: cell-centred, in world units, finite-checked and
// extended past its active region as the options say.
turb::VectorField velocityField(const std::string& path, const RoleGrids& g, const turb::CoordBBox& box,
    const turb::Lattice& lattice, bool cells, const ReadOptions& options)
{
    turb::VectorField v(box, lattice);
    std::string label;
    if (g.vel) {
        label = g.vel->getName();
        if (g.vel->getGridClass() == openvdb::GRID_STAGGERED) {
            v.fill(turb::Vec3f(g.vel->background()[0], g.vel->background()[1], g.vel->background()[2]));
            staggeredToCentred(*g.vel, v);
        } else copyToField(*g.vel, v);
    } else {
        label = g.comp[0]->getName() + "/.y/.z";
        turb::ScalarField c(box, lattice);
        for (int a = 0; a < 3; ++a) {
            c.fill(0.0f);
            copyToField(*g.comp[a], c);
            for (size_t n = 0; n < c.size(); ++n) v.data()[n][a] = c.data()[n];
        }
    }
    if (cells) {
        const float s = float(lattice.voxelSize);
        for (auto& x : v.values()) x *= s;
    }
    if (options.checkFinite) requireFinite(path, label, v);
    if (options.extendVelocity > 0) {
        // Known = active in the file. Blender (and sparse Houdini vel) store velocity only near the
        // smoke; the zeros beyond are "unknown", and would read as a velocity jump at the smoke's edge.
        std::vector<uint8_t> known(v.size(), 0);
        const auto mark = [&](const openvdb::GridBase& grid) {
            const CoordBBoxCallback cb = [&](const openvdb::CoordBBox& b) {
                openvdb::CoordBBox c = b;
                c.intersect(box);
                if (c.empty()) return; // outside the held box (an empty box's iterator would not stop)
                for (auto it = c.begin(); it; ++it) known[v.offset((*it).x(), (*it).y(), (*it).z())] = 1;
            };
            forEachActiveBox(grid, cb);
        };
        if (g.vel) mark(*g.vel);
        else
            for (const auto& c : g.comp) mark(*c);
        extendIntoUnknown(v, known, options.extendVelocity);
    }
    return v;
}

turb::ScalarField scalarField(const std::string& path, const openvdb::FloatGrid& grid, const turb::CoordBBox& box,
    const turb::Lattice& lattice, bool checkFinite)
{
    turb::ScalarField f(box, lattice);
    copyToField(grid, f);
    if (checkFinite) requireFinite(path, grid.getName(), f);
    return f;
}

} // namespace

namespace {

// Largest per-axis gap between two boxes (0 when they touch or overlap).
int boxGap(const turb::CoordBBox& a, const turb::CoordBBox& b)
{
    int g = 0;
    for (int k = 0; k < 3; ++k) g = std::max({g, b.min()[k] - a.max()[k], a.min()[k] - b.max()[k]});
    return std::max(g, 0);
}

// One leaf's or active tile's smoke (voxels above the threshold), or a cluster of them.
struct SmokeNode
{
    turb::CoordBBox box;
    long long voxels = 0;
    double mass = 0.0;
};

// The leaf cell (8^3 voxels) of c as one key: 21 bits of each axis.
uint64_t leafKey(const openvdb::Coord& c)
{
    return (uint64_t(uint32_t(c.x() >> 3) & 0x1fffff) << 42) | (uint64_t(uint32_t(c.y() >> 3) & 0x1fffff) << 21) |
           uint64_t(uint32_t(c.z() >> 3) & 0x1fffff);
}

// The smoke of a grid by node: leaves first (leafCount of them, found by leafIndex), then active tiles; `outside`
// collects the smoke outside the simulation box.
struct SmokeNodes
{
    SmokeNode outside;
    std::vector<SmokeNode> nodes;
    std::unordered_map<uint64_t, size_t> leafIndex;
    size_t leafCount = 0;
};

SmokeNodes smokeNodes(
    const openvdb::FloatGrid& grid, const ReadOptions& o, const std::optional<turb::CoordBBox>& simulationBox)
{
    SmokeNodes s;
    SmokeNode& outside = s.outside;
    const float thr = o.smokeThreshold;
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        SmokeNode n;
        const bool whole = !simulationBox || simulationBox->isInside(leaf->getNodeBoundingBox());
        for (auto v = leaf->cbeginValueOn(); v; ++v)
            if (*v > thr) {
                SmokeNode& to = whole || simulationBox->isInside(v.getCoord()) ? n : outside;
                to.box.expand(v.getCoord());
                ++to.voxels;
                to.mass += double(*v);
            }
        if (n.voxels == 0) continue;
        s.leafIndex.emplace(leafKey(leaf->origin()), s.nodes.size());
        s.nodes.push_back(n);
    }
    s.leafCount = s.nodes.size();
    auto it = grid.tree().cbeginValueOn();
    it.setMaxDepth(openvdb::FloatTree::ValueOnCIter::LEAF_DEPTH - 1); // tiles only
    for (; it; ++it)
        if (*it > thr) {
            SmokeNode n;
            n.box = it.getBoundingBox();
            n.voxels = (long long)n.box.volume();
            n.mass = double(*it) * double(n.voxels);
            if (simulationBox && !simulationBox->isInside(n.box)) {
                outside.box.expand(n.box);
                outside.voxels += n.voxels;
                outside.mass += n.mass;
            } else {
                s.nodes.push_back(n);
            }
        }
    return s;
}

// Union-find over the nodes; a set's root is its lowest node index.
struct NodeSets
{
    std::vector<size_t> parent;
    explicit NodeSets(size_t n) : parent(n)
    {
        for (size_t i = 0; i < parent.size(); ++i) parent[i] = i;
    }
    size_t root(size_t i)
    {
        while (parent[i] != i) i = parent[i] = parent[parent[i]];
        return i;
    }
    void join(size_t a, size_t b)
    {
        a = root(a);
        b = root(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
};

// A leaf's smoke joins that of its 26 neighbour leaves.
void joinNeighbourLeaves(const openvdb::FloatGrid& grid, const SmokeNodes& s, NodeSets& sets)
{
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        const auto me = s.leafIndex.find(leafKey(leaf->origin()));
        if (me == s.leafIndex.end()) continue;
        for (int dx = -8; dx <= 8; dx += 8)
            for (int dy = -8; dy <= 8; dy += 8)
                for (int dz = -8; dz <= 8; dz += 8) {
                    const auto nb = s.leafIndex.find(leafKey(leaf->origin().offsetBy(dx, dy, dz)));
                    if (nb != s.leafIndex.end()) sets.join(me->second, nb->second);
                }
    }
}

// A tile joins every node within 8 voxels of it. Comparing each tile with every node took minutes on a tree of
// active tiles over 2^31 voxels (1e5 tiles and leaves): look up only the leaves and tiles that can be that near,
// by the leaf- and 128-voxel cells their origins lie in. The larger (root) tiles, few, are compared with all.
void joinNearTiles(const SmokeNodes& s, NodeSets& sets)
{
    const std::vector<SmokeNode>& nodes = s.nodes;
    std::unordered_map<uint64_t, std::vector<size_t>> tileIndex8, tileIndex128;
    const auto key128 = [&](const openvdb::Coord& c) {
        return leafKey(openvdb::Coord(c.x() >> 4, c.y() >> 4, c.z() >> 4));
    };
    for (size_t t = s.leafCount; t < nodes.size(); ++t) {
        const int size = nodes[t].box.dim().x();
        if (size == 8) tileIndex8[leafKey(nodes[t].box.min())].push_back(t);
        else if (size == 128) tileIndex128[key128(nodes[t].box.min())].push_back(t);
    }
    const auto joinNear = [&](size_t t, size_t i) {
        if (i != t && boxGap(nodes[t].box, nodes[i].box) <= 8) sets.join(t, i);
    };
    for (size_t t = s.leafCount; t < nodes.size(); ++t) {
        const turb::CoordBBox near = nodes[t].box.expandBy(8);
        if (nodes[t].box.dim().x() > 128) {
            for (size_t i = 0; i < nodes.size(); ++i) joinNear(t, i);
            continue;
        }
        // Leaves and 8-voxel tiles by the leaf cells the near box covers, 128-voxel tiles by its 128-voxel cells.
        const openvdb::Coord lo = near.min() >> 3, hi = near.max() >> 3;
        for (int x = lo.x(); x <= hi.x(); ++x)
            for (int y = lo.y(); y <= hi.y(); ++y)
                for (int z = lo.z(); z <= hi.z(); ++z) {
                    const uint64_t k = leafKey(openvdb::Coord(x << 3, y << 3, z << 3));
                    if (const auto leaf = s.leafIndex.find(k); leaf != s.leafIndex.end()) joinNear(t, leaf->second);
                    if (const auto tiles = tileIndex8.find(k); tiles != tileIndex8.end())
                        for (size_t i : tiles->second) joinNear(t, i);
                }
        for (int x = lo.x() >> 4; x <= hi.x() >> 4; ++x)
            for (int y = lo.y() >> 4; y <= hi.y() >> 4; ++y)
                for (int z = lo.z() >> 4; z <= hi.z() >> 4; ++z)
                    if (const auto tiles = tileIndex128.find(key128(openvdb::Coord(x << 7, y << 7, z << 7)));
                        tiles != tileIndex128.end())
                        for (size_t i : tiles->second) joinNear(t, i);
    }
}

// The clusters, heaviest first (ties in the tree's order); `total` gets the mass of all the smoke, outside included.
std::vector<SmokeNode> clustersByMass(const SmokeNodes& s, NodeSets& sets, double& total)
{
    std::map<size_t, SmokeNode> clusters; // by root: the lowest node index, so the order is the tree's
    total = s.outside.mass;
    for (size_t i = 0; i < s.nodes.size(); ++i) {
        SmokeNode& c = clusters[sets.root(i)];
        c.box.expand(s.nodes[i].box);
        c.voxels += s.nodes[i].voxels;
        c.mass += s.nodes[i].mass;
        total += s.nodes[i].mass;
    }
    std::vector<SmokeNode> list;
    for (auto& kv : clusters) list.push_back(kv.second);
    std::stable_sort(list.begin(), list.end(), [](const SmokeNode& a, const SmokeNode& b) { return a.mass > b.mass; });
    return list;
}

StrayCluster strayOf(const SmokeNode& c, double total, int distance)
{
    StrayCluster s;
    s.box = c.box;
    s.voxels = c.voxels;
    s.massShare = total > 0.0 ? c.mass / total : 0.0;
    s.distance = distance;
    return s;
}

// The smoke is the heaviest cluster and those of enough mass and voxels (all with keepIsolated), grown by the
// small clusters near it; the rest, and the smoke outside the simulation box, are strays.
SmokeRegion separateStrays(
    const std::vector<SmokeNode>& list, const SmokeNode& outside, double total, const ReadOptions& o)
{
    SmokeRegion r;
    r.hasDensity = true;
    std::vector<bool> kept(list.size(), false);
    for (size_t i = 0; i < list.size(); ++i)
        if (i == 0 || o.keepIsolated || (list[i].mass >= o.strayShare * total && list[i].voxels >= o.strayVoxels)) {
            kept[i] = true;
            r.smoke.expand(list[i].box);
        }
    // Small clusters near the smoke cost little and may be real (a wisp): keep them, growing the box.
    for (bool grew = true; grew;) {
        grew = false;
        for (size_t i = 0; i < list.size(); ++i)
            if (!kept[i] && boxGap(r.smoke, list[i].box) <= o.strayDistance) {
                kept[i] = grew = true;
                r.smoke.expand(list[i].box);
            }
    }
    for (size_t i = 0; i < list.size(); ++i) {
        if (kept[i]) {
            r.smokeVoxels += list[i].voxels;
            continue;
        }
        r.strays.push_back(strayOf(list[i], total, boxGap(r.smoke, list[i].box)));
    }
    if (outside.voxels > 0) { // left out whatever its size: Blender writes nothing there
        r.strays.push_back(strayOf(outside, total, r.smoke.empty() ? 0 : boxGap(r.smoke, outside.box)));
        std::stable_sort(r.strays.begin(), r.strays.end(),
            [](const StrayCluster& a, const StrayCluster& b) { return a.massShare > b.massShare; });
    }
    return r;
}

// Clusters the smoke of `grid` at leaf-node granularity: a leaf's smoke joins that of its 26 neighbour leaves,
// an active tile that of every node within one leaf of it. Serial and ordered, so the answer never depends on
// threads; a pass over the active voxels, far cheaper than the dense copy it saves.
// `simulationBox` (a Blender cache's): smoke outside it is a stray whatever its size or mass.
SmokeRegion findSmoke(
    const openvdb::FloatGrid& grid, const ReadOptions& o, const std::optional<turb::CoordBBox>& simulationBox)
{
    const SmokeNodes s = smokeNodes(grid, o, simulationBox);
    NodeSets sets(s.nodes.size());
    joinNeighbourLeaves(grid, s, sets);
    joinNearTiles(s, sets);
    double total = 0.0;
    const std::vector<SmokeNode> list = clustersByMass(s, sets, total);
    return separateStrays(list, s.outside, total, o);
}

} // namespace

std::string SmokeRegion::describeStrays(const std::string& grid) const
{
    if (strays.empty()) return "";
    long long voxels = 0;
    int lo = strays.front().distance, hi = lo;
    double share = 0.0;
    for (const auto& s : strays) {
        voxels += s.voxels;
        lo = std::min(lo, s.distance);
        hi = std::max(hi, s.distance);
        share += s.massShare;
    }
    std::ostringstream os;
    os << voxels << " voxel" << (voxels == 1 ? "" : "s") << " of " << grid << " far from the smoke";
    if (strays.size() > 1) os << " in " << strays.size() << " clusters";
    os << " (" << (lo == hi ? std::to_string(lo) : std::to_string(lo) + "-" + std::to_string(hi)) << " voxels away, ";
    os.precision(2);
    os << (share * 100.0) << "% of its mass, first at " << strays.front().box.min()
       << "), ignored: see --keep-isolated";
    return os.str();
}

turb::CoordBBox heldRegion(const SmokeRegion& region, const turb::CoordBBox& span, const ReadOptions& options)
{
    if (!options.cropToSmoke || !region.hasDensity || span.empty()) return span;
    if (!options.holdBox.empty()) return options.holdBox; // one box for a sequence (synth) or a space tile (transfer)
    if (region.smoke.empty()) {
        // No smoke: two voxels a side keep the frame's lattice and place without holding the velocity box. Not
        // one: a box one voxel thick in z reads as a 2D cache (turb::isFlat), so a 3D sequence's empty frame
        // would switch the dimension; clipped to the span, a 2D cache's stays one layer.
        const turb::Coord c((span.min().x() + span.max().x()) / 2, (span.min().y() + span.max().y()) / 2,
            (span.min().z() + span.max().z()) / 2);
        turb::CoordBBox b(c, c.offsetBy(1));
        b.intersect(span);
        return b;
    }
    turb::CoordBBox b = region.smoke;
    b.expand(std::max(options.cropMargin, 0));
    b.intersect(span);
    return b.empty() ? region.smoke : b;
}

SmokeRegion smokeRegion(const std::string& path, const ReadOptions& options)
{
    const detail::GuardedResult r = guarded(
        path,
        [&](detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
            openvdb::MetaMap&) {
            const std::vector<GridEntry> entries = listGrids(file, order);
            const std::vector<std::string> names = uniqueNames(entries);
            const auto name = resolveGrid(names, GridRole::Density, options.densityGrid);
            if (name.empty() && !options.densityGrid.empty())
                throw detail::missingGrid(path, GridRole::Density, options, describeEntries(entries), names);
            if (!name.empty()) out.push_back(readGridNamed(file, path, name[0]));
        },
        options.readTimeout);
    if (r.grids.empty()) return SmokeRegion{};
    checkDensity(path, *asFloatGrid(path, r.grids.front(), "density"));
    return findSmoke(*asFloatGrid(path, r.grids.front(), "density"), options,
        options.keepIsolated ? std::nullopt : blenderSimulationBox(*r.grids.front(), *r.meta));
}

namespace {

// The grids the reader took, by the role readRoles labelled them with. A Blender-style file places index 0 where
// Blender does; the frame keeps the lattice it was written from, so the placement offset comes off here.
RoleGrids gridsByRole(const std::string& path, const detail::GuardedResult& r)
{
    const openvdb::Vec3d offset = blenderOffset(*r.meta);
    if (offset != openvdb::Vec3d(0.0))
        for (const auto& grid : r.grids) grid->transform().postTranslate(-offset);
    RoleGrids g;
    for (const auto& grid : r.grids) {
        const std::string role = roleOf(*grid);
        if (role == "density") {
            g.density = asFloatGrid(path, grid, "density");
            checkDensity(path, *g.density);
        } else if (role == "velocity") g.vel = asVec3Grid(path, grid);
        else if (role == "velocity.x") g.comp[0] = asFloatGrid(path, grid, "velocity component");
        else if (role == "velocity.y") g.comp[1] = asFloatGrid(path, grid, "velocity component");
        else if (role == "velocity.z") g.comp[2] = asFloatGrid(path, grid, "velocity component");
        else if (role == "temperature") g.temperature = asFloatGrid(path, grid, "temperature");
        else if (role == "flame") g.flame = asFloatGrid(path, grid, "flame");
    }
    return g;
}

// Where a frame's grids lie, on the frame's lattice.
struct GridSpans
{
    turb::Lattice lattice;              ///< the frame's: the density's (the velocity's without density)
    std::optional<turb::Coord> baseRes; ///< Blender's simulation box, when the file records it
    std::optional<turb::CoordBBox> simulationBox; ///< that box for a cache Blender wrote (blenderSimulationBox)
    std::vector<turb::CoordBBox> boxes; ///< each grid's active box (RoleGrids::all() order)
    double bytesPerVoxel = 0.0;         ///< of the dense fields the grids become
    turb::CoordBBox domain;             ///< Blender's box or vdbturb's recorded one, and the boxes' union
};

GridSpans gridSpans(const std::string& path, const RoleGrids& g, const std::vector<openvdb::GridBase::ConstPtr>& all,
    bool keepIsolated, const openvdb::MetaMap& meta)
{
    // One lattice for the frame: the density's (the velocity's without density). Grids on another uniform
    // lattice (Houdini's velocity voxel scale) are resampled onto it; components must share one lattice.
    GridSpans s;
    s.lattice = latticeOf(path, *all.front());
    std::vector<turb::Lattice> lattices;
    for (const auto& grid : all) lattices.push_back(latticeOf(path, *grid));
    if (g.comp[0])
        for (int a = 1; a < 3; ++a)
            if (!latticeOf(path, *g.comp[a]).approxEqual(latticeOf(path, *g.comp[0])))
                throw IoError(path + ": velocity components " + quoted(g.comp[0]->getName()) + " and " +
                              quoted(g.comp[a]->getName()) + " lie on different lattices");

    // Domain: Blender records its full simulation box; otherwise the union of the grids' active boxes.
    for (const auto& grid : all) {
        if (auto res = baseResolution(*grid)) s.baseRes = res;
        if (auto box = blenderSimulationBox(*grid, meta); box && !keepIsolated) s.simulationBox = box;
    }
    if (s.baseRes) s.domain = turb::CoordBBox(turb::Coord(0), *s.baseRes - turb::Coord(1));
    // vdbturb's own outputs record the box they span; their grids may be sparse within it.
    if (const auto recorded = recordedDomain(meta)) s.domain.expand(*recorded);
    for (size_t i = 0; i < all.size(); ++i) {
        turb::CoordBBox b = activeBoxOn(*all[i], lattices[i], s.lattice);
        // A staggered grid's faces on the domain's upper boundary (vdbturb writes them so the last voxel has both
        // faces) are not voxels of the domain.
        if (s.baseRes && all[i]->getGridClass() == openvdb::GRID_STAGGERED)
            b.intersect(turb::CoordBBox(turb::Coord(0), *s.baseRes - turb::Coord(1)));
        // Nothing a Blender cache holds outside its simulation box is part of the simulation: a stray voxel there
        // must not stretch the span (and with it the margin's reach) toward itself.
        if (s.simulationBox) b.intersect(*s.simulationBox);
        s.boxes.push_back(b);
        if (!b.empty()) s.domain.expand(b);
        const bool vector = all[i] == openvdb::GridBase::ConstPtr(g.vel);
        s.bytesPerVoxel += vector ? 12.0 : 4.0;
    }
    if (s.domain.empty()) s.domain = turb::CoordBBox(turb::Coord(0), turb::Coord(0)); // every grid is empty
    return s;
}

// The box the frame's fields cover: the smoke and its margin (or ReadOptions::holdBox) with cropToSmoke, else the
// domain; refused when its dense fields would not fit. Fills `rep`'s span, held box, smoke region and strays note.
turb::CoordBBox heldBox(const std::string& path, const RoleGrids& g,
    const std::vector<openvdb::GridBase::ConstPtr>& all, const GridSpans& spans, const ReadOptions& options,
    ReadReport& rep, std::string& stage)
{
    // Hold the smoke, not the span: stray voxels and a large velocity box around a small plume cost nothing.
    turb::CoordBBox domain = spans.domain;
    rep.span = domain;
    if (g.density && options.cropToSmoke) {
        stage = "finding the smoke in grid " + quoted(g.density->getName());
        rep.region = findSmoke(*g.density, options, spans.simulationBox);
        // The margin reaches as far as the other grids (or Blender's domain) do, never toward the strays.
        turb::CoordBBox reach = rep.region.smoke;
        if (spans.baseRes) reach.expand(turb::CoordBBox(turb::Coord(0), *spans.baseRes - turb::Coord(1)));
        for (size_t i = 0; i < all.size(); ++i)
            if (all[i] != openvdb::GridBase::ConstPtr(g.density) && !spans.boxes[i].empty())
                reach.expand(spans.boxes[i]);
        domain = heldRegion(rep.region, reach.empty() ? domain : reach, options);
        if (!options.holdBox.empty()) domain = options.holdBox;
        if (!rep.region.strays.empty()) {
            rep.notes.push_back(rep.region.describeStrays(g.density->getName()));
            if (options.strayNote) options.strayNote(path + ": " + rep.notes.back());
        }
    }
    rep.held = domain;
    std::vector<std::pair<std::string, turb::CoordBBox>> named;
    for (size_t i = 0; i < all.size(); ++i) named.emplace_back(all[i]->getName(), spans.boxes[i]);
    detail::checkDenseSize(path, domain, named, spans.bytesPerVoxel, options);
    return domain;
}

// The frame's velocity over `domain` on `lattice`, from a grid on that lattice or on its own (read over the part
// the held box samples, then resampled, with a note in `rep`). `stage` names the step for out-of-memory messages.
turb::VectorField heldVelocity(const std::string& path, const RoleGrids& g, const turb::CoordBBox& domain,
    const turb::Lattice& lattice, bool cells, const ReadOptions& options, ReadReport& rep, std::string& stage)
{
    const openvdb::GridBase& vg = g.vel ? static_cast<const openvdb::GridBase&>(*g.vel) : *g.comp[0];
    if (latticeOf(path, vg).approxEqual(lattice)) {
        stage = "grid " + quoted(vg.getName()) + " over " + spanText(domain);
        return velocityField(path, g, domain, lattice, cells, options);
    }
    // Read on its own lattice over its own active box (plus the extension), then resample.
    const turb::Lattice own = latticeOf(path, vg);
    // Only the part the held box samples (trilinear: one voxel around), plus the extension's reach.
    turb::CoordBBox box = vg.evalActiveVoxelBoundingBox();
    box.expand(options.extendVelocity);
    turb::CoordBBox need = detail::boxOnLattice(domain, lattice, own);
    need.expand(2 + options.extendVelocity);
    box.intersect(need);
    if (box.empty()) box = turb::CoordBBox(turb::Coord(0), turb::Coord(0));
    stage = "grid " + quoted(vg.getName()) + " over " + spanText(box) + " before resampling";
    const turb::VectorField native = velocityField(path, g, box, own, cells, options);
    stage = "grid " + quoted(vg.getName()) + " resampled over " + spanText(domain);
    turb::VectorField v = resampledOnto(native, domain, lattice);
    std::ostringstream note;
    note << "grid " << quoted(vg.getName()) << " (voxel " << own.voxelSize << ") resampled trilinearly onto the "
         << (g.density ? "density's" : "frame's") << " lattice (voxel " << lattice.voxelSize << ")"
         << (std::abs(own.voxelSize / lattice.voxelSize - 2.0) < 1e-6 ? ": Houdini's velocity voxel scale 2" : "");
    rep.notes.push_back(note.str());
    return v;
}

// Temperature or flame over `domain` on `lattice` (nothing without the grid), resampled from its own lattice
// with a note in `rep` when it has one.
std::optional<turb::ScalarField> heldScalar(const std::string& path, const openvdb::FloatGrid::Ptr& grid,
    const turb::CoordBBox& domain, const turb::Lattice& lattice, const ReadOptions& options, ReadReport& rep,
    std::string& stage)
{
    if (!grid) return std::nullopt;
    stage = "grid " + quoted(grid->getName()) + " over " + spanText(domain);
    if (latticeOf(path, *grid).approxEqual(lattice))
        return scalarField(path, *grid, domain, lattice, options.checkFinite);
    turb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
    turb::CoordBBox need = detail::boxOnLattice(domain, lattice, latticeOf(path, *grid));
    need.expand(2);
    box.intersect(need);
    const turb::ScalarField native =
        scalarField(path, *grid, box.empty() ? turb::CoordBBox(turb::Coord(0), turb::Coord(0)) : box,
            latticeOf(path, *grid), options.checkFinite);
    turb::ScalarField f = resampledOnto(native, domain, lattice);
    rep.notes.push_back("grid " + quoted(grid->getName()) + " resampled trilinearly onto the frame's lattice");
    return f;
}

// A NanoVDB file cannot hold Blender's markers (file_base_resolution, creator): a staggered `velocity`, Blender's
// name and layout, is read as world units per second, cell-centred, as such a grid without the markers is in an
// OpenVDB file. One converted from a Blender cache is in grid cells per Blender time unit: say so once per input.
void noteNanoVdbVelocity(const std::string& path, const RoleGrids& g, const openvdb::MetaMap& meta,
    const ReadOptions& options, ReadReport& rep)
{
    if (!meta.getMetadata<openvdb::BoolMetadata>("__turb_nanovdb") || !g.vel || g.vel->getName() != "velocity" ||
        g.vel->getGridClass() != openvdb::GRID_STAGGERED || options.velocityUnits != VelocityUnits::Auto)
        return;
    const std::string note =
        "grid 'velocity' is staggered, as Blender writes it, but a NanoVDB file keeps none of Blender's markers "
        "(file_base_resolution, its domain and units): read as world units per second. If it was converted from a "
        "Blender cache (grid cells per Blender time unit), read that cache instead";
    rep.notes.push_back(note);
    if (options.readNote) options.readNote(path, note);
}

// File-level string metadata (vdbturb parameters, creator) travels with the frame.
void copyFileMetadata(const openvdb::MetaMap& meta, turb::Frame& frame)
{
    for (auto it = meta.beginMeta(); it != meta.endMeta(); ++it)
        if (it->second && it->second->typeName() == openvdb::StringMetadata::staticTypeName() &&
            it->first.rfind("__turb", 0) != 0 && it->first != turb::meta::kBlenderOffset)
            frame.metadata[it->first] = it->second->str();
}

} // namespace

static turb::Frame readFrameUnchecked(
    const std::string& path, int frameNumber, const ReadOptions& options, ReadReport* report, std::string& stage);

turb::Frame readFrame(const std::string& path, int frameNumber, const ReadOptions& options, ReadReport* report)
{
    std::string stage;
    try {
        return readFrameUnchecked(path, frameNumber, options, report, stage);
    } catch (const std::bad_alloc&) {
        throw IoError(path + ": not enough memory to load the frame" + (stage.empty() ? "" : " (" + stage + ")"));
    }
}

static turb::Frame readFrameUnchecked(
    const std::string& path, int frameNumber, const ReadOptions& options, ReadReport* report, std::string& stage)
{
    const detail::GuardedResult r = guarded(
        path,
        [&](detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
            openvdb::MetaMap& meta) { readRoles(file, order, out, meta, path, options); },
        options.readTimeout);
    const RoleGrids g = gridsByRole(path, r);
    const std::vector<openvdb::GridBase::ConstPtr> all = g.all();
    if (all.empty()) throw IoError(path + ": none of the requested grids is present");
    const GridSpans spans = gridSpans(path, g, all, options.keepIsolated, *r.meta);
    const turb::Lattice& lattice = spans.lattice;
    ReadReport rep;
    noteNanoVdbVelocity(path, g, *r.meta, options, rep);
    const turb::CoordBBox domain = heldBox(path, g, all, spans, options, rep, stage);
    // A background that is not zero (a wind in `vel`, an ambient temperature) is the value of every voxel the grid does
    // not store: read so inside the held box, as renderers read it; outputs are written with background zero.
    const auto background = [&](const openvdb::GridBase::ConstPtr& grid) {
        std::ostringstream v;
        if (const auto f = openvdb::gridConstPtrCast<openvdb::FloatGrid>(grid)) {
            if (f->background() == 0.0f) return;
            v << f->background();
        } else if (const auto w = openvdb::gridConstPtrCast<openvdb::Vec3SGrid>(grid)) {
            if (w->background() == openvdb::Vec3s(0.0f)) return;
            v << w->background();
        } else {
            return;
        }
        std::ostringstream note;
        note << "grid " << quoted(grid->getName()) << " has background " << v.str()
             << ", not zero: the voxels it does not store read as that inside the box held; outputs are written with "
                "background zero, so they hold zero beyond that box";
        rep.notes.push_back(note.str());
        if (options.readNote) options.readNote(path, note.str());
    };
    for (const auto& grid : all)
        if (grid != openvdb::GridBase::ConstPtr(g.density)) background(grid);

    turb::Frame frame;
    frame.number = frameNumber;
    if (g.density) {
        stage = "grid " + quoted(g.density->getName()) + " over " + spanText(domain);
        frame.density = scalarField(path, *g.density, domain, lattice, options.checkFinite);
    }
    bool blenderVelocity = false;
    if (g.vel || g.comp[0]) {
        blenderVelocity = g.vel && isBlenderVelocity(*g.vel);
        const bool cells = options.velocityUnits == VelocityUnits::Cells ||
                           (options.velocityUnits == VelocityUnits::Auto && blenderVelocity);
        frame.velocity = heldVelocity(path, g, domain, lattice, cells, options, rep, stage);
        frame.metadata[turb::meta::kInputVelocityUnits] = cells ? "cells" : "world";
    }
    frame.temperature = heldScalar(path, g.temperature, domain, lattice, options, rep, stage);
    frame.flame = heldScalar(path, g.flame, domain, lattice, options, rep, stage);
    stage.clear();
    copyFileMetadata(*r.meta, frame);

    // Time per frame and the units: explicit option > recorded by vdbturb > the writer's convention.
    const ReadReport timing = resolveTiming(blenderVelocity, spans.baseRes.has_value(),
        metaDouble(*r.meta, turb::meta::kDt, 0.0), options, metaDouble(*r.meta, turb::meta::kTimeUnit, 0.0));
    frame.dt = timing.dt;
    frame.timeUnit = timing.timeUnit;
    if (report) {
        *report = timing;
        report->notes = rep.notes;
        report->span = rep.span;
        report->held = rep.held;
        report->region = rep.region;
    }
    return frame;
}

// ---------------------------------------------------------------------------------------------
// Writing

namespace {

std::string dirName(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? std::string(".") : path.substr(0, slash);
}

std::string baseName(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string tempPathFor(const std::string& path)
{
    static std::atomic<unsigned> counter{0};
    return dirName(path) + "/." + baseName(path) + ".tmp" + std::to_string(::getpid()) + "_" +
           std::to_string(counter++);
}

// Removes temporary files a killed run left for `path` (".NAME.tmpPID_N" whose process no longer runs), so a
// kill -9 mid-write leaves no litter once the frame is written again (e.g. by --resume).
void removeStaleTemporaries(const std::string& path)
{
    const std::string dir = dirName(path), head = "." + baseName(path) + ".tmp";
    DIR* d = ::opendir(dir.c_str());
    if (!d) return;
    while (const dirent* e = ::readdir(d)) {
        const std::string name = e->d_name;
        if (name.compare(0, head.size(), head) != 0) continue;
        const long pid = std::strtol(name.c_str() + head.size(), nullptr, 10);
        if (pid <= 0 || pid == long(::getpid())) continue;
        if (::kill(pid_t(pid), 0) != 0 && errno == ESRCH) ::unlink((dir + "/" + name).c_str());
    }
    ::closedir(d);
}

bool fileExists(const std::string& path)
{
    struct stat st;
    return ::stat(path.c_str(), &st) == 0;
}

// An output stream over a file descriptor that remembers the first write error (errno), so a full disk,
// a file-size limit (EFBIG with SIGXFSZ ignored) or an I/O error is reported instead of leaving a short
// file behind. Seekable, as OpenVDB's writer goes back to fill in grid offsets.
class FdOutBuf : public std::streambuf
{
public:
    explicit FdOutBuf(int fd, bool killAfterFirstFlush = false) : mFd(fd), mKill(killAfterFirstFlush), mBuf(1 << 20)
    {
        setp(mBuf.data(), mBuf.data() + mBuf.size());
    }
    ~FdOutBuf() override { flushBuffer(); }
    int error() const { return mErr; }
    bool flushBuffer()
    {
        const char* p = pbase();
        size_t n = size_t(pptr() - pbase());
        while (n > 0 && mErr == 0) {
            const ssize_t w = ::write(mFd, p, n);
            if (w < 0) {
                if (errno == EINTR) continue;
                mErr = errno;
                break;
            }
            p += w;
            n -= size_t(w);
            if (mKill) {
                ::fsync(mFd);
                ::kill(::getpid(), SIGKILL);
            }
        }
        setp(mBuf.data(), mBuf.data() + mBuf.size());
        return mErr == 0;
    }

protected:
    int_type overflow(int_type c) override
    {
        if (!flushBuffer()) return traits_type::eof();
        if (!traits_type::eq_int_type(c, traits_type::eof())) {
            *pptr() = traits_type::to_char_type(c);
            pbump(1);
        }
        return traits_type::not_eof(c);
    }
    int sync() override { return flushBuffer() ? 0 : -1; }
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override
    {
        if (!flushBuffer()) return pos_type(off_type(-1));
        const int whence = dir == std::ios_base::beg ? SEEK_SET : dir == std::ios_base::cur ? SEEK_CUR : SEEK_END;
        const off_t r = ::lseek(mFd, off_t(off), whence);
        if (r < 0) mErr = errno;
        return r < 0 ? pos_type(off_type(-1)) : pos_type(off_type(r));
    }
    pos_type seekpos(pos_type pos, std::ios_base::openmode which) override
    {
        return seekoff(off_type(pos), std::ios_base::beg, which);
    }

private:
    int mFd;
    bool mKill;
    int mErr = 0;
    std::vector<char> mBuf;
};

// OpenVDB's File::write opens its own std::ofstream and never checks it; its protected seekable writer is
// the same code on a stream we own.
class CheckedArchive : public openvdb::io::Archive
{
public:
    void writeTo(std::ostream& os, const openvdb::GridPtrVec& grids, const openvdb::MetaMap& meta) const
    {
        Archive::write(os, grids, /*seekable=*/true, meta);
    }
};

// The message for a failed write: a full disk and a file-size limit say so in words.
// A write that failed with errno `err`: the machine's limits (disk, quota, file size) are worth a retry elsewhere.
[[noreturn]] void throwWriteFailure(const std::string& path, int err)
{
    std::string why = std::strerror(err);
    if (err == ENOSPC) why += ": the disk is full";
    else if (err == EFBIG) {
        struct rlimit lim
        {};
        if (::getrlimit(RLIMIT_FSIZE, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY)
            why = "file size limit reached: ulimit -f allows " + std::to_string((unsigned long long)lim.rlim_cur) +
                  " bytes a file (" + formatBytes(double(lim.rlim_cur)) + ")";
        else why += ": the file system's maximum file size was reached";
    } else if (err == EDQUOT) why += ": the disk quota is exhausted";
    const std::string msg = path + ": write failed (" + why + "); nothing was written under this name";
    if (err == ENOSPC || err == EFBIG || err == EDQUOT) throw turb::TransientError(msg);
    throw IoError(msg);
}

// Test hook for tests/cli/test_faults.cc: with VDBTURB_TEST_KILL_IN_WRITE=N the process sends itself SIGKILL
// during its N-th VDB write, after the first part of the temporary file reached the disk: kill -9 in the
// middle of a write, at a reproducible point.
bool killThisWrite()
{
    static const char* env = std::getenv("VDBTURB_TEST_KILL_IN_WRITE");
    if (!env || !*env) return false;
    static std::atomic<int> writes{0};
    return ++writes == std::atoi(env);
}

// Runs `body` on a checked stream over the new file `tmp`, fsyncs it, and throws naming `path` on any error (the
// temporary file is removed).
void writeChecked(
    const std::string& tmp, const std::string& path, const std::function<void(std::ostream&)>& body, bool forkGuarded)
{
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) throw IoError(path + ": cannot write (" + std::strerror(errno) + ")");
    int err = 0;
    std::string other;
    {
        FdOutBuf buf(fd, killThisWrite());
        std::ostream os(&buf);
        try {
            std::unique_lock<std::mutex> noFork(detail::forkGuard(), std::defer_lock); // Blosc's global mutex
            if (forkGuarded) noFork.lock();                                            // (GuardedRead.h)
            body(os);
            os.flush();
            buf.flushBuffer();
        } catch (const std::exception& e) {
            other = e.what();
        }
        err = buf.error();
        if (err == 0 && !os && other.empty()) err = EIO;
    }
    if (err == 0 && other.empty() && ::fsync(fd) != 0) err = errno;
    if (::close(fd) != 0 && err == 0 && other.empty()) err = errno;
    if (err != 0 || !other.empty()) {
        ::unlink(tmp.c_str());
        if (err != 0) throwWriteFailure(path, err);
        throw IoError(path + ": write failed (" + cleanMessage(other) + ")");
    }
}

// Moves a finished (fsynced) temporary file into place. With noClobber, link() fails instead of replacing.
void commitTemp(const std::string& tmp, const std::string& path, bool noClobber)
{
    if (noClobber) {
        if (::link(tmp.c_str(), path.c_str()) != 0) {
            const int err = errno;
            ::unlink(tmp.c_str());
            if (err == EEXIST) throw IoError(path + ": exists, not replaced", {"noClobber"});
            throw IoError(path + ": cannot write (" + std::strerror(err) + ")");
        }
        ::unlink(tmp.c_str());
        return;
    }
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        const int err = errno;
        ::unlink(tmp.c_str());
        throw IoError(path + ": cannot write (" + std::strerror(err) + ")");
    }
}

openvdb::math::Transform::Ptr transformOf(const turb::Lattice& l)
{
    auto xf = openvdb::math::Transform::createLinearTransform(l.voxelSize);
    xf->postTranslate(l.origin);
    return xf;
}

template<typename GridT, typename T>
typename GridT::Ptr fieldToGrid(const turb::Field<T>& field, const T& tolerance)
{
    auto grid = newGrid<GridT>(turb::Field<T>::zeroValue());
    // copyFromDense only reads; Dense has no const-value variant.
    openvdb::tools::Dense<T, openvdb::tools::LayoutZYX> dense(field.bbox(), const_cast<T*>(field.data()));
    openvdb::tools::copyFromDense(dense, *grid, tolerance);
    grid->setTransform(transformOf(field.lattice()));
    return grid;
}

// MAC velocity from cell-centred, the exact inverse of staggeredToCentred: along each line the faces f satisfy
// (f_i + f_{i+1}) / 2 = c_i for every voxel, so a Blender-style file reads back as the centred field it was written
// from (averaging plain face means instead blurs the top octave: hf_ratio fell from 1.01 to 0.82). One face beyond
// the box's upper side is written so the last voxel has both faces. The solutions differ by an alternating term
// (-1)^i K; K is the one closest, in least squares, to the smooth faces (c_{i-1} + c_i) / 2, so the faces carry
// no more checkerboard than the centred field's own Nyquist content needs.
openvdb::Vec3SGrid::Ptr centredToStaggered(const turb::VectorField& v, float scale)
{
    const turb::CoordBBox& b = v.bbox();
    const turb::CoordBBox faces(b.min(), b.max().offsetBy(1));
    turb::VectorField mac(faces, v.lattice());
    const turb::Coord dim = b.dim();
    std::vector<double> c, p;
    for (int a = 0; a < 3; ++a) {
        const int u = (a + 1) % 3, w = (a + 2) % 3, n = dim[a];
        c.resize(size_t(n));
        p.resize(size_t(n) + 1);
        for (int j = b.min()[u]; j <= b.max()[u]; ++j)
            for (int k = b.min()[w]; k <= b.max()[w]; ++k) {
                turb::Coord q;
                q[u] = j;
                q[w] = k;
                for (int i = 0; i < n; ++i) {
                    q[a] = b.min()[a] + i;
                    c[size_t(i)] = double(v[q][a]);
                }
                const auto smooth = [&](int i) {
                    return i == 0 ? c[0] : i == n ? c[size_t(n - 1)] : 0.5 * (c[size_t(i - 1)] + c[size_t(i)]);
                };
                p[0] = smooth(0);
                for (int i = 0; i < n; ++i) p[size_t(i + 1)] = 2.0 * c[size_t(i)] - p[size_t(i)];
                double K = 0.0;
                for (int i = 0; i <= n; ++i) K -= ((i & 1) ? -1.0 : 1.0) * (p[size_t(i)] - smooth(i));
                K /= double(n + 1);
                for (int i = 0; i <= n; ++i) {
                    q[a] = b.min()[a] + i;
                    mac[q][a] = float((p[size_t(i)] + ((i & 1) ? -K : K)) * double(scale));
                }
            }
    }
    // Every face active, zeros included: the reader takes a voxel whose upper face is inactive from its lower face
    // alone (Blender clips velocity to the smoke), which would break the inverse.
    return fieldToGrid<openvdb::Vec3SGrid>(mac, turb::Vec3f(-1.0f));
}

// Where a trimmed frame writes its temperature and flame, as Blender writes them: the smoke (density or flame above
// options.smokeThreshold; flame counts so a fire's hot core is kept where it holds no soot). Its velocity goes on
// this mask dilated by options.velocityMargin.
openvdb::MaskGrid::Ptr smokeMask(const turb::Frame& frame, const WriteOptions& options)
{
    auto mask = newGrid<openvdb::MaskGrid>(false);
    mask->setTransform(transformOf(frame.lattice()));
    {
        auto acc = mask->getAccessor();
        for (const turb::ScalarField* f : {&frame.density, frame.flame ? &*frame.flame : nullptr}) {
            if (!f) continue;
            for (size_t n = 0; n < f->size(); ++n)
                if (f->data()[n] > options.smokeThreshold) acc.setValueOn(f->coordOf(n));
        }
    }
    return mask;
}

// The field's non-zero values at the mask's voxels (a zero is the background either way; transfer's restore reads a
// zero velocity as "not written").
template<typename GridT, typename T>
typename GridT::Ptr maskedGrid(const turb::Field<T>& field, const openvdb::MaskGrid& mask)
{
    auto g = newGrid<GridT>(turb::Field<T>::zeroValue());
    g->setTransform(transformOf(field.lattice()));
    auto out = g->getAccessor();
    const turb::CoordBBox& box = field.bbox();
    for (auto it = mask.cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (box.isInside(c) && field[c] != turb::Field<T>::zeroValue()) out.setValueOn(c, field[c]);
    }
    return g;
}

// Velocity on a lattice `scale` times coarser (Houdini's velocity voxel scale): each coarse voxel the mean of its
// block (turb::boxDownsample), written where `near` (or, without it, the field) has a voxel of the block.
openvdb::Vec3SGrid::Ptr coarseVelocityGrid(const turb::VectorField& velocity, int scale, const openvdb::MaskGrid* near)
{
    const turb::VectorField coarse = turb::boxDownsample(velocity, scale);
    if (!near) return fieldToGrid<openvdb::Vec3SGrid>(coarse, turb::Vec3f(0.0f));
    auto mask = newGrid<openvdb::MaskGrid>(false);
    mask->setTransform(transformOf(coarse.lattice()));
    auto acc = mask->getAccessor();
    const bool flat = turb::isFlat(velocity.bbox());
    for (auto it = near->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        acc.setValueOn(openvdb::Coord(
            turb::floorDiv(c.x(), scale), turb::floorDiv(c.y(), scale), flat ? c.z() : turb::floorDiv(c.z(), scale)));
    }
    return maskedGrid<openvdb::Vec3SGrid>(coarse, *mask);
}

} // namespace

void writeFileAtomic(const std::string& path, const std::string& bytes, bool noClobber)
{
    if (noClobber && fileExists(path)) throw IoError(path + ": exists, not replaced", {"noClobber"});
    const std::string tmp = tempPathFor(path);
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) throw IoError(path + ": cannot write (" + std::strerror(errno) + ")");
    int err = 0;
    {
        FdOutBuf buf(fd);
        buf.sputn(bytes.data(), std::streamsize(bytes.size()));
        buf.flushBuffer();
        err = buf.error();
    }
    if (err == 0 && ::fsync(fd) != 0) err = errno;
    if (::close(fd) != 0 && err == 0) err = errno;
    if (err != 0) {
        ::unlink(tmp.c_str());
        throwWriteFailure(path, err);
    }
    commitTemp(tmp, path, noClobber);
}

OutputFormat outputFormatFor(const std::string& path, OutputFormat format)
{
    if (format != OutputFormat::Auto) return format;
    std::string ext = path.size() >= 5 ? path.substr(path.size() - 5) : std::string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext == ".nvdb" ? OutputFormat::NanoVdb : OutputFormat::Vdb;
}

namespace detail {

void writeFileChecked(
    const std::string& path, bool noClobber, const std::function<void(std::ostream&)>& body, bool forkGuarded)
{
    removeStaleTemporaries(path);
    const std::string tmp = tempPathFor(path);
    writeChecked(tmp, path, body, forkGuarded);
    commitTemp(tmp, path, noClobber);
}

GridSet readEveryGrid(const std::string& path, double timeout)
{
    const GuardedResult r = guarded(
        path,
        [&](detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
            openvdb::MetaMap& meta) {
            for (const auto& n : uniqueNames(listGrids(file, order))) out.push_back(readGridNamed(file, path, n));
            if (auto fm = file.getMetadata())
                for (auto it = fm->beginMeta(); it != fm->endMeta(); ++it) meta.insertMeta(it->first, *it->second);
        },
        timeout);
    GridSet set;
    set.grids = r.grids;
    for (auto it = r.meta->beginMeta(); it != r.meta->endMeta(); ++it) set.meta.insertMeta(it->first, *it->second);
    return set;
}

} // namespace detail

void writeAtomically(const std::string& path, bool noClobber, const std::function<void(const std::string& tmp)>& write)
{
    if (noClobber && fileExists(path)) throw IoError(path + ": exists, not replaced", {"noClobber"});
    const std::string tmp = tempPathFor(path);
    try {
        write(tmp);
    } catch (...) {
        ::unlink(tmp.c_str());
        throw;
    }
    if (!fileExists(tmp)) throw IoError(path + ": the writer produced no file");
    // The writer closed the file; a full disk can still surface when its pages reach the disk.
    const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
    const int err = fd < 0 ? errno : (::fsync(fd) != 0 ? errno : 0);
    if (fd >= 0) ::close(fd);
    if (err != 0) {
        ::unlink(tmp.c_str());
        throwWriteFailure(path, err);
    }
    commitTemp(tmp, path, noClobber);
}

namespace {

// The file's metadata: the creator, the frame's own entries, the velocity margin of a trimmed write and dt. For
// Blender, the grids the frame made (not those passed on as read) move to Blender's placement, recorded too.
openvdb::MetaMap fileMetadata(const turb::Frame& frame, const WriteOptions& options, bool trimmed, double timeUnit,
    openvdb::GridPtrVec& grids, const std::vector<openvdb::GridBase::Ptr>& passedAsRead)
{
    const bool blender = options.style == WriteStyle::Blender;
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("vdbturb " VDBTURB_VERSION_STRING));
    for (const auto& kv : frame.metadata) {
        if (kv.first == "creator" || kv.first == turb::meta::kBlenderOffset) continue;
        meta.insertMeta(kv.first, openvdb::StringMetadata(kv.second));
    }
    if (blender) {
        // Blender puts index 0 of every resolution of a domain at one point (its own 32^3 and 128^3 caches both
        // have translation 0), where a cell-centred refinement by f puts it (f - 1) / 2 fine voxels lower. An
        // up-res written for Blender takes Blender's placement; the offset is recorded so readers take it off.
        const auto ratio = frame.metadata.find(turb::meta::kRatio);
        const int f = ratio == frame.metadata.end() ? 1 : std::atoi(ratio->second.c_str());
        if (f > 1) {
            const double shift = 0.5 * (f - 1) * frame.lattice().voxelSize;
            const openvdb::Vec3d offset(shift, shift, frame.bbox().dim().z() == 1 ? 0.0 : shift);
            for (auto& g : grids)
                if (std::find(passedAsRead.begin(), passedAsRead.end(), g) == passedAsRead.end())
                    g->transform().postTranslate(offset);
            std::ostringstream os;
            os.precision(17);
            os << offset[0] << " " << offset[1] << " " << offset[2];
            meta.insertMeta(turb::meta::kBlenderOffset, openvdb::StringMetadata(os.str()));
        }
    }
    if (trimmed)
        meta.insertMeta(turb::meta::kVelocityMargin, openvdb::StringMetadata(std::to_string(options.velocityMargin)));
    const auto exact = [](double v) {
        std::ostringstream os;
        os.precision(17);
        os << v;
        return openvdb::StringMetadata(os.str());
    };
    // dt in the written time unit: the motion per frame, velocity x dt, is what the frame holds.
    if (frame.dt > 0.0) meta.insertMeta(turb::meta::kDt, exact(frame.dt * frame.timeUnit / timeUnit));
    meta.insertMeta(turb::meta::kTimeUnit, exact(timeUnit));

    return meta;
}

// Blender's resolution and voxel size on each grid it reads.
void addBlenderMeta(openvdb::GridBase& g, const turb::Frame& frame)
{
    const turb::Coord res = frame.bbox().dim();
    g.insertMeta("file_base_resolution", openvdb::Vec3IMetadata(openvdb::Vec3i(res.x(), res.y(), res.z())));
    g.insertMeta("file_voxel_size", openvdb::FloatMetadata(float(frame.lattice().voxelSize)));
}

// The written time unit: seconds for Houdini and renderers; for Blender the frame's own when it came from Blender,
// else Mantaflow's at time scale 1 (a frame is 0.1 x 25/fps units and 1/fps s: 0.4 s a unit).
double writtenTimeUnit(const turb::Frame& frame, const WriteOptions& options)
{
    const bool blender = options.style == WriteStyle::Blender;
    constexpr double kMantaflowTimeUnit = 0.4;
    return options.keepTimeUnit ? frame.timeUnit
           : blender            ? (frame.timeUnit != 1.0 ? frame.timeUnit : kMantaflowTimeUnit)
                                : 1.0;
}

// Where a trimmed velocity is kept: the smoke dilated by the velocity margin, as voxels.
openvdb::MaskGrid::Ptr velocityMask(const openvdb::MaskGrid& inSmoke, const WriteOptions& options)
{
    openvdb::MaskGrid::Ptr near = inSmoke.deepCopy();
    if (options.velocityMargin > 0)
        openvdb::tools::dilateActiveValues(
            near->tree(), options.velocityMargin, openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::EXPAND_TILES);
    near->tree().voxelizeActiveTiles();
    return near;
}

// The velocity grid in the style's convention: Houdini's cell-centred `vel` (coarse or trimmed to `near` as asked) in
// the written time unit, or Blender's staggered `velocity` in voxels per its time unit.
openvdb::Vec3SGrid::Ptr velocityGrid(
    const turb::Frame& frame, const WriteOptions& options, const openvdb::MaskGrid* near, float velocityScale)
{
    const bool blender = options.style == WriteStyle::Blender;
    openvdb::Vec3SGrid::Ptr g;
    if (!blender && options.velocityVoxelScale > 1) {
        g = coarseVelocityGrid(frame.velocity, options.velocityVoxelScale, near);
        g->setName("vel");
        g->setGridClass(openvdb::GRID_UNKNOWN);
    } else if (blender) {
        g = centredToStaggered(frame.velocity, float(1.0 / frame.lattice().voxelSize) * velocityScale);
        g->setName("velocity");
        g->setGridClass(openvdb::GRID_STAGGERED);
        addBlenderMeta(*g, frame);
    } else if (near) {
        g = maskedGrid<openvdb::Vec3SGrid>(frame.velocity, *near);
        g->setName("vel");
        g->setGridClass(openvdb::GRID_UNKNOWN);
    } else {
        g = fieldToGrid<openvdb::Vec3SGrid>(frame.velocity, turb::Vec3f(0.0f));
        g->setName("vel");
        g->setGridClass(openvdb::GRID_UNKNOWN);
    }
    if (!blender && velocityScale != 1.0f)
        for (auto it = g->beginValueOn(); it; ++it) it.setValue(*it * velocityScale);
    g->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    g->setSaveFloatAsHalf(options.halfFloat);
    return g;
}

// The density: a fog volume, its values within the density tolerance of zero left inactive.
openvdb::FloatGrid::Ptr densityGrid(const turb::Frame& frame, const WriteOptions& options)
{
    auto g = fieldToGrid<openvdb::FloatGrid>(frame.density, options.densityTolerance);
    g->setName("density");
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setSaveFloatAsHalf(options.halfFloat);
    if (options.style == WriteStyle::Blender) addBlenderMeta(*g, frame);
    return g;
}

// Temperature or flame, when the frame has it: a fog volume, trimmed to the smoke when `inSmoke` is given.
void appendScalar(openvdb::GridPtrVec& grids, const std::optional<turb::ScalarField>& f, const char* name,
    const turb::Frame& frame, const WriteOptions& options, const openvdb::MaskGrid* inSmoke)
{
    if (!f || f->empty()) return;
    auto g = inSmoke ? maskedGrid<openvdb::FloatGrid>(*f, *inSmoke) : fieldToGrid<openvdb::FloatGrid>(*f, 0.0f);
    g->setName(name);
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setSaveFloatAsHalf(options.halfFloat);
    if (options.style == WriteStyle::Blender) addBlenderMeta(*g, frame);
    grids.push_back(g);
}

// The other grids read beside the frame, appended to `grids`: those that follow the frame on its lattice, the rest
// (also listed in `passedAsRead`) as they were read.
void appendOtherGrids(const OtherGrids::Impl& others, const turb::Lattice& lat, const WriteOptions& options,
    openvdb::GridPtrVec& grids, std::vector<openvdb::GridBase::Ptr>& passedAsRead)
{
    for (size_t i = 0; i < others.grids.size(); ++i) {
        // A shallow copy: the caller's grids keep their transform and metadata.
        openvdb::GridBase::Ptr g = others.grids[i]->copyGrid();
        if (auto half = g->getMetadata<openvdb::BoolMetadata>(kHalfKey)) {
            g->setSaveFloatAsHalf(half->value() || options.halfFloat);
            g->removeMeta(kHalfKey);
        }
        if (others.followFrame[i]) {
            g->setTransform(transformOf(lat));
        } else {
            passedAsRead.push_back(g);
        }
        grids.push_back(g);
    }
}

} // namespace

void writeFrame(
    const std::string& path, const turb::Frame& frame, const WriteOptions& options, const OtherGrids* others)
{
    initOpenVdb();
    if (options.noClobber && fileExists(path)) throw IoError(path + ": exists, not replaced", {"noClobber"});
    if (!frame.hasVelocity() && !frame.hasDensity()) throw IoError(path + ": frame has no grids to write");
    const bool nano = outputFormatFor(path, options.format) == OutputFormat::NanoVdb;
    // Blender's placement offset and simulation box live in metadata, which NanoVDB files cannot hold: such a file
    // would read back shifted.
    if (nano && options.style == WriteStyle::Blender)
        throw turb::ValueError(path + ": NanoVDB output takes the Houdini style (vel in world units per second): "
                                      "the Blender style's placement and domain live in metadata NanoVDB cannot hold",
            {"style"});

    openvdb::GridPtrVec grids;
    const bool blender = options.style == WriteStyle::Blender;
    const double timeUnit = writtenTimeUnit(frame, options);
    const float velocityScale = float(timeUnit / frame.timeUnit);
    // Trimmed (Houdini style only: Blender's staggered faces need whole lines for the exact inverse).
    const bool trim = !blender && options.velocityMargin >= 0 && frame.hasDensity();
    const openvdb::MaskGrid::Ptr inSmoke = trim ? smokeMask(frame, options) : nullptr;
    const openvdb::MaskGrid::Ptr near = trim ? velocityMask(*inSmoke, options) : nullptr;
    if (frame.hasDensity()) grids.push_back(densityGrid(frame, options));
    if (frame.hasVelocity() && options.writeVelocity)
        grids.push_back(velocityGrid(frame, options, near.get(), velocityScale));
    appendScalar(grids, frame.temperature, "temperature", frame, options, inSmoke.get());
    appendScalar(grids, frame.flame, "flame", frame, options, inSmoke.get());
    std::vector<openvdb::GridBase::Ptr> passedAsRead; // not moved by Blender's placement below
    if (others) appendOtherGrids(*others->mImpl, frame.lattice(), options, grids, passedAsRead);

    const openvdb::MetaMap meta = fileMetadata(frame, options, near != nullptr, timeUnit, grids, passedAsRead);
    if (nano) {
        detail::writeNanoVdb(path, {grids, meta}, options.nanoQuantization, options.noClobber);
        return;
    }
    detail::writeFileChecked(
        path, options.noClobber,
        [&](std::ostream& os) {
            CheckedArchive archive;
            archive.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
            archive.writeTo(os, grids, meta);
        },
        /*forkGuarded=*/true);
}

OtherGrids OtherGrids::read(const std::string& path, const ReadOptions& options, const turb::Lattice& frameLattice)
{
    const detail::GuardedResult r = guarded(
        path,
        [&](detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
            openvdb::MetaMap& meta) {
            const std::vector<std::string> names = uniqueNames(listGrids(file, order));
            const std::vector<std::string> taken = takenNames(names, options);
            for (const auto& n : names)
                if (!hasName(taken, n)) out.push_back(readGridNamed(file, path, n));
            if (auto fm = file.getMetadata())
                for (auto it = fm->beginMeta(); it != fm->endMeta(); ++it) meta.insertMeta(it->first, *it->second);
        },
        options.readTimeout);
    OtherGrids o;
    const openvdb::Vec3d offset = blenderOffset(*r.meta); // taken off as readFrame takes it off
    for (const auto& g : r.grids) {
        if (offset != openvdb::Vec3d(0.0)) g->transform().postTranslate(-offset);
        double vs = 0.0;
        turb::Vec3d origin(0.0);
        const bool follows =
            uniformTransform(g->transform(), vs, origin) && turb::Lattice{vs, origin}.approxEqual(frameLattice);
        o.mImpl->grids.push_back(g);
        o.mImpl->followFrame.push_back(follows);
        if (!follows && offset != openvdb::Vec3d(0.0)) g->transform().postTranslate(offset); // written as read
    }
    return o;
}

// ---------------------------------------------------------------------------------------------
// Inspection

namespace {

// The value range, active voxel count and bounding box of a float or vector grid (magnitudes for vectors), from a
// serial pass over its voxels (OpenVDB's own counters use TBB, which a forked child must not), recorded as
// __turb_* metadata on `header`.
void recordValueStatistics(const openvdb::GridBase::Ptr& full, openvdb::GridBase& header)
{
    double lo = 0, hi = 0;
    long long count = 0;
    openvdb::CoordBBox box;
    const auto take = [&](double v, const openvdb::CoordBBox& b) {
        if (count == 0) lo = hi = v;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
        count += (long long)b.volume();
        box.expand(b);
    };
    if (auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(full))
        for (auto it = fg->cbeginValueOn(); it; ++it) take(double(*it), it.getBoundingBox());
    else if (auto dg = openvdb::gridPtrCast<openvdb::DoubleGrid>(full))
        for (auto it = dg->cbeginValueOn(); it; ++it) take(*it, it.getBoundingBox());
    else if (auto vg = openvdb::gridPtrCast<openvdb::Vec3SGrid>(full))
        for (auto it = vg->cbeginValueOn(); it; ++it) take(double(it->length()), it.getBoundingBox());
    else if (auto wg = openvdb::gridPtrCast<openvdb::Vec3DGrid>(full))
        for (auto it = wg->cbeginValueOn(); it; ++it) take(it->length(), it.getBoundingBox());
    if (count > 0) {
        header.insertMeta("__turb_min", openvdb::DoubleMetadata(lo));
        header.insertMeta("__turb_max", openvdb::DoubleMetadata(hi));
        header.insertMeta("__turb_bbox_min", openvdb::Vec3IMetadata(box.min().asVec3i()));
        header.insertMeta("__turb_bbox_max", openvdb::Vec3IMetadata(box.max().asVec3i()));
    }
    header.insertMeta("__turb_count", openvdb::Int64Metadata(count));
}

// The child's part of inspectFile: the file's versions and metadata, and the header of every grid in file order,
// labelled with its unique name and position (two unnamed grids each get their own statistics); with
// `readValues`, each float and vector grid's value statistics.
void readHeaders(detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
    openvdb::MetaMap& meta, const std::string& path, bool readValues)
{
    meta.insertMeta("__turb_file_version", openvdb::Int64Metadata(file.fileVersion()));
    const auto lv = file.libraryVersion();
    meta.insertMeta(
        "__turb_lib_version", openvdb::StringMetadata(std::to_string(lv.first) + "." + std::to_string(lv.second)));
    if (auto fm = file.getMetadata())
        for (auto it = fm->beginMeta(); it != fm->endMeta(); ++it) meta.insertMeta(it->first, *it->second);
    const std::vector<GridEntry> entries = listGrids(file, order);
    // Grids read in the child are never freed there (keepInChild): a file of 10,000 small grids held 3.1 GB for
    // their value ranges. Past this budget the ranges are left unread, and the file says how many.
    constexpr size_t kStatisticsBudget = size_t(1) << 30;
    size_t held = 0;
    int64_t skipped = 0;
    for (size_t i = 0; i < entries.size(); ++i) {
        openvdb::GridBase::Ptr g;
        try {
            g = file.readGridMetadata(entries[i].unique);
        } catch (const std::exception& e) {
            throw IoError(path + ": grid " + quoted(cleanMessage(entries[i].unique)) + " has a damaged header (" +
                          cleanMessage(e.what()) + ")");
        }
        g->insertMeta(kHalfKey, openvdb::BoolMetadata(g->saveFloatAsHalf()));
        g->insertMeta("__turb_unique", openvdb::StringMetadata(entries[i].unique));
        g->insertMeta("__turb_index", openvdb::Int64Metadata(int64_t(i)));
        const std::string type = valueTypeOf(*g);
        const bool scalar = type == "float" || type == "double";
        const bool vector = type == "vec3s" || type == "vec3d";
        if (readValues && (scalar || vector)) {
            if (held < kStatisticsBudget) {
                const openvdb::GridBase::Ptr values = readGridNamed(file, path, entries[i].unique);
                held += size_t(values->memUsage());
                recordValueStatistics(values, *g);
            } else {
                ++skipped;
            }
        }
        out.push_back(g);
    }
    if (skipped > 0) meta.insertMeta("__turb_ranges_skipped", openvdb::Int64Metadata(skipped));
}

// What one grid's header (and the child's __turb_* statistics) says, for FileInfo. `selector` is its unique name;
// Blender's placement offset (`fileMeta`) is taken off its transform as readFrame takes it off.
GridInfo gridInfoOf(
    openvdb::GridBase& g, int index, const std::string& selector, GridRole role, const openvdb::MetaMap& fileMeta)
{
    GridInfo gi;
    gi.index = index;
    if (auto idx = g.getMetadata<openvdb::Int64Metadata>("__turb_index")) gi.index = int(idx->value());
    gi.selector = selector;
    gi.name = g.getName();
    gi.valueType = valueTypeOf(g);
    gi.gridClass = openvdb::GridBase::gridClassToString(g.getGridClass());
    gi.vectorType = openvdb::GridBase::vecTypeToString(g.getVectorType());
    gi.role = role;
    if (auto h = g.getMetadata<openvdb::BoolMetadata>(kHalfKey)) gi.halfFloat = h->value();
    gi.mapType = g.transform().mapType();
    g.transform().postTranslate(-blenderOffset(fileMeta));
    gi.supportedTransform = uniformTransform(g.transform(), gi.voxelSize, gi.origin);
    if (!gi.supportedTransform) {
        gi.voxelSize = g.transform().voxelSize()[0];
        gi.origin = g.transform().indexToWorld(openvdb::Vec3d(0.0));
    }
    if (gi.role == GridRole::Velocity) gi.units = isBlenderVelocity(g) ? "cells" : "world";
    const auto bbox = [&](const char* lo, const char* hi) {
        auto bmin = g.getMetadata<openvdb::Vec3IMetadata>(lo);
        auto bmax = g.getMetadata<openvdb::Vec3IMetadata>(hi);
        if (!bmin || !bmax) return false;
        const auto a = bmin->value(), b = bmax->value();
        gi.activeBBox = turb::CoordBBox(turb::Coord(a.x(), a.y(), a.z()), turb::Coord(b.x(), b.y(), b.z()));
        gi.hasBBox = !gi.activeBBox.empty();
        return true;
    };
    if (!bbox(openvdb::GridBase::META_FILE_BBOX_MIN, openvdb::GridBase::META_FILE_BBOX_MAX))
        bbox("__turb_bbox_min", "__turb_bbox_max");
    if (auto cnt = g.getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_VOXEL_COUNT))
        gi.activeVoxels = cnt->value();
    else if (auto c2 = g.getMetadata<openvdb::Int64Metadata>("__turb_count")) gi.activeVoxels = c2->value();
    if (g.getMetadata<openvdb::DoubleMetadata>("__turb_min")) {
        gi.hasRange = true;
        gi.minValue = g.metaValue<double>("__turb_min");
        gi.maxValue = g.metaValue<double>("__turb_max");
    }
    return gi;
}

} // namespace

FileInfo inspectFile(const std::string& path, bool readValues)
{
    const detail::GuardedResult r =
        guarded(path, [&](detail::GridSource& file, const std::vector<Descriptor>& order, openvdb::GridPtrVec& out,
                          openvdb::MetaMap& meta) { readHeaders(file, order, out, meta, path, readValues); });

    FileInfo info;
    info.path = path;
    info.nanoVdb = bool(r.meta->getMetadata<openvdb::BoolMetadata>("__turb_nanovdb"));
    if (auto m = r.meta->getMetadata<openvdb::Int64Metadata>("__turb_file_version"))
        info.fileVersion = unsigned(m->value());
    if (auto m = r.meta->getMetadata<openvdb::StringMetadata>("__turb_lib_version")) info.libraryVersion = m->value();
    if (auto c = r.meta->getMetadata<openvdb::StringMetadata>("creator")) info.creator = c->value();
    info.recordedDt = metaDouble(*r.meta, turb::meta::kDt, 0.0);
    info.recordedTimeUnit = metaDouble(*r.meta, turb::meta::kTimeUnit, 0.0);
    const auto text = [&](const char* key) {
        const auto m = r.meta->getMetadata<openvdb::StringMetadata>(key);
        return m ? m->value() : std::string();
    };
    info.sourceFrame = text(turb::meta::kSourceFrame);
    info.upAxis = text(turb::meta::kUpAxis);
    info.tileBox = text(turb::meta::kTileBox);
    info.farmTiles = text(turb::meta::kFarmTiles);
    info.tileBorders = text(turb::meta::kTileBorders);
    info.command = text(turb::meta::kCommand);
    info.settings = text(turb::meta::kSettings);
    info.recordedDomain = recordedDomain(*r.meta);
    info.sequenceDomain = recordedDomain(*r.meta, turb::meta::kSequenceDomain);
    info.velocityMargin = int(metaDouble(*r.meta, turb::meta::kVelocityMargin, -1.0));
    if (auto m = r.meta->getMetadata<openvdb::Int64Metadata>("__turb_ranges_skipped"))
        info.rangesSkipped = int(m->value());

    std::vector<std::string> names;
    for (const auto& g : r.grids) {
        auto u = g->getMetadata<openvdb::StringMetadata>("__turb_unique");
        names.push_back(u ? u->value() : g->getName());
    }
    // Each role resolved once: per grid, it was quadratic in the grid count (10,000 grids took seconds).
    std::vector<std::pair<GridRole, std::vector<std::string>>> resolved;
    for (GridRole role : {GridRole::Density, GridRole::Velocity, GridRole::Temperature, GridRole::Flame})
        resolved.emplace_back(role, resolveGrid(names, role));
    const auto roleOfName = [&](const std::string& n) {
        for (const auto& [role, picked] : resolved)
            if (hasName(picked, n)) return role;
        return GridRole::Other;
    };
    for (size_t i = 0; i < r.grids.size(); ++i) {
        info.grids.push_back(gridInfoOf(*r.grids[i], int(i), names[i], roleOfName(names[i]), *r.meta));
        if (auto res = baseResolution(*r.grids[i])) info.baseResolution = res;
    }
    std::sort(
        info.grids.begin(), info.grids.end(), [](const GridInfo& a, const GridInfo& b) { return a.index < b.index; });
    return info;
}

} // namespace turbio
