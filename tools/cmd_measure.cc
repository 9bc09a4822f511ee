// vdbturb measure --output OUT --target TGT [--source SRC]: quality numbers of an up-res, per frame.
// stdout: one JSON line per frame and a summary line (always: the numbers are this command's product).
#include "CommandLine.h"
#include "Commands.h"
#include "Console.h"
#include "Figures.h"
#include "Preflight.h"

#include <turb/Metadata.h>
#include <turb/Error.h>
#include <turb/Resample.h>
#include <turb/Measure.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>
#include <turbio/System.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>
#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <set>

namespace vdbturb {

namespace {

struct MeasureArgs
{
    std::string output, target, source, frames, plotDir, plotFormat = "png", patchOrigin, tileBorders, up = "auto";
    bool json = false;          // accepted for symmetry with the other commands; JSON is always written
    bool spectraJson = false;   // include the E(k) arrays in the JSON lines
    bool computeSpectra = true; // --plot and --spectra compute them whatever this says
    turb::MeasureSettings settings;
    turbio::ReadOptions read;
    int sourceExtend = 0; // the metrics' definitions read the source as written: no extension by default
};

nlohmann::json opt(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); }

nlohmann::json spectrumJson(const turb::Spectrum& s)
{
    if (s.empty()) return nullptr;
    return {{"k", s.k}, {"E", s.energy}, {"dk", s.dk}, {"mean_energy", s.meanEnergy}, {"fft_side", s.fftSide}};
}

nlohmann::json frameJson(const turb::FrameMeasures& m, bool spectra)
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

std::string humanLine(const turb::FrameMeasures& m)
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

turb::MeasureSettings measureSettings(const MeasureArgs& a)
{
    turb::MeasureSettings s = a.settings;
    s.patchOrigin = parseCoord(a.patchOrigin);
    if (!a.tileBorders.empty()) s.tileBorders = turb::parseTileBorders(a.tileBorders);
    s.spectra = a.computeSpectra || !a.plotDir.empty() || a.spectraJson;
    s.threads = globals().threads;
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

MeasurePlan planMeasure(const MeasureArgs& a)
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
    p.readOut.requireDensity = false; // an up-res may carry velocity only; the target then gives the region
    p.readOut.requireVelocity = false; // or density only (Blender's noise): its density numbers
    p.readSrc.extendVelocity = a.sourceExtend;
    return p;
}

// Every frame's headers before the first measurement (all a dry run does), and the plots' paths. Frames are
// measured one by one, so a lattice that changes within a sequence is read frame by frame; tcoh skips the change.
void preflight(const MeasureArgs& a, const MeasurePlan& p)
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
    if (!a.plotDir.empty()) {
        if (std::string why; !gnuplotAvailable(why)) throw turb::Error(why);
        std::vector<std::string> plots{a.plotDir + "/metrics.png"};
        for (int f : p.frames)
            plots.push_back(a.plotDir + "/" + turbio::FramePattern::parse("spectrum.####.png").format(f));
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
    ConsoleProgress progress(int(i), int(p.frames.size()), f);
    turb::FrameMeasures m = turb::measureFrame(in, s, &progress);
    progress.clear();
    prev.out = std::move(o);
    prev.tgt = std::move(t);
    prev.src = std::move(sf);
    return m;
}

void plotSpectrum(const MeasureArgs& a, const turb::FrameMeasures& m, int f)
{
    if (a.plotDir.empty()) return;
    char name[64];
    std::snprintf(name, sizeof(name), "/spectrum.%04d.%s", f, a.plotFormat.c_str());
    writeSpectrumFigure(a.plotDir + name, m, "E(k) frame " + std::to_string(f));
}

// The frame's human line on stderr and its JSON line on stdout.
void reportFrame(const MeasureArgs& a, const turb::FrameMeasures& m, int f, size_t i, size_t count, double sec)
{
    char head[96];
    std::snprintf(head, sizeof(head), "frame %d (%zu/%zu) %.2f s  ", f, i + 1, count, sec);
    logInfo(head + humanLine(m));
    for (const auto& n : m.notes)
        logVerbose("frame " + std::to_string(f) + ": " + n + (n == "tcoh: unknown time step" ? " (give --dt)" : ""));
    nlohmann::json j = frameJson(m, a.spectraJson);
    j["frame"] = f;
    j["seconds"] = sec;
    writeData(j.dump() + "\n");
    frameReported(f, int(i + 1), int(count));
}

void reportSummary(const std::vector<turb::FrameMeasures>& results, const std::vector<double>& seconds, int failed,
    const turb::MeasureSettings& s, std::chrono::steady_clock::time_point t0)
{
    nlohmann::json sum;
    sum["summary"] = true;
    sum["command"] = "measure";
    sum["frames"] = results.size();
    sum["failed"] = failed;
    sum["median_s_per_frame"] = median(seconds);
    sum["total_s"] = secondsSince(t0);
    sum["peak_rss_mb"] = double(turbio::peakRssBytes()) / (1024.0 * 1024.0);
    sum["threads"] = globals().threads > 0 ? globals().threads : tbb::info::default_concurrency();
    sum["machine"] = turbio::machineDescription();
    sum["threshold"] = s.densityThreshold;
    std::string human = "summary over " + std::to_string(results.size()) + " frames:";
    for (const auto& [name, st] : turb::summarize(results)) {
        sum[name] = {{"mean", st.mean}, {"median", st.median}, {"min", st.min}, {"max", st.max}, {"n", st.count}};
        char b[96];
        std::snprintf(b, sizeof(b), "  %s %.4g", name.c_str(), st.mean);
        human += b;
    }
    logInfo(human + " (means)");
    writeData(sum.dump() + "\n");
}

int runMeasure(MeasureArgs& a)
{
    const auto t0 = std::chrono::steady_clock::now();
    turb::MeasureSettings s = measureSettings(a);
    const MeasurePlan p = planMeasure(a);
    if (p.frames.empty()) {
        return reportFailure(
            "no frame is present in both " + p.out.pattern.str() + " and " + p.tgt.pattern.str(), kFailed);
    }
    if (holds(p.out, p.frames.front())) {
        std::string why;
        s.upAxis = upAxisOf(p.out.path(p.frames.front()), a.up, why);
        if (!why.empty()) logInfo("detail_profile: heights along +y (" + why + "; --up z measures along z)");
    }
    logInfo("measure: output " + p.out.pattern.str() + ", target " + p.tgt.pattern.str() +
            (p.src ? ", source " + p.src->pattern.str() : std::string(", no source")) + ", frames " +
            turbio::formatFrameList(p.frames));
    preflight(a, p);
    if (globals().dryRun) return kOk;
    if (!a.plotDir.empty()) std::filesystem::create_directories(a.plotDir);

    std::vector<turb::FrameMeasures> results;
    std::vector<double> seconds;
    int failed = 0;
    Previous prev;
    for (size_t i = 0; i < p.frames.size(); ++i) {
        const int f = p.frames[i];
        const auto t1 = std::chrono::steady_clock::now();
        try {
            turb::FrameMeasures m = measureOne(p, s, f, i, prev);
            plotSpectrum(a, m, f);
            const double sec = secondsSince(t1);
            seconds.push_back(sec);
            reportFrame(a, m, f, i, p.frames.size(), sec);
            results.push_back(std::move(m));
        } catch (const turb::Cancelled&) {
            throw;
        } catch (const turb::IoError& e) {
            ++failed;
            logError("frame " + std::to_string(f) + ": " + messageWithFlags(e)); // names its file
            prev.reset();
        } catch (const turb::Error& e) {
            ++failed;
            logError("frame " + std::to_string(f) + " (output " + p.out.path(f) + ", target " + p.tgt.path(f) +
                     "): " + messageWithFlags(e));
            prev.reset();
        }
    }
    if (!a.plotDir.empty() && !results.empty()) {
        const std::string ext = "." + a.plotFormat;
        writeMetricsFigure(a.plotDir + "/metrics" + ext, results, "vdbturb measure: " + p.out.pattern.str());
        logInfo("plots: " + a.plotDir + "/metrics" + ext + ", " + a.plotDir + "/spectrum.####" + ext);
    }
    reportSummary(results, seconds, failed, s, t0);
    return failed ? kFailed : kOk;
}

// The second tier: the region and lattice a metric uses when the metadata does not say, and what to skip.
void addMeasureSettings(CLI::App* app, MeasureArgs& a)
{
    turb::MeasureSettings& s = a.settings;
    setting(app->add_option("--patch-size,--patchSize", s.patchSize,
                   "Seam spacing for block, in output voxels (0: the output's vdbturb_patch_size metadata)")
                ->check(CLI::Range(0, 0) | CLI::Range(2, 4096)),
        "patchSize");
    setting(app->add_option("--patch-origin,--patchOrigin", a.patchOrigin,
                "An output voxel where a patch starts, X,Y,Z (default: vdbturb_patch_origin metadata, else 0,0,0)"),
        "patchOrigin");
    setting(app->add_option("--tile-borders", a.tileBorders,
                "Space-tile border planes for tile_block and tile_div_rel, in output voxels, e.g. x:64;y:64 (default: "
                "the output's vdbturb_tile_borders metadata, which farm join writes)"),
        "tile-borders");
    setting(app->add_option("--tile-border-width", s.tileBorderWidth,
                   "Output voxels either side of a tile border that tile_* cover (0: 2 patch sizes)")
                ->check(CLI::Range(0, 4096)),
        "tile-border-width");
    setting(addEnum<turb::Alignment>(app, "--align,--alignment", s.alignment,
                {{"auto", turb::Alignment::Auto}, {"world", turb::Alignment::World}, {"index", turb::Alignment::Index}},
                "Output against the refined target lattice: auto, world (the transforms) or index (the voxels)"),
        "alignment");
    setting(app->add_option("--source-extend-velocity,--sourceRead.extendVelocity", a.sourceExtend,
                   "Continue the source's velocity this many voxels past its active region, as transfer reads it "
                   "(0: as written)")
                ->check(CLI::Range(0, 64)),
        "sourceRead.extendVelocity");
    // MeasureSettings::spectra under another key: --spectra is the everyday flag for the JSON arrays.
    boolSetting(app, "--computeSpectra", a.computeSpectra,
        "Energy spectra (false: skip the FFTs unless --plot or --spectra needs them)", "computeSpectra");
    legacy(app->add_flag_function(
               "--no-spectra", [&a](int64_t) { a.computeSpectra = false; }, ""),
        "computeSpectra", "false");
    boolSetting(app, "--structure", s.structure,
        "The structure numbers aniso, isotropy, lattice, detail_scale and vort_peak (false: skip them)", "structure");
    legacy(app->add_flag_function(
               "--no-structure", [&s](int64_t) { s.structure = false; }, ""),
        "structure", "false");
    setting(app->add_option("--plot-format", a.plotFormat, "Picture format of --plot (exr and tif from gnuplot's PNG)")
                ->check(CLI::IsMember({"png", "svg", "pdf", "exr", "tif"})),
        "plot-format");
}

} // namespace

