// runAnimate's inputs (AnimateParts.h): the example video, the still and its flow design, the built-ins.
#include "AnimateParts.h"

#include <turb/run/CacheCamera.h>
#include <turb/run/Reporter.h>

#include <scenes/Animate2D.h>
#include <turb/CameraBridge.h>
#include <turb/Error.h>
#include <turb/Render.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

namespace turb::run {

namespace detail {

namespace {

std::vector<double> numbers(const std::string& s, char sep, size_t n, const std::string& what)
{
    std::vector<double> v;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, sep)) {
        try {
            size_t pos = 0;
            v.push_back(std::stod(item, &pos));
            if (pos != item.size()) throw std::invalid_argument(item);
        } catch (...) {
            v.clear();
            break;
        }
    }
    if (v.size() != n)
        throw turb::ValueError(
            what + ": '" + s + "' is not " + std::to_string(n) + " numbers separated by '" + sep + "'");
    return v;
}

/// "builtin:river[:WxH[xN]]" -> sizes; false when `text` is not a built-in.
bool builtin(const std::string& text, int& w, int& h, int& n)
{
    if (text.rfind("builtin:river", 0) != 0) return false;
    const size_t c = text.find(':', 8);
    if (c == std::string::npos) return true;
    const std::string spec = text.substr(c + 1);
    const size_t x = std::count(spec.begin(), spec.end(), 'x');
    const auto v = numbers(spec, 'x', x + 1, "built-in size");
    if (v.size() < 2 || v.size() > 3) throw turb::ValueError(text + ": the size is WxH or WxHxN");
    w = int(v[0]);
    h = int(v[1]);
    if (v.size() == 3) n = int(v[2]);
    return true;
}

// "builtin:river" names animate/river_strokes.json (or, for clone strokes, river_clone.json) in the first of the job's
// data folders that holds it.
std::string builtinStrokes(const AnimateJob& a, const std::string& name, const std::string& kind = "strokes")
{
    namespace fs = std::filesystem;
    const std::string file = "animate/" + name + "_" + kind + ".json";
    std::string tried;
    for (const std::string& dir : a.builtinDataDirs) {
        const fs::path d(dir);
        if (fs::exists(d / file)) return (d / file).string();
        tried += (tried.empty() ? "" : ", ") + (d / file).string();
    }
    throw turb::IoError("--" + std::string(kind == "strokes" ? "flow-strokes" : "clone-strokes") + " builtin:" + name +
                        ": no such built-in design (looked for " + tried + ")");
}

turb::ChannelImage rgbOfImage(const turb::RgbaImage& img)
{
    turb::ChannelImage c(img.width(), img.height(), 3);
    for (size_t i = 0; i < img.size(); ++i)
        for (int k = 0; k < 3; ++k) c.pixel(i)[k] = img.pixels()[i][k];
    return c;
}

turb::ChannelImage fromPicture(const turb::Image& img)
{
    turb::ChannelImage c(img.width(), img.height(), 3);
    for (int y = 0; y < img.height(); ++y)
        for (int x = 0; x < img.width(); ++x)
            for (int k = 0; k < 3; ++k) c.at(x, y, k) = img.at(x, y)[k];
    return c;
}

// A cache frame through the camera: its render, and its view (opacity and projected motion).
turb::CameraView viewCacheFrame(
    const AnimateJob& a, const turb::BridgeSettings& bridge, const std::string& path, int f, Example& ex)
{
    turbio::ReadOptions ro = a.read;
    ro.readExtras = false;
    ro.cropToSmoke = false; // the camera frames the cache's box: it must not change with the smoke
    const turb::Frame frame = turbio::readFrame(path, f, ro);
    turb::CameraView view;
    try {
        view = turb::viewThroughCamera(frame, bridge);
    } catch (const turb::ValueError& e) {
        throw turb::IoError(path + ": " + e.what(), e.settings());
    }
    turb::DensityRenderSettings dr;
    dr.camera = bridge.camera;
    dr.camera->width = view.alpha.width();
    dr.camera->height = view.alpha.height();
    dr.extinction = a.camera.extinction;
    dr.stepVoxels = a.camera.step;
    ex.frames.push_back(fromPicture(turb::renderDensity(frame.density, dr)));
    return view;
}

// A cache: renders through the camera are the frames; the opacity-weighted mean of the projected velocity is v.
void readCacheExample(const AnimateJob& a, const turbio::Sequence& seq, Example& ex)
{
    const turb::BridgeSettings bridge = bridgeSettings(a.camera);
    turb::ChannelImage num, den;
    for (int f : seq.frames) {
        const std::string path = seq.path(f);
        const turb::CameraView view = viewCacheFrame(a, bridge, path, f, ex);
        if (num.empty()) {
            num = turb::ChannelImage(view.alpha.width(), view.alpha.height(), 2);
            den = turb::ChannelImage(view.alpha.width(), view.alpha.height(), 1);
        } else if (!view.alpha.sameSize(den)) {
            throw turb::IoError(
                path + ": the camera image changed size (the cache's box changed); give --width and --height");
        }
        for (size_t i = 0; i < den.pixelCount(); ++i) {
            const float w = view.alpha.pixel(i)[0];
            num.pixel(i)[0] += w * view.motion.pixel(i)[0];
            num.pixel(i)[1] += w * view.motion.pixel(i)[1];
            den.pixel(i)[0] += w;
        }
    }
    for (size_t i = 0; i < den.pixelCount(); ++i) {
        const float w = den.pixel(i)[0];
        num.pixel(i)[0] = w > 1e-6f ? num.pixel(i)[0] / w : 0.0f;
        num.pixel(i)[1] = w > 1e-6f ? num.pixel(i)[1] / w : 0.0f;
    }
    ex.flow = std::move(num);
    ex.label += " (" + cameraName(a.camera.kind) + " camera)";
}

// An image sequence: headers first, so that a frame of another size stops the run before any pixel is read.
void readImageExample(const turbio::Sequence& seq, Example& ex)
{
    const turbio::ImageFileInfo first = turbio::inspectImage(seq.path(seq.frames.front()));
    for (int f : seq.frames) {
        const turbio::ImageFileInfo info = turbio::inspectImage(seq.path(f));
        if (info.width != first.width || info.height != first.height)
            throw turb::IoError(seq.path(f) + ": " + std::to_string(info.width) + "x" + std::to_string(info.height) +
                                ", but " + seq.path(seq.frames.front()) + " is " + std::to_string(first.width) + "x" +
                                std::to_string(first.height) + ": every example frame must have one size");
    }
    for (int f : seq.frames) ex.frames.push_back(rgbOfImage(turbio::readImage(seq.path(f))));
}

// The still's pixels and alpha: the file's, or the built-in river's (with its matte).
void readStill(const AnimateJob& a, Target& t)
{
    int bw = 320, bh = 240, bn = 0;
    if (builtin(a.target, bw, bh, bn)) {
        t.rgb = turb::scenes::riverStill(bw, bh, 2);
        t.matte = turb::scenes::riverMatte(bw, bh);
        t.colorSpace = "sRGB";
    } else {
        turbio::ImageFileInfo info;
        const turb::RgbaImage img = turbio::readImage(a.target, &info);
        t.rgb = rgbOfImage(img);
        t.colorSpace = img.colorSpace;
        if (info.hasAlpha)
            for (const auto& p : img.pixels()) t.alpha.push_back(p[3]);
    }
    t.label = a.target;
    if (t.alpha.empty()) t.alpha.assign(t.rgb.pixelCount(), 1.0f);
}

void readMatte(const AnimateJob& a, Target& t)
{
    const int W = t.rgb.width(), H = t.rgb.height();
    const turb::RgbaImage m = turbio::readImage(a.targetAlpha);
    if (m.width() != W || m.height() != H)
        throw turb::IoError(a.targetAlpha + ": the matte is " + std::to_string(m.width()) + "x" +
                            std::to_string(m.height()) + ", the target " + a.target + " is " + std::to_string(W) + "x" +
                            std::to_string(H));
    t.matte = turb::channelOf(m, 0);
    float mx = 0.0f;
    for (float v : t.matte->data()) mx = std::max(mx, v);
    if (!(mx > 0.0f)) throw turb::IoError(a.targetAlpha + ": the matte is empty (zero everywhere): nothing would move");
}

// A dense flow image of the still's size, finite everywhere.
turb::ChannelImage readDenseFlow(const AnimateJob& a, int W, int H)
{
    const turb::RgbaImage f = turbio::readImage(a.flow);
    if (f.width() != W || f.height() != H)
        throw turb::IoError(a.flow + ": the flow is " + std::to_string(f.width()) + "x" + std::to_string(f.height()) +
                            ", the target " + a.target + " is " + std::to_string(W) + "x" + std::to_string(H));
    turb::ChannelImage v(W, H, 2);
    for (size_t i = 0; i < f.size(); ++i) {
        v.pixel(i)[0] = f.pixels()[i][0];
        v.pixel(i)[1] = a.flowYUp ? -f.pixels()[i][1] : f.pixels()[i][1];
        if (!std::isfinite(v.pixel(i)[0]) || !std::isfinite(v.pixel(i)[1]))
            throw turb::IoError(a.flow + ": the flow holds NaN or Inf");
    }
    return v;
}

void readDesign(const AnimateJob& a, Target& t)
{
    if (a.strokes.empty() && a.flow.empty())
        throw turb::IoError(
            a.target + ": no flow design for the target: give --flow-strokes FILE.json or --flow IMAGE");
    if (!a.strokes.empty() && !a.flow.empty()) throw turb::ValueError("give --flow-strokes or --flow, not both");
    const int W = t.rgb.width(), H = t.rgb.height();
    if (!a.strokes.empty()) {
        const bool isBuiltin = a.strokes.rfind("builtin:", 0) == 0;
        t.strokes = turbio::readFlowStrokes(isBuiltin ? builtinStrokes(a, a.strokes.substr(8)) : a.strokes, W, H);
    } else {
        t.flow = readDenseFlow(a, W, H);
    }
}

turb::RgbaImage opaqueRgba(const turb::ChannelImage& c)
{
    turb::RgbaImage r(c.width(), c.height());
    for (size_t i = 0; i < r.size(); ++i)
        r.pixels()[i] =
            turb::Rgba(c.pixel(i)[0], c.pixel(i)[c.channels() > 1 ? 1 : 0], c.pixel(i)[c.channels() > 2 ? 2 : 0], 1.0f);
    r.colorSpace = "sRGB";
    return r;
}

} // namespace

