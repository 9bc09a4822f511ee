// animate's second tier as a settings table (turb/run/Settings.h): turb::AnimateSettings' knobs under their fields'
// names (the job's own beside them), in the order --help-all lists them.
#include "SettingsRows.h"

#include <turb/run/Animate.h>

namespace turb::run {

namespace {

using detail::add;
using Table = SettingsTable<AnimateJob>;

// The design's input, what the run writes besides its frames, and the refinement (section 5.1).
void addDesign(Table& t)
{
    add(t, "flow-y-up", "", "The --flow image's G channel points up", TURB_FIELD(flowYUp)).flag = true;
    add(t, "dump", "", "Also write every stage's images into DIR (float EXR) and flow pictures (PNG)",
        TURB_FIELD(dump));
    add(t, "measure", "", "Measure the output's flow against the design and its temporal statistics",
        TURB_FIELD(measure))
        .flag = true;
    add(t, "refine", "", "Refine the design by the target's gradients: auto (strokes yes, --flow no), on, off",
        TURB_FIELD(refine))
        .choices = {
        {"auto", int(AnimateRefine::Auto)}, {"on", int(AnimateRefine::On)}, {"off", int(AnimateRefine::Off)}};
    add(t, "refine.orient", "orient",
        "Refined orientation: parallel to the image gradient (the paper) or perpendicular (along edges)",
        TURB_FIELD(settings.refine.orient))
        .choices = {
        {"parallel", int(GradientOrientation::Parallel)}, {"perpendicular", int(GradientOrientation::Perpendicular)}};
    add(t, "refine.wf", "wf", "w_f: blur of the refined orientation, Gaussian std in pixels (paper 12)",
        TURB_FIELD(settings.refine.wf), 0.1, 500.0);
}

// The residuals: their lifetime, the average A' they are added to, their transfer (section 5.4) and the example's
// analysis.
void addResiduals(Table& t)
{
    add(t, "tau", "", "Lifetime of a residual in frames (paper 16); the output has N - tau frames",
        TURB_FIELD(settings.tau), 1, 10000);
    add(t, "average.shutter", "shutter", "Sh: motion blur of the target along the flow for A', in frames",
        TURB_FIELD(settings.average.shutter), 0.0, 200.0);
    add(t, "average.wa", "wa", "w_a: Gaussian std in pixels after the motion blur for A'",
        TURB_FIELD(settings.average.wa), 0.0, 500.0);
    add(t, "transfer.patchSize", "patch", "Residual transfer patch size in pixels (paper 8-32)",
        TURB_FIELD(settings.transfer.patchSize), 8, 64);
    add(t, "transfer.downsample", "search-downsample", "Match flows downsampled by 1, 2 or 4",
        TURB_FIELD(settings.transfer.downsample))
        .choices = {{"1", 1}, {"2", 2}, {"4", 4}};
    add(t, "transfer.variety", "variety",
        "Residual transfer: candidates within this fraction of the patch's design speed of the best are equally good, "
        "and the one farthest from its neighbours' windows is taken (0: the nearest, the paper)",
        TURB_FIELD(settings.transfer.variety), 0.0, 1.0);
    add(t, "transfer.candidates", "",
        "Residual transfer: random example windows costed per patch besides the 8 nearest (only with variety > 0)",
        TURB_FIELD(settings.transfer.candidates), 1, 64);
    add(t, "analysis.features", "features", "Lucas-Kanade features per example frame pair (paper 100)",
        TURB_FIELD(settings.analysis.features), 1, 100000);
    add(t, "analysis.window", "lk-window", "Lucas-Kanade window in pixels (paper 10)",
        TURB_FIELD(settings.analysis.window), 3, 64);
}

// Histogram matching (section 5.6): the steerable pyramid's repetitions and the grid of cells.
void addHistogramMatching(Table& t)
{
    add(t, "hm.reps", "hm-rep", "HM Rep: repetitions of the steerable matching (paper 3)", TURB_FIELD(settings.hm.reps),
        1, 10);
    // Checked while parsing, so a bad grid is a usage error (exit 2) like every other option's bad value.
    Setting<AnimateJob>& grid = add(
        t, "hm-grid", "", "HM Grid: COLSxROWS, auto (cells of about hm.cellSize pixels) or off", TURB_FIELD(hmGrid));
    grid.validate = hmGridProblem;
    grid.typeName = "COLSxROWS|auto|off";
    add(t, "hm.cellSize", "hm-cell", "Cell size of the automatic HM grid in pixels", TURB_FIELD(settings.hm.cellSize),
        16, 100000);
    add(t, "hm.pixelPasses", "hm-passes", "Final pixel-domain matching passes", TURB_FIELD(settings.hm.pixelPasses), 1,
        20);
    add(t, "hm.blendPixels", "",
        "Blend the cells' pixel-domain matches (false: each cell's statistics exact, seams can show)",
        TURB_FIELD(settings.hm.blendPixels));
    add(t, "hm.cellMoments", "",
        "Finally solve one blended gain and offset per cell so every cell's mean and std are the target's (false: "
        "stop after the pixel passes)",
        TURB_FIELD(settings.hm.cellMoments));
    add(t, "hmApply", "hm-apply",
        "per-frame: match every frame (the paper); sequence: match the mean frame once, give every frame that "
        "correction and its own cell moments (keeps the moving detail on smooth stills such as smoke renders; a "
        "static speckle on textured ones; docs/animate.md)",
        TURB_FIELD(settings.hmApply))
        .choices = {{"per-frame", int(HmApply::PerFrame)}, {"sequence", int(HmApply::Sequence)}};
    add(t, "analysis.givenFlow", "",
        "v of a cache example: best (its projected velocity or the tracked flow, whichever leaves the smaller "
        "residuals), use (the velocity) or track (the paper's tracking)",
        TURB_FIELD(settings.analysis.givenFlow))
        .choices = {{"best", int(GivenFlow::Best)}, {"use", int(GivenFlow::Use)}, {"track", int(GivenFlow::Track)}};
}

} // namespace

const SettingsTable<AnimateJob>& animateSettings()
{
    static const Table table = detail::tableOf<AnimateJob>({addDesign, addResiduals, addHistogramMatching});
    return table;
}

const std::vector<OldSpelling>& animateOldSpellings()
{
    static const std::vector<OldSpelling> spellings{{"hm-exact-cells", "hm.blendPixels", "false", ""}};
    return spellings;
}

} // namespace turb::run
