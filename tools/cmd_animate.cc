// vdbturb animate: animate a still picture of fluid from a video example (Okabe et al. 2009).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"
#include "StylizeCommon.h"

#include <scenes/Animate2D.h>
#include <turb/Animate.h>
#include <turb/AnimateQuality.h>
#include <turb/CameraBridge.h>
#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Render.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/Strokes.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>

namespace vdbturb {

namespace {

enum class Refine { Auto, On, Off };
enum class HmMode { Steerable, Laplacian, Off };

struct AnimateArgs
{
    std::string example, exampleCache, frames;
    stylize::CameraArgs camera;
    std::string target, targetAlpha;
    std::string strokes, flow;
    bool flowYUp = false;
    Refine refine = Refine::Auto; ///< auto: a stroke design is refined, a dense --flow is not
    HmMode hm = HmMode::Steerable;
    std::string hmGrid = "auto";
    std::string out, dump, sheet, exportBuiltin;
    int start = 1;
    bool json = false, noClobber = false, measure = false;
    bool skipExisting = false;
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
    turbio::ReadOptions read;
    turb::AnimateSettings settings;
};

// "builtin:river" names scenes/animate/river_strokes.json: in PREFIX/share/vdbturb/animate beside an installed
// binary (found from /proc/self/exe, so a moved prefix works); the binary in the build tree reads the source tree.
std::string builtinStrokes(const std::string& name)
{
    namespace fs = std::filesystem;
    const std::string file = "animate/" + name + "_strokes.json";
    std::vector<fs::path> dirs;
    std::error_code ec;
    const fs::path exeDir = fs::read_symlink("/proc/self/exe", ec).parent_path();
    if (!ec && fs::equivalent(exeDir, VDBTURB_BUILD_BIN_DIR, ec)) {
        dirs.emplace_back(VDBTURB_SOURCE_DATA_DIR);
    } else if (!exeDir.empty()) {
        fs::path prefix = exeDir;
        for (const auto& part : fs::path(VDBTURB_INSTALL_BIN_DIR))
            if (!part.empty()) prefix = prefix.parent_path();
        dirs.push_back(prefix / VDBTURB_INSTALL_DATA_DIR);
    }
    std::string tried;
    for (const fs::path& d : dirs) {
        if (fs::exists(d / file)) return (d / file).string();
        tried += (tried.empty() ? "" : ", ") + (d / file).string();
    }
    throw turb::IoError("--flow-strokes builtin:" + name + ": no such built-in design (looked for " + tried + ")");
}

std::string fmt(const char* f, double v)
{
    char b[64];
    std::snprintf(b, sizeof(b), f, v);
    return b;
}

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

// ---------------------------------------------------------------------------------------------
// The example video: an image sequence, a VDB cache through a camera, or the built-in river.

struct Example
{
    std::vector<turb::ChannelImage> frames;
    std::optional<turb::ChannelImage> flow; // a cache's opacity-weighted projected motion
    std::string label;
    std::vector<int> numbers;
};

// A cache: renders through the camera are the frames; the opacity-weighted mean of the projected velocity is v.
void readCacheExample(const AnimateArgs& a, const turbio::Sequence& seq, Example& ex)
{
    const turb::BridgeSettings bridge = stylize::bridgeSettings(a.camera);
    turbio::ReadOptions ro = a.read;
    ro.readExtras = false;
    ro.cropToSmoke = false; // the camera frames the cache's box: it must not change with the smoke
    turb::ChannelImage num, den;
    for (int f : seq.frames) {
        const std::string path = seq.path(f);
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
    ex.label += " (" + stylize::cameraName(a.camera.kind) + " camera)";
}

Example readExample(const AnimateArgs& a, int tau)
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
    if (!a.example.empty()) {
        // Headers first: a frame of another size stops the run before any pixel is read.
        const turbio::ImageFileInfo first = turbio::inspectImage(seq.path(seq.frames.front()));
        for (int f : seq.frames) {
            const turbio::ImageFileInfo info = turbio::inspectImage(seq.path(f));
            if (info.width != first.width || info.height != first.height)
                throw turb::IoError(seq.path(f) + ": " + std::to_string(info.width) + "x" +
                                    std::to_string(info.height) + ", but " + seq.path(seq.frames.front()) + " is " +
                                    std::to_string(first.width) + "x" + std::to_string(first.height) +
                                    ": every example frame must have one size");
        }
        for (int f : seq.frames) ex.frames.push_back(rgbOfImage(turbio::readImage(seq.path(f))));
        return ex;
    }
    readCacheExample(a, seq, ex);
    return ex;
}

// ---------------------------------------------------------------------------------------------
// The target and its flow design.

struct Target
{
    turb::ChannelImage rgb;
    std::vector<float> alpha; // output alpha per pixel (the still's own, 1 without one)
    std::optional<turb::ChannelImage> matte;
    std::string colorSpace, label;
    std::optional<turbio::StrokeFile> strokes;
    std::optional<turb::ChannelImage> flow;
};

Target readTarget(const AnimateArgs& a)
{
    Target t;
    if (a.target.empty()) throw turb::ValueError("give the still to animate: --target IMAGE");
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
    const int W = t.rgb.width(), H = t.rgb.height();
    if (!a.targetAlpha.empty()) {
        const turb::RgbaImage m = turbio::readImage(a.targetAlpha);
        if (m.width() != W || m.height() != H)
            throw turb::IoError(a.targetAlpha + ": the matte is " + std::to_string(m.width()) + "x" +
                                std::to_string(m.height()) + ", the target " + a.target + " is " + std::to_string(W) +
                                "x" + std::to_string(H));
        t.matte = turb::channelOf(m, 0);
        float mx = 0.0f;
        for (float v : t.matte->data()) mx = std::max(mx, v);
        if (!(mx > 0.0f))
            throw turb::IoError(a.targetAlpha + ": the matte is empty (zero everywhere): nothing would move");
    }
    if (a.strokes.empty() && a.flow.empty())
        throw turb::IoError(
            a.target + ": no flow design for the target: give --flow-strokes FILE.json or --flow IMAGE");
    if (!a.strokes.empty() && !a.flow.empty()) throw turb::ValueError("give --flow-strokes or --flow, not both");
    if (!a.strokes.empty()) {
        const bool builtin = a.strokes.rfind("builtin:", 0) == 0;
        t.strokes = turbio::readFlowStrokes(builtin ? builtinStrokes(a.strokes.substr(8)) : a.strokes, W, H);
    } else {
        const turb::RgbaImage f = turbio::readImage(a.flow);
        if (f.width() != W || f.height() != H)
            throw turb::IoError(a.flow + ": the flow is " + std::to_string(f.width()) + "x" +
                                std::to_string(f.height()) + ", the target " + a.target + " is " + std::to_string(W) +
                                "x" + std::to_string(H));
        turb::ChannelImage v(W, H, 2);
        for (size_t i = 0; i < f.size(); ++i) {
            v.pixel(i)[0] = f.pixels()[i][0];
            v.pixel(i)[1] = a.flowYUp ? -f.pixels()[i][1] : f.pixels()[i][1];
            if (!std::isfinite(v.pixel(i)[0]) || !std::isfinite(v.pixel(i)[1]))
                throw turb::IoError(a.flow + ": the flow holds NaN or Inf");
        }
        t.flow = std::move(v);
    }
    return t;
}

// ---------------------------------------------------------------------------------------------
// Pictures: --dump and --sheet.

turb::Image picture(const turb::ChannelImage& img)
{
    turb::Image p(img.width(), img.height());
    for (int y = 0; y < img.height(); ++y)
        for (int x = 0; x < img.width(); ++x) {
            const float* v = img.pixel(x, y);
            const int C = img.channels();
            p.at(x, y) = turb::Rgb(std::clamp(v[0], 0.0f, 1.0f), std::clamp(v[std::min(1, C - 1)], 0.0f, 1.0f),
                std::clamp(v[std::min(2, C - 1)], 0.0f, 1.0f));
        }
    return p;
}

/// A signed image as grey around 0.5 (+-range maps to 0..1), luminance of its channels.
turb::Image signedPicture(const turb::ChannelImage& img, float range)
{
    const turb::ChannelImage y = turb::luminance(img);
    turb::Image p(img.width(), img.height());
    for (int yy = 0; yy < img.height(); ++yy)
        for (int x = 0; x < img.width(); ++x)
            p.at(x, yy) = turb::Rgb(std::clamp(0.5f + 0.5f * y.at(x, yy, 0) / range, 0.0f, 1.0f));
    return p;
}

/// A 2D flow as line integral convolution, tinted by speed (black..0.5 * max).
turb::Image flowPicture(const turb::ChannelImage& m)
{
    const int W = m.width(), H = m.height();
    turb::VectorField v(
        turb::CoordBBox(turb::Coord(0, 0, 0), turb::Coord(W - 1, H - 1, 0)), turb::Lattice{1.0, {0, 0, 0}});
    float vmax = 1e-6f;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            v(x, H - 1 - y, 0) = turb::Vec3f(m.at(x, y, 0), -m.at(x, y, 1), 0.0f);
            vmax = std::max(vmax, std::hypot(m.at(x, y, 0), m.at(x, y, 1)));
        }
    turb::LicSettings ls;
    ls.view = turb::View::Top;
    ls.width = W;
    turb::Image lic = turb::renderLic(v, ls);
    for (int y = 0; y < lic.height() && y < H; ++y)
        for (int x = 0; x < lic.width() && x < W; ++x) {
            const turb::Rgb c =
                turb::colormap(turb::Colormap::Viridis, std::hypot(m.at(x, y, 0), m.at(x, y, 1)) / vmax);
            const float l = lic.at(x, y)[0];
            lic.at(x, y) =
                turb::Rgb(c[0] * (0.35f + 0.65f * l), c[1] * (0.35f + 0.65f * l), c[2] * (0.35f + 0.65f * l));
        }
    return lic;
}

/// Halves a picture until it is at most `maxWidth` wide (box means), for sheets.
turb::Image fit(const turb::Image& p, int maxWidth)
{
    turb::Image cur = p;
    while (cur.width() > maxWidth) {
        turb::Image h((cur.width() + 1) / 2, (cur.height() + 1) / 2);
        for (int y = 0; y < h.height(); ++y)
            for (int x = 0; x < h.width(); ++x) {
                turb::Rgb s(0.0f);
                int n = 0;
                for (int j = 0; j < 2; ++j)
                    for (int i = 0; i < 2; ++i)
                        if (cur.inside(2 * x + i, 2 * y + j)) {
                            s += cur.at(2 * x + i, 2 * y + j);
                            ++n;
                        }
                h.at(x, y) = s / float(n);
            }
        cur = h;
    }
    return cur;
}

void writeData(const std::string& path, const turb::ChannelImage& img, bool noClobber)
{
    turb::RgbaImage out(img.width(), img.height());
    const int C = img.channels();
    for (size_t i = 0; i < out.size(); ++i) {
        const float* v = img.pixel(i);
        out.pixels()[i] = turb::Rgba(v[0], C > 1 ? v[1] : v[0], C > 2 ? v[2] : (C > 1 ? 0.0f : v[0]), 1.0f);
    }
    turbio::ImageWriteOptions o;
    o.noClobber = noClobber;
    o.alpha = false;
    o.bits = turbio::PixelBits::Float;
    turbio::ensureParentDirectory(path);
    turbio::writeImage(path, out, o);
}

/// What the contact sheet shows, gathered during the run.
struct SheetParts
{
    std::vector<std::pair<int, turb::Image>> example; // example frame index, picture
    turb::ChannelImage A, v, R0, rough, refined, Aprime;
    std::vector<std::pair<int, turb::Image>> outputs;
};

turb::Image contactSheet(const SheetParts& p, const turb::Image& target, const std::string& title)
{
    const int w = 240;
    std::vector<turb::Image> pics; // owned, referenced by the cells
    pics.reserve(32);
    const auto add = [&](const turb::Image& img) -> const turb::Image* {
        pics.push_back(fit(img, w));
        return &pics.back();
    };
    float rr = 1e-6f;
    for (float v : p.R0.data()) rr = std::max(rr, std::abs(v));
    std::vector<std::vector<turb::SheetCell>> rows(3);
    for (const auto& [i, img] : p.example) rows[0].push_back({add(img), "example frame " + std::to_string(i)});
    rows[0].push_back({add(picture(p.A)), "average A"});
    rows[0].push_back({add(flowPicture(p.v)), "flow v"});
    rows[0].push_back({add(signedPicture(p.R0, 0.5f * rr)), "residual R0"});
    rows[1].push_back({add(target), "target"});
    rows[1].push_back({add(flowPicture(p.rough)), "rough flow"});
    rows[1].push_back({add(flowPicture(p.refined)), "refined flow"});
    rows[1].push_back({add(picture(p.Aprime)), "A'"});
    for (const auto& [i, img] : p.outputs) rows[2].push_back({add(img), "output " + std::to_string(i)});
    return turb::contactSheet(rows, {"example", "design", "output"}, title, 1);
}

// ---------------------------------------------------------------------------------------------

nlohmann::json statsJson(const turb::AnimateStats& st)
{
    nlohmann::json j;
    j["example"] = {{"pairs", st.analysis.pairs}, {"pairs_tracked", st.analysis.pairsUsed},
        {"tracks_per_pair", st.analysis.tracksPerPair}, {"mean_speed", st.analysis.meanSpeed},
        {"rms_difference", st.analysis.rmsDifference}, {"rms_residual", st.analysis.rmsResidual},
        {"flow_given", st.analysis.flowGiven}};
    j["design_mean_speed"] = st.designMeanSpeed;
    j["transfer"] = {{"patches", st.transfer.patches}, {"pasted", st.transfer.pasted},
        {"mean_cost", st.transfer.meanCost}, {"max_cost", st.transfer.maxCost}, {"covered", st.transfer.covered},
        {"distinct_windows", st.transfer.distinct}};
    j["eq8"] = {
        {"alpha", st.alpha}, {"beta", st.beta}, {"mean_d", st.meanD}, {"sigma_d", st.sigmaD}, {"sigma_c", st.sigmaC}};
    j["hm_grid"] = {st.gridCols, st.gridRows};
    j["stages_s"] = {{"analysis", st.secondsAnalysis}, {"design", st.secondsDesign}, {"transfer", st.secondsTransfer},
        {"average", st.secondsAverage}, {"synthesis", st.secondsSynthesis}, {"matching", st.secondsMatching}};
    return j;
}

void configure(AnimateArgs& a)
{
    turb::AnimateSettings& s = a.settings;
    s.refineFlow = a.refine == Refine::On || (a.refine == Refine::Auto && a.flow.empty());
    s.histogramMatch = a.hm != HmMode::Off;
    s.hm.pyramid = a.hm == HmMode::Laplacian ? turb::HmPyramid::Laplacian : turb::HmPyramid::Steerable;
    if (a.hmGrid == "off") {
        s.hm.gridCols = s.hm.gridRows = 1;
    } else if (a.hmGrid != "auto") {
        const auto v = numbers(a.hmGrid, 'x', 2, "--hm-grid"); // checked while parsing (gridCheck)
        s.hm.gridCols = int(v[0]);
        s.hm.gridRows = int(v[1]);
    }
    turb::validate(s);
}

int exportBuiltin(const AnimateArgs& a)
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
    const auto rgba = [](const turb::ChannelImage& c) {
        turb::RgbaImage r(c.width(), c.height());
        for (size_t i = 0; i < r.size(); ++i)
            r.pixels()[i] = turb::Rgba(
                c.pixel(i)[0], c.pixel(i)[c.channels() > 1 ? 1 : 0], c.pixel(i)[c.channels() > 2 ? 2 : 0], 1.0f);
        r.colorSpace = "sRGB";
        return r;
    };
    const turbio::FramePattern pat = turbio::FramePattern::parse(dir + "/river.####.png");
    turbio::ensureParentDirectory(pat.format(1));
    for (int i = 0; i < n; ++i) turbio::writeImage(pat.format(i + 1), rgba(frames[size_t(i)]), o);
    turbio::writeImage(dir + "/still.png", rgba(turb::scenes::riverStill(tw, th, 2)), o);
    turbio::writeImage(dir + "/matte.png", rgba(turb::scenes::riverMatte(tw, th)), o);
    logInfo("animate: wrote " + std::to_string(n) + " example frames " + pat.str() + ", " + dir + "/still.png and " +
            dir + "/matte.png");
    return kOk;
}

