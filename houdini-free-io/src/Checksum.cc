// Grid fingerprints (turbio/Checksum.h): read through the guarded reader, hashed in the parent.
#include <turbio/Checksum.h>

#include "ActiveVoxels.h"
#include "GuardedRead.h"

#include <turb/Error.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace turbio {

namespace {

struct Fnv
{
    uint64_t h = 1469598103934665603ull;
    void add(const void* p, size_t n)
    {
        const unsigned char* b = static_cast<const unsigned char*>(p);
        for (size_t i = 0; i < n; ++i) {
            h ^= b[i];
            h *= 1099511628211ull;
        }
    }
    void add(const std::string& s)
    {
        const uint64_t n = s.size();
        add(&n, sizeof n);
        add(s.data(), s.size());
    }
};

// A bool's bits are not portable; everything else is hashed as stored in memory.
template<typename V>
void addValue(Fnv& f, const V& v)
{
    if constexpr (std::is_same_v<V, bool>) {
        const unsigned char b = v ? 1 : 0;
        f.add(&b, 1);
    } else {
        f.add(&v, sizeof v);
    }
}

// splitmix64's finaliser: spreads a voxel's hash over all 64 bits before the voxels' hashes are summed.
uint64_t mix(uint64_t h)
{
    h = (h ^ (h >> 30)) * 0xbf58476d1ce4e5b9ull;
    h = (h ^ (h >> 27)) * 0x94d049bb133111ebull;
    return h ^ (h >> 31);
}

// The sum of per-voxel hashes of (position, value): independent of the order voxels are visited in, so a tile
// and the voxels it covers, or any other tree layout of the same values, hash the same.
template<typename GridT>
bool hashValues(const openvdb::GridBase& base, GridChecksum& out, uint64_t& sum)
{
    const GridT* g = dynamic_cast<const GridT*>(&base);
    if (!g) return false;
    detail::forEachActiveVoxel(*g, [&](const openvdb::Coord& c, const typename GridT::ValueType& value) {
        Fnv f;
        const int32_t xyz[3] = {c.x(), c.y(), c.z()};
        f.add(xyz, sizeof xyz);
        addValue(f, value);
        sum += mix(f.h);
        ++out.activeVoxels;
    });
    return true;
}

bool statistic(const std::string& name)
{
    return name.rfind("file_bbox_", 0) == 0 || name == "file_mem_bytes" || name == "file_voxel_count";
}

} // namespace

std::string hexDigest(uint64_t h)
{
    char b[17];
    std::snprintf(b, sizeof b, "%016llx", static_cast<unsigned long long>(h));
    return b;
}

std::vector<GridChecksum> gridChecksums(const std::string& path)
{
    openvdb::initialize();
    const detail::GuardedResult read = detail::guardedRead(
        path, [](detail::GridSource& file, openvdb::GridPtrVec& grids, openvdb::MetaMap&) { grids = file.readAll(); },
        60.0);
    std::vector<GridChecksum> out;
    for (const openvdb::GridBase::Ptr& g : read.grids) {
        GridChecksum c;
        c.name = g->getName();
        c.valueType = g->valueType();
        Fnv v;
        const openvdb::math::Mat4d m = g->transform().baseMap()->getAffineMap()->getMat4();
        v.add(m.asPointer(), 16 * sizeof(double));
        v.add(openvdb::GridBase::gridClassToString(g->getGridClass()));
        uint64_t sum = 0;
        const bool known = hashValues<openvdb::FloatGrid>(*g, c, sum) || hashValues<openvdb::DoubleGrid>(*g, c, sum) ||
                           hashValues<openvdb::Int32Grid>(*g, c, sum) || hashValues<openvdb::Int64Grid>(*g, c, sum) ||
                           hashValues<openvdb::BoolGrid>(*g, c, sum) || hashValues<openvdb::Vec3SGrid>(*g, c, sum) ||
                           hashValues<openvdb::Vec3DGrid>(*g, c, sum) || hashValues<openvdb::Vec3IGrid>(*g, c, sum);
        if (!known)
            throw turb::IoError(
                path + ": grid '" + c.name + "' has value type " + c.valueType + ", which vdbturb cannot fingerprint");
        v.add(&sum, sizeof sum);
        v.add(&c.activeVoxels, sizeof c.activeVoxels);
        c.values = v.h;
        std::vector<std::pair<std::string, std::string>> meta;
        for (auto it = g->beginMeta(); it != g->endMeta(); ++it)
            if (!statistic(it->first)) meta.emplace_back(it->first, it->second->typeName() + ":" + it->second->str());
        std::sort(meta.begin(), meta.end());
        Fnv mh;
        for (const auto& [name, value] : meta) {
            mh.add(name);
            mh.add(value);
        }
        c.metadata = mh.h;
        out.push_back(std::move(c));
    }
    return out;
}

} // namespace turbio
