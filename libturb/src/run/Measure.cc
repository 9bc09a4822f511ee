// turb::run::runMeasure: vdbturb measure's run (turb/run/Measure.h).
#include <turb/run/Measure.h>

#include "RunHelpers.h"

#include <turb/run/Flags.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Metadata.h>
#include <turb/Resample.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <set>

namespace turb::run {

using detail::secondsSince;

namespace {

nlohmann::json opt(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); }

nlohmann::json spectrumJson(const turb::Spectrum& s)
{
    if (s.empty()) return nullptr;
    return {{"k", s.k}, {"E", s.energy}, {"dk", s.dk}, {"mean_energy", s.meanEnergy}, {"fft_side", s.fftSide}};
}

} // namespace

nlohmann::json measureJson(const turb::FrameMeasures& m, bool spectra)
{
    nlohmann::json j;
    for (const auto& [name, v] : m.scalars()) j[name] = opt(v);
    const auto profile = [](const std::vector<std::optional<double>>& p) {
        nlohmann::json a = nlohmann::json::array();
        for (const auto& v : p) a.push_back(opt(v));
        return a;
    };
    j["detail_profile"] = profile(m.detailProfile);
    j["detail_profile_source"] = profile(m.detailProfileSource);
    j["ratio"] = m.ratio;
    j["source_ratio"] = m.sourceRatio;
    j["alignment"] = turb::alignmentName(m.alignment);
    j["alignment_offset_voxels"] = {m.alignmentOffset.x(), m.alignmentOffset.y(), m.alignmentOffset.z()};
    j["resampled"] = m.resampled;
    j["smoke_voxels"] = m.smokeVoxels;
    j["smoke_cells"] = m.smokeCells;
    j["patch_size"] = m.patchSize;
    j["patch_origin"] = {m.patchOrigin.x(), m.patchOrigin.y(), m.patchOrigin.z()};
    j["tile_voxels"] = m.tileVoxels;
    j["dt"] = m.dt > 0.0 ? nlohmann::json(m.dt) : nlohmann::json(nullptr);
    j["k_nyquist_target"] = m.targetNyquist;
    const auto energy = [](const turb::Spectrum& s) {
        return s.empty() ? nlohmann::json(nullptr) : nlohmann::json(s.meanEnergy);
    };
    j["spectrum_mean_energy"] = {{"output", energy(m.spectrumOutput)}, {"target", energy(m.spectrumTarget)},
        {"source", energy(m.spectrumSource)}};
    if (spectra)
        j["spectra"] = {{"output", spectrumJson(m.spectrumOutput)}, {"target", spectrumJson(m.spectrumTarget)},
            {"source", spectrumJson(m.spectrumSource)}};
    j["notes"] = m.notes;
    return j;
}

std::string measureLine(const turb::FrameMeasures& m)
{
    const auto f = [](const std::optional<double>& v) {
        if (!v) return std::string("-");
        char b[32];
        std::snprintf(b, sizeof(b), "%.4g", *v);
        return std::string(b);
    };
    return "lf_err " + f(m.lfErr) + "  hf_ratio " + f(m.hfRatio) + "  div_rel " + f(m.divRel) + " (source " +
           f(m.divRelSource) + ")  block " + f(m.block) + "  tcoh " + f(m.tcoh) + " (source " + f(m.tcohSource) +
           ")  mass " + f(m.massRatio) + "  peak " + f(m.peakRatio) + "  density_err " + f(m.densityErr) +
           "  imprint " + f(m.densityImprint) + "  aniso_ratio " + f(m.anisoRatio) + " (" + f(m.aniso) + " against " +
           f(m.anisoSource) + ")  detail_scale_ratio " + f(m.detailScaleRatio) + "  isotropy " + f(m.isotropy) +
           " (source " + f(m.isotropySource) + ")  lattice " + f(m.lattice) + " (source " + f(m.latticeSource) +
           ")  vort_peak_ratio " + f(m.vortPeakRatio) + "  air_detail " + f(m.airDetail) +
           (m.tileVoxels > 0 ? "  tile_block " + f(m.tileBlock) + "  tile_div_rel " + f(m.tileDivRel) +
                                   "  tile_hf_ratio " + f(m.tileHfRatio)
                             : std::string());
}

