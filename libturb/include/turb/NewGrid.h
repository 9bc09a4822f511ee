/// @file NewGrid.h
/// @brief An empty typed OpenVDB grid made by OpenVDB's grid registry instead of GridT::create. Constructing a
/// Grid<TreeT> in a file instantiates its and its tree's virtual functions (IO, copying, merging, statistics) there:
/// 5-8 s of compile time for each grid type in each file (NanoRead.cc took 53 s for eight types, OtherGrids.cc 59 s for
/// nine). Through the registry libopenvdb's own instantiations are used, and a file instantiates only what it calls.
#pragma once

#include <openvdb/openvdb.h>

namespace turb {

/// An empty grid of type GridT (one OpenVDB registers: openvdb::initialize's types) with background `background`.
template<typename GridT>
typename GridT::Ptr newGrid(const typename GridT::ValueType& background)
{
    openvdb::initialize(); // registers the types; a no-op after the first call
    auto grid = openvdb::GridBase::grid<GridT>(openvdb::GridBase::createGrid(GridT::gridType()));
    grid->tree().root().setBackground(background, /*updateChildNodes=*/false);
    return grid;
}

} // namespace turb
