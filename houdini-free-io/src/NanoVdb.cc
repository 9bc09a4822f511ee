// NanoVDB output and headers. NanoVDB's converter is template-heavy: it is included here only, so one translation
// unit pays for it. The converted grids are written through the VDB writer's checked atomic write (GridSet.h).
#include <turbio/NanoVdb.h>

#include "GridSet.h"
#include "GuardedRead.h"

#include <turb/Error.h>

// NanoVDB's parallel loops (leaf encoding, statistics, checksums) run on TBB, so --threads bounds them as it bounds
// the rest; without this they start hardware_concurrency()/2 std::threads of their own. Results do not depend on it.
#define NANOVDB_USE_TBB
#include <nanovdb/NanoVDB.h>
#include <nanovdb/util/IO.h>
#include <nanovdb/util/OpenToNanoVDB.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sys/stat.h>

namespace turbio {

using detail::cleanMessage;
using turb::IoError;

namespace {

std::string inQuotes(const std::string& s) { return "'" + s + "'"; }

const char* typeName(nanovdb::GridType t)
{
    static const char* const names[] = {"unknown", "float", "double", "int16", "int32", "int64", "vec3f", "vec3d",
        "mask", "half", "uint32", "bool", "rgba8", "fp4", "fp8", "fp16", "fpN", "vec4f", "vec4d", "index"};
    const auto i = size_t(t);
    return i < sizeof(names) / sizeof(names[0]) ? names[i] : "unknown";
}

const char* className(nanovdb::GridClass c)
{
    static const char* const names[] = {"unknown", "level set", "fog volume", "staggered", "point index", "point data",
        "topology", "voxel volume", "index"};
    const auto i = size_t(c);
    return i < sizeof(names) / sizeof(names[0]) ? names[i] : "unknown";
}

// One OpenVDB grid as NanoVDB: float grids other than level sets quantised as asked (a level set's far markers,
// Blender's 1e4, would spread each leaf's range over the whole quantisation), every grid with its statistics and
// a full checksum (nanovdb_validate checks every node against it). A tree of tiles without a leaf (Blender's constant
// `shadow`) gets the partial one, over its headers, as nanovdb_convert writes: NanoVDB 10.0.1's full checksum
// takes the address of the first leaf, and Debian's nanovdb_validate (built with assertions) aborts there.
nanovdb::GridHandle<> toNano(const openvdb::GridBase::Ptr& g, NanoQuantization q)
{
    constexpr auto stats = nanovdb::StatsMode::Default; // bbox, min/max, average and deviation
    const bool tilesOnly = g->baseTree().leafCount() == 0;
    const auto crc = tilesOnly ? nanovdb::ChecksumMode::Partial : nanovdb::ChecksumMode::Full;
    if (!g->transform().baseMap()->isLinear())
        throw IoError("a " + g->transform().mapType() + " transform (NanoVDB holds affine transforms only)");
    if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(g); f && f->getGridClass() != openvdb::GRID_LEVEL_SET) {
        if (q == NanoQuantization::Fp16)
            return nanovdb::openToNanoVDB<nanovdb::HostBuffer, openvdb::FloatTree, nanovdb::Fp16>(*f, stats, crc);
        if (q == NanoQuantization::Fp8)
            return nanovdb::openToNanoVDB<nanovdb::HostBuffer, openvdb::FloatTree, nanovdb::Fp8>(*f, stats, crc);
    }
    return nanovdb::openToNanoVDB(g, stats, crc);
}

std::string gridLabel(const openvdb::GridBase& g)
{
    return g.getName().empty() ? std::string("(unnamed)") : inQuotes(g.getName());
}

// The grids of `set` as NanoVDB, in order, with a description of each ("'density' fp16 fog volume"). A grid NanoVDB
// cannot hold is an IoError naming `path` and the grid, or, with `skipped`, left out and described there.
std::vector<nanovdb::GridHandle<>> convertAll(const std::string& path, const detail::GridSet& set, NanoQuantization q,
    std::vector<std::string>* written, std::vector<std::string>* skipped)
{
    std::vector<nanovdb::GridHandle<>> handles;
    for (const auto& g : set.grids) {
        try {
            handles.push_back(toNano(g, q));
        } catch (const std::exception& e) {
            const std::string why = detail::cleanMessage(e.what());
            if (!skipped)
                throw IoError(path + ": grid " + gridLabel(*g) + " (" + g->valueType() +
                              ") cannot be written as NanoVDB: " + why);
            skipped->push_back(gridLabel(*g) + " (" + g->valueType() + ": " + why + ")");
            continue;
        }
        if (written) {
            const nanovdb::GridMetaData* m = handles.back().gridMetaData();
            written->push_back(gridLabel(*g) + " " + typeName(m->gridType()) + " " + className(m->gridClass()));
        }
    }
    return handles;
}

// NaN or Inf among a float or vector grid's active values (voxels and tiles) is an IoError naming the grid, worded as
// the frame reader's: a renderer given one draws nothing or garbage there.
void requireFinite(const std::string& path, const openvdb::GridBase::Ptr& g)
{
    long long bad = 0;
    openvdb::Coord first;
    const auto scan = [&](const auto& grid) {
        for (auto it = grid.cbeginValueOn(); it; ++it) {
            bool ok = true;
            if constexpr (openvdb::VecTraits<std::decay_t<decltype(*it)>>::IsVec) {
                for (int a = 0; a < 3; ++a) ok = ok && std::isfinite((*it)[a]);
            } else {
                ok = std::isfinite(*it);
            }
            if (!ok && bad++ == 0) first = it.getCoord();
        }
    };
    if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(g)) scan(*f);
    else if (auto d = openvdb::GridBase::grid<openvdb::DoubleGrid>(g)) scan(*d);
    else if (auto v = openvdb::GridBase::grid<openvdb::Vec3SGrid>(g)) scan(*v);
    else if (auto w = openvdb::GridBase::grid<openvdb::Vec3DGrid>(g)) scan(*w);
    if (bad > 0)
        throw IoError(path + ": grid " + gridLabel(*g) + " has " + std::to_string(bad) + " NaN/Inf voxel" +
                      (bad > 1 ? "s" : "") + " (first at [" + std::to_string(first.x()) + ", " +
                      std::to_string(first.y()) + ", " + std::to_string(first.z()) + "])");
}

