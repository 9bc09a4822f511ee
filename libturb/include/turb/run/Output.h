/// @file Output.h
/// @brief What every command that writes frames shares (turb::run, the entry points' layer): the up-res's write
///        defaults, the output options' consistency, reads qualified by their flags' prefix.
#pragma once

#include <turb/Error.h>
#include <turb/Frame.h>
#include <turbio/Vdb.h>

#include <string>

namespace turb::run {

/// A run that cannot go as asked (an --out without a frame token for a sequence, output options that contradict each
/// other): the CLI's usage error, exit 2, like its own parse errors.
class UsageError : public turb::ValueError
{
public:
    using turb::ValueError::ValueError;
};

/// Runs `read`, a read with the ReadOptions that addReadOptions declared with `prefix`, and qualifies the settings
/// a turb::Error it throws names with that prefix, so that its message names this command's flags.
template<typename Read>
auto readingAs(const std::string& prefix, Read&& read) -> decltype(read())
{
    try {
        return read();
    } catch (turb::Error& e) {
        e.qualifySettings(prefix);
        throw;
    }
}

/// Warns (once per run, through `warned`) when `options.densityTolerance` (--clipping) is at or above every density
/// value of a frame that holds smoke: its density grid would be written empty.
void warnIfClippedAway(
    const turb::Frame& frame, const turbio::WriteOptions& options, const std::string& path, bool& warned);

/// Refuses (UsageError, exit 2) output options that contradict each other for the output pattern `out`: --format
/// against the name's extension (.vdb / .nvdb), --nanovdb-quant for OpenVDB output, and for NanoVDB output the Blender
/// style and `resumeFlag` ("--resume", "--skip-existing"; "" when not given), which need metadata NanoVDB cannot hold.
void checkOutputFormat(const turbio::WriteOptions& w, const std::string& out, const std::string& resumeFlag = "");

/// --velocity-margin auto: one target voxel, resolved to the ratio once it is known (resolveVelocityMargin).
constexpr int kVelocityMarginAuto = -2;
/// What an up-res (transfer, farm join) writes by default: 16-bit floats and velocity within one target voxel of
/// the smoke, as Blender and Houdini caches are written (docs/io.md, Size). --full-float and --velocity-margin -1
/// give the whole frame in 32-bit floats.
turbio::WriteOptions upResWriteDefaults();
/// --velocity-margin auto becomes `ratio` output voxels (one target voxel); other values are kept.
inline void resolveVelocityMargin(turbio::WriteOptions& w, int ratio)
{
    if (w.velocityMargin == kVelocityMarginAuto) w.velocityMargin = ratio;
}

} // namespace turb::run