Example readExample(const AnimateJob& a, int tau)
{
    Example ex;
    const int sources = int(!a.example.empty()) + int(!a.exampleCache.empty());
    if (sources != 1)
        throw turb::ValueError(
            "give one video example: --example PATTERN (images) or --example-cache PATTERN (VDB through --camera)");
    int bw = 320, bh = 240, bn = 60;
    if (!a.example.empty() && builtin(a.example, bw, bh, bn)) {
        ex.frames = turb::scenes::riverExample({bw, bh, bn, 1, 1.0});
        ex.label = a.example;
        for (int i = 0; i < bn; ++i) ex.numbers.push_back(i + 1);
        return ex;
    }
    const turbio::Sequence seq = turbio::resolveSequence(a.example.empty() ? a.exampleCache : a.example, a.frames);
    if (!seq.missing.empty())
        throw turb::IoError(
            seq.path(seq.missing.front()) + ": missing (frames " + turbio::formatFrameList(seq.missing) + ")");
    ex.label = seq.pattern.str();
    ex.numbers = seq.frames;
    if (int(seq.frames.size()) < tau + 2)
        throw turb::IoError(seq.pattern.str() + ": the video example has " + std::to_string(seq.frames.size()) +
                            " frame" + (seq.frames.size() == 1 ? "" : "s") + "; tau = " + std::to_string(tau) +
                            " needs at least tau + 2 = " + std::to_string(tau + 2));
    if (!a.example.empty()) readImageExample(seq, ex);
    else readCacheExample(a, seq, ex);
    return ex;
}