constexpr size_t kMinMeasuredFrames = 8;

// The quality measures of --measure: the output's flow against the design, its temporal statistics against the
// example's. They need the example's frames before the library consumes them.
struct Measures
{
    std::optional<turb::TemporalStats> exTemporal, outTemporal;
    std::vector<turb::ChannelImage> outLuma;
    std::optional<turb::FlowAgreement> exampleAgreement, exampleTracks;
};

Measures startMeasures(const AnimateArgs& a, const Example& example, const Target& target)
{
    Measures m;
    if (!a.measure) return m;
    const turb::AnimateSettings& s = a.settings;
    m.exTemporal.emplace(s.tau);
    for (size_t i = size_t(s.tau); i < example.frames.size(); ++i) m.exTemporal->add(example.frames[i]);
    m.outTemporal.emplace(s.tau, target.matte ? &*target.matte : nullptr);
    // Calibration of the measurement: the same tracking on the example against the cache's own flow.
    if (example.flow)
        turb::withThreads(globals().threads, [&] {
            std::vector<turb::FlowTrack> tracks; // one tracking pass gives both measures
            const turb::ChannelImage v = turb::estimateMeanFlow(example.frames, s.analysis, nullptr, nullptr, &tracks);
            m.exampleAgreement = turb::compareFlows(v, *example.flow, nullptr, 0.25);
            m.exampleTracks = turb::compareTracks(tracks, *example.flow, nullptr, 0.25);
        });
    return m;
}

