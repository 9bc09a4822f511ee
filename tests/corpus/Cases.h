// The bad-input corpus: one row per case. tests/corpus/make_corpus.cc writes each case's files
// into the build tree; tests/io/test_corpus.cc runs every cache-reading command on them and checks the row.
#pragma once

#include <string>
#include <vector>

namespace corpus {

/// The commands every case runs through, in this order.
enum Command { kInfo, kTransfer, kSynth, kMeasure, kResample, kPreview, kConvert, kCommands };
inline const char* commandName(int c)
{
    static const char* names[] = {"info", "transfer", "synth", "measure", "resample", "preview", "convert"};
    return names[c];
}

/// Where a case's bad file lives. Each case directory holds t.####.vdb (a target: coarse, velocity and
/// density) and s.####.vdb (its source at 4x the resolution); the subject is the sequence with the bad file.
enum class Subject {
    Target, ///< the bad file is in t.####.vdb: transfer's --target, measure's --target, the cache of the others
    Source  ///< the bad file is in s.####.vdb: transfer's --source, measure's --output, the cache of the others
};

enum Flags : unsigned {
    kNone = 0,
    kAsNobody = 1,     ///< run the commands as an unprivileged user (permissions mean nothing to root)
    kOutReadOnly = 2,  ///< the output directory exists and is read-only
    kOutIsInput = 4,   ///< --out names the subject's own files
    kOutUnderFile = 8, ///< --out goes through a path whose parent is a regular file
    kPadding3 = 16,    ///< the subject pattern asks for 3-digit frames (the files have 4)
    kDirectory = 32,   ///< the subject is given as its directory
};

/// Expected exit code: 0, 1, or kEither (damage a reader cannot detect: a flipped voxel value reads fine).
constexpr int kEither = -1;

struct Case
{
    const char* name;
    const char* what; ///< one line for docs/reliability.md
    Subject subject;
    int badFrame;          ///< frame number of the bad file (0: every frame / not a file problem)
    int expect[kCommands]; ///< exit code per command
    const char* says;      ///< words the message must hold besides the file name: "a;b" all of, "a|b" any of
    unsigned flags;
};

// Codes per command:       info transfer synth measure resample preview convert
inline const std::vector<Case>& cases()
{
    static const std::vector<Case> all = {
        // Files that are not (whole) VDB files.
        {"empty_file", "zero-byte file", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "too short", kNone},
        {"not_vdb", "a text file named .vdb", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "not an OpenVDB file", kNone},
        {"format_225", "file format 225 (OpenVDB 13)", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1},
            "file format 225;newer OpenVDB", kNone},
        {"directory", "a directory where frame 2 is expected", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1},
            "is a directory", kNone},
        {"unreadable", "frame 2 unreadable (mode 000, run unprivileged)", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1},
            "Permission denied", kAsNobody},
        {"cut_in_header", "cut 20 bytes into the header", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "truncated",
            kNone},
        // Truncation of a real Blender frame at many offsets (fraction of its 60 kB).
        {"cut_5", "Blender frame cut at 5%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_15", "Blender frame cut at 15%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_30", "Blender frame cut at 30%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_50", "Blender frame cut at 50%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_70", "Blender frame cut at 70%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_90", "Blender frame cut at 90%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_99", "Blender frame cut at 99%", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"cut_last_byte", "Blender frame missing its last byte", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1}, "truncated",
            kNone},
        // Bit flips in the header, metadata, topology and compressed data of a real Blender frame.
        {"flip_magic", "flipped bit in the magic number", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1},
            "not an OpenVDB file", kNone},
        {"flip_grid_offset", "flipped high bit in a grid's file offset", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1},
            "inconsistent offsets|truncated", kNone},
        {"flip_grid_meta_count", "flipped bit in a grid's metadata count", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1},
            "damaged metadata", kNone},
        {"flip_meta_length", "flipped bit in a grid metadata entry's length", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1},
            "damaged metadata", kNone},
        {"flip_file_meta", "flipped bit in the file metadata's length", Subject::Target, 1, {1, 1, 1, 1, 1, 1, 1},
            "truncated or corrupt", kNone},
        {"flip_blosc_size", "flipped bit in a Blosc chunk's size (compressed data)", Subject::Target, 1,
            {1, 1, 1, 1, 1, 1, 1}, "could not be read|corrupt", kNone},
        {"flip_topology", "flipped bit in a grid's topology (8^3 frame 2)", Subject::Target, 2,
            {kEither, kEither, kEither, kEither, kEither, kEither, kEither}, "", kNone},
        {"flip_random_1", "4 random bit flips past the header of 8^3 frame 2 (seed 1)", Subject::Target, 2,
            {kEither, kEither, kEither, kEither, kEither, kEither, kEither}, "", kNone},
        {"flip_random_2", "4 random bit flips past the header of 8^3 frame 2 (seed 2)", Subject::Target, 2,
            {kEither, kEither, kEither, kEither, kEither, kEither, kEither}, "", kNone},
        {"flip_random_3", "4 random bit flips past the header of 8^3 frame 2 (seed 3)", Subject::Target, 2,
            {kEither, kEither, kEither, kEither, kEither, kEither, kEither}, "", kNone},
        {"flip_random_4", "4 random bit flips past the header of 8^3 frame 2 (seed 4)", Subject::Target, 2,
            {kEither, kEither, kEither, kEither, kEither, kEither, kEither}, "", kNone},
        {"reader_crash", "Houdini vel file with the bit that crashes OpenVDB 10 (byte 71344)", Subject::Target, 1,
            {1, 1, 1, 1, 1, 1, 1}, "", kNone},
        {"reader_hang",
            "Blender 128^3 frame with the bit that makes OpenVDB 10 loop (byte 172654; some runs read "
            "uninitialised memory and fail instead, as a damaged header)",
            Subject::Source, 1, {1, 1, 1, 1, 1, 1, 1}, "did not finish|could not be read|damaged header", kNone},
        // NanoVDB frames (EmberGen's and renderers' caches) named as the VDB frames: read as VDB frames are, and
        // damaged ones refused before anything reads them wrong.
        {"nvdb_frame", "frame 2 a NanoVDB file (float) among VDB frames", Subject::Target, 0, {0, 0, 0, 0, 0, 0, 0}, "",
            kNone},
        {"nvdb_cut", "NanoVDB frame 2 cut at 60%", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "truncated", kNone},
        {"nvdb_header", "NanoVDB frame 2 with a damaged segment header (grid count 0)", Subject::Target, 2,
            {1, 1, 1, 1, 1, 1, 1}, "damaged NanoVDB file", kNone},
        {"nvdb_checksum", "NanoVDB frame 2 with a flipped bit in a density value (its checksum)", Subject::Target, 2,
            {1, 1, 1, 1, 1, 1, 1}, "checksum", kNone},
        // Grids and values.
        {"int32_density", "'density' is an Int32 grid", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 0}, "'density';int32",
            kNone},
        {"float_vel", "'vel' is a float grid", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 0}, "'vel';vec3s", kNone},
        {"nan_density", "NaN voxels in frame 2's density", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "'density';NaN",
            kNone},
        {"inf_velocity", "Inf voxels in frame 2's velocity", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "'vel';NaN/Inf",
            kNone},
        {"empty_smoke", "no active density and zero velocity in every frame", Subject::Target, 0, {0, 0, 0, 0, 0, 0, 0},
            "", kNone},
        {"frame_gap", "frames 1, 2, 4: frame 3 missing", Subject::Target, 0, {0, 1, 1, 0, 0, 0, 0}, "missing", kNone},
        {"unnamed_grids", "grids without names (VDB Convert SOP)", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 0},
            "(unnamed)", kNone},
        {"density_only", "density but no velocity (EmberGen export)", Subject::Target, 0, {0, 1, 1, 1, 0, 0, 0},
            "no velocity", kNone},
        {"velocity_only", "velocity but no density", Subject::Target, 0, {0, 1, 0, 1, 0, 1, 0}, "no density", kNone},
        {"lattice_change", "frame 3 re-cached at twice the voxel size", Subject::Target, 3, {0, 1, 1, 0, 0, 0, 0},
            "voxel size changes", kNone},
        {"vel_voxel_scale", "Houdini velocity voxel scale 2 in every frame", Subject::Target, 0, {0, 0, 0, 0, 0, 0, 0},
            "", kNone},
        {"stray_voxel", "one density voxel 20000 voxels away (left out of the region held)", Subject::Target, 2,
            {0, 0, 0, 0, 0, 0, 0}, "", kNone},
        {"rotated", "rotated transform", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 0}, "uniform voxels", kNone},
        {"nonuniform_scale", "non-uniform scale", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 0}, "uniform voxels", kNone},
        {"frustum", "frustum transform", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 1}, "uniform voxels|affine transforms",
            kNone},
        {"component_lattices", "vel.x/.y/.z on different lattices", Subject::Target, 2, {1, 1, 1, 1, 1, 1, 0},
            "different lattices", kNone},
        {"double_half_components", "double density, half-float vel.x/.y/.z", Subject::Target, 0, {0, 0, 0, 0, 0, 0, 0},
            "", kNone},
        {"duplicate_names", "two grids named 'density' (the first is read, as OpenVDB does)", Subject::Target, 0,
            {0, 0, 0, 0, 0, 0, 0}, "", kNone},
        // Target against source.
        {"source_ratio_1_2", "source voxel = target voxel / 1.2", Subject::Source, 0, {0, 1, 0, 1, 0, 0, 0},
            "leaves no detail|not an integer refinement", kNone},
        {"source_rotated", "source with a rotated transform", Subject::Source, 1, {1, 1, 1, 1, 1, 1, 0},
            "uniform voxels", kNone},
        {"source_ratio_2_5", "source voxel = target voxel / 2.5 (transfer resamples it to the nearest integer ratio)",
            Subject::Source, 0, {0, 0, 0, 1, 0, 0, 0}, "not an integer refinement", kNone},
        // Outputs.
        {"out_read_only", "output directory read-only (run unprivileged)", Subject::Target, 0, {0, 1, 1, 0, 1, 1, 1},
            "cannot write into", kAsNobody | kOutReadOnly},
        {"out_is_input", "--out names the input files", Subject::Target, 0, {0, 1, 1, 0, 1, 1, 1}, "input",
            kOutIsInput},
        {"out_under_file", "--out through a path whose parent is a file", Subject::Target, 0, {0, 1, 1, 0, 1, 1, 1},
            "is a file, not a directory", kOutUnderFile},
        // Patterns.
        {"padding_mismatch", "### pattern against 4-digit files", Subject::Target, 0, {1, 1, 1, 1, 1, 1, 1}, "4-digit",
            kPadding3},
        {"directory_as_cache", "the cache given as its directory", Subject::Target, 0, {1, 1, 1, 1, 1, 1, 1},
            "is a directory", kDirectory},
    };
    return all;
}

} // namespace corpus