Target readTarget(const AnimateJob& a)
{
    Target t;
    if (a.target.empty()) throw turb::ValueError("give the still to animate: --target IMAGE");
    readStill(a, t);
    if (!a.targetAlpha.empty()) readMatte(a, t);
    readDesign(a, t);
    return t;
}

void readClones(const AnimateJob& a, const Example& example, Target& target)
{
    if (a.cloneStrokes.empty()) return;
    const bool isBuiltin = a.cloneStrokes.rfind("builtin:", 0) == 0;
    const std::string path = isBuiltin ? builtinStrokes(a, a.cloneStrokes.substr(8), "clone") : a.cloneStrokes;
    const turb::ChannelImage& f = example.frames.front();
    target.clones = turbio::readCloneStrokes(path, f.width(), f.height(), target.rgb.width(), target.rgb.height());
}

void configure(AnimateJob& a)
{
    turb::AnimateSettings& s = a.settings;
    s.refineFlow = a.refine == AnimateRefine::On || (a.refine == AnimateRefine::Auto && a.flow.empty());
    s.histogramMatch = a.hm != AnimateHm::Off;
    s.hm.pyramid = a.hm == AnimateHm::Laplacian ? turb::HmPyramid::Laplacian : turb::HmPyramid::Steerable;
    if (a.hmGrid == "off") {
        s.hm.gridCols = s.hm.gridRows = 1;
    } else if (a.hmGrid != "auto") {
        const auto v = numbers(a.hmGrid, 'x', 2, "--hm-grid"); // checked while parsing (hmGridProblem)
        s.hm.gridCols = int(v[0]);
        s.hm.gridRows = int(v[1]);
    }
    turb::validate(s);
}