long long fileBytes(const std::string& path)
{
    struct stat st;
    return ::stat(path.c_str(), &st) == 0 ? (long long)st.st_size : -1;
}

} // namespace

namespace detail {

void writeNanoVdb(const std::string& path, const GridSet& set, NanoQuantization quantization, bool noClobber)
{
    // Every grid is converted before the file is opened: a grid NanoVDB cannot hold leaves nothing behind.
    const std::vector<nanovdb::GridHandle<>> handles = convertAll(path, set, quantization, nullptr, nullptr);
    if (handles.empty()) throw IoError(path + ": no grids to write");
    // Uncompressed, as renderers map and upload it: NanoVDB's Blosc and zip codecs need a reader built with them.
    writeFileChecked(path, noClobber, [&](std::ostream& os) { nanovdb::io::writeGrids(os, handles); });
}

} // namespace detail

std::string nanoVdbCannotHold(const GridInfo& grid)
{
    // The types nanovdb::openToNanoVDB (10.0.1) converts, as OpenVDB names them.
    static const char* const held[] = {"float", "double", "int32", "int64", "uint32", "vec3s", "vec3d", "mask", "bool",
        "vec4s", "vec4d", "ptidx32", "ptdataidx32"};
    if (std::find(std::begin(held), std::end(held), grid.valueType) == std::end(held))
        return "a " + grid.valueType + " grid (NanoVDB has no such grid type)";
    if (grid.mapType.find("Frustum") != std::string::npos)
        return "a " + grid.mapType + " transform (NanoVDB holds affine transforms only)";
    return "";
}

bool isNanoVdbPath(const std::string& path) { return outputFormatFor(path) == OutputFormat::NanoVdb; }

bool isNanoVdbFile(const std::string& path)
{
    char head[8] = {};
    std::ifstream in(path, std::ios::binary);
    in.read(head, sizeof(head));
    return in && std::memcmp(head, "NanoVDB", 7) == 0;
}

const char* quantizationName(NanoQuantization q)
{
    switch (q) {
    case NanoQuantization::Fp16: return "fp16";
    case NanoQuantization::Fp8: return "fp8";
    default: return "float";
    }
}

NanoConvertReport convertToNanoVdb(
    const std::string& vdbPath, const std::string& nvdbPath, const NanoConvertOptions& options)
{
    if (options.noClobber && fileBytes(nvdbPath) >= 0)
        throw IoError(nvdbPath + ": exists, not replaced", {"noClobber"});
    const detail::GridSet set = detail::readEveryGrid(vdbPath, options.readTimeout);
    if (set.grids.empty()) throw IoError(vdbPath + ": holds no grids to convert");
    for (const auto& g : set.grids) requireFinite(vdbPath, g);
    NanoConvertReport report;
    const std::vector<nanovdb::GridHandle<>> handles =
        convertAll(vdbPath, set, options.quantization, &report.grids, &report.skipped);
    if (handles.empty())
        throw IoError(vdbPath + ": no grid NanoVDB can hold: " + report.skipped.front() + " (" +
                      std::to_string(report.skipped.size()) + " grids)");
    detail::writeFileChecked(
        nvdbPath, options.noClobber, [&](std::ostream& os) { nanovdb::io::writeGrids(os, handles); });
    report.bytes = fileBytes(nvdbPath);
    return report;
}

