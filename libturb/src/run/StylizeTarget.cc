// What both methods of runStylize share (StylizeParts.h): the target, the output checks and plan, the pictures.
#include "StylizeParts.h"

#include <turb/run/Output.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Render.h>
#include <turbio/ImageIO.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <sstream>

namespace turb::run::detail {

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
    if (v.size() != n)
        throw turb::ValueError(what + ": '" + s + "' is not " + std::to_string(n) + " comma-separated numbers");
    return v;
}

void checkOutputPatterns(const std::string& out, const std::string& more)
{
    if (out.empty()) throw UsageError("give --out PATTERN (.png, .exr or .tif with #### for the frame)");
    try {
        turbio::outputFormatOf(out);
        if (!more.empty()) turbio::outputFormatOf(more);
    } catch (const turb::ValueError& e) {
        throw UsageError(e.what(), e.settings());
    }
}

void checkFrameToken(const turbio::FramePattern& out, const std::string& outText, size_t frames)
{
    if (!out.numbered() && frames > 1)
        throw UsageError(
            "--out " + outText + " has no frame token (####) but there are " + std::to_string(frames) + " frames");
}

SkipPlan planOutputFrames(const StylizeJob& a, const std::vector<int>& frames, const turbio::FramePattern& out,
    std::vector<std::string>& settings)
{
    std::vector<std::string> outputs;
    for (int f : frames) outputs.push_back(out.format(f));
    settings = sequentialSettings(a.settingsText, frames);
    SkipPlan plan = planSkips(outputs, frames, "stylize", settings, a.skipExisting);
    if (a.dryRun && a.skipExisting) printSkipPlan(plan, outputs);
    return plan;
}

void printWouldWrite(const StylizeJob& a, const std::vector<int>& frames, const turbio::FramePattern& out)
{
    if (a.skipExisting) return; // planOutputFrames printed the plan
    for (int f : frames) printData("would write " + out.format(f) + " (frame " + std::to_string(f) + ")");
}

turb::Image motionPicture(const turb::ChannelImage& m)
{
    const int W = m.width(), H = m.height();
    turb::VectorField v(
        turb::CoordBBox(turb::Coord(0, 0, 0), turb::Coord(W - 1, H - 1, 0)), turb::Lattice{1.0, {0, 0, 0}});
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) v(x, H - 1 - y, 0) = turb::Vec3f(m.at(x, y, 0), -m.at(x, y, 1), 0.0f);
    turb::LicSettings ls;
    ls.view = turb::View::Top;
    ls.width = W;
    return turb::renderLic(v, ls);
}

turb::Image cacheRender(const TargetFrame& t, const TargetSource& src)
{
    turb::DensityRenderSettings dr;
    dr.camera = src.bridge().camera;
    dr.camera->width = t.alpha.width();
    dr.camera->height = t.alpha.height();
    dr.extinction = src.bridge().extinction;
    return turb::renderDensity(t.cacheFrame->density, dr);
}

TargetSource::TargetSource(const StylizeJob& a, bool flowOptional) : mArgs(a)
{
    const int kinds = int(!a.flow.empty() || !a.alpha.empty()) + int(!a.cache.empty()) + int(!a.scene.empty());
    if (kinds != 1)
        throw turb::ValueError("give one target: --flow and --alpha (2D), --cache (3D through --camera) or --scene");
    if (!a.cache.empty()) {
        mCache = turbio::resolveSequence(a.cache, a.frames);
        requireAll(*mCache);
        mFrames = mCache->frames;
        mBridge = bridgeSettings(a.camera);
    } else if (!a.scene.empty()) {
        openScene(a);
    } else {
        open2D(a, flowOptional);
    }
    if (mFrames.empty()) throw turb::IoError("no target frames");
}

void TargetSource::openScene(const StylizeJob& a)
{
    const auto wh = parseSize(a.sceneSize);
    mScene.kind = a.scene;
    mScene.width = wh.first;
    mScene.height = wh.second;
    mScene.speed = a.sceneSpeed;
    const std::vector<int> list = a.frames.empty() ? std::vector<int>{1} : turbio::parseFrameList(a.frames);
    if (list.size() == 1 && a.frames.find('-') == std::string::npos)
        for (int f = 1; f <= list[0]; ++f) mFrames.push_back(f);
    else mFrames = list;
}

void TargetSource::open2D(const StylizeJob& a, bool flowOptional)
{
    if (a.alpha.empty() || (a.flow.empty() && !flowOptional))
        throw turb::ValueError("a 2D target needs both --flow and --alpha");
    mAlpha = turbio::resolveSequence(a.alpha, a.frames.empty() ? "" : a.frames);
    requireAll(*mAlpha);
    if (a.flow.empty()) {
        mFrames = mAlpha->frames; // masks only: the motion is estimated by the caller
        return;
    }
    mFlow = turbio::resolveSequence(a.flow, a.frames);
    requireAll(*mFlow);
    for (int f : mFlow->frames)
        if (std::find(mAlpha->frames.begin(), mAlpha->frames.end(), f) != mAlpha->frames.end()) mFrames.push_back(f);
    for (int f : mFlow->frames)
        if (std::find(mFrames.begin(), mFrames.end(), f) == mFrames.end())
            throw turb::IoError(mAlpha->path(f) + ": missing (the alpha mask of flow frame " + std::to_string(f) + ")");
    for (int f : mAlpha->frames)
        if (std::find(mFrames.begin(), mFrames.end(), f) == mFrames.end())
            throw turb::IoError(
                mFlow->path(f) + ": missing (the motion field of alpha frame " + std::to_string(f) + ")");
}

