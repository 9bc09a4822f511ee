/// @file Vdb.h
/// @brief Reading any smoke cache (Houdini, Blender/Mantaflow, EmberGen, vdbturb) into a turb::Frame,
///        and writing frames back. The only code in vdbturb that opens VDB files.
///
/// Reading applies the cache conventions once, so stages never see them:
/// - grids are found by alias (density: density, density_noise; velocity: vel, velocity, v, or the three
///   float grids vel.x/vel.y/vel.z; temperature: temperature, heat; flame: flame, flames);
/// - staggered (MAC) velocity is averaged to cell centres;
/// - Blender's velocity (grid cells per time unit) is scaled to world units;
/// - double and half-float grids become float; Int32 and unknown grids are ignored;
/// - a NanoVDB file (by its magic number, whatever its name: EmberGen's exports, renderers' .nvdb caches) is read by
///   NanoVDB's reader, its grids converted to OpenVDB grids (quantised floats to float), then as an OpenVDB file's.
///
/// Every failure throws turb::IoError naming the file and, where there is one, the grid; an error that a
/// ReadOptions or WriteOptions field fixes names that field in turb::Error::settings() ("velocityGrid").
///
/// @code
/// turbio::ReadOptions opt;
/// turb::Frame f = turbio::readFrame("blender-plume-32/fluid_data_0010.vdb", 10, opt);
/// turbio::writeFrame("out/plume.0010.vdb", f, turbio::WriteOptions{});
/// @endcode
#pragma once

