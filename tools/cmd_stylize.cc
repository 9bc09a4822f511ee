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
                throw turb::IoError(path + ": the exemplar (" + std::to_string(info.width) + "x" +
                                    std::to_string(info.height) + ") is smaller than a " + std::to_string(patchSize) +
                                    "x" + std::to_string(patchSize) + " patch");
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
            const std::string apath = mAlphaSeq->frames.empty()
                                          ? mAlphaSeq->pattern.str()
                                          : mAlphaSeq->path(mAlphaSeq->frames[k % mAlphaSeq->frames.size()]);
            const turb::RgbaImage mask = turbio::readImage(apath);
            if (!mask.sameSize(img))
                throw turb::IoError(apath + ": the exemplar mask (" + std::to_string(mask.width()) + "x" +
                                    std::to_string(mask.height()) + ") and " + path + " (" +
                                    std::to_string(img.width()) + "x" + std::to_string(img.height()) +
                                    ") differ in size");
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

turb::Image previewSheet(
    const TargetFrame& t, const TargetSource& src, const turb::RgbaImage& ex, const turb::RgbaImage& out, int frame)
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
    const turb::Image lic = motionPicture(t.motion), styl = turb::overBackground(out, bg),
                      exPic = turb::overBackground(ex, bg);
    const std::vector<turb::SheetCell> row{{&target, t.cacheFrame ? "cache render" : "target alpha"},
        {&lic, "motion (LIC)"}, {&styl, "stylized"}, {&exPic, "exemplar"}};
    return turb::contactSheet({row}, {}, "stylize frame " + std::to_string(frame), 1);
}

nlohmann::json statsJson(const turb::StylizeStats& st)
{
    nlohmann::json usage = nlohmann::json::array();
    for (const auto& u : st.usage)
        usage.push_back({{"segment", u.label == 1 ? "interior" : "boundary"}, {"sources", u.sources},
            {"targets", u.targets}, {"K", u.K}, {"R", u.R}, {"min_count", u.minCount}, {"max_count", u.maxCount},
            {"coverage", u.coverage}});
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
    j["shot_start"] = st.shotStart;
    if (st.preroll > 0) j["preroll"] = st.preroll;
    j["iou"] = st.iou;
    j["boundary_gradient_match"] = st.boundaryGradientMatch;
    j["boundary_gradient_histogram"] = st.boundaryGradient;
    j["exemplar_boundary_gradient_histogram"] = st.exemplarBoundaryGradient;
    j["steps_s"] = {{"guides", st.secondsGuides}, {"nnf", st.secondsNnf}, {"vote", st.secondsVote},
        {"warp", st.secondsWarp}, {"stats", st.secondsStats}};
    return j;
}

std::string humanLine(const turb::StylizeStats& st)
{
    std::string s = "coverage " + fmt("%.1f%%", 100.0 * st.coverage);
    for (const auto& u : st.usage)
        s += std::string(u.label == 1 ? ", interior" : ", boundary") + " counts " + std::to_string(u.minCount) + "-" +
             std::to_string(u.maxCount) + " (K " + std::to_string(u.K) + ")";
    s += fmt(", std %.2f", st.stdRatio) + fmt(" grad %.2f", st.gradientRatio) + fmt(", IoU %.3f", st.iou) +
         fmt(" edge %.2f", st.boundaryGradientMatch);
    if (st.temporalChange) s += fmt(", change %.4f", *st.temporalChange);
    if (st.shotStart)
        s += st.preroll > 0 ? ", shot start (pre-roll " + std::to_string(st.preroll) + ")" : ", shot start";
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
    for (size_t i = 0; i < mv.size(); ++i)
        mv.pixels()[i] = turb::Rgba(t.motion.pixel(i)[0], t.motion.pixel(i)[1], 0.0f, 1.0f);
    o.bits = turbio::PixelBits::Float;
    turbio::writeImage(m.format(frame), mv, o);
}

// Frames that do not follow each other (a step, a gap) start a new shot: F^{t-1} does not apply.
struct Previous
{
    std::optional<turb::ChannelImage> motion, alpha;
    int frame = 0;
    const turb::ChannelImage* motionInto(int fr) const { return motion && frame == fr - 1 ? &*motion : nullptr; }
};

