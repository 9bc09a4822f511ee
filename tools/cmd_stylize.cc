// vdbturb stylize: appearance transfer onto fluid motion (LazyFluids, Jamriška et al. 2015).
#include "Commands.h"
#include "StylizeCommon.h"
#include "Console.h"
#include "RunReport.h"

#include <scenes/Targets2D.h>
#include <turb/CameraBridge.h>
#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Render.h>
#include <turb/Stylize.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

namespace vdbturb {

namespace {

using namespace stylize;


/// The exemplar: a still or a sequence (video), each frame with its alpha (from the file or a mask).
class ExemplarSource
{
public:
    ExemplarSource(const StylizeArgs& a, int patchSize) : mArgs(a)
    {
        if (a.exemplar.rfind("builtin:fire", 0) == 0) {
            const size_t c = a.exemplar.find(':', 8);
            mBuiltin = c == std::string::npos ? 128 : std::stoi(a.exemplar.substr(c + 1));
            mFrames = {0};
            return;
        }
        mSeq = turbio::resolveSequence(a.exemplar);
        if (!mSeq->missing.empty()) throw turb::IoError(mSeq->path(mSeq->missing.front()) + ": missing exemplar frame");
        mFrames = mSeq->frames;
        if (mFrames.empty()) mFrames = {0};
        if (!a.exemplarAlpha.empty()) mAlphaSeq = turbio::resolveSequence(a.exemplarAlpha);
        // Headers of every frame now, so a bad exemplar stops the run before anything is written.
        for (size_t i = 0; i < mFrames.size(); ++i) {
            const std::string path = pathOf(i);
            const turbio::ImageFileInfo info = turbio::inspectImage(path);
            if (info.width < patchSize || info.height < patchSize)
                throw turb::IoError(path + ": the exemplar (" + std::to_string(info.width) + "x" + std::to_string(info.height) +
                                    ") is smaller than a " + std::to_string(patchSize) + "x" + std::to_string(patchSize) + " patch");
            if (!info.hasAlpha && !mAlphaSeq)
                throw turb::IoError(path + ": the exemplar has no alpha channel; give its mask with --exemplar-alpha");
        }
    }

    size_t count() const { return mFrames.size(); }
    bool video() const { return mFrames.size() > 1; }
    std::string label() const { return mBuiltin ? "builtin:fire:" + std::to_string(mBuiltin) : mSeq->pattern.str(); }

    /// Exemplar frame for target index i (looping when the exemplar is shorter), read with its alpha.
    const turb::RgbaImage& frame(size_t i)
    {
        const size_t k = i % mFrames.size();
        if (mCache.count(k)) return mCache.at(k);
        if (mCache.size() > 4) mCache.clear(); // a video exemplar: keep a few frames only
        turb::RgbaImage img = mBuiltin ? turb::scenes::fireExemplar(mBuiltin, 1) : load(k);
        return mCache.emplace(k, std::move(img)).first->second;
    }

private:
    std::string pathOf(size_t k) const { return mSeq->path(mFrames[k]); }

    turb::RgbaImage load(size_t k) const
    {
        const std::string path = pathOf(k);
        turbio::ImageFileInfo info;
        turb::RgbaImage img = turbio::readImage(path, &info);
        if (mAlphaSeq) {
            const std::string apath = mAlphaSeq->frames.empty() ? mAlphaSeq->pattern.str()
                                                                 : mAlphaSeq->path(mAlphaSeq->frames[k % mAlphaSeq->frames.size()]);
            const turb::RgbaImage mask = turbio::readImage(apath);
            if (!mask.sameSize(img))
                throw turb::IoError(apath + ": the exemplar mask (" + std::to_string(mask.width()) + "x" + std::to_string(mask.height()) +
                                    ") and " + path + " (" + std::to_string(img.width()) + "x" + std::to_string(img.height()) + ") differ in size");
            for (size_t p = 0; p < img.size(); ++p) img.pixels()[p][3] = mask.pixels()[p][0];
        }
        float amax = 0.0f;
        for (const auto& p : img.pixels()) amax = std::max(amax, p[3]);
        if (!(amax > 0.0f)) throw turb::IoError(path + ": the exemplar's alpha is empty (zero everywhere)");
        return img;
    }

