// turb::run::runPreview: vdbturb preview's run, pictures and contact sheets of caches (turb/run/Preview.h).
#include <turb/run/Preview.h>

#include "RunHelpers.h"

#include <turb/run/Output.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Image.h>
#include <turb/Operators.h>
#include <turb/Parallel.h>
#include <turb/Render.h>
#include <turb/Reorient.h>
#include <turb/Resample.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <sstream>

namespace turb::run {

using detail::fmt;
using detail::secondsSince;

namespace {

using Mode = PreviewMode;
using PreviewArgs = PreviewJob;

struct Input
{
    std::string label;
    turbio::Sequence seq;
    float speedMax = 0.0f, vorticityMax = 0.0f; // fixed colour ranges for the whole run
    float densityScale = 1.0f;                  // --match-density: the density render's extinction times this
    std::optional<turb::CoordBBox> frameBox;    // one camera for the whole run (see below)
    turb::Lattice lattice;                      // frameBox's
    turb::CoordBBox held;                       // the union of the frames' held boxes (before shareCamera)
    int extraMargin = 0;                        // voxels more than the read margin, so a read covers frameBox
    bool still = false;                         // one unnumbered file: drawn in every row
    bool yUp = false;                           // a y-up cache (Houdini): turned so that +y is drawn upward
    bool ownCamera = false;                     // not framed with the first input (another scene): labelled so
};

const char* modeName(Mode m)
{
    switch (m) {
    case Mode::Density: return "density";
    case Mode::Speed: return "speed";
    case Mode::Vorticity: return "vorticity";
    case Mode::Lic: return "LIC";
    }
    return "?";
}

std::string viewName(turb::View v)
{
    for (const auto& [name, view] : previewViews())
        if (view == v) return name;
    return "?";
}

bool needsVelocity(const std::vector<Mode>& modes)
{
    return std::any_of(modes.begin(), modes.end(), [](Mode m) { return m != Mode::Density; });
}

/// The value below which `fraction` of the smoke region's values lie (the whole field if no smoke).
float percentile(const turb::ScalarField& f, const turb::ScalarField* density, double fraction)
{
    std::vector<float> v;
    v.reserve(f.size());
    for (size_t q = 0; q < f.size(); ++q)
        if (!density || density->empty() || density->data()[q] > 0.01f) v.push_back(f.data()[q]);
    if (v.empty()) return 0.0f;
    const size_t k = std::min(v.size() - 1, size_t(fraction * double(v.size() - 1)));
    std::nth_element(v.begin(), v.begin() + long(k), v.end());
    return v[k];
}

/// Sheet columns of one scene (target, source, output) are drawn over the union of their framed world boxes, so they
/// line up at one scale; an up-res is otherwise framed tighter than its target (its margin is in fine voxels). One
/// scene: the box lies inside the first input's and is at least an eighth of its size (a high-res source's smoke
/// inside the target's domain), or it overlaps the first's and, along every axis, their union is at most twice the
/// shorter of the two. Other inputs (another scene that happens to share the origin) keep their own camera, and
/// their labels say so.
void shareCamera(std::vector<Input>& inputs)
{
    using turb::Vec3d;
    const auto world = [](const Input& in) {
        return std::make_pair(in.lattice.indexToWorld(in.frameBox->min().asVec3d() - Vec3d(0.5)),
            in.lattice.indexToWorld(in.frameBox->max().asVec3d() + Vec3d(0.5)));
    };
    if (inputs.size() < 2 || !inputs.front().frameBox) return;
    auto all = world(inputs.front());
    std::vector<Input*> group{&inputs.front()};
    for (size_t i = 1; i < inputs.size(); ++i) {
        if (!inputs[i].frameBox) continue;
        const auto w = world(inputs[i]), first = world(inputs.front());
        bool similar = true, inside = true;
        double extent = 0.0, firstExtent = 0.0;
        for (int a = 0; a < 3; ++a) {
            extent = std::max(extent, w.second[a] - w.first[a]);
            firstExtent = std::max(firstExtent, first.second[a] - first.first[a]);
        }
        for (int a = 0; a < 3; ++a) {
            const double lo = std::min(w.first[a], first.first[a]), hi = std::max(w.second[a], first.second[a]);
            const double shorter = std::min(w.second[a] - w.first[a], first.second[a] - first.first[a]);
            similar =
                similar && w.first[a] < first.second[a] && first.first[a] < w.second[a] && hi - lo <= 2.0 * shorter;
            const double slack = 1e-6 * (first.second[a] - first.first[a]);
            inside = inside && w.first[a] >= first.first[a] - slack && w.second[a] <= first.second[a] + slack;
        }
        // Inside, but tiny (under an eighth of the first's size): drawn at the first's scale it would be a few pixels.
        const bool sameScene = similar || (inside && extent >= firstExtent / 8.0);
        inputs[i].ownCamera = !sameScene;
        if (!sameScene) continue;
        group.push_back(&inputs[i]);
        for (int a = 0; a < 3; ++a) {
            all.first[a] = std::min(all.first[a], w.first[a]);
            all.second[a] = std::max(all.second[a], w.second[a]);
        }
    }
    for (Input* in : group) {
        const Vec3d lo = in->lattice.worldToIndex(all.first) + Vec3d(0.5),
                    hi = in->lattice.worldToIndex(all.second) - Vec3d(0.5);
        turb::CoordBBox b(
            turb::Coord(int(std::floor(lo.x() + 1e-6)), int(std::floor(lo.y() + 1e-6)), int(std::floor(lo.z() + 1e-6))),
            turb::Coord(int(std::ceil(hi.x() - 1e-6)), int(std::ceil(hi.y() - 1e-6)), int(std::ceil(hi.z() - 1e-6))));
        if (turb::isFlat(*in->frameBox)) { // a one-layer (2D) cache keeps its layer
            b.min().z() = in->frameBox->min().z();
            b.max().z() = in->frameBox->max().z();
        }
        in->frameBox = b;
    }
}

/// A thin outline of the domain on a picture (where the smoke can go).
void outline(turb::Image& img) { img.drawRect(0, 0, img.width(), img.height(), turb::Rgb(0.35f)); }

turb::Image render(const turb::Frame& f, Mode m, const PreviewArgs& a, const Input& in)
{
    // A 2D cache (one z layer) is shown in its own plane, whatever --view says: a ray march through one voxel
    // would show almost nothing, so its density is a colour-mapped slice too.
    const bool flat = turb::isFlat(f.hasDensity() ? f.density.bbox() : f.velocity.bbox());
    const turb::View view = flat ? turb::View::Top : a.view;
    switch (m) {
    case Mode::Density: {
        if (flat) {
            turb::SliceSettings s;
            s.view = view;
            s.width = a.width;
            s.map = turb::Colormap::Viridis;
            turb::Image img = turb::renderSlice(f.density, s);
            outline(img);
            return img;
        }
        turb::DensityRenderSettings s;
        s.view = view;
        s.width = a.width;
        s.exposure = a.exposure;
        s.extinction = a.extinction * in.densityScale;
        turb::Image img = turb::renderDensity(f.density, s);
        outline(img);
        return img;
    }
    case Mode::Speed:
    case Mode::Vorticity: {
        const bool speed = m == Mode::Speed;
        turb::SliceSettings s;
        s.view = view;
        s.position = a.slice;
        s.width = a.width;
        s.map = speed ? turb::Colormap::Viridis : turb::Colormap::Magma;
        const float top = speed ? in.speedMax : in.vorticityMax;
        s.maxValue = top > 0.0f ? top : 1.0f;
        return turb::renderSlice(turb::magnitude(speed ? f.velocity : turb::curl(f.velocity)), s);
    }
    case Mode::Lic: {
        turb::LicSettings s;
        s.view = view;
        s.position = a.slice;
        s.width = a.width;
        s.maxSpeed = in.speedMax;
        return turb::renderLic(f.velocity, s);
    }
    }
    return {};
}

std::string cellLabel(const Input& in, Mode m, size_t inputs, size_t modes)
{
    std::string unit;
    if (m == Mode::Speed) unit = " 0-" + fmt("%.3g", in.speedMax) + "/s";
    if (m == Mode::Vorticity) unit = " 0-" + fmt("%.3g", in.vorticityMax) + "/s";
    if (m == Mode::Density && in.densityScale != 1.0f) unit += " (density x" + fmt("%.3g", in.densityScale) + ")";
    if (in.ownCamera) unit += " (own framing)"; // another scene beside the first: not at the first column's scale
    if (inputs > 1 && modes > 1) return in.label + " " + modeName(m) + unit;
    if (inputs > 1) return in.label + unit;
    return std::string(modeName(m)) + unit;
}

// What a run draws: the caches (columns), the frames (rows), the modes and how frames are read.
struct PreviewPlan
{
    std::vector<Mode> modes;
    std::vector<Input> inputs;
    std::vector<int> frames;
    turbio::ReadOptions read;
};

bool exists(const Input& in, int frame)
{
    return in.still || std::find(in.seq.frames.begin(), in.seq.frames.end(), frame) != in.seq.frames.end();
}

// A still's one file is read as its own frame number, whatever the row.
int fileFrame(const Input& in, int frame) { return in.still && !in.seq.frames.empty() ? in.seq.frames.front() : frame; }

std::vector<Input> resolveInputs(const PreviewArgs& a)
{
    std::vector<Input> inputs;
    for (const auto& text : a.inputs) {
        Input in;
        std::string pattern = text;
        const auto eq = text.find('=');
        if (eq != std::string::npos && eq > 0 && text.find('/') > eq) {
            in.label = text.substr(0, eq);
            pattern = text.substr(eq + 1);
        }
        // A sheet picks its rows from the frames asked for; missing frames show as empty cells.
        in.seq = turbio::resolveSequence(pattern, a.sheet.empty() ? a.frames : "");
        in.still = !in.seq.pattern.numbered();
        if (in.label.empty()) {
            const std::string p = in.seq.pattern.str();
            const auto slash = p.find_last_of('/');
            in.label = slash == std::string::npos ? p : p.substr(slash + 1);
        }
        inputs.push_back(std::move(in));
    }
    return inputs;
}

// Rows: the frames asked for; for a sheet without --frames, three frames spread over the first cache.
std::vector<int> rowFrames(const PreviewArgs& a, const std::vector<Input>& inputs)
{
    std::vector<int> frames;
    if (!a.frames.empty()) frames = turbio::parseFrameList(a.frames);
    else if (!a.sheet.empty()) {
        // The first sequence's frames; a single file has one "frame" and is drawn in every row.
        const Input* first = &inputs.front();
        for (const auto& in : inputs)
            if (!in.still) {
                first = &in;
                break;
            }
        const auto& f = first->seq.frames;
        if (f.empty()) throw turb::IoError(first->seq.pattern.str() + ": no frames on disk");
        for (double t : {1.0 / 3.0, 2.0 / 3.0, 1.0}) {
            const int n = f[size_t(std::lround(t * double(f.size() - 1)))];
            if (frames.empty() || frames.back() != n) frames.push_back(n);
        }
    } else {
        frames = inputs.front().seq.frames;
        for (const auto& in : inputs)
            if (!in.still) {
                frames = in.seq.frames;
                break;
            }
    }
    if (frames.empty()) throw turb::IoError("no frames to preview");
    return frames;
}

// Which way is up in a cache: --up, else the vdbturb_up_axis metadata, else y for Houdini's files (its world is y
// up and its VDBs say so only through their creator), else z (Blender, EmberGen, vdbturb's scenes).
void chooseUpAxis(const std::string& up, Input& in, int frame)
{
    std::string why;
    in.yUp = upAxisOf(in.seq.path(frame), up, why) == 1;
    if (in.yUp && !why.empty()) logInfo(in.label + ": drawn with +y up (" + why + "; --up z draws it as stored)");
}

// Every picture's frames, checked before the first is drawn, and one camera per input for the whole run. Returns
// the files the pictures are drawn from.
std::vector<std::string> checkAndFrame(PreviewPlan& p, const std::string& up)
{
    std::vector<std::string> inputPaths;
    for (auto& in : p.inputs) {
        const turbio::SequenceScan scan =
            checkInput("preview", in.label, in.seq, in.still ? in.seq.frames : p.frames, p.read, LatticePolicy::Report);
        for (int f : p.frames)
            if (exists(in, f)) inputPaths.push_back(in.seq.path(fileFrame(in, f)));
        // Every frame is drawn over the union of the frames' domains (a Blender domain, else the union of the grids'
        // active boxes), so a flipbook does not jump in size as the smoke grows and sheet columns stay in line.
        // Frames on different lattices keep their own boxes.
        if (scan.changes.empty()) {
            for (const auto& fs : scan.frames) {
                if (!fs.error.empty() || !fs.domainKnown || fs.domain.empty()) continue;
                // A transfer output records its target's domain: framed over it, the output column lines up with
                // the target's even where the output holds only the smoke's neighbourhood.
                turb::CoordBBox box = fs.domain;
                if (fs.sequenceDomain && !fs.sequenceDomain->empty()) box.expand(*fs.sequenceDomain);
                if (!in.frameBox) in.frameBox = box;
                else in.frameBox->expand(box);
                in.lattice = fs.lattice;
            }
        }
        if (in.frameBox) in.held = *in.frameBox;
        for (int f : p.frames)
            if (exists(in, f)) {
                chooseUpAxis(up, in, fileFrame(in, f));
                break;
            }
    }
    shareCamera(p.inputs);
    // A shared camera can reach past what a read holds (the smoke and its margin): read that much more, so the
    // velocity there is the cache's and not a zero-filled rim (a false box in speed and vorticity slices).
    for (auto& in : p.inputs)
        if (in.frameBox && !in.held.empty())
            for (int ax = 0; ax < 3; ++ax)
                in.extraMargin = std::max({in.extraMargin, in.held.min()[ax] - in.frameBox->min()[ax],
                    in.frameBox->max()[ax] - in.held.max()[ax]});
    return inputPaths;
}

// The pictures' paths, checked against the inputs. Throws UsageError saying why.
void checkOutputPaths(const PreviewArgs& a, const PreviewPlan& p, const std::vector<std::string>& inputPaths)
{
    if (a.sheet.empty() && p.frames.size() > 1 && !turbio::FramePattern::parse(a.out).numbered()) {
        throw UsageError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(p.frames.size()) +
                         " frames are requested; every frame would overwrite the last");
    }
    std::vector<std::string> outputs;
    if (a.sheet.empty())
        for (int f : p.frames) outputs.push_back(turbio::FramePattern::parse(a.out).format(f));
    else outputs.push_back(a.sheet);
    checkOutputs(outputs, inputPaths, false, false);
    try {
        turbio::outputFormatOf(a.sheet.empty() ? a.out : a.sheet); // an unknown extension fails before any drawing
                                                                   // (after "out is an input", the worse mistake)
    } catch (const turb::ValueError& e) {
        throw UsageError(e.what(), e.settings());
    }
}

// The input's frame of the last row that it has (none: nullopt), its density and velocity both optional.
std::optional<turb::Frame> lastRowFrame(const Input& in, const PreviewPlan& p)
{
    int ref = -1;
    for (auto it = p.frames.rbegin(); it != p.frames.rend() && ref < 0; ++it)
        if (exists(in, *it)) ref = *it;
    if (ref < 0) return std::nullopt;
    turbio::ReadOptions ro = p.read;
    ro.requireDensity = ro.requireVelocity = false;
    ro.cropMargin += in.extraMargin;
    return turbio::readFrame(in.seq.path(fileFrame(in, ref)), fileFrame(in, ref), ro);
}

// Fixed ranges for the whole run, from each input's last-row frame (read once), so sequences do not flicker.
// Colours: speed shares one range across caches (same world units, comparable); vorticity grows with resolution, so
// each cache gets its own. --match-density: each cache's density drawn at the first cache's peak. Blender's noise
// up-res writes its density at about f times its base's peak (8x at f = 8): drawn as written it is 8 times as
// opaque as its own target and its edges look harder than the same shape at the target's density.
void fixedRanges(const PreviewArgs& a, PreviewPlan& p)
{
    const bool velocity = needsVelocity(p.modes);
    const bool density = a.matchDensity && std::find(p.modes.begin(), p.modes.end(), Mode::Density) != p.modes.end();
    if (!velocity && !density) return;
    float speedAll = a.speedMax, firstPeak = 0.0f;
    for (size_t i = 0; i < p.inputs.size(); ++i) {
        Input& in = p.inputs[i];
        std::optional<turb::Frame> last = lastRowFrame(in, p);
        if (!last) continue;
        turb::Frame& f = *last;
        if (density && f.hasDensity()) {
            float peak = 0.0f;
            for (float v : f.density.values()) peak = std::max(peak, v);
            if (peak > 0.0f && i == 0) firstPeak = peak;
            else if (peak > 0.0f && firstPeak > 0.0f) in.densityScale = firstPeak / peak;
        }
        if (!velocity || !f.hasVelocity()) continue;
        turb::toTimeUnit(f, 1.0); // one speed scale for every column: world units per second
        const turb::ScalarField* d = f.hasDensity() ? &f.density : nullptr;
        in.speedMax = a.speedMax > 0.0f ? a.speedMax : percentile(turb::magnitude(f.velocity), d, 0.995);
        in.vorticityMax =
            a.vorticityMax > 0.0f ? a.vorticityMax : percentile(turb::magnitude(turb::curl(f.velocity)), d, 0.99);
        if (a.speedMax <= 0.0f) speedAll = std::max(speedAll, in.speedMax);
    }
    if (velocity)
        for (auto& in : p.inputs) in.speedMax = speedAll > 0.0f ? speedAll : 1.0f;
}

// One row: every cache's pictures of `frame` in every mode (empty where the cache lacks the frame), labelled.
std::vector<turb::Image> renderRow(
    const PreviewArgs& a, const PreviewPlan& p, int frame, FrameProgress& progress, std::vector<std::string>& labels)
{
    std::vector<turb::Image> images;
    for (const auto& in : p.inputs) {
        std::optional<turb::Frame> f;
        if (exists(in, frame)) {
            progress.begin("reading " + in.label);
            turbio::ReadOptions ro = p.read;
            ro.cropMargin += in.extraMargin;
            f = turbio::readFrame(in.seq.path(fileFrame(in, frame)), fileFrame(in, frame), ro);
            turb::toTimeUnit(*f, 1.0);
            if (in.frameBox) {
                if (f->hasDensity()) f->density = turb::cropped(f->density, *in.frameBox);
                if (f->hasVelocity()) f->velocity = turb::cropped(f->velocity, *in.frameBox);
            }
            // The views draw +z up: a y-up cache is turned a quarter about x, once for all its modes (+y onto +z,
            // exactly: voxels move, nothing is resampled); a 2D cache is drawn in its own plane either way.
            if (in.yUp && !turb::isFlat(f->bbox())) f = turb::reorientFrame(*f, turb::AxisRotation::quarterTurns(0, 1));
        } else {
            logWarning(in.seq.path(frame) + ": missing, left empty");
        }
        for (Mode m : p.modes) {
            progress.begin(std::string("rendering ") + modeName(m));
            const bool drawable = f && (m == Mode::Density ? f->hasDensity() : f->hasVelocity());
            images.push_back(drawable ? render(*f, m, a, in) : turb::Image());
            labels.push_back(f && !drawable ? in.label + " " + modeName(m) +
                                                  (m == Mode::Density ? " (no density)" : " (no velocity)")
                                            : cellLabel(in, m, p.inputs.size(), p.modes.size()));
        }
    }
    return images;
}

// The world box each input is drawn over (one camera per scene) and its density scale, for the frame's JSON line.
nlohmann::json framedJson(const std::vector<Input>& inputs)
{
    nlohmann::json extra;
    for (const auto& in : inputs)
        if (in.frameBox) {
            const turb::Vec3d lo = in.lattice.indexToWorld(in.frameBox->min().asVec3d() - turb::Vec3d(0.5)),
                              hi = in.lattice.indexToWorld(in.frameBox->max().asVec3d() + turb::Vec3d(0.5));
            const auto clean = [](double x) { return std::round(x * 1e9) / 1e9; }; // no 1.9999999999999858
            extra["framed"][in.label] = {
                clean(lo.x()), clean(lo.y()), clean(lo.z()), clean(hi.x()), clean(hi.y()), clean(hi.z())};
            extra["density_scale"][in.label] = in.densityScale;
        }
    return extra;
}

// One picture per frame: a single image, or the modes side by side as a one-row sheet. Returns its path.
std::string writePicture(const PreviewArgs& a, const PreviewPlan& p, int frame, const std::vector<turb::Image>& images,
    const std::vector<std::string>& labels)
{
    turb::Image pic;
    if (images.size() == 1) pic = images.front();
    else {
        std::vector<std::vector<turb::SheetCell>> one(1);
        for (size_t c = 0; c < images.size(); ++c) one[0].push_back({&images[c], labels[c]});
        pic = turb::contactSheet(one, {}, p.inputs.front().label + "  frame " + std::to_string(frame), 1);
    }
    const std::string path = turbio::FramePattern::parse(a.out).format(frame);
    turbio::ensureParentDirectory(path);
    turbio::writeImage(path, pic);
    return path;
}

void writeSheet(const PreviewArgs& a, const PreviewPlan& p, const std::vector<std::vector<turb::SheetCell>>& rows,
    const std::vector<std::string>& rowLabels)
{
    std::string title = a.title;
    if (title.empty()) {
        for (const auto& in : p.inputs) title += (title.empty() ? "" : " | ") + in.label;
        bool allFlat = true; // 2D caches are drawn in their own x-y plane whatever --view says
        for (const auto& in : p.inputs) allFlat = allFlat && in.frameBox && turb::isFlat(*in.frameBox);
        title += allFlat ? std::string("  (x-y plane)") : "  (" + viewName(a.view) + " view)";
    }
    const turb::Image sheet = turb::contactSheet(rows, rowLabels, title, 2);
    turbio::ensureParentDirectory(a.sheet);
    turbio::writeImage(a.sheet, sheet);
    logInfo("wrote " + a.sheet + " (" + std::to_string(sheet.width()) + "x" + std::to_string(sheet.height()) + ")");
}

// Draws every row: a picture per frame, or the rows of one sheet. Returns the files written.
std::vector<std::string> drawRows(const PreviewArgs& a, PreviewPlan& p)
{
    fixedRanges(a, p);
    reporter().runStarted("preview");
    std::vector<std::string> written;
    std::vector<std::vector<turb::Image>> rowImages;
    std::vector<std::vector<turb::SheetCell>> rows;
    std::vector<std::string> rowLabels;
    for (size_t r = 0; r < p.frames.size(); ++r) {
        const int frame = p.frames[r];
        const auto t0 = std::chrono::steady_clock::now();
        const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(int(r), int(p.frames.size()), frame);
        std::vector<std::string> labels;
        std::vector<turb::Image> images = renderRow(a, p, frame, *progress, labels);
        progress->clear();
        nlohmann::json extra = framedJson(p.inputs);
        if (a.sheet.empty()) {
            const std::string path = writePicture(a, p, frame, images, labels);
            written.push_back(path);
            extra["out"] = path;
            reporter().frameDone(
                FrameRecord{frame, int(r), int(p.frames.size()), secondsSince(t0), "-> " + path, extra});
        } else {
            rowImages.push_back(std::move(images));
            rowLabels.push_back("frame " + std::to_string(frame));
            std::vector<turb::SheetCell> cells;
            for (size_t c = 0; c < rowImages.back().size(); ++c)
                cells.push_back({rowImages.back()[c].empty() ? nullptr : &rowImages.back()[c], labels[c]});
            rows.push_back(std::move(cells));
            reporter().frameDone(FrameRecord{frame, int(r), int(p.frames.size()), secondsSince(t0), "rendered", extra});
        }
    }
    if (!a.sheet.empty()) {
        writeSheet(a, p, rows, rowLabels);
        written.push_back(a.sheet);
    }
    reporter().runFinished(0, nlohmann::json::object());
    return written;
}

// The plan: the modes, the caches and their rows, how they are read. Throws UsageError for options that do not go
// together (CLI11 cannot express them; the CLI's exit 2).
PreviewPlan planPreview(const PreviewArgs& a)
{
    PreviewPlan p;
    p.modes = parsePreviewModes(a.modes);
    if (a.sheet.empty() && a.out.empty())
        throw UsageError("give --out PATTERN.png|.exr (one picture per frame) or --sheet FILE.png|.exr");
    if (a.sheet.empty() && a.inputs.size() > 1)
        throw UsageError("several caches go side by side into a contact sheet: add --sheet FILE.png");
    p.inputs = resolveInputs(a);
    p.frames = rowFrames(a, p.inputs);
    p.read = a.read;
    // A sheet may set a density-only cache (Blender's noise up-res) beside others: its velocity cells are left
    // empty, labelled. One cache alone must have what its modes draw.
    p.read.requireVelocity = needsVelocity(p.modes) && p.inputs.size() == 1;
    p.read.requireDensity = std::find(p.modes.begin(), p.modes.end(), Mode::Density) != p.modes.end();
    p.read.readExtras = false;
    return p;
}

// A dry run's plan: every input's headers were read to frame the pictures, and the output paths checked.
void printPlan(const PreviewArgs& a, const PreviewPlan& p)
{
    const std::string what = std::to_string(p.inputs.size()) + " cache" + (p.inputs.size() == 1 ? "" : "s") + " x " +
                             std::to_string(p.modes.size()) + " mode" + (p.modes.size() == 1 ? "" : "s");
    if (!a.sheet.empty())
        printData("would write " + a.sheet + " (a sheet: " + std::to_string(p.frames.size()) + " rows, " + what + ")");
    else
        for (int f : p.frames)
            printData("would write " + turbio::FramePattern::parse(a.out).format(f) + " (frame " + std::to_string(f) +
                      ", " + what + ")");
}

} // namespace

