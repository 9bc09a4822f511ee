// vdbturb measure --output OUT --target TGT [--source SRC]: quality numbers of an up-res, per frame.
// stdout: one JSON line per frame and a summary line (always: the numbers are this command's product). Parses the
// options into a turb::run::MeasureJob, runs it (libturb/src/run/Measure.cc), reports and plots.
#include "CommandLine.h"
#include "Commands.h"
#include "Console.h"

#include <turb/Error.h>
#include <turb/Measure.h>
#include <turb/run/Figures.h>
#include <turb/run/Measure.h>
#include <turb/run/Settings.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <memory>

namespace vdbturb {

namespace {

using turb::run::MeasureJob;

struct MeasureArgs : MeasureJob
{
    bool json = false;        // accepted for symmetry with the other commands; JSON is always written
    bool spectraJson = false; // include the E(k) arrays in the JSON lines
};

void plotSpectrum(const MeasureArgs& a, const turb::FrameMeasures& m, int f)
{
    if (a.plotDir.empty()) return;
    char name[64];
    std::snprintf(name, sizeof(name), "/spectrum.%04d.%s", f, a.plotFormat.c_str());
    turb::run::writeSpectrumFigure(a.plotDir + name, m, "E(k) frame " + std::to_string(f));
}

// The frame's human line on stderr and its JSON line on stdout.
void reportFrame(const MeasureArgs& a, const turb::run::MeasuredFrame& mf)
{
    const turb::FrameMeasures& m = *mf.measures;
    char head[96];
    std::snprintf(head, sizeof(head), "frame %d (%zu/%zu) %.2f s  ", mf.frame, mf.index + 1, mf.count, mf.seconds);
    logInfo(head + turb::run::measureLine(m));
    for (const auto& n : m.notes)
        logVerbose(
            "frame " + std::to_string(mf.frame) + ": " + n + (n == "tcoh: unknown time step" ? " (give --dt)" : ""));
    nlohmann::json j = turb::run::measureJson(m, a.spectraJson);
    j["frame"] = mf.frame;
    j["seconds"] = mf.seconds;
    writeData(j.dump() + "\n");
    frameReported(mf.frame, int(mf.index + 1), int(mf.count));
}

void reportSummary(const turb::run::MeasureRun& run, const turb::MeasureSettings& s, double seconds)
{
    std::string human = "summary over " + std::to_string(run.frames.size()) + " frames:";
    for (const auto& [name, st] : turb::summarize(run.frames)) {
        char b[96];
        std::snprintf(b, sizeof(b), "  %s %.4g", name.c_str(), st.mean);
        human += b;
    }
    logInfo(human + " (means)");
    writeData(turb::run::measureSummaryJson(run, s, seconds, globals().threads).dump() + "\n");
}

int runMeasure(MeasureArgs& a)
{
    const auto t0 = std::chrono::steady_clock::now();
    a.spectra = a.spectra || !a.plotDir.empty() || a.spectraJson; // --plot and --spectra need them whatever it says
    a.dryRun = globals().dryRun;
    a.threads = globals().threads;
    if (std::string why; !a.plotDir.empty() && !turb::run::gnuplotAvailable(why)) throw turb::Error(why);
    const turb::run::MeasureRun run = turb::run::runMeasure(a, [&](const turb::run::MeasuredFrame& f) {
        plotSpectrum(a, *f.measures, f.frame);
        reportFrame(a, f);
    });
    if (run.nothingToMeasure) return reportFailure(run.noFramesMessage, kFailed);
    if (a.dryRun) return kOk;
    if (!a.plotDir.empty() && !run.frames.empty()) {
        const std::string ext = "." + a.plotFormat;
        turb::run::writeMetricsFigure(
            a.plotDir + "/metrics" + ext, run.frames, "vdbturb measure: " + run.outputPattern);
        logInfo("plots: " + a.plotDir + "/metrics" + ext + ", " + a.plotDir + "/spectrum.####" + ext);
    }
    turb::MeasureSettings s = a.settings;
    reportSummary(run, s, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    return run.failed ? kFailed : kOk;
}

// The second tier (turb::run::measureSettings()): the region and lattice a metric uses when the metadata does not say,
// what to skip, the plots' format.
void addMeasureSettings(CLI::App* app, MeasureArgs& a)
{
    addSettings(app, static_cast<MeasureJob&>(a), turb::run::measureSettings(), turb::run::measureOldSpellings());
    // The row's range [0, 4096] less 1 (its check of the text says so too): CLI11's union of two ranges names them in
    // --help-all and in its error, as the option always has.
    CLI::Option* patchSize = app->get_option("--patchSize");
    patchSize->get_validator()->active(false);
    patchSize->check(CLI::Range(0, 0) | CLI::Range(2, 4096));
}

} // namespace

std::string measureJsonText(const turb::FrameMeasures& m, bool spectra)
{
    return turb::run::measureJson(m, spectra).dump();
}

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
