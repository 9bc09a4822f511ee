// vdbturb transfer: turbulence style transfer (seed 002) from a high-res source onto a low-res target.
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"
#include "RunReport.h"

#include <turb/Budget.h>
#include <turb/Error.h>
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
#include <memory>
#include <optional>
#include <sstream>

namespace vdbturb {

namespace {

struct TransferArgs
{
    std::string target, source, out;
    std::string frames, sourceFrames;
    int sourceOffset = 0;
    std::string wrap = "loop";
    std::string align = "none";
    std::string density = "advect";
    std::string densityScheme = "bfecc"; ///< --density-scheme
    bool noSeams = false, noTracking = false, noFollow = false, keepCoarse = false, resume = false, json = false, noResample = false;
    bool keepTargetDivergence = false;
    std::string energy = "source";
    int extendVelocity = 4;
    int preroll = 0;
    int band = 0; ///< --band: both band widths (3D and 2D); 0 = their defaults
    std::string seamSolver = "cgnr"; ///< --seam-solver
    turbio::ReadOptions targetRead, sourceRead;
    const CLI::Option* sourceCropMargin = nullptr; ///< given or not: its default depends on the ratio
    turbio::WriteOptions write;
    turb::TransferSettings settings;
};

// The source's frequency split and its candidate patches near the smoke's edge reach a few *coarse* voxels past
// the smoke; a margin of 8 source voxels is one coarse voxel at ratio 8 and moved block by 5% and tcoh by 14%
// on the ratio-8 pair (docs/design.md). The default margin is therefore 8 target voxels.
constexpr int kSourceMarginCoarseVoxels = 8;

void defaultSourceMargin(TransferArgs& a, const turbio::Sequence& target, const turbio::Sequence& source,
    const std::vector<int>& sourceFor)
{
    if (a.sourceCropMargin->count() > 0 || target.frames.empty() || !a.sourceRead.cropToSmoke) return;
    try {
        const double tv = turbio::scanFrame(target.path(target.frames.front()), target.frames.front(), a.targetRead).lattice.voxelSize;
        const double sv = turbio::scanFrame(source.path(sourceFor.front()), sourceFor.front(), a.sourceRead).lattice.voxelSize;
        a.sourceRead.cropMargin = std::max(a.sourceRead.cropMargin, kSourceMarginCoarseVoxels * turb::transferRatio(tv, sv, !a.noResample));
    } catch (const std::exception&) {
        // The preflight reports an unreadable frame or a bad ratio with its own message.
    }
}

turbio::SourceWrap parseWrap(const std::string& s)
{
    if (s == "pingpong") return turbio::SourceWrap::PingPong;
    if (s == "clamp") return turbio::SourceWrap::Clamp;
    if (s == "error") return turbio::SourceWrap::Error;
    return turbio::SourceWrap::Loop;
}

turb::FlowAlignment parseAlign(const std::string& s)
{
    if (s == "normalize") return turb::FlowAlignment::Normalize;
    if (s == "rotate") return turb::FlowAlignment::Rotate;
    if (s == "both") return turb::FlowAlignment::Both;
    return turb::FlowAlignment::None;
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

// A frame written trimmed to the smoke, in half floats or Blender style is not the state the next frame starts
// from. The exact state is then kept beside the outputs in one file, rewritten after every frame: one frame's
// disk, not the sequence's. "up/turb.####.vdb" keeps "up/.turb.resume.vdb". None for a single unnumbered file.
std::string resumeStatePath(const turbio::FramePattern& out, const turbio::WriteOptions& w)
{
    const bool lossy = w.velocityMargin >= 0 || w.halfFloat || w.style == turbio::WriteStyle::Blender;
    if (!lossy || !out.numbered()) return {};
    const std::filesystem::path p(out.prefix() + "resume" + out.suffix());
    return (p.parent_path() / ("." + p.filename().string())).string();
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
    const turbio::SequenceScan ts = checkInput("transfer", "target", target, targetFrames, a.targetRead, LatticePolicy::Refuse);
    const turbio::SequenceScan ss = checkInput("transfer", "source", source, sourceFrames, a.sourceRead, LatticePolicy::Refuse);
    reportTiming("target", ts, true, "target-");
    reportTiming("source", ss, true, "source-");

    const turbio::FrameScan& t0 = ts.frames.front();
    const turbio::FrameScan& s0 = ss.frames.front();
    const double tv = t0.lattice.voxelSize, sv = s0.lattice.voxelSize;
    const int f = turb::transferRatio(tv, sv, !a.noResample); // throws, saying why, where the run would
    const bool resampled = !turb::isIntegerRatio(tv, sv);
    const turbio::FrameScan* tl = ts.largestDomain();
    const turbio::FrameScan* sl = ss.largestDomain();
    const turb::CoordBBox tBox = tl ? tl->domain : t0.domain;
    const double tVoxels = double(tBox.volume());
    const double sVoxels = sl ? double(sl->domain.volume()) : 0.0;
    const turb::Lattice outLattice = turb::refinedLattice(t0.lattice, tBox, f);
    const turb::Coord outDim = turb::refineDomain(tBox, f).dim(); // a 2D target keeps its one z layer
    printData("ratio " + fmt("%.4g", tv / sv) + " (target voxel " + fmt("%g", tv) + ", source voxel " + fmt("%g", sv) + ")" +
              (resampled ? ": not an integer, the source is resampled trilinearly to ratio " + std::to_string(f) : ""));
    printData("output lattice: " + dims(outDim) + " voxels of " + fmt("%g", outLattice.voxelSize) + ", world " +
              worldBox(tBox, t0.lattice) + " (the target's held box: its smoke and margin" + (tl && tl->frame != t0.frame ? " at frame " +
              std::to_string(tl->frame) + ", its largest" : "") + ")");

    // Output size (Blosc gains little on noisy floats). Velocity covers the target velocity's box padded by two
    // voxels, at f^3 voxels each (zero beyond it: not written), or trimmed, the smoke and the margin's shell
    // (1.2x the smoke at margin 1, 1.45x at 2 on the Blender plume2 pair at 128^3).
    // The smoke, where density and temperature are written, is the target's smoke voxels x f^3 and the up-sampling's
    // spread (1.6x: 53 k fine voxels from 532 coarse ones at plume2's frame 1).
    const bool trimmed = a.write.velocityMargin >= 0 && a.write.style == turbio::WriteStyle::Houdini;
    const double floatBytes = a.write.halfFloat ? 2.0 : 4.0;
    const double box = double(outDim.x()) * outDim.y() * outDim.z();
    double outBytes = 0.0, stateBytes = 0.0;
    for (const auto& fr : ts.frames) {
        const double cells = double(f) * f * (turb::isFlat(tBox) ? 1.0 : f);
        const double smoke = std::min(box, 1.6 * cells * (fr.densityActive > 0 ? double(fr.densityActive) : double(fr.domain.volume())));
        const double whole = std::min(box, cells * velocityBoxVoxels(fr));
        const double vel = trimmed ? std::min(whole, smoke * (1.0 + 0.25 * a.write.velocityMargin)) : whole;
        outBytes = std::max(outBytes, floatBytes * (3.0 * vel + 2.0 * smoke));
        stateBytes = std::max(stateBytes, 12.0 * whole + 4.0 * smoke);
    }
    printData("output size: about " + turbio::formatBytes(outBytes) + " per frame, " +
              turbio::formatBytes(outBytes * double(targetFrames.size())) + " for " + std::to_string(targetFrames.size()) +
              " frame" + (targetFrames.size() == 1 ? "" : "s"));
    if (const std::string state = resumeStatePath(outPattern, a.write); !state.empty())
        printData("resume state: " + state + ", about " + turbio::formatBytes(stateBytes) +
                  " (the last frame in full precision, rewritten every frame)");

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
                f2 = turb::transferRatio(tv, sv2, !a.noResample);
            } catch (const turb::ValueError&) {
                break; // the ratio fell below 2
            }
            const double n2 = sVoxels / double(down) / double(down) / double(down);
            if (turb::transferPeakBytes(tVoxels, f2, matchedVoxels(sv2, n2, f2)) <= 0.9 * double(usable))
                fits = "A source box-downsampled by " + std::to_string(down) + " (voxel " + fmt("%g", sv2) + ", ratio " +
                       std::to_string(f2) + ") fits: vdbturb resample " + source.pattern.str() + " --down " +
                       std::to_string(down) + " --out PROXY.####.vdb";
        }
        if (fits.empty()) fits = "No coarser source fits: crop or coarsen the target first.";
    }
    checkMemory(need, "target " + dims(tBox.dim()) + " at ratio " + std::to_string(f) + " = " + dims(outDim) +
                          " output voxels, source " + (sl ? dims(sl->domain.dim()) : std::string("?")),
        fits);

