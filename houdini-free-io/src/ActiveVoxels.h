// Visiting every active voxel of a grid, active tiles included, without copying the tree.
#pragma once

#include <openvdb/openvdb.h>

namespace turbio::detail {

/// Calls fn(coord, value) once for each active voxel of `grid`: leaf voxels as stored and each voxel an active
/// tile covers. Tiles are expanded in place rather than by `voxelizeActiveTiles()` on a deep copy, which costs
/// a copy of the grid at run time and, instantiated for every value type, minutes of compile time. Voxels of a
/// tile are visited together (x, then y, then z), so the order differs from a voxelized tree's where tiles exist:
/// callers whose result depends on the order do not rely on tiles being absent.
template<typename GridT, typename Fn>
void forEachActiveVoxel(const GridT& grid, Fn&& fn)
{
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        if (it.isVoxelValue()) {
            fn(it.getCoord(), *it);
            continue;
        }
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        const auto value = *it;
        for (int x = box.min().x(); x <= box.max().x(); ++x)
            for (int y = box.min().y(); y <= box.max().y(); ++y)
                for (int z = box.min().z(); z <= box.max().z(); ++z) fn(openvdb::Coord(x, y, z), value);
    }
}

} // namespace turbio::detail
