// The VDB reader/writer. All OpenVDB file handling and cache conventions live here.
#include <turbio/Vdb.h>

#include "GuardedRead.h"

#include <turb/Error.h>

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/Dense.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <functional>
#include <mutex>
#include <sstream>
#include <sys/stat.h>
#include <unistd.h>

namespace turbio {

using turb::IoError;
using detail::cleanMessage;

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
    if (magic != int64_t(0x56444220)) throw IoError(path + ": not an OpenVDB file (bad magic number)");
    if (version > openvdb::OPENVDB_FILE_VERSION) {
        std::ostringstream os;
        os << path << ": written by a newer OpenVDB (file format " << version
           << "); this build uses OpenVDB " << openvdb::getLibraryVersionString() << ", which reads formats up to "
           << openvdb::OPENVDB_FILE_VERSION << ". Re-save the cache from the application that wrote it with an "
           << "OpenVDB 10 compatible format.";
        throw IoError(os.str());
    }
}

// OpenVDB reads raw and compressed chunks without checking for end of file, so a file cut short
// inside its last grid reads "successfully" with garbage. Walk the grid descriptors (the layout of
// io::Archive::readHeader and io::GridDescriptor::read) and check every grid ends inside the file.
void checkGridExtents(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) return;
    const int64_t size = fileSize(path);
    const auto corrupt = [&](const std::string& why) {
        return IoError(path + ": truncated or corrupt file (" + why + ")");
    };
    const auto readRaw = [&](void* p, size_t n) {
        in.read(static_cast<char*>(p), std::streamsize(n));
        if (!in) throw corrupt("header ends early");
    };
    const auto readString = [&]() {
        uint32_t n = 0;
        readRaw(&n, 4);
        if (int64_t(n) > size) throw corrupt("bad string length in header");
        std::string str(n, '\0');
        if (n) readRaw(&str[0], n);
        return str;
    };
    int64_t magic = 0;
    uint32_t version = 0, major = 0, minor = 0;
    readRaw(&magic, 8);
    readRaw(&version, 4);
    if (version < 222) return; // older layouts are not walked; the guarded reader still applies
    readRaw(&major, 4);
    readRaw(&minor, 4);
    char hasOffsets = 0;
    readRaw(&hasOffsets, 1);
    char uuid[36];
    readRaw(uuid, 36);
    uint32_t metaCount = 0;
    readRaw(&metaCount, 4);
    for (uint32_t m = 0; m < metaCount; ++m) {
        readString(); // name
        readString(); // type
        readString(); // value, stored as size + bytes
    }
    if (!hasOffsets) return;
    uint32_t gridCount = 0;
    readRaw(&gridCount, 4);
    for (uint32_t g = 0; g < gridCount; ++g) {
        const std::string name = readString();
        readString(); // type
        readString(); // instance parent
        int64_t gridPos = 0, blockPos = 0, endPos = 0;
        readRaw(&gridPos, 8);
        readRaw(&blockPos, 8);
        readRaw(&endPos, 8);
        const int64_t here = int64_t(in.tellg());
        if (gridPos < here || blockPos < gridPos || endPos < blockPos)
            throw corrupt("grid descriptor " + std::to_string(g) + " has inconsistent offsets");
        if (endPos > size)
            throw IoError(path + ": truncated file: grid '" + cleanMessage(name) + "' ends at byte " +
                          std::to_string(endPos) + " but the file has " + std::to_string(size) + " bytes");
        in.seekg(endPos);
    }
}

// Runs a read body on `path` in the guarded child after the cheap in-process checks.
detail::GuardedResult guarded(const std::string& path, const detail::ReadBody& body)
{
    initOpenVdb();
    checkHeader(path);
    checkGridExtents(path);
    // Generous: a healthy read runs at hundreds of MB/s, even slow farm storage at 5 MB/s passes; only a
    // reader stuck in a loop hits this.
    const double timeout = 10.0 + double(std::max<int64_t>(fileSize(path), 0)) / 5.0e6;
    return detail::guardedRead(path, body, timeout);
}

// --- helpers that run inside the reader child (no TBB) ---