std::vector<PreviewMode> parsePreviewModes(const std::string& text)
{
    std::vector<Mode> modes;
    std::stringstream ss(text);
    std::string m;
    while (std::getline(ss, m, ',')) {
        if (m == "density") modes.push_back(Mode::Density);
        else if (m == "speed") modes.push_back(Mode::Speed);
        else if (m == "vorticity") modes.push_back(Mode::Vorticity);
        else if (m == "lic") modes.push_back(Mode::Lic);
        else if (m == "all") modes.insert(modes.end(), {Mode::Density, Mode::Speed, Mode::Vorticity, Mode::Lic});
        else throw turb::ValueError("--mode: unknown mode '" + m + "' (density, speed, vorticity, lic, all)");
    }
    if (modes.empty()) throw turb::ValueError("--mode: no mode given");
    return modes;
}

const std::vector<std::pair<std::string, turb::View>>& previewViews()
{
    static const std::vector<std::pair<std::string, turb::View>> views{
        {"front", turb::View::Front}, {"side", turb::View::Side}, {"top", turb::View::Top}};
    return views;
}

PreviewRun runPreview(const PreviewJob& a)
{
    PreviewPlan p = planPreview(a);
    const std::vector<std::string> inputPaths = checkAndFrame(p, a.up);
    checkOutputPaths(a, p, inputPaths);
    PreviewRun run;
    if (a.dryRun) printPlan(a, p);
    else turb::withThreads(a.threads, [&] { run.written = drawRows(a, p); });
    return run;
}

} // namespace turb::run
