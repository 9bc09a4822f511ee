// vdbturb measure --output OUT --target TGT [--source SRC]: quality numbers of an up-res, per frame.
// stdout: one JSON line per frame and a summary line (always: the numbers are this command's product).
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
    std::string output, target, source, frames, plotDir, plotFormat = "png", align = "auto", patchOrigin;
    bool json = false;        // accepted for symmetry with the other commands; JSON is always written
    bool spectraJson = false; // include the E(k) arrays in the JSON lines
    bool noSpectra = false, noStructure = false;
    turb::MeasureSettings settings;
    turbio::ReadOptions read;
    int sourceExtend = 0;     // the metrics' definitions read the source as written: no extension by default
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
    j["ratio"] = m.ratio;
    j["source_ratio"] = m.sourceRatio;
    j["alignment"] = turb::alignmentName(m.alignment);
    j["alignment_offset_voxels"] = {m.alignmentOffset.x(), m.alignmentOffset.y(), m.alignmentOffset.z()};
    j["resampled"] = m.resampled;
    j["smoke_voxels"] = m.smokeVoxels;
    j["smoke_cells"] = m.smokeCells;
    j["patch_size"] = m.patchSize;
    j["patch_origin"] = {m.patchOrigin.x(), m.patchOrigin.y(), m.patchOrigin.z()};
    j["dt"] = m.dt > 0.0 ? nlohmann::json(m.dt) : nlohmann::json(nullptr);
    j["k_nyquist_target"] = m.targetNyquist;
    const auto energy = [](const turb::Spectrum& s) { return s.empty() ? nlohmann::json(nullptr) : nlohmann::json(s.meanEnergy); };
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
           f(m.divRelSource) + ")  block " + f(m.block) + "  tcoh " + f(m.tcoh) + " (source " + f(m.tcohSource) + ")  mass " +
           f(m.massRatio) + "  peak " + f(m.peakRatio) + "  density_err " + f(m.densityErr) + "  imprint " + f(m.densityImprint) + "  aniso " + f(m.aniso) +
           " (source " + f(m.anisoSource) + ")  isotropy " + f(m.isotropy) + " (source " + f(m.isotropySource) + ")  air_detail " +
           f(m.airDetail);
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

