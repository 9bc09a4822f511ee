// NanoVDB input: the reader child's GridSource for a NanoVDB file (GuardedRead.h). NanoVDB's own reader
// (nanovdb::io::readGrid) loads a grid when a body asks for it, its checksum is verified, and it is copied node by node
// into an OpenVDB tree of the same shape; from there its grids go the way an OpenVDB file's grids go (Vdb.cc).
#include "GuardedRead.h"

#include <turbio/NanoVdb.h>

#include <turb/Error.h>
#include <turb/NewGrid.h>

#include <nanovdb/NanoVDB.h>
#include <nanovdb/util/GridChecksum.h>
#include <nanovdb/util/IO.h>
#include <nanovdb/util/NodeManager.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>

namespace turbio::detail {

using turb::IoError;

namespace {

std::string quoted(const std::string& s) { return "'" + cleanMessage(s) + "'"; }

// The types a smoke cache's grids come in; quantised floats become float, as every reader of them sees them.
bool readable(const std::string& nanoType)
{
    static const std::set<std::string> types = {"float", "fp4", "fp8", "fp16", "fpN", "double", "vec3f", "vec3d"};
    return types.count(nanoType) > 0;
}

// OpenVDB's unique grid names, as io::Archive gives them on write: an unnamed grid is "\x1e0", a second grid of a name
// "name\x1e1", a third "name\x1e2".
std::vector<std::string> uniqueNames(const NanoFileInfo& info)
{
    std::vector<std::string> out;
    std::set<std::string> taken;
    for (const NanoGridInfo& g : info.grids) {
        std::string unique = g.name.empty() ? g.name + "\x1e" + "0" : g.name;
        for (int n = 1; taken.count(unique); ++n) unique = g.name + "\x1e" + std::to_string(n);
        taken.insert(unique);
        out.push_back(unique);
    }
    return out;
}

// A transform as nanovdb::nanoToOpenVDB builds it from NanoVDB's map (`matrix` as NanoVDB stores it, row by row).
openvdb::math::Transform::Ptr transformOf(const double* matrix, const double* translation)
{
    openvdb::math::Mat4d mat = openvdb::math::Mat4d::identity();
    mat.setMat3(openvdb::math::Mat3d(matrix));
    mat.transpose(); // NanoVDB's 3x3 is the transpose of OpenVDB's
    mat.setTranslation(openvdb::Vec3d(translation));
    return openvdb::math::Transform::createLinearTransform(mat);
}

// NanoVDB's checksum of `grid`, as nanovdb::GridChecksum computes it (GridChecksum.h, 10.0.1) for the mode its recorded
// checksum was made in, but serially (GridChecksum runs on nanovdb::forEach, which starts threads: TBB must not run in
// the forked reader child, fork did not copy its pool threads): CRC32 over the grid, tree and root headers after the
// magic number and the checksum, then, for a full checksum, CRC32 over each node's fixed-size part (upper, lower, leaf
// nodes in the node manager's order) and CRC32 over those.
template<typename BuildT>
uint64_t checksumOf(const nanovdb::NanoGrid<BuildT>& grid, bool full)
{
    const auto& tree = grid.tree();
    const auto& root = tree.root();
    nanovdb::CRC32 crc;
    const auto* begin = reinterpret_cast<const uint8_t*>(&grid);
    crc(begin + 16, begin + grid.memUsage() + tree.memUsage() + root.memUsage());
    const uint32_t head = uint32_t(crc.checksum());
    if (!full || tree.isEmpty()) return nanovdb::GridChecksum(head, uint32_t(nanovdb::CRC32::EMPTY)).checksum();
    auto managerHandle = nanovdb::createNodeManager(grid);
    const auto* manager = managerHandle.template mgr<BuildT>();
    std::vector<std::uint_fast32_t> sums;
    const auto add = [&](const auto& node) {
        nanovdb::CRC32 local;
        local(node);
        sums.push_back(local.checksum());
    };
    for (uint32_t i = 0; i < tree.nodeCount(2); ++i) add(manager->upper(i));
    for (uint32_t i = 0; i < tree.nodeCount(1); ++i) add(manager->lower(i));
    for (uint32_t i = 0; i < tree.nodeCount(0); ++i) add(manager->leaf(i));
    crc.reset();
    crc(sums.data(), sizeof(std::uint_fast32_t) * sums.size());
    return nanovdb::GridChecksum(head, uint32_t(crc.checksum())).checksum();
}

// The OpenVDB value type a NanoVDB build type is read as: quantised floats as float, vectors as OpenVDB's vectors.
template<typename BuildT>
struct OpenValue
{
    using Type = float; // float, Fp4, Fp8, Fp16, FpN
};
template<>
struct OpenValue<double>
{
    using Type = double;
};
template<typename T>
struct OpenValue<nanovdb::Vec3<T>>
{
    using Type = openvdb::math::Vec3<T>;
};

// A NanoVDB grid copied node by node into an OpenVDB tree of the same shape: every node, tile (active or not, so a
// level set's inside keeps its sign) and voxel as stored, quantised values decoded. Serial, for the forked reader
// child (see checksumOf); nanovdb::nanoToOpenVDB does the same on nanovdb::forEach's threads, and its eight
// instantiations took a minute of compile time.
template<typename BuildT>
class ToOpenVdb
{
    using OpenV = typename OpenValue<BuildT>::Type;
    using OpenTree = typename openvdb::tree::Tree4<OpenV, 5, 4, 3>::Type;
    using OpenLeaf = typename OpenTree::LeafNodeType;
    using OpenLower = typename OpenTree::RootNodeType::ChildNodeType::ChildNodeType;
    using OpenUpper = typename OpenTree::RootNodeType::ChildNodeType;
    using NanoTree = nanovdb::NanoTree<BuildT>;
    using NanoLeaf = typename NanoTree::LeafNodeType;
    using NanoLower = typename NanoTree::Node1;
    using NanoUpper = typename NanoTree::Node2;

public:
    static typename openvdb::Grid<OpenTree>::Ptr convert(const nanovdb::NanoGrid<BuildT>& grid)
    {
        const auto* root = grid.tree().root().data();
        auto out = turb::newGrid<openvdb::Grid<OpenTree>>(open(root->mBackground));
        out->setName(grid.gridName());
        out->setGridClass(grid.gridClass() == nanovdb::GridClass::LevelSet    ? openvdb::GRID_LEVEL_SET
                          : grid.gridClass() == nanovdb::GridClass::FogVolume ? openvdb::GRID_FOG_VOLUME
                          : grid.gridClass() == nanovdb::GridClass::Staggered ? openvdb::GRID_STAGGERED
                                                                              : openvdb::GRID_UNKNOWN);
        const nanovdb::Map& map = reinterpret_cast<const nanovdb::GridData*>(&grid)->mMap;
        out->setTransform(transformOf(map.mMatD, map.mVecD));
        auto& openRoot = out->tree().root();
        for (uint32_t i = 0; i < root->mTableSize; ++i) {
            const auto* tile = root->tile(i);
            if (tile->isChild()) openRoot.addChild(internal<OpenUpper>(*root->getChild(tile)));
            else openRoot.addTile(coordOf(tile->origin()), open(tile->value), tile->state);
        }
        return out;
    }

private:
    static openvdb::Coord coordOf(const nanovdb::Coord& c) { return openvdb::Coord(c[0], c[1], c[2]); }
    template<typename V>
    static OpenV open(const V& v)
    {
        if constexpr (std::is_same_v<OpenV, float> || std::is_same_v<OpenV, double>) return OpenV(v);
        else return OpenV(v[0], v[1], v[2]);
    }
    // An internal node: its masks and table as stored, children copied in turn.
    template<typename OpenNode, typename NanoNode>
    static OpenNode* internal(const NanoNode& node)
    {
        auto* out = new OpenNode();
        out->setOrigin(coordOf(node.origin()));
        auto& valueMask = const_cast<typename OpenNode::NodeMaskType&>(out->getValueMask());
        auto& childMask = const_cast<typename OpenNode::NodeMaskType&>(out->getChildMask());
        auto* table = const_cast<typename OpenNode::UnionType*>(out->getTable());
        const auto* data = node.data();
        for (uint32_t n = 0; n < OpenNode::NUM_VALUES; ++n) {
            if (node.valueMask().isOn(n)) valueMask.setOn(n);
            if (!node.childMask().isOn(n)) {
                table[n].setValue(open(data->mTable[n].value));
                continue;
            }
            childMask.setOn(n);
            if constexpr (std::is_same_v<NanoNode, NanoUpper>)
                table[n].setChild(internal<OpenLower>(*data->getChild(n)));
            else table[n].setChild(leaf(*data->getChild(n)));
        }
        return out;
    }
    static OpenLeaf* leaf(const NanoLeaf& node)
    {
        auto* out = new OpenLeaf(coordOf(node.origin()), OpenV(0));
        OpenV* values = out->buffer().data();
        for (uint32_t n = 0; n < OpenLeaf::SIZE; ++n) {
            values[n] = open(node.getValue(n));
            if (node.valueMask().isOn(n)) out->setActiveState(n, true);
        }
        return out;
    }
};

// `grid` as an OpenVDB grid, after its checksum (when it records one) matched. `label` names it in errors.
template<typename BuildT>
openvdb::GridBase::Ptr convertChecked(const nanovdb::NanoGrid<BuildT>& grid, const std::string& label)
{
    const nanovdb::GridChecksum recorded(grid.checksum());
    if (recorded.mode() != nanovdb::ChecksumMode::Disable) {
        const uint64_t computed = checksumOf(grid, recorded.mode() == nanovdb::ChecksumMode::Full);
        if (computed != recorded.checksum()) {
            char text[80];
            std::snprintf(text, sizeof text, " (recorded %016llx, computed %016llx)",
                (unsigned long long)recorded.checksum(), (unsigned long long)computed);
            throw IoError(label + " does not match its checksum" + text + ": a damaged NanoVDB file");
        }
    }
    return ToOpenVdb<BuildT>::convert(grid);
}

// The grid of handle `h` as an OpenVDB grid (float for the quantised types), or null for a type vdbturb does not read.
// The buffer's own header is checked first: a grid of another type than its file header says, or of another size,
// is damaged (and nanovdb::GridHandle::grid would walk a damaged grid index past the buffer).
openvdb::GridBase::Ptr convert(const nanovdb::GridHandle<>& h, const std::string& label)
{
    const auto* data = reinterpret_cast<const nanovdb::GridData*>(h.data());
    if (!data || h.size() < sizeof(nanovdb::GridData) || data->mMagic != NANOVDB_MAGIC_NUMBER ||
        data->mGridSize != h.size())
        throw IoError(label + " has a damaged header (magic number or size)");
    const auto as = [&](auto build) {
        using BuildT = decltype(build);
        return convertChecked(*reinterpret_cast<const nanovdb::NanoGrid<BuildT>*>(data), label);
    };
    switch (data->mGridType) {
    case nanovdb::GridType::Float: return as(float());
    case nanovdb::GridType::Fp4: return as(nanovdb::Fp4());
    case nanovdb::GridType::Fp8: return as(nanovdb::Fp8());
    case nanovdb::GridType::Fp16: return as(nanovdb::Fp16());
    case nanovdb::GridType::FpN: return as(nanovdb::FpN());
    case nanovdb::GridType::Double: return as(double());
    case nanovdb::GridType::Vec3f: return as(nanovdb::Vec3f());
    case nanovdb::GridType::Vec3d: return as(nanovdb::Vec3d());
    default: return nullptr;
    }
}

// An empty grid of the OpenVDB type a NanoVDB grid of `nanoType` is read as, for a header.
openvdb::GridBase::Ptr emptyGridFor(const std::string& nanoType)
{
    if (nanoType == "double") return turb::newGrid<openvdb::DoubleGrid>(0.0);
    if (nanoType == "vec3f") return turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    if (nanoType == "vec3d") return turb::newGrid<openvdb::Vec3DGrid>(openvdb::Vec3d(0.0));
    if (nanoType == "int32") return turb::newGrid<openvdb::Int32Grid>(0);
    if (nanoType == "int64") return turb::newGrid<openvdb::Int64Grid>(0);
    if (nanoType == "bool") return turb::newGrid<openvdb::BoolGrid>(false);
    if (nanoType == "mask") return turb::newGrid<openvdb::MaskGrid>(false);
    return turb::newGrid<openvdb::FloatGrid>(
        0.0f); // float and its quantised forms (a header of any other type says it)
}

openvdb::GridClass classOf(const std::string& nanoClass)
{
    if (nanoClass == "level set") return openvdb::GRID_LEVEL_SET;
    if (nanoClass == "fog volume") return openvdb::GRID_FOG_VOLUME;
    if (nanoClass == "staggered") return openvdb::GRID_STAGGERED;
    return openvdb::GRID_UNKNOWN;
}

class NanoSource : public GridSource
{
public:
    explicit NanoSource(const std::string& path) : mPath(path), mInfo(inspectNanoFile(path))
    {
        mUnique = uniqueNames(mInfo);
    }
    std::vector<std::string> names() override { return mUnique; }
    openvdb::GridBase::Ptr readGridMetadata(const std::string& unique) override { return header(indexOf(unique)); }
    openvdb::GridBase::Ptr readGrid(const std::string& unique) override { return grid(indexOf(unique)); }
    openvdb::GridPtrVec readAll() override
    {
        openvdb::GridPtrVec all;
        for (size_t i = 0; i < mInfo.grids.size(); ++i) all.push_back(grid(i));
        return all;
    }
    // NanoVDB files hold no metadata but the grids' own fields; the marker tells the reader where the grids came from.
    openvdb::MetaMap::Ptr getMetadata() override
    {
        auto meta = std::make_shared<openvdb::MetaMap>();
        meta->insertMeta("__turb_nanovdb", openvdb::BoolMetadata(true));
        return meta;
    }
    uint32_t fileVersion() const override { return 0; }
    std::pair<int, int> libraryVersion() const override { return {0, 0}; }

private:
    size_t indexOf(const std::string& unique) const
    {
        const auto it = std::find(mUnique.begin(), mUnique.end(), unique);
        if (it == mUnique.end()) throw IoError(mPath + ": no grid " + quoted(unique));
        return size_t(it - mUnique.begin());
    }
    std::string label(size_t i) const
    {
        return mPath + ": grid " +
               (mInfo.grids[i].name.empty() ? std::string("(unnamed)") : quoted(mInfo.grids[i].name));
    }
    const nanovdb::GridHandle<>& loaded(size_t i);
    openvdb::GridBase::Ptr header(size_t i);
    openvdb::GridBase::Ptr grid(size_t i);

