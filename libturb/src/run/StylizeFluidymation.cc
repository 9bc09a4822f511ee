// runStylize with StylizeMethod::Fluidymation: moving exemplars (turb/run/Stylize.h).
#include "StylizeParts.h"

#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <scenes/Ink2D.h>
#include <turb/Error.h>
#include <turb/Fluidymation.h>
#include <turb/Parallel.h>
#include <turb/Render.h>
#include <turbio/ImageIO.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <memory>

namespace turb::run::detail {

namespace {

/// The moving exemplar: RGB frames and their motion (masks, flows given or estimated, extents).
struct ExemplarVideo
{
    std::vector<turb::ChannelImage> rgb;
    turb::MotionSequence motion;
    std::string label, colorSpace;
};

std::string sizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

/// "builtin:ink[:WxH[xN]]".
turb::scenes::InkSettings parseInk(const std::string& spec)
{
    turb::scenes::InkSettings s;
    const size_t c = spec.find(':', 8);
    if (c == std::string::npos) return s;
    const std::string dims = spec.substr(c + 1);
    int w = 0, h = 0, n = 0;
    char x1 = 0, x2 = 0, extra = 0;
    const int got = std::sscanf(dims.c_str(), "%d%c%d%c%d%c", &w, &x1, &h, &x2, &n, &extra);
    if (!((got == 3 && x1 == 'x') || (got == 5 && x1 == 'x' && x2 == 'x')) || w < 32 || h < 32 || (got == 5 && n < 1))
        throw turb::ValueError("--exemplar " + spec + ": expected builtin:ink[:WxH[xFRAMES]] with W, H >= 32");
    s.width = w;
    s.height = h;
    if (got == 5) s.frames = n;
    return s;
}

turb::ChannelImage flowImage(const std::string& path)
{
    const turb::RgbaImage img = turbio::readImage(path);
    turb::ChannelImage m(img.width(), img.height(), 2);
    for (size_t i = 0; i < img.size(); ++i) {
        m.pixel(i)[0] = img.pixels()[i][0];
        m.pixel(i)[1] = img.pixels()[i][1];
    }
    return m;
}

turb::ChannelImage maskOf(const turb::RgbaImage& img, int channel)
{
    turb::ChannelImage m(img.width(), img.height(), 1);
    for (size_t i = 0; i < img.size(); ++i) m.pixel(i)[0] = img.pixels()[i][channel];
    return m;
}

ExemplarVideo builtinInk(const std::string& spec, bool estimateFlow)
{
    ExemplarVideo ex;
    const turb::scenes::InkSettings s = parseInk(spec);
    turb::scenes::InkSequence ink = turb::scenes::inkExemplar(s);
    ex.label = "builtin:ink:" + sizeText(s.width, s.height) + "x" + std::to_string(s.frames);
    ex.colorSpace = "sRGB";
    ex.motion = turb::MotionSequence(s.width, s.height);
    for (int i = 0; i < s.frames; ++i) {
        ex.rgb.push_back(turb::channelRange(turb::toChannels(ink.rgb[size_t(i)]), 0, 3));
        ex.motion.addFrame(ink.mask[size_t(i)], estimateFlow ? nullptr : &ink.flow[size_t(i)]);
    }
    return ex;
}

/// The exemplar's files: its frames, and its masks and flows when given (as many as the frames).
struct ExemplarFiles
{
    turbio::Sequence seq;
    std::vector<int> frames;
    std::optional<turbio::Sequence> masks, flows;

