/// @file Vdb.h
/// @brief Reading any smoke cache (Houdini, Blender/Mantaflow, EmberGen, vdbturb) into a turb::Frame,
///        and writing frames back. The only code in vdbturb that opens VDB files.
///
/// Reading applies the cache conventions once, so stages never see them:
/// - grids are found by alias (density: density, density_noise; velocity: vel, velocity, v, or the three
///   float grids vel.x/vel.y/vel.z; temperature: temperature, heat; flame: flame, flames);
/// - staggered (MAC) velocity is averaged to cell centres;
/// - Blender's velocity (grid cells per time unit) is scaled to world units;
/// - double and half-float grids become float; Int32 and unknown grids are ignored.
///
/// Every failure throws turb::IoError naming the file and, where there is one, the grid.
///
/// @code
/// turbio::ReadOptions opt;
/// turb::Frame f = turbio::readFrame("blender-plume-32/fluid_data_0010.vdb", 10, opt);
/// turbio::writeFrame("out/plume.0010.vdb", f, turbio::WriteOptions{});
/// @endcode
#pragma once

#include <turb/Frame.h>

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace turbio {

enum class VelocityUnits
{
    Auto,  ///< detect: Blender's staggered `velocity` with `file_base_resolution` is in cells
    World, ///< world units per time unit (Houdini, EmberGen, vdbturb)
    Cells  ///< grid cells per time unit (Blender/Mantaflow)
};

/// Which role a grid plays for vdbturb.
enum class GridRole { Density, Velocity, Temperature, Flame, Other };

struct ReadOptions
{
    std::string densityGrid;   ///< grid name overriding the density aliases; empty = aliases
    std::string velocityGrid;  ///< grid name (or "name.x" stem) overriding the velocity aliases
    VelocityUnits velocityUnits = VelocityUnits::Auto; ///< unit convention of the velocity grid
    bool requireDensity = true;   ///< a missing density grid is an error (else the field stays empty)
    bool requireVelocity = true;  ///< a missing velocity grid is an error (else the field stays empty)
    bool readExtras = true;       ///< also read temperature and flame when present
    double dt = 0.0;              ///< time per frame; > 0 overrides metadata and writer defaults
    double fps = 24.0;            ///< frames per second used for writer defaults of dt (Houdini, Blender)
    bool checkFinite = true;      ///< NaN/Inf voxels are an error naming the grid
    double maxVoxels = 5.0e8;     ///< largest dense domain accepted (velocity needs 12 bytes a voxel)
    int extendVelocity = 0;       ///< continue velocity this many voxels past the grid's active region (caches
                                  ///< that clip velocity to the smoke, as Blender's do); 0 = inactive reads as zero
};

/// The aliases of a role, in priority order.
const std::vector<std::string>& gridAliases(GridRole role);

/// Chooses the grid of `role` among `names` (an override wins and must exist). For velocity the result
/// may be three names (x, y, z components). Empty when nothing matches.
std::vector<std::string> resolveGrid(const std::vector<std::string>& names, GridRole role,
    const std::string& overrideName = "");

/// Reads one frame. `frameNumber` is stored in the frame.
turb::Frame readFrame(const std::string& path, int frameNumber, const ReadOptions& options);

/// Convention of the written grids.
enum class WriteStyle
{
    Houdini, ///< `vel` (Vec3s, contravariant relative, world units, cell-centred) + `density`
    Blender  ///< `velocity` (staggered, grid cells per time unit) + `density`, with Blender's metadata
};

struct WriteOptions
{
    WriteStyle style = WriteStyle::Houdini; ///< naming and unit convention of the written grids
    bool noClobber = false;   ///< refuse to replace an existing file
    bool halfFloat = false;   ///< store floats as half (smaller, ~3 significant digits)
    float densityTolerance = 0.0f;  ///< density at or below this is written inactive (sparse)
};

/// Writes a frame atomically: to a temporary file in the same directory, then renamed over `path`,
/// so readers never see a partial file and a failed write leaves any previous file untouched.
/// Frame metadata becomes grid metadata; "vdbturb_dt" records dt.
void writeFrame(const std::string& path, const turb::Frame& frame, const WriteOptions& options);

/// Writes `bytes` to `path` atomically (used for images and reports too).
void writeFileAtomic(const std::string& path, const std::string& bytes, bool noClobber = false);

/// Atomic write through a writer that creates the file itself (OpenImageIO, OpenVDB): `write` is given
/// a temporary name in the same directory as `path`; when it returns, the file is renamed over `path`
/// (with `noClobber`, linked, failing if `path` exists). If `write` throws, the temporary file is
/// removed and the exception propagates; nothing appears at `path`.
void writeAtomically(const std::string& path, bool noClobber, const std::function<void(const std::string& tmp)>& write);

// ---------------------------------------------------------------------------------------------
// Inspection (vdbturb info)

struct GridInfo
{
    std::string name;
    std::string valueType;   ///< "float", "vec3s", "int32", ...
    std::string gridClass;   ///< "fog volume", "staggered", "level set", "unknown"
    std::string vectorType;  ///< "invariant", "covariant", "contravariant relative", ...
    GridRole role = GridRole::Other;
    std::string units;       ///< velocity only: "world" or "cells" (detected)
    bool halfFloat = false;  ///< stored as half on disk
    double voxelSize = 0.0;
    turb::Vec3d origin{0.0}; ///< world position of voxel (0,0,0)'s centre
    std::string mapType;     ///< OpenVDB map type name
    bool supportedTransform = true; ///< uniform scale + translation
    bool hasBBox = false;
    turb::CoordBBox activeBBox; ///< from the file's header statistics
    long long activeVoxels = -1; ///< from header statistics; -1 if not recorded
    bool hasRange = false;   ///< value range read from the voxels (only when asked)
    double minValue = 0.0, maxValue = 0.0; ///< scalar range, or vector magnitude range
};

struct FileInfo
{
    std::string path;
    unsigned fileVersion = 0;
    std::string libraryVersion;
    std::string creator;          ///< file-level "creator" metadata, if any
    std::optional<turb::Coord> baseResolution; ///< Blender's file_base_resolution
    std::vector<GridInfo> grids;
};

/// Reads a file's header and grid descriptors (fast: no voxel data), and with `readValues` also
/// each float/vector grid's value range.
FileInfo inspectFile(const std::string& path, bool readValues);

/// Name of a role, for messages ("density", "velocity", ...).
const char* roleName(GridRole role);

} // namespace turbio
