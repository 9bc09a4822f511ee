// What runSynth says about its plan and its frames, and the pictures and statistics beside them (SynthSteps.h).
#include "SynthSteps.h"

#include <turb/Metadata.h>
#include <turb/Render.h>
#include <turb/Resample.h>
#include <turbio/ImageIO.h>
#include <turbio/System.h>

#include <algorithm>
#include <cmath>

namespace turb::run::synth {

namespace {

std::string weightingName(turb::CombineSettings::Weighting w)
{
    for (const WeightingName& n : kWeightingNames)
        if (n.weighting == w) return n.name;
    return "constant";
}

turb::View parseView(const std::string& s, bool twoD)
{
    if (s == "top" || (s.empty() && twoD)) return turb::View::Top;
    if (s == "side") return turb::View::Side;
    return turb::View::Front;
}

turb::Image labelled(const turb::Image& img, const std::string& label)
{
    turb::Image out(img.width(), img.height() + turb::Image::textHeight(1) + 6, turb::Rgb(0.07f));
    out.blit(img, 0, 0);
    out.drawText(3, img.height() + 3, label, turb::Rgb(0.9f), 1);
    return out;
}

// --stats: how well each planar view's neighbourhoods match its exemplar.
nlohmann::json textureStats(const std::vector<turb::SynthView>& views, const turb::DetailField& H, bool volume)
{
    nlohmann::json m = nlohmann::json::array();
    for (size_t v = 0; v < views.size(); ++v) {
        if (!views[v].exemplar.planar()) continue;
        turb::TextureMatchSettings ts;
        ts.axis = volume ? views[v].normal : 2; // exact for axis-aligned local frames
        ts.stride = volume ? 8 : 4;
        const turb::TextureMatch tm = turb::textureMatch(views[v].exemplar, H.local, ts);
        m.push_back({{"view", v}, {"nn_distance", tm.distance}, {"shuffled", tm.shuffled}, {"ratio", tm.ratio()},
            {"rms", {tm.fieldRms[0], tm.fieldRms[1]}}, {"exemplar_rms", {tm.exemplarRms[0], tm.exemplarRms[1]}}});
    }
    return m;
}

// --preview: a sheet of the exemplar, up(L), H', F and the density; returns the picture's path.
std::string writeSynthPreview(const SynthJob& a, const SynthPlan& p, const FrameOutcome& o, int fr)
{
    const turb::View view = parseView(a.previewView, !p.volume);
    turb::LicSettings ls;
    ls.view = view;
    ls.width = a.previewWidth;
    turb::LicSettings le = ls;
    le.view = turb::View::Top;
    le.width = std::max(64, a.previewWidth / 2);
    const turb::Image exImg = labelled(turb::renderLic(turb::exemplarAsField(p.views[0].exemplar), le), "exemplar");
    const turb::Image hImg = labelled(turb::renderLic(o.detail->world, ls), "detail H'");
    const turb::Image lImg =
        labelled(turb::renderLic(turb::upsampleCoarse(o.coarse->velocity, a.seq.factor), ls), "coarse up(L)");
    const turb::Image fImg = labelled(turb::renderLic(o.result->motion, ls), "F = up(L) + w H'");
    std::vector<turb::SheetCell> row{{&exImg, ""}, {&lImg, ""}, {&hImg, ""}, {&fImg, ""}};
    turb::Image dImg;
    const turb::Frame& outFrame = o.result->frame;
    if (!outFrame.density.empty()) {
        turb::DensityRenderSettings dr;
        dr.view = view;
        dr.width = a.previewWidth;
        dImg = labelled(p.volume ? turb::renderDensity(outFrame.density, dr)
                                 : turb::renderSlice(outFrame.density, turb::SliceSettings{view, 0.5, a.previewWidth}),
            "density");
        row.push_back({&dImg, ""});
    }
    const turb::Image sheet = turb::contactSheet({row}, {""}, "synth frame " + std::to_string(fr), 1);
    const std::string png = a.preview + "/" + turbio::FramePattern::parse("synth.####." + a.previewFormat).format(fr);
    turbio::ensureParentDirectory(png);
    turbio::writeImage(png, sheet);
    return png;
}

// The synthesis's levels, their sizes, radii and energies (and descent with --trace-descent).
nlohmann::json levelsJson(const turb::DetailField& H)
{
    nlohmann::json lv = nlohmann::json::array();
    for (const auto& l : H.levels) {
        nlohmann::json lj = {{"level", l.level}, {"size", {l.dim.x(), l.dim.y(), l.dim.z()}}, {"radius", l.radius},
            {"energy", l.energy}};
        if (!l.descent.empty()) lj["descent"] = l.descent; // [at search, after the average, after all terms]
        lv.push_back(lj);
    }
    return lv;
}

} // namespace

void logPlan(const SynthJob& a, const CoarseSource& source, const SynthPlan& p)
{
    logInfo("synth: " + source.label() + ", frames " + turbio::formatFrameList(p.frames) + ", " +
            (p.volume ? "3D" : "2D") + ", factor " + std::to_string(a.seq.factor) + ", " +
            std::to_string(p.views.size()) + " view" + (p.views.size() == 1 ? "" : "s") + ", " +
            (a.seq.synth.search == turb::SearchMethod::Tree ? "tree search" : "k-coherence"));
    for (const auto& v : p.views)
        logInfo("  exemplar " + v.exemplar.name + " (" + std::to_string(v.exemplar.nx) + "x" +
                std::to_string(v.exemplar.ny) + (v.exemplar.planar() ? "" : "x" + std::to_string(v.exemplar.nz)) +
                (v.exemplar.periodic ? ", periodic" : "") + ")" +
                (v.exemplar.planar() && p.volume ? ", looks along e" + std::to_string(v.normal + 1) : "") +
                (p.views.size() > 1 ? ", weight " + fmt("%g", v.weight) : ""));
}

void logLevels(const turb::DetailField& H, int fr)
{
    for (const auto& l : H.levels) {
        std::string e;
        for (double x : l.energy) e += fmt(" %.4f", x);
        logVerbose("frame " + std::to_string(fr) + ": level " + std::to_string(l.level) + " " +
                   std::to_string(l.dim.x()) + "x" + std::to_string(l.dim.y()) + "x" + std::to_string(l.dim.z()) +
                   " energy" + e);
    }
}

nlohmann::json projectionReport(
    const SynthJob& a, const turb::SynthFrameResult& r, int fr, FrameProgress& progress, std::vector<int>& unconverged)
{
    nlohmann::json projJson;
    if (r.projection) {
        const turb::ProjectionResult& pr = *r.projection;
        projJson = {{"converged", pr.converged}, {"iterations", pr.iterations}, {"div_max_before", pr.divMaxBefore},
            {"div_max_after", pr.divMaxAfter}};
        if (!pr.converged) {
            // A solver that stops short is a result the user must hear about, not only a JSON field.
            unconverged.push_back(fr);
            progress.clear();
            logWarning("frame " + std::to_string(fr) + ": the projection did not converge (" +
                       std::to_string(pr.iterations) + " iterations); the written velocity is not divergence-free" +
                       (a.strict ? "" : " (--strict makes this an error)"));
            logVerbose("frame " + std::to_string(fr) + ": projection max|div| " + fmt("%.3g", pr.divMaxBefore) +
                       " -> " + fmt("%.3g", pr.divMaxAfter) + " (x" + fmt("%.2e", pr.relativeDivergence()) +
                       "), solver residual " + fmt("%.2e", pr.relativeResidual));
        }
    }
    return projJson;
}

nlohmann::json detailDivergenceReport(
    const SynthJob& a, const turb::SynthFrameResult& r, int fr, FrameProgress& progress, std::vector<int>& unconverged)
{
    if (!r.detailDivergence) return nullptr;
    const turb::CentralDivergenceResult& d = *r.detailDivergence;
    logVerbose("frame " + std::to_string(fr) + ": detail divergence rms " + fmt("%.3g", d.divRmsBefore) + " -> " +
               fmt("%.3g", d.divRmsAfter) + " (" + std::to_string(d.iterations) + " CG iterations)");
    if (!d.converged) {
        if (unconverged.empty() || unconverged.back() != fr) unconverged.push_back(fr);
        progress.clear();
        logWarning("frame " + std::to_string(fr) + ": taking the detail's divergence out did not converge (" +
                   std::to_string(d.iterations) + " iterations, rms " + fmt("%.3g", d.divRmsBefore) + " -> " +
                   fmt("%.3g", d.divRmsAfter) + ")" + (a.strict ? "" : " (--strict makes this an error)"));
    }
    return {{"converged", d.converged}, {"iterations", d.iterations}, {"div_rms_before", d.divRmsBefore},
        {"div_rms_after", d.divRmsAfter}};
}

void tagOutput(turb::Frame& outFrame, const SynthJob& a, const std::vector<turb::SynthView>& views)
{
    outFrame.metadata[turb::meta::kCommand] = "synth";
    std::string names;
    for (const auto& v : views) names += (names.empty() ? "" : ",") + v.exemplar.name;
    outFrame.metadata[turb::meta::kExemplars] = names;
    outFrame.metadata[turb::meta::kOmega] = fmt("%g", a.seq.combine.omega) +
                                            (a.seq.combine.relative ? " x rms|L|" : "") + " " +
                                            weightingName(a.seq.combine.weighting);
    outFrame.metadata[turb::meta::kSeed] = std::to_string(a.seq.synth.seed);
    outFrame.metadata[turb::meta::kRatio] = std::to_string(a.seq.factor); // Blender-style placement (io.md)
}

nlohmann::json frameJson(const SynthJob& a, const SynthPlan& p, const FrameOutcome& o, int fr, FrameProgress& progress)
{
    const turb::SynthFrameResult& r = *o.result;
    const turb::DetailField& H = *o.detail;
    const turb::VectorField& F = r.motion;
    nlohmann::json extra;
    extra["out"] = o.outPath;
    extra["size"] = {F.bbox().dim().x(), F.bbox().dim().y(), F.bbox().dim().z()};
    extra["continued"] = H.fromPrevious;
    extra["levels"] = levelsJson(H);
    extra["energy"] = H.finalEnergy();
    double h2 = 0.0;
    for (const auto& v : H.world.values()) h2 += v.lengthSqr();
    extra["detail_rms"] = std::sqrt(h2 / double(std::max<size_t>(1, H.world.size())));
    extra["detail_region"] = a.seq.detailNearSmoke && o.coarse->hasDensity() ? "smoke" : "everywhere";
    if (a.seq.project) extra["projection"] = o.projection;
    if (r.densityMass) extra["density_mass"] = *r.densityMass;
    if (!o.divergence.is_null()) extra["detail_divergence"] = o.divergence;
    extra["steps_s"] = {{"read", o.readSeconds}, {"write", o.writeSeconds}};
    for (const auto& [name, sec] : r.seconds.named()) extra["steps_s"][name] = sec;
    if (a.stats) {
        progress.begin("statistics");
        extra["texture_match"] = textureStats(p.views, H, p.volume);
    }
    if (!a.preview.empty()) {
        progress.begin("preview");
        extra["preview"] = writeSynthPreview(a, p, o, fr);
    }
    return extra;
}

std::string frameLine(const SynthJob& a, const FrameOutcome& o, const nlohmann::json& extra)
{
    const turb::DetailField& H = *o.detail;
    return std::string(H.fromPrevious ? "continued" : "synthesised") + fmt(", E %.4f", H.finalEnergy()) +
           fmt(", |H'| rms %.3f", extra["detail_rms"].get<double>()) +
           fmt(", synthesis %.2f s", o.result->seconds.synthesis) +
           (a.seq.project ? " projection " + std::to_string(o.projection["iterations"].get<int>()) + " it" : "") +
           " -> " + o.outPath;
}

} // namespace turb::run::synth