namespace {

std::optional<turb::Coord> parseCoord(const std::string& text)
{
    if (text.empty()) return std::nullopt;
    int v[3];
    if (std::sscanf(text.c_str(), "%d,%d,%d", &v[0], &v[1], &v[2]) == 3) return turb::Coord(v[0], v[1], v[2]);
    if (std::sscanf(text.c_str(), "%d", &v[0]) == 1) return turb::Coord(v[0]);
    throw turb::ValueError("--patch-origin: expected X,Y,Z or one number, got '" + text + "'");
}

double median(std::vector<double> v)
{
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    const size_t h = v.size() / 2;
    return v.size() % 2 ? v[h] : 0.5 * (v[h - 1] + v[h]);
}

turb::MeasureSettings measureSettings(const MeasureJob& a)
{
    turb::MeasureSettings s = a.settings;
    s.patchOrigin = parseCoord(a.patchOrigin);
    if (!a.tileBorders.empty()) s.tileBorders = turb::parseTileBorders(a.tileBorders);
    s.spectra = a.spectra;
    s.threads = a.threads;
    return s;
}

// The sequences measured, the frames and how each sequence is read.
struct MeasurePlan
{
    turbio::Sequence out, tgt;
    std::optional<turbio::Sequence> src;
    std::vector<int> frames;
    turbio::ReadOptions readOut, readTgt, readSrc;
};

MeasurePlan planMeasure(const MeasureJob& a)
{
    MeasurePlan p;
    p.out = turbio::resolveSequence(a.output, a.frames);
    p.tgt = turbio::resolveSequence(a.target, a.frames);
    if (!a.source.empty()) p.src = turbio::resolveSequence(a.source);

    // Explicit --frames: every requested frame counts, and a missing file fails that frame. Otherwise the
    // frames both sequences hold (a 10-frame target against a 30-frame output measures 10 frames).
    if (!a.frames.empty()) {
        std::set<int> all(p.out.frames.begin(), p.out.frames.end());
        all.insert(p.out.missing.begin(), p.out.missing.end());
        p.frames.assign(all.begin(), all.end());
    } else {
        std::set_intersection(p.out.frames.begin(), p.out.frames.end(), p.tgt.frames.begin(), p.tgt.frames.end(),
            std::back_inserter(p.frames));
        if (p.frames.size() < p.out.frames.size())
            logInfo("measuring the " + std::to_string(p.frames.size()) +
                    " frames both the output and the target hold (" +
                    (p.frames.empty() ? std::string("none") : turbio::formatFrameList(p.frames)) + ")");
    }
    p.readOut = p.readTgt = p.readSrc = a.read;
    p.readOut.readExtras = p.readTgt.readExtras = p.readSrc.readExtras = false;
    p.readOut.requireDensity = false;  // an up-res may carry velocity only; the target then gives the region
    p.readOut.requireVelocity = false; // or density only (Blender's noise): its density numbers
    p.readSrc.extendVelocity = a.sourceExtend;
    return p;
}

// Every frame's headers before the first measurement (all a dry run does), and the plots' paths. Frames are
// measured one by one, so a lattice that changes within a sequence is read frame by frame; tcoh skips the change.
void preflight(const MeasureJob& a, const MeasurePlan& p, const std::string& plotDir)
{
    const turbio::SequenceScan outScan =
        checkInput("measure", "output", p.out, p.frames, p.readOut, LatticePolicy::Report);
    const turbio::SequenceScan tgtScan =
        checkInput("measure", "target", p.tgt, p.frames, p.readTgt, LatticePolicy::Report);
    reportTiming("output", outScan, true);
    reportTiming("target", tgtScan, true);
    if (p.src) {
        const turbio::SequenceScan srcScan =
            checkInput("measure", "source", *p.src, p.src->frames, p.readSrc, LatticePolicy::Report);
        reportTiming("source", srcScan, true);
        const turbio::FrameScan* sf = srcScan.frames.empty() ? nullptr : &srcScan.frames.front();
        if (sf && sf->timing.cells && p.readSrc.extendVelocity == 0)
            logWarning("the source is a Blender cache, whose velocity stops at the smoke's edge: that step counts as "
                       "turbulence in hf_energy_source, so hf_ratio reads low while the plume is small (frame 1 of "
                       "the Blender plume2 pair: 0.17; 1.12 measured as transfer calibrates). "
                       "--source-extend-velocity 4 measures the source as transfer reads it");
    }
    // An up-res sits on a lattice an integer number of times finer than its target's.
    if (!outScan.frames.empty() && !tgtScan.frames.empty()) {
        const turbio::FrameScan& o = outScan.frames.front();
        const turbio::FrameScan& t = tgtScan.frames.front();
        if (!turb::isIntegerRatio(t.lattice.voxelSize, o.lattice.voxelSize))
            throw turb::ValueError("the output " + o.path + " (voxel " + std::to_string(o.lattice.voxelSize) +
                                   ") is not an integer refinement of the target " + t.path + " (voxel " +
                                   std::to_string(t.lattice.voxelSize) + "): ratio " +
                                   std::to_string(t.lattice.voxelSize / o.lattice.voxelSize) + " is not an integer");
    }
    if (!plotDir.empty()) {
        std::vector<std::string> plots{plotDir + "/metrics.png"};
        for (int f : p.frames)
            plots.push_back(plotDir + "/" + turbio::FramePattern::parse("spectrum.####.png").format(f));
        checkOutputs(plots, {}, false, false);
    }
}

bool holds(const turbio::Sequence& q, int f) { return std::binary_search(q.frames.begin(), q.frames.end(), f); }

// The frames last measured, for tcoh: the previous *processed* frame of each sequence.
struct Previous
{
    std::optional<turb::Frame> out, tgt, src;
    void reset()
    {
        out.reset();
        tgt.reset();
        src.reset();
    }
};

// Reads frame `f` of every sequence and measures it; the frames read become `prev`.
turb::FrameMeasures measureOne(const MeasurePlan& p, const turb::MeasureSettings& s, int f, size_t i, Previous& prev)
{
    if (!holds(p.out, f)) throw turb::IoError(p.out.path(f) + ": missing");
    if (!holds(p.tgt, f)) throw turb::IoError(p.tgt.path(f) + ": missing");
    turb::Frame o = turbio::readFrame(p.out.path(f), f, p.readOut);
    turb::Frame t = turbio::readFrame(p.tgt.path(f), f, p.readTgt);
    std::optional<turb::Frame> sf;
    if (p.src) {
        // A transfer output names its source frame; otherwise the same frame number.
        int sn = f;
        if (auto it = o.metadata.find(turb::meta::kSourceFrame); it != o.metadata.end())
            sn = std::atoi(it->second.c_str());
        if (holds(*p.src, sn)) sf = turbio::readFrame(p.src->path(sn), sn, p.readSrc);
        else logWarning("frame " + std::to_string(f) + ": source frame " + std::to_string(sn) + " missing");
    }
    // One time unit for all three: an output written for Houdini is per second, a Blender target per Mantaflow unit.
    turb::toTimeUnit(o, t.timeUnit);
    if (sf) turb::toTimeUnit(*sf, t.timeUnit);
    // tcoh compares with the previous *processed* frame, over the real time between the two, and only on one
    // lattice (a sequence whose lattice changes is measured frame by frame).
    const bool consecutive = prev.out && prev.tgt && prev.out->number < f &&
                             prev.out->lattice().approxEqual(o.lattice()) &&
                             prev.tgt->lattice().approxEqual(t.lattice());
    turb::MeasureInput in;
    in.output = &o;
    in.target = &t;
    in.source = sf ? &*sf : nullptr;
    in.previousOutput = consecutive ? &*prev.out : nullptr;
    in.previousTarget = consecutive ? &*prev.tgt : nullptr;
    in.previousSource = (sf && prev.src && prev.src->number < sf->number) ? &*prev.src : nullptr;
    const std::unique_ptr<FrameProgress> progress = reporter().frameProgress(int(i), int(p.frames.size()), f);
    turb::FrameMeasures m = turb::measureFrame(in, s, progress.get());
    progress->clear();
    prev.out = std::move(o);
    prev.tgt = std::move(t);
    prev.src = std::move(sf);
    return m;
}

// The numbers say which axis is up for detail_profile: the output's first frame's metadata, else its writer.
void chooseUpAxis(const MeasureJob& a, const MeasurePlan& p, turb::MeasureSettings& s)
{
    if (!holds(p.out, p.frames.front())) return;
    std::string why;
    s.upAxis = upAxisOf(p.out.path(p.frames.front()), a.up, why);
    if (!why.empty()) logInfo("detail_profile: heights along +y (" + why + "; --up z measures along z)");
}

// Frame i measured, or logged and counted as failed (the next frames still count).
void measureFrameAt(const MeasurePlan& p, const turb::MeasureSettings& s, size_t i, Previous& prev, MeasureRun& run,
    const std::function<void(const MeasuredFrame&)>& onFrame)
{
    const int f = p.frames[i];
    const auto t1 = std::chrono::steady_clock::now();
    try {
        turb::FrameMeasures m = measureOne(p, s, f, i, prev);
        const double sec = secondsSince(t1);
        run.seconds.push_back(sec);
        run.frames.push_back(std::move(m));
        if (onFrame) onFrame(MeasuredFrame{f, i, p.frames.size(), sec, &run.frames.back()});
    } catch (const turb::Cancelled&) {
        throw;
    } catch (const turb::IoError& e) {
        ++run.failed;
        reporter().log(
            Reporter::Level::Error, "frame " + std::to_string(f) + ": " + messageWithFlags(e)); // names its file
        prev.reset();
    } catch (const turb::Error& e) {
        ++run.failed;
        reporter().log(Reporter::Level::Error, "frame " + std::to_string(f) + " (output " + p.out.path(f) +
                                                   ", target " + p.tgt.path(f) + "): " + messageWithFlags(e));
        prev.reset();
    }
}

} // namespace

