// turb::run::runSynth: vdbturb synth's run, from a coarse flow to files (turb/run/Synth.h).
#include <turb/run/Synth.h>

#include "RunHelpers.h"

#include "SynthSteps.h"

#include <turb/run/Output.h>

#include <turb/Budget.h>
#include <turb/Error.h>
#include <turb/Metadata.h>
#include <turb/Resample.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iterator>

namespace turb::run {

using detail::secondsSince;

namespace {

using namespace synth;

// The synthesis carries look-back density only when the coarse input has density and it is written.
bool cf0HasDensity(const turb::Frame& f, const SynthJob& a) { return f.hasDensity() && a.seq.density; }

// Synth's density sources and look-back need one box over the sequence: the union of the frames' held boxes (each
// the smoke and its margin, strays left out), not the cache's domain. Over every frame on disk, not only the
// requested ones (header boxes: cheap): a shot rendered in parts (--frames 1-10, then 11-20, or on a farm) then
// holds the same box, and gives the same frames, as one run over the whole shot.
turb::CoordBBox heldBoxOverShot(const turbio::Sequence& seq, const std::vector<int>& frames,
    const turbio::SequenceScan& scan, const turbio::ReadOptions& ro)
{
    // The requested frames are scanned already; only the others are read here.
    const turbio::Sequence onDisk = turbio::resolveSequence(seq.pattern.str());
    std::vector<int> asked = frames, onDiskSorted = onDisk.frames, others;
    std::sort(asked.begin(), asked.end());
    std::sort(onDiskSorted.begin(), onDiskSorted.end());
    std::set_difference(
        onDiskSorted.begin(), onDiskSorted.end(), asked.begin(), asked.end(), std::back_inserter(others));
    turb::CoordBBox all;
    for (const auto& fs : scan.frames) all.expand(fs.domain);
    if (!others.empty())
        for (const auto& fs : turbio::scanSequence(onDisk, others, ro).frames) all.expand(fs.domain);
    return all;
}

// Before anything is read in full: every frame's headers, one lattice, the output paths. Sets the one box a
// cache is held over (synth's sources and look-back need one box over the sequence).
std::optional<turbio::SequenceScan> preflightSynth(
    SynthJob& a, const CoarseSource& source, const std::vector<int>& frames, const turbio::FramePattern& outPattern)
{
    std::optional<turbio::SequenceScan> scan;
    std::vector<std::string> outputs, inputs;
    for (int fr : frames) outputs.push_back(outPattern.format(fr));
    if (const auto& seq = source.sequence()) {
        turbio::ReadOptions ro = a.read;
        ro.requireDensity = false;
        scan = checkInput("synth", "target", *seq, frames, ro, LatticePolicy::Refuse);
        reportTiming("target", *scan, true);
        if (a.read.cropToSmoke) a.read.holdBox = heldBoxOverShot(*seq, frames, *scan, ro);
        for (int fr : frames) inputs.push_back(seq->path(fr));
    }
    checkOutputs(outputs, inputs, a.write.noClobber, a.skipExisting);
    return scan;
}

std::string dims(const turb::Coord& d)
{
    return std::to_string(d.x()) + "x" + std::to_string(d.y()) + "x" + std::to_string(d.z());
}

// The output lattice of the coarse box `coarse`, for the plan (dry run and -v).
void printOutputLattice(const SynthJob& a, const turb::Frame& f0, const turb::CoordBBox& coarse, bool volume)
{
    const turb::FineDomain d = turb::fineDomain(f0.velocity, a.seq.factor);
    const turb::Lattice& cl = f0.velocity.lattice();
    const turb::Vec3d lo = cl.indexToWorld(coarse.min().asVec3d() - turb::Vec3d(0.5));
    const turb::Vec3d hi = cl.indexToWorld(coarse.max().asVec3d() + turb::Vec3d(0.5));
    const double outVoxels = double(coarse.volume()) * std::pow(double(a.seq.factor), volume ? 3.0 : 2.0);
    printData("output lattice: " + dims(d.box.dim()) + " voxels of " + fmt("%g", d.lattice.voxelSize) + " (factor " +
              std::to_string(a.seq.factor) + "), world (" + fmt("%.4g", lo.x()) + "," + fmt("%.4g", lo.y()) + "," +
              fmt("%.4g", lo.z()) + ")-(" + fmt("%.4g", hi.x()) + "," + fmt("%.4g", hi.y()) + "," +
              fmt("%.4g", hi.z()) + "); output size about " + turbio::formatBytes(outVoxels * 16.0) + " per frame");
}

// The output lattice (dry run and -v) and the memory check, from the largest coarse frame.
void checkSynthLatticeAndMemory(const SynthJob& a, const turb::Frame& f0,
    const std::optional<turbio::SequenceScan>& scan, bool volume, int frameCount)
{
    const turb::SynthSettings& s = a.seq.synth;
    turb::CoordBBox coarse = f0.velocity.bbox();
    if (scan)
        if (const turbio::FrameScan* l = scan->largestDomain()) coarse = l->domain;
    if (reporter().showsPlan()) printOutputLattice(a, f0, coarse, volume);
    const int lb = cf0HasDensity(f0, a) ? a.seq.lookback : 0;
    // The synthesis runs on the box grown by --face-padding on its open faces (walls not grown).
    double grown = 1.0;
    for (int ax = 0; ax < (volume ? 3 : 2); ++ax) {
        const int open = !(s.boundary.walls & (1u << (2 * ax))) + !(s.boundary.walls & (1u << (2 * ax + 1)));
        grown *= double(coarse.dim()[ax] + open * s.facePadding) / double(coarse.dim()[ax]);
    }
    const double coarseVoxels = (volume ? double(coarse.volume()) : double(coarse.volume()) / a.seq.factor) * grown;
    const double need = turb::synthPeakBytes(coarseVoxels, a.seq.factor, frameCount, lb);
    const long long usable = turbio::usableMemoryBytes();
    const int fMax = usable > 0 ? turb::largestSynthFactor(0.9 * double(usable), coarseVoxels, frameCount, lb) : 0;
    checkMemory(need, dims(coarse.dim()) + " coarse voxels at factor " + std::to_string(a.seq.factor),
        fMax >= 1 ? "--factor " + std::to_string(fMax) + " fits" : "no factor fits: crop the coarse cache");
}

// The first coarse frame, read to decide 2D or 3D and the views.
turb::Frame readFirstFrame(CoarseSource& source, const std::vector<int>& frames)
{
    const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(0, int(frames.size()), frames.front());
    progress->begin("reading");
    turb::Frame first = source.read(frames.front(), progress.get());
    progress->clear();
    if (!first.hasVelocity())
        throw turb::ValueError(source.label() + ": frame " + std::to_string(frames.front()) + " has no velocity");
    return first;
}

SynthPlan planSynth(SynthJob& a, CoarseSource& source)
{
    SynthPlan p;
    p.frames = source.frames();
    p.out = turbio::FramePattern::parse(a.out);
    checkOutputFormat(a.write, a.out, a.skipExisting ? "--skip-existing" : "");
    if (p.frames.size() > 1 && !p.out.numbered())
        throw UsageError("--out '" + a.out + "' has no frame token (####, %04d, $F4) but " +
                         std::to_string(p.frames.size()) + " frames are requested");
    p.scan = preflightSynth(a, source, p.frames, p.out);
    if (a.exemplars.empty()) a.exemplars.push_back("circles:16");
    std::vector<turb::Exemplar> ex;
    for (const auto& spec : a.exemplars) ex.push_back(loadExemplar(spec, a));
    p.first = readFirstFrame(source, p.frames);
    p.volume = p.first.bbox().dim().z() > 1;
    p.views = synthViews(a, ex, p.volume);
    a.seq.synth.boundary.walls = a.walls.empty() ? source.sceneWalls() : parseWalls(a.walls);
    p.obstacle = readObstacle(a, source, p.first);
    return p;
}

// The frames of a run, in order: each continues the detail (and density) of the one before.
class FrameLoop
{
public:
    FrameLoop(const SynthJob& a, CoarseSource& source, SynthPlan& p, turb::SynthSequence& sequence, SynthRun& done)
        : mA(a), mSource(source), mP(p), mSequence(sequence), mDone(done)
    {}

