// Private to turb_io: runs OpenVDB's file reader in a child process.
//
// OpenVDB 10's reader trusts the bytes it reads: a corrupt Blosc/zip chunk or a damaged node mask can
// corrupt the heap (abort, segfault) or loop forever. A render-farm tool must turn that into an error
// naming the file, not a crash. The child opens the file, runs the caller's read body, and streams the
// resulting grids back uncompressed over a pipe; the parent only ever parses that trusted stream.
//
// The body runs in a forked child of a possibly multi-threaded process, so it must not start TBB work:
// OpenVDB's readGrid/readAllGridMetadata and serial iteration are fine; tools:: algorithms, voxel
// counts and bounding-box evaluation (which use TBB in OpenVDB 10) are not.
#pragma once

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <functional>
#include <mutex>
#include <string>

namespace turbio::detail {

struct GuardedResult
{
    openvdb::GridPtrVec grids;
    openvdb::MetaMap::Ptr meta;
};

using ReadBody = std::function<void(openvdb::io::File& file, openvdb::GridPtrVec& grids, openvdb::MetaMap& meta)>;

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

/// Opens `path` in a child process and runs `body` there. turb::Error thrown by the body is rethrown here as
/// turb::IoError with its message and settings; a crash, a hang longer than `timeoutSeconds` in two readers in a
/// row (the first may have inherited a lock held at the fork) or a memory blow-up becomes a turb::IoError naming
/// the file.
GuardedResult guardedRead(const std::string& path, const ReadBody& body, double timeoutSeconds);

} // namespace turbio::detail
