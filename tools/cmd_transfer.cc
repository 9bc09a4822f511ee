// vdbturb transfer: turbulence style transfer (Sato et al. 2018) from a high-res source onto a low-res target.
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"

#include <turb/Budget.h>
#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Resample.h>
#include <turb/Metadata.h>
#include <turb/Transfer.h>
#include <turbio/Scan.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <future>
#include <memory>
#include <optional>
#include <sstream>

namespace vdbturb {

namespace {

// The settings with a 3D and a 2D form: the two options, and the 3D one's name in the recorded settings text
// (the 2D one's is that name with "-2d"). Given for the other kind of cache, an option has no effect.
struct KindTwin
{
    const char *option3D, *option2D, *recorded3D;
};
constexpr KindTwin kKindTwins[] = {{"--seams.bandWidth", "--seams.bandWidth2D", "band"},
    {"--seams.cgTolerance", "--seams.cgTolerance2D", "cg-tolerance"},
    {"--detailEnergy", "--detailEnergy2D", "detail-energy"},
    {"--regenerateBlend", "--regenerateBlend2D", "regenerate-blend"},
    {"--structureTolerance", "--structureTolerance2D", "structure-tolerance"}};

struct TransferArgs
{
    std::string target, source, out;
    std::string frames, sourceFrames;
    int sourceOffset = 0;
    turbio::SourceWrap wrap = turbio::SourceWrap::Loop;
    bool resume = false, json = false;
    int preroll = 0;
    turbio::ReadOptions targetRead;
    turbio::ReadOptions sourceRead = [] {
        // Only the source: Blender clips velocity to the smoke and the zeros beyond would read as turbulence at its
        // edge. The target's velocity stays as stored: the output keeps the target's coarse motion as the file has it.
        turbio::ReadOptions r;
        r.extendVelocity = 4;
        return r;
    }();
    const CLI::Option* sourceCropMargin = nullptr; ///< given or not: its default depends on the ratio
    const CLI::Option* velocityMargin = nullptr;   ///< given or not: --style blender ignores it, saying so if given
    /// kKindTwins' options as parsed (3D, 2D): one given for the other kind of cache gets a warning.
    std::vector<std::pair<const CLI::Option*, const CLI::Option*>> kindTwins;
    std::string tileBox; ///< "X0,Y0,Z0,X1,Y1,Z1": hold only this box of the target (a space tile and its halo)
    turbio::WriteOptions write = upResWriteDefaults();
    turb::TransferSettings settings;
    /// Set by planFrames: "F-" when the requested frames begin at F, after the cache's first frame (a task of a
    /// shot's frames, which may write into one folder beside others): it goes into the resume state's file names.
    std::string stateTag;
};

// The source's frequency split and its candidate patches near the smoke's edge reach a few *coarse* voxels past
// the smoke; a margin of 8 source voxels is one coarse voxel at ratio 8 and moved block by 5% and tcoh by 14%
// on the ratio-8 pair (docs/design.md). The default margin is therefore 8 target voxels.
constexpr int kSourceMarginCoarseVoxels = 8;

// The margins the ratio sets: the source's crop margin above, and --velocity-margin auto, one target voxel of
// written velocity around the smoke (2 output voxels moved measure's lf_err by 13% at ratio 8: docs/io.md, Size).
void defaultMargins(
    TransferArgs& a, const turbio::Sequence& target, const turbio::Sequence& source, const std::vector<int>& sourceFor)
{
    if (target.frames.empty()) return;
    try {
        const double tv = turbio::scanFrame(target.path(target.frames.front()), target.frames.front(), a.targetRead)
                              .lattice.voxelSize;
        const double sv =
            turbio::scanFrame(source.path(sourceFor.front()), sourceFor.front(), a.sourceRead).lattice.voxelSize;
        const int ratio = turb::transferRatio(tv, sv, a.settings.resampleSource);
        resolveVelocityMargin(a.write, ratio);
        if (a.sourceCropMargin->count() == 0 && a.sourceRead.cropToSmoke)
            a.sourceRead.cropMargin = std::max(a.sourceRead.cropMargin, kSourceMarginCoarseVoxels * ratio);
    } catch (const std::exception&) {
        // The preflight reports an unreadable frame or a bad ratio with its own message.
    }
}

std::string wrapName(turbio::SourceWrap w)
{
    switch (w) {
    case turbio::SourceWrap::PingPong: return "pingpong";
    case turbio::SourceWrap::Clamp: return "clamp";
    case turbio::SourceWrap::Error: return "error";
    default: return "loop";
    }
}

std::string fmt(const char* f, double v)
{
    char b[64];
    std::snprintf(b, sizeof(b), f, v);
    return b;
}

std::string dims(const turb::Coord& d)
{
    return std::to_string(d.x()) + "x" + std::to_string(d.y()) + "x" + std::to_string(d.z());
}

std::string worldBox(const turb::CoordBBox& b, const turb::Lattice& l)
{
    const turb::Vec3d lo = l.indexToWorld(b.min().asVec3d() - turb::Vec3d(0.5));
    const turb::Vec3d hi = l.indexToWorld(b.max().asVec3d() + turb::Vec3d(0.5));
    char buf[160];
    const auto clean = [](double x) { return std::abs(x) < 1e-9 ? 0.0 : x; }; // 4e-17 is rounding, not a place
    std::snprintf(buf, sizeof(buf), "(%.4g,%.4g,%.4g)-(%.4g,%.4g,%.4g)", clean(lo.x()), clean(lo.y()), clean(lo.z()),
        clean(hi.x()), clean(hi.y()), clean(hi.z()));
    return buf;
}

// Voxels of the frame's velocity box padded by two voxels (clipped to its domain), from the header.
double velocityBoxVoxels(const turbio::FrameScan& fr)
{
    for (const auto& g : fr.grids)
        if (g.selector == fr.velocityGrid && g.hasBBox) {
            turb::CoordBBox b = g.activeBBox;
            b.expand(2);
            b.intersect(fr.domain);
            return double(b.volume());
        }
    return double(fr.domain.volume());
}

// A frame written trimmed to the smoke, in half floats, Blender style or in another time unit than the target's is
// not the state the next frame starts from. The exact state is then kept beside the outputs in two files that take
// turns, odd and even frames, each written before its frame: whichever write a kill cuts, the state of the last
// whole frame survives. Two frames' disk, not the sequence's. "up/turb.####.vdb" keeps "up/turb.resume-state-odd.vdb"
// and "-even", visible names that no frame pattern takes (a hidden file was picked up by publish tools unseen). None
// for a single unnumbered file. A run whose frames begin after the cache's first frame, F, names them
// "turb.resume-state-F-odd.vdb": tasks on other frames of the shot, writing into one folder at once, each keep
// their own (with one pair, each overwrote the others' and a killed task resumed approximately). The slot a frame
// writes is stateSlot's: its parity's, unless the frame before took that one.
std::string resumeStatePath(const turbio::FramePattern& out, const TransferArgs& a, double timeUnit, int frame)
{
    const turbio::WriteOptions& w = a.write;
    // A Houdini-style frame holds velocity per second: scaling a Blender target's time unit back is not exact.
    const bool lossy = w.velocityMargin >= 0 || w.halfFloat || w.velocityVoxelScale > 1 || !w.writeVelocity ||
                       w.style == turbio::WriteStyle::Blender || timeUnit != 1.0;
    // NanoVDB output cannot be resumed (checkOutputFormat): no state to keep.
    const bool nano = turbio::outputFormatFor(out.format(0), w.format) == turbio::OutputFormat::NanoVdb;
    if (!lossy || !out.numbered() || nano) return {};
    return out.prefix() + "resume-state-" + a.stateTag + ((frame & 1) ? "odd" : "even") + out.suffix();
}

// Everything the run needs, checked before its first frame (and all a dry run does): every target and source
// frame's headers, one lattice per sequence, the ratio, the output paths, the memory. Returns the target's whole
// domain over the frames, refined to the output lattice (framing metadata; empty when there are no frames).
turb::CoordBBox preflight(const TransferArgs& a, const turbio::Sequence& target, const turbio::Sequence& source,
    const std::vector<int>& sourceFor, const turbio::FramePattern& outPattern, size_t first)
{
    const std::vector<int> targetFrames(target.frames.begin() + long(first), target.frames.end());
    std::vector<int> sourceFrames(sourceFor.begin() + long(first), sourceFor.end());
    std::sort(sourceFrames.begin(), sourceFrames.end());
    sourceFrames.erase(std::unique(sourceFrames.begin(), sourceFrames.end()), sourceFrames.end());
    if (targetFrames.empty()) return {};
    const turbio::SequenceScan ts =
        checkInput("transfer", "target", target, targetFrames, a.targetRead, LatticePolicy::Refuse, "target");
    const turbio::SequenceScan ss =
        checkInput("transfer", "source", source, sourceFrames, a.sourceRead, LatticePolicy::Refuse, "source");
    reportTiming("target", ts, true, "target");
    reportTiming("source", ss, true, "source");
    if (!ss.frames.empty() && ss.frames.front().timing.cells && a.sourceRead.extendVelocity > 0)
        logInfo("source: Blender clips its velocity to the smoke; the detail is calibrated to it continued " +
                std::to_string(a.sourceRead.extendVelocity) + " voxels past the edge, at full strength from the " +
                "first frame. Measure it so (vdbturb measure --source-extend-velocity " +
                std::to_string(a.sourceRead.extendVelocity) + "): against the clipped source the edge's step " +
                "counts as turbulence and the first frames' hf_ratio reads low (0.17 at frame 1 of Blender plume2, " +
                "1.12 so measured)");

    const turbio::FrameScan& t0 = ts.frames.front();
    const turbio::FrameScan& s0 = ss.frames.front();
    const double tv = t0.lattice.voxelSize, sv = s0.lattice.voxelSize;
    const int f = turb::transferRatio(tv, sv, a.settings.resampleSource); // throws, saying why, where the run would
    const bool resampled = !turb::isIntegerRatio(tv, sv);
    const turbio::FrameScan* tl = ts.largestDomain();
    const turbio::FrameScan* sl = ss.largestDomain();
    const turb::CoordBBox tBox = tl ? tl->domain : t0.domain;
    if (!a.tileBox.empty()) {
        // A tile box is a part of the target's domain: off it, the run would hold (and write) nothing or a vast box
        // of empty space; one voxel thick in a 3D cache, it would read as a 2D cache.
        turb::CoordBBox spans;
        for (const turbio::FrameScan& fs : ts.frames) spans.expand(fs.span);
        const turb::CoordBBox& tb = a.targetRead.holdBox;
        // Checked when a run starts: a resumed one scans only its remaining frames, whose grids (a sparse cache's)
        // may no longer reach the box that the whole shot's did.
        if (first == 0 && !spans.isInside(tb))
            throw turb::ValueError("--tile-box " + a.tileBox + " is not inside the target's domain " +
                                   std::to_string(spans.min().x()) + "," + std::to_string(spans.min().y()) + "," +
                                   std::to_string(spans.min().z()) + "," + std::to_string(spans.max().x()) + "," +
                                   std::to_string(spans.max().y()) + "," + std::to_string(spans.max().z()) +
                                   " (the frames' grids, in target voxels)");
        if (turb::isFlat(tb) != turb::isFlat(spans))
            throw turb::ValueError("--tile-box " + a.tileBox + " is one voxel thick in z, but the target is 3D: " +
                                   "a tile of a 3D cache must be at least 2 voxels thick");
    }
    // As process() refuses it at the first frame, so that a dry run says so too.
    // Frames without smoke (an empty first frame's 1-voxel placeholder) say nothing of the kind.
    if (tl && sl && !tl->span.empty() && !sl->span.empty() && turb::isFlat(tBox) != turb::isFlat(sl->domain))
        throw turb::ValueError(turb::isFlat(tBox)
                                   ? "the target is 2D (one z layer) but the source is not: give a 2D source"
                                   : "the target is 3D but the source is 2D (one z layer)");
    const double tVoxels = double(tBox.volume());
    const double sVoxels = sl ? double(sl->domain.volume()) : 0.0;
    const turb::Lattice outLattice = turb::refinedLattice(t0.lattice, tBox, f);
    const turb::Coord outDim = turb::refineDomain(tBox, f).dim(); // a 2D target keeps its one z layer
    printData("ratio " + fmt("%.4g", tv / sv) + " (target voxel " + fmt("%g", tv) + ", source voxel " + fmt("%g", sv) +
              ")" +
              (resampled ? ": not an integer, the source is resampled trilinearly to ratio " + std::to_string(f) : ""));
    printData("output lattice: " + dims(outDim) + " voxels of " + fmt("%g", outLattice.voxelSize) + ", world " +
              worldBox(tBox, t0.lattice) +
              (a.tileBox.empty() ? " (the target's held box: its smoke and margin" : " (the tile box --tile-box") +
              (tl && tl->frame != t0.frame ? " at frame " + std::to_string(tl->frame) + ", its largest" : "") + ")");

    {
        // The settings with a 2D twin: say which apply, as a 2D cache silently takes other values.
        const bool flat = turb::isFlat(tBox);
        const turb::TransferSettings& st = a.settings;
        printData(std::string(flat ? "2D cache (one z layer): B^2 patches; " : "3D cache: ") + "detail energy " +
                  turb::detailEnergyName(flat ? st.detailEnergy2D : st.detailEnergy) + ", seam band " +
                  std::to_string(flat ? st.seams.bandWidth2D : st.seams.bandWidth) + ", regenerate blend " +
                  fmt("%g", flat ? st.regenerateBlend2D : st.regenerateBlend) + ", seam CG tolerance " +
                  fmt("%g", flat ? st.seams.cgTolerance2D : st.seams.cgTolerance) + ", structure tolerance " +
                  fmt("%g", flat ? st.structureTolerance2D : st.structureTolerance) +
                  (flat ? " (detailEnergy2D, seams.bandWidth2D, regenerateBlend2D, seams.cgTolerance2D, "
                          "structureTolerance2D)"
                        : ""));
        for (const auto& [threeD, twoD] : a.kindTwins)
            if ((flat ? threeD : twoD)->count() > 0)
                logWarning((flat ? threeD : twoD)->get_name() + " is for " + (flat ? "3D" : "2D") +
                           " caches and has no effect on this " + (flat ? "2D" : "3D") +
                           " target: " + (flat ? twoD : threeD)->get_name() + " is the one that applies");
    }
    // Output size (Blosc gains little on noisy floats). Velocity covers the target velocity's box padded by two
    // voxels, at f^3 voxels each (zero beyond it: not written), or trimmed, the smoke and the margin's shell
    // (1.2x the smoke at margin 1, 1.45x at 2 on the Blender plume2 pair at 128^3).
    // The smoke, where density and temperature are written, is the target's smoke cells x f^3 and the up-sampling's
    // spread (1.2x: 0.93-1.0x from frame 2 on, 1.5x at frame 1's compact puff, on plume2). Headers count active
    // cells, and many of a cache's are thin tails below any smoke threshold (a third of plume2-32's at frame 30):
    // the largest frame, read once, gives the share that is smoke, applied to every frame.
    double smokeShare = 1.0;
    {
        const auto largest = std::max_element(ts.frames.begin(), ts.frames.end(),
            [](const turbio::FrameScan& x, const turbio::FrameScan& y) { return x.densityActive < y.densityActive; });
        if (largest->densityActive > 0) {
            const turb::Frame fr = turbio::readFrame(largest->path, largest->frame, a.targetRead);
            const float thr = std::max(a.write.densityTolerance, a.write.smokeThreshold);
            const float* d = fr.density.data();
            const double smokeCells = double(std::count_if(d, d + fr.density.size(), [&](float v) { return v > thr; }));
            smokeShare = std::min(1.0, smokeCells / double(largest->densityActive));
        }
    }
    const bool trimmed = a.write.velocityMargin >= 0 && a.write.style == turbio::WriteStyle::Houdini;
    // NanoVDB stores no half floats and compresses nothing: vel is 4 bytes a component, density its quantisation, in
    // whole 8^3 leaves (0.55 of a leaf's voxels active on plume2's frame 10 at 128^3), plus about 300 kB of internal
    // node tables a grid (docs/nanovdb.md, Size).
    const bool nano = turbio::outputFormatFor(outPattern.format(0), a.write.format) == turbio::OutputFormat::NanoVdb;
    const double leafFill = nano ? 0.55 : 1.0, gridTables = nano ? 4 * 300e3 : 0.0;
    const double floatBytes = nano ? 4.0 : a.write.halfFloat ? 2.0 : 4.0;
    const double scalarBytes = !nano                                                        ? floatBytes
                               : a.write.nanoQuantization == turbio::NanoQuantization::Fp16 ? 2.0
                               : a.write.nanoQuantization == turbio::NanoQuantization::Fp8  ? 1.0
                                                                                            : 4.0;
    const double box = double(outDim.x()) * outDim.y() * outDim.z();
    double outBytes = 0.0, totalBytes = 0.0, stateBytes = 0.0; // the largest frame's, the run's (summed), state's
    for (const auto& fr : ts.frames) {
        const double cells = double(f) * f * (turb::isFlat(tBox) ? 1.0 : f);
        const double smoke = std::min(box,
            1.2 * cells * (fr.densityActive > 0 ? smokeShare * double(fr.densityActive) : double(fr.domain.volume())));
        const double whole = std::min(box, cells * velocityBoxVoxels(fr));
        const double scale = a.write.style == turbio::WriteStyle::Houdini ? a.write.velocityVoxelScale : 1.0;
        const double vel = !a.write.writeVelocity
                               ? 0.0
                               : (trimmed ? std::min(whole, smoke * (1.0 + 0.25 * a.write.velocityMargin)) : whole) /
                                     (turb::isFlat(tBox) ? scale * scale : scale * scale * scale);
        const double bytes = (floatBytes * 3.0 * vel + scalarBytes * 2.0 * smoke) / leafFill + gridTables;
        outBytes = std::max(outBytes, bytes);
        totalBytes += bytes;
        stateBytes = std::max(stateBytes, 12.0 * whole + 4.0 * smoke);
    }
    printData("output size: about " + turbio::formatBytes(outBytes) + " for the largest frame, " +
              turbio::formatBytes(totalBytes) + " for " + std::to_string(targetFrames.size()) + " frame" +
              (targetFrames.size() == 1 ? "" : "s"));
    const double unit = ts.frames.front().timing.timeUnit;
    if (const std::string odd = resumeStatePath(outPattern, a, unit, 1); !odd.empty())
        printData("resume state: " + odd + " and " + resumeStatePath(outPattern, a, unit, 0) + ", about " +
                  turbio::formatBytes(stateBytes) + " each (odd and even frames in full precision, for --resume)");

    // The source is matched at the ratio's voxel: a non-integer ratio resamples it first.
    const auto matchedVoxels = [&](double sourceVoxel, double voxels, int ratio) {
        return voxels * std::pow(sourceVoxel * ratio / tv, 3.0);
    };
    const double need = turb::transferPeakBytes(tVoxels, f, matchedVoxels(sv, sVoxels, f));
    const long long usable = turbio::usableMemoryBytes();
    std::string fits;
    if (usable > 0 && need > 0.9 * double(usable)) {
        // The smallest box-downsampling of the source (vdbturb resample --down K) that fits.
        for (int down = 2; down <= 64 && fits.empty(); ++down) {
            const double sv2 = sv * down;
            int f2 = 0;
            try {
                f2 = turb::transferRatio(tv, sv2, a.settings.resampleSource);
            } catch (const turb::ValueError&) {
                break; // the ratio fell below 2
            }
            const double n2 = sVoxels / double(down) / double(down) / double(down);
            if (turb::transferPeakBytes(tVoxels, f2, matchedVoxels(sv2, n2, f2)) <= 0.9 * double(usable))
                fits = "A source box-downsampled by " + std::to_string(down) + " (voxel " + fmt("%g", sv2) +
                       ", ratio " + std::to_string(f2) + ") fits: vdbturb resample " + source.pattern.str() +
                       " --down " + std::to_string(down) + " --out PROXY.####.vdb";
        }
        if (fits.empty()) fits = "No coarser source fits: crop or coarsen the target first.";
    }
    checkMemory(need,
        "target " + dims(tBox.dim()) + " at ratio " + std::to_string(f) + " = " + dims(outDim) +
            " output voxels, source " + (sl ? dims(sl->domain.dim()) : std::string("?")),
        fits);

    // The time, frame by frame from each frame's held box (the model's error: docs/performance.md, Time estimate).
    double seconds = 0.0, worst = 0.0;
    for (const turbio::FrameScan& fs : ts.frames) {
        const double s = turb::transferSecondsPerFrame(double(fs.domain.volume()), f, matchedVoxels(sv, sVoxels, f));
        seconds += s;
        worst = std::max(worst, s);
    }
    if (!ts.frames.empty())
        printData("time: about " + fmt("%.2g", seconds / double(ts.frames.size())) + " s/frame on 2 cores (up to " +
                  fmt("%.2g", worst) + "), " +
                  (seconds < 90.0 ? fmt("%.2g", seconds) + " s" : fmt("%.3g", seconds / 60.0) + " min") + " for " +
                  std::to_string(ts.frames.size()) +
                  " frames (the model's totals were within 0.9-1.25x on the bench's pairs, " +
                  "single frames within 2.3x: docs/performance.md)");

    std::vector<std::string> outputs, inputs;
    for (size_t i = first; i < target.frames.size(); ++i) outputs.push_back(outPattern.format(target.frames[i]));
    for (int t : target.frames) inputs.push_back(target.path(t));
    for (int sf : sourceFrames) inputs.push_back(source.path(sf));
    checkOutputs(outputs, inputs, a.write.noClobber, false);
    if (globals().dryRun)
        for (size_t i = first; i < target.frames.size(); ++i)
            if (i < first + 3 || i + 2 >= target.frames.size())
                printData("would write " + outPattern.format(target.frames[i]) + " from target " +
                          target.path(target.frames[i]) + " and source " + source.path(sourceFor[i]));
            else if (i == first + 3)
                printData("  ... " + std::to_string(target.frames.size() - first - 5) + " more frames");
    turb::CoordBBox domain;
    for (const auto& fr : ts.frames)
        if (fr.error.empty() && !fr.span.empty()) domain.expand(fr.span);
    return domain.empty() ? domain : turb::refineDomain(domain, f);
}

// An input sequence as recorded in outputs: the absolute pattern, so a relative spelling of the same cache matches.
std::string inputId(const turbio::Sequence& seq)
{
    return std::filesystem::absolute(seq.pattern.str()).lexically_normal().string();
}

// How the frames are written ("style=houdini;half=1;..."): a resume that wrote them otherwise would leave one
// sequence in two formats.
std::string writeSettingsText(const turbio::WriteOptions& w)
{
    std::ostringstream os;
    os << "style=" << (w.style == turbio::WriteStyle::Blender ? "blender" : "houdini")
       << ";half=" << (w.halfFloat ? 1 : 0) << ";clipping=" << w.densityTolerance
       << ";velocity-margin=" << w.velocityMargin;
    // Recorded only when set, so that frames written before these options existed still compare equal.
    if (w.velocityVoxelScale != 1) os << ";vel-voxel-scale=" << w.velocityVoxelScale;
    if (!w.writeVelocity) os << ";no-velocity=1";
    return os.str();
}

// Continuing with other settings or other inputs would silently mix two looks, or two shots, in one sequence.
void checkResumable(const std::string& prevPath, const turb::Frame& prevOut, const turb::TransferSettings& s,
    const turbio::WriteOptions& w, const turbio::Sequence& target, const turbio::Sequence& source,
    const std::string& tileBox)
{
    std::vector<std::string> diff;
    const auto saved = prevOut.metadata.find(turb::meta::kSettings);
    if (saved != prevOut.metadata.end()) {
        diff = turb::settingsDifferences(saved->second, turb::outputSettingsText(s));
        // Of a setting with a 2D twin ("band", "band-2d"), only the one for the frame's kind matters.
        const bool flat = turb::isFlat(prevOut.velocity.bbox());
        const auto otherKind = [&](const std::string& d) {
            const std::string name = d.substr(0, d.find(':'));
            for (const KindTwin& k : kKindTwins)
                if (name == (flat ? std::string(k.recorded3D) : std::string(k.recorded3D) + "-2d")) return true;
            return false;
        };
        diff.erase(std::remove_if(diff.begin(), diff.end(), otherKind), diff.end());
    } else
        logWarning(
            prevPath + ": no vdbturb_settings metadata (written by an older vdbturb): the settings cannot be checked");
    // Older outputs carry no write settings: nothing to compare them with.
    if (const auto written = prevOut.metadata.find(turb::meta::kWriteSettings); written != prevOut.metadata.end())
        for (const std::string& d : turb::settingsDifferences(written->second, writeSettingsText(w))) diff.push_back(d);
    for (const auto& [key, now] : {std::pair<const char*, std::string>{turb::meta::kTargetInput, inputId(target)},
             std::pair<const char*, std::string>{turb::meta::kSourceInput, inputId(source)}}) {
        const auto m = prevOut.metadata.find(key);
        if (m != prevOut.metadata.end() && m->second != now)
            diff.push_back(
                std::string(key == turb::meta::kTargetInput ? "target" : "source") + ": " + m->second + " -> " + now);
    }
    // A space tile's box: the state continues only on the box it was made over.
    const auto box = prevOut.metadata.find(turb::meta::kTileBox);
    const std::string savedBox = box == prevOut.metadata.end() ? std::string() : box->second;
    if (savedBox != tileBox)
        diff.push_back("tile-box: " + (savedBox.empty() ? std::string("none") : savedBox) + " -> " +
                       (tileBox.empty() ? std::string("none") : tileBox));
    if (diff.empty()) return;
    std::string list;
    for (const std::string& d : diff) list += "\n  " + d;
    throw turb::ValueError(prevPath + " was made with other settings or inputs; --resume continues only the same run:" +
                           list + "\n  (use the saved values, or start again without --resume)");
}

// The state file beside the outputs, when the last output names it and it is that frame's. Without it restore()
// starts from the output itself: exact when it was written whole, approximate when trimmed (said once, here).
std::optional<turb::Frame> resumeStateFrame(const std::string& prevPath, int prev, const turb::Frame& prevOut)
{
    const auto named = prevOut.metadata.find(turb::meta::kResumeStateFile);
    if (named == prevOut.metadata.end()) return std::nullopt;
    const std::string side = (std::filesystem::path(prevPath).parent_path() / named->second).string();
    std::string why;
    if (!std::filesystem::exists(side)) {
        why = "it is missing";
    } else {
        try {
            turbio::ReadOptions ro;
            ro.cropToSmoke = false;
            turb::Frame st = turbio::readFrame(side, prev, ro);
            const auto frame = st.metadata.find(turb::meta::kResumeFrame);
            if (frame == st.metadata.end() || frame->second != std::to_string(prev))
                why = "it holds frame " + (frame == st.metadata.end() ? std::string("?") : frame->second) + ", not " +
                      std::to_string(prev) + ": a run stopped between the two writes, or frames were removed";
            else if (st.metadata[turb::meta::kState] != prevOut.metadata.at(turb::meta::kState))
                why = "it is another run's";
            else return st;
        } catch (const turb::Error& e) {
            why = messageWithFlags(e);
        }
    }
    logWarning("resume: the exact state " + side + " cannot be used: " + why + ". Continuing from " + prevPath +
               " as written: the detail outside its velocity margin starts again, and the frames after differ "
               "slightly from an uninterrupted run's");
    return std::nullopt;
}

// The frames a run processes: the requested ones, the pre-roll before them and where writing and resuming start.
struct FramePlan
{
    turbio::Sequence target, source;
    turbio::FramePattern out;
    std::vector<int> sourceFor; ///< per target frame (pre-roll included): the source frame it reads
    size_t first = 0;           ///< the first frame to process (a resume skips those written)
    size_t writeFrom = 0;       ///< frames before this index are pre-roll: processed, not written
    std::string stateTag;       ///< TransferArgs::stateTag
};

// The source frame of every target frame, as --source-offset and --source-wrap map them.
std::vector<int> sourceFrames(
    const TransferArgs& a, const std::vector<int>& targetFrames, const turbio::Sequence& source)
{
    std::vector<int> out;
    for (int t : targetFrames) {
        try {
            out.push_back(turbio::mapSourceFrame(t, source.frames, a.sourceOffset, a.wrap));
        } catch (const turb::ValueError& e) {
            // --source-wrap maps only frames past the ends; a gap inside the range is another matter.
            const int s = t + a.sourceOffset;
            const bool gap = !source.frames.empty() && s > source.frames.front() && s < source.frames.back();
            throw turb::ValueError(
                std::string(e.what()) + (gap ? "; the source has a gap there: give --source-frames up to the gap (the "
                                               "wrap then maps the rest), or another --source-offset"
                                             : "; --source-offset or another --source-wrap maps it"),
                e.settings());
        }
    }
    return out;
}

// Which source frame each target frame reads: a source numbered otherwise (1001-1012 for a target at 1-12) is
// wrapped silently by the mapping rules, so the plan says how, and warns where the two ranges do not meet.
void reportSourceMapping(const TransferArgs& a, const FramePlan& p)
{
    if (p.target.frames.empty() || p.source.frames.empty()) return;
    const std::vector<int>& t = p.target.frames;
    size_t wrapped = 0;
    for (size_t i = 0; i < t.size(); ++i) wrapped += p.sourceFor[i] != t[i] + a.sourceOffset;
    const int s0 = p.source.frames.front(), s1 = p.source.frames.back();
    std::string line = "source frames: source = target + " + std::to_string(a.sourceOffset) + " (--source-offset)";
    if (wrapped > 0)
        line += ", " + std::to_string(wrapped) + " of " + std::to_string(t.size()) + " wrapped by --source-wrap " +
                wrapName(a.wrap) + " into the source's " + std::to_string(s0) + "-" + std::to_string(s1);
    line += "; target " + std::to_string(t.front()) + " -> source " + std::to_string(p.sourceFor.front());
    if (t.size() > 1)
        line += ", target " + std::to_string(t.back()) + " -> source " + std::to_string(p.sourceFor.back());
    logInfo(line);
    const int t0 = t.front() + a.sourceOffset, t1 = t.back() + a.sourceOffset;
    if (t1 >= s0 && t0 <= s1) return;
    // The offset that lines up the two caches' first frames, whichever --frames this run takes.
    const std::vector<int> cache = turbio::resolveSequence(a.target).frames;
    const int firstOfCache = cache.empty() ? t.front() : cache.front();
    logWarning("the source's frames " + std::to_string(s0) + "-" + std::to_string(s1) +
               " do not overlap the target's " + std::to_string(t.front()) + "-" + std::to_string(t.back()) +
               (a.sourceOffset != 0 ? " + offset " + std::to_string(a.sourceOffset) : std::string()) +
               ": every source frame is chosen by --source-wrap " + wrapName(a.wrap) + "; --source-offset " +
               std::to_string(s0 - firstOfCache) + " lines up the caches' first frames (target " +
               std::to_string(firstOfCache) + ", source " + std::to_string(s0) + ")");
}

// Stepped frames (--frames 1001-1100x2): the carried detail and density jump over the skipped frames.
void reportFrameStep(const std::vector<int>& frames)
{
    int step = 1;
    for (size_t i = 1; i < frames.size(); ++i) step = std::max(step, frames[i] - frames[i - 1]);
    if (step > 1)
        logWarning("frames step by up to " + std::to_string(step) + ": the detail and density are carried across " +
                   "the skipped frames in one advection step of " + std::to_string(step) +
                   " frames' time with the earlier frame's velocity, so these frames differ from the same frames of a "
                   "run over every frame (for those, run every frame and keep one in " +
                   std::to_string(step) + "); see docs/transfer.md");
}

// The detail and the advected density are state: a run that starts at a later frame than the cache's first differs
// from a longer run's frames there. --preroll runs up to N earlier cache frames first, unwritten.
void addPreroll(const TransferArgs& a, FramePlan& p)
{
    const turbio::Sequence whole = turbio::resolveSequence(a.target);
    std::vector<int> earlier;
    for (int t : whole.frames)
        if (t < p.target.frames.front()) earlier.push_back(t);
    if (a.preroll <= 0) {
        if (!earlier.empty())
            logWarning("the detail starts fresh at frame " + std::to_string(p.target.frames.front()) +
                       " while the cache begins at " + std::to_string(earlier.front()) +
                       ": these frames differ from a run started earlier (--preroll " + std::to_string(earlier.size()) +
                       " runs earlier frames first without writing them)");
        return;
    }
    const size_t n = std::min(earlier.size(), size_t(a.preroll));
    const std::vector<int> pre(earlier.end() - std::ptrdiff_t(n), earlier.end());
    if (n < size_t(a.preroll))
        logWarning("--preroll " + std::to_string(a.preroll) + ": the target cache has only " + std::to_string(n) +
                   " frames before frame " + std::to_string(p.target.frames.front()));
    const std::vector<int> preSource = sourceFrames(a, pre, p.source);
    p.sourceFor.insert(p.sourceFor.begin(), preSource.begin(), preSource.end());
    p.target.frames.insert(p.target.frames.begin(), pre.begin(), pre.end());
    p.writeFrom = n;
    if (n > 0) logInfo("pre-roll: frames " + turbio::formatFrameList(pre) + " run first and are not written");
}

FramePlan planFrames(const TransferArgs& a)
{
    FramePlan p;
    p.target = turbio::resolveSequence(a.target, a.frames);
    p.source = turbio::resolveSequence(a.source, a.sourceFrames);
    p.out = turbio::FramePattern::parse(a.out);
    checkOutputFormat(a.write, a.out, a.resume ? "--resume" : "");
    if (!p.target.missing.empty())
        throw turb::IoError(p.target.pattern.str() +
                            (p.target.missing.size() == 1 ? ": missing target frame " : ": missing target frames ") +
                            turbio::formatFrameList(p.target.missing));
    if (p.target.frames.size() > 1 && !p.out.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(p.target.frames.size()) + " frames are requested");
    p.sourceFor = sourceFrames(a, p.target.frames, p.source);
    if (!a.frames.empty() && !p.target.frames.empty() && p.out.numbered()) {
        const turbio::Sequence whole = turbio::resolveSequence(a.target);
        if (!whole.frames.empty() && p.target.frames.front() > whole.frames.front())
            p.stateTag = std::to_string(p.target.frames.front()) + "-";
    }
    logInfo("transfer: target " + p.target.pattern.str() + " frames " + turbio::formatFrameList(p.target.frames) +
            ", source " + p.source.pattern.str() + " frames " + turbio::formatFrameList(p.source.frames) +
            (p.source.frames.size() < p.target.frames.size() ? " (" + wrapName(a.wrap) + ")" : ""));
    reportSourceMapping(a, p);
    reportFrameStep(p.target.frames);
    if (a.resume)
        while (p.first < p.target.frames.size() && std::filesystem::exists(p.out.format(p.target.frames[p.first])))
            ++p.first;
    p.writeFrom = p.first;
    if (p.first == 0 && !p.target.frames.empty()) addPreroll(a, p);
    return p;
}

// Continues after the last frame already written, from the state saved with it. Returns the name of the state file
// that frame names (empty when none), which the next frame's state must not overwrite.
std::string restoreFromLastWritten(const TransferArgs& a, const FramePlan& p, turb::TurbulenceTransfer& transfer)
{
    const int prev = p.target.frames[p.first - 1];
    const std::string prevPath = p.out.format(prev);
    turbio::ReadOptions ro;
    ro.cropToSmoke = false; // the file holds the box the run held (written cropped); restore needs all of it
    turb::Frame prevOut = turbio::readFrame(prevPath, prev, ro);
    const auto it = prevOut.metadata.find(turb::meta::kState);
    if (it == prevOut.metadata.end()) throw turb::IoError(prevPath + ": no vdbturb_state metadata to resume from");
    checkResumable(prevPath, prevOut, a.settings, a.write, p.target, p.source, a.tileBox);
    const turb::Frame prevTarget =
        readingAs("target", [&] { return turbio::readFrame(p.target.path(prev), prev, a.targetRead); });
    try {
        std::optional<turb::Frame> state = resumeStateFrame(prevPath, prev, prevOut);
        turb::Frame& from = state ? *state : prevOut;
        turb::toTimeUnit(from, prevTarget.timeUnit); // a no-op for the state, which keeps the target's unit
        transfer.restore(it->second, from, prevTarget);
    } catch (const turb::Error& e) {
        throw turb::IoError(prevPath + ": cannot resume from this frame: " + e.what(), e.settings());
    } catch (const std::exception& e) {
        throw turb::IoError(prevPath + ": cannot resume from this frame: damaged vdbturb_state (" + e.what() + ")");
    }
    logInfo("resume: continuing after frame " + std::to_string(prev));
    const auto named = prevOut.metadata.find(turb::meta::kResumeStateFile);
    return named == prevOut.metadata.end() ? std::string() : named->second;
}

// What an output frame records about how it was made: resume state, settings, inputs and framing.
void tagOutput(turb::Frame& frame, const TransferArgs& a, const FramePlan& p, size_t i, const std::string& state,
    const turb::CoordBBox& sequenceDomain)
{
    frame.metadata[turb::meta::kState] = state;
    frame.metadata[turb::meta::kSettings] = turb::outputSettingsText(a.settings);
    frame.metadata[turb::meta::kWriteSettings] = writeSettingsText(a.write);
    frame.metadata[turb::meta::kTargetInput] = inputId(p.target);
    frame.metadata[turb::meta::kSourceInput] = inputId(p.source);
    frame.metadata[turb::meta::kSourceFrame] = std::to_string(p.sourceFor[i]);
    frame.metadata[turb::meta::kCommand] = "transfer";
    if (!a.tileBox.empty()) frame.metadata[turb::meta::kTileBox] = a.tileBox;
    if (!sequenceDomain.empty()) {
        std::ostringstream box; // the format of vdbturb_domain
        box << sequenceDomain.min().x() << ' ' << sequenceDomain.min().y() << ' ' << sequenceDomain.min().z() << ' '
            << sequenceDomain.max().x() << ' ' << sequenceDomain.max().y() << ' ' << sequenceDomain.max().z();
        frame.metadata[turb::meta::kSequenceDomain] = box.str();
    }
}

// The state slot frame `frame` writes: its parity's, or the other one when the frame written before it (whose state
// file name is `previous`) took that. Frames that step by 2 (every one odd) would otherwise overwrite the state of the
// last whole frame before their own write: a kill in that write then resumed approximately.
std::string stateSlot(
    const turbio::FramePattern& out, const TransferArgs& a, double timeUnit, int frame, const std::string& previous)
{
    const std::string own = resumeStatePath(out, a, timeUnit, frame);
    if (own.empty() || std::filesystem::path(own).filename().string() != previous) return own;
    return resumeStatePath(out, a, timeUnit, frame + 1);
}

// Writes, for small (lossy) outputs, the full-precision state into the frame's slot (resumeStatePath), then the
// frame: an output on disk always has its state, and a kill between the two leaves the other slot, the previous
// frame's, untouched.
void writeOutput(turb::Frame& frame, int t, const TransferArgs& a, const std::string& outPath,
    const std::string& statePath, bool& warnedClipping)
{
    turbio::ensureParentDirectory(outPath);
    warnIfClippedAway(frame, a.write, outPath, warnedClipping);
    if (!statePath.empty()) {
        // The state is velocity and density (what restore reads), in the target's time unit, in full float.
        std::optional<turb::ScalarField> temperature = std::move(frame.temperature), flame = std::move(frame.flame);
        frame.temperature.reset();
        frame.flame.reset();
        frame.metadata[turb::meta::kResumeFrame] = std::to_string(t);
        turbio::WriteOptions exact;
        exact.keepTimeUnit = true;
        turbio::writeFrame(statePath, frame, exact);
        frame.metadata.erase(turb::meta::kResumeFrame);
        frame.temperature = std::move(temperature);
        frame.flame = std::move(flame);
        frame.metadata[turb::meta::kResumeStateFile] = std::filesystem::path(statePath).filename().string();
        testKillPoint("after-state", t);
    }
    turbio::writeFrame(outPath, frame, a.write);
}

// The frame's JSON line: what the transfer did and how its solvers ended.
nlohmann::json frameJson(const turb::TransferResult& r, const std::string& outPath, int sourceFrame)
{
    const turb::TransferStats& st = r.stats;
    nlohmann::json extra;
    extra["out"] = outPath;
    extra["source_frame"] = sourceFrame;
    extra["empty"] = r.empty;
    extra["ratio"] = st.ratio;
    if (st.sourceResampled) extra["source_ratio_resampled_from"] = st.sourceRatio;
    extra["patches"] = st.localPatches;
    extra["global_searches"] = st.globalSearches;
    extra["tracked"] = st.trackedPatches;
    extra["followed"] = st.followedPatches;
    extra["regenerated"] = st.regeneratedPatches;
    extra["repeats_avoided"] = st.repeatsAvoided;
    extra["vorticity_limited_voxels"] = st.vorticityLimited;
    extra["patch_strength_gain"] = st.patchStrengthGain;
    extra["regenerated_for_structure"] = st.structureRegenerated;
    if (st.structureRatio) extra["structure_ratio"] = *st.structureRatio;
    if (st.structureRedone) extra["structure_redone"] = true;
    if (st.structureFirstRatio) extra["structure_ratio_first"] = *st.structureFirstRatio;
    extra["continuations"] = st.continuations;
    extra["mean_local_energy"] = st.meanLocalEnergy;
    extra["energy_scale"] = st.energyScale;
    extra["coarse_kept"] = st.coarseKept;
    extra["lf_err"] = st.lfErr;
    extra["density_err"] = st.densityErr;
    extra["density_err_before_guide"] = st.densityErrBefore;
    if (st.detailChange) {
        extra["detail_change"] = *st.detailChange;
        extra["detail_growth"] = st.detailGrowth;
    }
    extra["band_voxels"] = st.seams.bandVoxels;
    extra["seam_initial_energy"] = st.seams.initialEnergy;
    nlohmann::json em = nlohmann::json::array();
    for (const auto& it : st.seams.iterations)
        em.push_back({{"cg_iterations", it.cgIterations}, {"cg_residual", it.cgResidual}, {"energy", it.energy}});
    extra["seam_em"] = em;
    if (st.seams.stoppedAtMStep > 0.0) extra["seam_em_stopped_at_m_step"] = st.seams.stoppedAtMStep;
    nlohmann::json steps;
    for (const auto& [name, sec] : st.seconds.named()) steps[name] = sec;
    extra["steps_s"] = steps;
    return extra;
}

// The farm log's line for the frame.
std::string frameLine(const turb::TransferResult& r, const std::string& outPath)
{
    const turb::TransferStats& st = r.stats;
    std::string human = r.empty ? "no smoke in target: wrote the up-sampled target"
                                : std::to_string(st.localPatches) + " patches (" + std::to_string(st.globalSearches) +
                                      " global searches), seams " + std::to_string(st.seams.iterations.size()) + " EM";
    if (!st.seams.iterations.empty()) {
        const auto& last = st.seams.iterations.back();
        human += fmt(" E_b %.4g", last.energy) + " (CG " + std::to_string(last.cgIterations) +
                 fmt(" it, res %.1e)", last.cgResidual);
    }
    return human + " -> " + outPath;
}

// -v: the solvers' iterations, the detail's energy and coherence, and the time of every step.
void logFrameDetails(const turb::TransferResult& r, int t)
{
    const turb::TransferStats& st = r.stats;
    const std::string frame = "frame " + std::to_string(t);
    for (size_t k = 0; k < st.seams.iterations.size(); ++k) {
        const auto& it = st.seams.iterations[k];
        logVerbose(frame + ": seam EM " + std::to_string(k + 1) + ": CG " + std::to_string(it.cgIterations) +
                   " iterations, residual " + fmt("%.2e", it.cgResidual) + ", E_b " + fmt("%.6g", it.energy));
    }
    logVerbose(frame + ": seams: setup " + fmt("%.2f s", st.seams.setupSeconds) + ", M-steps " +
               fmt("%.2f s", st.seams.mStepSeconds) + ", E-steps " + fmt("%.2f s", st.seams.eStepSeconds) + ", band " +
               std::to_string(st.seams.bandVoxels) + " voxels, " + std::to_string(st.seams.boundaryPatches) +
               " boundary patches");
    if (!r.empty) {
        std::string detailLine = frame + ": detail energy x" + fmt("%.3f", st.energyScale) +
                                 fmt(", coarse part kept %.2f", st.coarseKept) + fmt(" (lf_err %.3f)", st.lfErr);
        if (st.detailChange)
            detailLine += fmt(", change against last frame advected %.3f", *st.detailChange) +
                          fmt(" (growth %.3f: at least ", st.detailGrowth) +
                          fmt("%.3f)", std::max(0.0, 1.0 - 1.0 / st.detailGrowth));
        logVerbose(detailLine);
        if (st.structureRatio)
            logVerbose(frame + ": structure: " + std::to_string(st.regeneratedPatches) + " patches regenerated (" +
                       std::to_string(st.structureRegenerated) + " for the goal), finished at " +
                       fmt("%.3f", *st.structureRatio) + " of the source's anisotropy" +
                       (st.structureFirstRatio
                               ? fmt(" after a second pass (the first finished at %.3f)", *st.structureFirstRatio)
                               : std::string()));
    }
    std::string timing = frame + ": time";
    for (const auto& [name, sec] : st.seconds.named())
        if (std::string(name) != "total") timing += std::string(" ") + name + fmt(" %.2f", sec);
    logVerbose(timing);
}

int runTransfer(TransferArgs& a)
{
    a.settings.threads = globals().threads;
    if (!a.tileBox.empty()) {
        if (!a.targetRead.cropToSmoke)
            throw turb::ValueError("--tile-box holds a box of the target; it cannot be combined with --target-no-crop");
        // One box for the whole range, so --resume and the farm join see the same box on every frame.
        a.targetRead.holdBox = turb::parseTileBox(a.tileBox);
    }
    FramePlan p = planFrames(a);
    a.stateTag = p.stateTag;
    defaultMargins(a, p.target, p.source, p.sourceFor);
    logVerbose("source crop margin: " + std::to_string(a.sourceRead.cropMargin) + " source voxels");
    const turb::CoordBBox sequenceDomain = preflight(a, p.target, p.source, p.sourceFor, p.out, p.writeFrom);
    if (globals().dryRun) {
        if (a.resume && p.first > 0) {
            const std::string prevPath = p.out.format(p.target.frames[p.first - 1]);
            checkResumable(prevPath, turbio::readFrame(prevPath, p.target.frames[p.first - 1], turbio::ReadOptions{}),
                a.settings, a.write, p.target, p.source, a.tileBox);
        }
        return kOk;
    }
    lockOutputFrames(
        p.out, std::vector<int>(p.target.frames.begin() + long(std::max(p.first, p.writeFrom)), p.target.frames.end()));
    turb::TurbulenceTransfer transfer(a.settings);
    if (a.resume && p.first == p.target.frames.size()) {
        // Nothing left to compute, but the frames must be this run's: a plan rewritten with other settings over the
        // same scratch directory would otherwise hand on another run's frames.
        const int last = p.target.frames.back();
        const std::string lastPath = p.out.format(last);
        turbio::ReadOptions ro;
        ro.cropToSmoke = false;
        checkResumable(
            lastPath, turbio::readFrame(lastPath, last, ro), a.settings, a.write, p.target, p.source, a.tileBox);
        logInfo("resume: every requested frame already exists (made with these settings); nothing to do");
        return kOk;
    }
    std::string lastStateFile; // the state file the last frame written names: the next frame writes the other
    if (a.resume && p.first > 0) lastStateFile = restoreFromLastWritten(a, p, transfer);
    if (a.write.style == turbio::WriteStyle::Blender && a.velocityMargin && a.velocityMargin->count() > 0 &&
        a.write.velocityMargin >= 0)
        logWarning("--velocity-margin " + std::to_string(a.write.velocityMargin) +
                   " is ignored with --style blender: Blender's staggered velocity is written over the whole box");
    if (a.write.style == turbio::WriteStyle::Blender && a.write.velocityVoxelScale > 1)
        logWarning("--vel-voxel-scale is ignored with --style blender: Blender's velocity is written on the frame's "
                   "lattice");
    RunReport report("transfer", a.json);
    double targetUnit = 0.0; // the resume state's need: known from the first target frame's time unit
    bool warnedClipping = false;
    const int count = int(p.target.frames.size());
    // Frame k's two inputs are read while frame k - 1 is computed and written: a read is mostly its guarded reader's
    // child process (fork, decode, the copy back), time the cores otherwise spend waiting. A read that fails throws
    // from get(), at frame k, after frame k - 1 is written, as reading in turn would.
    const auto readInputs = [&](size_t k) {
        const int tk = p.target.frames[k];
        std::pair<turb::Frame, turb::Frame> in;
        in.first = readingAs("target", [&] { return turbio::readFrame(p.target.path(tk), tk, a.targetRead); });
        in.second = readingAs(
            "source", [&] { return turbio::readFrame(p.source.path(p.sourceFor[k]), p.sourceFor[k], a.sourceRead); });
        return in;
    };
    std::future<std::pair<turb::Frame, turb::Frame>> ahead;
    if (p.first < p.target.frames.size()) ahead = std::async(std::launch::async, readInputs, p.first);
    for (size_t i = p.first; i < p.target.frames.size(); ++i) {
        const int t = p.target.frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        ConsoleProgress progress(int(i), count, t);
        progress.begin("reading");
        const auto [tf, sf] = ahead.get();
        if (i == p.first) {
            targetUnit = tf.timeUnit;
            if (const std::string odd = resumeStatePath(p.out, a, targetUnit, 1); !odd.empty())
                logInfo("resume state: " + odd + " and " + resumeStatePath(p.out, a, targetUnit, 0) +
                        " (odd and even frames in full precision, for --resume; not frames of the shot)");
        }
        if (i + 1 < p.target.frames.size()) ahead = std::async(std::launch::async, readInputs, i + 1);
        turb::TransferResult r;
        try {
            r = transfer.process(tf, sf, &progress);
        } catch (const turb::ValueError& e) {
            // The library names frames, not files: say which files this frame came from.
            throw turb::ValueError("frame " + std::to_string(t) + " (target " + p.target.path(t) + ", source " +
                                       p.source.path(p.sourceFor[i]) + "): " + e.what(),
                e.settings());
        }
        if (i < p.writeFrom) {
            progress.clear();
            logInfo("pre-roll frame " + std::to_string(t) + " done in " + fmt("%.2f s", secondsSince(t0)) +
                    " (not written)");
            continue;
        }
        tagOutput(r.frame, a, p, i, transfer.saveState(), sequenceDomain);
        progress.begin("writing");
        const std::string outPath = p.out.format(t);
        const nlohmann::json extra = frameJson(r, outPath, p.sourceFor[i]);
        const std::string statePath = stateSlot(p.out, a, targetUnit, t, lastStateFile);
        writeOutput(r.frame, t, a, outPath, statePath, warnedClipping);
        if (!statePath.empty()) lastStateFile = std::filesystem::path(statePath).filename().string();
        progress.clear();
        if (r.stats.sourceResampled && i == p.first)
            logInfo("source resampled trilinearly from ratio " + fmt("%.4g", r.stats.sourceRatio) + " to " +
                    std::to_string(r.stats.ratio) + " (output voxel = target voxel / " + std::to_string(r.stats.ratio) +
                    ")");
        logFrameDetails(r, t);
        report.frameDone(t, int(i), count, secondsSince(t0), frameLine(r, outPath), extra);
        testKillPoint("after-frame", t);
    }
    report.finish();
    return kOk;
}

} // namespace

namespace {

// A numeric setting: the option, in the second tier under `key`.
template<typename T>
CLI::Option* num(CLI::App* app, const std::string& names, T& v, const std::string& help, const std::string& key)
{
    return setting(app->add_option(names, v, help), key);
}

// Matching (Sato et al. section 3.2): patch sizes, descriptor, candidates and the energy's weights.
void addSearchSettings(CLI::App* app, turb::TransferSettings& s)
{
    num(app, "--alpha", s.alpha, "Weight of the density-mask term in matching (paper 0.004)", "alpha")
        ->check(finiteIn(0.0));
    num(app, "--beta", s.beta, "Weight of the temporal term: previous detail advected (paper 0.5)", "beta")
        ->check(finiteIn(0.0));
    num(app, "--density-threshold,--densityThreshold", s.densityThreshold, "D_th: smoke where density > this",
        "densityThreshold")
        ->check(finiteIn(0.0));
    num(app, "--patch,--localPatch", s.localPatch, "B: local patch edge in output voxels", "localPatch")
        ->check(CLI::Range(2, 64));
    num(app, "--global-patch,--globalPatch", s.globalPatch,
        "b: global patch edge in target voxels, odd (0 = 2*ceil(B/f)+1)", "globalPatch");
    num(app, "--pca,--pcaComponents", s.pcaComponents, "PCA dimensions of patch descriptors", "pcaComponents")
        ->check(CLI::Range(1, 256));
    num(app, "--stride,--localStride", s.localStride, "Spacing of candidate source patches in the local search",
        "localStride")
        ->check(CLI::Range(1, 16));
    num(app, "--candidates,--refineCandidates", s.refineCandidates, "Local candidates re-scored at full resolution",
        "refineCandidates")
        ->check(CLI::Range(1, 4096));
}

// Seam smoothing (section 3.3): the band, the boundary patches, EM and CG.
void addSeamSettings(CLI::App* app, turb::SeamSettings& seams)
{
    num(app, "--gamma,--seams.gamma", seams.gamma, "Weight of divergence in seam smoothing (paper 10)", "seams.gamma")
        ->check(finiteIn(0.0));
    num(app, "--seams.bandWidth", seams.bandWidth, "Seam band: voxels on each side of a patch border (3D)",
        "seams.bandWidth")
        ->check(CLI::Range(1, 32));
    num(app, "--seams.bandWidth2D", seams.bandWidth2D, "Seam band on 2D caches", "seams.bandWidth2D")
        ->check(CLI::Range(1, 32));
    legacy(app->add_option_function<int>(
                  "--band", [&seams](int v) { seams.bandWidth = seams.bandWidth2D = v; }, "Both seam band widths")
               ->check(CLI::Range(1, 32)),
        "seams.bandWidth,seams.bandWidth2D");
    num(app, "--boundary-patch,--seams.boundaryPatch", seams.boundaryPatch, "C: boundary patch edge, even (0 = B)",
        "seams.boundaryPatch");
    num(app, "--em-iterations,--seams.maxEmIterations", seams.maxEmIterations, "Seam EM iterations at most",
        "seams.maxEmIterations")
        ->check(CLI::Range(1, 50));
    num(app, "--em-tolerance,--seams.emTolerance", seams.emTolerance,
        "Stop EM when E_b changes by less than this fraction", "seams.emTolerance");
    num(app, "--cg-iterations,--seams.maxCgIterations", seams.maxCgIterations, "CG iterations per E-step at most",
        "seams.maxCgIterations")
        ->check(CLI::Range(1, 100000));
    num(app, "--seams.cgTolerance", seams.cgTolerance, "CG relative residual (3D)", "seams.cgTolerance")
        ->check(finiteIn(1e-12, 1.0));
    num(app, "--seams.cgTolerance2D", seams.cgTolerance2D, "CG relative residual on 2D caches", "seams.cgTolerance2D")
        ->check(finiteIn(1e-12, 1.0));
    legacy(app->add_option_function<double>(
                  "--cg-tolerance", [&seams](double v) { seams.cgTolerance = seams.cgTolerance2D = v; },
                  "Both CG tolerances")
               ->check(finiteIn(1e-12, 1.0)),
        "seams.cgTolerance,seams.cgTolerance2D");
    num(app, "--value-weight,--seams.valueWeight", seams.valueWeight,
        "Weight of seam-solve rows keeping carried detail at its value (0 = the paper's energy)", "seams.valueWeight")
        ->check(finiteIn(0.0));
    num(app, "--box-weight,--seams.boxWeight", seams.boxWeight,
        "Weight of the seam-solve rows holding U_h's coarse-cell means (0 = free; coarseTolerance bounds them)",
        "seams.boxWeight")
        ->check(finiteIn(0.0));
    setting(addEnum<turb::SeamSolver>(app, "--seam-solver,--seams.solver", seams.solver,
                {{"cgnr", turb::SeamSolver::Cgnr}, {"eigen", turb::SeamSolver::EigenLscg}},
                "Seam E-step solver: cgnr (matrix-free, parallel) or eigen (Eigen's LeastSquaresConjugateGradient)"),
        "seams.solver");
    num(app, "--box-keep,--seams.boxKeep", seams.boxKeep,
        "Fraction of each coarse cell's mean of U_h the seam solve keeps (1: leaves the coarse motion; 0: pulls it to "
        "0)",
        "seams.boxKeep")
        ->check(finiteIn(0.0, 1.0));
    boolSetting(
        app, "--seams.enabled", seams.enabled, "Seam smoothing (false: paste patches as they are)", "seams.enabled");
    legacy(app->add_flag_function(
               "--no-seams", [&seams](int64_t) { seams.enabled = false; }, "seams.enabled = false"),
        "seams.enabled", "false");
}

// Beyond the paper: what U_h keeps of its coarse part, how patches follow the source, resampling.
void addDetailSettings(CLI::App* app, turb::TransferSettings& s)
{
    num(app, "--coarse-tolerance,--coarseTolerance", s.coarseTolerance,
        "lf_err bound: U_h's coarse-cell means are reduced only down to this fraction of the target's (0 = exactly)",
        "coarseTolerance")
        ->check(finiteIn(0.0, 1.0));
    boolSetting(app, "--removeCoarseDetail", s.removeCoarseDetail, "Reduce U_h's coarse part (false lets lf_err grow)",
        "removeCoarseDetail");
    legacy(app->add_flag_function(
               "--keep-coarse-detail", [&s](int64_t) { s.removeCoarseDetail = false; }, "removeCoarseDetail = false"),
        "removeCoarseDetail", "false");
    num(app, "--coherence", s.coherence,
        "Take a neighbour's continued source patch within this fraction of the best E_h (0 = off, the paper)",
        "coherence")
        ->check(finiteIn(0.0));
    setting(app->add_flag("--whole-fresh-patches,--solveFreshPatchesWhole", s.solveFreshPatchesWhole,
                "Solve every voxel of patches without carried detail, not only the seam band"),
        "solveFreshPatchesWhole");
    boolSetting(app, "--resampleSource", s.resampleSource,
        "Resample a source at a non-integer ratio trilinearly to the nearest integer one (false: refuse it)",
        "resampleSource");
    legacy(app->add_flag_function(
               "--no-resample-source", [&s](int64_t) { s.resampleSource = false; }, "resampleSource = false"),
        "resampleSource", "false");
    boolSetting(app, "--followSourceFlow", s.followSourceFlow,
        "Patches follow the source's flow from frame to frame (false: re-paste where last frame found them)",
        "followSourceFlow");
    legacy(app->add_flag_function(
               "--no-follow-source", [&s](int64_t) { s.followSourceFlow = false; }, "followSourceFlow = false"),
        "followSourceFlow", "false");
    num(app, "--follow-tolerance,--followTolerance", s.followTolerance,
        "Keep a patch's continuation while its E_h is within (1 + this) of the best", "followTolerance")
        ->check(finiteIn(0.0));
    num(app, "--source-smoke,--sourceSmoke", s.sourceSmoke,
        "Fraction of a source patch's voxels that must hold smoke for it to be a candidate (0 = any, the paper)",
        "sourceSmoke")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--even-patches,--evenPatches", s.evenPatches,
        "How far to even out the detail's strength over the position in the patch (variance-preserving seams; 0 = "
        "off, the paper)",
        "evenPatches")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--local-energy,--localEnergy", s.localEnergy,
        "How far each patch's detail strength moves toward the source detail pasted into it, the frame's total kept "
        "(0 = one factor per frame)",
        "localEnergy")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--vorticity-limit,--vorticityLimit", s.vorticityLimit,
        "Scale the detail down where the vorticity exceeds this times the source's 0.999 quantile (0 = off)",
        "vorticityLimit")
        ->check(finiteIn(0.0));
    num(app, "--repeat-radius,--repeatRadius", s.repeatRadius,
        "Patches within this many patches never take overlapping source patches (0 = off, the paper)", "repeatRadius")
        ->check(CLI::Range(0, 4));
    num(app, "--repeatTolerance", s.repeatTolerance,
        "Avoid a repeat with a candidate whose E_h is within (1 + this) of the best", "repeatTolerance")
        ->check(finiteIn(0.0));
    boolSetting(app, "--trackGlobalPatches", s.trackGlobalPatches,
        "Follow last frame's global patch (false: global search every frame)", "trackGlobalPatches");
    legacy(app->add_flag_function(
               "--no-tracking", [&s](int64_t) { s.trackGlobalPatches = false; }, "trackGlobalPatches = false"),
        "trackGlobalPatches", "false");
    const std::vector<std::pair<std::string, turb::DetailEnergy>> energies{{"source", turb::DetailEnergy::Source},
        {"pasted", turb::DetailEnergy::Pasted}, {"none", turb::DetailEnergy::None},
        {"distribution", turb::DetailEnergy::Distribution}};
    // Defined before the two settings, so that one of them given as well wins on its own kind of cache.
    legacy(addEnum<turb::DetailEnergy>(
               app, "--detail-energy", s.detailEnergy, energies, "Both detail energies (3D and 2D caches)")
               // addEnum's transform has already turned the name into the enum's number.
               ->each([&s](const std::string& v) { s.detailEnergy2D = static_cast<turb::DetailEnergy>(std::stoi(v)); }),
        "detailEnergy,detailEnergy2D");
    setting(addEnum<turb::DetailEnergy>(app, "--detailEnergy", s.detailEnergy, energies,
                "U_h's energy per smoke voxel on 3D caches: source (the source's high-frequency energy), pasted "
                "(the pasted patches' energy), none (as made), or distribution (|U_h| remapped rank for rank onto "
                "the source detail's magnitudes, then the source's energy)"),
        "detailEnergy");
    setting(addEnum<turb::DetailEnergy>(app, "--detailEnergy2D,--detail-energy-2d", s.detailEnergy2D, energies,
                "The same on 2D (one z layer) caches"),
        "detailEnergy2D");
    boolSetting(app, "--compensateTargetDivergence", s.compensateTargetDivergence,
        "The seam gamma term penalises div(up(u_t) + U_h) (false: div(U_h), the paper)", "compensateTargetDivergence");
    legacy(app->add_flag_function(
               "--no-target-divergence", [&s](int64_t) { s.compensateTargetDivergence = false; },
               "compensateTargetDivergence = false"),
        "compensateTargetDivergence", "false");
}