    std::vector<std::string> outputs, inputs;
    for (size_t i = first; i < target.frames.size(); ++i) outputs.push_back(outPattern.format(target.frames[i]));
    for (int t : target.frames) inputs.push_back(target.path(t));
    for (int sf : sourceFrames) inputs.push_back(source.path(sf));
    checkOutputs(outputs, inputs, a.write.noClobber, false);
    if (globals().dryRun)
        for (size_t i = first; i < target.frames.size(); ++i)
            if (i < first + 3 || i + 2 >= target.frames.size())
                printData("would write " + outPattern.format(target.frames[i]) + " from target " + target.path(target.frames[i]) +
                          " and source " + source.path(sourceFor[i]));
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
    os << "style=" << (w.style == turbio::WriteStyle::Blender ? "blender" : "houdini") << ";half=" << (w.halfFloat ? 1 : 0)
       << ";clipping=" << w.densityTolerance << ";velocity-margin=" << w.velocityMargin;
    return os.str();
}

// Continuing with other settings or other inputs would silently mix two looks, or two shots, in one sequence.
void checkResumable(const std::string& prevPath, const turb::Frame& prevOut, const turb::TransferSettings& s,
    const turbio::WriteOptions& w, const turbio::Sequence& target, const turbio::Sequence& source)
{
    std::vector<std::string> diff;
    const auto saved = prevOut.metadata.find(turb::meta::kSettings);
    if (saved != prevOut.metadata.end()) diff = turb::settingsDifferences(saved->second, turb::outputSettingsText(s));
    else logWarning(prevPath + ": no vdbturb_settings metadata (written by an older vdbturb): the settings cannot be checked");
    // Older outputs carry no write settings: nothing to compare them with.
    if (const auto written = prevOut.metadata.find(turb::meta::kWriteSettings); written != prevOut.metadata.end())
        for (const std::string& d : turb::settingsDifferences(written->second, writeSettingsText(w))) diff.push_back(d);
    for (const auto& [key, now] : {std::pair<const char*, std::string>{turb::meta::kTargetInput, inputId(target)},
             std::pair<const char*, std::string>{turb::meta::kSourceInput, inputId(source)}}) {
        const auto m = prevOut.metadata.find(key);
        if (m != prevOut.metadata.end() && m->second != now)
            diff.push_back(std::string(key == turb::meta::kTargetInput ? "target" : "source") + ": " + m->second + " -> " + now);
    }
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
            else
                return st;
        } catch (const turb::Error& e) {
            why = e.what();
        }
    }
    logWarning("resume: the exact state " + side + " cannot be used: " + why + ". Continuing from " + prevPath +
               " as written: the detail outside its velocity margin starts again, and the frames after differ "
               "slightly from an uninterrupted run's");
    return std::nullopt;
}

