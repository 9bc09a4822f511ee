// Private to turb_io: what turbio::OtherGrids holds, shared by the reader and writer (Vdb.cc) and the
// transformations (OtherGrids.cc).
#pragma once

#include <turbio/Vdb.h>

#include <openvdb/openvdb.h>

namespace turbio {

struct OtherGrids::Impl
{
    openvdb::GridPtrVec grids;     ///< in file order, full precision (the half-float flag restored on write)
    std::vector<bool> followFrame; ///< per grid: on the frame's lattice, so it is resampled and turned with it
};

} // namespace turbio