void exportBuiltin(const AnimateJob& a)
{
    int w = 320, h = 240, n = 60;
    if (!builtin(a.example.empty() ? "builtin:river" : a.example, w, h, n))
        throw turb::ValueError("--export-builtin needs --example builtin:river[:WxHxN] (or none)");
    int tw = w, th = h, tn = 0;
    if (!a.target.empty() && !builtin(a.target, tw, th, tn))
        throw turb::ValueError("--export-builtin: --target must be builtin:river[:WxH] (or none)");
    const std::string dir = a.exportBuiltin;
    const auto frames = turb::scenes::riverExample({w, h, n, 1, 1.0});
    turbio::ImageWriteOptions o;
    o.alpha = false;
    o.noClobber = a.noClobber;
    const turbio::FramePattern pat = turbio::FramePattern::parse(dir + "/river.####.png");
    turbio::ensureParentDirectory(pat.format(1));
    for (int i = 0; i < n; ++i) turbio::writeImage(pat.format(i + 1), opaqueRgba(frames[size_t(i)]), o);
    turbio::writeImage(dir + "/still.png", opaqueRgba(turb::scenes::riverStill(tw, th, 2)), o);
    turbio::writeImage(dir + "/matte.png", opaqueRgba(turb::scenes::riverMatte(tw, th)), o);
    logInfo("animate: wrote " + std::to_string(n) + " example frames " + pat.str() + ", " + dir + "/still.png and " +
            dir + "/matte.png");
}

} // namespace detail

std::string hmGridProblem(const std::string& grid)
{
    if (grid == "auto" || grid == "off") return {};
    try {
        const auto n = detail::numbers(grid, 'x', 2, "--hm-grid");
        if (n[0] < 1 || n[1] < 1 || n[0] != std::floor(n[0]) || n[1] != std::floor(n[1]))
            return "cells per axis must be whole numbers >= 1";
    } catch (const turb::ValueError& e) {
        return e.what();
    }
    return {};
}

} // namespace turb::run
