/// @file Checksum.h
/// @brief Fingerprints of the grids in a VDB file, for grid-based regression tests: two files whose grids have
///        the same names, types, transforms, active voxels and values (bit for bit) get the same fingerprints,
///        whatever the file's UUID, compression or tree layout.
///
/// @code
/// for (const turbio::GridChecksum& g : turbio::gridChecksums("up/turb.0001.vdb"))
///     std::cout << g.name << ' ' << g.values << '\n';
/// @endcode
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace turbio {

struct GridChecksum
{
    std::string name;
    std::string valueType;      ///< "float", "vec3s", ...
    long long activeVoxels = 0; ///< active voxels, tiles counted voxel by voxel
    uint64_t values = 0;   ///< FNV-1a over the transform, the grid class and every active voxel's (coordinate, value
                           ///< bits) in index order; tiles count as their voxels
    uint64_t metadata = 0; ///< FNV-1a over the grid's metadata (name, type, value as text), sorted by name, leaving
                           ///< out OpenVDB's own statistics (file_bbox_*, file_mem_bytes, file_voxel_count)
};

/// Every grid of the file, in file order. Throws turb::IoError naming the file when it cannot be read, and
/// naming the grid when its value type is not one vdbturb reads (float, double, int32, int64, bool, vec3s, vec3d,
/// vec3i).
std::vector<GridChecksum> gridChecksums(const std::string& path);

/// 16 hex digits.
std::string hexDigest(uint64_t h);

} // namespace turbio