// Temporal coherence, alignment, the output density and the source's velocity extension.
void addTimeSettings(CLI::App* app, TransferArgs& a)
{
    turb::TransferSettings& s = a.settings;
    num(app, "--temporal-blend,--temporalBlend", s.temporalBlend,
        "Weight of last frame's detail advected through the target (0 = the paper)", "temporalBlend")
        ->check(finiteIn(0.0, 0.999));
    num(app, "--regenerate", s.regenerate,
        "Regenerate carried detail stretched below this fraction of the fresh patches' anisotropy (0 = off)",
        "regenerate")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--regenerateBlend", s.regenerateBlend, "Carried weight per frame in a regenerated patch (3D)",
        "regenerateBlend")
        ->check(finiteIn(0.0, 0.999));
    num(app, "--regenerateBlend2D", s.regenerateBlend2D, "The same on 2D caches", "regenerateBlend2D")
        ->check(finiteIn(0.0, 0.999));
    num(app, "--structureTolerance", s.structureTolerance,
        "Regenerate more patches while the detail's anisotropy is this fraction off the source's, and redo a frame "
        "that finishes 3x this off (3D; 0 = off)",
        "structureTolerance")
        ->check(finiteIn(0.0, 0.99));
    num(app, "--structureTolerance2D", s.structureTolerance2D, "The same on 2D caches", "structureTolerance2D")
        ->check(finiteIn(0.0, 0.99));
    legacy(app->add_option_function<float>(
                  "--regenerate-blend", [&s](float v) { s.regenerateBlend = s.regenerateBlend2D = v; },
                  "Both regeneration blends")
               ->check(finiteIn(0.0, 0.999)),
        "regenerateBlend,regenerateBlend2D");
    setting(addEnum<turb::FlowAlignment>(app, "--align,--alignment", s.alignment,
                {{"none", turb::FlowAlignment::None}, {"normalize", turb::FlowAlignment::Normalize},
                    {"rotate", turb::FlowAlignment::Rotate}, {"both", turb::FlowAlignment::Both}},
                "Match after aligning flows: none (the paper), normalize, rotate, both"),
        "alignment");
    num(app, "--lookback,--lookBackFrames", s.lookBackFrames, "m for --density lookback", "lookBackFrames")
        ->check(CLI::Range(1, 100));
    setting(
        addEnum<turb::AdvectSettings::Scheme>(app, "--density-scheme,--densityScheme", s.densityScheme,
            {{"bfecc", turb::AdvectSettings::Scheme::BFECC}, {"maccormack", turb::AdvectSettings::Scheme::MacCormack},
                {"semi-lagrangian", turb::AdvectSettings::Scheme::SemiLagrangian}},
            "Advection scheme of the output density"),
        "densityScheme");
    num(app, "--density-guide,--densityGuide.strength", s.densityGuide.strength,
        "Fraction of the way the output density's coarse means move onto the target's per frame (0 = off)",
        "densityGuide.strength")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--interface-compression,--interfaceCompression", s.interfaceCompression,
        "Sharpen the output density's edge: interface compression in voxels per frame (0 = off; docs/look.md: 0.5)",
        "interfaceCompression")
        ->check(finiteIn(0.0, 1.0));
    num(app, "--level-set-diffusion,--levelSetDiffusion", s.levelSetDiffusion,
        "Even out hairs along the output density's surface: diffusion along its level sets per pass (0 = off; "
        "docs/look.md: 0.15)",
        "levelSetDiffusion")
        ->check(finiteIn(0.0, 1.0 / 6.0));
    num(app, "--level-set-diffusion-passes,--levelSetDiffusionPasses", s.levelSetDiffusionPasses,
        "Passes of the level-set diffusion per frame", "levelSetDiffusionPasses")
        ->check(CLI::Range(0, 20));
    num(app, "--extend-velocity,--sourceRead.extendVelocity", a.sourceRead.extendVelocity,
        "Continue the source's velocity this many voxels past its active region (Blender clips it to the smoke; 0 = "
        "off)",
        "sourceRead.extendVelocity")
        ->check(CLI::Range(0, 64));
}