// The measures into the summary's "quality", and said.
void finishMeasures(const AnimateArgs& a, const Measures& m, const turb::ChannelImage& designed, const Target& target,
    nlohmann::json& summary)
{
    turb::AnalysisSettings as = a.settings.analysis;
    turb::AnalysisStats tracked;
    std::vector<turb::FlowTrack> tracks; // one tracking pass gives both measures
    const turb::ChannelImage measured = turb::estimateMeanFlow(m.outLuma, as, &tracked, nullptr, &tracks);
    const turb::ChannelImage* matte = target.matte ? &*target.matte : nullptr;
    // No pair tracked: the interpolated field is zero by default, not a measurement.
    const turb::FlowAgreement fa = tracked.pairsUsed > 0 ? turb::compareFlows(measured, designed, matte)
                                                         : turb::FlowAgreement{std::nan(""), std::nan(""), 0.0};
    const turb::FlowAgreement ft = turb::compareTracks(tracks, designed, matte);
    const turb::TemporalSummary te = m.exTemporal->summary(), to = m.outTemporal->summary();
    summary["quality"] = {{"track_median_angle_deg", ft.medianAngleDeg},
        {"track_median_speed_ratio", ft.medianSpeedRatio}, {"track_fraction", ft.pixels},
        {"flow_median_angle_deg", fa.medianAngleDeg}, {"flow_median_speed_ratio", fa.medianSpeedRatio},
        {"flow_pixels", fa.pixels}, {"temporal_std", to.temporalStd}, {"temporal_std_example", te.temporalStd},
        {"autocorrelation", to.autocorrelation}, {"autocorrelation_example", te.autocorrelation}};
    const auto said = [](const turb::FlowAgreement& f) {
        return std::isnan(f.medianAngleDeg)
                   ? std::string("not measured (nothing tracked)")
                   : fmt("%.1f deg", f.medianAngleDeg) + ", speed ratio " + fmt("%.2f", f.medianSpeedRatio);
    };
    if (m.exampleAgreement) {
        summary["quality"]["example_track_median_angle_deg"] = m.exampleTracks->medianAngleDeg;
        summary["quality"]["example_track_median_speed_ratio"] = m.exampleTracks->medianSpeedRatio;
        summary["quality"]["example_flow_median_angle_deg"] = m.exampleAgreement->medianAngleDeg;
        summary["quality"]["example_flow_median_speed_ratio"] = m.exampleAgreement->medianSpeedRatio;
        logInfo("animate: the same tracking on the example against the cache's flow: tracks " + said(*m.exampleTracks) +
                "; interpolated field " + said(*m.exampleAgreement));
    }
    logInfo("animate: motion vs design: tracks " + said(ft) + "; interpolated field " + said(fa) + "; temporal std " +
            fmt("%.4f", to.temporalStd) + " (example " + fmt("%.4f", te.temporalStd) + "); autocorrelation lag 1 " +
            fmt("%.2f", to.autocorrelation[0]) + " (example " + fmt("%.2f", te.autocorrelation[0]) + ")");
    // Medians over a handful of frame pairs swing widely (2 frames gave speed ratios of 10-27).
    if (m.outLuma.size() < kMinMeasuredFrames)
        logWarning("--measure: " + std::to_string(m.outLuma.size()) +
                   " output frames; the motion and temporal "
                   "figures need at least " +
                   std::to_string(kMinMeasuredFrames) + " to mean much");
    if (std::isnan(ft.medianAngleDeg))
        logWarning("--measure: nothing moving was tracked in the output inside the matte; no motion figures");
    if (!a.dump.empty()) turbio::writeImage(a.dump + "/measured_flow.png", flowPicture(measured));
}

