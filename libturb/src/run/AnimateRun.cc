// turb::run::runAnimate: vdbturb animate's run (Okabe et al. 2009), from files to files (turb/run/Animate.h).
#include <turb/run/Animate.h>

#include "AnimateParts.h"
#include "StylizeParts.h"

#include <turb/run/Output.h>
#include <turb/run/Preflight.h>
#include <turb/run/Reporter.h>

#include <turb/Animate.h>
#include <turb/Parallel.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>

#include <algorithm>
#include <chrono>
#include <memory>

namespace turb::run {

namespace {

using detail::Example;
using detail::fmt;
using detail::Measures;
using detail::SheetParts;
using detail::Target;

nlohmann::json statsJson(const turb::AnimateStats& st)
{
    nlohmann::json j;
    j["example"] = {{"pairs", st.analysis.pairs}, {"pairs_tracked", st.analysis.pairsUsed},
        {"tracks_per_pair", st.analysis.tracksPerPair}, {"track_speed", st.analysis.trackSpeed},
        {"mean_speed", st.analysis.meanSpeed}, {"rms_difference", st.analysis.rmsDifference},
        {"rms_residual", st.analysis.rmsResidual}, {"flow_given", st.analysis.flowGiven}};
    // A given flow (a cache's) weighed against the tracked one: the residuals each left (analysis.givenFlow best).
    if (st.analysis.rmsResidualGiven > 0.0 || st.analysis.rmsResidualTracked > 0.0) {
        j["example"]["rms_residual_given_flow"] = st.analysis.rmsResidualGiven;
        j["example"]["rms_residual_tracked_flow"] = st.analysis.rmsResidualTracked;
    }
    j["design_mean_speed"] = st.designMeanSpeed;
    j["transfer"] = {{"patches", st.transfer.patches}, {"pasted", st.transfer.pasted},
        {"mean_cost", st.transfer.meanCost}, {"max_cost", st.transfer.maxCost}, {"covered", st.transfer.covered},
        {"distinct_windows", st.transfer.distinct}};
    if (st.transfer.cloned > 0.0) j["transfer"]["cloned"] = st.transfer.cloned;
    j["eq8"] = {
        {"alpha", st.alpha}, {"beta", st.beta}, {"mean_d", st.meanD}, {"sigma_d", st.sigmaD}, {"sigma_c", st.sigmaC}};
    j["hm_grid"] = {st.gridCols, st.gridRows};
    j["stages_s"] = {{"analysis", st.secondsAnalysis}, {"design", st.secondsDesign}, {"transfer", st.secondsTransfer},
        {"average", st.secondsAverage}, {"synthesis", st.secondsSynthesis}, {"matching", st.secondsMatching}};
    return j;
}

// What the library shows of its stages: the refined design (for --measure), the sheet's pictures, --dump's files.
struct Inspector
{
    const AnimateJob& a;
    SheetParts& sheet;
    turb::ChannelImage& designed;

    void operator()(const std::string& name, int index, const turb::ChannelImage& img) const
    {
        if (name == "refined") designed = img;
        if (!a.sheet.empty()) keepForSheet(name, index, img);
        if (a.dump.empty() || name == "Dsecond" || name == "gradient") return;
        const std::string file = index < 0
                                     ? a.dump + "/" + name + ".exr"
                                     : turbio::FramePattern::parse(a.dump + "/" + name + ".####.exr").format(index);
        detail::writeData(file, img, a.noClobber);
        if (name == "v" || name == "rough" || name == "refined")
            turbio::writeImage(a.dump + "/" + name + ".png", detail::flowPicture(img));
    }

