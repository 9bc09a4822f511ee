// Private to turb_io: the checks and messages readFrame and the header scans (Scan.cc) share, so a dry run
// fails with the same words as the run.
#pragma once

#include <turb/Error.h>
#include <turbio/Vdb.h>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace turbio::detail {

/// "PATH: no velocity (...) grid; the file has: LISTING.", naming the setting that chooses the grid
/// ("velocityGrid"; the caller's own name for it, such as a flag, follows the listing); a selector given in `options`
/// that is a typo of one of `names` (the file's grid selectors) gets "(did you mean 'NAME'?)".
turb::IoError missingGrid(const std::string& path, GridRole role, const ReadOptions& options, const std::string& listing,
    const std::vector<std::string>& names);

/// "PATH: none of the requested grids is present; the file has: LISTING.", naming densityGrid and velocityGrid.
turb::IoError noRequestedGrid(const std::string& path, const std::string& listing);

/// The file's grids cannot give a frame whatever the selectors: it holds no grids (an empty frame, as Houdini writes
/// for geometry without volumes) or only VDB points (particles). The message, or "" when it holds volumes. `types`
/// are the grids' value types ("float", "ptdataidx32", ...).
std::string noVolumeProblem(const std::string& path, const std::vector<std::string>& types, const std::string& listing);

/// "PATH: grid 'G' is a level set ...": a level set (signed distances) chosen as the density.
std::string levelSetDensityMessage(const std::string& path, const std::string& grid);

/// "PATH: grid 'G' has a MAP transform with ...; vdbturb supports only uniform voxels with a translation."
std::string unsupportedTransformMessage(const std::string& path, const std::string& grid, const std::string& mapType);

/// The voxels of `target` whose centres lie inside the world-space cells of box `b` on lattice `own`.
turb::CoordBBox boxOnLattice(const turb::CoordBBox& b, const turb::Lattice& own, const turb::Lattice& target);

/// "" when a dense frame over `domain` fits (ReadOptions::maxVoxels and 80% of the usable memory); else the
/// message, naming every grid's span.
std::string denseSizeProblem(const std::string& path, const turb::CoordBBox& domain,
    const std::vector<std::pair<std::string, turb::CoordBBox>>& spans, double bytesPerVoxel,
    const ReadOptions& options);

/// Throws denseSizeProblem's message, if any: a turb::TransientError (exit 75: retry) when the dense fields would
/// fit this machine's memory and only a job's limit or other processes hold them back, else a turb::IoError.
void checkDenseSize(const std::string& path, const turb::CoordBBox& domain,
    const std::vector<std::pair<std::string, turb::CoordBBox>>& spans, double bytesPerVoxel,
    const ReadOptions& options);

/// Blender's simulation box [0, `baseResolution`) when Blender wrote the file (its `creator` is not vdbturb): Mantaflow
/// writes nothing outside it, so voxels there are strays. None for vdbturb's Blender-style files, whose boxes start
/// where the frame's does, and for files without Blender's metadata.
std::optional<turb::CoordBBox> blenderSimulationBox(
    const std::optional<turb::Coord>& baseResolution, const std::string& creator);

} // namespace turbio::detail