// What the library shows of its stages: the refined design (for --measure), the sheet's pictures, --dump's files.
struct Inspector
{
    const AnimateArgs& a;
    SheetParts& sheet;
    turb::ChannelImage& designed;

    void operator()(const std::string& name, int index, const turb::ChannelImage& img) const
    {
        if (name == "refined") designed = img;
        if (!a.sheet.empty()) {
            if (name == "A") sheet.A = img;
            else if (name == "v") sheet.v = img;
            else if (name == "R" && index == 0) sheet.R0 = img;
            else if (name == "rough") sheet.rough = img;
            else if (name == "refined") sheet.refined = img;
            else if (name == "Aprime") sheet.Aprime = img;
        }
        if (a.dump.empty() || name == "Dsecond" || name == "gradient") return;
        const std::string file = index < 0
                                     ? a.dump + "/" + name + ".exr"
                                     : turbio::FramePattern::parse(a.dump + "/" + name + ".####.exr").format(index);
        writeData(file, img, a.noClobber);
        if (name == "v" || name == "rough" || name == "refined")
            turbio::writeImage(a.dump + "/" + name + ".png", flowPicture(img));
    }
};

// Each frame as the library finishes it: written with the still's alpha, measured, kept for the sheet, reported.
struct FrameWriter
{
    const AnimateArgs& a;
    const Target& target;
    const turbio::FramePattern& outPattern;
    int count;
    Measures& measures;
    SheetParts& sheet;
    RunReport& report;
    ConsoleProgress& stages;
    const SkipPlan& plan;
    const std::string& settings; ///< what each frame records (--skip-existing)