int runMeasure(MeasureArgs& a)
{
    const auto t0 = std::chrono::steady_clock::now();
    turb::MeasureSettings s = a.settings;
    s.alignment = a.align == "world" ? turb::Alignment::World
                  : a.align == "index" ? turb::Alignment::Index
                                       : turb::Alignment::Auto;
    s.patchOrigin = parseCoord(a.patchOrigin);
    s.spectra = !a.noSpectra || !a.plotDir.empty() || a.spectraJson;
    s.structure = !a.noStructure;
    s.threads = globals().threads;

    const turbio::Sequence out = turbio::resolveSequence(a.output, a.frames);
    const turbio::Sequence tgt = turbio::resolveSequence(a.target, a.frames);
    std::optional<turbio::Sequence> src;
    if (!a.source.empty()) src = turbio::resolveSequence(a.source);

    // Explicit --frames: every requested frame counts, and a missing file fails that frame. Otherwise the
    // frames both sequences hold (a 10-frame target against a 30-frame output measures 10 frames).
    std::vector<int> frames;
    if (!a.frames.empty()) {
        std::set<int> all(out.frames.begin(), out.frames.end());
        all.insert(out.missing.begin(), out.missing.end());
        frames.assign(all.begin(), all.end());
    } else {
        std::set_intersection(out.frames.begin(), out.frames.end(), tgt.frames.begin(), tgt.frames.end(),
            std::back_inserter(frames));
        if (frames.size() < out.frames.size())
            logInfo("measuring the " + std::to_string(frames.size()) + " frames both the output and the target hold (" +
                    (frames.empty() ? std::string("none") : turbio::formatFrameList(frames)) + ")");
    }
    if (frames.empty()) {
        logError("no frame is present in both " + out.pattern.str() + " and " + tgt.pattern.str());
        return kFailed;
    }
    logInfo("measure: output " + out.pattern.str() + ", target " + tgt.pattern.str() +
            (src ? ", source " + src->pattern.str() : std::string(", no source")) + ", frames " +
            turbio::formatFrameList(frames));

    turbio::ReadOptions readOut = a.read, readTgt = a.read, readSrc = a.read;
    readOut.readExtras = readTgt.readExtras = readSrc.readExtras = false;
    readOut.requireDensity = false; // an up-res may carry velocity only; the target then gives the region
    readSrc.extendVelocity = a.sourceExtend;

    // Every frame's headers before the first measurement (a dry run stops here). Frames are measured one by
    // one, so a lattice that changes within a sequence is read frame by frame; tcoh skips the change.
    const turbio::SequenceScan outScan = checkInput("measure", "output", out, frames, readOut, LatticePolicy::Report);
    const turbio::SequenceScan tgtScan = checkInput("measure", "target", tgt, frames, readTgt, LatticePolicy::Report);
    reportTiming("output", outScan, true);
    reportTiming("target", tgtScan, true);
    if (src) {
        const turbio::SequenceScan srcScan = checkInput("measure", "source", *src, src->frames, readSrc, LatticePolicy::Report);
        reportTiming("source", srcScan, true);
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
        for (int f : frames) plots.push_back(a.plotDir + "/" + turbio::FramePattern::parse("spectrum.####.png").format(f));
        checkOutputs(plots, {}, false, false);
    }
    if (globals().dryRun) return kOk;
    if (!a.plotDir.empty()) std::filesystem::create_directories(a.plotDir);

    const auto has = [](const turbio::Sequence& q, int f) {
        return std::binary_search(q.frames.begin(), q.frames.end(), f);
    };
    std::vector<turb::FrameMeasures> results;
    std::vector<double> seconds;
    int failed = 0;
    std::optional<turb::Frame> prevOut, prevTgt, prevSrc;
    for (size_t i = 0; i < frames.size(); ++i) {
        const int f = frames[i];
        const auto t1 = std::chrono::steady_clock::now();
        try {
            if (!has(out, f)) throw turb::IoError(out.path(f) + ": missing");
            if (!has(tgt, f)) throw turb::IoError(tgt.path(f) + ": missing");
            turb::Frame o = turbio::readFrame(out.path(f), f, readOut);
            turb::Frame t = turbio::readFrame(tgt.path(f), f, readTgt);
            std::optional<turb::Frame> sf;
            if (src) {
                // A transfer output names its source frame; otherwise the same frame number.
                int sn = f;
                if (auto it = o.metadata.find(turb::meta::kSourceFrame); it != o.metadata.end())
                    sn = std::atoi(it->second.c_str());
                if (has(*src, sn)) sf = turbio::readFrame(src->path(sn), sn, readSrc);
                else logWarning("frame " + std::to_string(f) + ": source frame " + std::to_string(sn) + " missing");
            }
            // tcoh compares with the previous *processed* frame, over the real time between the two, and only
            // on one lattice (a sequence whose lattice changes is measured frame by frame).
            const bool consecutive = prevOut && prevTgt && prevOut->number < f && prevOut->lattice().approxEqual(o.lattice()) &&
                                     prevTgt->lattice().approxEqual(t.lattice());
            turb::MeasureInput in;
            in.output = &o;
            in.target = &t;
            in.source = sf ? &*sf : nullptr;
            in.previousOutput = consecutive ? &*prevOut : nullptr;
            in.previousTarget = consecutive ? &*prevTgt : nullptr;
            in.previousSource = (sf && prevSrc && prevSrc->number < sf->number) ? &*prevSrc : nullptr;
            ConsoleProgress progress(int(i), int(frames.size()), f);
            turb::FrameMeasures m = turb::measureFrame(in, s, &progress);
            progress.clear();
            if (!a.plotDir.empty()) {
                char name[64];
                std::snprintf(name, sizeof(name), "/spectrum.%04d.%s", f, a.plotFormat.c_str());
                writeSpectrumFigure(a.plotDir + name, m, "E(k) frame " + std::to_string(f));
            }
            const double sec = secondsSince(t1);
            seconds.push_back(sec);
            char head[96];
            std::snprintf(head, sizeof(head), "frame %d (%zu/%zu) %.2f s  ", f, i + 1, frames.size(), sec);
            logInfo(head + humanLine(m));
            for (const auto& n : m.notes)
                logVerbose("frame " + std::to_string(f) + ": " + n + (n == "tcoh: unknown time step" ? " (give --dt)" : ""));
            nlohmann::json j = frameJson(m, a.spectraJson);
            j["frame"] = f;
            j["seconds"] = sec;
            std::cout << j.dump() << std::endl;
            results.push_back(std::move(m));
            prevOut = std::move(o);
            prevTgt = std::move(t);
            prevSrc = std::move(sf);
        } catch (const turb::Cancelled&) {
            throw;
        } catch (const turb::IoError& e) {
            ++failed;
            logError("frame " + std::to_string(f) + ": " + messageWithFlags(e)); // names its file
            prevOut.reset();
            prevTgt.reset();
            prevSrc.reset();
        } catch (const turb::Error& e) {
            ++failed;
            logError("frame " + std::to_string(f) + " (output " + out.path(f) + ", target " + tgt.path(f) + "): " +
                     messageWithFlags(e));
            prevOut.reset();
            prevTgt.reset();
            prevSrc.reset();
        }
    }

    if (!a.plotDir.empty() && !results.empty()) {
        const std::string ext = "." + a.plotFormat;
        writeMetricsFigure(a.plotDir + "/metrics" + ext, results, "vdbturb measure: " + out.pattern.str());
        logInfo("plots: " + a.plotDir + "/metrics" + ext + ", " + a.plotDir + "/spectrum.####" + ext);
    }

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
    std::cout << sum.dump() << std::endl;
    return failed ? kFailed : kOk;
}

} // namespace