int runTransfer(TransferArgs& a)
{
    turb::TransferSettings& s = a.settings;
    s.threads = globals().threads;
    globals().json = a.json;
    s.seams.enabled = !a.noSeams;
    if (a.band > 0) s.seams.bandWidth = s.seams.bandWidth2D = a.band;
    s.seams.solver = a.seamSolver == "eigen" ? turb::SeamSolver::EigenLscg : turb::SeamSolver::Cgnr;
    s.trackGlobalPatches = !a.noTracking;
    s.followSourceFlow = !a.noFollow;
    s.resampleSource = !a.noResample;
    s.removeCoarseDetail = !a.keepCoarse;
    s.detailEnergy = a.energy == "none" ? turb::DetailEnergy::None
                     : a.energy == "pasted" ? turb::DetailEnergy::Pasted : turb::DetailEnergy::Source;
    s.compensateTargetDivergence = !a.keepTargetDivergence;
    s.alignment = parseAlign(a.align);
    s.densityMode = a.density == "lookback" ? turb::DensityMode::LookBack : turb::DensityMode::Advect;
    for (const auto sc : {turb::AdvectSettings::Scheme::BFECC, turb::AdvectSettings::Scheme::MacCormack,
             turb::AdvectSettings::Scheme::SemiLagrangian})
        if (a.densityScheme == turb::schemeName(sc)) s.densityScheme = sc;

    // Only the source: its detail is what the extension cleans up. The target's velocity stays as stored,
    // since the output must keep the target's coarse motion exactly as the file has it.
    a.sourceRead.extendVelocity = a.extendVelocity;
    turbio::Sequence target = turbio::resolveSequence(a.target, a.frames);
    const turbio::Sequence source = turbio::resolveSequence(a.source, a.sourceFrames);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    if (!target.missing.empty())
        throw turb::IoError(target.pattern.str() + ": missing target frames " + turbio::formatFrameList(target.missing));
    if (target.frames.size() > 1 && !outPattern.numbered())
        throw turb::ValueError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                               std::to_string(target.frames.size()) + " frames are requested");
    const turbio::SourceWrap wrap = parseWrap(a.wrap);
    std::vector<int> sourceFor;
    try {
        for (int t : target.frames) sourceFor.push_back(turbio::mapSourceFrame(t, source.frames, a.sourceOffset, wrap));
    } catch (const turb::ValueError& e) {
        throw turb::ValueError(std::string(e.what()) + "; --source-offset or another --source-wrap maps it");
    }

    logInfo("transfer: target " + target.pattern.str() + " frames " + turbio::formatFrameList(target.frames) +
            ", source " + source.pattern.str() + " frames " + turbio::formatFrameList(source.frames) +
            (source.frames.size() < target.frames.size() ? " (" + a.wrap + ")" : ""));

    size_t first = 0;
    if (a.resume)
        while (first < target.frames.size() && std::filesystem::exists(outPattern.format(target.frames[first]))) ++first;
    // The detail and the advected density are state: a run that starts at a later frame than the cache's first
    // differs from a longer run's frames there. --preroll runs up to N earlier cache frames first, unwritten.
    size_t writeFrom = first;
    if (first == 0 && !target.frames.empty()) {
        const turbio::Sequence whole = turbio::resolveSequence(a.target);
        std::vector<int> earlier;
        for (int t : whole.frames)
            if (t < target.frames.front()) earlier.push_back(t);
        if (a.preroll > 0) {
            const size_t n = std::min(earlier.size(), size_t(a.preroll));
            std::vector<int> pre(earlier.end() - std::ptrdiff_t(n), earlier.end());
            if (n < size_t(a.preroll))
                logWarning("--preroll " + std::to_string(a.preroll) + ": the target cache has only " + std::to_string(n) +
                           " frames before frame " + std::to_string(target.frames.front()));
            std::vector<int> preSource;
            for (int t : pre) preSource.push_back(turbio::mapSourceFrame(t, source.frames, a.sourceOffset, wrap));
            sourceFor.insert(sourceFor.begin(), preSource.begin(), preSource.end());
            target.frames.insert(target.frames.begin(), pre.begin(), pre.end());
            writeFrom = n;
            if (n > 0)
                logInfo("pre-roll: frames " + turbio::formatFrameList(pre) + " run first and are not written");
        } else if (!earlier.empty()) {
            logWarning("the detail starts fresh at frame " + std::to_string(target.frames.front()) + " while the cache begins at " +
                       std::to_string(earlier.front()) + ": these frames differ from a run started earlier (--preroll " +
                       std::to_string(earlier.size()) + " runs earlier frames first without writing them)");
        }
    }
    defaultSourceMargin(a, target, source, sourceFor);
    logVerbose("source crop margin: " + std::to_string(a.sourceRead.cropMargin) + " source voxels");
    const turb::CoordBBox sequenceDomain = preflight(a, target, source, sourceFor, outPattern, writeFrom);
    if (globals().dryRun) {
        if (a.resume && first > 0) {
            const std::string prevPath = outPattern.format(target.frames[first - 1]);
            checkResumable(prevPath, turbio::readFrame(prevPath, target.frames[first - 1], turbio::ReadOptions{}), s, a.write, target,
                source);
        }
        return kOk;
    }

    turb::TurbulenceTransfer transfer(s);
    if (a.resume) {
        // Continue after the last frame already written, from the state saved with it.
        if (first == target.frames.size()) {
            logInfo("resume: every requested frame already exists; nothing to do");
            return kOk;
        }
        if (first > 0) {
            const int prev = target.frames[first - 1];
            const std::string prevPath = outPattern.format(prev);
            turbio::ReadOptions ro;
            ro.cropToSmoke = false; // the file holds the box the run held (written cropped); restore needs all of it
            const turb::Frame prevOut = turbio::readFrame(prevPath, prev, ro);
            const auto it = prevOut.metadata.find(turb::meta::kState);
            if (it == prevOut.metadata.end())
                throw turb::IoError(prevPath + ": no vdbturb_state metadata to resume from");
            checkResumable(prevPath, prevOut, s, a.write, target, source);
            const turb::Frame prevTarget = turbio::readFrame(target.path(prev), prev, a.targetRead);
            try {
                const std::optional<turb::Frame> state = resumeStateFrame(prevPath, prev, prevOut);
                transfer.restore(it->second, state ? *state : prevOut, prevTarget);
            } catch (const turb::Error& e) {
                throw turb::IoError(prevPath + ": cannot resume from this frame: " + e.what());
            } catch (const std::exception& e) {
                throw turb::IoError(prevPath + ": cannot resume from this frame: damaged vdbturb_state (" + e.what() + ")");
            }
            logInfo("resume: continuing after frame " + std::to_string(prev));
        }
    }

    if (a.write.style == turbio::WriteStyle::Blender && a.write.velocityMargin >= 0)
        logWarning("--velocity-margin " + std::to_string(a.write.velocityMargin) +
                   " is ignored with --style blender: Blender's staggered velocity is written over the whole box");
    RunReport report("transfer", a.json);
    const std::string statePath = resumeStatePath(outPattern, a.write);
    bool warnedClipping = false;
    if (!statePath.empty()) logVerbose("resume state: " + statePath + " (the last frame in full precision)");
    const int count = int(target.frames.size());
    for (size_t i = first; i < target.frames.size(); ++i) {
        const int t = target.frames[i];
        const auto t0 = std::chrono::steady_clock::now();
        ConsoleProgress progress(int(i), count, t);
        progress.begin("reading");
        const turb::Frame tf = turbio::readFrame(target.path(t), t, a.targetRead);
        const turb::Frame sf = turbio::readFrame(source.path(sourceFor[i]), sourceFor[i], a.sourceRead);
        turb::TransferResult r;
        try {
            r = transfer.process(tf, sf, &progress);
        } catch (const turb::ValueError& e) {
            // The library names frames, not files: say which files this frame came from.
            throw turb::ValueError("frame " + std::to_string(t) + " (target " + target.path(t) + ", source " +
                                   source.path(sourceFor[i]) + "): " + e.what());
        }
        if (i < writeFrom) {
            progress.clear();
            logInfo("pre-roll frame " + std::to_string(t) + " done in " + fmt("%.2f s", secondsSince(t0)) + " (not written)");
            continue;
        }
        r.frame.metadata[turb::meta::kState] = transfer.saveState();
        r.frame.metadata[turb::meta::kSettings] = turb::outputSettingsText(s);
        r.frame.metadata[turb::meta::kWriteSettings] = writeSettingsText(a.write);
        r.frame.metadata[turb::meta::kTargetInput] = inputId(target);
        r.frame.metadata[turb::meta::kSourceInput] = inputId(source);
        r.frame.metadata[turb::meta::kSourceFrame] = std::to_string(sourceFor[i]);
        r.frame.metadata[turb::meta::kCommand] = "transfer";
        if (!sequenceDomain.empty()) {
            std::ostringstream box; // the format of vdbturb_domain
            box << sequenceDomain.min().x() << ' ' << sequenceDomain.min().y() << ' ' << sequenceDomain.min().z() << ' '
                << sequenceDomain.max().x() << ' ' << sequenceDomain.max().y() << ' ' << sequenceDomain.max().z();
            r.frame.metadata[turb::meta::kSequenceDomain] = box.str();
        }
        progress.begin("writing");
        const std::string outPath = outPattern.format(t);
        turbio::ensureParentDirectory(outPath);
        warnIfClippedAway(r.frame, a.write, outPath, warnedClipping);
        if (!statePath.empty())
            r.frame.metadata[turb::meta::kResumeStateFile] = std::filesystem::path(statePath).filename().string();
        turbio::writeFrame(outPath, r.frame, a.write);
        if (!statePath.empty()) {
            // After the output: a run stopped between the two leaves a state one frame behind, which resume detects.
            // The written frame is not needed any more: its fields move into the state.
            turb::Frame st;
            st.number = t;
            st.dt = r.frame.dt;
            st.velocity = std::move(r.frame.velocity);
            st.density = std::move(r.frame.density);
            st.metadata = std::move(r.frame.metadata);
            st.metadata[turb::meta::kResumeFrame] = std::to_string(t);
            turbio::writeFrame(statePath, st, turbio::WriteOptions{});
        }
        progress.clear();

        const turb::TransferStats& st = r.stats;
        nlohmann::json extra;
        extra["out"] = outPath;
        extra["source_frame"] = sourceFor[i];
        extra["empty"] = r.empty;
        extra["ratio"] = st.ratio;
        if (st.sourceResampled) extra["source_ratio_resampled_from"] = st.sourceRatio;
        if (st.sourceResampled && i == first)
            logInfo("source resampled trilinearly from ratio " + fmt("%.4g", st.sourceRatio) + " to " + std::to_string(st.ratio) +
                    " (output voxel = target voxel / " + std::to_string(st.ratio) + ")");
        extra["patches"] = st.localPatches;
        extra["global_searches"] = st.globalSearches;
        extra["tracked"] = st.trackedPatches;
        extra["followed"] = st.followedPatches;
        extra["regenerated"] = st.regeneratedPatches;
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
        nlohmann::json steps;
        for (const auto& [name, sec] : st.seconds.named()) steps[name] = sec;
        extra["steps_s"] = steps;
        std::string human = r.empty ? "no smoke in target: wrote the up-sampled target"
                                    : std::to_string(st.localPatches) + " patches (" + std::to_string(st.globalSearches) +
                                          " global searches), seams " + std::to_string(st.seams.iterations.size()) + " EM";
        if (!st.seams.iterations.empty()) {
            const auto& last = st.seams.iterations.back();
            human += fmt(" E_b %.4g", last.energy) + " (CG " + std::to_string(last.cgIterations) + fmt(" it, res %.1e)", last.cgResidual);
        }
        human += " -> " + outPath;
        for (size_t k = 0; k < st.seams.iterations.size(); ++k) {
            const auto& it = st.seams.iterations[k];
            logVerbose("frame " + std::to_string(t) + ": seam EM " + std::to_string(k + 1) + ": CG " +
                       std::to_string(it.cgIterations) + " iterations, residual " + fmt("%.2e", it.cgResidual) +
                       ", E_b " + fmt("%.6g", it.energy));
        }
        logVerbose("frame " + std::to_string(t) + ": seams: setup " + fmt("%.2f s", st.seams.setupSeconds) + ", M-steps " +
                   fmt("%.2f s", st.seams.mStepSeconds) + ", E-steps " + fmt("%.2f s", st.seams.eStepSeconds) + ", band " +
                   std::to_string(st.seams.bandVoxels) + " voxels, " + std::to_string(st.seams.boundaryPatches) + " boundary patches");
        if (!r.empty) {
            std::string detailLine = "frame " + std::to_string(t) + ": detail energy x" + fmt("%.3f", st.energyScale) +
                                     fmt(", coarse part kept %.2f", st.coarseKept) + fmt(" (lf_err %.3f)", st.lfErr);
            if (st.detailChange)
                detailLine += fmt(", change against last frame advected %.3f", *st.detailChange) +
                              fmt(" (growth %.3f: at least ", st.detailGrowth) +
                              fmt("%.3f)", std::max(0.0, 1.0 - 1.0 / st.detailGrowth));
            logVerbose(detailLine);
        }
        std::string timing = "frame " + std::to_string(t) + ": time";
        for (const auto& [name, sec] : st.seconds.named())
            if (std::string(name) != "total") timing += std::string(" ") + name + fmt(" %.2f", sec);
        logVerbose(timing);
        report.frameDone(t, int(i), count, secondsSince(t0), human, extra);
    }
    report.finish();
    return kOk;
}

} // namespace