    void keepForSheet(const std::string& name, int index, const turb::ChannelImage& img) const
    {
        if (name == "A") sheet.A = img;
        else if (name == "v") sheet.v = img;
        else if (name == "R" && index == 0) sheet.R0 = img;
        else if (name == "rough") sheet.rough = img;
        else if (name == "refined") sheet.refined = img;
        else if (name == "Aprime") sheet.Aprime = img;
    }
};

// Each frame as the library finishes it: written with the still's alpha, measured, kept for the sheet, reported.
struct FrameWriter
{
    const AnimateJob& a;
    const Target& target;
    const turbio::FramePattern& outPattern;
    int count;
    Measures& measures;
    SheetParts& sheet;
    FrameProgress& stages;
    const SkipPlan& plan;
    const std::string& settings; ///< what each frame records (--skip-existing)
    AnimateRun& done;

    void operator()(const turb::AnimatedFrame& f) const
    {
        stages.clear();
        const auto tw = std::chrono::steady_clock::now();
        const int number = a.start + f.index;
        const std::string path = outPattern.format(number);
        // A frame --skip-existing leaves as it is was made all the same: --measure and --sheet still see it.
        if (measures.outTemporal) {
            measures.outTemporal->add(f.image);
            measures.outLuma.push_back(turb::luminance(f.image));
        }
        const std::vector<int> sheetFrames{0, count / 3, 2 * count / 3, count - 1};
        if (!a.sheet.empty() && std::find(sheetFrames.begin(), sheetFrames.end(), f.index) != sheetFrames.end())
            sheet.outputs.emplace_back(number, detail::picture(f.image));
        if (plan.skipped(size_t(f.index))) {
            reporter().frameSkipped(number, f.index, count, f.seconds + detail::secondsSince(tw), path, false);
            ++done.framesSkipped;
            return;
        }
        write(f, path);
        reporter().frameDone(FrameRecord{
            number, f.index, count, f.seconds + detail::secondsSince(tw), line(f, path), frameJson(f, path)});
        ++done.framesWritten;
    }

    void write(const turb::AnimatedFrame& f, const std::string& path) const
    {
        turb::RgbaImage img(f.image.width(), f.image.height());
        for (size_t i = 0; i < img.size(); ++i) {
            const float* p = f.image.pixel(i);
            img.pixels()[i] = turb::Rgba(p[0], p[1], p[2], target.alpha[i]);
        }
        img.colorSpace = target.colorSpace;
        turbio::ensureParentDirectory(path);
        turbio::ImageWriteOptions wo;
        wo.noClobber = a.noClobber;
        wo.metadata = frameMetadata("animate", settings);
        turbio::writeImage(path, img, wo);
    }

    nlohmann::json frameJson(const turb::AnimatedFrame& f, const std::string& path) const
    {
        nlohmann::json extra{
            {"out", path}, {"example_index", f.exampleIndex}, {"mean_error", f.meanError}, {"std_error", f.stdError}};
        // Without histogram matching there are no cells: no per-cell numbers rather than a misleading 0.
        if (a.settings.histogramMatch) {
            extra["cell_mean_error"] = f.cellMeanError;
            extra["cell_std_error"] = f.cellStdError;
        }
        return extra;
    }