std::string TargetSource::label() const
{
    if (mCache) return "cache " + mCache->pattern.str() + " (" + cameraName(mArgs.camera.kind) + " camera)";
    if (mFlow) return "flow " + mFlow->pattern.str() + " + alpha " + mAlpha->pattern.str();
    if (mAlpha) return "masks " + mAlpha->pattern.str();
    return "scene " + mScene.kind + " " + mArgs.sceneSize;
}

void TargetSource::validate2D(bool allowEmpty) const
{
    if (!mAlpha) return;
    int W = -1, H = -1;
    std::string first;
    for (int f : mFrames) {
        const TargetFrame t = read(f);
        if (W < 0) {
            W = t.alpha.width();
            H = t.alpha.height();
            first = t.alphaName;
        } else if (t.alpha.width() != W || t.alpha.height() != H) {
            throw turb::IoError(t.alphaName + ": " + std::to_string(t.alpha.width()) + "x" +
                                std::to_string(t.alpha.height()) + ", but " + first + " is " + std::to_string(W) + "x" +
                                std::to_string(H));
        }
        float amax = 0.0f;
        for (float v : t.alpha.data()) amax = std::max(amax, v);
        if (!(amax > 0.0f) && !allowEmpty)
            throw turb::IoError(t.alphaName + ": the alpha mask is empty (zero everywhere)");
    }
}

TargetFrame TargetSource::read(int frame) const
{
    TargetFrame t;
    if (mScene.width > 0 && !mAlpha && !mCache) {
        turb::scenes::Target2D s = turb::scenes::target2D(mScene, frame);
        t.alpha = std::move(s.alpha);
        t.motion = std::move(s.motion);
        t.alphaName = t.motionName = "scene " + mScene.kind + " frame " + std::to_string(frame);
        return t;
    }
    if (mCache) return readCache(frame);
    t.alphaName = mAlpha->path(frame);
    t.alpha = turb::channelOf(turbio::readImage(t.alphaName), 0);
    if (!mFlow) return t; // a mask-only target: the caller estimates the motion
    t.motionName = mFlow->path(frame);
    t.motion = readMotion(t.motionName, frame);
    if (!t.motion.sameSize(t.alpha))
        throw turb::IoError(t.motionName + ": motion " + std::to_string(t.motion.width()) + "x" +
                            std::to_string(t.motion.height()) + " and alpha " + t.alphaName + " " +
                            std::to_string(t.alpha.width()) + "x" + std::to_string(t.alpha.height()) +
                            " differ in size");
    return t;
}

TargetFrame TargetSource::readCache(int frame) const
{
    TargetFrame t;
    const std::string path = mCache->path(frame);
    turbio::ReadOptions ro = mArgs.read;
    ro.readExtras = false;
    ro.cropToSmoke = false; // the camera frames the cache's box: it must not change with the smoke
    turb::Frame f = turbio::readFrame(path, frame, ro);
    turb::CameraView v;
    try {
        v = turb::viewThroughCamera(f, mBridge);
    } catch (const turb::ValueError& e) {
        throw turb::IoError(path + ": " + e.what(), e.settings());
    }
    t.alpha = std::move(v.alpha);
    t.motion = std::move(v.motion);
    t.alphaName = t.motionName = path;
    t.cacheFrame = std::move(f);
    return t;
}

void TargetSource::requireAll(const turbio::Sequence& s)
{
    if (!s.missing.empty())
        throw turb::IoError(
            s.path(s.missing.front()) + ": missing (frames " + turbio::formatFrameList(s.missing) + ")");
    if (s.frames.empty()) throw turb::IoError(s.pattern.str() + ": no frames on disk");
}

std::pair<int, int> TargetSource::parseSize(const std::string& s)
{
    const size_t x = s.find('x');
    const auto v =
        parseNumbers(x == std::string::npos ? s + "," + s : s.substr(0, x) + "," + s.substr(x + 1), 2, "--scene-size");
    return {int(v[0]), int(v[1])};
}

turb::ChannelImage TargetSource::readMotion(const std::string& path, int frame) const
{
    const bool vdb = path.size() > 4 && path.compare(path.size() - 4, 4, ".vdb") == 0;
    if (vdb) return readMotionVdb(path, frame);
    const turb::RgbaImage img = turbio::readImage(path);
    turb::ChannelImage m(img.width(), img.height(), 2);
    for (size_t i = 0; i < img.size(); ++i) {
        m.pixel(i)[0] = img.pixels()[i][0];
        m.pixel(i)[1] = mArgs.flowYUp ? -img.pixels()[i][1] : img.pixels()[i][1];
    }
    return m;
}

turb::ChannelImage TargetSource::readMotionVdb(const std::string& path, int frame) const
{
    turbio::ReadOptions ro = mArgs.read;
    ro.requireDensity = false;
    ro.readExtras = false;
    ro.cropToSmoke = false; // a 2D motion VDB is an image: every pixel, one size for every frame
    const turb::Frame f = turbio::readFrame(path, frame, ro);
    const turb::CoordBBox b = f.velocity.bbox();
    if (b.dim().z() != 1)
        throw turb::IoError(path + ": a 2D motion VDB has one z layer, this one has " + std::to_string(b.dim().z()));
    // Voxel (i, j) is pixel (i - min, max - j): VDB y points up, image y down.
    const double scale = f.dt / f.lattice().voxelSize;
    turb::ChannelImage m(b.dim().x(), b.dim().y(), 2);
    for (int j = b.min().y(); j <= b.max().y(); ++j)
        for (int i = b.min().x(); i <= b.max().x(); ++i) {
            const turb::Vec3f v = f.velocity(i, j, b.min().z());
            m.at(i - b.min().x(), b.max().y() - j, 0) = float(v.x() * scale);
            m.at(i - b.min().x(), b.max().y() - j, 1) = float(-v.y() * scale);
        }
    return m;
}

} // namespace turb::run::detail