// ---------------------------------------------------------------------------------------------
// Headers (vdbturb info). NanoVDB's own reader trusts the file's sizes (a damaged name length allocates gigabytes,
// a damaged grid size reads past the buffer): here every size is checked against the bytes left first, and no
// pointer inside a grid is followed; only the grid's fixed-size header (GridData) is read, for its transform.

namespace {

class Bounded
{
public:
    Bounded(const std::string& path) : mPath(path), mIn(path, std::ios::binary)
    {
        if (!mIn) throw IoError(path + ": cannot open (" + std::strerror(errno) + ")");
        mIn.seekg(0, std::ios::end);
        mSize = (long long)mIn.tellg();
        mIn.seekg(0);
    }
    long long size() const { return mSize; }
    long long pos() const { return mPos; }
    long long left() const { return mSize - mPos; }
    // Reads `n` bytes at the current position; `what` names them in the error of a file that ends first.
    void read(void* dst, long long n, const std::string& what)
    {
        if (n < 0 || n > left())
            throw IoError(mPath + ": truncated or damaged NanoVDB file: " + what + " needs " + std::to_string(n) +
                          " bytes at byte " + std::to_string(mPos) + " but the file has " + std::to_string(mSize));
        mIn.seekg(mPos);
        mIn.read(static_cast<char*>(dst), std::streamsize(n));
        if (!mIn) throw IoError(mPath + ": cannot read (" + std::strerror(errno) + ")");
        mPos += n;
    }
    void seek(long long p) { mPos = p; }

private:
    std::string mPath;
    std::ifstream mIn;
    long long mSize = 0, mPos = 0;
};

std::string versionText(const nanovdb::Version& v)
{
    return std::to_string(v.getMajor()) + "." + std::to_string(v.getMinor()) + "." + std::to_string(v.getPatch());
}

// A segment's header at the current position, checked: NanoVDB's magic, this build's major version, a grid count
// and a codec NanoVDB knows.
nanovdb::io::Header readSegmentHeader(Bounded& in, const std::string& path)
{
    nanovdb::io::Header header;
    const bool first = in.pos() == 0;
    in.read(&header, sizeof(header), "a segment header");
    if (header.magic != NANOVDB_MAGIC_NUMBER) {
        // NanoVDB 32.6 (OpenVDB 11) and later begin files with "NanoVDB1" or "NanoVDB2" and lay grids out anew.
        if (first && std::memcmp(&header.magic, "NanoVDB", 7) == 0)
            throw IoError(path + ": a NanoVDB file of another layout than this build's NanoVDB " +
                          std::to_string(NANOVDB_MAJOR_VERSION_NUMBER) + "." +
                          std::to_string(NANOVDB_MINOR_VERSION_NUMBER) + " (OpenVDB 10) reads (magic number 'NanoVDB" +
                          cleanMessage(std::string(1, reinterpret_cast<const char*>(&header.magic)[7])) +
                          "'), or a damaged one: write it with NanoVDB 32.4, or give the OpenVDB cache it was made "
                          "from");
        if (first) throw IoError(path + ": not a NanoVDB file (bad magic number)");
        throw IoError(path + ": damaged NanoVDB file: no segment header at byte " + std::to_string(in.pos() - 16));
    }
    if (header.version.getMajor() != NANOVDB_MAJOR_VERSION_NUMBER)
        throw IoError(path + ": written by NanoVDB " + versionText(header.version) +
                      ", another major version than this build's (" + std::to_string(NANOVDB_MAJOR_VERSION_NUMBER) +
                      ".x)");
    if (header.gridCount == 0 || header.codec >= nanovdb::io::Codec::END)
        throw IoError(path + ": damaged NanoVDB file: segment header at byte " + std::to_string(in.pos() - 16) +
                      " holds " + std::to_string(header.gridCount) + " grids, codec " +
                      std::to_string(int(header.codec)));
    return header;
}

// What a grid's file header (and its segment's) says about it; grid `index` of the file.
NanoGridInfo gridInfoOf(const nanovdb::io::MetaData& m, const std::string& name, const nanovdb::io::Header& header,
    int index, const std::string& path)
{
    NanoGridInfo g;
    g.index = index;
    g.name = name;
    g.valueType = typeName(m.gridType);
    g.gridClass = className(m.gridClass);
    g.activeVoxels = (long long)m.voxelCount;
    g.hasBBox = !m.indexBBox.empty();
    if (g.hasBBox)
        g.activeBBox = turb::CoordBBox(turb::Coord(m.indexBBox[0][0], m.indexBBox[0][1], m.indexBBox[0][2]),
            turb::Coord(m.indexBBox[1][0], m.indexBBox[1][1], m.indexBBox[1][2]));
    g.voxelSize = turb::Vec3d(m.voxelSize[0], m.voxelSize[1], m.voxelSize[2]);
    g.worldMin = turb::Vec3d(m.worldBBox[0][0], m.worldBBox[0][1], m.worldBBox[0][2]);
    g.worldMax = turb::Vec3d(m.worldBBox[1][0], m.worldBBox[1][1], m.worldBBox[1][2]);
    g.bytes = (long long)m.gridSize;
    g.fileBytes = (long long)m.fileSize;
    g.codec = header.codec == nanovdb::io::Codec::ZIP     ? "zip"
              : header.codec == nanovdb::io::Codec::BLOSC ? "blosc"
                                                          : "none";
    g.version = versionText(header.version);
    if (header.codec == nanovdb::io::Codec::NONE && m.fileSize != m.gridSize)
        throw IoError(path + ": damaged NanoVDB file: grid " + inQuotes(name) + " records " +
                      std::to_string(m.fileSize) + " bytes on disk and " + std::to_string(m.gridSize) +
                      " in memory, which an uncompressed grid cannot");
    return g;
}

// The segment's grid headers (each a MetaData and the grid's name); `first` is the file index of its first grid.
void readGridHeaders(Bounded& in, const std::string& path, const nanovdb::io::Header& header, size_t first,
    std::vector<NanoGridInfo>& grids, std::vector<nanovdb::io::MetaData>& metas)
{
    for (int i = 0; i < header.gridCount; ++i) {
        nanovdb::io::MetaData m;
        in.read(&m, sizeof(m), "grid header " + std::to_string(first + grids.size()));
        if (m.nameSize > in.left() || m.nameSize > (1u << 20))
            throw IoError(path + ": damaged NanoVDB file: a grid name of " + std::to_string(m.nameSize) +
                          " bytes at byte " + std::to_string(in.pos()));
        std::string name(m.nameSize, '\0');
        in.read(name.data(), m.nameSize, "a grid name");
        name.resize(std::strlen(name.c_str()));
        grids.push_back(gridInfoOf(m, name, header, int(first + grids.size()), path));
        metas.push_back(m);
    }
}

// The grids follow the segment's headers, in order: each must fit in the file; an uncompressed one's fixed-size
// header gives its transform (the file's headers hold only the voxel size).
void readGridTransforms(Bounded& in, const std::string& path, const nanovdb::io::Header& header,
    std::vector<NanoGridInfo>& grids, const std::vector<nanovdb::io::MetaData>& metas)
{
    for (size_t i = 0; i < grids.size(); ++i) {
        const long long start = in.pos();
        if ((long long)metas[i].fileSize > in.left())
            throw IoError(path + ": truncated NanoVDB file: grid " + inQuotes(grids[i].name) + " needs " +
                          std::to_string(metas[i].fileSize) + " bytes at byte " + std::to_string(start) +
                          " but the file has " + std::to_string(in.size()));
        if (header.codec == nanovdb::io::Codec::NONE && metas[i].gridSize >= sizeof(nanovdb::GridData)) {
            alignas(NANOVDB_DATA_ALIGNMENT) unsigned char raw[sizeof(nanovdb::GridData)];
            in.read(raw, sizeof(raw), "the header of grid " + inQuotes(grids[i].name));
            const auto* data = reinterpret_cast<const nanovdb::GridData*>(raw);
            if (data->mMagic != NANOVDB_MAGIC_NUMBER)
                throw IoError(path + ": damaged NanoVDB file: grid " + inQuotes(grids[i].name) +
                              " does not start with NanoVDB's magic number");
            grids[i].hasTransform = true;
            grids[i].origin = turb::Vec3d(data->mMap.mVecD[0], data->mMap.mVecD[1], data->mMap.mVecD[2]);
            std::copy(std::begin(data->mMap.mMatD), std::end(data->mMap.mMatD), grids[i].matrix);
        }
        in.seek(start + (long long)metas[i].fileSize);
    }
}

} // namespace

NanoFileInfo inspectNanoFile(const std::string& path)
{
    NanoFileInfo info;
    info.path = path;
    Bounded in(path);
    info.fileBytes = in.size();
    if (in.size() == 0) throw IoError(path + ": empty file, not a NanoVDB file");
    while (in.left() > 0) {
        const nanovdb::io::Header header = readSegmentHeader(in, path);
        std::vector<NanoGridInfo> grids;
        std::vector<nanovdb::io::MetaData> metas;
        readGridHeaders(in, path, header, info.grids.size(), grids, metas);
        readGridTransforms(in, path, header, grids, metas);
        info.grids.insert(info.grids.end(), grids.begin(), grids.end());
    }
    return info;
}

} // namespace turbio
