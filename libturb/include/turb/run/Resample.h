/// @file Resample.h
/// @brief `vdbturb resample` as a library call (turb::run, the entry points' layer): a cache box-downsampled by an
///        integer factor and/or turned by quarter turns, exactly, frame by frame from files to files (proxies and
///        test inputs).
///
/// @code
/// turb::run::ResampleJob job;
/// job.in = "cache/smoke.####.vdb";
/// job.out = "proxy/smoke.####.vdb";
/// job.down = 2;
/// turb::run::runResample(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// Each frame is made from its input frame alone, on its own lattice (a lattice change within the sequence is carried
/// through), with the file's other grids resampled alongside unless dropOtherGrids.
#pragma once

#include <turbio/Vdb.h>

#include <string>

namespace turb::run {

/// A resample run: the CLI's options as plain values (same names, same defaults).
struct ResampleJob
{
    std::string in;              ///< the cache: a pattern (####, %04d, $F4) or one real file name
    std::string out;             ///< output pattern (.vdb, or .nvdb for NanoVDB); its folders are made
    std::string frames;          ///< frame list ("1-30"); empty = every frame on disk
    int down = 1;                ///< mean over down^3 blocks onto a down times coarser lattice, [1, 64]
    std::string rotate;          ///< AXIS:TURNS quarter turns about x, y or z ("y:1"; ":TURNS" omitted = 1); "" = none
    bool dropOtherGrids = false; ///< write only density, velocity, temperature and flame
    bool skipExisting = false;   ///< skip frames already written by the same settings; refuse ones written otherwise
    turbio::ReadOptions read;    ///< requireDensity / requireVelocity are ignored: a frame needs neither
    turbio::WriteOptions write;
    /// The command's settings as "name=value;..." without its input (the CLI's commandSettingsText(app, {})): what
    /// each frame records (vdbturb_settings) and skipExisting compares. The run adds the input's absolute pattern.
    std::string settings;
    bool dryRun = false; ///< check and plan (printData: "would write" / "would skip"), write nothing
};

/// What a run did.
struct ResampleRun
{
    int framesWritten = 0;
    int framesSkipped = 0; ///< already written by the same settings (skipExisting)
};

/// Runs `job`. Throws turb::ValueError (a bad rotate; a frame written by other settings under skipExisting),
/// UsageError (output options that contradict each other, an out without a frame token for several frames),
/// turb::IoError (a missing or damaged input, an output that cannot be written) and turb::TransientError (a frame
/// locked by another process). Frames written before a throw stay.
ResampleRun runResample(const ResampleJob& job);

} // namespace turb::run