    void operator()(const turb::AnimatedFrame& f) const
    {
        stages.clear();
        const auto tw = std::chrono::steady_clock::now();
        const int number = a.start + f.index;
        const std::string path = outPattern.format(number);
        // A frame --skip-existing leaves as it is was made all the same: --measure and --sheet still see it.
        if (measures.outTemporal) {
            measures.outTemporal->add(f.image);
            measures.outLuma.push_back(turb::luminance(f.image));
        }
        const std::vector<int> sheetFrames{0, count / 3, 2 * count / 3, count - 1};
        if (!a.sheet.empty() && std::find(sheetFrames.begin(), sheetFrames.end(), f.index) != sheetFrames.end())
            sheet.outputs.emplace_back(number, picture(f.image));
        if (plan.skipped(size_t(f.index))) {
            report.frameSkipped(number, f.index, count, f.seconds + secondsSince(tw), path, false);
            return;
        }
        turb::RgbaImage img(f.image.width(), f.image.height());
        for (size_t i = 0; i < img.size(); ++i) {
            const float* p = f.image.pixel(i);
            img.pixels()[i] = turb::Rgba(p[0], p[1], p[2], target.alpha[i]);
        }
        img.colorSpace = target.colorSpace;
        turbio::ensureParentDirectory(path);
        turbio::ImageWriteOptions wo;
        wo.noClobber = a.noClobber;
        wo.metadata = frameMetadata("animate", settings);
        turbio::writeImage(path, img, wo);
        nlohmann::json extra{
            {"out", path}, {"example_index", f.exampleIndex}, {"mean_error", f.meanError}, {"std_error", f.stdError}};
        // Without histogram matching there are no cells: no per-cell numbers rather than a misleading 0.
        const bool cells = a.settings.histogramMatch;
        if (cells) {
            extra["cell_mean_error"] = f.cellMeanError;
            extra["cell_std_error"] = f.cellStdError;
        }
        report.frameDone(number, f.index, count, f.seconds + secondsSince(tw),
            "mean/std vs target " + fmt("%.2f%%", 100 * f.meanError) + "/" + fmt("%.2f%%", 100 * f.stdError) +
                (cells ? ", worst cell " + fmt("%.2f%%", 100 * f.cellMeanError) + "/" +
                             fmt("%.2f%%", 100 * f.cellStdError)
                       : std::string(", no histogram matching")) +
                " -> " + path,
            extra);
    }
};

void logStages(const turb::AnimateStats& st)
{
    logInfo("animate: example flow " + fmt("%.2f px/frame", st.analysis.meanSpeed) +
            (st.analysis.flowGiven ? " (from the cache)" : "") + ", residual rms " +
            fmt("%.4f", st.analysis.rmsResidual) + " vs difference rms " + fmt("%.4f", st.analysis.rmsDifference) +
            "; design " + fmt("%.2f px/frame", st.designMeanSpeed) + "; transfer cost " +
            fmt("%.3f", st.transfer.meanCost) + "; stages " + fmt("%.1f", st.secondsAnalysis) + "/" +
            fmt("%.1f", st.secondsDesign) + "/" + fmt("%.1f", st.secondsTransfer) + "/" +
            fmt("%.1f", st.secondsAverage) + "/" + fmt("%.1f", st.secondsSynthesis) + "/" +
            fmt("%.1f", st.secondsMatching) + " s (analysis/design/transfer/A'/synthesis/matching)");
}