    std::string mPath;
    NanoFileInfo mInfo;
    std::vector<std::string> mUnique;
    std::map<size_t, nanovdb::GridHandle<>> mLoaded;
};

// Grid `i` as NanoVDB's reader loads it (once). The headers were checked (inspectNanoFile): every size fits the file.
const nanovdb::GridHandle<>& NanoSource::loaded(size_t i)
{
    auto it = mLoaded.find(i);
    if (it == mLoaded.end()) {
        try {
            it = mLoaded.emplace(i, nanovdb::io::readGrid<nanovdb::HostBuffer>(mPath, uint64_t(i))).first;
        } catch (const std::bad_alloc&) {
            throw;
        } catch (const std::exception& e) {
            throw IoError(
                label(i) + " could not be read; truncated or damaged NanoVDB file (" + cleanMessage(e.what()) + ")");
        }
    }
    return it->second;
}

// Grid `i`'s header: its name, class, transform, active box and voxel count, no voxels; the type it is read as (a
// quantised float is float).
openvdb::GridBase::Ptr NanoSource::header(size_t i)
{
    const NanoGridInfo& g = mInfo.grids[i];
    openvdb::GridBase::Ptr out = emptyGridFor(g.valueType);
    out->setName(g.name);
    out->setGridClass(classOf(g.gridClass));
    if (g.hasTransform) {
        const double translation[3] = {g.origin.x(), g.origin.y(), g.origin.z()};
        out->setTransform(transformOf(g.matrix, translation));
    } else { // a compressed grid: its header is inside the compressed data
        const auto* data = reinterpret_cast<const nanovdb::GridData*>(loaded(i).data());
        if (!data || loaded(i).size() < sizeof(nanovdb::GridData))
            throw IoError(label(i) + " has a damaged header (size)");
        out->setTransform(transformOf(data->mMap.mMatD, data->mMap.mVecD));
    }
    if (g.hasBBox) {
        const turb::CoordBBox& b = g.activeBBox;
        out->insertMeta(openvdb::GridBase::META_FILE_BBOX_MIN, openvdb::Vec3IMetadata(b.min().asVec3i()));
        out->insertMeta(openvdb::GridBase::META_FILE_BBOX_MAX, openvdb::Vec3IMetadata(b.max().asVec3i()));
    }
    out->insertMeta(openvdb::GridBase::META_FILE_VOXEL_COUNT, openvdb::Int64Metadata(g.activeVoxels));
    if (!readable(g.valueType)) out->insertMeta("__turb_value_type", openvdb::StringMetadata(g.valueType));
    return out;
}

// Grid `i` whole, converted; its NanoVDB buffer is freed once converted (HostBuffer frees with free(): no TBB here).
openvdb::GridBase::Ptr NanoSource::grid(size_t i)
{
    const NanoGridInfo& g = mInfo.grids[i];
    if (!readable(g.valueType))
        throw IoError(label(i) + " is a NanoVDB " + g.valueType +
                      " grid: vdbturb reads NanoVDB float (and fp4, fp8, fp16, fpN), double, vec3f and vec3d grids "
                      "(resample: --drop-other-grids leaves the others out)");
    openvdb::GridBase::Ptr out;
    try {
        out = convert(loaded(i), label(i));
    } catch (const turb::Error&) {
        throw;
    } catch (const std::bad_alloc&) {
        throw;
    } catch (const std::exception& e) {
        throw IoError(label(i) + " could not be converted; damaged NanoVDB file (" + cleanMessage(e.what()) + ")");
    }
    if (!out) throw IoError(label(i) + " holds another type than its file header says (" + g.valueType + ")");
    keepInChild(out);
    mLoaded.erase(i);
    out->setName(g.name); // the file header's name: a long name's grid keeps only its first 255 bytes
    return out;
}

} // namespace

std::unique_ptr<GridSource> openNanoSource(const std::string& path) { return std::make_unique<NanoSource>(path); }

} // namespace turbio::detail
