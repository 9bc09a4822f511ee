// turbio::OtherGrids' down-sampling and quarter turns, on sparse OpenVDB grids of any value type.
#include "OtherGrids.h"

#include "ActiveVoxels.h"

#include <turb/Error.h>
#include <turb/NewGrid.h>

#include <openvdb/tools/ValueTransformer.h>

#include <algorithm>
#include <cctype>
#include <string>
#include <type_traits>

namespace turbio {

namespace {

using openvdb::Coord;
using turb::newGrid;

Coord blockOf(const Coord& c, const turb::Coord& f)
{
    return Coord(turb::floorDiv(c.x(), f.x()), turb::floorDiv(c.y(), f.y()), turb::floorDiv(c.z(), f.z()));
}

// The mean over each block, inactive voxels counting as the background: a sum and a count per coarse voxel.
template<typename GridT>
openvdb::GridBase::Ptr blockMean(const GridT& in, const turb::Coord& f)
{
    using V = typename GridT::ValueType;
    const V background = in.background();
    auto sum = newGrid<GridT>(openvdb::zeroVal<V>());
    auto count = newGrid<openvdb::Int32Grid>(0);
    {
        auto sumAcc = sum->getAccessor();
        auto countAcc = count->getAccessor();
        // Summed in visiting order: tiles come whole, which can move a block's sum by an ulp against voxels.
        turbio::detail::forEachActiveVoxel(in, [&](const Coord& c, const V& value) {
            const Coord b = blockOf(c, f);
            sumAcc.setValue(b, sumAcc.getValue(b) + value);
            countAcc.setValue(b, countAcc.getValue(b) + 1);
        });
    }
    const double n = double(f.x()) * f.y() * f.z();
    auto out = newGrid<GridT>(background);
    auto outAcc = out->getAccessor();
    auto sumAcc = sum->getConstAccessor();
    for (auto it = count->cbeginValueOn(); it; ++it) {
        const Coord b = it.getCoord();
        const V total = sumAcc.getValue(b) + background * typename openvdb::VecTraits<V>::ElementType(n - double(*it));
        outAcc.setValue(b, total * typename openvdb::VecTraits<V>::ElementType(1.0 / n));
    }
    return out;
}

// Labels: each block takes its centre voxel (value and active state).
template<typename GridT>
openvdb::GridBase::Ptr blockCentre(const GridT& in, const turb::Coord& f)
{
    auto out = newGrid<GridT>(in.background());
    auto outAcc = out->getAccessor();
    auto inAcc = in.getConstAccessor();
    turbio::detail::forEachActiveVoxel(in, [&](const Coord& voxel, const typename GridT::ValueType&) {
        const Coord b = blockOf(voxel, f);
        const Coord c(b.x() * f.x() + f.x() / 2, b.y() * f.y() + f.y() / 2, b.z() * f.z() + f.z() / 2);
        typename GridT::ValueType v;
        if (inAcc.probeValue(c, v)) {
            outAcc.setValue(b, v);
        } else if (!outAcc.isValueOn(b)) {
            // A partial block at the domain's edge (its centre lies outside the data): the block's active voxel
            // nearest the centre, first in x, y, z order on ties, so no edge block is lost.
            long best = -1;
            for (int x = 0; x < f.x(); ++x)
                for (int y = 0; y < f.y(); ++y)
                    for (int z = 0; z < f.z(); ++z) {
                        const Coord q(b.x() * f.x() + x, b.y() * f.y() + y, b.z() * f.z() + z);
                        typename GridT::ValueType w;
                        if (!inAcc.probeValue(q, w)) continue;
                        const long d = long(q.x() - c.x()) * (q.x() - c.x()) + long(q.y() - c.y()) * (q.y() - c.y()) +
                                       long(q.z() - c.z()) * (q.z() - c.z());
                        if (best < 0 || d < best) {
                            best = d;
                            outAcc.setValue(b, w);
                        }
                    }
        }
    });
    return out;
}

template<typename V>
V turned(const V& v, const turb::AxisRotation& r, bool rotateValues)
{
    if constexpr (openvdb::VecTraits<V>::IsVec && openvdb::VecTraits<V>::Size == 3) {
        if (!rotateValues) return v;
        V o;
        for (int i = 0; i < 3; ++i) o[i] = v[r.perm[size_t(i)]] * typename V::value_type(r.sign[size_t(i)]);
        return o;
    } else {
        (void)r;
        (void)rotateValues;
        return v;
    }
}

template<typename GridT>
openvdb::GridBase::Ptr rotatedGrid(const GridT& in, const turb::AxisRotation& r)
{
    // Vectors turn with the grid. OpenVDB's vector type cannot say which ones do not: it defaults to "invariant",
    // which Blender's velocities carry too. Colours go by name (Houdini's Cd, "color", "colour").
    std::string name = in.getName();
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char ch) { return char(std::tolower(ch)); });
    const bool rotateValues =
        name != "cd" && name.find("color") == std::string::npos && name.find("colour") == std::string::npos;
    auto out = newGrid<GridT>(turned(in.background(), r, rotateValues));
    auto outAcc = out->getAccessor();
    turbio::detail::forEachActiveVoxel(in, [&](const Coord& o, const typename GridT::ValueType& value) {
        // As turb::rotated: output voxel c takes input voxel o with o[perm[i]] = sign[i] c[i].
        Coord c;
        for (int i = 0; i < 3; ++i) c[i] = r.sign[size_t(i)] * o[r.perm[size_t(i)]];
        outAcc.setValue(c, turned(value, r, rotateValues));
    });
    return out;
}