Command measureCommand()
{
    auto args = std::make_shared<MeasureArgs>();
    Command c;
    c.name = "measure";
    c.help = "Quality numbers of an up-res (lf_err, hf_ratio, div_rel, block, tcoh, density, structure, air_detail, "
             "spectra): JSON lines on stdout";
    c.setup = [args](CLI::App* app) {
        auto& s = args->settings;
        app->add_option("--output", args->output, "The up-res cache (pattern or one file): velocity, density optional")
            ->required();
        app->add_option("--target", args->target, "The low-res cache it was made from: velocity and density")->required();
        app->add_option("--source", args->source,
            "The high-res source cache, for hf_ratio and div_rel_source (frame from the output's vdbturb_source_frame, "
            "else the same number)");
        app->add_option("--frames", args->frames, "Frames to measure, e.g. 1-30x2 (default: those output and target both hold)")->check(frameListCheck());
        app->add_option("--threshold", s.densityThreshold, "Smoke region: density above this (default 0.01)")
            ->check(CLI::NonNegativeNumber);
        app->add_option("--patch-size", s.patchSize,
               "Seam spacing for block, in output voxels (default: the output's vdbturb_patch_size metadata)")
            ->check(CLI::Range(2, 4096));
        app->add_option("--patch-origin", args->patchOrigin,
            "An output voxel where a patch starts, X,Y,Z (default: vdbturb_patch_origin metadata, else 0,0,0)");
        app->add_option("--align", args->align,
               "Output vs refined target lattice: auto (index when the boxes match but the transforms do not "
               "nest, as in Blender caches; else world), world, index")
            ->check(CLI::IsMember({"auto", "world", "index"}));
        app->add_option("--source-extend-velocity", args->sourceExtend,
               "Continue the source's velocity this many voxels past its active region before measuring it, as "
               "transfer reads it (default 0: the source as written; Blender's zeros beyond the smoke then count as "
               "high-frequency energy at its edge)")
            ->check(CLI::Range(0, 64));
        app->add_flag("--no-spectra", args->noSpectra, "Skip the energy spectra (faster)");
        app->add_flag("--no-structure", args->noStructure, "Skip aniso and isotropy (faster)");
        app->add_flag("--spectra", args->spectraJson, "Include the E(k) arrays in the JSON lines");
        app->add_option("--plot", args->plotDir,
            "Write plots here with gnuplot (Debian gnuplot-nox): spectrum.####.png per frame, metrics.png, and their "
            "gnuplot scripts (.gp) to restyle them");
        app->add_option("--plot-format", args->plotFormat,
               "Picture format of the plots (drawn by gnuplot; exr and tif converted from its PNG)")
            ->check(CLI::IsMember({"png", "svg", "pdf", "exr", "tif"}));
        app->add_flag("--json", args->json, "Accepted for symmetry with other commands: measure always prints JSON");
        addReadOptions(app, args->read);
    };
    c.run = [args] { return runMeasure(*args); };
    return c;
}

} // namespace vdbturb