// Writes the stylized frame and what --write-target and --preview ask for; returns the frame's JSON.
nlohmann::json writeStylized(const StylizeArgs& a, int fr, const TargetFrame& t, const TargetSource& target,
    const turb::RgbaImage& ex, const turb::StylizedFrame& outFrame, const Previous& prev, const std::string& outPath,
    const std::string& settings)
{
    turbio::ensureParentDirectory(outPath);
    turbio::ImageWriteOptions wo;
    wo.noClobber = a.noClobber;
    wo.metadata = frameMetadata("stylize", settings);
    turbio::writeImage(outPath, outFrame.image, wo);
    nlohmann::json extra = statsJson(outFrame.stats);
    extra["out"] = outPath;
    if (prev.motionInto(fr) && prev.alpha && prev.alpha->sameSize(t.alpha)) {
        // Is the target's motion right? The previous alpha advected by it against left in place.
        const turb::AdvectionCheck ac = turb::checkAdvection(*prev.alpha, *prev.motion, t.alpha);
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
    return extra;
}

// The frames in order: each one's temporal term reads the previous output, warped by the previous motion.
void stylizeFrames(const StylizeArgs& a, const TargetSource& target, ExemplarSource& exemplar,
    const turbio::FramePattern& outPattern, const SkipPlan& plan, const std::vector<std::string>& settings)
{
    turb::Stylizer styl(a.settings);
    RunReport report("stylize", a.json);
    Previous prev;
    const auto& frames = target.frames();
    for (size_t i = 0; i < plan.end; ++i) {
        const int fr = frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        ConsoleProgress progress(int(i), int(frames.size()), fr);
        progress.begin("reading");
        const TargetFrame t = target.read(fr);
        // Copies: the exemplar source keeps only a few frames of a video cached.
        const turb::RgbaImage ex = exemplar.frame(i);
        std::optional<turb::RgbaImage> exPrevious;
        if (exemplar.video() && i > 0) exPrevious = exemplar.frame(i - 1);
        turb::StylizeFrame in;
        in.alpha = &t.alpha;
        in.motionIn = prev.motionInto(fr);
        in.motionOut = &t.motion;
        in.number = fr;
        in.exemplar = &ex;
        in.exemplarPrevious = exPrevious && exPrevious->sameSize(ex) ? &*exPrevious : nullptr;
        turb::StylizedFrame outFrame;
        try {
            outFrame = styl.next(in, &progress);
        } catch (const turb::ValueError& e) {
            throw turb::ValueError(t.alphaName + " with exemplar " + exemplar.label() + ": " + e.what(), e.settings());
        }
        const std::string outPath = outPattern.format(fr);
        if (plan.skipped(i)) {
            progress.clear();
            report.frameSkipped(fr, int(i), int(frames.size()), secondsSince(t0), outPath, true);
        } else {
            progress.begin("writing");
            const nlohmann::json extra = writeStylized(a, fr, t, target, ex, outFrame, prev, outPath, settings[i]);
            progress.clear();
            report.frameDone(
                fr, int(i), int(frames.size()), secondsSince(t0), humanLine(outFrame.stats) + " -> " + outPath, extra);
        }
        prev.motion = t.motion;
        prev.alpha = t.alpha;
        prev.frame = fr;
    }
    report.finish();
}

// The options given on the command line (or in a settings file) that the chosen method does not read, warned once.
void warnUnread(const std::vector<const CLI::Option*>& options, const std::string& whose, const std::string& method)
{
    std::string given;
    for (const CLI::Option* o : options)
        if (o->count() > 0) given += (given.empty() ? "" : ", ") + o->get_name();
    if (!given.empty())
        logWarning("stylize: " + given + " set " + whose + " synthesis; " + method + " does not read " +
                   (given.find(',') == std::string::npos ? "it" : "them"));
}

int runStylize(StylizeArgs& a)
{
    if (a.method == Method::Fluidymation) {
        warnUnread(a.lazyFluidsOnly, "LazyFluids'", "--method fluidymation");
        return runFluidymation(a);
    }
    warnUnread(a.fluidymationOnly, "Fluidymation's", "--method lazyfluids (the default)");
    const turb::StylizeSettings& s = a.settings;
    turb::validate(s);
    if (const int rc = checkOutputPatterns(a.out); rc != kOk) return rc;
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    TargetSource target(a);
    if (!outPattern.numbered() && target.frames().size() > 1)
        throw UsageError("--out " + a.out + " has no frame token (####) but there are " +
                         std::to_string(target.frames().size()) + " frames");
    ExemplarSource exemplar(a, s.patchSize);
    logInfo("stylize: " + target.label() + ", exemplar " + exemplar.label() +
            (exemplar.video() ? " (video, " + std::to_string(exemplar.count()) + " frames)" : "") + ", " +
            std::to_string(target.frames().size()) + " frames, nnf " +
            (s.nnf == turb::NnfMode::Standard ? "standard" : "uniform") +
            (s.preroll > 0 && s.lambda > 0.0f
                    ? ", pre-roll " + std::to_string(s.preroll) + " on the first frame of each shot (after a gap too)"
                    : std::string()));
    target.validate2D();
    // Every exemplar frame is read once before the first output, so a bad one writes nothing.
    for (size_t i = 0; i < exemplar.count(); ++i) exemplar.frame(i);
    std::vector<std::string> settings;
    const SkipPlan plan = planOutputFrames(a, target.frames(), outPattern, settings);
    if (globals().dryRun) {
        // The plan is the dry run's data: stdout, as transfer's "would write" lines.
        if (!a.skipExisting)
            for (int f : target.frames())
                printData("would write " + outPattern.format(f) + " (frame " + std::to_string(f) + ")");
        return kOk;
    }
    lockOutputFrames(outPattern, plan.writing); // two tasks never write one frame (a second exits 75)
    turb::withThreads(globals().threads, [&] { stylizeFrames(a, target, exemplar, outPattern, plan, settings); });
    return kOk;
}

// The exemplar, the target (2D masks and flows, a cache through a camera, or a built-in scene) and the frames.
void addInputOptions(CLI::App* app, StylizeArgs& a)
{
    app->add_option("--exemplar", a.exemplar,
           "Exemplar: a picture, a #### sequence (a video), builtin:fire[:N]; fluidymation: its frames or "
           "builtin:ink[:WxH[xN]]")
        ->required();
    app->add_option(
        "--exemplar-alpha", a.exemplarAlpha, "Grayscale mask (or #### sequence) giving the exemplar's alpha");
    app->add_option(
        "--flow", a.flow, "2D target motion per frame: R,G in pixels per frame (x right, y down), or 1-layer VDBs");
    app->add_option("--alpha", a.alpha, "2D target alpha masks per frame (grayscale images)");
    app->add_option(
        "--cache", a.cache, "3D target: a cache seen through --camera (alpha = opacity, motion = projected velocity)");
    addCameraOptions(app, a.camera);
    app->add_option("--scene", a.scene, "Built-in 2D target: rotate, swirl, rise, fill, grow or stroke")
        ->check(CLI::IsMember({"rotate", "swirl", "rise", "fill", "grow", "stroke"}));
    app->add_option(
           "--frames", a.frames, "Frames, e.g. 1-150; a scene: a count N or a list (empty: all on disk; scene 1)")
        ->check(frameListCheck());
    setting(app->add_option("--scene-size", a.sceneSize, "Built-in target size WxH"), "scene-size");
    setting(app->add_option("--scene-speed", a.sceneSpeed,
                "Built-in target: radians per frame at the centre (rise: widths per frame)"),
        "scene-speed");
    setting(
        app->add_flag("--flow-y-up", a.flowYUp, "The flow images' G channel points up (Nuke, Houdini)"), "flow-y-up");
    addReadOptions(app, a.read);
    // Only a --cache target reads grids: its grid and frame-rate choices are settings here.
    for (const char* name : {"density-grid", "vel-grid", "fps"})
        setting(app->get_option(std::string("--") + name), name);
}

void addOutputOptions(CLI::App* app, StylizeArgs& a)
{
    app->add_option(
        "--out", a.out, "Output RGBA frames, e.g. styl/fire.####.exr (EXR: half, premultiplied; PNG: straight)");
    app->add_option(
           "--preview", a.preview, "Write a PNG per frame into DIR: target | motion (LIC) | stylized | exemplar")
        ->group(kGroupOutput);
    app->add_flag("--no-clobber", a.noClobber, "Never replace an existing output file")->group(kGroupOutput);
    app->add_flag("--skip-existing", a.skipExisting,
           "Skip the frames already written by the same settings (farm wrappers' retries; the frames before the last "
           "one to write are made again, not written); a frame written otherwise is refused (exit 1)")
        ->group(kGroupOutput);
    a.app = app;
    app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
    setting(app->add_option("--write-target", a.writeTarget,
                "Write the target per frame into DIR: alpha.####.png, motion.####.exr"),
        "write-target");
}

// LazyFluids' knobs (Jamriška et al. 2015), under turb::StylizeSettings' field names; their measured effects are in
// docs/stylize.md.
void addLazyFluidsSettings(CLI::App* app, turb::StylizeSettings& s)
{
    const auto knob = [app](const std::string& names, auto& v, const std::string& help, const std::string& key) {
        return setting(app->add_option(names, v, help), key);
    };
    setting(addEnum<turb::NnfMode>(app, "--nnf", s.nnf,
                {{"uniform", turb::NnfMode::Uniform}, {"standard", turb::NnfMode::Standard}},
                "uniform: reversed NNF, uniform patch usage (the paper); standard: nearest neighbours (the wash-out "
                "ablation)"),
        "nnf");
    knob("--patch,--patchSize", s.patchSize, "Patch size in pixels, odd (paper 5)", "patchSize")
        ->check(CLI::Range(3, 15));
    knob("--lambda", s.lambda, "Temporal coherence lambda (paper 0.2; 0 = independent frames)", "lambda")
        ->check(finiteIn(0.0));
    knob("--eta", s.eta, "Weight of the blurred-alpha guide (paper 3)", "eta")->check(finiteIn(0.0));
    knob("--blur-radius,--blurRadius", s.blurRadius, "r: Gaussian standard deviation (pixels) of the guide alpha",
        "blurRadius")
        ->check(finitePositive());
    knob("--lower", s.lower, "l: boundary segment where the blurred alpha lies in (l, u)", "lower")
        ->check(finiteIn(0.0, 1.0));
    knob("--upper", s.upper, "u: interior segment where the blurred alpha >= u", "upper")->check(finiteIn(0.0, 1.0));
    knob("--levels", s.levels, "Pyramid levels (0 = short sides >= 32 px, at most 5)", "levels")
        ->check(CLI::Range(0, 8));
    knob("--iterations", s.iterations, "EM iterations on each coarser level", "iterations")->check(CLI::Range(1, 50));
    knob("--fine-iterations,--fineIterations", s.fineIterations, "EM iterations on the finest level", "fineIterations")
        ->check(CLI::Range(1, 50));
    knob("--sweeps", s.sweeps, "PatchMatch sweeps per retrieval round", "sweeps")->check(CLI::Range(1, 32));
    setting(app->add_flag("--rotations", s.rotations, "Also use the exemplar rotated by 90, 180 and 270 degrees"),
        "rotations");
    knob("--motion-blur,--motionBlur", s.motionBlur, "Blur along F^t by this fraction of a frame's motion (0 = none)",
        "motionBlur")
        ->check(finiteIn(0.0));
    knob("--vote-weight,--voteWeight", s.voteWeight,
        "Beyond the paper: votes weighted by exp(-D / (w x the 75th percentile of D)) (Wexler 2007; 0 = the paper's "
        "plain average)",
        "voteWeight")
        ->check(finiteIn(0.0));
    boolSetting(app, "--startFromPrevious", s.startFromPrevious,
        "Beyond the paper: later frames start every level from the previous output advected (false: coarse to fine, "
        "the paper)",
        "startFromPrevious");
    knob("--preroll", s.preroll,
        "Beyond the paper: a first frame is synthesised again N times as a held frame under the temporal term, so the "
        "look does not step between frames 1 and 5 (0 = the paper's first frame)",
        "preroll")
        ->check(CLI::Range(0, 100));
    knob("--seed", s.seed, "Random seed: the same seed gives the same frames at any --threads", "seed");
}

} // namespace