    std::string line(const turb::AnimatedFrame& f, const std::string& path) const
    {
        const bool cells = a.settings.histogramMatch;
        return "mean/std vs target " + fmt("%.2f%%", 100 * f.meanError) + "/" + fmt("%.2f%%", 100 * f.stdError) +
               (cells ? ", worst cell " + fmt("%.2f%%", 100 * f.cellMeanError) + "/" +
                            fmt("%.2f%%", 100 * f.cellStdError)
                      : std::string(", no histogram matching")) +
               " -> " + path;
    }
};

void logStages(const turb::AnimateStats& st)
{
    const bool weighed = st.analysis.rmsResidualGiven > 0.0 || st.analysis.rmsResidualTracked > 0.0;
    const std::string source = !weighed
                                   ? (st.analysis.flowGiven ? " (from the cache)" : "")
                                   : std::string(st.analysis.flowGiven ? " (the cache's" : " (tracked: the cache's") +
                                         " flow left residual rms " + fmt("%.4f", st.analysis.rmsResidualGiven) +
                                         ", the tracked " + fmt("%.4f", st.analysis.rmsResidualTracked) + ")";
    logInfo("animate: example flow " + fmt("%.2f px/frame", st.analysis.meanSpeed) + source + ", residual rms " +
            fmt("%.4f", st.analysis.rmsResidual) + " vs difference rms " + fmt("%.4f", st.analysis.rmsDifference) +
            "; design " + fmt("%.2f px/frame", st.designMeanSpeed) + "; transfer cost " +
            fmt("%.3f", st.transfer.meanCost) + "; stages " + fmt("%.1f", st.secondsAnalysis) + "/" +
            fmt("%.1f", st.secondsDesign) + "/" + fmt("%.1f", st.secondsTransfer) + "/" +
            fmt("%.1f", st.secondsAverage) + "/" + fmt("%.1f", st.secondsSynthesis) + "/" +
            fmt("%.1f", st.secondsMatching) + " s (analysis/design/transfer/A'/synthesis/matching)");
}

void logPlan(const AnimateJob& a, const Example& example, const Target& target)
{
    const int N = int(example.frames.size()), tau = a.settings.tau;
    logInfo("animate: example " + example.label + " (" + std::to_string(N) + " frames, " +
            std::to_string(example.frames[0].width()) + "x" + std::to_string(example.frames[0].height()) +
            "), target " + target.label + " (" + std::to_string(target.rgb.width()) + "x" +
            std::to_string(target.rgb.height()) + (target.matte ? ", matte" : "") + "), " +
            (target.strokes ? std::to_string(target.strokes->strokes.size()) + " strokes" : "dense flow " + a.flow) +
            (target.clones ? ", " + std::to_string(target.clones->clones.size()) + " clone strokes" : "") + ", tau " +
            std::to_string(tau) + " -> " + std::to_string(N - tau) + " frames");
}

// The matcher keeps cells of at least 8 pixels: say so when a given grid is finer.
void warnFinerGrid(const AnimateJob& a, const Target& target)
{
    const turb::HistogramMatchSettings& hm = a.settings.hm;
    const auto [cols, rows] = turb::histogramGrid(target.rgb.width(), target.rgb.height(), hm);
    if (a.settings.histogramMatch && hm.gridCols > 0 && (cols != hm.gridCols || rows != hm.gridRows))
        logWarning("--hm-grid " + a.hmGrid + ": cells must be at least 8 pixels wide on the " +
                   std::to_string(target.rgb.width()) + "x" + std::to_string(target.rgb.height()) + " still; using " +
                   std::to_string(cols) + "x" + std::to_string(rows));
}

// The library's input: the example's frames (consumed), its flow, the still, its matte and design.
turb::AnimateInput animateInput(Example& example, const Target& target)
{
    turb::AnimateInput in;
    in.exampleFrames = std::move(example.frames);
    in.exampleFlow = example.flow ? &*example.flow : nullptr;
    in.target = target.rgb;
    in.matte = target.matte ? &*target.matte : nullptr;
    if (target.strokes) in.strokes = &target.strokes->strokes;
    if (target.flow) in.designedFlow = &*target.flow;
    if (target.clones) in.clones = &target.clones->clones;
    return in;
}

// The animation: the library's stages, each frame written as it comes, then the summary (and --measure, --sheet).
void animateFrames(const AnimateJob& a, Example& example, const Target& target, const turbio::FramePattern& outPattern,
    const SkipPlan& plan, const std::string& settings, AnimateRun& done)
{
    const turb::AnimateSettings& s = a.settings;
    const int N = int(example.frames.size());
    Measures measures = detail::startMeasures(a, example, target);
    SheetParts sheet;
    if (!a.sheet.empty())
        for (int i : {0, N / 2, N - 1})
            sheet.example.emplace_back(example.numbers[size_t(i)], detail::picture(example.frames[size_t(i)]));
    turb::AnimateInput in = animateInput(example, target);
    turb::ChannelImage designed;
    turb::withThreads(a.threads, [&] {
        const int count = N - s.tau;
        const std::unique_ptr<FrameProgress> stages = reporter().frameProgress(0, count, a.start);
        const turb::AnimateStats st = turb::animate(std::move(in), s,
            FrameWriter{a, target, outPattern, count, measures, sheet, *stages, plan, settings, done}, stages.get(),
            Inspector{a, sheet, designed});
        nlohmann::json summary = statsJson(st);
        logStages(st);
        if (a.measure) detail::finishMeasures(a, measures, designed, target, summary);
        if (!a.sheet.empty()) {
            turbio::ensureParentDirectory(a.sheet);
            turbio::writeImage(a.sheet, detail::contactSheet(sheet, detail::picture(target.rgb),
                                            "animate: " + example.label + " -> " + target.label));
            summary["sheet"] = a.sheet;
        }
        reporter().runFinished(0, summary);
    });
}

// The outputs' paths and frame numbers, checked (with the sheet and the dump) before anything is written.
std::vector<std::string> plannedOutputs(
    const AnimateJob& a, const turbio::FramePattern& outPattern, int frames, std::vector<int>& numbers)
{
    std::vector<std::string> outputs;
    for (int j = 0; j < frames - a.settings.tau; ++j) {
        outputs.push_back(outPattern.format(a.start + j));
        numbers.push_back(a.start + j);
    }
    std::vector<std::string> paths = outputs;
    if (!a.sheet.empty()) paths.push_back(a.sheet);
    if (!a.dump.empty()) paths.push_back(a.dump + "/A.exr");
    checkOutputs(paths, {a.target, a.targetAlpha, a.strokes, a.flow, a.cloneStrokes}, a.noClobber, a.skipExisting);
    return outputs;
}

void printDryRun(const AnimateJob& a, const SkipPlan& plan, const std::vector<std::string>& outputs)
{
    if (a.skipExisting) return printSkipPlan(plan, outputs);
    for (int j = 0; j < int(outputs.size()); ++j)
        printData("would write " + outputs[size_t(j)] + " (frame " + std::to_string(a.start + j) + ")");
}

AnimateRun runConfigured(const AnimateJob& a)
{
    AnimateRun done;
    detail::checkOutputPatterns(a.out);
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(a.out);
    if (!outPattern.numbered())
        throw UsageError("--out " + a.out + " has no frame token (####): animate writes a sequence");
    // Everything is read and checked before the first file is written; the run's time counts the reading.
    if (!a.dryRun) reporter().runStarted("animate");
    Target target = detail::readTarget(a);
    warnFinerGrid(a, target);
    Example example = detail::readExample(a, a.settings.tau);
    detail::readClones(a, example, target);
    std::vector<int> numbers;
    const std::vector<std::string> outputs = plannedOutputs(a, outPattern, int(example.frames.size()), numbers);
    // Every frame is made from the whole example (the design, eq. 8's statistics): its frames are a setting here.
    const std::string settings = a.settingsText + "example_frames=" + turbio::formatFrameList(example.numbers) + ";";
    const SkipPlan plan = planSkips(outputs, numbers, "animate", settings, a.skipExisting);
    if (!a.settings.histogramMatch && a.settings.hmApply != turb::HmApply::PerFrame)
        logWarning("--hm-apply is ignored with --hm off");
    logPlan(a, example, target);
    if (a.dryRun) {
        printDryRun(a, plan, outputs);
        return done;
    }
    if (a.skipExisting && !outputs.empty() && plan.writing.empty()) {
        // The frames come from one pass over the whole shot: with all of them written, there is nothing to make.
        logInfo("animate: all " + std::to_string(outputs.size()) +
                " frames were written by the same settings (--skip-existing): nothing to do");
        return done;
    }
    lockOutputFrames(outPattern, plan.writing); // two tasks never write one frame (a second exits 75)
    animateFrames(a, example, target, outPattern, plan, settings, done);
    return done;
}

} // namespace

AnimateRun runAnimate(const AnimateJob& job)
{
    if (!job.exportBuiltin.empty()) {
        detail::exportBuiltin(job);
        return {};
    }
    AnimateJob a = job;
    detail::configure(a);
    return runConfigured(a);
}

} // namespace turb::run
