/// @file Transfer.h
/// @brief `vdbturb transfer` as a library call (turb::run, the entry points' layer): turbulence style transfer
///        (Sato et al. 2018, seed 002) of a high-res source cache onto a low-res target cache, frame after frame,
///        from files to files.
///
/// @code
/// turb::run::TransferJob job;
/// job.target = "lowres/smoke.####.vdb";
/// job.source = "hires/swirl.####.vdb";
/// job.out = "up/turb.####.vdb";
/// job.frames = "1001-1100";
/// turb::run::TransferRun done = turb::run::runTransfer(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// The run checks everything before its first frame (every input frame's headers, the ratio, the outputs, the
/// memory: what a dry run does), reads frame k + 1 while frame k is computed, writes each frame atomically with the
/// metadata --resume continues from, and takes a lock on each frame it writes. The method, its settings and their
/// measured effects are docs/transfer.md's; TransferSettings documents each field.
#pragma once

#include <turb/Transfer.h>
#include <turb/run/Output.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <string>
#include <utility>
#include <vector>

namespace turb::run {

/// The settings that have a 3D and a 2D form: their two flags, and the 3D one's name in the recorded settings text
/// (the 2D one's is that name with "-2d"). Given for the other kind of cache, a setting has no effect.
struct KindTwin
{
    const char *option3D, *option2D, *recorded3D;
};
inline constexpr KindTwin kKindTwins[] = {{"--seams.bandWidth", "--seams.bandWidth2D", "band"},
    {"--seams.cgTolerance", "--seams.cgTolerance2D", "cg-tolerance"},
    {"--detailEnergy", "--detailEnergy2D", "detail-energy"},
    {"--regenerateBlend", "--regenerateBlend2D", "regenerate-blend"},
    {"--structureTolerance", "--structureTolerance2D", "structure-tolerance"}};
inline constexpr size_t kKindTwinCount = sizeof(kKindTwins) / sizeof(kKindTwins[0]);

/// A transfer run: the CLI's options as plain values (same names, same defaults).
struct TransferJob
{
    std::string target, source, out;  ///< frame patterns (####, %04d, $F4) or single files; out's folders are made
    std::string frames, sourceFrames; ///< frame lists ("1001-1100x2,1200"); empty = every frame on disk
    int sourceOffset = 0;             ///< source frame = target frame + offset, before wrap
    turbio::SourceWrap wrap = turbio::SourceWrap::Loop; ///< when the source runs out
    bool resume = false; ///< skip frames written with these settings and continue from the state saved in the last
    int preroll = 0;     ///< run up to this many earlier cache frames first, unwritten (>= 0)
    turbio::ReadOptions targetRead;
    turbio::ReadOptions sourceRead = [] {
        // Only the source: Blender clips velocity to the smoke and the zeros beyond would read as turbulence at its
        // edge. The target's velocity stays as stored: the output keeps the target's coarse motion as the file has it.
        turbio::ReadOptions r;
        r.extendVelocity = 4;
        return r;
    }();
    bool sourceCropMarginGiven = false; ///< sourceRead.cropMargin as given; otherwise 8 target voxels at the ratio
    bool velocityMarginGiven = false;   ///< write.velocityMargin as given (--style blender ignores it, saying so)
    /// Per kKindTwins entry: whether its 3D and its 2D setting were given (one given for the other kind of cache is
    /// warned about). Empty: none was.
    std::vector<std::pair<bool, bool>> kindTwinsGiven;
    std::string tileBox; ///< "X0,Y0,Z0,X1,Y1,Z1": hold only this box of the target (a space tile and its halo)
    turbio::WriteOptions write = upResWriteDefaults();
    turb::TransferSettings settings;
    bool dryRun = false; ///< check and plan (printData), write nothing
    int threads = 0;     ///< 0 = all cores (TransferSettings::threads is set from it)
};

/// What a run did.
struct TransferRun
{
    int framesWritten = 0;
    int prerollFrames = 0;        ///< processed before the first requested frame, not written
    int framesAlreadyWritten = 0; ///< skipped by resume
};

/// Runs `job`. Throws turb::ValueError (bad settings; a frame's failure, naming its target and source files),
/// UsageError (output options that contradict each other, an --out without a frame token for several frames),
/// turb::IoError (a missing or damaged input, naming the file and grid; a resume from another run's frames),
/// turb::TransientError (not enough memory here, a frame locked by another process) and turb::Cancelled (the
/// reporter's progress asked to stop: the frame in flight is dropped whole). Frames written before a throw stay.
TransferRun runTransfer(const TransferJob& job);

} // namespace turb::run
