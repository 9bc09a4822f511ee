// vdbturb stylize: appearance transfer onto fluid motion (seed 000, LazyFluids).
#include "Commands.h"
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

struct StylizeArgs
{
    std::string exemplar, exemplarAlpha;
    std::string flow, alpha, cache, scene;
    std::string sceneSize = "256x256";
    double sceneSpeed = 0.02;
    std::string frames;
    std::string camera = "front";
    std::string cameraPos, lookAt, cameraUp = "0,0,1";
    double fov = 40.0;
    int width = 0, height = 0;
    float extinction = 6.0f, step = 0.5f;
    bool flowYUp = false;
    std::string out;
    std::string preview, writeTarget;
    std::string nnf = "uniform";
    bool json = false, noClobber = false;
    turbio::ReadOptions read;
    turb::StylizeSettings settings;
};

std::string fmt(const char* f, double v)
{
    char b[64];
    std::snprintf(b, sizeof(b), f, v);
    return b;
}

std::vector<double> parseNumbers(const std::string& s, size_t n, const std::string& what)
{
    std::vector<double> v;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) {
        try {
            size_t pos = 0;
            v.push_back(std::stod(item, &pos));
            if (pos != item.size()) throw std::invalid_argument(item);
        } catch (...) {
            throw turb::ValueError(what + ": '" + s + "' is not " + std::to_string(n) + " comma-separated numbers");
        }
    }
    if (v.size() != n) throw turb::ValueError(what + ": '" + s + "' is not " + std::to_string(n) + " comma-separated numbers");
    return v;
}

turb::Vec3d parseVec(const std::string& s, const std::string& what)
{
    const auto v = parseNumbers(s, 3, what);
    return turb::Vec3d(v[0], v[1], v[2]);
}

/// One target frame: its mask, its motion F^t, and for a cache the density render for previews.
struct TargetFrame
{
    turb::ChannelImage alpha, motion;
    std::string alphaName, motionName; // for messages
    std::optional<turb::Frame> cacheFrame;
};

/// Where the target comes from: 2D flow and alpha sequences, a VDB cache through a camera, or a scene.
class TargetSource
{
public:
    explicit TargetSource(const StylizeArgs& a) : mArgs(a)
    {
        const int kinds = int(!a.flow.empty() || !a.alpha.empty()) + int(!a.cache.empty()) + int(!a.scene.empty());
        if (kinds != 1) throw turb::ValueError("give one target: --flow and --alpha (2D), --cache (3D through --camera) or --scene");
        if (!a.cache.empty()) {
            mCache = turbio::resolveSequence(a.cache, a.frames);
            requireAll(*mCache);
            mFrames = mCache->frames;
            setupCamera();
        } else if (!a.scene.empty()) {
            const auto wh = parseSize(a.sceneSize);
            mScene.kind = a.scene;
            mScene.width = wh.first;
            mScene.height = wh.second;
            mScene.speed = a.sceneSpeed;
            const std::vector<int> list = a.frames.empty() ? std::vector<int>{1} : turbio::parseFrameList(a.frames);
            if (list.size() == 1 && a.frames.find('-') == std::string::npos)
                for (int f = 1; f <= list[0]; ++f) mFrames.push_back(f);
            else
                mFrames = list;
        } else {
            if (a.flow.empty() || a.alpha.empty()) throw turb::ValueError("a 2D target needs both --flow and --alpha");
            mFlow = turbio::resolveSequence(a.flow, a.frames);
            mAlpha = turbio::resolveSequence(a.alpha, a.frames.empty() ? "" : a.frames);
            requireAll(*mFlow);
            requireAll(*mAlpha);
            for (int f : mFlow->frames)
                if (std::find(mAlpha->frames.begin(), mAlpha->frames.end(), f) != mAlpha->frames.end()) mFrames.push_back(f);
            for (int f : mFlow->frames)
                if (std::find(mFrames.begin(), mFrames.end(), f) == mFrames.end())
                    throw turb::IoError(mAlpha->path(f) + ": missing (the alpha mask of flow frame " + std::to_string(f) + ")");
            for (int f : mAlpha->frames)
                if (std::find(mFrames.begin(), mFrames.end(), f) == mFrames.end())
                    throw turb::IoError(mFlow->path(f) + ": missing (the motion field of alpha frame " + std::to_string(f) + ")");
        }
        if (mFrames.empty()) throw turb::IoError("no target frames");
    }

    const std::vector<int>& frames() const { return mFrames; }
    bool isCache() const { return mCache.has_value(); }
    bool is2D() const { return mFlow.has_value(); }
    const turb::BridgeSettings& bridge() const { return mBridge; }
    std::string label() const
    {
        if (mCache) return "cache " + mCache->pattern.str() + " (" + mArgs.camera + " camera)";
        if (mFlow) return "flow " + mFlow->pattern.str() + " + alpha " + mAlpha->pattern.str();
        return "scene " + mScene.kind + " " + mArgs.sceneSize;
    }

