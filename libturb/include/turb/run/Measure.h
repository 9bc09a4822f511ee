/// @file Measure.h
/// @brief `vdbturb measure` as a library call (turb::run, the entry points' layer): the quality numbers of an up-res
///        against its target (and source), frame by frame, from files. The numbers are turb::measureFrame's
///        (turb/Measure.h, docs/measure.md).
#pragma once

#include <turb/Measure.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace turb::run {

/// A measure run: the CLI's options as plain values (same names, same defaults).
struct MeasureJob
{
    std::string output, target, source; ///< patterns or files; source optional (the source's numbers)
    std::string frames;                 ///< a frame list; empty: the frames output and target both hold
    std::string up = "auto"; ///< detail_profile's up axis: auto (metadata, else y for Houdini's files, else z), y, z
    std::string patchOrigin; ///< "X,Y,Z" or "N": an output voxel where a patch starts (default: metadata)
    std::string tileBorders; ///< "x:64;y:64": tile_* border planes (default: the output's metadata)
    bool spectra = true;     ///< compute E(k) (MeasureSettings::spectra)
    turb::MeasureSettings settings;
    turbio::ReadOptions read;
    int sourceExtend = 0; ///< source velocity continued this many voxels past its active region (0: as written)
    /// Where the caller draws its plots (spectrum.####.png, metrics.png): checked as outputs before the first frame
    /// and created; empty: none. The run draws none itself: the caller draws them as it goes (turb/run/Figures.h).
    std::string plotDir;
    std::string plotFormat = "png"; ///< the plots' picture format: png, svg, pdf, exr or tif
    bool dryRun = false;
    int threads = 0;
};

/// One measured frame, as the run hands it on.
struct MeasuredFrame
{
    int frame = 0;
    size_t index = 0, count = 0;
    double seconds = 0.0;
    const turb::FrameMeasures* measures = nullptr;
};

struct MeasureRun
{
    std::vector<turb::FrameMeasures> frames; ///< the frames measured, in order
    std::vector<double> seconds;             ///< per measured frame
    int failed = 0;                          ///< frames that could not be measured (each logged at Error)
    bool nothingToMeasure = false;           ///< no frame is present in both output and target (a failure)
    std::string noFramesMessage;             ///< then: what to say
    std::string outputPattern;               ///< the output sequence's pattern, for titles
};

/// Runs `job`, calling `onFrame` after each frame it measures (a frame that fails is logged, counted and skipped:
/// the next frames still count). Throws before the first frame on bad inputs (turb::IoError naming the file,
/// turb::ValueError: an output that is no integer refinement of the target, a bad --patch-origin) and
/// turb::Cancelled.
MeasureRun runMeasure(const MeasureJob& job, const std::function<void(const MeasuredFrame&)>& onFrame = {});

/// One frame's numbers as measure's JSON line holds them (without "frame" and "seconds"); `spectra` adds the E(k)
/// arrays.
nlohmann::json measureJson(const turb::FrameMeasures& m, bool spectra);

/// One frame's numbers as the farm log's line.
std::string measureLine(const turb::FrameMeasures& m);

/// The summary line's JSON: the frames, failures, timing and machine, and every number's mean, median, min, max.
nlohmann::json measureSummaryJson(
    const MeasureRun& run, const turb::MeasureSettings& s, double totalSeconds, int threads);

} // namespace turb::run