std::string measureJsonText(const turb::FrameMeasures& m, bool spectra) { return frameJson(m, spectra).dump(); }

Command measureCommand()
{
    auto args = std::make_shared<MeasureArgs>();
    Command c;
    c.name = "measure";
    c.help = "Quality numbers of an up-res (lf_err, hf_ratio, div_rel, block, tcoh, density, structure, air_detail, "
             "spectra): JSON lines on stdout";
    c.setup = [args](CLI::App* app) {
        MeasureArgs& a = *args;
        app->add_option("--output", a.output, "The up-res cache (pattern or one file): velocity, density optional")
            ->required();
        app->add_option("--target", a.target, "The low-res cache it was made from: velocity and density")->required();
        app->add_option(
            "--source", a.source, "The high-res source cache, for the source's numbers (hf_ratio, div_rel_source)");
        app->add_option(
               "--frames", a.frames, "Frames to measure, e.g. 1-30x2 (default: those output and target both hold)")
            ->check(frameListCheck());
        app->add_option("--threshold", a.settings.densityThreshold, "Smoke region: density above this")
            ->check(finiteIn(0.0));
        app->add_flag("--spectra", a.spectraJson, "Include the E(k) arrays in the JSON lines");
        app->add_flag("--json", a.json, "Accepted for symmetry with other commands: measure always prints JSON");
        app->add_option("--up", a.up,
               "World axis pointing up, for detail_profile's heights: auto (vdbturb_up_axis metadata, else y for "
               "Houdini's files, else z), y, z")
            ->check(CLI::IsMember({"auto", "y", "z"}));
        addReadOptions(app, a.read);
        app->add_option("--plot", a.plotDir,
               "Write plots into DIR with gnuplot: spectrum.####.png per frame, metrics.png, and their .gp scripts")
            ->group(kGroupOutput);
        addMeasureSettings(app, a);
    };
    c.run = [args] { return runMeasure(*args); };
    return c;
}

} // namespace vdbturb
