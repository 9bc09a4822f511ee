// vdbturb transfer: turbulence style transfer (Sato et al. 2018) from a high-res source onto a low-res target.
// Parses the options into a turb::run::TransferJob and runs it (libturb/src/run/Transfer.cc).
#include "Commands.h"
#include "Console.h"

#include <turb/Farm.h>
#include <turb/Transfer.h>
#include <turb/run/Transfer.h>

#include <memory>
#include <utility>
#include <vector>

namespace vdbturb {

namespace {

using turb::run::kKindTwins;
using turb::run::TransferJob;

// The command line's transfer: the job, and the options whose being given matters.
struct TransferArgs : TransferJob
{
    const CLI::Option* sourceCropMargin = nullptr; ///< given or not: its default depends on the ratio
    const CLI::Option* velocityMargin = nullptr;   ///< given or not: --style blender ignores it, saying so if given
    /// kKindTwins' options as parsed (3D, 2D): one given for the other kind of cache gets a warning.
    std::vector<std::pair<const CLI::Option*, const CLI::Option*>> kindTwins;
};

int runTransfer(TransferArgs& a)
{
    TransferJob job = a;
    job.sourceCropMarginGiven = a.sourceCropMargin && a.sourceCropMargin->count() > 0;
    job.velocityMarginGiven = a.velocityMargin && a.velocityMargin->count() > 0;
    for (const auto& [threeD, twoD] : a.kindTwins)
        job.kindTwinsGiven.emplace_back(threeD->count() > 0, twoD->count() > 0);
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    turb::run::runTransfer(job);
    return kOk;
}

} // namespace

Command transferCommand()
{
    auto args = std::make_shared<TransferArgs>();
    Command c;
    c.name = "transfer";
    c.help = "Turbulence style transfer: add a high-res source's detail to a low-res target's motion (3D, or 2D: "
             "one-z-layer caches)";
    c.setup = [args](CLI::App* app) {
        TransferArgs& a = *args;
        app->add_option("--target", a.target, "Low-res target cache (velocity + density): pattern or one file")
            ->required();
        app->add_option("--source", a.source, "High-res source cache whose turbulence is transferred")->required();
        app->add_option("--out", a.out, "Output pattern, e.g. up/turb.####.vdb (directories are created)")->required();
        app->add_option("--frames", a.frames, "Target frames, e.g. 1001-1100x2 (default: all on disk)")
            ->check(frameListCheck());
        app->add_option("--source-frames", a.sourceFrames, "Restrict the source to these frames")
            ->check(frameListCheck());
        app->add_option("--source-offset", a.sourceOffset, "Source frame = target frame + offset");
        addEnum<turbio::SourceWrap>(app, "--source-wrap", a.wrap,
            {{"loop", turbio::SourceWrap::Loop}, {"pingpong", turbio::SourceWrap::PingPong},
                {"clamp", turbio::SourceWrap::Clamp}, {"error", turbio::SourceWrap::Error}},
            "When the source runs out");
        addEnum<turb::DensityMode>(app, "--density", a.settings.densityMode,
            {{"advect", turb::DensityMode::Advect}, {"lookback", turb::DensityMode::LookBack}},
            "Output density: advected, or looked back m frames (Ma et al.'s supplement)");
        app->add_option("--preroll", a.preroll,
               "Run up to N cache frames before the first requested one without writing them, so the detail and "
               "density are established as in a longer run")
            ->check(finiteIn(0.0));
        app->add_flag("--resume,--skip-existing", a.resume,
            "Skip frames already written (refused unless the last was made with these settings) and continue from the "
            "state saved in it; --skip-existing is the farm wrappers' name for it");
        app->add_flag("--json", "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.targetRead, "target");
        addReadOptions(app, a.sourceRead, "source");
        a.sourceCropMargin =
            app->get_option("--source-crop-margin")
                ->description("Source voxels kept around the source's smoke (default: 8 target voxels)");
        app->add_option("--tile-box", a.tileBox,
               "Hold only this box of the target, X0,Y0,Z0,X1,Y1,Z1 (inclusive voxel indices): a space tile and its "
               "halo, as farm plan --tiles writes it. The output covers its refined box")
            ->check(parsedBy([](const std::string& t) { turb::parseTileBox(t); }, "X0,Y0,Z0,X1,Y1,Z1"))
            ->group(kGroupInput);
        addWriteOptions(app, a.write);
        addFormatOptions(app, a.write);
        addVelocityWriteOptions(app, a.write);
        a.velocityMargin = app->get_option("--velocity-margin");
        addSettings(
            app, static_cast<TransferJob&>(a), turb::run::transferSettings(), turb::run::transferOldSpellings());
        for (const turb::run::KindTwin& k : kKindTwins)
            a.kindTwins.emplace_back(app->get_option(k.option3D), app->get_option(k.option2D));
    };
    c.run = [args] { return runTransfer(*args); };
    return c;
}

} // namespace vdbturb
