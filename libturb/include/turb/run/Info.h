/// @file Info.h
/// @brief `vdbturb info` as a library call (turb::run, the entry points' layer): what a cache holds, from its files'
///        headers: the frames found and missing, the lattice and its changes, dt and velocity units with where they
///        came from, each file's grids; NanoVDB files' grids, types and sizes.
///
/// @code
/// turb::run::InfoJob job;
/// job.pattern = "cache/smoke.####.vdb";
/// const turb::run::InfoRun info = turb::run::runInfo(job); // the tables go to turb::run::printData
/// const nlohmann::json& files = info.report["files"];      // one object per frame
/// @endcode
#pragma once

#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <string>

namespace turb::run {

/// An info run: the CLI's options as plain values (same names, same defaults).
struct InfoJob
{
    std::string pattern;      ///< the cache: a pattern (####, @, %04d, $F4, ${F4}) or one real file name
    std::string frames;       ///< frames to inspect ("1001-1100x2,1200"); empty = every frame on disk
    bool json = false;        ///< the caller prints InfoRun::report on stdout: the tables go to printData's stderr
    bool allValues = false;   ///< read every frame's voxels for value ranges (default: the first frame's only)
    bool noValues = false;    ///< read no voxels at all (no value ranges, no smoke region)
    bool validate = false;    ///< also read every frame as the other commands do and say which commands can use it
    bool checksum = false;    ///< fingerprint every grid of every frame, bit for bit
    bool everyTable = false;  ///< every frame's grid table (the CLI's -v), not only the first frame's, where the
                              ///< lattice changes and as allValues / checksum ask
    turbio::ReadOptions read; ///< how the frames are read: grid names, crop margin, timing (requireDensity and
                              ///< requireVelocity are set from the grids named)
};

/// What a run found. The tables and lines for people went to printData as the frames were read.
struct InfoRun
{
    /// What --json prints (dump(1)): the pattern, frames, missing, lattice changes, timing, and "files", one object
    /// per frame (its grids, metadata, smoke region, checksums, validation; "error" for a frame that failed to read).
    /// NanoVDB: "format": "nanovdb" and each file's grids and bytes.
    nlohmann::json report;
    int framesFailed = 0;     ///< frames whose headers or (validate) voxels failed to read
    std::string failedLine;   ///< "2 of 10 frames failed to read: 4,7" (the CLI's error line); empty when none did
    std::string validateLine; ///< validate's verdict, "validate: every frame reads; ..." for printData; empty without
};

/// Runs `job`. A frame that fails to read is described by its error, and the walk goes on (InfoRun::framesFailed).
/// Throws UsageError (validate or checksum on NanoVDB files) and turb::IoError (no such cache, no frame on disk).
InfoRun runInfo(const InfoJob& job);

} // namespace turb::run
