/// @file StylizeCommon.h
/// @brief What both methods of `vdbturb stylize` share: the options, the target (2D masks and flows, a
///        VDB cache through a camera, or a built-in scene), and small helpers. LazyFluids lives in
///        cmd_stylize.cc, Fluidymation in cmd_stylize_fluidymation.cc. `vdbturb animate` uses the camera.
#pragma once

#include "Commands.h"
#include "Preflight.h"

#include <scenes/Targets2D.h>
#include <turb/CameraBridge.h>
#include <turb/Fluidymation.h>
#include <turb/Image.h>
#include <turb/Stylize.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vdbturb::stylize {

enum class Method { LazyFluids, Fluidymation };

/// The camera a VDB cache is seen through: an axis view of the whole box, or a placed perspective camera.
enum class CameraKind { Front, Side, Top, Perspective };

struct CameraArgs
{
    CameraKind kind = CameraKind::Front;
    std::string position, lookAt, up = "0,0,1"; ///< perspective: X,Y,Z in world units
    double fov = 40.0;                          ///< perspective: horizontal field of view, degrees
    int width = 0, height = 0;                  ///< 0: turb::CameraSettings' defaults
    float extinction = 6.0f, step = 0.5f;       ///< turb::BridgeSettings
};

/// --camera and --width (everyday); the perspective camera's placement, the height and the ray march (settings).
void addCameraOptions(CLI::App* app, CameraArgs& c);
/// The bridge's camera and ray march; throws when a perspective camera is not placed.
turb::BridgeSettings bridgeSettings(const CameraArgs& c);
std::string cameraName(CameraKind k);

/// Options of `--method fluidymation` only.
struct FluidyArgs
{
    std::string exemplarMask, exemplarFlow; ///< the exemplar's masks and (optional) flows
    std::string targetMask, targetFlow;     ///< a 2D target: masks and (optional) flows
    std::string outRot, debugNnf;           ///< T^rot images; a folder for the NNF (i, x, y, theta)
    float maskThreshold = 0.5f;             ///< a target alpha or rendered opacity >= this is inside the mask
    bool estimateFlow = false;              ///< ignore given target flows: estimate them from the masks (Appendix A)
    turb::FluidySettings settings;
    turb::MotionGuideSettings guides;
};

struct StylizeArgs
{
    Method method = Method::LazyFluids;
    FluidyArgs fluidy;
    std::string exemplar, exemplarAlpha;
    std::string flow, alpha, cache, scene;
    std::string sceneSize = "256x256";
    double sceneSpeed = 0.02;
    std::string frames;
    CameraArgs camera;
    bool flowYUp = false;
    std::string out;
    std::string preview, writeTarget;
    bool json = false, noClobber = false;
    bool skipExisting = false;
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
    turbio::ReadOptions read;
    turb::StylizeSettings settings;
    std::vector<const CLI::Option*> lazyFluidsOnly;   ///< options --method fluidymation does not read (it warns)
    std::vector<const CLI::Option*> fluidymationOnly; ///< options --method lazyfluids does not read (it warns)
};

/// --skip-existing's plan for the output frames `frames` of `out` (a dry run prints it), and each frame's settings
/// (sequentialSettings: a frame follows the one before it) into `settings`.
SkipPlan planOutputFrames(const StylizeArgs& a, const std::vector<int>& frames, const turbio::FramePattern& out,
    std::vector<std::string>& settings);

std::string fmt(const char* f, double v);
/// kOk, or kUsage (said) when --out is missing or it or `more` (--out-rot) has no image extension the writers know.
int checkOutputPatterns(const std::string& out, const std::string& more = "");
std::vector<double> parseNumbers(const std::string& s, size_t n, const std::string& what);
turb::Vec3d parseVec(const std::string& s, const std::string& what);

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
    TargetSource(const StylizeArgs& a, bool flowOptional = false);
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
    static void requireAll(const turbio::Sequence& s);
    static std::pair<int, int> parseSize(const std::string& s);
    turb::ChannelImage readMotion(const std::string& path, int frame) const;

    const StylizeArgs& mArgs;
    std::optional<turbio::Sequence> mCache, mFlow, mAlpha;
    turb::scenes::Target2DSettings mScene{"", 0, 0, 0.0};
    turb::BridgeSettings mBridge;
    std::vector<int> mFrames;
};

/// The motion field as a LIC picture (2D: a one-voxel-thick field seen from the top).
turb::Image motionPicture(const turb::ChannelImage& m);

/// `--method fluidymation`: its options, and the run.
void addFluidymationOptions(CLI::App* app, StylizeArgs& a);
int runFluidymation(StylizeArgs& a);

} // namespace vdbturb::stylize
