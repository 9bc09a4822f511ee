/// @file Scan.h
/// @brief What reading a sequence will give, from file headers only (no voxels): each frame's lattice,
///        domain, chosen grids, units and time step, and the frames where the lattice changes.
///
/// `info`, every dry run and the checks each command runs before its first frame use this, so a dry run
/// fails where the run would (a missing grid, a truncated file, a newer file format, an unsupported
/// transform, a lattice that changes halfway) without reading a voxel.
///
/// @code
/// turbio::SequenceScan scan = turbio::scanSequence(seq, seq.frames, readOptions);
/// if (!scan.changes.empty()) std::cerr << scan.describeChanges() << "\n";
/// @endcode
#pragma once

#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <string>
#include <vector>

namespace turbio {

/// One frame as a read with the same ReadOptions will see it.
struct FrameScan
{
    int frame = 0;
    std::string path;
    std::string error; ///< non-empty: reading this frame will fail; the message names the file and grid
    std::vector<std::string> errorSettings; ///< the ReadOptions fields that fix the error (turb::Error::settings)
    turb::Lattice lattice;                  ///< the frame's lattice (the density's, else the velocity's)
    turb::CoordBBox domain; ///< index box of the dense frame: `span` cropped to the smoke and its margin
                            ///< (ReadOptions::cropToSmoke); from the density's header box, or from its voxels
                            ///< when that box is far larger than its voxels (strays), so it bounds the read's
    turb::CoordBBox span;   ///< Blender's domain, else the union of the grids' active boxes
    std::optional<turb::CoordBBox> sequenceDomain; ///< FileInfo::sequenceDomain: where preview frames the sequence
    turb::CoordBBox others;        ///< Blender's domain and the non-density grids' boxes: how far a margin may reach
    SmokeRegion region;            ///< the smoke (strays only when the voxels were read: regionFromVoxels)
    bool regionFromVoxels = false; ///< the density's voxels were read to find the smoke
    bool domainKnown = false;      ///< the headers held the active boxes (or the voxels were read for them)
    std::string densityGrid;       ///< selector of the density grid a read uses; empty if none
    std::string velocityGrid;      ///< selector of the velocity grid (or the x component); empty if none
    double velocityVoxel = 0.0;    ///< the velocity grid's own voxel size (differs from lattice: it is resampled)
    long long densityActive = -1;  ///< active voxels of the density grid, from the header; -1 unknown
    long long velocityActive = -1; ///< active voxels of the velocity grid, from the header; -1 unknown
    ReadReport timing;             ///< dt and velocity units with their sources
    std::optional<turb::Coord> blenderResolution; ///< file_base_resolution of a cache Blender wrote (not vdbturb)
    std::vector<GridInfo> grids;   ///< every grid of the file, in file order
};

/// Scans one file's headers. Never throws for a bad file: the problem goes into FrameScan::error (and
/// errorSettings).
/// With `readVoxelsIfNeeded`, a file whose headers lack active boxes is read (in the guarded child) for them.
FrameScan scanFrame(const std::string& path, int frame, const ReadOptions& options, bool readVoxelsIfNeeded = false);

/// Two consecutive scanned frames on different lattices (voxel size or placement).
struct LatticeChange
{
    int fromFrame = 0, toFrame = 0;
    std::string fromPath, toPath;
    turb::Lattice from, to;
    bool voxelSizeChanged = false; ///< else only the origin moved
};

struct SequenceScan
{
    std::vector<FrameScan> frames;      ///< in the order scanned
    std::vector<LatticeChange> changes; ///< where consecutive frames' lattices differ
    /// Non-empty for a cache Blender baked with an Adaptive Domain: its simulation box (file_base_resolution) changes
    /// from frame to frame and Blender writes each frame's box scaled over the whole domain, so the files' voxel sizes
    /// and positions are not the simulation's. Says which frames show it. Every command but `info` refuses such a
    /// sequence (CheckInput); a single frame cannot show it.
    std::string blenderAdaptive;

    /// The first frame that will fail to read, with its error and errorSettings; nullptr when every frame reads.
    const FrameScan* firstFailure() const;
    /// "voxel size changes from 0.1 at frame 2 (a.0002.vdb) to 0.2 at frame 3 (a.0003.vdb); ..." (at most `most`).
    std::string describeChanges(size_t most = 4) const;
    /// The frame with the largest domain (for memory estimates); nullptr when none is known.
    const FrameScan* largestDomain() const;
};

/// Scans `frames` of `seq` (frames that are not on disk are skipped: the caller reports missing frames).
/// `readVoxelsIfNeeded` applies to the first frame only (the others keep header boxes or none).
SequenceScan scanSequence(
    const Sequence& seq, const std::vector<int>& frames, const ReadOptions& options, bool readVoxelsIfNeeded = false);

/// Whether `a` and `b` are one lattice (voxel size and placement).
bool sameLattice(const turb::Lattice& a, const turb::Lattice& b);

} // namespace turbio
