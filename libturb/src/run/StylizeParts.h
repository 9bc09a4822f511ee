// What both methods of runStylize share (private to libturb/src/run): the target (2D masks and flows, a VDB cache
// through a camera, or a built-in scene), the output checks and plan, the pictures. LazyFluids runs in StylizeRun.cc,
// Fluidymation in StylizeFluidymation.cc.
#pragma once

#include "RunHelpers.h"

#include <turb/run/Preflight.h>
#include <turb/run/Stylize.h>

#include <scenes/Targets2D.h>
#include <turb/CameraBridge.h>
#include <turb/ChannelImage.h>
#include <turb/Frame.h>
#include <turb/Image.h>
#include <turbio/Sequence.h>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace turb::run::detail {

/// `n` comma-separated numbers; throws turb::ValueError naming `what` otherwise.
std::vector<double> parseNumbers(const std::string& s, size_t n, const std::string& what);

/// Refuses (UsageError) a missing --out, and an --out or `more` (--out-rot) without an image extension the writers
/// know.
void checkOutputPatterns(const std::string& out, const std::string& more = "");
/// Refuses (UsageError) an --out without a frame token for `frames` > 1 frames.
void checkFrameToken(const turbio::FramePattern& out, const std::string& outText, size_t frames);

/// --skip-existing's plan for the output frames `frames` of `out` (a dry run prints it), and each frame's settings
/// (sequentialSettings: a frame follows the one before it) into `settings`.
SkipPlan planOutputFrames(const StylizeJob& a, const std::vector<int>& frames, const turbio::FramePattern& out,
    std::vector<std::string>& settings);
/// A dry run's data without --skip-existing: the frames it would write, on stdout as transfer's.
void printWouldWrite(const StylizeJob& a, const std::vector<int>& frames, const turbio::FramePattern& out);

struct TargetFrame
{
    turb::ChannelImage alpha, motion;
    std::string alphaName, motionName; // for messages
    std::optional<turb::Frame> cacheFrame;
};

/// Where the target comes from: 2D flow and alpha sequences, a VDB cache through a camera, or a scene.
/// With `flowOptional` a 2D target may come without flows (TargetFrame::motion is then empty).
class TargetSource
{
public:
    TargetSource(const StylizeJob& a, bool flowOptional = false);
    const std::vector<int>& frames() const { return mFrames; }
    bool isCache() const { return mCache.has_value(); }
    bool is2D() const { return mAlpha.has_value(); }
    bool hasFlow() const { return !mAlpha.has_value() || mFlow.has_value(); }
    const turb::BridgeSettings& bridge() const { return mBridge; }
    std::string label() const;
    /// Checks every 2D frame before anything is written: sizes agree and (unless `allowEmpty`) masks are
    /// not empty.
    void validate2D(bool allowEmpty = false) const;
    TargetFrame read(int frame) const;

private:
    void openScene(const StylizeJob& a);
    void open2D(const StylizeJob& a, bool flowOptional);
    static void requireAll(const turbio::Sequence& s);
    static std::pair<int, int> parseSize(const std::string& s);
    TargetFrame readCache(int frame) const;
    turb::ChannelImage readMotion(const std::string& path, int frame) const;
    turb::ChannelImage readMotionVdb(const std::string& path, int frame) const;

    const StylizeJob& mArgs;
    std::optional<turbio::Sequence> mCache, mFlow, mAlpha;
    turb::scenes::Target2DSettings mScene{"", 0, 0, 0.0};
    turb::BridgeSettings mBridge;
    std::vector<int> mFrames;
};

/// The motion field as a LIC picture (2D: a one-voxel-thick field seen from the top).
turb::Image motionPicture(const turb::ChannelImage& m);
/// A cache target's frame `t` rendered through its camera, at the target's size (the previews' first picture).
turb::Image cacheRender(const TargetFrame& t, const TargetSource& src);

/// StylizeMethod::Fluidymation's run (StylizeFluidymation.cc).
StylizeRun runFluidymation(const StylizeJob& a);

} // namespace turb::run::detail
