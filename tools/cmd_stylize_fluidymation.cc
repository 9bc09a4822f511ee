// vdbturb stylize --method fluidymation: moving exemplars (Fluidymation).
#include "Console.h"
#include "RunReport.h"
#include "StylizeCommon.h"

#include <scenes/Ink2D.h>
#include <turb/Error.h>
#include <turb/Fluidymation.h>
#include <turb/Parallel.h>
#include <turb/Render.h>
#include <turbio/ImageIO.h>

#include <algorithm>
#include <cmath>
#include <memory>

namespace vdbturb::stylize {

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

ExemplarVideo loadExemplar(const StylizeArgs& a, bool estimateFlow)
{
    const FluidyArgs& f = a.fluidy;
    ExemplarVideo ex;
    if (a.exemplar.rfind("builtin:ink", 0) == 0) {
        const turb::scenes::InkSettings s = parseInk(a.exemplar);
        turb::scenes::InkSequence ink = turb::scenes::inkExemplar(s);
        ex.label = "builtin:ink:" + sizeText(s.width, s.height) + "x" + std::to_string(s.frames);
        ex.colorSpace = "sRGB";
        ex.motion = turb::MotionSequence(s.width, s.height);
        for (int i = 0; i < s.frames; ++i) {
            ex.rgb.push_back(turb::channelRange(turb::toChannels(ink.rgb[size_t(i)]), 0, 3));
            ex.motion.addFrame(ink.mask[size_t(i)], estimateFlow ? nullptr : &ink.flow[size_t(i)]);
        }
    } else {
        const turbio::Sequence seq = turbio::resolveSequence(a.exemplar);
        if (!seq.missing.empty()) throw turb::IoError(seq.path(seq.missing.front()) + ": missing exemplar frame");
        std::vector<int> frames = seq.frames.empty() ? std::vector<int>{0} : seq.frames;
        ex.label = seq.pattern.str();
        std::optional<turbio::Sequence> masks, flows;
        if (!f.exemplarMask.empty()) masks = turbio::resolveSequence(f.exemplarMask);
        if (!f.exemplarFlow.empty() && !estimateFlow) flows = turbio::resolveSequence(f.exemplarFlow);
        for (const auto* s : {&masks, &flows}) {
            if (!*s) continue;
            if (!(*s)->missing.empty()) throw turb::IoError((*s)->path((*s)->missing.front()) + ": missing");
            const size_t n = (*s)->frames.empty() ? 1 : (*s)->frames.size();
            if (n != frames.size())
                throw turb::IoError((*s)->pattern.str() + ": " + std::to_string(n) +
                                    (s == &masks ? " masks" : " flows") + " but the exemplar " + ex.label + " has " +
                                    std::to_string(frames.size()) + " frames (the counts must match)");
        }
        for (size_t k = 0; k < frames.size(); ++k) {
            const std::string path = seq.frames.empty() ? seq.pattern.str() : seq.path(frames[k]);
            turbio::ImageFileInfo info;
            const turb::RgbaImage img = turbio::readImage(path, &info);
            if (k == 0) {
                ex.motion = turb::MotionSequence(img.width(), img.height());
                ex.colorSpace = img.colorSpace;
            } else if (img.width() != ex.motion.width() || img.height() != ex.motion.height()) {
                throw turb::IoError(path + ": " + sizeText(img.width(), img.height()) +
                                    ", but the first exemplar frame is " +
                                    sizeText(ex.motion.width(), ex.motion.height()));
            }
            turb::ChannelImage mask;
            std::string maskPath = path;
            if (masks) {
                maskPath = masks->frames.empty() ? masks->pattern.str() : masks->path(masks->frames[k]);
                mask = maskOf(turbio::readImage(maskPath), 0);
            } else if (info.hasAlpha) {
                mask = maskOf(img, 3);
            } else {
                throw turb::IoError(path + ": the exemplar has no alpha channel; give its masks with --exemplar-mask");
            }
            if (!mask.sameSize(turb::channelOf(img, 0)))
                throw turb::IoError(maskPath + ": the mask (" + sizeText(mask.width(), mask.height()) + ") and " +
                                    path + " (" + sizeText(img.width(), img.height()) + ") differ in size");
            turb::ChannelImage flow;
            if (flows) {
                const std::string fp = flows->frames.empty() ? flows->pattern.str() : flows->path(flows->frames[k]);
                flow = flowImage(fp);
                if (!flow.sameSize(mask))
                    throw turb::IoError(fp + ": the flow and the exemplar frame " + path + " differ in size");
            }
            ex.rgb.push_back(turb::channelRange(turb::toChannels(img), 0, 3));
            try {
                ex.motion.addFrame(mask, flows ? &flow : nullptr);
            } catch (const turb::ValueError& e) {
                throw turb::IoError(path + ": " + e.what(), e.settings());
            }
        }
    }
    ex.motion.finish(a.fluidy.guides);
    return ex;
}

/// Reads every target frame: masks thresholded, flows given (a 2D flow, the cache's projected motion,
/// the scene's) or estimated from the masks.
turb::MotionSequence loadTarget(const TargetSource& src, const FluidyArgs& f)
{
    turb::MotionSequence seq;
    const bool useFlow = src.hasFlow() && !f.estimateFlow;
    for (size_t i = 0; i < src.frames().size(); ++i) {
        ConsoleProgress progress(int(i), int(src.frames().size()), src.frames()[i]);
        progress.begin("reading target");
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
        progress.clear();
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

/// Writes everything a frame asked for.
nlohmann::json writeFrame(const StylizeArgs& a, int fr, const turb::FluidyFrame& out, const ExemplarVideo& ex,
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
    const int W = out.rotation.width(), H = out.rotation.height();
    if (!a.fluidy.outRot.empty()) {
        // R = theta (radians), G, B = cos, sin (0 where no patch is centred), A = 1: float EXR or TIFF.
        turb::RgbaImage rot(W, H, turb::Rgba(0, 0, 0, 1));
        for (size_t p = 0; p < rot.size(); ++p) {
            const float* r = out.rotation.pixel(p);
            rot.pixels()[p] = turb::Rgba(r[0], r[1] * std::cos(r[0]), r[1] * std::sin(r[0]), 1.0f);
        }
        const std::string path = turbio::FramePattern::parse(a.fluidy.outRot).format(fr);
        writeFloat(path, rot, a.noClobber);
        extra["rotation"] = path;
    }
    if (!a.fluidy.debugNnf.empty()) {
        // nnf.####.exr: R = source frame (0-based), G = x, B = y, A = 1 where matched; nnf_theta: theta in R.
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
        extra["nnf"] = turbio::FramePattern::parse(base + "nnf.####.exr").format(fr);
    }
    if (!a.preview.empty()) {
        const std::string png = turbio::FramePattern::parse(a.preview + "/fluidymation.####.png").format(fr);
        turbio::ensureParentDirectory(png);
        std::optional<turb::Image> render;
        if (source.isCache()) { // the cache as preview renders it, through the same camera
            const TargetFrame t = source.read(fr);
            turb::DensityRenderSettings dr;
            dr.camera = source.bridge().camera;
            dr.camera->width = t.alpha.width();
            dr.camera->height = t.alpha.height();
            dr.extinction = source.bridge().extinction;
            render = turb::renderDensity(t.cacheFrame->density, dr);
        }
        turbio::writeImage(
            png, previewSheet(target.mask(index), target.flow(index), out, ex, fr, render ? &*render : nullptr));
        extra["preview"] = png;
    }
    return extra;
}

} // namespace

void addFluidymationOptions(CLI::App* app, StylizeArgs& a)
{
    FluidyArgs& f = a.fluidy;
    turb::FluidySettings& s = f.settings;
    const std::string m = "[fluidymation] ";
    app->add_option(
        "--exemplar-mask", f.exemplarMask, m + "Binary masks of the exemplar frames (empty: the exemplar's alpha)");
    app->add_option("--target-mask", f.targetMask, m + "Binary target masks (#### sequence): the 2D target");
    const auto knob = [app, &m](const std::string& names, auto& v, const std::string& help, const std::string& key) {
        return setting(app->add_option(names, v, m + help), key);
    };
    knob("--exemplar-flow", f.exemplarFlow, "Exemplar flows, R,G in pixels per frame (empty: estimated from the masks)",
        "exemplar-flow");
    knob("--target-flow", f.targetFlow, "Target flows, R,G in pixels per frame (empty: estimated from the masks)",
        "target-flow");
    knob("--mask-threshold", f.maskThreshold, "Target alpha / rendered opacity at or above this is inside the mask",
        "mask-threshold")
        ->check(finiteIn(0.001, 1.0));
    setting(app->add_flag("--estimate-flow", f.estimateFlow,
                m + "Estimate the target's flow from its masks even when one is given"),
        "estimate-flow");
    knob("--out-rot", f.outRot, "Write T^rot per frame: float EXR/TIFF, R = theta (radians), G, B = cos, sin",
        "out-rot");
    knob("--debug-nnf", f.debugNnf,
        "Write the NNF per frame into DIR: nnf.####.exr (R = frame, G = x, B = y), nnf_theta, nnf_vis", "debug-nnf");
    // turb::FluidySettings under its field names (Table 1's values are the defaults; docs/fluidymation.md).
    knob("--n,--fluidy.patchSize", s.patchSize, "Patch size n", "fluidy.patchSize")->check(CLI::Range(3, 15));
    knob("--b,--fluidy.boundaryBlur", s.boundaryBlur, "Boundary blur radius b in pixels (sigma = b/3)",
        "fluidy.boundaryBlur")
        ->check(finiteIn(0.1, 1000.0));
    knob("--r,--fluidy.cuboidFrames", s.cuboidFrames,
        "Occurrence cuboid half-length r in frames (the exemplar needs 2r+1)", "fluidy.cuboidFrames")
        ->check(CLI::Range(0, 50));
    knob("--w-bound,--fluidy.wBound", s.wBound, "w^bound (0 = ablation)", "fluidy.wBound")->check(finiteIn(0.0));
    knob("--w-ext,--fluidy.wExt", s.wExt, "w^ext", "fluidy.wExt")->check(finiteIn(0.0));
    knob("--w-dir,--fluidy.wDir", s.wDir, "w^dir", "fluidy.wDir")->check(finiteIn(0.0));
    knob("--w-temp,--fluidy.wTemp", s.wTemp, "w^temp", "fluidy.wTemp")->check(finiteIn(0.0));
    knob("--w-uni,--fluidy.wUni", s.wUni, "w^uni", "fluidy.wUni")->check(finiteIn(0.0));
    knob("--m-lower,--fluidy.mLower", s.mLower, "m_l as a fraction of the target's larger side", "fluidy.mLower")
        ->check(finiteIn(0.0, 10.0));
    knob("--m-upper,--fluidy.mUpper", s.mUpper, "m_u as a fraction of the target's larger side", "fluidy.mUpper")
        ->check(finiteIn(0.0, 10.0));
    knob("--dir-clamp,--fluidy.dirClamp", s.dirClamp, "Clamp of |tan| in D^dir", "fluidy.dirClamp")
        ->check(finitePositive());
    knob("--extent-scale,--fluidy.extentScale", s.extentScale,
        "The exemplar's D^ext unit in pixels (0 = its 95th percentile)", "fluidy.extentScale")
        ->check(finiteIn(0.0));
    knob("--target-extent-scale,--fluidy.targetExtentScale", s.targetExtentScale,
        "The target's D^ext unit in pixels (0 = its own 95th percentile)", "fluidy.targetExtentScale")
        ->check(finiteIn(0.0));
    knob("--fluidy-levels,--fluidy.levels", s.levels, "Pyramid levels (0 = floor(log2(d_min / n)))", "fluidy.levels")
        ->check(CLI::Range(0, 8));
    knob(
        "--fluidy-iterations,--fluidy.iterations", s.iterations, "EM iterations on coarser levels", "fluidy.iterations")
        ->check(CLI::Range(1, 50));
    knob("--fluidy-fine-iterations,--fluidy.fineIterations", s.fineIterations, "EM iterations on the finest level",
        "fluidy.fineIterations")
        ->check(CLI::Range(1, 50));
    knob("--fluidy-sweeps,--fluidy.sweeps", s.sweeps, "PatchMatch sweeps per E-step on coarser levels", "fluidy.sweeps")
        ->check(CLI::Range(1, 32));
    knob("--fluidy-fine-sweeps,--fluidy.fineSweeps", s.fineSweeps, "PatchMatch sweeps per E-step on the finest level",
        "fluidy.fineSweeps")
        ->check(CLI::Range(1, 32));
    boolSetting(app, "--fluidy.reusePrevious", s.reusePrevious,
        m + "Start each frame from the previous one's NNF (false: random)", "fluidy.reusePrevious");
    legacy(app->add_flag_function(
               "--no-reuse", [&s](int64_t) { s.reusePrevious = false; }, "fluidy.reusePrevious = false"),
        "fluidy.reusePrevious", "false");
}

namespace {

// The target as the shared reader takes it: it knows a 2D target as --alpha/--flow.
StylizeArgs targetArgsOf(const StylizeArgs& a)
{
    const FluidyArgs& f = a.fluidy;
    if (!a.flow.empty() || !a.alpha.empty() || !a.exemplarAlpha.empty())
        throw turb::ValueError("--method fluidymation takes --target-mask/--target-flow and --exemplar-mask (not "
                               "--alpha, --flow, --exemplar-alpha)");
    const int kinds = int(!f.targetMask.empty()) + int(!a.cache.empty()) + int(!a.scene.empty());
    if (kinds != 1)
        throw turb::ValueError(
            "give one target: --target-mask [--target-flow] (2D), --cache (3D through --camera) or --scene");
    if (!f.targetFlow.empty() && f.targetMask.empty()) throw turb::ValueError("--target-flow needs --target-mask");
    StylizeArgs targetArgs = a;
    targetArgs.alpha = f.targetMask;
    targetArgs.flow = f.targetFlow;
    return targetArgs;
}

// The frames in order (each starts from the previous one's NNF), or with --dry-run the plan, once the solver is set up.
void fluidymateFrames(const StylizeArgs& a, const TargetSource& target, const ExemplarVideo& ex,
    const turb::MotionSequence& tgt, const turbio::FramePattern& outPattern)
{
    std::unique_ptr<turb::Fluidymator> fl;
    try {
        fl = std::make_unique<turb::Fluidymator>(a.fluidy.settings, ex.rgb, ex.motion, tgt);
    } catch (const turb::ValueError& e) {
        throw turb::ValueError("exemplar " + ex.label + ", target " + target.label() + ": " + e.what(), e.settings());
    }
    logVerbose("levels " + std::to_string(fl->levels()) + ", extent units " + fmt("%.2f px", fl->extentScale()) +
               " (exemplar), " + fmt("%.2f px", fl->targetExtentScale()) + " (target)");
    std::vector<std::string> settings;
    const SkipPlan plan = planOutputFrames(a, target.frames(), outPattern, settings);
    if (globals().dryRun) {
        // The plan is the dry run's data: stdout, as transfer's "would write" lines.
        if (!a.skipExisting)
            for (int fr : target.frames())
                printData("would write " + outPattern.format(fr) + " (frame " + std::to_string(fr) + ")");
        return;
    }
    lockOutputFrames(outPattern, plan.writing); // two tasks never write one frame (a second exits 75)
    RunReport report("stylize fluidymation", a.json);
    const auto& frames = target.frames();
    for (size_t i = 0; i < plan.end; ++i) {
        const int fr = frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        ConsoleProgress progress(int(i), int(frames.size()), fr);
        const turb::FluidyFrame out = fl->next(&progress);
        if (plan.skipped(i)) {
            progress.clear();
            report.frameSkipped(fr, int(i), int(frames.size()), secondsSince(t0), outPattern.format(fr), true);
            continue;
        }
        progress.begin("writing");
        const nlohmann::json extra = writeFrame(a, fr, out, ex, tgt, int(i), target, settings[i]);
        progress.clear();
        report.frameDone(fr, int(i), int(frames.size()), secondsSince(t0),
            humanLine(out.stats) + " -> " + extra["out"].get<std::string>(), extra);
    }
    report.finish();
}

} // namespace

int runFluidymation(StylizeArgs& a)
{
    FluidyArgs& f = a.fluidy;
    f.settings.seed = a.settings.seed;
    turb::validate(f.settings);
    if (const int rc = checkOutputPatterns(a.out, f.outRot); rc != kOk) return rc;
    const StylizeArgs targetArgs = targetArgsOf(a);
    TargetSource target(targetArgs, true);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    if (!outPattern.numbered() && target.frames().size() > 1)
        throw UsageError("--out " + a.out + " has no frame token (####) but there are " +
                         std::to_string(target.frames().size()) + " frames");
    target.validate2D(true);

    // Everything is read and checked before the first frame is written.
    const ExemplarVideo ex = loadExemplar(a, false);
    const turb::MotionSequence tgt = loadTarget(target, f);
    logInfo("stylize fluidymation: " + target.label() + (tgt.flowsEstimated() ? " (flow from the masks)" : "") +
            ", exemplar " + ex.label + " (" + std::to_string(ex.motion.frames()) + " frames " +
            sizeText(ex.motion.width(), ex.motion.height()) +
            (ex.motion.flowsEstimated() ? ", flow from the masks" : "") + "), " +
            std::to_string(target.frames().size()) + " frames");
    turb::withThreads(globals().threads, [&] { fluidymateFrames(a, target, ex, tgt, outPattern); });
    return kOk;
}

} // namespace vdbturb::stylize
