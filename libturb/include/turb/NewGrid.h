/// @file NewGrid.h
/// @brief An empty typed OpenVDB grid made by OpenVDB's grid registry instead of GridT::create. Constructing a
/// Grid<TreeT> in a file instantiates its and its tree's virtual functions (IO, copying, merging, statistics) there:
/// 5-8 s of compile time for each grid type in each file (NanoRead.cc took 53 s for eight types, OtherGrids.cc 59 s for
/// nine). Through the registry libopenvdb's own instantiations are used, and a file instantiates only what it calls.
#pragma once

#include <turb/Error.h>

#include <openvdb/openvdb.h>

namespace turb {

/// An empty grid of type GridT with background `background`. GridT must be one of the types openvdb::initialize
/// registers (float, double, int32, int64, bool, mask, vec3s/d/i, ...); any other is a turb::Error.
template<typename GridT>
typename GridT::Ptr newGrid(const typename GridT::ValueType& background)
{
    openvdb::initialize(); // registers the types; a no-op after the first call
    auto grid = openvdb::GridBase::grid<GridT>(openvdb::GridBase::createGrid(GridT::gridType()));
    if (!grid) throw Error("newGrid: OpenVDB has no registered grid type " + GridT::gridType());
    grid->tree().root().setBackground(background, /*updateChildNodes=*/false);
    return grid;
}

} // namespace turb
