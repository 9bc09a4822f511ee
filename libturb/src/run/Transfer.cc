// turb::run::runTransfer: vdbturb transfer's run, from files to files (turb/run/Transfer.h).
#include <turb/run/Transfer.h>

#include "RunHelpers.h"

#include <turb/run/Flags.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

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

#include <nlohmann/json.hpp>

#include <chrono>
#include <utility>

namespace turb::run {

using detail::fmt;
using detail::secondsSince;

namespace {

// The job and what the run adds to it.
struct TransferArgs : TransferJob
{
    explicit TransferArgs(const TransferJob& job) : TransferJob(job) {}
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
        if (!a.sourceCropMarginGiven && a.sourceRead.cropToSmoke)
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

// What preflight learns and its steps share: the scans, the ratio, the boxes.
struct TransferScan
{
    turbio::SequenceScan target, source;
    double tv = 0.0, sv = 0.0; ///< target and source voxel sizes
    int ratio = 0;
    bool resampled = false;    ///< a non-integer ratio: the source is resampled to `ratio`
    turb::CoordBBox targetBox; ///< the target's held box (its largest frame's), or the tile box
    double sourceVoxels = 0.0; ///< of the source's largest domain
    turb::Coord outDim;        ///< output voxels (a 2D target keeps its one z layer)
    // Into target.frames and source.frames (a TransferScan is moved, never copied).
    const turbio::FrameScan* targetLargest = nullptr; ///< the target frame with the largest held box
    const turbio::FrameScan* sourceLargest = nullptr;
};

// Every target and source frame's headers, one lattice per sequence, the time step's sources.
TransferScan scanInputs(const TransferArgs& a, const turbio::Sequence& target, const turbio::Sequence& source,
    const std::vector<int>& targetFrames, const std::vector<int>& sourceFrames)
{
    TransferScan sc;
    sc.target = checkInput("transfer", "target", target, targetFrames, a.targetRead, LatticePolicy::Refuse, "target");
    sc.source = checkInput("transfer", "source", source, sourceFrames, a.sourceRead, LatticePolicy::Refuse, "source");
    reportTiming("target", sc.target, true, "target");
    reportTiming("source", sc.source, true, "source");
    if (!sc.source.frames.empty() && sc.source.frames.front().timing.cells && a.sourceRead.extendVelocity > 0)
        logInfo("source: Blender clips its velocity to the smoke; the detail is calibrated to it continued " +
                std::to_string(a.sourceRead.extendVelocity) + " voxels past the edge, at full strength from the " +
                "first frame. Measure it so (vdbturb measure --source-extend-velocity " +
                std::to_string(a.sourceRead.extendVelocity) + "): against the clipped source the edge's step " +
                "counts as turbulence and the first frames' hf_ratio reads low (0.17 at frame 1 of Blender plume2, " +
                "1.12 so measured)");
    const turbio::FrameScan& t0 = sc.target.frames.front();
    const turbio::FrameScan& s0 = sc.source.frames.front();
    sc.tv = t0.lattice.voxelSize;
    sc.sv = s0.lattice.voxelSize;
    sc.ratio = turb::transferRatio(sc.tv, sc.sv, a.settings.resampleSource); // throws, saying why, where the run would
    sc.resampled = !turb::isIntegerRatio(sc.tv, sc.sv);
    sc.targetLargest = sc.target.largestDomain();
    sc.sourceLargest = sc.source.largestDomain();
    sc.targetBox = sc.targetLargest ? sc.targetLargest->domain : t0.domain;
    sc.sourceVoxels = sc.sourceLargest ? double(sc.sourceLargest->domain.volume()) : 0.0;
    sc.outDim = turb::refineDomain(sc.targetBox, sc.ratio).dim();
    return sc;
}

// A tile box is a part of the target's domain: off it, the run would hold (and write) nothing or a vast box of empty
// space; one voxel thick in a 3D cache, it would read as a 2D cache. And the two caches are both 2D or both 3D.
void checkBoxes(const TransferArgs& a, const TransferScan& sc, size_t first)
{
    if (!a.tileBox.empty()) {
        turb::CoordBBox spans;
        for (const turbio::FrameScan& fs : sc.target.frames) spans.expand(fs.span);
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
    const turbio::FrameScan* tl = sc.targetLargest;
    const turbio::FrameScan* sl = sc.sourceLargest;
    if (tl && sl && !tl->span.empty() && !sl->span.empty() && turb::isFlat(sc.targetBox) != turb::isFlat(sl->domain))
        throw turb::ValueError(turb::isFlat(sc.targetBox)
                                   ? "the target is 2D (one z layer) but the source is not: give a 2D source"
                                   : "the target is 3D but the source is 2D (one z layer)");
}

// The plan's first lines: the ratio, the output lattice, and which of the settings with a 2D twin apply (a 2D cache
// silently takes other values), warning about one given for the other kind.
void printLattice(const TransferArgs& a, const TransferScan& sc)
{
    const turbio::FrameScan& t0 = sc.target.frames.front();
    const turbio::FrameScan* tl = sc.targetLargest;
    const turb::Lattice outLattice = turb::refinedLattice(t0.lattice, sc.targetBox, sc.ratio);
    printData(
        "ratio " + fmt("%.4g", sc.tv / sc.sv) + " (target voxel " + fmt("%g", sc.tv) + ", source voxel " +
        fmt("%g", sc.sv) + ")" +
        (sc.resampled ? ": not an integer, the source is resampled trilinearly to ratio " + std::to_string(sc.ratio)
                      : ""));
    printData("output lattice: " + dims(sc.outDim) + " voxels of " + fmt("%g", outLattice.voxelSize) + ", world " +
              worldBox(sc.targetBox, t0.lattice) +
              (a.tileBox.empty() ? " (the target's held box: its smoke and margin" : " (the tile box --tile-box") +
              (tl && tl->frame != t0.frame ? " at frame " + std::to_string(tl->frame) + ", its largest" : "") + ")");
    const bool flat = turb::isFlat(sc.targetBox);
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
    for (size_t k = 0; k < a.kindTwinsGiven.size() && k < kKindTwinCount; ++k)
        if (flat ? a.kindTwinsGiven[k].first : a.kindTwinsGiven[k].second)
            logWarning(std::string(flat ? kKindTwins[k].option3D : kKindTwins[k].option2D) + " is for " +
                       (flat ? "3D" : "2D") + " caches and has no effect on this " + (flat ? "2D" : "3D") +
                       " target: " + (flat ? kKindTwins[k].option2D : kKindTwins[k].option3D) +
                       " is the one that applies");
}

// Headers count active cells, and many of a cache's are thin tails below any smoke threshold (a third of
// plume2-32's at frame 30): the largest frame, read once, gives the share that is smoke, applied to every frame.
double smokeShareOfActive(const TransferArgs& a, const turbio::SequenceScan& ts)
{
    const auto largest = std::max_element(ts.frames.begin(), ts.frames.end(),
        [](const turbio::FrameScan& x, const turbio::FrameScan& y) { return x.densityActive < y.densityActive; });
    if (largest->densityActive <= 0) return 1.0;
    const turb::Frame fr = turbio::readFrame(largest->path, largest->frame, a.targetRead);
    const float thr = std::max(a.write.densityTolerance, a.write.smokeThreshold);
    const float* d = fr.density.data();
    const double smokeCells = double(std::count_if(d, d + fr.density.size(), [&](float v) { return v > thr; }));
    return std::min(1.0, smokeCells / double(largest->densityActive));
}

// Output size (Blosc gains little on noisy floats). Velocity covers the target velocity's box padded by two
// voxels, at f^3 voxels each (zero beyond it: not written), or trimmed, the smoke and the margin's shell
// (1.2x the smoke at margin 1, 1.45x at 2 on the Blender plume2 pair at 128^3).
// The smoke, where density and temperature are written, is the target's smoke cells x f^3 and the up-sampling's
// spread (1.2x: 0.93-1.0x from frame 2 on, 1.5x at frame 1's compact puff, on plume2).
void printOutputSize(
    const TransferArgs& a, const TransferScan& sc, const turbio::FramePattern& outPattern, size_t frameCount)
{
    const turbio::SequenceScan& ts = sc.target;
    const double smokeShare = smokeShareOfActive(a, ts);
    const int f = sc.ratio;
    const bool flat = turb::isFlat(sc.targetBox);
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
    const double box = double(sc.outDim.x()) * sc.outDim.y() * sc.outDim.z();
    double outBytes = 0.0, totalBytes = 0.0, stateBytes = 0.0; // the largest frame's, the run's (summed), state's
    for (const auto& fr : ts.frames) {
        const double cells = double(f) * f * (flat ? 1.0 : f);
        const double smoke = std::min(box,
            1.2 * cells * (fr.densityActive > 0 ? smokeShare * double(fr.densityActive) : double(fr.domain.volume())));
        const double whole = std::min(box, cells * velocityBoxVoxels(fr));
        const double scale = a.write.style == turbio::WriteStyle::Houdini ? a.write.velocityVoxelScale : 1.0;
        const double vel = !a.write.writeVelocity
                               ? 0.0
                               : (trimmed ? std::min(whole, smoke * (1.0 + 0.25 * a.write.velocityMargin)) : whole) /
                                     (flat ? scale * scale : scale * scale * scale);
        const double bytes = (floatBytes * 3.0 * vel + scalarBytes * 2.0 * smoke) / leafFill + gridTables;
        outBytes = std::max(outBytes, bytes);
        totalBytes += bytes;
        stateBytes = std::max(stateBytes, 12.0 * whole + 4.0 * smoke);
    }
    printData("output size: about " + turbio::formatBytes(outBytes) + " for the largest frame, " +
              turbio::formatBytes(totalBytes) + " for " + std::to_string(frameCount) + " frame" +
              (frameCount == 1 ? "" : "s"));
    const double unit = ts.frames.front().timing.timeUnit;
    if (const std::string odd = resumeStatePath(outPattern, a, unit, 1); !odd.empty())
        printData("resume state: " + odd + " and " + resumeStatePath(outPattern, a, unit, 0) + ", about " +
                  turbio::formatBytes(stateBytes) + " each (odd and even frames in full precision, for --resume)");
}

// The source is matched at the ratio's voxel: a non-integer ratio resamples it first.
double matchedVoxels(double tv, double sourceVoxel, double voxels, int ratio)
{
    return voxels * std::pow(sourceVoxel * ratio / tv, 3.0);
}

// The peak memory against what this process may use; when it does not fit, the smallest box-downsampling of the
// source (vdbturb resample --down K) that does.
void checkTransferMemory(const TransferArgs& a, const TransferScan& sc, const turbio::Sequence& source)
{
    const double tVoxels = double(sc.targetBox.volume());
    const double tv = sc.tv, sv = sc.sv, sVoxels = sc.sourceVoxels;
    const double need = turb::transferPeakBytes(tVoxels, sc.ratio, matchedVoxels(tv, sv, sVoxels, sc.ratio));
    const long long usable = turbio::usableMemoryBytes();
    std::string fits;
    if (usable > 0 && need > 0.9 * double(usable)) {
        for (int down = 2; down <= 64 && fits.empty(); ++down) {
            const double sv2 = sv * down;
            int f2 = 0;
            try {
                f2 = turb::transferRatio(tv, sv2, a.settings.resampleSource);
            } catch (const turb::ValueError&) {
                break; // the ratio fell below 2
            }
            const double n2 = sVoxels / double(down) / double(down) / double(down);
            if (turb::transferPeakBytes(tVoxels, f2, matchedVoxels(tv, sv2, n2, f2)) <= 0.9 * double(usable))
                fits = "A source box-downsampled by " + std::to_string(down) + " (voxel " + fmt("%g", sv2) +
                       ", ratio " + std::to_string(f2) + ") fits: vdbturb resample " + source.pattern.str() +
                       " --down " + std::to_string(down) + " --out PROXY.####.vdb";
        }
        if (fits.empty()) fits = "No coarser source fits: crop or coarsen the target first.";
    }
    checkMemory(need,
        "target " + dims(sc.targetBox.dim()) + " at ratio " + std::to_string(sc.ratio) + " = " + dims(sc.outDim) +
            " output voxels, source " + (sc.sourceLargest ? dims(sc.sourceLargest->domain.dim()) : std::string("?")),
        fits);
}

// The time, frame by frame from each frame's held box (the model's error: docs/performance.md, Time estimate).
void printTimeEstimate(const TransferScan& sc)
{
    const turbio::SequenceScan& ts = sc.target;
    double seconds = 0.0, worst = 0.0;
    for (const turbio::FrameScan& fs : ts.frames) {
        const double s = turb::transferSecondsPerFrame(
            double(fs.domain.volume()), sc.ratio, matchedVoxels(sc.tv, sc.sv, sc.sourceVoxels, sc.ratio));
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
}

// The outputs can be written and are not inputs; a dry run lists the first and last few.
void checkTransferOutputs(const TransferArgs& a, const turbio::Sequence& target, const turbio::Sequence& source,
    const std::vector<int>& sourceFor, const std::vector<int>& sourceFrames, const turbio::FramePattern& outPattern,
    size_t first)
{
    std::vector<std::string> outputs, inputs;
    for (size_t i = first; i < target.frames.size(); ++i) outputs.push_back(outPattern.format(target.frames[i]));
    for (int t : target.frames) inputs.push_back(target.path(t));
    for (int sf : sourceFrames) inputs.push_back(source.path(sf));
    checkOutputs(outputs, inputs, a.write.noClobber, false);
    if (!a.dryRun) return;
    for (size_t i = first; i < target.frames.size(); ++i)
        if (i < first + 3 || i + 2 >= target.frames.size())
            printData("would write " + outPattern.format(target.frames[i]) + " from target " +
                      target.path(target.frames[i]) + " and source " + source.path(sourceFor[i]));
        else if (i == first + 3)
            printData("  ... " + std::to_string(target.frames.size() - first - 5) + " more frames");
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
    const TransferScan sc = scanInputs(a, target, source, targetFrames, sourceFrames);
    checkBoxes(a, sc, first);
    printLattice(a, sc);
    printOutputSize(a, sc, outPattern, targetFrames.size());
    checkTransferMemory(a, sc, source);
    printTimeEstimate(sc);
    checkTransferOutputs(a, target, source, sourceFor, sourceFrames, outPattern, first);
    turb::CoordBBox domain;
    for (const auto& fr : sc.target.frames)
        if (fr.error.empty() && !fr.span.empty()) domain.expand(fr.span);
    return domain.empty() ? domain : turb::refineDomain(domain, sc.ratio);
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

// The job's settings as the run uses them: threads, and a tile box held for the whole range, so --resume and the
// farm join see the same box on every frame.
void prepareJob(TransferArgs& a)
{
    a.settings.threads = a.threads;
    if (a.tileBox.empty()) return;
    if (!a.targetRead.cropToSmoke)
        throw turb::ValueError("--tile-box holds a box of the target; it cannot be combined with --target-no-crop");
    a.targetRead.holdBox = turb::parseTileBox(a.tileBox);
}

// A dry run's last check: a resume continues only frames this run would have made.
void checkDryResume(const TransferArgs& a, const FramePlan& p)
{
    if (!a.resume || p.first == 0) return;
    const std::string prevPath = p.out.format(p.target.frames[p.first - 1]);
    checkResumable(prevPath, turbio::readFrame(prevPath, p.target.frames[p.first - 1], turbio::ReadOptions{}),
        a.settings, a.write, p.target, p.source, a.tileBox);
}

// A resume with every frame written: nothing left to compute, but the frames must be this run's: a plan rewritten
// with other settings over the same scratch directory would otherwise hand on another run's frames.
void checkAllWritten(const TransferArgs& a, const FramePlan& p)
{
    const int last = p.target.frames.back();
    const std::string lastPath = p.out.format(last);
    turbio::ReadOptions ro;
    ro.cropToSmoke = false;
    checkResumable(lastPath, turbio::readFrame(lastPath, last, ro), a.settings, a.write, p.target, p.source, a.tileBox);
    logInfo("resume: every requested frame already exists (made with these settings); nothing to do");
}

void warnIgnoredWriteOptions(const TransferArgs& a)
{
    if (a.write.style != turbio::WriteStyle::Blender) return;
    if (a.velocityMarginGiven && a.write.velocityMargin >= 0)
        logWarning("--velocity-margin " + std::to_string(a.write.velocityMargin) +
                   " is ignored with --style blender: Blender's staggered velocity is written over the whole box");
    if (a.write.velocityVoxelScale > 1)
        logWarning("--vel-voxel-scale is ignored with --style blender: Blender's velocity is written on the frame's "
                   "lattice");
}

// The frames of a run, in order, and what carries from one to the next.
class FrameLoop
{
public:
    FrameLoop(const TransferArgs& a, const FramePlan& p, turb::TurbulenceTransfer& transfer,
        const turb::CoordBBox& sequenceDomain, std::string lastStateFile)
        : mA(a), mP(p), mTransfer(transfer), mDomain(sequenceDomain), mLastStateFile(std::move(lastStateFile))
    {}

    // Frame k's two inputs are read while frame k - 1 is computed and written: a read is mostly its guarded reader's
    // child process (fork, decode, the copy back), time the cores otherwise spend waiting. A read that fails throws
    // from get(), at frame k, after frame k - 1 is written, as reading in turn would.
    void run(TransferRun& done)
    {
        if (mP.first < mP.target.frames.size())
            mAhead = std::async(std::launch::async, [this] { return read(mP.first); });
        for (size_t i = mP.first; i < mP.target.frames.size(); ++i)
            if (frame(i)) ++done.framesWritten;
            else ++done.prerollFrames;
    }

private:
    std::pair<turb::Frame, turb::Frame> read(size_t k) const
    {
        const int tk = mP.target.frames[k];
        std::pair<turb::Frame, turb::Frame> in;
        in.first = readingAs("target", [&] { return turbio::readFrame(mP.target.path(tk), tk, mA.targetRead); });
        in.second = readingAs("source",
            [&] { return turbio::readFrame(mP.source.path(mP.sourceFor[k]), mP.sourceFor[k], mA.sourceRead); });
        return in;
    }

    // Frame i: read (ahead), transfer, write unless pre-roll, report. True when written.
    bool frame(size_t i)
    {
        const int t = mP.target.frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        const std::unique_ptr<FrameProgress> progress =
            reporter().frameProgress(int(i), int(mP.target.frames.size()), t);
        progress->begin("reading");
        const auto [tf, sf] = mAhead.get();
        if (i == mP.first) firstFrameRead(tf);
        if (i + 1 < mP.target.frames.size()) mAhead = std::async(std::launch::async, [this, i] { return read(i + 1); });
        turb::TransferResult r = process(i, tf, sf, *progress);
        if (i < mP.writeFrom) {
            progress->clear();
            logInfo("pre-roll frame " + std::to_string(t) + " done in " + fmt("%.2f s", secondsSince(t0)) +
                    " (not written)");
            return false;
        }
        tagOutput(r.frame, mA, mP, i, mTransfer.saveState(), mDomain);
        progress->begin("writing");
        const std::string outPath = mP.out.format(t);
        const nlohmann::json extra = frameJson(r, outPath, mP.sourceFor[i]);
        const std::string statePath = stateSlot(mP.out, mA, mTargetUnit, t, mLastStateFile);
        writeOutput(r.frame, t, mA, outPath, statePath, mWarnedClipping);
        if (!statePath.empty()) mLastStateFile = std::filesystem::path(statePath).filename().string();
        progress->clear();
        if (r.stats.sourceResampled && i == mP.first)
            logInfo("source resampled trilinearly from ratio " + fmt("%.4g", r.stats.sourceRatio) + " to " +
                    std::to_string(r.stats.ratio) + " (output voxel = target voxel / " + std::to_string(r.stats.ratio) +
                    ")");
        logFrameDetails(r, t);
        reporter().frameDone(
            FrameRecord{t, int(i), int(mP.target.frames.size()), secondsSince(t0), frameLine(r, outPath), extra});
        testKillPoint("after-frame", t);
        return true;
    }

    // The resume state's need: the target's time unit, known from the first frame read.
    void firstFrameRead(const turb::Frame& tf)
    {
        mTargetUnit = tf.timeUnit;
        if (const std::string odd = resumeStatePath(mP.out, mA, mTargetUnit, 1); !odd.empty())
            logInfo("resume state: " + odd + " and " + resumeStatePath(mP.out, mA, mTargetUnit, 0) +
                    " (odd and even frames in full precision, for --resume; not frames of the shot)");
    }

    turb::TransferResult process(size_t i, const turb::Frame& tf, const turb::Frame& sf, FrameProgress& progress)
    {
        try {
            return mTransfer.process(tf, sf, &progress);
        } catch (const turb::ValueError& e) {
            // The library names frames, not files: say which files this frame came from.
            const int t = mP.target.frames[i];
            throw turb::ValueError("frame " + std::to_string(t) + " (target " + mP.target.path(t) + ", source " +
                                       mP.source.path(mP.sourceFor[i]) + "): " + e.what(),
                e.settings());
        }
    }

    const TransferArgs& mA;
    const FramePlan& mP;
    turb::TurbulenceTransfer& mTransfer;
    const turb::CoordBBox mDomain;
    std::string mLastStateFile; // the state file the last frame written names: the next frame writes the other
    double mTargetUnit = 0.0;
    bool mWarnedClipping = false;
    std::future<std::pair<turb::Frame, turb::Frame>> mAhead;
};

TransferRun runTransferArgs(TransferArgs& a)
{
    TransferRun done;
    prepareJob(a);
    const FramePlan p = planFrames(a);
    a.stateTag = p.stateTag;
    defaultMargins(a, p.target, p.source, p.sourceFor);
    logVerbose("source crop margin: " + std::to_string(a.sourceRead.cropMargin) + " source voxels");
    const turb::CoordBBox sequenceDomain = preflight(a, p.target, p.source, p.sourceFor, p.out, p.writeFrom);
    done.framesAlreadyWritten = int(p.first);
    if (a.dryRun) {
        checkDryResume(a, p);
        return done;
    }
    lockOutputFrames(
        p.out, std::vector<int>(p.target.frames.begin() + long(std::max(p.first, p.writeFrom)), p.target.frames.end()));
    turb::TurbulenceTransfer transfer(a.settings);
    if (a.resume && p.first == p.target.frames.size()) {
        checkAllWritten(a, p);
        return done;
    }
    std::string lastStateFile; // the state file the last frame written names: the next frame writes the other
    if (a.resume && p.first > 0) lastStateFile = restoreFromLastWritten(a, p, transfer);
    warnIgnoredWriteOptions(a);
    reporter().runStarted("transfer");
    FrameLoop(a, p, transfer, sequenceDomain, lastStateFile).run(done);
    reporter().runFinished(0, nlohmann::json::object());
    return done;
}

} // namespace

TransferRun runTransfer(const TransferJob& job)
{
    TransferArgs a(job);
    return runTransferArgs(a);
}

} // namespace turb::run
