/// @file Convert.h
/// @brief `vdbturb convert` as a library call (turb::run, the entry points' layer): a VDB sequence as NanoVDB (what
///        GPU renderers load), grid for grid, one file per frame (docs/nanovdb.md).
///
/// @code
/// turb::run::ConvertJob job;
/// job.in = "up/turb.####.vdb";
/// job.out = "gpu/turb.####.nvdb";
/// job.nano.quantization = turbio::NanoQuantization::Fp16;
/// turb::run::runConvert(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// Every frame's headers are read before the first write; grids NanoVDB cannot hold are left out, with a warning once
/// per grid.
#pragma once

#include <turbio/NanoVdb.h>

#include <string>

namespace turb::run {

/// A convert run: the CLI's options as plain values (same names, same defaults).
struct ConvertJob
{
    std::string in;     ///< the VDB cache: a pattern (####, %04d, $F4) or one real file name
    std::string out;    ///< output pattern ending in .nvdb; its folders are made
    std::string frames; ///< frame list; every one must exist. Empty = the frames on disk (a gap is warned about)
    turbio::NanoConvertOptions nano; ///< quantisation of float grids, no-clobber
    bool dryRun = false;             ///< check and plan (printData, "would write PATH"), write nothing
    int threads = 0;                 ///< 0 = all cores
};

/// What a run did.
struct ConvertRun
{
    int framesWritten = 0;
};

/// Runs `job`. Throws UsageError (an out not ending in .nvdb, or without a frame token for several frames),
/// turb::IoError (a missing frame asked for, a damaged input, a file with no grid NanoVDB can hold, an output that
/// cannot be written), turb::TransientError (a frame locked by another process) and turb::Cancelled (the reporter's
/// progress asked to stop; checked between frames). Frames written before a throw stay.
ConvertRun runConvert(const ConvertJob& job);

} // namespace turb::run