    void run()
    {
        for (size_t i = 0; i < mP.skips.end; ++i) frame(i);
    }

private:
    // Frame i: read, synthesise and combine, write (or skip), report.
    void frame(size_t i)
    {
        const int fr = mP.frames[i], count = int(mP.frames.size());
        const auto t0 = std::chrono::steady_clock::now();
        const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(int(i), count, fr);
        progress->begin("reading");
        turb::Frame cf = i == 0 ? std::move(mP.first) : mSource.read(fr, progress.get());
        if (!cf.hasVelocity())
            throw turb::ValueError(mSource.label() + ": frame " + std::to_string(fr) + " has no velocity");
        FrameOutcome o;
        o.coarse = &cf;
        o.readSeconds = secondsSince(t0);
        turb::SynthFrameResult r = synthesise(cf, fr, *progress);
        o.result = &r;
        o.detail = &mSequence.lastDetail();
        if (r.smokeless) {
            progress->clear();
            logWarning("frame " + std::to_string(fr) + ": the density has no smoke (nothing above " +
                       fmt("%g", mA.seq.combine.smokeThreshold) +
                       "), so no detail is written; --detail-everywhere puts it everywhere");
        }
        o.projection = projectionReport(mA, r, fr, *progress, mDone.unconverged);
        o.divergence = detailDivergenceReport(mA, r, fr, *progress, mDone.unconverged);
        const auto tWrite = std::chrono::steady_clock::now();
        o.outPath = mP.out.format(fr);
        if (mP.skips.skipped(i)) {
            progress->clear();
            reporter().frameSkipped(fr, int(i), count, secondsSince(t0), o.outPath, true);
            ++mDone.framesSkipped;
            return;
        }
        write(r.frame, i, o.outPath, *progress);
        o.writeSeconds = secondsSince(tWrite);
        const nlohmann::json extra = frameJson(mA, mP, o, fr, *progress);
        progress->clear();
        const std::string line = frameLine(mA, o, extra);
        logLevels(*o.detail, fr);
        reporter().frameDone(FrameRecord{fr, int(i), count, secondsSince(t0), line, extra});
        ++mDone.framesWritten;
    }