#include <turb/Frame.h>
#include <turb/Reorient.h>

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace turbio {

enum class VelocityUnits {
    Auto,  ///< detect: Blender's staggered `velocity` with `file_base_resolution` is in cells
    World, ///< world units per time unit (Houdini, EmberGen, vdbturb)
    Cells, ///< grid cells per time unit (Blender/Mantaflow)
    Frame  ///< world units per frame (Blender's volume "Velocity Unit: Frame", Katana's "units / frame"): the time unit
           ///< is a frame, 1/fps seconds, and dt is 1 unless given
};

/// Which role a grid plays for vdbturb.
enum class GridRole { Density, Velocity, Temperature, Flame, Other };

struct ReadOptions
{
    std::string densityGrid;  ///< grid selector overriding the density aliases: a name, OpenVDB's "name[N]" (the
                              ///< N-th grid of that name; "[0]" = the first unnamed grid) or "#N" (the file's N-th
                              ///< grid, as `vdbturb info` numbers them); empty = aliases
    std::string velocityGrid; ///< the same for velocity; a name may also be the stem of NAME.x/.y/.z
    VelocityUnits velocityUnits = VelocityUnits::Auto; ///< unit convention of the velocity grid
    bool requireDensity = true;  ///< a missing density grid is an error (else the field stays empty)
    bool requireVelocity = true; ///< a missing velocity grid is an error (else the field stays empty)
    bool readExtras = true;      ///< also read temperature and flame when present
    double dt = 0.0;             ///< time per frame; > 0 overrides metadata and writer defaults
    double fps = 0.0;            ///< frames per second for the writers' default dt; 0 = not given (24 is assumed,
                                 ///< and ReadReport says so)
    bool checkFinite = true;     ///< NaN/Inf voxels are an error naming the grid
    double maxVoxels = 5.0e8;    ///< largest dense domain accepted (velocity needs 12 bytes a voxel)
    int extendVelocity = 0;      ///< continue velocity this many voxels past the grid's active region (caches
                                 ///< that clip velocity to the smoke, as Blender's do); 0 = inactive reads as zero

    // The region held densely (see SmokeRegion). Without a density grid the frame covers every grid's span.
    bool cropToSmoke = true;     ///< hold only the smoke (plus cropMargin), not the union of the grids' active boxes
    double readTimeout = 0.0;    ///< seconds the guarded reader may take before the file counts as one that hangs
                                 ///< OpenVDB, plus 1 s per 5 MB; 0 = VDBTURB_READ_TIMEOUT_S, else 10
    int cropMargin = 8;          ///< voxels of the frame's lattice kept around the smoke, >= 0: patch radius,
                                 ///< advection reach and the seam band of the stages that read the frame
    float smokeThreshold = 0.0f; ///< active density above this is smoke
    double strayShare = 0.01;    ///< a cluster of smoke holding less than this share of the density mass, and
                              ///< farther than strayDistance from the rest, is a stray: reported, not held, in [0, 1)
    int strayVoxels = 8;     ///< a far cluster of fewer active smoke voxels than this is a stray whatever its mass
    int strayDistance = 32;  ///< voxels; clusters nearer the kept smoke than this are kept, >= 0
    /// Hold every cluster of smoke, strays included (and, in a Blender cache, voxels outside its simulation box):
    /// `--keep-isolated`. The held box then spans them all, which may not fit.
    bool keepIsolated = false;
    /// Called with the strays note (SmokeRegion::describeStrays) of each frame readFrame finds strays in, for a
    /// command to show; empty: the note is in the ReadReport only. The library prints nothing itself.
    std::function<void(const std::string&)> strayNote;
    /// Called by readFrame with (path, note) for what a command should say once per input about how a grid was read:
    /// a velocity, temperature or flame grid whose background is not zero. The note is also in ReadReport::notes.
    std::function<void(const std::string&, const std::string&)> readNote;
    turb::CoordBBox holdBox; ///< non-empty (with cropToSmoke): hold this box instead of the frame's own, for
                             ///< stages that need one box over a sequence (synth: the union of the scans' boxes; a
                             ///< transfer space tile: its core and halo), whether or not it holds smoke
};

/// A cluster of smoke left out of the region: stray voxels far from the main smoke (particles, sourcing,
/// a dilation), which would otherwise stretch the dense box over the whole gap.
struct StrayCluster
{
    turb::CoordBBox box;    ///< its active smoke voxels' bounding box
    long long voxels = 0;   ///< active voxels above the threshold
    double massShare = 0.0; ///< its share of the density mass
    int distance = 0;       ///< voxels between its box and the kept smoke's box (largest axis gap)
};

/// Where a frame's smoke is: density voxels above ReadOptions::smokeThreshold, clustered by leaf node (8^3)
/// with their neighbours; clusters holding a real share of the mass, and those near them, are kept.
struct SmokeRegion
{
    bool hasDensity = false;          ///< a density grid was found
    turb::CoordBBox smoke;            ///< bounding box of the kept clusters (empty: no smoke)
    long long smokeVoxels = 0;        ///< active smoke voxels in the kept clusters
    std::vector<StrayCluster> strays; ///< left out, largest mass first

    /// "1 voxel of density far from the smoke (580 voxels away, 0.067% of its mass, first at [600, 600, 600]),
    /// ignored: see --keep-isolated" (one line, "" without strays).
    std::string describeStrays(const std::string& grid = "density") const;
};

/// The smoke region of one file's density grid (reads that grid only). Throws IoError as readFrame does.
SmokeRegion smokeRegion(const std::string& path, const ReadOptions& options);

/// The box a frame is held over: the smoke dilated by the margin, within `span` (the grids' union or Blender's
/// domain); a single voxel at span's centre when there is no smoke; `span` itself without a density grid.
turb::CoordBBox heldRegion(const SmokeRegion& region, const turb::CoordBBox& span, const ReadOptions& options);

/// How a read interpreted the cache: the time step and velocity units, and where each came from (a flag,
/// metadata, or a writer's convention). Filled by readFrame and scanFrame for logs and dry runs.
struct ReadReport
{
    double dt = 0.0;          ///< time per frame in the velocity's time unit
    std::string dtSource;     ///< e.g. "vdbturb_dt metadata", "ReadOptions::dt", "1/fps seconds"
    std::string dtSetting;    ///< "dt" when ReadOptions::dt decided dt, else "" (the cache or a convention did)
    double fps = 24.0;        ///< the frame rate dt was derived from (when it was)
    std::string fpsSource;    ///< "ReadOptions::fps", "assumed: the cache records no frame rate", "not used"
    std::string fpsSetting;   ///< "fps" when ReadOptions::fps gave the frame rate dt was derived from, else ""
    bool cells = false;       ///< the velocity was in grid cells per time unit and was scaled by the voxel size
    std::string unitsSource;  ///< why the units were taken as they were
    std::string unitsSetting; ///< "velocityUnits" when ReadOptions::velocityUnits decided them (not Auto), else ""
    bool conventionAssumed = false; ///< dt rests on an assumed frame rate / time scale (warn the user once)
    double timeUnit = 1.0;          ///< seconds per time unit of velocity and dt (Frame::timeUnit): 1 = per second;
                                    ///< Blender's is 1 / (fps x dt), 0.4 at time scale 1
    std::string timeUnitSource;     ///< why: "vdbturb_time_unit metadata", "Blender's time unit, 1 / (fps x dt)", ...
    std::vector<std::string> notes; ///< conversions worth one log line (e.g. velocity resampled onto density)
    turb::CoordBBox span;           ///< readFrame: the union of the grids' active boxes (or Blender's domain)
    turb::CoordBBox held;           ///< readFrame: the box the frame's fields cover (span cropped to the smoke)
    SmokeRegion region;             ///< readFrame: the smoke and its strays
};

/// The time step and units rules, shared by readFrame and header scans. `blenderVelocity`: the velocity
/// grid is Blender's (staggered `velocity` with file_base_resolution); `blenderCache`: the file has
/// Blender's domain metadata; `recordedDt`: vdbturb_dt metadata, <= 0 if absent; `recordedTimeUnit`:
/// vdbturb_time_unit metadata (seconds per time unit), <= 0 if absent.
ReadReport resolveTiming(bool blenderVelocity, bool blenderCache, double recordedDt, const ReadOptions& options,
    double recordedTimeUnit = 0.0);

/// The aliases of a role, in priority order.
const std::vector<std::string>& gridAliases(GridRole role);

/// The candidate nearest to `word` when it is near enough to be a typo: an optimal string alignment distance (edits
/// and adjacent swaps: "tranfser" is one from "transfer") of at most max(2, word length / 3); "" otherwise. For grid
/// names here, and for the command line's commands and flags.
std::string nearestName(const std::string& word, const std::vector<std::string>& candidates);

/// Chooses the grid of `role` among `names` (an override wins and must exist). `names` are OpenVDB's
/// unique grid names in file order ("density", "[0]" for an unnamed grid, "vel[1]" for a second "vel");
/// an override may also be "#N" (the N-th name) or "name[0]" (the first grid of that name). For velocity
/// the result may be three names (x, y, z components). Empty when nothing matches.
std::vector<std::string> resolveGrid(
    const std::vector<std::string>& names, GridRole role, const std::string& overrideName = "");

/// Reads one frame. `frameNumber` is stored in the frame. Grids of a frame on different lattices (e.g.
/// Houdini's velocity voxel scale: vel at twice the density's voxel) are resampled trilinearly onto the
/// density's lattice (the velocity's when there is no density); `report` (optional) gets a note saying so,
/// and the time step and units with their sources.
turb::Frame readFrame(
    const std::string& path, int frameNumber, const ReadOptions& options, ReadReport* report = nullptr);

/// Convention of the written grids.
enum class WriteStyle {
    Houdini, ///< `vel` (Vec3s, contravariant relative, world units, cell-centred) + `density`
    Blender  ///< `velocity` (staggered, grid cells per time unit) + `density`, with Blender's metadata
};

/// The file format a frame is written in.
enum class OutputFormat {
    Auto,   ///< by the path's extension: ".nvdb" is NanoVDB, any other OpenVDB (as images go by theirs)
    Vdb,    ///< OpenVDB: Blosc, optional half floats, every metadata entry (the default for other extensions)
    NanoVdb ///< NanoVDB (format 32.4, what GPU renderers load): one uncompressed grid per role (docs/nanovdb.md)
};

/// How a NanoVDB file stores its float grids (density, temperature, flame and carried float grids other than level
/// sets). Vectors are always Vec3f and level sets float. Fp16 and Fp8 quantise each 8^3 leaf between its lowest and
/// highest value: a voxel is off by at most half a step, (leaf max - leaf min) / 2 / (2^bits - 1).
enum class NanoQuantization {
    Float, ///< 32-bit floats: the values exactly
    Fp16,  ///< 16 bits a voxel: error <= leaf range / 131070
    Fp8    ///< 8 bits a voxel: error <= leaf range / 510
};

struct WriteOptions
{
    WriteStyle style = WriteStyle::Houdini; ///< naming and unit convention of the written grids
    OutputFormat format = OutputFormat::Auto; ///< OpenVDB or NanoVDB; Auto goes by the path's extension
    /// NanoVDB only: the float grids' storage. NanoVDB holds no half floats, so halfFloat does not apply to it.
    NanoQuantization nanoQuantization = NanoQuantization::Float;
    bool noClobber = false;                 ///< refuse to replace an existing file
    bool halfFloat = false;                 ///< store floats as half (smaller, ~3 significant digits)
    /// Density at or below this is written inactive (sparse), as Blender's cache "Clipping" does. >= 0.
    float densityTolerance = 0.0f;
    /// Extent of velocity (Houdini style): -1 writes the whole box (every non-zero voxel), as it does temperature
    /// and flame; N >= 0 writes velocity only within N voxels of smoke (density or flame > smokeThreshold), and
    /// temperature and flame only at the smoke, as Blender does. A renderer's motion blur needs velocity where
    /// there is smoke (N = 1 covers its trilinear lookups); re-advecting the density for a frame needs about its
    /// travel per frame in voxels. The Blender style always writes the whole box.
    int velocityMargin = -1;
    /// Houdini style: write `vel` on a lattice this many times coarser than the frame's (Houdini's "Velocity Voxel
    /// Scale"), each voxel the mean of its scale^3 block, where any voxel of the block is written; >= 1. 2 writes an
    /// eighth of the velocity voxels: enough for a renderer's motion blur, not for the finest octave of detail
    /// (`measure` reads it back resampled, so its velocity numbers change).
    int velocityVoxelScale = 1;
    bool writeVelocity = true;    ///< false: no velocity grid at all (a density-only cache, as Blender's noise)
    float smokeThreshold = 1e-3f; ///< density above this is smoke for velocityMargin
    /// Write velocity and dt in the frame's own time unit (Frame::timeUnit) instead of the style's: transfer's
    /// exact resume state only. Otherwise the Houdini style writes world units per second, as Houdini, Karma,
    /// Arnold and RenderMan read `vel`, and the Blender style a Blender time unit (the frame's when it is not
    /// seconds, else 0.4 s: Mantaflow at time scale 1). Either way the file records its unit (vdbturb_time_unit).
    bool keepTimeUnit = false;
};

/// The grids of a file that readFrame does not take: Blender's flags, colour, shadow, level sets and previous
/// velocity, a Houdini cache's extra fields. Held sparse, as the file stores them, for a command that passes a
/// file's other grids through (resample): nothing a cache holds is dropped without a word.
///
/// A grid on the frame's lattice (readFrame's, Blender's placement offset taken off as readFrame does) follows
/// the frame: down-sampled and turned with it and written on its output lattice. A grid on another lattice, or
/// with a transform that is not a uniform scale and translation, is written unchanged (`unchanged()`).
class OtherGrids
{
public:
    OtherGrids();
    ~OtherGrids();
    OtherGrids(OtherGrids&&) noexcept;
    OtherGrids& operator=(OtherGrids&&) noexcept;

    /// Reads them, guarded like readFrame (a file that crashes or hangs OpenVDB is an IoError naming it).
    /// `options` selects the grids readFrame takes (the same selectors and readExtras); `frameLattice` is the
    /// lattice readFrame gave the frame.
    static OtherGrids read(const std::string& path, const ReadOptions& options, const turb::Lattice& frameLattice);

    /// Down-samples the grids that follow the frame by `factors` (turb::domainFactors of the frame's box: a 2D
    /// frame keeps its z layer), each >= 1. Float, double and vector grids take the mean over each block, inactive
    /// voxels counting as the background (turb::boxDownsample's rule). Level sets, and integer and boolean grids
    /// (Blender's flags), take the block's centre voxel (for an even factor the one just above the centre): their
    /// values are distances with far markers (Blender writes 1e4) and labels, which a mean would mix; a partial
    /// block at the domain's edge takes its active voxel nearest the centre. Blender's staggered velocities (grid
    /// cells per step) are divided by the factor. Blender's
    /// file_base_resolution and file_voxel_size metadata are scaled with the lattice. Throws ValueError for a
    /// factor < 1.
    void downsample(const turb::Coord& factors);
    /// Turns the grids that follow the frame as turb::reorientFrame turns its fields: voxel I moves to the rotated
    /// index, and vector values are rotated, except colours (a grid named Cd, or with "color" or "colour" in its
    /// name: OpenVDB's vector type defaults to "invariant" on velocities too, so it cannot tell).
    void rotate(const turb::AxisRotation& r);

    /// Leaves out the grids with these names (those the frame's own grids will be written as: two grids of one
    /// name in a file make readers pick one). Returns the names left out, in file order.
    std::vector<std::string> dropNamed(const std::vector<std::string>& names);

    size_t size() const;
    std::vector<std::string> names() const;     ///< every grid held, in file order
    std::vector<std::string> unchanged() const; ///< those on another lattice, written as they were read
    std::vector<std::string> staggered() const; ///< those of class staggered among the ones that follow the frame:
                                                ///< moved as cell values, so their faces are off by up to a voxel

    struct Impl;

private:
    std::unique_ptr<Impl> mImpl;
    friend void writeFrame(const std::string&, const turb::Frame&, const WriteOptions&, const OtherGrids*);
};

/// `format` resolved for the file `path`: Auto becomes NanoVdb for a name ending in ".nvdb" (any case), else Vdb.
OutputFormat outputFormatFor(const std::string& path, OutputFormat format = OutputFormat::Auto);

/// Writes a frame atomically: to a temporary file in the same directory, then renamed over `path`,
/// so readers never see a partial file and a failed write leaves any previous file untouched.
/// Frame metadata becomes grid metadata; "vdbturb_dt" records dt. `others` (optional) are written after the
/// frame's grids: those that follow the frame on its lattice (and with Blender's placement in the Blender style),
/// the rest as read. A name the frame's grids also use is kept: OpenVDB files allow it, and readers that look a
/// name up find the frame's grid, written first.
///
/// NanoVDB (outputFormatFor(path, options.format)): the same grids, names, classes and transforms, one NanoVDB grid
/// each (float grids quantised as options.nanoQuantization says, vectors Vec3f), uncompressed, with NanoVDB's
/// statistics and full checksum; the file-level string metadata (vdbturb_dt, ...) has no place there and is not
/// written (docs/nanovdb.md). Throws turb::ValueError naming "style" for the Blender style (its placement and
/// domain live in metadata NanoVDB cannot hold), and turb::IoError naming the grid for one NanoVDB cannot hold
/// (a non-affine transform).
void writeFrame(
    const std::string& path, const turb::Frame& frame, const WriteOptions& options, const OtherGrids* others = nullptr);

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
    int index = 0;        ///< position in the file (what "#N" selects)
    std::string selector; ///< how to choose this grid (ReadOptions::densityGrid/velocityGrid): its name when unique,
                          ///< else OpenVDB's "name[N]" ("[0]" for the first unnamed grid)
    std::string name;
    std::string valueType;  ///< "float", "vec3s", "int32", ...
    std::string gridClass;  ///< "fog volume", "staggered", "level set", "unknown"
    std::string vectorType; ///< "invariant", "covariant", "contravariant relative", ...
    GridRole role = GridRole::Other;
    std::string units;      ///< velocity only: "world" or "cells" (detected)
    bool halfFloat = false; ///< stored as half on disk
    double voxelSize = 0.0;
    turb::Vec3d origin{0.0};        ///< world position of voxel (0,0,0)'s centre
    std::string mapType;            ///< OpenVDB map type name
    bool supportedTransform = true; ///< uniform scale + translation
    bool hasBBox = false;
    turb::CoordBBox activeBBox;            ///< from the file's header statistics
    long long activeVoxels = -1;           ///< from header statistics; -1 if not recorded
    bool hasRange = false;                 ///< value range read from the voxels (only when asked)
    double minValue = 0.0, maxValue = 0.0; ///< scalar range, or vector magnitude range
};