    const StylizeArgs& mArgs;
    std::optional<turbio::Sequence> mSeq, mAlphaSeq;
    std::vector<int> mFrames;
    int mBuiltin = 0;
    std::map<size_t, turb::RgbaImage> mCache;
};


turb::Image previewSheet(const TargetFrame& t, const TargetSource& src, const turb::RgbaImage& ex, const turb::RgbaImage& out, int frame)
{
    const turb::Rgb bg(0.07f, 0.075f, 0.09f);
    turb::Image target;
    if (t.cacheFrame) {
        turb::DensityRenderSettings dr;
        dr.camera = src.bridge().camera;
        dr.camera->width = t.alpha.width();
        dr.camera->height = t.alpha.height();
        dr.extinction = src.bridge().extinction;
        target = turb::renderDensity(t.cacheFrame->density, dr);
    } else {
        target = turb::channelPicture(turb::toRgba(t.alpha), 0);
    }
    const turb::Image lic = motionPicture(t.motion), styl = turb::overBackground(out, bg), exPic = turb::overBackground(ex, bg);
    const std::vector<turb::SheetCell> row{{&target, t.cacheFrame ? "cache render" : "target alpha"},
        {&lic, "motion (LIC)"}, {&styl, "stylized"}, {&exPic, "exemplar"}};
    return turb::contactSheet({row}, {}, "stylize frame " + std::to_string(frame), 1);
}

nlohmann::json statsJson(const turb::StylizeStats& st)
{
    nlohmann::json usage = nlohmann::json::array();
    for (const auto& u : st.usage)
        usage.push_back({{"segment", u.label == 1 ? "interior" : "boundary"}, {"sources", u.sources}, {"targets", u.targets},
            {"K", u.K}, {"R", u.R}, {"min_count", u.minCount}, {"max_count", u.maxCount}, {"coverage", u.coverage}});
    nlohmann::json j;
    j["size"] = {st.width, st.height};
    j["levels"] = st.levels;
    j["patch_usage"] = usage;
    j["coverage"] = st.coverage;
    j["rounds"] = st.rounds;
    j["energy"] = st.energy;
    j["std_ratio"] = st.stdRatio;
    j["gradient_ratio"] = st.gradientRatio;
    if (st.temporalChange) {
        j["temporal_change"] = *st.temporalChange;
        j["temporal_pixels"] = st.temporalPixels;
    }
    j["iou"] = st.iou;
    j["boundary_gradient_match"] = st.boundaryGradientMatch;
    j["boundary_gradient_histogram"] = st.boundaryGradient;
    j["exemplar_boundary_gradient_histogram"] = st.exemplarBoundaryGradient;
    j["steps_s"] = {{"guides", st.secondsGuides}, {"nnf", st.secondsNnf}, {"vote", st.secondsVote}, {"warp", st.secondsWarp},
        {"stats", st.secondsStats}};
    return j;
}

std::string humanLine(const turb::StylizeStats& st)
{
    std::string s = "coverage " + fmt("%.1f%%", 100.0 * st.coverage);
    for (const auto& u : st.usage)
        s += std::string(u.label == 1 ? ", interior" : ", boundary") + " counts " + std::to_string(u.minCount) + "-" + std::to_string(u.maxCount) +
             " (K " + std::to_string(u.K) + ")";
    s += fmt(", std %.2f", st.stdRatio) + fmt(" grad %.2f", st.gradientRatio) + fmt(", IoU %.3f", st.iou) +
         fmt(" edge %.2f", st.boundaryGradientMatch);
    if (st.temporalChange) s += fmt(", change %.4f", *st.temporalChange);
    return s;
}

void writeTargetFiles(const std::string& dir, int frame, const TargetFrame& t, bool noClobber)
{
    const turbio::FramePattern a = turbio::FramePattern::parse(dir + "/alpha.####.png");
    const turbio::FramePattern m = turbio::FramePattern::parse(dir + "/motion.####.exr");
    turbio::ensureParentDirectory(a.format(frame));
    turbio::ImageWriteOptions o;
    o.noClobber = noClobber;
    o.alpha = false;
    turb::RgbaImage gray(t.alpha.width(), t.alpha.height());
    for (size_t i = 0; i < gray.size(); ++i) {
        const float v = t.alpha.pixel(i)[0];
        gray.pixels()[i] = turb::Rgba(v, v, v, 1.0f);
    }
    turbio::writeImage(a.format(frame), gray, o);
    turb::RgbaImage mv(t.motion.width(), t.motion.height());
    for (size_t i = 0; i < mv.size(); ++i) mv.pixels()[i] = turb::Rgba(t.motion.pixel(i)[0], t.motion.pixel(i)[1], 0.0f, 1.0f);
    o.bits = turbio::PixelBits::Float;
    turbio::writeImage(m.format(frame), mv, o);
}

int runStylize(StylizeArgs& a)
{
    if (a.method == "fluidymation") return runFluidymation(a);
    turb::StylizeSettings& s = a.settings;
    s.nnf = a.nnf == "standard" ? turb::NnfMode::Standard : turb::NnfMode::Uniform;
    turb::validate(s);
    if (a.out.empty()) {
        logError("give --out PATTERN (.png, .exr or .tif with #### for the frame)");
        return kUsage;
    }
    try {
        turbio::outputFormatOf(a.out);
    } catch (const turb::ValueError& e) {
        logError(messageWithFlags(e));
        return kUsage;
    }
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    TargetSource target(a);
    if (!outPattern.numbered() && target.frames().size() > 1)
        throw turb::ValueError("--out " + a.out + " has no frame token (####) but there are " + std::to_string(target.frames().size()) + " frames");
    ExemplarSource exemplar(a, s.patchSize);
    logInfo("stylize: " + target.label() + ", exemplar " + exemplar.label() + (exemplar.video() ? " (video, " + std::to_string(exemplar.count()) + " frames)" : "") +
            ", " + std::to_string(target.frames().size()) + " frames, nnf " + a.nnf);
    target.validate2D();
    // Every exemplar frame is read once before the first output, so a bad one writes nothing.
    for (size_t i = 0; i < exemplar.count(); ++i) exemplar.frame(i);
    if (globals().dryRun) {
        for (int f : target.frames()) logInfo("frame " + std::to_string(f) + " -> " + outPattern.format(f));
        return kOk;
    }

    int result = kOk;
    turb::withThreads(globals().threads, [&] {
        turb::Stylizer styl(s);
        RunReport report("stylize", a.json);
        std::optional<turb::ChannelImage> previousMotion, previousAlpha;
        int previousFrame = 0;
        const auto& frames = target.frames();
        for (size_t i = 0; i < frames.size(); ++i) {
            const int fr = frames[i];
            const auto t0 = std::chrono::steady_clock::now();
            ConsoleProgress progress(int(i), int(frames.size()), fr);
            progress.begin("reading");
            const TargetFrame t = target.read(fr);
            // Copies: the exemplar source keeps only a few frames of a video cached.
            const turb::RgbaImage ex = exemplar.frame(i);
            std::optional<turb::RgbaImage> exPrevious;
            if (exemplar.video() && i > 0) exPrevious = exemplar.frame(i - 1);
            const turb::RgbaImage* exPrev = exPrevious && exPrevious->sameSize(ex) ? &*exPrevious : nullptr;
            turb::StylizeFrame in;
            in.alpha = &t.alpha;
            // Frames that do not follow each other (a step, a gap) start a new shot: F^{t-1} does not apply.
            in.motionIn = previousMotion && previousFrame == fr - 1 ? &*previousMotion : nullptr;
            in.motionOut = &t.motion;
            in.exemplar = &ex;
            in.exemplarPrevious = exPrev;
            turb::StylizedFrame outFrame;
            try {
                outFrame = styl.next(in, &progress);
            } catch (const turb::ValueError& e) {
                throw turb::ValueError(t.alphaName + " with exemplar " + exemplar.label() + ": " + e.what(),
                    e.settings());
            }
            progress.begin("writing");
            const std::string outPath = outPattern.format(fr);
            turbio::ensureParentDirectory(outPath);
            turbio::ImageWriteOptions wo;
            wo.noClobber = a.noClobber;
            turbio::writeImage(outPath, outFrame.image, wo);
            nlohmann::json extra = statsJson(outFrame.stats);
            extra["out"] = outPath;
            if (in.motionIn && previousAlpha && previousAlpha->sameSize(t.alpha)) {
                // Is the target's motion right? The previous alpha advected by it against left in place.
                const turb::AdvectionCheck ac = turb::checkAdvection(*previousAlpha, *previousMotion, t.alpha);
                extra["alpha_error_advected"] = ac.advected;
                extra["alpha_error_still"] = ac.still;
            }
            if (!a.writeTarget.empty()) writeTargetFiles(a.writeTarget, fr, t, a.noClobber);
            if (!a.preview.empty()) {
                const std::string png = turbio::FramePattern::parse(a.preview + "/stylize.####.png").format(fr);
                turbio::ensureParentDirectory(png);
                turbio::writeImage(png, previewSheet(t, target, ex, outFrame.image, fr));
                extra["preview"] = png;
            }
            progress.clear();
            report.frameDone(fr, int(i), int(frames.size()), secondsSince(t0), humanLine(outFrame.stats) + " -> " + outPath, extra);
            previousMotion = t.motion;
            previousAlpha = t.alpha;
            previousFrame = fr;
        }
        report.finish();
    });
    return result;
}

} // namespace

Command stylizeCommand()
{
    auto args = std::make_shared<StylizeArgs>();
    Command c;
    c.name = "stylize";
    c.help = "Appearance transfer onto fluid motion: an exemplar's look on 2D flows or on a VDB cache seen through a camera (LazyFluids; "
             "--method fluidymation: a moving exemplar's look and dynamics)";
    c.setup = [args](CLI::App* app) {
        StylizeArgs& a = *args;
        turb::StylizeSettings& s = a.settings;
        app->add_option("--method", a.method,
               "lazyfluids (LazyFluids: a still or video RGBA exemplar, uniform patch usage; default) or fluidymation (Fluidymation: a "
               "moving exemplar's look and dynamics; options marked [fluidymation])")
            ->check(CLI::IsMember({"lazyfluids", "fluidymation"}));
        app->add_option("--exemplar", a.exemplar,
               "RGBA exemplar: one picture (PNG, EXR, TIFF, JPEG...), a sequence with #### (a video exemplar: target frame i "
               "uses exemplar frame i, looping), or builtin:fire[:N] (procedural, smooth and textured halves); fluidymation: the RGB "
               "frames of the moving exemplar, or builtin:ink[:WxH[xFRAMES]] (ink spreading on wet paper)")
            ->required();
        app->add_option("--exemplar-alpha", a.exemplarAlpha, "Grayscale mask (or ####-sequence) giving the exemplar's alpha");
        app->add_option("--flow", a.flow, "2D motion F^t per frame: images with R,G in pixels per frame (x right, y down), or one-layer VDBs");
        app->add_option("--alpha", a.alpha, "2D target alpha masks per frame (grayscale images)");
        app->add_flag("--flow-y-up", a.flowYUp, "The flow images' G channel points up (Nuke/Houdini style) rather than down");
        app->add_option("--cache", a.cache, "A 3D cache (density + velocity) seen through --camera: alpha = rendered opacity, motion = projected velocity");
        app->add_option("--scene", a.scene,
               "A built-in 2D target: rotate, swirl (a blob in a rotating/shearing vortex), rise, fill (all fluid), grow (a spreading "
               "blot that comes to rest) or stroke (a brush stroke whose tip advances)")
            ->check(CLI::IsMember({"rotate", "swirl", "rise", "fill", "grow", "stroke"}));
        app->add_option("--scene-size", a.sceneSize, "Built-in target size WxH (default 256x256)");
        app->add_option("--scene-speed", a.sceneSpeed, "Built-in target: radians per frame at the centre (rise: image widths per frame) (default 0.02)");
        app->add_option("--frames", a.frames, "Frames (e.g. 1-150); a scene: a count N or a list (default: every frame on disk; scene 1)")->check(frameListCheck());
        app->add_option("--camera", a.camera, "Cache camera: front (along +y), side (along +x), top (down -z), or perspective (default front)")
            ->check(CLI::IsMember({"front", "side", "top", "perspective"}));
        app->add_option("--camera-pos", a.cameraPos, "Perspective camera position X,Y,Z (world units)");
        app->add_option("--look-at", a.lookAt, "Perspective camera target X,Y,Z (world units)");
        app->add_option("--camera-up", a.cameraUp, "Perspective camera up direction (default 0,0,1)");
        app->add_option("--fov", a.fov, "Perspective horizontal field of view in degrees (default 40)")->check(CLI::Range(1.0, 170.0));
        app->add_option("--width", a.width, "Cache camera image width (default: 4 pixels per voxel; perspective 512)")->check(CLI::Range(16, 16384));
        app->add_option("--height", a.height, "Perspective image height (default: the width)")->check(CLI::Range(0, 16384));
        app->add_option("--extinction", a.extinction, "Cache opacity: optical depth per unit density per world unit (default 6, as preview)")
            ->check(CLI::PositiveNumber);
        app->add_option("--step", a.step, "Cache ray-march step in voxels (default 0.5)")->check(CLI::Range(0.05, 1.0));
        app->add_option("--out", a.out, "Output RGBA frames, e.g. styl/fire.####.exr (EXR half, premultiplied) or .png (straight alpha)");
        app->add_flag("--no-clobber", a.noClobber, "Never replace an existing output file");
        app->add_option("--preview", a.preview, "Write a PNG per frame into DIR: target | motion (LIC) | stylized | exemplar");
        app->add_option("--write-target", a.writeTarget, "Write the target per frame into DIR: alpha.####.png and motion.####.exr (float R,G)");
        app->add_option("--nnf", a.nnf, "uniform (reversed NNF with uniform patch usage, the paper) or standard (Kwatra nearest neighbours: the wash-out ablation)")
            ->check(CLI::IsMember({"uniform", "standard"}));
        app->add_option("--patch", s.patchSize, "Patch size in pixels, odd (default 5, paper)")->check(CLI::Range(3, 15));
        app->add_option("--lambda", s.lambda, "Temporal coherence lambda (default 0.2, paper; 0 = independent frames)")->check(CLI::NonNegativeNumber);
        app->add_option("--eta", s.eta, "Weight of the blurred-alpha guide (default 3, paper)")->check(CLI::NonNegativeNumber);
        app->add_option("--blur-radius", s.blurRadius, "r: Gaussian standard deviation (pixels) of the guide alpha (default 3, paper)")
            ->check(CLI::PositiveNumber);
        app->add_option("--lower", s.lower, "l: boundary segment where the blurred alpha lies in (l, u) (default 0.1)")->check(CLI::Range(0.0, 1.0));
        app->add_option("--upper", s.upper, "u: interior segment where the blurred alpha >= u (default 0.9)")->check(CLI::Range(0.0, 1.0));
        app->add_option("--levels", s.levels, "Pyramid levels (default 0 = auto: short sides >= 32 px, at most 5)")->check(CLI::Range(0, 8));
        app->add_option("--iterations", s.iterations, "EM iterations on each coarser level (default 4)")->check(CLI::Range(1, 50));
        app->add_option("--fine-iterations", s.fineIterations, "EM iterations on the finest level (default 2)")->check(CLI::Range(1, 50));
        app->add_option("--sweeps", s.sweeps, "PatchMatch sweeps per retrieval round (default 2)")->check(CLI::Range(1, 32));
        app->add_flag("--rotations", s.rotations, "Also use the exemplar rotated by 90, 180 and 270 degrees (section 4.5)");
        app->add_option("--motion-blur", s.motionBlur, "Blur along F^t by this fraction of a frame's motion (default 0 = none; Fig. 9)")
            ->check(CLI::NonNegativeNumber);
        app->add_option("--seed", s.seed, "Random seed: the same seed gives the same frames at any --threads (default 1)");
        app->add_flag("--json", a.json, "One JSON line per frame (patch usage, std/gradient ratios, temporal change, IoU, times) and a summary");
        addReadOptions(app, a.read);
        addFluidymationOptions(app, a);
    };
    c.run = [args] { return runStylize(*args); };
    return c;
}

} // namespace vdbturb
