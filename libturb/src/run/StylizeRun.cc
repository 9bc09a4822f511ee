// turb::run::runStylize: vdbturb stylize's run, LazyFluids (Jamriška et al. 2015) from files to files
// (turb/run/Stylize.h); --method fluidymation runs in StylizeFluidymation.cc.
#include <turb/run/Stylize.h>

#include "StylizeParts.h"

#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <scenes/Targets2D.h>
#include <turb/CameraBridge.h>
#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Render.h>
#include <turb/Stylize.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <map>
#include <memory>
#include <optional>

namespace turb::run {

namespace {

using detail::fmt;
using detail::TargetFrame;
using detail::TargetSource;

/// The exemplar: a still or a sequence (video), each frame with its alpha (from the file or a mask).
class ExemplarSource
{
public:
    ExemplarSource(const StylizeJob& a, int patchSize)
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
        checkHeaders(patchSize);
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

    // Headers of every frame now, so a bad exemplar stops the run before anything is written.
    void checkHeaders(int patchSize) const
    {
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

    std::optional<turbio::Sequence> mSeq, mAlphaSeq;
    std::vector<int> mFrames;
    int mBuiltin = 0;
    std::map<size_t, turb::RgbaImage> mCache;
};

turb::Image previewSheet(
    const TargetFrame& t, const TargetSource& src, const turb::RgbaImage& ex, const turb::RgbaImage& out, int frame)
{
    const turb::Rgb bg(0.07f, 0.075f, 0.09f);
    const turb::Image target =
        t.cacheFrame ? detail::cacheRender(t, src) : turb::channelPicture(turb::toRgba(t.alpha), 0);
    const turb::Image lic = detail::motionPicture(t.motion), styl = turb::overBackground(out, bg),
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
nlohmann::json writeStylized(const StylizeJob& a, int fr, const TargetFrame& t, const TargetSource& target,
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
class FrameLoop
{
public:
    FrameLoop(const StylizeJob& a, const TargetSource& target, ExemplarSource& exemplar,
        const turbio::FramePattern& outPattern, const SkipPlan& plan, const std::vector<std::string>& settings)
        : mA(a), mTarget(target), mExemplar(exemplar), mOut(outPattern), mPlan(plan), mSettings(settings),
          mStylizer(a.settings)
    {}

    void run(StylizeRun& done)
    {
        reporter().runStarted("stylize");
        for (size_t i = 0; i < mPlan.end; ++i) frame(i, done);
        reporter().runFinished(0, nlohmann::json::object());
    }

private:
    void frame(size_t i, StylizeRun& done)
    {
        const auto& frames = mTarget.frames();
        const int fr = frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(int(i), int(frames.size()), fr);
        progress->begin("reading");
        const TargetFrame t = mTarget.read(fr);
        // Copies: the exemplar source keeps only a few frames of a video cached.
        const turb::RgbaImage ex = mExemplar.frame(i);
        std::optional<turb::RgbaImage> exPrevious;
        if (mExemplar.video() && i > 0) exPrevious = mExemplar.frame(i - 1);
        const turb::StylizedFrame outFrame = stylize(t, ex, exPrevious, fr, *progress);
        const std::string outPath = mOut.format(fr);
        if (mPlan.skipped(i)) {
            progress->clear();
            reporter().frameSkipped(fr, int(i), int(frames.size()), detail::secondsSince(t0), outPath, true);
            ++done.framesSkipped;
        } else {
            progress->begin("writing");
            const nlohmann::json extra = writeStylized(mA, fr, t, mTarget, ex, outFrame, mPrev, outPath, mSettings[i]);
            progress->clear();
            reporter().frameDone(FrameRecord{fr, int(i), int(frames.size()), detail::secondsSince(t0),
                humanLine(outFrame.stats) + " -> " + outPath, extra});
            ++done.framesWritten;
        }
        mPrev.motion = t.motion;
        mPrev.alpha = t.alpha;
        mPrev.frame = fr;
    }

    turb::StylizedFrame stylize(const TargetFrame& t, const turb::RgbaImage& ex,
        const std::optional<turb::RgbaImage>& exPrevious, int fr, FrameProgress& progress)
    {
        turb::StylizeFrame in;
        in.alpha = &t.alpha;
        in.motionIn = mPrev.motionInto(fr);
        in.motionOut = &t.motion;
        in.number = fr;
        in.exemplar = &ex;
        in.exemplarPrevious = exPrevious && exPrevious->sameSize(ex) ? &*exPrevious : nullptr;
        try {
            return mStylizer.next(in, &progress);
        } catch (const turb::ValueError& e) {
            throw turb::ValueError(t.alphaName + " with exemplar " + mExemplar.label() + ": " + e.what(), e.settings());
        }
    }

    const StylizeJob& mA;
    const TargetSource& mTarget;
    ExemplarSource& mExemplar;
    const turbio::FramePattern& mOut;
    const SkipPlan& mPlan;
    const std::vector<std::string>& mSettings;
    turb::Stylizer mStylizer;
    Previous mPrev;
};

void logPlan(const StylizeJob& a, const TargetSource& target, const ExemplarSource& exemplar)
{
    const turb::StylizeSettings& s = a.settings;
    logInfo("stylize: " + target.label() + ", exemplar " + exemplar.label() +
            (exemplar.video() ? " (video, " + std::to_string(exemplar.count()) + " frames)" : "") + ", " +
            std::to_string(target.frames().size()) + " frames, nnf " +
            (s.nnf == turb::NnfMode::Standard ? "standard" : "uniform") +
            (s.preroll > 0 && s.lambda > 0.0f
                    ? ", pre-roll " + std::to_string(s.preroll) + " on the first frame of each shot (after a gap too)"
                    : std::string()));
}

StylizeRun runLazyFluids(const StylizeJob& a)
{
    StylizeRun done;
    turb::validate(a.settings);
    detail::checkOutputPatterns(a.out);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    TargetSource target(a);
    detail::checkFrameToken(outPattern, a.out, target.frames().size());
    ExemplarSource exemplar(a, a.settings.patchSize);
    logPlan(a, target, exemplar);
    target.validate2D();
    // Every exemplar frame is read once before the first output, so a bad one writes nothing.
    for (size_t i = 0; i < exemplar.count(); ++i) exemplar.frame(i);
    std::vector<std::string> settings;
    const SkipPlan plan = detail::planOutputFrames(a, target.frames(), outPattern, settings);
    if (a.dryRun) {
        detail::printWouldWrite(a, target.frames(), outPattern); // the dry run's data
        return done;
    }
    lockOutputFrames(outPattern, plan.writing); // two tasks never write one frame (a second exits 75)
    turb::withThreads(a.threads, [&] { FrameLoop(a, target, exemplar, outPattern, plan, settings).run(done); });
    return done;
}

} // namespace

StylizeRun runStylize(const StylizeJob& job)
{
    if (job.method == StylizeMethod::Fluidymation) return detail::runFluidymation(job);
    return runLazyFluids(job);
}

} // namespace turb::run
