/// @file NanoVdb.h
/// @brief NanoVDB files (.nvdb), as GPU renderers load them: a VDB file turned into one, grid for grid, and a
///        NanoVDB file's headers read for `vdbturb info`. Frames are written as NanoVDB by turbio::writeFrame
///        (Vdb.h) with WriteOptions::format, or an output name ending in ".nvdb" (docs/nanovdb.md).
///
/// Every failure throws turb::IoError naming the file and, where there is one, the grid; a full disk or a file-size
/// limit is a turb::TransientError, as for VDB output.
///
/// @code
/// turbio::NanoConvertOptions opt;
/// opt.quantization = turbio::NanoQuantization::Fp16;
/// turbio::NanoConvertReport r = turbio::convertToNanoVdb("up/turb.0010.vdb", "up/turb.0010.nvdb", opt);
/// turbio::NanoFileInfo info = turbio::inspectNanoFile("up/turb.0010.nvdb"); // info.grids[0].valueType == "fp16"
/// @endcode
#pragma once

#include <turb/Frame.h>
#include <turbio/Vdb.h>

#include <string>
#include <vector>

namespace turbio {

/// One grid of a NanoVDB file, from its headers.
struct NanoGridInfo
{
    int index = 0;              ///< position in the file
    std::string name;           ///< the grid's name ("" for an unnamed grid)
    std::string valueType;      ///< NanoVDB's grid type: "float", "fp16", "fp8", "vec3f", "double", "int32", ...
    std::string gridClass;      ///< "fog volume", "level set", "staggered", "unknown", ...
    long long activeVoxels = 0; ///< active voxels, tiles counted by their voxels
    bool hasBBox = false;       ///< false for an empty grid
    turb::CoordBBox activeBBox; ///< index-space bounding box of the active voxels
    turb::Vec3d voxelSize{0.0}; ///< world units per voxel along x, y and z
    bool hasTransform = false;  ///< origin is known (the grid's header was read: an uncompressed grid)
    turb::Vec3d origin{0.0};    ///< world position of voxel (0,0,0)'s centre: the map's translation
    double matrix[9] = {};      ///< with hasTransform: the map's 3x3 index-to-world matrix, as NanoVDB stores it
    turb::Vec3d worldMin{0.0}, worldMax{0.0}; ///< NanoVDB's world bounding box of the active voxels
    long long bytes = 0;                      ///< the grid's size in memory (the GPU upload)
    long long fileBytes = 0;                  ///< its size in the file (the same when uncompressed)
    std::string codec;                        ///< the file's compression of it: "none", "zip" or "blosc"
    std::string version;                      ///< the NanoVDB format version that wrote it ("32.4.2")
};

/// A NanoVDB file's grids, from its headers (no voxel is read).
struct NanoFileInfo
{
    std::string path;
    long long fileBytes = 0; ///< the file's size
    std::vector<NanoGridInfo> grids;
};

/// Reads the headers of the NanoVDB file `path`, every size checked against the file before it is used, so a
/// damaged or truncated file is an IoError, never a crash. Throws IoError for a missing file, a file that is not
/// NanoVDB (bad magic number), one of another NanoVDB major version, and one that is truncated or damaged.
NanoFileInfo inspectNanoFile(const std::string& path);

/// True when `path` ends in ".nvdb" (any case).
bool isNanoVdbPath(const std::string& path);

/// True when the file `path` begins with "NanoVDB", NanoVDB's magic number (format 32.4 writes "NanoVDB0", later
/// formats "NanoVDB1"/"NanoVDB2", which inspectNanoFile names), whatever its name. Every reader (Vdb.h) reads
/// such a file as NanoVDB. False for a file that cannot be read.
bool isNanoVdbFile(const std::string& path);

struct NanoConvertOptions
{
    NanoQuantization quantization = NanoQuantization::Float; ///< float grids other than level sets
    bool noClobber = false;                                  ///< refuse to replace an existing file
    double readTimeout = 0.0;                                ///< ReadOptions::readTimeout for the guarded VDB read
};

/// What a conversion wrote.
struct NanoConvertReport
{
    std::vector<std::string> grids;   ///< written, in file order: "'density' fp16 fog volume"
    std::vector<std::string> skipped; ///< grids NanoVDB cannot hold, left out: "'name' (vec3i: why)"
    long long bytes = 0;              ///< the NanoVDB file's size
};

/// Writes every grid of the VDB file `vdbPath` as stored (names, classes, transforms and values; half floats as
/// float; no unit or naming convention applied) to the NanoVDB file `nvdbPath`, atomically, float grids other than
/// level sets quantised as `options` says. Grids NanoVDB cannot hold (a type it has no counterpart for, a frustum
/// transform) are left out and listed in the report; a file with none it can hold is an IoError. The VDB file is read
/// through the guarded reader (Vdb.h): a missing, damaged or truncated file is an IoError naming it, and so is a float
/// or vector grid with NaN or Inf among its active values (naming the grid and the first voxel); then nothing is
/// written.
NanoConvertReport convertToNanoVdb(
    const std::string& vdbPath, const std::string& nvdbPath, const NanoConvertOptions& options);

/// Why NanoVDB cannot hold a grid `inspectFile` describes ("a NonlinearFrustumMap transform (NanoVDB holds affine
/// transforms only)", "a vec3i grid (...)"), or "" when it can: for checks before anything is converted.
std::string nanoVdbCannotHold(const GridInfo& grid);

/// The name of a quantisation as the command line writes it: "float", "fp16", "fp8".
const char* quantizationName(NanoQuantization q);

} // namespace turbio