void logPlan(const AnimateArgs& a, const Example& example, const Target& target)
{
    const int N = int(example.frames.size()), tau = a.settings.tau;
    logInfo("animate: example " + example.label + " (" + std::to_string(N) + " frames, " +
            std::to_string(example.frames[0].width()) + "x" + std::to_string(example.frames[0].height()) +
            "), target " + target.label + " (" + std::to_string(target.rgb.width()) + "x" +
            std::to_string(target.rgb.height()) + (target.matte ? ", matte" : "") + "), " +
            (target.strokes ? std::to_string(target.strokes->strokes.size()) + " strokes" : "dense flow " + a.flow) +
            ", tau " + std::to_string(tau) + " -> " + std::to_string(N - tau) + " frames");
}

// The animation: the library's stages, each frame written as it comes, then the summary (and --measure, --sheet).
void animateFrames(const AnimateArgs& a, Example& example, const Target& target, const turbio::FramePattern& outPattern,
    const SkipPlan& plan, const std::string& settings, std::chrono::steady_clock::time_point started)
{
    const turb::AnimateSettings& s = a.settings;
    const int N = int(example.frames.size());
    Measures measures = startMeasures(a, example, target);
    SheetParts sheet;
    if (!a.sheet.empty())
        for (int i : {0, N / 2, N - 1})
            sheet.example.emplace_back(example.numbers[size_t(i)], picture(example.frames[size_t(i)]));

    turb::AnimateInput in;
    in.exampleFrames = std::move(example.frames);
    in.exampleFlow = example.flow ? &*example.flow : nullptr;
    in.target = target.rgb;
    in.matte = target.matte ? &*target.matte : nullptr;
    if (target.strokes) in.strokes = &target.strokes->strokes;
    if (target.flow) in.designedFlow = &*target.flow;
    turb::ChannelImage designed;

    turb::withThreads(globals().threads, [&] {
        RunReport report("animate", a.json, started);
        const int count = N - s.tau;
        ConsoleProgress stages(0, count, a.start);
        const turb::AnimateStats st = turb::animate(std::move(in), s,
            FrameWriter{a, target, outPattern, count, measures, sheet, report, stages, plan, settings}, &stages,
            Inspector{a, sheet, designed});
        nlohmann::json summary = statsJson(st);
        logStages(st);
        if (a.measure) finishMeasures(a, measures, designed, target, summary);
        if (!a.sheet.empty()) {
            turbio::ensureParentDirectory(a.sheet);
            turbio::writeImage(
                a.sheet, contactSheet(sheet, picture(target.rgb), "animate: " + example.label + " -> " + target.label));
            summary["sheet"] = a.sheet;
        }
        report.finish(0, summary);
    });
}

int runAnimate(AnimateArgs& a)
{
    if (!a.exportBuiltin.empty()) return exportBuiltin(a);
    const auto started = std::chrono::steady_clock::now(); // total_s counts reading the example and the still
    configure(a);
    if (const int rc = stylize::checkOutputPatterns(a.out); rc != kOk) return rc;
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    if (!outPattern.numbered())
        throw UsageError("--out " + a.out + " has no frame token (####): animate writes a sequence");
    // Everything is read and checked before the first file is written.
    const Target target = readTarget(a);
    // The matcher keeps cells of at least 8 pixels: say so when a given grid is finer.
    const turb::HistogramMatchSettings& hm = a.settings.hm;
    const auto [cols, rows] = turb::histogramGrid(target.rgb.width(), target.rgb.height(), hm);
    if (a.settings.histogramMatch && hm.gridCols > 0 && (cols != hm.gridCols || rows != hm.gridRows))
        logWarning("--hm-grid " + a.hmGrid + ": cells must be at least 8 pixels wide on the " +
                   std::to_string(target.rgb.width()) + "x" + std::to_string(target.rgb.height()) + " still; using " +
                   std::to_string(cols) + "x" + std::to_string(rows));
    Example example = readExample(a, a.settings.tau);
    std::vector<std::string> outputs;
    std::vector<int> numbers;
    for (int j = 0; j < int(example.frames.size()) - a.settings.tau; ++j) {
        outputs.push_back(outPattern.format(a.start + j));
        numbers.push_back(a.start + j);
    }
    {
        std::vector<std::string> paths = outputs;
        if (!a.sheet.empty()) paths.push_back(a.sheet);
        if (!a.dump.empty()) paths.push_back(a.dump + "/A.exr");
        checkOutputs(paths, {a.target, a.targetAlpha, a.strokes, a.flow}, a.noClobber, a.skipExisting);
    }
    // Every frame is made from the whole example (the design, eq. 8's statistics): its frames are a setting here.
    const std::string settings =
        commandSettingsText(*a.app, {}) + "example_frames=" + turbio::formatFrameList(example.numbers) + ";";
    const SkipPlan plan = planSkips(outputs, numbers, "animate", settings, a.skipExisting);
    if (!a.settings.histogramMatch && a.settings.hmApply != turb::HmApply::PerFrame)
        logWarning("--hm-apply is ignored with --hm off");
    logPlan(a, example, target);
    if (globals().dryRun) {
        if (a.skipExisting) {
            printSkipPlan(plan, outputs);
        } else {
            for (int j = 0; j < int(outputs.size()); ++j)
                printData("would write " + outputs[size_t(j)] + " (frame " + std::to_string(a.start + j) + ")");
        }
        return kOk;
    }
    if (a.skipExisting && !outputs.empty() && plan.writing.empty()) {
        // The frames come from one pass over the whole shot: with all of them written, there is nothing to make.
        logInfo("animate: all " + std::to_string(outputs.size()) +
                " frames were written by the same settings (--skip-existing): nothing to do");
        return kOk;
    }
    lockOutputFrames(outPattern, plan.writing); // two tasks never write one frame (a second exits 75)
    animateFrames(a, example, target, outPattern, plan, settings, started);
    return kOk;
}

