// Private to turb_io: runs OpenVDB's file reader (or NanoVDB's, and its converter) in a child process.
//
// OpenVDB 10's reader trusts the bytes it reads: a corrupt Blosc/zip chunk or a damaged node mask can
// corrupt the heap (abort, segfault) or loop forever; NanoVDB's reader and converter follow the offsets a file
// holds. A render-farm tool must turn that into an error naming the file, not a crash. The child opens the file,
// runs the caller's read body, and streams the resulting grids back uncompressed over a pipe; the parent only ever
// parses that trusted stream.
//
// The body runs in a forked child of a possibly multi-threaded process, so it must not start TBB work:
// OpenVDB's readGrid/readAllGridMetadata and serial iteration are fine; tools:: algorithms, voxel
// counts and bounding-box evaluation (which use TBB in OpenVDB 10) are not.
#pragma once

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace turbio::detail {

struct GuardedResult
{
    openvdb::GridPtrVec grids;
    openvdb::MetaMap::Ptr meta;
};

/// What a read body reads in the child: an OpenVDB file through io::File, or a NanoVDB file whose grids are converted
/// to OpenVDB grids there (NanoRead.cc), so both kinds of file go through the same bodies. The calls are io::File's.
class GridSource
{
public:
    virtual ~GridSource() = default;
    /// OpenVDB's unique names of the grids ("density", "vel\x1e1" for a second 'vel', "\x1e0" for an unnamed grid):
    /// for OpenVDB in io::File's order (by name; Vdb.cc's listGrids puts them in file order), for NanoVDB in file
    /// order.
    virtual std::vector<std::string> names() = 0;
    /// A grid's header: name, class, transform and metadata, no voxels.
    virtual openvdb::GridBase::Ptr readGridMetadata(const std::string& unique) = 0;
    /// A whole grid.
    virtual openvdb::GridBase::Ptr readGrid(const std::string& unique) = 0;
    /// Every grid, in file order (io::File::getGrids).
    virtual openvdb::GridPtrVec readAll() = 0;
    /// The file's own metadata (none for NanoVDB, whose files hold none), or null.
    virtual openvdb::MetaMap::Ptr getMetadata() = 0;
    virtual uint32_t fileVersion() const = 0;
    virtual std::pair<int, int> libraryVersion() const = 0;
};

using ReadBody = std::function<void(GridSource& file, openvdb::GridPtrVec& grids, openvdb::MetaMap& meta)>;

/// The child's NanoVDB source (NanoRead.cc): the file read by NanoVDB's own reader after its headers were checked
/// (inspectNanoFile), each grid's checksum verified, grids copied node by node into OpenVDB trees when a body reads
/// them. Only float (and its quantised forms fp4, fp8, fp16, fpN), double, vec3f and vec3d grids are read; any other
/// is a turb::IoError naming the grid and its type when a body reads it. Runs only in the reader child.
std::unique_ptr<GridSource> openNanoSource(const std::string& path);

/// Held while a reader forks and while the parent parses a child's grids, and by every VDB write: a child inherits
/// each mutex as it was at the fork, so a fork while another thread is inside Blosc (whose compressor holds a global
/// mutex) or OpenVDB's stream parse (the grid and metadata registries) would leave the child waiting for ever. With
/// this, reads may run on one thread while another computes and writes (transfer reads the next frame ahead).
std::mutex& forkGuard();

/// For read bodies: keeps `grid` alive until the child exits (the grids a body returns are kept already). OpenVDB 10 frees a tree's nodes with tbb::parallel_for,
/// which in a forked child can wait for ever on pool threads the fork did not copy (seen with gdb: a child stuck in
/// ~Tree after its stream was written), so nothing read in the child is ever destroyed there; _exit frees it all.
void keepInChild(const openvdb::GridBase::Ptr& grid);

/// OpenVDB messages may quote bytes of a damaged file: keep them printable and short.
std::string cleanMessage(const std::string& message);

/// Opens `path` (OpenVDB, or NanoVDB by its magic number) in a child process and runs `body` there. turb::Error thrown
/// by the body is rethrown here as turb::IoError with its message and settings; a crash, a hang longer than
/// `timeoutSeconds` in two readers in a row (the first may have inherited a lock held at the fork) or a memory blow-up
/// becomes a turb::IoError naming the file.
GuardedResult guardedRead(const std::string& path, const ReadBody& body, double timeoutSeconds);

} // namespace turbio::detail