    turb::SynthFrameResult synthesise(const turb::Frame& cf, int fr, FrameProgress& progress)
    {
        turb::SynthFrameInput in;
        in.coarse = &cf.velocity;
        in.coarseDensity = cf.hasDensity() ? &cf.density : nullptr;
        in.obstacle = mP.obstacle ? &*mP.obstacle : nullptr;
        in.frame = fr;
        in.dt = cf.dt > 0.0 ? cf.dt : mA.flowDt;
        in.timeUnit = cf.timeUnit;
        const std::optional<turb::ScalarField> emitters =
            cf.hasDensity() && mA.seq.density ? mSource.sceneEmitters(cf.density, fr) : std::nullopt;
        in.emitters = emitters ? &*emitters : nullptr;
        try {
            return mSequence.next(in, &progress);
        } catch (const turb::ValueError& e) {
            // The library names frames, not files: say which file this frame came from.
            const auto& seq = mSource.sequence();
            throw turb::ValueError(
                "frame " + std::to_string(fr) + (seq ? " (" + seq->path(fr) + ")" : std::string()) + ": " + e.what(),
                e.settings());
        }
    }

    void write(turb::Frame& outFrame, size_t i, const std::string& outPath, FrameProgress& progress)
    {
        tagOutput(outFrame, mA, mP.views);
        outFrame.metadata[turb::meta::kSettings] = mP.settings[i];
        progress.begin("writing");
        turbio::ensureParentDirectory(outPath);
        warnIfClippedAway(outFrame, mA.write, outPath, mWarnedClipping);
        turbio::writeFrame(outPath, outFrame, mA.write);
    }

    const SynthJob& mA;
    CoarseSource& mSource;
    SynthPlan& mP;
    turb::SynthSequence& mSequence;
    SynthRun& mDone;
    bool mWarnedClipping = false;
};

// The frames' outputs and the settings each records, and which of them --skip-existing leaves as they are.
void planOutputs(const SynthJob& a, SynthPlan& p)
{
    for (int fr : p.frames) p.outputs.push_back(p.out.format(fr));
    // Each frame continues the one before it: what it records names the run's frames up to it.
    p.settings = sequentialSettings(a.settingsText, p.frames);
    p.skips = planSkips(p.outputs, p.frames, "synth", p.settings, a.skipExisting);
}

// The exemplars' pyramids and search indices, built once for every frame.
turb::SynthExemplars prepareExemplars(const SynthJob& a, const SynthPlan& p)
{
    const auto tPrep = std::chrono::steady_clock::now();
    const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(0, int(p.frames.size()), p.frames.front());
    progress->begin("exemplar indices");
    turb::SynthExemplars prepared(p.views, a.seq.synth, p.volume, progress.get());
    progress->clear();
    logVerbose("exemplar pyramids and indices: " + fmt("%.2f s", secondsSince(tPrep)) + ", " +
               std::to_string(prepared.levels()) + " levels");
    return prepared;
}

// A solver that stopped short fails a --strict run; otherwise the run ends with a warning listing the frames.
void reportUnconverged(const SynthJob& a, SynthRun& done)
{
    if (done.unconverged.empty()) return;
    std::string list;
    for (int fr : done.unconverged) list += (list.empty() ? "" : ", ") + std::to_string(fr);
    const std::string msg = std::to_string(done.unconverged.size()) +
                            " frame(s) with a projection or a detail divergence solve that did not converge: " + list;
    if (a.strict) done.strictFailure = msg + " (--strict)";
    else logWarning(msg);
}

SynthRun runSynthJob(SynthJob& a)
{
    SynthRun done;
    fillSettings(a);
    CoarseSource source(a);
    SynthPlan p = planSynth(a, source);
    logPlan(a, source, p);
    checkSynthLatticeAndMemory(a, p.first, p.scan, p.volume, int(p.frames.size()));
    planOutputs(a, p);
    if (a.dryRun) {
        printSkipPlan(p.skips, p.outputs);
        return done;
    }
    lockOutputFrames(p.out, p.skips.writing); // two tasks never write one frame (a second exits 75)
    if (a.seq.synth.traceDescent && !a.json) logWarning("--trace-descent reports in the JSON lines only: add --json");
    // The report's clock starts here, so its total includes building the exemplar indices.
    reporter().runStarted("synth");
    const turb::SynthExemplars prepared = prepareExemplars(a, p);
    turb::SynthSequence sequence(prepared, a.seq);
    FrameLoop(a, source, p, sequence, done).run();
    reporter().runFinished(0, nlohmann::json::object());
    reportUnconverged(a, done);
    return done;
}

} // namespace

SynthRun runSynth(const SynthJob& job)
{
    SynthJob a = job; // the run fills in what the job leaves to it (walls, the held box, the default exemplar)
    return runSynthJob(a);
}

} // namespace turb::run
