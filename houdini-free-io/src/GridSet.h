// Private to turb_io: a file's grids, and the checked atomic write, shared by the OpenVDB writer (Vdb.cc) and the
// NanoVDB writer (NanoVdb.cc): writeFrame builds one set of grids and hands it to either, through the same machinery.
#pragma once

#include <turbio/Vdb.h>

#include <openvdb/openvdb.h>

#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace turbio::detail {

/// The grids of one file, in file order, and its file-level metadata.
struct GridSet
{
    openvdb::GridPtrVec grids;
    openvdb::MetaMap meta;
};

/// Every grid of the VDB file `path` as stored (half floats read as float), and its file metadata, through the
/// guarded reader: a missing, damaged or newer file is a turb::IoError naming it; a file that crashes or hangs
/// OpenVDB too. `timeout`: ReadOptions::readTimeout.
GridSet readEveryGrid(const std::string& path, double timeout);

/// Writes `path` atomically: `body` writes the file's bytes to a stream over a new temporary file in the same
/// directory (seekable; every write checked), which is fsynced and renamed over `path` (with `noClobber`, linked,
/// failing if `path` exists). Temporaries a killed run left for `path` are removed first. A full disk, a file-size
/// limit or an I/O error is a turb::TransientError / IoError naming `path`, an exception from `body` an IoError with
/// its message; either way the temporary file is removed and nothing appears at `path`. `forkGuarded`: hold
/// forkGuard() while `body` runs (OpenVDB's Blosc writer holds a global mutex a forked reader must not inherit).
void writeFileChecked(
    const std::string& path, bool noClobber, const std::function<void(std::ostream&)>& body, bool forkGuarded = false);

/// The NanoVDB writer (NanoVdb.cc): `set`'s grids converted one for one (float grids other than level sets
/// quantised as `quantization` says) and written atomically to `path` (writeFileChecked). `set.meta` is not written:
/// NanoVDB files hold no string metadata. A grid NanoVDB cannot hold is a turb::IoError naming it, before the file is
/// opened.
void writeNanoVdb(const std::string& path, const GridSet& set, NanoQuantization quantization, bool noClobber);

} // namespace turbio::detail