    /// Checks every 2D frame before anything is written: sizes agree, masks are not empty.
    void validate2D() const
    {
        if (!mFlow) return;
        int W = -1, H = -1;
        std::string first;
        for (int f : mFrames) {
            const TargetFrame t = read(f);
            if (W < 0) {
                W = t.alpha.width();
                H = t.alpha.height();
                first = t.alphaName;
            } else if (t.alpha.width() != W || t.alpha.height() != H) {
                throw turb::IoError(t.alphaName + ": " + std::to_string(t.alpha.width()) + "x" + std::to_string(t.alpha.height()) +
                                    ", but " + first + " is " + std::to_string(W) + "x" + std::to_string(H));
            }
            float amax = 0.0f;
            for (float v : t.alpha.data()) amax = std::max(amax, v);
            if (!(amax > 0.0f)) throw turb::IoError(t.alphaName + ": the alpha mask is empty (zero everywhere)");
        }
    }

    TargetFrame read(int frame) const
    {
        TargetFrame t;
        if (mScene.width > 0 && !mFlow && !mCache) {
            turb::scenes::Target2D s = turb::scenes::target2D(mScene, frame);
            t.alpha = std::move(s.alpha);
            t.motion = std::move(s.motion);
            t.alphaName = t.motionName = "scene " + mScene.kind + " frame " + std::to_string(frame);
            return t;
        }
        if (mCache) {
            const std::string path = mCache->path(frame);
            turbio::ReadOptions ro = mArgs.read;
            ro.readExtras = false;
            turb::Frame f = turbio::readFrame(path, frame, ro);
            turb::CameraView v;
            try {
                v = turb::viewThroughCamera(f, mBridge);
            } catch (const turb::ValueError& e) {
                throw turb::IoError(path + ": " + e.what());
            }
            t.alpha = std::move(v.alpha);
            t.motion = std::move(v.motion);
            t.alphaName = t.motionName = path;
            t.cacheFrame = std::move(f);
            return t;
        }
        t.alphaName = mAlpha->path(frame);
        t.motionName = mFlow->path(frame);
        t.alpha = turb::channelOf(turbio::readImage(t.alphaName), 0);
        t.motion = readMotion(t.motionName, frame);
        if (!t.motion.sameSize(t.alpha))
            throw turb::IoError(t.motionName + ": motion " + std::to_string(t.motion.width()) + "x" + std::to_string(t.motion.height()) +
                                " and alpha " + t.alphaName + " " + std::to_string(t.alpha.width()) + "x" + std::to_string(t.alpha.height()) +
                                " differ in size");
        return t;
    }

private:
    static void requireAll(const turbio::Sequence& s)
    {
        if (!s.missing.empty()) throw turb::IoError(s.path(s.missing.front()) + ": missing (frames " + turbio::formatFrameList(s.missing) + ")");
        if (s.frames.empty()) throw turb::IoError(s.pattern.str() + ": no frames on disk");
    }

    static std::pair<int, int> parseSize(const std::string& s)
    {
        const size_t x = s.find('x');
        const auto v = parseNumbers(x == std::string::npos ? s + "," + s : s.substr(0, x) + "," + s.substr(x + 1), 2, "--scene-size");
        return {int(v[0]), int(v[1])};
    }

    void setupCamera()
    {
        turb::CameraSettings& c = mBridge.camera;
        if (mArgs.camera == "perspective") {
            if (mArgs.cameraPos.empty() || mArgs.lookAt.empty())
                throw turb::ValueError("--camera perspective needs --camera-pos X,Y,Z and --look-at X,Y,Z");
            c.perspective = true;
            c.position = parseVec(mArgs.cameraPos, "--camera-pos");
            c.lookAt = parseVec(mArgs.lookAt, "--look-at");
            c.up = parseVec(mArgs.cameraUp, "--camera-up");
            c.fovDegrees = mArgs.fov;
        } else {
            c.view = mArgs.camera == "side" ? turb::View::Side : mArgs.camera == "top" ? turb::View::Top : turb::View::Front;
        }
        c.width = mArgs.width;
        c.height = mArgs.height;
        mBridge.extinction = mArgs.extinction;
        mBridge.stepVoxels = mArgs.step;
    }