// Applies op to the grid as its concrete type; false for a type vdbturb cannot transform (points, strings).
template<typename Op>
openvdb::GridBase::Ptr transformed(const openvdb::GridBase& g, Op&& op)
{
    openvdb::GridBase::Ptr result;
    using Types = openvdb::TypeList<openvdb::FloatGrid, openvdb::DoubleGrid, openvdb::Vec3SGrid, openvdb::Vec3DGrid,
        openvdb::Int32Grid, openvdb::Int64Grid, openvdb::Vec3IGrid, openvdb::BoolGrid, openvdb::MaskGrid>;
    g.apply<Types>([&](const auto& typed) { result = op(typed); });
    if (!result) return nullptr;
    result->setTransform(g.transform().copy());
    result->insertMeta(g);
    result->setName(g.getName());
    result->setGridClass(g.getGridClass());
    result->setVectorType(g.getVectorType());
    return result;
}

template<typename GridT>
constexpr bool kLabels = std::is_integral_v<typename openvdb::VecTraits<typename GridT::ValueType>::ElementType>;

// Blender's record of the whole domain (file_base_resolution, file_voxel_size) kept true for the new lattice.
void rescaleBlenderDomain(openvdb::GridBase& g, const turb::Coord& f)
{
    if (auto res = g.getMetadata<openvdb::Vec3IMetadata>("file_base_resolution")) {
        const openvdb::Vec3i r = res->value();
        g.insertMeta("file_base_resolution", openvdb::Vec3IMetadata(openvdb::Vec3i((r[0] + f.x() - 1) / f.x(),
                                                 (r[1] + f.y() - 1) / f.y(), (r[2] + f.z() - 1) / f.z())));
    }
    if (auto vs = g.getMetadata<openvdb::FloatMetadata>("file_voxel_size"))
        g.insertMeta("file_voxel_size", openvdb::FloatMetadata(vs->value() * float(f.x())));
}

void turnBlenderDomain(openvdb::GridBase& g, const turb::AxisRotation& r)
{
    if (auto res = g.getMetadata<openvdb::Vec3IMetadata>("file_base_resolution")) {
        const openvdb::Vec3i v = res->value();
        g.insertMeta(
            "file_base_resolution", openvdb::Vec3IMetadata(openvdb::Vec3i(v[r.perm[0]], v[r.perm[1]], v[r.perm[2]])));
    }
}

} // namespace

