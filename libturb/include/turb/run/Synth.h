/// @file Synth.h
/// @brief `vdbturb synth` as a library call (turb::run, the entry points' layer): motion-field texture synthesis
///        (Ma et al. 2009) of detail motion from small exemplars, oriented along a coarse flow L, frame after frame,
///        into files.
///
/// @code
/// turb::run::SynthJob job;
/// job.target = "lowres/smoke.####.vdb";
/// job.exemplars = {"swirls:16"};
/// job.seq.factor = 4;
/// job.out = "synth/synth.####.vdb";
/// turb::run::SynthRun done = turb::run::runSynth(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// The run checks everything before its first frame (every cache frame's headers, the output paths, the memory:
/// what a dry run does), builds the exemplars' pyramids and indices once, then synthesises each frame continuing
/// from the one before, and writes it atomically with the metadata --skip-existing compares. The method and its
/// settings are docs/synth.md's; turb::SynthSequenceSettings documents each of `seq`'s fields.
#pragma once

#include <turb/SynthSequence.h>
#include <turbio/Vdb.h>

#include <string>
#include <vector>

namespace turb::run {

/// The names of omega's shapes (--omega-mode), the first of a value's names the one its metadata records.
struct WeightingName
{
    const char* name;
    turb::CombineSettings::Weighting weighting;
};
inline constexpr WeightingName kWeightingNames[] = {{"constant", turb::CombineSettings::Weighting::Constant},
    {"energy", turb::CombineSettings::Weighting::KineticEnergy},
    {"vorticity", turb::CombineSettings::Weighting::Vorticity}};

/// A synth run: the CLI's options as plain values (same names, same defaults). The text fields are read when the
/// run starts, as the command line's are, and a malformed one throws turb::ValueError naming its flag.
struct SynthJob
{
    /// The coarse motion L, exactly one of three: a VDB cache (frame pattern or one file; density optional), a
    /// built-in scene simulated on the fly (plume, swirl, obstacle, wind) or an analytic flow (uniform, vortex, shear:
    /// no density).
    std::string target, scene, flow;
    std::string sceneRes = "32x32x48"; ///< scene cells "NXxNYxNZ" along x, y, z (z up), or "N" for N^3
    std::string flowRes = "64x64x1";   ///< analytic flow cells "NXxNYxNZ" or "N"; NZ = 1 is 2D
    double flowSpeed = 1.0;            ///< analytic flow speed, world units/s
    double flowAngle = 0.0;            ///< uniform flow direction in the xy plane, degrees from +x
    double flowWidth = 4.0;            ///< the analytic flow's domain width along x, world units
    double flowDt = 1.0 / 24.0;        ///< seconds per frame of a flow, and of a frame that records no dt
    /// Cache: a frame list ("1001-1100x2,1200"; empty = every frame on disk). Scene and flow: a count N (frames 1..N)
    /// or a list of frames from 1 (empty = frame 1).
    std::string frames;
    int sceneSeed = 1; ///< the scene's emitter noise seed
    int sliceZ = -1;   ///< >= 0: synthesise in 2D on this coarse z layer of a 3D input
    /// Exemplars, one per view: circles|swirls|squares|hearts|stripes|sinusoids[:PERIOD[:SIZE]], rg:PICTURE[:SCALE],
    /// gray:PICTURE[:SCALE], vdb:FILE.vdb[:AXIS:INDEX], vdb3:FILE.vdb (docs/synth.md). Empty = circles:16.
    std::vector<std::string> exemplars;
    double exemplarScale = 1.0;        ///< > 0: the exemplars' features this many times larger
    bool periodic = false;             ///< picture and VDB exemplars tile seamlessly (procedurals always do)
    std::string views;                 ///< 3D: the local axis each exemplar looks along, "0,1,2" (empty: one per axis)
    std::string viewWeights;           ///< 3D: relative weight per view, "1,1,4", each > 0 (empty: equal)
    std::string iterations;            ///< iterations per level "LARGE,SMALL" or "SMALL" (empty: seq.synth's)
    std::string radius;                ///< neighbourhood radii "LARGE,SMALL" or "SMALL" (empty: seq.synth's)
    std::string secondary = "density"; ///< 3D second local axis: "density" or a fixed vector "X,Y,Z" (not zero)
    /// Walls: any of "x-,x+,y-,y+,z-,z+", "all" or "none"; empty: a scene's closed faces, else none.
    std::string walls;
    std::string obstacle; ///< a signed distance FILE.vdb[:GRID] in world units (grid 'surface'); empty: the scene's
    bool json = false;    ///< the caller shows the frames' JSON lines (--json): --trace-descent reports only there
    bool stats = false;   ///< texture statistics per frame in the frame's record (texture_match)
    /// Skip the frames already written with `settingsText` (the frames before the last one to write are made again,
    /// not written); a frame written otherwise is refused (turb::ValueError).
    bool skipExisting = false;
    /// The settings each frame records (vdbturb_settings, with the run's frames up to it) and --skip-existing
    /// compares: the CLI's commandSettingsText.
    std::string settingsText;
    bool strict = false; ///< a projection or detail divergence solve that does not converge fails the run (SynthRun)
    std::string out = "synth/synth.####.vdb"; ///< output pattern (####, %04d, $F4) or one file; folders are made
    std::string preview;     ///< a folder for a picture per frame (exemplar, up(L), H', F, density); empty: none
    std::string previewView; ///< top, front or side; empty: top in 2D, front in 3D
    int previewWidth = 256;  ///< pixels per preview panel, 32-4096
    std::string previewFormat = "png"; ///< png, exr (linear half) or tif
    int volumeCrop = 32;               ///< vdb3 exemplars: the central N^3 voxels, 8-128
    turbio::ReadOptions read;          ///< how cache frames and vdb exemplars are read
    turbio::WriteOptions write;
    turb::SynthSequenceSettings seq; ///< the synthesis, F = up(L) + omega H', the projection, the density
    bool dryRun = false;             ///< check and plan (printData), write nothing
    int threads = 0;                 ///< 0 = all cores (seq.synth.threads and the scene's are set from it)
};

/// What a run did.
struct SynthRun
{
    int framesWritten = 0;
    int framesSkipped = 0; ///< left as they were by --skip-existing
    /// Frames whose projection or detail divergence solve stopped short (each warned about as it happened).
    std::vector<int> unconverged;
    /// With `strict` and unconverged frames: the message the run fails with (the CLI's exit 1); else empty (the
    /// run warned with it).
    std::string strictFailure;
};

/// Runs `job`. Throws turb::ValueError (bad settings or exemplars, a frame's failure naming its cache file, a frame
/// --skip-existing finds made otherwise), UsageError (output options that contradict each other, an --out without
/// a frame token for several frames), turb::IoError (a missing or damaged input, naming the file and grid),
/// turb::TransientError (not enough memory here, a frame locked by another process) and turb::Cancelled (the
/// reporter's progress asked to stop: the frame in flight is dropped whole). Frames written before a throw stay.
SynthRun runSynth(const SynthJob& job);

} // namespace turb::run