    std::string framePath(size_t k) const { return seq.frames.empty() ? seq.pattern.str() : seq.path(frames[k]); }
    static std::string pathIn(const turbio::Sequence& s, size_t k)
    {
        return s.frames.empty() ? s.pattern.str() : s.path(s.frames[k]);
    }
};

ExemplarFiles exemplarFiles(const StylizeJob& a, bool estimateFlow)
{
    const FluidymationJob& f = a.fluidy;
    ExemplarFiles files{turbio::resolveSequence(a.exemplar), {}, {}, {}};
    const turbio::Sequence& seq = files.seq;
    if (!seq.missing.empty()) throw turb::IoError(seq.path(seq.missing.front()) + ": missing exemplar frame");
    files.frames = seq.frames.empty() ? std::vector<int>{0} : seq.frames;
    const std::string label = seq.pattern.str();
    if (!f.exemplarMask.empty()) files.masks = turbio::resolveSequence(f.exemplarMask);
    if (!f.exemplarFlow.empty() && !estimateFlow) files.flows = turbio::resolveSequence(f.exemplarFlow);
    for (const auto* s : {&files.masks, &files.flows}) {
        if (!*s) continue;
        if (!(*s)->missing.empty()) throw turb::IoError((*s)->path((*s)->missing.front()) + ": missing");
        const size_t n = (*s)->frames.empty() ? 1 : (*s)->frames.size();
        if (n != files.frames.size())
            throw turb::IoError((*s)->pattern.str() + ": " + std::to_string(n) +
                                (s == &files.masks ? " masks" : " flows") + " but the exemplar " + label + " has " +
                                std::to_string(files.frames.size()) + " frames (the counts must match)");
    }
    return files;
}

// Exemplar frame k: its picture, mask and flow, into `ex`.
void addExemplarFrame(const ExemplarFiles& files, size_t k, ExemplarVideo& ex)
{
    const std::string path = files.framePath(k);
    turbio::ImageFileInfo info;
    const turb::RgbaImage img = turbio::readImage(path, &info);
    if (k == 0) {
        ex.motion = turb::MotionSequence(img.width(), img.height());
        ex.colorSpace = img.colorSpace;
    } else if (img.width() != ex.motion.width() || img.height() != ex.motion.height()) {
        throw turb::IoError(path + ": " + sizeText(img.width(), img.height()) + ", but the first exemplar frame is " +
                            sizeText(ex.motion.width(), ex.motion.height()));
    }
    turb::ChannelImage mask;
    std::string maskPath = path;
    if (files.masks) {
        maskPath = ExemplarFiles::pathIn(*files.masks, k);
        mask = maskOf(turbio::readImage(maskPath), 0);
    } else if (info.hasAlpha) {
        mask = maskOf(img, 3);
    } else {
        throw turb::IoError(path + ": the exemplar has no alpha channel; give its masks with --exemplar-mask");
    }
    if (!mask.sameSize(turb::channelOf(img, 0)))
        throw turb::IoError(maskPath + ": the mask (" + sizeText(mask.width(), mask.height()) + ") and " + path + " (" +
                            sizeText(img.width(), img.height()) + ") differ in size");
    turb::ChannelImage flow;
    if (files.flows) {
        const std::string fp = ExemplarFiles::pathIn(*files.flows, k);
        flow = flowImage(fp);
        if (!flow.sameSize(mask))
            throw turb::IoError(fp + ": the flow and the exemplar frame " + path + " differ in size");
    }
    ex.rgb.push_back(turb::channelRange(turb::toChannels(img), 0, 3));
    try {
        ex.motion.addFrame(mask, files.flows ? &flow : nullptr);
    } catch (const turb::ValueError& e) {
        throw turb::IoError(path + ": " + e.what(), e.settings());
    }
}

ExemplarVideo loadExemplar(const StylizeJob& a, bool estimateFlow)
{
    ExemplarVideo ex;
    if (a.exemplar.rfind("builtin:ink", 0) == 0) {
        ex = builtinInk(a.exemplar, estimateFlow);
    } else {
        const ExemplarFiles files = exemplarFiles(a, estimateFlow);
        ex.label = files.seq.pattern.str();
        for (size_t k = 0; k < files.frames.size(); ++k) addExemplarFrame(files, k, ex);
    }
    ex.motion.finish(a.fluidy.guides);
    return ex;
}

/// Reads every target frame: masks thresholded, flows given (a 2D flow, the cache's projected motion,
/// the scene's) or estimated from the masks.
turb::MotionSequence loadTarget(const TargetSource& src, const FluidymationJob& f)
{
    turb::MotionSequence seq;
    const bool useFlow = src.hasFlow() && !f.estimateFlow;
    for (size_t i = 0; i < src.frames().size(); ++i) {
        const std::unique_ptr<FrameProgress> progress =
            reporter().frameProgress(int(i), int(src.frames().size()), src.frames()[i]);
        progress->begin("reading target");
        const TargetFrame t = src.read(src.frames()[i]);
        if (i == 0) seq = turb::MotionSequence(t.alpha.width(), t.alpha.height());
        if (t.alpha.width() != seq.width() || t.alpha.height() != seq.height())
            throw turb::IoError(t.alphaName + ": " + sizeText(t.alpha.width(), t.alpha.height()) +
                                ", but the first target frame is " + sizeText(seq.width(), seq.height()));
        try {
            seq.addFrame(t.alpha, useFlow ? &t.motion : nullptr, f.maskThreshold);
        } catch (const turb::ValueError& e) {
            throw turb::IoError((useFlow ? t.motionName : t.alphaName) + ": " + e.what(), e.settings());
        }
        progress->clear();
    }
    long long masked = 0;
    for (int i = 0; i < seq.frames(); ++i) masked += seq.maskedPixels(i);
    if (masked == 0)
        throw turb::IoError(src.label() +
                            ": the target mask is empty in every frame (nothing reaches --mask-threshold " +
                            fmt("%g", f.maskThreshold) + ")");
    seq.finish(f.guides);
    return seq;
}

turb::Rgb hue(double t)
{
    const double h = 6.0 * (t - std::floor(t));
    const int k = int(h) % 6;
    const float fr = float(h - std::floor(h)), v = 0.92f, s = 0.75f, p = v * (1 - s), q = v * (1 - s * fr),
                u = v * (1 - s * (1 - fr));
    switch (k) {
    case 0: return {v, u, p};
    case 1: return {q, v, p};
    case 2: return {p, v, u};
    case 3: return {p, q, v};
    case 4: return {u, p, v};
    default: return {v, p, q};
    }
}

/// T^rot as colour: hue = theta, grey where no patch is centred.
turb::Image rotationPicture(const turb::ChannelImage& rot)
{
    turb::Image img(rot.width(), rot.height(), turb::Rgb(0.12f));
    for (int y = 0; y < rot.height(); ++y)
        for (int x = 0; x < rot.width(); ++x)
            if (rot.at(x, y, 1) > 0.5f) img.at(x, y) = hue(rot.at(x, y, 0) / 6.283185307179586);
    return img;
}

/// The NNF as colour: R = source x, G = source y, B = source frame, each over its range.
turb::Image nnfPicture(const turb::RotatedNnf& nnf, int sw, int sh, int frames)
{
    turb::Image img(nnf.width, nnf.height, turb::Rgb(0.0f));
    for (int y = 0; y < nnf.height; ++y)
        for (int x = 0; x < nnf.width; ++x) {
            const turb::PatchRef& m = nnf.match[size_t(y) * size_t(nnf.width) + size_t(x)];
            if (m.valid())
                img.at(x, y) = turb::Rgb(float(m.x) / float(std::max(1, sw - 1)),
                    float(m.y) / float(std::max(1, sh - 1)), float(m.frame) / float(std::max(1, frames - 1)));
        }
    return img;
}

nlohmann::json statsJson(const turb::FluidyStats& st)
{
    nlohmann::json j;
    j["size"] = {st.width, st.height};
    j["levels"] = st.levels;
    j["masked_pixels"] = st.maskedPixels;
    j["centres"] = st.centres;
    j["energy"] = {{"tex", st.energy.tex}, {"bound", st.energy.bound}, {"dir", st.energy.dir}, {"ext", st.energy.ext},
        {"temp", st.energy.temp}, {"uni", st.energy.uni}, {"total", st.energy.total()}};
    j["mean_abs_sin"] = st.meanAbsSin.value_or(-1.0); // -1: no moving pixels, as bench/fluidymation_plots.py reads it
    j["moving_pixels"] = st.movingPixels;
    j["speed_correlation"] = st.speedCorrelation;
    j["extent_correlation"] = st.extentCorrelation;
    if (st.stationaryChange) {
        j["stationary_change"] = *st.stationaryChange;
        j["stationary_pixels"] = st.stationaryPixels;
    }
    j["coverage"] = st.coverage;
    j["distinct_patches"] = st.distinctPatches;
    j["contrast_ratio"] = st.contrastRatio;
    j["mean_shift"] = st.meanShift;
    j["reused_fraction"] = st.reusedFraction;
    j["steps_s"] = {{"guides", st.secondsGuides}, {"search", st.secondsSearch}, {"vote", st.secondsVote},
        {"stats", st.secondsStats}};
    return j;
}

std::string humanLine(const turb::FluidyStats& st)
{
    if (st.maskedPixels == 0) return "empty mask: transparent";
    std::string s = std::to_string(st.maskedPixels) + " px, E " + fmt("%.2f", st.energy.total());
    if (st.meanAbsSin) s += fmt(", |sin| %.3f", *st.meanAbsSin);
    s += fmt(", speed corr %.2f", st.speedCorrelation) + fmt(", coverage %.1f%%", 100.0 * st.coverage) +
         fmt(", contrast %.2f", st.contrastRatio);
    if (st.stationaryChange) s += fmt(", still change %.4f", *st.stationaryChange);
    return s;
}

turb::Image previewSheet(const turb::ChannelImage& mask, const turb::ChannelImage& flow, const turb::FluidyFrame& out,
    const ExemplarVideo& ex, int frame, const turb::Image* render)
{
    const turb::Image m = turb::channelPicture(turb::toRgba(mask), 0);
    const turb::Image lic = motionPicture(flow);
    const turb::Image styl = turb::overBackground(out.image, turb::Rgb(0.95f));
    const turb::Image rot = rotationPicture(out.rotation);
    const turb::Image nnf = nnfPicture(out.nnf, ex.motion.width(), ex.motion.height(), ex.motion.frames());
    std::vector<turb::SheetCell> row{
        {&m, "target mask"}, {&lic, "flow (LIC)"}, {&styl, "stylized"}, {&rot, "T^rot (hue)"}, {&nnf, "NNF (x, y, i)"}};
    if (render) row.insert(row.begin(), {render, "cache render"});
    return turb::contactSheet({row}, {}, "fluidymation frame " + std::to_string(frame), 1);
}

void writeFloat(const std::string& path, const turb::RgbaImage& img, bool noClobber)
{
    turbio::ensureParentDirectory(path);
    turbio::ImageWriteOptions o;
    o.noClobber = noClobber;
    o.bits = turbio::PixelBits::Float;
    turbio::writeImage(path, img, o);
}

// --out-rot: R = theta (radians), G, B = cos, sin (0 where no patch is centred), A = 1: float EXR or TIFF.
std::string writeRotation(const StylizeJob& a, int fr, const turb::FluidyFrame& out)
{
    turb::RgbaImage rot(out.rotation.width(), out.rotation.height(), turb::Rgba(0, 0, 0, 1));
    for (size_t p = 0; p < rot.size(); ++p) {
        const float* r = out.rotation.pixel(p);
        rot.pixels()[p] = turb::Rgba(r[0], r[1] * std::cos(r[0]), r[1] * std::sin(r[0]), 1.0f);
    }
    const std::string path = turbio::FramePattern::parse(a.fluidy.outRot).format(fr);
    writeFloat(path, rot, a.noClobber);
    return path;
}

// --debug-nnf: nnf.####.exr: R = source frame (0-based), G = x, B = y, A = 1 where matched; nnf_theta: theta in R.
std::string writeNnf(const StylizeJob& a, int fr, const turb::FluidyFrame& out, const ExemplarVideo& ex)
{
    const int W = out.rotation.width(), H = out.rotation.height();
    turb::RgbaImage nnf(W, H, turb::Rgba(0, 0, 0, 0)), theta(W, H, turb::Rgba(0, 0, 0, 1));
    for (size_t p = 0; p < nnf.size(); ++p) {
        const turb::PatchRef& m = out.nnf.match[p];
        if (!m.valid()) continue;
        nnf.pixels()[p] = turb::Rgba(m.frame, m.x, m.y, 1.0f);
        const float t = float(turb::rotationAngle(m.rotation));
        theta.pixels()[p] = turb::Rgba(t, t, t, 1.0f);
    }
    const std::string base = a.fluidy.debugNnf + "/";
    writeFloat(turbio::FramePattern::parse(base + "nnf.####.exr").format(fr), nnf, a.noClobber);
    writeFloat(turbio::FramePattern::parse(base + "nnf_theta.####.exr").format(fr), theta, a.noClobber);
    turbio::writeImage(turbio::FramePattern::parse(base + "nnf_vis.####.png").format(fr),
        nnfPicture(out.nnf, ex.motion.width(), ex.motion.height(), ex.motion.frames()));
    return turbio::FramePattern::parse(base + "nnf.####.exr").format(fr);
}

// --preview: the frame's sheet, after the cache as preview renders it (through the same camera) for a cache target.
std::string writePreview(const StylizeJob& a, int fr, const turb::FluidyFrame& out, const ExemplarVideo& ex,
    const turb::MotionSequence& target, int index, const TargetSource& source)
{
    const std::string png = turbio::FramePattern::parse(a.preview + "/fluidymation.####.png").format(fr);
    turbio::ensureParentDirectory(png);
    std::optional<turb::Image> render;
    if (source.isCache()) render = cacheRender(source.read(fr), source);
    turbio::writeImage(
        png, previewSheet(target.mask(index), target.flow(index), out, ex, fr, render ? &*render : nullptr));
    return png;
}

/// Writes everything a frame asked for.
nlohmann::json writeFrame(const StylizeJob& a, int fr, const turb::FluidyFrame& out, const ExemplarVideo& ex,
    const turb::MotionSequence& target, int index, const TargetSource& source, const std::string& settings)
{
    nlohmann::json extra = statsJson(out.stats);
    const std::string outPath = turbio::FramePattern::parse(a.out).format(fr);
    turbio::ensureParentDirectory(outPath);
    turbio::ImageWriteOptions wo;
    wo.noClobber = a.noClobber;
    wo.metadata = frameMetadata("stylize", settings);
    turb::RgbaImage img = out.image;
    img.colorSpace = ex.colorSpace;
    turbio::writeImage(outPath, img, wo);
    extra["out"] = outPath;
    if (!a.fluidy.outRot.empty()) extra["rotation"] = writeRotation(a, fr, out);
    if (!a.fluidy.debugNnf.empty()) extra["nnf"] = writeNnf(a, fr, out, ex);
    if (!a.preview.empty()) extra["preview"] = writePreview(a, fr, out, ex, target, index, source);
    return extra;
}

// The target as the shared reader takes it: it knows a 2D target as --alpha/--flow.
StylizeJob targetArgsOf(const StylizeJob& a)
{
    const FluidymationJob& f = a.fluidy;
    if (!a.flow.empty() || !a.alpha.empty() || !a.exemplarAlpha.empty())
        throw turb::ValueError("--method fluidymation takes --target-mask/--target-flow and --exemplar-mask (not "
                               "--alpha, --flow, --exemplar-alpha)");
    const int kinds = int(!f.targetMask.empty()) + int(!a.cache.empty()) + int(!a.scene.empty());
    if (kinds != 1)
        throw turb::ValueError(
            "give one target: --target-mask [--target-flow] (2D), --cache (3D through --camera) or --scene");
    if (!f.targetFlow.empty() && f.targetMask.empty()) throw turb::ValueError("--target-flow needs --target-mask");
    StylizeJob targetArgs = a;
    targetArgs.alpha = f.targetMask;
    targetArgs.flow = f.targetFlow;
    return targetArgs;
}

std::unique_ptr<turb::Fluidymator> makeFluidymator(
    const FluidymationJob& f, const ExemplarVideo& ex, const turb::MotionSequence& tgt, const TargetSource& target)
{
    try {
        return std::make_unique<turb::Fluidymator>(f.settings, ex.rgb, ex.motion, tgt);
    } catch (const turb::ValueError& e) {
        throw turb::ValueError("exemplar " + ex.label + ", target " + target.label() + ": " + e.what(), e.settings());
    }
}

// The frames in order (each starts from the previous one's NNF), or with --dry-run the plan, once the solver is set up.
void fluidymateFrames(const StylizeJob& a, const TargetSource& target, const ExemplarVideo& ex,
    const turb::MotionSequence& tgt, const turbio::FramePattern& outPattern, StylizeRun& done)
{
    const std::unique_ptr<turb::Fluidymator> fl = makeFluidymator(a.fluidy, ex, tgt, target);
    logVerbose("levels " + std::to_string(fl->levels()) + ", extent units " + fmt("%.2f px", fl->extentScale()) +
               " (exemplar), " + fmt("%.2f px", fl->targetExtentScale()) + " (target)");
    std::vector<std::string> settings;
    const SkipPlan plan = planOutputFrames(a, target.frames(), outPattern, settings);
    if (a.dryRun) return printWouldWrite(a, target.frames(), outPattern); // the dry run's data
    lockOutputFrames(outPattern, plan.writing); // two tasks never write one frame (a second exits 75)
    reporter().runStarted("stylize fluidymation");
    const auto& frames = target.frames();
    for (size_t i = 0; i < plan.end; ++i) {
        const int fr = frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(int(i), int(frames.size()), fr);
        const turb::FluidyFrame out = fl->next(progress.get());
        if (plan.skipped(i)) {
            progress->clear();
            reporter().frameSkipped(fr, int(i), int(frames.size()), secondsSince(t0), outPattern.format(fr), true);
            ++done.framesSkipped;
            continue;
        }
        progress->begin("writing");
        const nlohmann::json extra = writeFrame(a, fr, out, ex, tgt, int(i), target, settings[i]);
        progress->clear();
        reporter().frameDone(FrameRecord{fr, int(i), int(frames.size()), secondsSince(t0),
            humanLine(out.stats) + " -> " + extra["out"].get<std::string>(), extra});
        ++done.framesWritten;
    }
    reporter().runFinished(0, nlohmann::json::object());
}

} // namespace

StylizeRun runFluidymation(const StylizeJob& job)
{
    StylizeRun done;
    StylizeJob a = job;
    FluidymationJob& f = a.fluidy;
    f.settings.seed = a.settings.seed;
    turb::validate(f.settings);
    checkOutputPatterns(a.out, f.outRot);
    const StylizeJob targetArgs = targetArgsOf(a);
    TargetSource target(targetArgs, true);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    checkFrameToken(outPattern, a.out, target.frames().size());
    target.validate2D(true);
    // Everything is read and checked before the first frame is written.
    const ExemplarVideo ex = loadExemplar(a, false);
    const turb::MotionSequence tgt = loadTarget(target, f);
    logInfo("stylize fluidymation: " + target.label() + (tgt.flowsEstimated() ? " (flow from the masks)" : "") +
            ", exemplar " + ex.label + " (" + std::to_string(ex.motion.frames()) + " frames " +
            sizeText(ex.motion.width(), ex.motion.height()) +
            (ex.motion.flowsEstimated() ? ", flow from the masks" : "") + "), " +
            std::to_string(target.frames().size()) + " frames");
    turb::withThreads(a.threads, [&] { fluidymateFrames(a, target, ex, tgt, outPattern, done); });
    return done;
}

} // namespace turb::run::detail