void OtherGrids::downsample(const turb::Coord& factors)
{
    if (factors.x() < 1 || factors.y() < 1 || factors.z() < 1)
        throw turb::ValueError("down-sampling factors must be >= 1");
    if (factors == turb::Coord(1)) return;
    for (size_t i = 0; i < mImpl->grids.size(); ++i) {
        if (!mImpl->followFrame[i]) continue;
        auto out = transformed(*mImpl->grids[i], [&](const auto& typed) -> openvdb::GridBase::Ptr {
            using GridT = std::decay_t<decltype(typed)>;
            // A level set's far values are markers (Blender's phi grids hold 1e4 away from surfaces): a mean
            // would mix them into distances. The centre voxel's distance is off by at most half a block.
            if constexpr (kLabels<GridT>) return blockCentre(typed, factors);
            else if (typed.getGridClass() == openvdb::GRID_LEVEL_SET) return blockCentre(typed, factors);
            else return blockMean(typed, factors);
        });
        if (out) {
            // Blender's staggered velocities are in grid cells per step: a cell N times larger holds 1/N of them.
            if (out->getGridClass() == openvdb::GRID_STAGGERED && (*out)["file_base_resolution"])
                if (auto v = openvdb::GridBase::grid<openvdb::Vec3SGrid>(out))
                    openvdb::tools::foreach (v->beginValueOn(),
                        [&](const openvdb::Vec3SGrid::ValueOnIter& it) { it.setValue(*it / float(factors.x())); });
            rescaleBlenderDomain(*out, factors);
            mImpl->grids[i] = out;
        } else {
            mImpl->followFrame[i] = false;
        }
    }
}

void OtherGrids::rotate(const turb::AxisRotation& r)
{
    if (r.isIdentity()) return;
    for (size_t i = 0; i < mImpl->grids.size(); ++i) {
        if (!mImpl->followFrame[i]) continue;
        auto out = transformed(*mImpl->grids[i], [&](const auto& typed) { return rotatedGrid(typed, r); });
        if (out) {
            turnBlenderDomain(*out, r);
            mImpl->grids[i] = out;
        } else {
            mImpl->followFrame[i] = false;
        }
    }
}

OtherGrids::OtherGrids() : mImpl(std::make_unique<Impl>()) {}
OtherGrids::~OtherGrids() = default;
OtherGrids::OtherGrids(OtherGrids&&) noexcept = default;
OtherGrids& OtherGrids::operator=(OtherGrids&&) noexcept = default;

std::vector<std::string> OtherGrids::dropNamed(const std::vector<std::string>& names)
{
    std::vector<std::string> dropped;
    for (size_t i = mImpl->grids.size(); i-- > 0;)
        if (std::find(names.begin(), names.end(), mImpl->grids[i]->getName()) != names.end()) {
            dropped.insert(dropped.begin(), mImpl->grids[i]->getName());
            mImpl->grids.erase(mImpl->grids.begin() + long(i));
            mImpl->followFrame.erase(mImpl->followFrame.begin() + long(i));
        }
    return dropped;
}

size_t OtherGrids::size() const { return mImpl->grids.size(); }

std::vector<std::string> OtherGrids::names() const
{
    std::vector<std::string> n;
    for (const auto& g : mImpl->grids) n.push_back(g->getName());
    return n;
}

std::vector<std::string> OtherGrids::unchanged() const
{
    std::vector<std::string> n;
    for (size_t i = 0; i < mImpl->grids.size(); ++i)
        if (!mImpl->followFrame[i]) n.push_back(mImpl->grids[i]->getName());
    return n;
}

std::vector<std::string> OtherGrids::staggered() const
{
    std::vector<std::string> n;
    for (size_t i = 0; i < mImpl->grids.size(); ++i)
        if (mImpl->followFrame[i] && mImpl->grids[i]->getGridClass() == openvdb::GRID_STAGGERED)
            n.push_back(mImpl->grids[i]->getName());
    return n;
}

} // namespace turbio