struct FileInfo
{
    std::string path;
    bool nanoVdb = false;     ///< a NanoVDB file: read by NanoVDB's reader, its grids as OpenVDB's (no versions below)
    unsigned fileVersion = 0; ///< OpenVDB's file format
    std::string libraryVersion;
    std::string creator;                           ///< file-level "creator" metadata, if any
    std::optional<turb::Coord> baseResolution;     ///< Blender's file_base_resolution
    double recordedDt = 0.0;                       ///< vdbturb_dt metadata, 0 if absent
    double recordedTimeUnit = 0.0;                 ///< vdbturb_time_unit metadata (seconds), 0 if absent
    std::string sourceFrame;                       ///< vdbturb_source_frame metadata: the transfer's source frame
    std::string upAxis;                            ///< vdbturb_up_axis metadata ("y", "z"), "" if absent
    std::string tileBox;     ///< vdbturb_tile_box: a space tile's transfer output, the target box it held
    std::string farmTiles;   ///< vdbturb_farm_tiles: a frame farm join assembled from tiles ("2x1x1 halo 4 ramp 8")
    std::string tileBorders; ///< vdbturb_tile_borders: the borders between those tiles' cores ("x:64")
    std::optional<turb::CoordBBox> recordedDomain; ///< vdbturb_domain metadata: the box a vdbturb output spans
    std::optional<turb::CoordBBox> sequenceDomain; ///< vdbturb_sequence_domain metadata: the domain of the input it was
                                                   ///< made from (for framing only)
    int velocityMargin = -1; ///< vdbturb_velocity_margin: velocity written only this near the smoke; -1 = not trimmed
    std::string command;     ///< vdbturb_command: the vdbturb command that wrote the file, "" for other writers
    std::string settings;    ///< vdbturb_settings: the settings that made it ("name=value;..."), for --skip-existing
    int rangesSkipped = 0;   ///< grids whose value range was not read: past 1 GB of grids read for ranges
    std::vector<GridInfo> grids; ///< in file order
};

/// Reads a file's header and grid descriptors (fast: no voxel data), and with `readValues` also
/// each float/vector grid's value range. A NanoVDB file (isNanoVdbFile, NanoVdb.h) is read too: its grids as they
/// are read as OpenVDB grids (a quantised float grid is float), with their NanoVDB types where vdbturb reads none.
FileInfo inspectFile(const std::string& path, bool readValues);

/// Name of a role, for messages ("density", "velocity", ...).
const char* roleName(GridRole role);

/// One line per grid for messages: "#0 'density' float fog volume, #1 (unnamed) vec3s staggered".
std::string describeGrids(const std::vector<GridInfo>& grids);

} // namespace turbio