MeasureRun runMeasure(const MeasureJob& a, const std::function<void(const MeasuredFrame&)>& onFrame)
{
    MeasureRun run;
    turb::MeasureSettings s = measureSettings(a);
    const MeasurePlan p = planMeasure(a);
    run.outputPattern = p.out.pattern.str();
    if (p.frames.empty()) {
        run.nothingToMeasure = true;
        run.noFramesMessage = "no frame is present in both " + p.out.pattern.str() + " and " + p.tgt.pattern.str();
        return run;
    }
    chooseUpAxis(a, p, s);
    logInfo("measure: output " + p.out.pattern.str() + ", target " + p.tgt.pattern.str() +
            (p.src ? ", source " + p.src->pattern.str() : std::string(", no source")) + ", frames " +
            turbio::formatFrameList(p.frames));
    preflight(a, p, a.plotDir);
    if (a.dryRun) return run;
    if (!a.plotDir.empty()) std::filesystem::create_directories(a.plotDir);
    Previous prev;
    for (size_t i = 0; i < p.frames.size(); ++i) measureFrameAt(p, s, i, prev, run, onFrame);
    return run;
}

nlohmann::json measureSummaryJson(
    const MeasureRun& run, const turb::MeasureSettings& s, double totalSeconds, int threads)
{
    const std::vector<turb::FrameMeasures>& results = run.frames;
    nlohmann::json sum;
    sum["summary"] = true;
    sum["command"] = "measure";
    sum["frames"] = results.size();
    sum["failed"] = run.failed;
    sum["median_s_per_frame"] = median(run.seconds);
    sum["total_s"] = totalSeconds;
    sum["peak_rss_mb"] = double(turbio::peakRssBytes()) / (1024.0 * 1024.0);
    sum["threads"] = threads > 0 ? threads : tbb::info::default_concurrency();
    sum["machine"] = turbio::machineDescription();
    sum["threshold"] = s.densityThreshold;
    for (const auto& [name, st] : turb::summarize(results))
        sum[name] = {{"mean", st.mean}, {"median", st.median}, {"min", st.min}, {"max", st.max}, {"n", st.count}};
    return sum;
}

} // namespace turb::run