Command transferCommand()
{
    auto args = std::make_shared<TransferArgs>();
    Command c;
    c.name = "transfer";
    c.help = "Turbulence style transfer: add a high-res source's detail to a low-res target's motion (3D, or 2D: one-z-layer caches)";
    c.setup = [args](CLI::App* app) {
        TransferArgs& a = *args;
        turb::TransferSettings& s = a.settings;
        app->add_option("--target", a.target, "Low-res target cache (velocity + density): pattern or one file")->required();
        app->add_option("--source", a.source, "High-res source cache whose turbulence is transferred")->required();
        app->add_option("--out", a.out, "Output pattern, e.g. up/turb.####.vdb (directories are created)")->required();
        app->add_option("--frames", a.frames, "Target frames, e.g. 1001-1100x2 (default: all on disk)")->check(frameListCheck());
        app->add_option("--source-frames", a.sourceFrames, "Restrict the source to these frames")->check(frameListCheck());
        app->add_option("--source-offset", a.sourceOffset, "Source frame = target frame + offset (default 0)");
        app->add_option("--source-wrap", a.wrap, "When the source runs out: loop (default), pingpong, clamp, error")
            ->check(CLI::IsMember({"loop", "pingpong", "clamp", "error"}));
        app->add_option("--alpha", s.alpha, "Weight of the density-mask term in matching (paper 0.004)")->check(finiteIn(0.0));
        app->add_option("--beta", s.beta, "Weight of the temporal term: previous detail advected (paper 0.5)")->check(finiteIn(0.0));
        app->add_option("--gamma", s.seams.gamma, "Weight of divergence in seam smoothing (paper 10)")->check(finiteIn(0.0));
        app->add_option("--density-threshold", s.densityThreshold, "D_th: smoke where density > this (default 0.01)")
            ->check(finiteIn(0.0));
        app->add_option("--patch", s.localPatch, "B: local patch edge in output voxels (default 8)")->check(CLI::Range(2, 64));
        app->add_option("--global-patch", s.globalPatch, "b: global patch edge in target voxels, odd (default 2*ceil(B/f)+1)");
        app->add_option("--pca", s.pcaComponents, "PCA dimensions of patch descriptors (default 16)")->check(CLI::Range(1, 256));
        app->add_option("--stride", s.localStride, "Spacing of candidate source patches in the local search (default 2)")->check(CLI::Range(1, 16));
        app->add_option("--candidates", s.refineCandidates, "Local candidates re-scored at full resolution (default 24)")->check(CLI::Range(1, 4096));
        app->add_option("--band", a.band, "Seam band: voxels on each side of a patch border (default 2; 3 for 2D caches)")->check(CLI::Range(1, 32));
        app->add_option("--boundary-patch", s.seams.boundaryPatch, "C: boundary patch edge, even (default B)");
        app->add_option("--em-iterations", s.seams.maxEmIterations, "Seam EM iterations at most (default 3)")->check(CLI::Range(1, 50));
        app->add_option("--em-tolerance", s.seams.emTolerance, "Stop EM when E_b changes by less than this fraction (default 0.02)");
        app->add_option("--cg-iterations", s.seams.maxCgIterations, "CG iterations per E-step at most (default 100)")->check(CLI::Range(1, 100000));
        app->add_option("--cg-tolerance", s.seams.cgTolerance, "CG relative residual (default 1e-3)");
        app->add_option("--seam-solver", a.seamSolver, "Seam E-step solver: cgnr (default) or eigen (Eigen's LSCG, for measuring)")->check(CLI::IsMember({"cgnr", "eigen"}));
        app->add_option("--value-weight", s.seams.valueWeight,
               "Weight of rows keeping carried detail at its value in the seam solve, times the patch's blend weight "
               "(default 0 = the paper's energy; 5 lowers pair a's tcoh from 0.196 to 0.192 but raises div_rel above the source's "
               "on pairs b and d; see docs/transfer.md)")
            ->check(CLI::NonNegativeNumber);
        app->add_option("--box-weight", s.seams.boxWeight,
               "Weight of the seam solve's rows holding U_h's coarse-cell means (default 10; 0 = the solve may change them "
               "and --coarse-tolerance alone bounds them)")
            ->check(CLI::NonNegativeNumber);
        app->add_option("--box-keep", s.seams.boxKeep,
               "The seam solve's box rows hold each coarse cell's mean of U_h at this fraction of its value on entry "
               "(default 1: the solve leaves the coarse motion as it came; 0: pulls it to zero)")
            ->check(CLI::Range(0.0, 1.0));
        app->add_option("--coarse-tolerance", s.coarseTolerance,
               "lf_err bound: U_h's coarse-cell means are reduced only until they are this fraction of the target's coarse "
               "velocity (rms over smoke cells; default 0.04; 0 = removed exactly). What is left in is carried detail: "
               "removing it changes the detail every frame (tcoh)")
            ->check(CLI::Range(0.0, 1.0));
        app->add_option("--coherence", s.coherence,
               "Take a neighbour's continued source patch when it matches within this fraction of the best (default 0 = off, the paper)")
            ->check(CLI::NonNegativeNumber);
        app->add_flag("--whole-fresh-patches", s.solveFreshPatchesWhole,
            "Solve every voxel of patches without carried detail (first frames, entering smoke), not only the seam band: "
            "the divergence term then reaches their insides (first frames' div_rel below the source's on pairs a, b, d; "
            "tcoh +0.002 on pair a, +0.007 on pair c; docs/transfer.md)");
        app->add_flag("--no-seams", a.noSeams, "Paste patches without seam smoothing (ablation)");
        app->add_flag("--no-resample-source", a.noResample,
            "Refuse a source whose voxel size is not an integer fraction of the target's (default: resample it trilinearly to "
            "the nearest integer ratio; the output then has voxel target/ratio)");
        app->add_flag("--no-follow-source", a.noFollow,
            "Re-paste patches where last frame found them instead of following the source's flow (ablation)");
        app->add_option("--follow-tolerance", s.followTolerance,
               "Keep a patch's continuation in the source's flow while its E_h is within (1 + this) of the best (default 1)")
            ->check(CLI::NonNegativeNumber);
        app->add_option("--source-smoke", s.sourceSmoke,
               "Fraction of a source patch's voxels that must hold smoke for it to be a candidate (default 0.5; 0 = any "
               "smoke, the paper's rule)")
            ->check(CLI::Range(0.0f, 1.0f));
        app->add_flag("--no-tracking", a.noTracking, "Run the global search every frame instead of following last frame's patch (ablation)");
        app->add_flag("--keep-coarse-detail", a.keepCoarse, "Do not remove U_h's coarse part (lets lf_err grow)");
        app->add_option("--detail-energy", a.energy,
               "Calibrate U_h's energy per smoke voxel to: source (the source's high-frequency energy; default), "
               "pasted (the chosen patches'), none")
            ->check(CLI::IsMember({"source", "pasted", "none"}));
        app->add_flag("--no-target-divergence", a.keepTargetDivergence,
            "Seam gamma term penalises div(U_h) only, as in the paper, not div(up(u_t) + U_h)");
        app->add_option("--temporal-blend", s.temporalBlend,
            "Weight of last frame's detail advected through the target, mixed into the patches it reaches (default 0.95; 0 = paper)")
            ->check(CLI::Range(0.0, 0.999));
        app->add_option("--regenerate", s.regenerate,
            "Regenerate carried detail that the flow has stretched: where its gradient energy along the flow over across "
            "it falls below this fraction of the fresh patches', it is blended at --regenerate-blend instead "
            "(default 0.6; 0 = off)")
            ->check(CLI::Range(0.0, 1.0));
        app->add_option_function<float>("--regenerate-blend", [args](float v) { args->settings.regenerateBlend = args->settings.regenerateBlend2D = v; },
            "Weight of the carried detail per frame in a regenerated patch (default 0.5; 0.6 in 2D)")
            ->check(CLI::Range(0.0, 0.999));
        app->add_option("--align", a.align, "Match after aligning flows: none (paper), normalize, rotate, both")
            ->check(CLI::IsMember({"none", "normalize", "rotate", "both"}));
        app->add_option("--density", a.density, "Output density: advect (default) or lookback (seed 003 supplement)")
            ->check(CLI::IsMember({"advect", "lookback"}));
        app->add_option("--lookback", s.lookBackFrames, "m for --density lookback (default 12)")->check(CLI::Range(1, 100));
        app->add_option("--density-scheme", a.densityScheme,
               "Advection scheme of the output density: bfecc (default), maccormack (one backtrace fewer, faster; more "
               "mass at a sharp inflow) or semi-lagrangian (fastest, shows the coarse cells at the smoke's edge)")
            ->check(CLI::IsMember({"bfecc", "maccormack", "semi-lagrangian"}));
        app->add_option("--density-guide", s.densityGuide.strength,
               "Move the output density's coarse cell means this fraction of the way onto the target's each frame "
               "(default 1; 0 = off: the high-res density drifts from the target's)")
            ->check(finiteIn(0.0, 1.0));
        app->add_option("--extend-velocity", a.extendVelocity,
               "Continue the source's velocity this many voxels past its active region (Blender clips velocity to the "
               "smoke; the zeros beyond would read as turbulence at the smoke's edge). Default 4; 0 = off")
            ->check(CLI::Range(0, 64));
        app->add_option("--velocity-margin", a.write.velocityMargin,
               "Write velocity only within N voxels of the smoke, and temperature and flame only at it (smaller files; 1 covers a "
               "renderer's motion blur, re-advection needs the smoke's travel per frame in voxels); -1 = the whole "
               "box (default; --style blender always writes the whole box). --resume stays exact through a full-precision "
               "copy of the last frame kept beside the outputs")
            ->check(CLI::Range(-1, 64));
        app->add_option("--preroll", a.preroll,
               "Run up to N cache frames before the first requested one without writing them, so the detail and density "
               "are established as in a longer run (default 0; a warning says when the run starts after the cache's first frame)")
            ->check(CLI::NonNegativeNumber);
        app->add_flag("--resume", a.resume, "Skip frames already written and continue from the state saved in the last one");
        app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.targetRead, "target");
        addReadOptions(app, a.sourceRead, "source");
        a.sourceCropMargin = app->get_option("--source-crop-margin");
        app->get_option("--source-crop-margin")
            ->description("Source voxels kept around the source's smoke (default: 8 target voxels, 8 x the ratio)");
        addWriteOptions(app, a.write);
    };
    c.run = [args] { return runTransfer(*args); };
    return c;
}

} // namespace vdbturb