std::vector<std::string> gridNames(openvdb::io::File& file)
{
    std::vector<std::string> names;
    for (auto it = file.beginName(); it != file.endName(); ++it) names.push_back(*it);
    return names;
}

openvdb::GridBase::Ptr readGridNamed(openvdb::io::File& file, const std::string& path, const std::string& name)
{
    try {
        auto g = file.readGrid(name);
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

std::string joinNames(const std::vector<std::string>& names)
{
    std::string s;
    for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
    return s.empty() ? "(none)" : s;
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
    if (!uniformTransform(g.transform(), vs, o)) {
        std::ostringstream os;
        os << path << ": grid " << quoted(g.getName()) << " has a " << g.transform().mapType()
           << " transform with non-uniform scale, rotation, shear or perspective; vdbturb supports only "
              "uniform voxels with a translation. Resample the cache (e.g. Houdini VDB Resample) first.";
        throw IoError(os.str());
    }
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

bool isBlenderVelocity(const openvdb::GridBase& g)
{
    return g.getName() == "velocity" && g.getGridClass() == openvdb::GRID_STAGGERED && baseResolution(g).has_value();
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
        auto out = openvdb::Vec3SGrid::create(openvdb::Vec3s(dg->background()));
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
    const turb::CoordBBox b = f.bbox();
    std::vector<size_t> front;
    std::vector<turb::Vec3f> values;
    for (int layer = 0; layer < layers; ++layer) {
        front.clear();
        values.clear();
        for (size_t n = 0; n < f.size(); ++n) {
            if (known[n]) continue;
            const turb::Coord c = f.coordOf(n);
            turb::Vec3f sum(0.0f);
            int cnt = 0;
            for (int a = 0; a < 3; ++a)
                for (int d : {-1, 1}) {
                    turb::Coord q = c;
                    q[a] += d;
                    if (!b.isInside(q)) continue;
                    const size_t m = f.offset(q.x(), q.y(), q.z());
                    if (!known[m]) continue;
                    sum += f.data()[m];
                    ++cnt;
                }
            if (cnt) {
                front.push_back(n);
                values.push_back(sum / float(cnt));
            }
        }
        if (front.empty()) break;
        for (size_t i = 0; i < front.size(); ++i) {
            f.data()[front[i]] = values[i];
            known[front[i]] = 1;
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
        } catch (...) {
        }
    }
    return fallback;
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

std::vector<std::string> resolveGrid(const std::vector<std::string>& names, GridRole role,
    const std::string& overrideName)
{
    const auto components = [&](const std::string& stem) -> std::vector<std::string> {
        const std::vector<std::string> c{stem + ".x", stem + ".y", stem + ".z"};
        if (hasName(names, c[0]) && hasName(names, c[1]) && hasName(names, c[2])) return c;
        return {};
    };
    if (!overrideName.empty()) {
        if (hasName(names, overrideName)) return {overrideName};
        if (role == GridRole::Velocity) return components(overrideName);
        return {};
    }
    for (const auto& a : gridAliases(role))
        if (hasName(names, a)) return {a};
    if (role == GridRole::Velocity)
        for (const auto& a : gridAliases(role))
            if (auto c = components(a); !c.empty()) return c;
    return {};
}

static turb::Frame readFrameUnchecked(const std::string& path, int frameNumber, const ReadOptions& options);

turb::Frame readFrame(const std::string& path, int frameNumber, const ReadOptions& options)
{
    try {
        return readFrameUnchecked(path, frameNumber, options);
    } catch (const std::bad_alloc&) {
        throw IoError(path + ": not enough memory to load the frame");
    }
}

static turb::Frame readFrameUnchecked(const std::string& path, int frameNumber, const ReadOptions& options)
{
    // Child: resolve names and read just the grids we need, labelled with their role.
    const auto body = [&](openvdb::io::File& file, openvdb::GridPtrVec& out, openvdb::MetaMap& meta) {
        const std::vector<std::string> names = gridNames(file);
        const auto densName = resolveGrid(names, GridRole::Density, options.densityGrid);
        const auto velName = resolveGrid(names, GridRole::Velocity, options.velocityGrid);
        if (densName.empty() && (options.requireDensity || !options.densityGrid.empty())) {
            const std::string wanted = options.densityGrid.empty() ? "density (density, density_noise)"
                                                                   : quoted(options.densityGrid);
            throw IoError(path + ": no " + wanted + " grid; the file has: " + joinNames(names) +
                          ". Use --density-grid NAME.");
        }
        if (velName.empty() && (options.requireVelocity || !options.velocityGrid.empty())) {
            const std::string wanted = options.velocityGrid.empty()
                                           ? "velocity (vel, velocity, v, or vel.x/vel.y/vel.z)"
                                           : quoted(options.velocityGrid);
            throw IoError(path + ": no " + wanted + " grid; the file has: " + joinNames(names) +
                          ". Use --vel-grid NAME.");
        }
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
        if (auto fm = file.getMetadata())
            for (auto it = fm->beginMeta(); it != fm->endMeta(); ++it) meta.insertMeta(it->first, *it->second);
    };
    const detail::GuardedResult r = guarded(path, body);

    openvdb::FloatGrid::Ptr density, temperature, flame;
    openvdb::Vec3SGrid::Ptr vel;
    openvdb::FloatGrid::Ptr comp[3];
    for (const auto& g : r.grids) {
        const std::string role = roleOf(*g);
        if (role == "density") density = asFloatGrid(path, g, "density");
        else if (role == "velocity") vel = asVec3Grid(path, g);
        else if (role == "velocity.x") comp[0] = asFloatGrid(path, g, "velocity component");
        else if (role == "velocity.y") comp[1] = asFloatGrid(path, g, "velocity component");
        else if (role == "velocity.z") comp[2] = asFloatGrid(path, g, "velocity component");
        else if (role == "temperature") temperature = asFloatGrid(path, g, "temperature");
        else if (role == "flame") flame = asFloatGrid(path, g, "flame");
    }

    // One lattice for the frame; every grid must agree.
    std::vector<openvdb::GridBase::ConstPtr> all;
    for (const auto& g : {openvdb::GridBase::ConstPtr(density), openvdb::GridBase::ConstPtr(vel),
             openvdb::GridBase::ConstPtr(comp[0]), openvdb::GridBase::ConstPtr(comp[1]),
             openvdb::GridBase::ConstPtr(comp[2]), openvdb::GridBase::ConstPtr(temperature),
             openvdb::GridBase::ConstPtr(flame)})
        if (g) all.push_back(g);
    if (all.empty()) throw IoError(path + ": none of the requested grids is present");
    const turb::Lattice lattice = latticeOf(path, *all.front());
    for (const auto& g : all) {
        const turb::Lattice l = latticeOf(path, *g);
        if (!l.approxEqual(lattice)) {
            std::ostringstream os;
            os << path << ": grid " << quoted(g->getName()) << " (voxel " << l.voxelSize << ", origin " << l.origin
               << ") does not share the transform of grid " << quoted(all.front()->getName()) << " (voxel "
               << lattice.voxelSize << ", origin " << lattice.origin
               << "); vdbturb needs all grids of a frame on one lattice";
            throw IoError(os.str());
        }
    }

    // Domain: Blender records its full simulation box; otherwise the union of the grids' active boxes.
    turb::CoordBBox domain;
    std::optional<turb::Coord> baseRes;
    for (const auto& g : all)
        if (auto res = baseResolution(*g)) baseRes = res;
    if (baseRes) domain = turb::CoordBBox(turb::Coord(0), *baseRes - turb::Coord(1));
    for (const auto& g : all) {
        const turb::CoordBBox b = g->evalActiveVoxelBoundingBox();
        if (!b.empty()) domain.expand(b);
    }
    if (domain.empty()) domain = turb::CoordBBox(turb::Coord(0), turb::Coord(0)); // every grid is empty
    if (double(domain.volume()) > options.maxVoxels) {
        std::ostringstream os;
        os << path << ": the grids span " << domain << " (" << double(domain.volume())
           << " voxels), more than the " << options.maxVoxels
           << " voxels vdbturb holds densely; a damaged file, or a cache too large for this tool";
        throw IoError(os.str());
    }

    turb::Frame frame;
    frame.number = frameNumber;
    if (density) {
        frame.density = turb::ScalarField(domain, lattice);
        copyToField(*density, frame.density);
        if (options.checkFinite) requireFinite(path, density->getName(), frame.density);
    }
    if (vel || comp[0]) {
        frame.velocity = turb::VectorField(domain, lattice);
        bool cells = false;
        std::string velLabel;
        if (vel) {
            velLabel = vel->getName();
            if (vel->getGridClass() == openvdb::GRID_STAGGERED) staggeredToCentred(*vel, frame.velocity);
            else copyToField(*vel, frame.velocity);
            cells = isBlenderVelocity(*vel);
        } else {
            velLabel = comp[0]->getName() + "/.y/.z";
            turb::ScalarField c(domain, lattice);
            for (int a = 0; a < 3; ++a) {
                c.fill(0.0f);
                copyToField(*comp[a], c);
                for (size_t n = 0; n < c.size(); ++n) frame.velocity.data()[n][a] = c.data()[n];
            }
        }
        if (options.velocityUnits == VelocityUnits::Cells) cells = true;
        if (options.velocityUnits == VelocityUnits::World) cells = false;
        if (cells) {
            const float s = float(lattice.voxelSize);
            for (auto& v : frame.velocity.values()) v *= s;
        }
        if (options.checkFinite) requireFinite(path, velLabel, frame.velocity);
        if (options.extendVelocity > 0) {
            // Known = active in the file. Blender (and sparse Houdini vel) store velocity only near the
            // smoke; the zeros beyond are "unknown", and would read as a velocity jump at the smoke's edge.
            std::vector<uint8_t> known(frame.velocity.size(), 0);
            const auto mark = [&](const openvdb::GridBase& g) {
                const CoordBBoxCallback cb = [&](const openvdb::CoordBBox& b) {
                    openvdb::CoordBBox c = b;
                    c.intersect(domain);
                    for (auto it = c.begin(); it; ++it) known[frame.velocity.offset((*it).x(), (*it).y(), (*it).z())] = 1;
                };
                forEachActiveBox(g, cb);
            };
            if (vel) mark(*vel);
            else
                for (const auto& c : comp) mark(*c);
            extendIntoUnknown(frame.velocity, known, options.extendVelocity);
        }
        frame.metadata["vdbturb_input_velocity_units"] = cells ? "cells" : "world";
    }
    const auto extra = [&](const openvdb::FloatGrid::Ptr& g, std::optional<turb::ScalarField>& dst) {
        if (!g) return;
        dst = turb::ScalarField(domain, lattice);
        copyToField(*g, *dst);
        if (options.checkFinite) requireFinite(path, g->getName(), *dst);
    };
    extra(temperature, frame.temperature);
    extra(flame, frame.flame);

    // File-level string metadata (vdbturb parameters, creator) travels with the frame.
    for (auto it = r.meta->beginMeta(); it != r.meta->endMeta(); ++it)
        if (it->second && it->second->typeName() == openvdb::StringMetadata::staticTypeName())
            frame.metadata[it->first] = it->second->str();

    // Time per frame: explicit option > recorded by vdbturb > the writer's convention.
    double dt = metaDouble(*r.meta, "vdbturb_dt", 0.0);
    if (options.dt > 0.0) dt = options.dt;
    else if (dt <= 0.0) {
        // Blender/Mantaflow: frame_length = 0.1 * (25 / fps) * time_scale, in Mantaflow time units
        // (time_scale assumed 1). Houdini and most others: seconds.
        dt = baseRes ? 0.1 * 25.0 / options.fps : 1.0 / options.fps;
    }
    frame.dt = dt;
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

bool fileExists(const std::string& path)
{
    struct stat st;
    return ::stat(path.c_str(), &st) == 0;
}

void fsyncPath(const std::string& path)
{
    const int fd = ::open(path.c_str(), O_RDONLY);
    if (fd >= 0) {
        ::fsync(fd);
        ::close(fd);
    }
}

// Moves a finished temporary file into place. With noClobber, link() fails instead of replacing.
void commitTemp(const std::string& tmp, const std::string& path, bool noClobber)
{
    fsyncPath(tmp);
    if (noClobber) {
        if (::link(tmp.c_str(), path.c_str()) != 0) {
            const int err = errno;
            ::unlink(tmp.c_str());
            if (err == EEXIST) throw IoError(path + ": exists, not replaced (--no-clobber)");
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
    auto grid = GridT::create(turb::Field<T>::zeroValue());
    // copyFromDense only reads; Dense has no const-value variant.
    openvdb::tools::Dense<T, openvdb::tools::LayoutZYX> dense(field.bbox(), const_cast<T*>(field.data()));
    openvdb::tools::copyFromDense(dense, *grid, tolerance);
    grid->setTransform(transformOf(field.lattice()));
    return grid;
}

// MAC velocity from cell-centred: the face i-1/2 value averages the centres i-1 and i.
openvdb::Vec3SGrid::Ptr centredToStaggered(const turb::VectorField& v, float scale)
{
    turb::VectorField mac(v.bbox(), v.lattice());
    const turb::CoordBBox& b = v.bbox();
    for (int i = b.min().x(); i <= b.max().x(); ++i)
        for (int j = b.min().y(); j <= b.max().y(); ++j)
            for (int k = b.min().z(); k <= b.max().z(); ++k) {
                const turb::Vec3f c = v(i, j, k);
                turb::Vec3f face;
                face[0] = 0.5f * (c[0] + v.valueOr(i - 1, j, k, c)[0]);
                face[1] = 0.5f * (c[1] + v.valueOr(i, j - 1, k, c)[1]);
                face[2] = 0.5f * (c[2] + v.valueOr(i, j, k - 1, c)[2]);
                mac(i, j, k) = face * scale;
            }
    return fieldToGrid<openvdb::Vec3SGrid>(mac, turb::Vec3f(0.0f));
}

} // namespace

void writeFileAtomic(const std::string& path, const std::string& bytes, bool noClobber)
{
    if (noClobber && fileExists(path)) throw IoError(path + ": exists, not replaced (--no-clobber)");
    const std::string tmp = tempPathFor(path);
    FILE* fp = std::fopen(tmp.c_str(), "wb");
    if (!fp) throw IoError(path + ": cannot write (" + std::strerror(errno) + ")");
    const size_t n = std::fwrite(bytes.data(), 1, bytes.size(), fp);
    const bool ok = (n == bytes.size()) && std::fflush(fp) == 0;
    const int err = errno;
    std::fclose(fp);
    if (!ok) {
        ::unlink(tmp.c_str());
        throw IoError(path + ": write failed (" + std::strerror(err) + ")");
    }
    commitTemp(tmp, path, noClobber);
}

void writeAtomically(const std::string& path, bool noClobber, const std::function<void(const std::string& tmp)>& write)
{
    if (noClobber && fileExists(path)) throw IoError(path + ": exists, not replaced (--no-clobber)");
    const std::string tmp = tempPathFor(path);
    try {
        write(tmp);
    } catch (...) {
        ::unlink(tmp.c_str());
        throw;
    }
    if (!fileExists(tmp)) throw IoError(path + ": the writer produced no file");
    commitTemp(tmp, path, noClobber);
}

void writeFrame(const std::string& path, const turb::Frame& frame, const WriteOptions& options)
{
    initOpenVdb();
    if (options.noClobber && fileExists(path)) throw IoError(path + ": exists, not replaced (--no-clobber)");
    if (!frame.hasVelocity() && !frame.hasDensity()) throw IoError(path + ": frame has no grids to write");

    openvdb::GridPtrVec grids;
    const bool blender = options.style == WriteStyle::Blender;
    const turb::Lattice& lat = frame.lattice();
    const turb::Coord res = frame.bbox().dim();

    const auto addBlenderMeta = [&](openvdb::GridBase& g) {
        g.insertMeta("file_base_resolution", openvdb::Vec3IMetadata(openvdb::Vec3i(res.x(), res.y(), res.z())));
        g.insertMeta("file_voxel_size", openvdb::FloatMetadata(float(lat.voxelSize)));
    };

    if (frame.hasDensity()) {
        auto g = fieldToGrid<openvdb::FloatGrid>(frame.density, options.densityTolerance);
        g->setName("density");
        g->setGridClass(openvdb::GRID_FOG_VOLUME);
        g->setSaveFloatAsHalf(options.halfFloat);
        if (blender) addBlenderMeta(*g);
        grids.push_back(g);
    }
    if (frame.hasVelocity()) {
        openvdb::Vec3SGrid::Ptr g;
        if (blender) {
            g = centredToStaggered(frame.velocity, float(1.0 / lat.voxelSize));
            g->setName("velocity");
            g->setGridClass(openvdb::GRID_STAGGERED);
            addBlenderMeta(*g);
        } else {
            g = fieldToGrid<openvdb::Vec3SGrid>(frame.velocity, turb::Vec3f(0.0f));
            g->setName("vel");
            g->setGridClass(openvdb::GRID_UNKNOWN);
        }
        g->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
        g->setSaveFloatAsHalf(options.halfFloat);
        grids.push_back(g);
    }
    const auto addScalar = [&](const std::optional<turb::ScalarField>& f, const char* name) {
        if (!f || f->empty()) return;
        auto g = fieldToGrid<openvdb::FloatGrid>(*f, 0.0f);
        g->setName(name);
        g->setGridClass(openvdb::GRID_FOG_VOLUME);
        g->setSaveFloatAsHalf(options.halfFloat);
        if (blender) addBlenderMeta(*g);
        grids.push_back(g);
    };
    addScalar(frame.temperature, "temperature");
    addScalar(frame.flame, "flame");

    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("vdbturb " VDBTURB_VERSION_STRING));
    for (const auto& kv : frame.metadata) {
        if (kv.first == "creator") continue;
        meta.insertMeta(kv.first, openvdb::StringMetadata(kv.second));
    }
    if (frame.dt > 0.0) {
        std::ostringstream os;
        os.precision(17);
        os << frame.dt;
        meta.insertMeta("vdbturb_dt", openvdb::StringMetadata(os.str()));
    }

    const std::string tmp = tempPathFor(path);
    try {
        openvdb::io::File file(tmp);
        file.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
        file.write(grids, meta);
        file.close();
    } catch (const std::exception& e) {
        ::unlink(tmp.c_str());
        throw IoError(path + ": write failed (" + e.what() + ")");
    }
    struct stat st;
    if (::stat(tmp.c_str(), &st) != 0 || st.st_size == 0) {
        ::unlink(tmp.c_str());
        throw IoError(path + ": write failed (empty file; disk full or directory not writable?)");
    }
    commitTemp(tmp, path, options.noClobber);
}

// ---------------------------------------------------------------------------------------------
// Inspection

FileInfo inspectFile(const std::string& path, bool readValues)
{
    // Child: headers of every grid, and with readValues a serial pass over each float/vector grid for
    // its range, count and bounding box (OpenVDB's own counters use TBB, which a forked child must not).
    const auto body = [&](openvdb::io::File& file, openvdb::GridPtrVec& out, openvdb::MetaMap& meta) {
        meta.insertMeta("__turb_file_version", openvdb::Int64Metadata(file.fileVersion()));
        const auto lv = file.libraryVersion();
        meta.insertMeta("__turb_lib_version",
            openvdb::StringMetadata(std::to_string(lv.first) + "." + std::to_string(lv.second)));
        if (auto fm = file.getMetadata())
            for (auto it = fm->beginMeta(); it != fm->endMeta(); ++it) meta.insertMeta(it->first, *it->second);
        openvdb::GridPtrVecPtr metas = file.readAllGridMetadata();
        for (const auto& g : *metas) {
            g->insertMeta(kHalfKey, openvdb::BoolMetadata(g->saveFloatAsHalf()));
            const std::string type = g->valueType();
            const bool scalar = type == "float" || type == "double";
            const bool vector = type == "vec3s" || type == "vec3d";
            if (readValues && (scalar || vector)) {
                auto full = readGridNamed(file, path, g->getName());
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
                    g->insertMeta("__turb_min", openvdb::DoubleMetadata(lo));
                    g->insertMeta("__turb_max", openvdb::DoubleMetadata(hi));
                    g->insertMeta("__turb_bbox_min", openvdb::Vec3IMetadata(box.min().asVec3i()));
                    g->insertMeta("__turb_bbox_max", openvdb::Vec3IMetadata(box.max().asVec3i()));
                }
                g->insertMeta("__turb_count", openvdb::Int64Metadata(count));
            }
            out.push_back(g);
        }
    };
    const detail::GuardedResult r = guarded(path, body);

    FileInfo info;
    info.path = path;
    if (auto m = r.meta->getMetadata<openvdb::Int64Metadata>("__turb_file_version")) info.fileVersion = unsigned(m->value());
    if (auto m = r.meta->getMetadata<openvdb::StringMetadata>("__turb_lib_version")) info.libraryVersion = m->value();
    if (auto c = r.meta->getMetadata<openvdb::StringMetadata>("creator")) info.creator = c->value();

    std::vector<std::string> names;
    for (const auto& g : r.grids) names.push_back(g->getName());
    const auto roleOfName = [&](const std::string& n) {
        for (GridRole role : {GridRole::Density, GridRole::Velocity, GridRole::Temperature, GridRole::Flame})
            if (hasName(resolveGrid(names, role), n)) return role;
        return GridRole::Other;
    };
    for (const auto& g : r.grids) {
        GridInfo gi;
        gi.name = g->getName();
        gi.valueType = g->valueType();
        gi.gridClass = openvdb::GridBase::gridClassToString(g->getGridClass());
        gi.vectorType = openvdb::GridBase::vecTypeToString(g->getVectorType());
        gi.role = roleOfName(gi.name);
        if (auto h = g->getMetadata<openvdb::BoolMetadata>(kHalfKey)) gi.halfFloat = h->value();
        gi.mapType = g->transform().mapType();
        gi.supportedTransform = uniformTransform(g->transform(), gi.voxelSize, gi.origin);
        if (!gi.supportedTransform) {
            gi.voxelSize = g->transform().voxelSize()[0];
            gi.origin = g->transform().indexToWorld(openvdb::Vec3d(0.0));
        }
        if (gi.role == GridRole::Velocity) gi.units = isBlenderVelocity(*g) ? "cells" : "world";
        if (auto res = baseResolution(*g)) info.baseResolution = res;
        const auto bbox = [&](const char* lo, const char* hi) {
            auto bmin = g->getMetadata<openvdb::Vec3IMetadata>(lo);
            auto bmax = g->getMetadata<openvdb::Vec3IMetadata>(hi);
            if (!bmin || !bmax) return false;
            const auto a = bmin->value(), b = bmax->value();
            gi.activeBBox = turb::CoordBBox(turb::Coord(a.x(), a.y(), a.z()), turb::Coord(b.x(), b.y(), b.z()));
            gi.hasBBox = !gi.activeBBox.empty();
            return true;
        };
        if (!bbox(openvdb::GridBase::META_FILE_BBOX_MIN, openvdb::GridBase::META_FILE_BBOX_MAX))
            bbox("__turb_bbox_min", "__turb_bbox_max");
        if (auto cnt = g->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_VOXEL_COUNT))
            gi.activeVoxels = cnt->value();
        else if (auto c2 = g->getMetadata<openvdb::Int64Metadata>("__turb_count"))
            gi.activeVoxels = c2->value();
        if (g->getMetadata<openvdb::DoubleMetadata>("__turb_min")) {
            gi.hasRange = true;
            gi.minValue = g->metaValue<double>("__turb_min");
            gi.maxValue = g->metaValue<double>("__turb_max");
        }
        info.grids.push_back(gi);
    }
    return info;
}

} // namespace turbio