    /// R, G of an image in pixels per frame, or the in-plane velocity of a one-layer VDB.
    turb::ChannelImage readMotion(const std::string& path, int frame) const
    {
        const bool vdb = path.size() > 4 && path.compare(path.size() - 4, 4, ".vdb") == 0;
        turb::ChannelImage m;
        if (vdb) {
            turbio::ReadOptions ro = mArgs.read;
            ro.requireDensity = false;
            ro.readExtras = false;
            const turb::Frame f = turbio::readFrame(path, frame, ro);
            const turb::CoordBBox b = f.velocity.bbox();
            if (b.dim().z() != 1) throw turb::IoError(path + ": a 2D motion VDB has one z layer, this one has " + std::to_string(b.dim().z()));
            // Voxel (i, j) is pixel (i - min, max - j): VDB y points up, image y down.
            const double scale = f.dt / f.lattice().voxelSize;
            m = turb::ChannelImage(b.dim().x(), b.dim().y(), 2);
            for (int j = b.min().y(); j <= b.max().y(); ++j)
                for (int i = b.min().x(); i <= b.max().x(); ++i) {
                    const turb::Vec3f v = f.velocity(i, j, b.min().z());
                    m.at(i - b.min().x(), b.max().y() - j, 0) = float(v.x() * scale);
                    m.at(i - b.min().x(), b.max().y() - j, 1) = float(-v.y() * scale);
                }
            return m;
        }
        const turb::RgbaImage img = turbio::readImage(path);
        m = turb::ChannelImage(img.width(), img.height(), 2);
        for (size_t i = 0; i < img.size(); ++i) {
            m.pixel(i)[0] = img.pixels()[i][0];
            m.pixel(i)[1] = mArgs.flowYUp ? -img.pixels()[i][1] : img.pixels()[i][1];
        }
        return m;
    }

    const StylizeArgs& mArgs;
    std::optional<turbio::Sequence> mCache, mFlow, mAlpha;
    turb::scenes::Target2DSettings mScene{"", 0, 0, 0.0};
    turb::BridgeSettings mBridge;
    std::vector<int> mFrames;
};

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

/// The motion field as a LIC picture (2D: a one-voxel-thick field seen from the top).
turb::Image motionPicture(const turb::ChannelImage& m)
{
    const int W = m.width(), H = m.height();
    turb::VectorField v(turb::CoordBBox(turb::Coord(0, 0, 0), turb::Coord(W - 1, H - 1, 0)), turb::Lattice{1.0, {0, 0, 0}});
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) v(x, H - 1 - y, 0) = turb::Vec3f(m.at(x, y, 0), -m.at(x, y, 1), 0.0f);
    turb::LicSettings ls;
    ls.view = turb::View::Top;
    ls.width = W;
    return turb::renderLic(v, ls);
}

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
    if (st.temporalChange >= 0.0) {
        j["temporal_change"] = st.temporalChange;
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
    if (st.temporalChange >= 0.0) s += fmt(", change %.4f", st.temporalChange);
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
        logError(e.what());
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
                throw turb::ValueError(t.alphaName + " with exemplar " + exemplar.label() + ": " + e.what());
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
    c.help = "Appearance transfer onto fluid motion (LazyFluids): an RGBA exemplar's look on 2D flows or on a VDB cache seen through a camera";
    c.setup = [args](CLI::App* app) {
        StylizeArgs& a = *args;
        turb::StylizeSettings& s = a.settings;
        app->add_option("--exemplar", a.exemplar,
               "RGBA exemplar: one picture (PNG, EXR, TIFF, JPEG...), a sequence with #### (a video exemplar: target frame i "
               "uses exemplar frame i, looping), or builtin:fire[:N] (procedural, smooth and textured halves)")
            ->required();
        app->add_option("--exemplar-alpha", a.exemplarAlpha, "Grayscale mask (or ####-sequence) giving the exemplar's alpha");
        app->add_option("--flow", a.flow, "2D motion F^t per frame: images with R,G in pixels per frame (x right, y down), or one-layer VDBs");
        app->add_option("--alpha", a.alpha, "2D target alpha masks per frame (grayscale images)");
        app->add_flag("--flow-y-up", a.flowYUp, "The flow images' G channel points up (Nuke/Houdini style) rather than down");
        app->add_option("--cache", a.cache, "A 3D cache (density + velocity) seen through --camera: alpha = rendered opacity, motion = projected velocity");
        app->add_option("--scene", a.scene, "A built-in 2D target: rotate, swirl (a blob in a rotating/shearing vortex), rise, or fill (all fluid)")
            ->check(CLI::IsMember({"rotate", "swirl", "rise", "fill"}));
        app->add_option("--scene-size", a.sceneSize, "Built-in target size WxH (default 256x256)");
        app->add_option("--scene-speed", a.sceneSpeed, "Built-in target: radians per frame at the centre (rise: image widths per frame) (default 0.02)");
        app->add_option("--frames", a.frames, "Frames (e.g. 1-150); a scene: a count N or a list (default: every frame on disk; scene 1)");
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
    };
    c.run = [args] { return runStylize(*args); };
    return c;
}

} // namespace vdbturb