// The video example, the still and its flow design (a cache example is seen through --camera).
void addInputOptions(CLI::App* app, AnimateArgs& a)
{
    app->add_option("--example", a.example, "Video example: an image sequence with ####, or builtin:river[:WxHxN]");
    app->add_option("--example-cache", a.exampleCache, "Video example from a VDB cache seen through --camera");
    app->add_option("--frames", a.frames, "Example frames to use, e.g. 1-100 (empty: all on disk)")
        ->check(frameListCheck());
    stylize::addCameraOptions(app, a.camera);
    app->add_option(
        "--target", a.target, "The still to animate (its alpha is kept in the output), or builtin:river[:WxH]");
    app->add_option(
        "--target-alpha", a.targetAlpha, "Matte of the fluid (grey image, target size): only the fluid moves");
    app->add_option("--flow-strokes", a.strokes,
        "Flow design: orientation and speed strokes (JSON, scenes/animate/README.md), or builtin:river / builtin:plume "
        "(the designs installed in share/vdbturb/animate)");
    app->add_option(
        "--flow", a.flow, "Flow design: a dense flow image, R,G = x,y in pixels per frame (x right, y down)");
    setting(app->add_flag("--flow-y-up", a.flowYUp, "The --flow image's G channel points up"), "flow-y-up");
    addReadOptions(app, a.read);
    // Only --example-cache reads grids: its grid and frame-rate choices are settings here.
    for (const char* name : {"density-grid", "vel-grid", "fps"})
        setting(app->get_option(std::string("--") + name), name);
}

void addOutputOptions(CLI::App* app, AnimateArgs& a)
{
    app->add_option("--out", a.out, "Output frames, e.g. anim/still.####.exr (EXR: half, premultiplied) or .png");
    app->add_option("--start", a.start, "Frame number of the first output frame")->group(kGroupOutput);
    app->add_flag("--no-clobber", a.noClobber, "Never replace an existing output file")->group(kGroupOutput);
    app->add_flag("--skip-existing", a.skipExisting,
           "Skip the frames already written by the same settings (farm wrappers' retries; when some are missing the "
           "whole shot is made again, since each frame comes from the whole example); a frame written otherwise is "
           "refused (exit 1)")
        ->group(kGroupOutput);
    a.app = app;
    app->add_option("--sheet", a.sheet, "Write a contact sheet PNG: example, design and output frames")
        ->group(kGroupOutput);
    app->add_flag("--json", a.json, "One JSON line per frame and a summary with stage times on stdout");
    app->add_option(
        "--export-builtin", a.exportBuiltin, "Write the built-in river example and still into DIR and stop");
    setting(app->add_option(
                "--dump", a.dump, "Also write every stage's images into DIR (float EXR) and flow pictures (PNG)"),
        "dump");
    setting(app->add_flag(
                "--measure", a.measure, "Measure the output's flow against the design and its temporal statistics"),
        "measure");
}

// Histogram matching (section 5.6): the steerable pyramid's repetitions and the grid of cells.
void addHmSettings(CLI::App* app, AnimateArgs& a)
{
    turb::HistogramMatchSettings& hm = a.settings.hm;
    setting(app->add_option("--hm-rep,--hm.reps", hm.reps, "HM Rep: repetitions of the steerable matching (paper 3)")
                ->check(CLI::Range(1, 10)),
        "hm.reps");
    // Checked while parsing, so a bad grid is a usage error (exit 2) like every other option's bad value.
    const CLI::Validator gridCheck(
        [](std::string& v) -> std::string {
            if (v == "auto" || v == "off") return {};
            try {
                const auto n = numbers(v, 'x', 2, "--hm-grid");
                if (n[0] < 1 || n[1] < 1 || n[0] != std::floor(n[0]) || n[1] != std::floor(n[1]))
                    return "cells per axis must be whole numbers >= 1";
            } catch (const turb::ValueError& e) {
                return e.what();
            }
            return {};
        },
        "COLSxROWS|auto|off");
    setting(
        app->add_option("--hm-grid", a.hmGrid, "HM Grid: COLSxROWS, auto (cells of about hm.cellSize pixels) or off")
            ->check(gridCheck),
        "hm-grid");
    setting(app->add_option("--hm-cell,--hm.cellSize", hm.cellSize, "Cell size of the automatic HM grid in pixels")
                ->check(CLI::Range(16, 100000)),
        "hm.cellSize");
    setting(app->add_option("--hm-passes,--hm.pixelPasses", hm.pixelPasses, "Final pixel-domain matching passes")
                ->check(CLI::Range(1, 20)),
        "hm.pixelPasses");
    boolSetting(app, "--hm.blendPixels", hm.blendPixels,
        "Blend the cells' pixel-domain matches (false: each cell's statistics exact, seams can show)",
        "hm.blendPixels");
    boolSetting(app, "--hm.cellMoments", hm.cellMoments,
        "Finally solve one blended gain and offset per cell so every cell's mean and std are the target's (false: "
        "stop after the pixel passes)",
        "hm.cellMoments");
    setting(addEnum<turb::HmApply>(app, "--hm-apply,--hmApply", a.settings.hmApply,
                {{"per-frame", turb::HmApply::PerFrame}, {"sequence", turb::HmApply::Sequence}},
                "per-frame: match every frame (the paper); sequence: match the mean frame once, give every frame that "
                "correction and its own cell moments (keeps the moving detail on smooth stills such as smoke renders; "
                "a static speckle on textured ones; docs/animate.md)"),
        "hmApply");
    legacy(app->add_flag_function(
               "--hm-exact-cells", [&hm](std::int64_t) { hm.blendPixels = false; }, "hm.blendPixels = false"),
        "hm.blendPixels", "false");
}