// The second tier: every solver and experimental knob of turb::TransferSettings under its field's name, beside the
// spelling scripts used before (their measured effects are in docs/transfer.md).
void addTransferSettings(CLI::App* app, TransferArgs& a)
{
    addSearchSettings(app, a.settings);
    addSeamSettings(app, a.settings.seams);
    addDetailSettings(app, a.settings);
    addTimeSettings(app, a);
}

} // namespace

Command transferCommand()
{
    auto args = std::make_shared<TransferArgs>();
    Command c;
    c.name = "transfer";
    c.help = "Turbulence style transfer: add a high-res source's detail to a low-res target's motion (3D, or 2D: "
             "one-z-layer caches)";
    c.setup = [args](CLI::App* app) {
        TransferArgs& a = *args;
        app->add_option("--target", a.target, "Low-res target cache (velocity + density): pattern or one file")
            ->required();
        app->add_option("--source", a.source, "High-res source cache whose turbulence is transferred")->required();
        app->add_option("--out", a.out, "Output pattern, e.g. up/turb.####.vdb (directories are created)")->required();
        app->add_option("--frames", a.frames, "Target frames, e.g. 1001-1100x2 (default: all on disk)")
            ->check(frameListCheck());
        app->add_option("--source-frames", a.sourceFrames, "Restrict the source to these frames")
            ->check(frameListCheck());
        app->add_option("--source-offset", a.sourceOffset, "Source frame = target frame + offset");
        addEnum<turbio::SourceWrap>(app, "--source-wrap", a.wrap,
            {{"loop", turbio::SourceWrap::Loop}, {"pingpong", turbio::SourceWrap::PingPong},
                {"clamp", turbio::SourceWrap::Clamp}, {"error", turbio::SourceWrap::Error}},
            "When the source runs out");
        addEnum<turb::DensityMode>(app, "--density", a.settings.densityMode,
            {{"advect", turb::DensityMode::Advect}, {"lookback", turb::DensityMode::LookBack}},
            "Output density: advected, or looked back m frames (Ma et al.'s supplement)");
        app->add_option("--preroll", a.preroll,
               "Run up to N cache frames before the first requested one without writing them, so the detail and "
               "density are established as in a longer run")
            ->check(finiteIn(0.0));
        app->add_flag("--resume,--skip-existing", a.resume,
            "Skip frames already written (refused unless the last was made with these settings) and continue from the "
            "state saved in it; --skip-existing is the farm wrappers' name for it");
        app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.targetRead, "target");
        addReadOptions(app, a.sourceRead, "source");
        a.sourceCropMargin =
            app->get_option("--source-crop-margin")
                ->description("Source voxels kept around the source's smoke (default: 8 target voxels)");
        app->add_option("--tile-box", a.tileBox,
               "Hold only this box of the target, X0,Y0,Z0,X1,Y1,Z1 (inclusive voxel indices): a space tile and its "
               "halo, as farm plan --tiles writes it. The output covers its refined box")
            ->check(parsedBy([](const std::string& t) { turb::parseTileBox(t); }, "X0,Y0,Z0,X1,Y1,Z1"))
            ->group(kGroupInput);
        addWriteOptions(app, a.write);
        addFormatOptions(app, a.write);
        addVelocityWriteOptions(app, a.write);
        a.velocityMargin = app->get_option("--velocity-margin");
        addTransferSettings(app, a);
        for (const KindTwin& k : kKindTwins)
            a.kindTwins.emplace_back(app->get_option(k.option3D), app->get_option(k.option2D));
    };
    c.run = [args] { return runTransfer(*args); };
    return c;
}

} // namespace vdbturb