Command stylizeCommand()
{
    auto args = std::make_shared<StylizeArgs>();
    Command c;
    c.name = "stylize";
    c.help =
        "Appearance transfer onto fluid motion: an exemplar's look on 2D flows or on a VDB cache seen through a camera "
        "(LazyFluids; --method fluidymation: a moving exemplar's look and dynamics)";
    c.setup = [args](CLI::App* app) {
        StylizeArgs& a = *args;
        addEnum<Method>(app, "--method", a.method,
            {{"lazyfluids", Method::LazyFluids}, {"fluidymation", Method::Fluidymation}},
            "lazyfluids: a still or video RGBA exemplar; fluidymation: a moving exemplar's look and dynamics");
        addInputOptions(app, a);
        addOutputOptions(app, a);
        const size_t before = app->get_options().size();
        addLazyFluidsSettings(app, a.settings);
        const std::vector<CLI::Option*> all = app->get_options();
        for (size_t i = before; i < all.size(); ++i)
            if (!all[i]->check_lname("seed")) a.lazyFluidsOnly.push_back(all[i]); // fluidymation reads the seed
        addFluidymationOptions(app, a);
        const std::vector<CLI::Option*> more = app->get_options();
        for (size_t i = all.size(); i < more.size(); ++i) a.fluidymationOnly.push_back(more[i]);
    };
    c.run = [args] { return runStylize(*args); };
    return c;
}

} // namespace vdbturb