// The method's knobs (Okabe et al.), under turb::AnimateSettings' field names; docs/animate.md has their measurements.
void addAnimateSettings(CLI::App* app, AnimateArgs& a)
{
    turb::AnimateSettings& s = a.settings;
    const auto knob = [app](const std::string& names, auto& v, const std::string& help, const std::string& key) {
        return setting(app->add_option(names, v, help), key);
    };
    setting(
        addEnum<Refine>(app, "--refine", a.refine, {{"auto", Refine::Auto}, {"on", Refine::On}, {"off", Refine::Off}},
            "Refine the design by the target's gradients: auto (strokes yes, --flow no), on, off"),
        "refine");
    setting(addEnum<turb::GradientOrientation>(app, "--orient,--refine.orient", s.refine.orient,
                {{"parallel", turb::GradientOrientation::Parallel},
                    {"perpendicular", turb::GradientOrientation::Perpendicular}},
                "Refined orientation: parallel to the image gradient (the paper) or perpendicular (along edges)"),
        "refine.orient");
    knob("--wf,--refine.wf", s.refine.wf, "w_f: blur of the refined orientation, Gaussian std in pixels (paper 12)",
        "refine.wf")
        ->check(finiteIn(0.1, 500.0));
    knob("--tau", s.tau, "Lifetime of a residual in frames (paper 16); the output has N - tau frames", "tau")
        ->check(CLI::Range(1, 10000));
    knob("--shutter,--average.shutter", s.average.shutter,
        "Sh: motion blur of the target along the flow for A', in frames", "average.shutter")
        ->check(finiteIn(0.0, 200.0));
    knob("--wa,--average.wa", s.average.wa, "w_a: Gaussian std in pixels after the motion blur for A'", "average.wa")
        ->check(finiteIn(0.0, 500.0));
    knob("--patch,--transfer.patchSize", s.transfer.patchSize, "Residual transfer patch size in pixels (paper 8-32)",
        "transfer.patchSize")
        ->check(CLI::Range(8, 64));
    knob("--search-downsample,--transfer.downsample", s.transfer.downsample, "Match flows downsampled by 1, 2 or 4",
        "transfer.downsample")
        ->check(CLI::IsMember({1, 2, 4}));
    knob("--variety,--transfer.variety", s.transfer.variety,
        "Residual transfer: candidates within this fraction of the patch's design speed of the best are equally good, "
        "and the one farthest from its neighbours' windows is taken (0: the nearest, the paper)",
        "transfer.variety")
        ->check(finiteIn(0.0, 1.0));
    knob("--transfer.candidates", s.transfer.candidates,
        "Residual transfer: random example windows costed per patch besides the 8 nearest (only with variety > 0)",
        "transfer.candidates")
        ->check(CLI::Range(1, 64));
    knob("--features,--analysis.features", s.analysis.features,
        "Lucas-Kanade features per example frame pair (paper 100)", "analysis.features")
        ->check(CLI::Range(1, 100000));
    knob("--lk-window,--analysis.window", s.analysis.window, "Lucas-Kanade window in pixels (paper 10)",
        "analysis.window")
        ->check(CLI::Range(3, 64));
    addHmSettings(app, a);
}

} // namespace

Command animateCommand()
{
    auto args = std::make_shared<AnimateArgs>();
    Command c;
    c.name = "animate";
    c.help = "Animate a still picture of fluid from a video example (Okabe et al.): strokes or a flow design, residual "
             "transfer, histogram matching";
    c.setup = [args](CLI::App* app) {
        AnimateArgs& a = *args;
        addInputOptions(app, a);
        addOutputOptions(app, a);
        addEnum<HmMode>(app, "--hm", a.hm,
            {{"steerable", HmMode::Steerable}, {"laplacian", HmMode::Laplacian}, {"off", HmMode::Off}},
            "Histogram matching: steerable (Heeger-Bergen), laplacian (one pass, the fast preview) or off");
        addAnimateSettings(app, a);
    };
    c.run = [args] { return runAnimate(*args); };
    return c;
}

} // namespace vdbturb
