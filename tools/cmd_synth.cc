// vdbturb synth: motion-field texture synthesis (Ma et al. 2009) over a coarse flow.
// Parses the options into a turb::run::SynthJob and runs it (libturb/src/run/SynthRun.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"

#include <turb/run/Synth.h>

#include <memory>

namespace vdbturb {

namespace {

// The command line's synth: the job, and the parser whose options its frames record.
struct SynthArgs : turb::run::SynthJob
{
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
};

int runSynthCommand(const SynthArgs& a)
{
    turb::run::SynthJob job = a;
    job.settingsText =
        commandSettingsText(*a.app, a.target.empty() ? std::vector<std::string>{} : std::vector<std::string>{a.target});
    job.dryRun = globals().dryRun;
    job.threads = globals().threads;
    const turb::run::SynthRun done = turb::run::runSynth(job);
    if (!done.strictFailure.empty()) return reportFailure(done.strictFailure, kFailed);
    return kOk;
}

} // namespace

Command synthCommand()
{
    auto args = std::make_shared<SynthArgs>();
    Command c;
    c.name = "synth";
    c.help = "Motion-field texture synthesis: detail motion from small exemplars, oriented along a coarse flow";
    c.setup = [args](CLI::App* app) {
        SynthArgs& a = *args;
        app->add_option("--target", a.target, "Coarse motion L: a VDB cache (pattern or one file); density optional");
        app->add_option("--scene", a.scene,
            "Coarse motion from a built-in scene simulated on the fly (plume, swirl, obstacle, wind)");
        app->add_option("--flow", a.flow, "Coarse motion from an analytic flow (no density)")
            ->check(CLI::IsMember({"uniform", "vortex", "shear"}));
        app->add_option(
               "--frames", a.frames, "Cache: frames to use (default all). Scene/flow: a count N or a list (default 1)")
            ->check(frameListCheck());
        app->add_option("--factor", a.seq.factor, "Up-res factor: output voxel = coarse voxel / factor")
            ->check(CLI::Range(1, 32));
        app->add_option("--exemplar", a.exemplars,
            "Exemplar, repeatable (one per view): circles|swirls|squares|hearts|stripes|sinusoids[:PERIOD[:SIZE]] "
            "(default "
            "circles:16), rg:PICTURE[:SCALE], gray:PICTURE[:SCALE], vdb:FILE.vdb[:AXIS:INDEX], vdb3:FILE.vdb "
            "(docs/synth.md)");
        app->add_option("--omega", a.seq.combine.omega, "Detail strength: times rms|L|")->check(finiteIn(0.0));
        app->add_option(
            "--walls", a.walls, "Walls: x-,x+,y-,y+,z-,z+, all or none (default: a scene's closed faces, else none)");
        app->add_flag(
            "--project", a.seq.project, "Make F divergence-free (Helmholtz-Hodge projection); walls are closed faces");
        app->add_flag("--strict", a.strict,
            "Exit 1 when a projection or the detail's divergence solve does not converge (always a warning naming the "
            "frame)");
        app->add_option(
            "--preview", a.preview, "Write a picture per frame into DIR: LIC of exemplar, up(L), H', F, and density");
        app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        addReadOptions(app, a.read);
        app->add_option("--out", a.out, "Output pattern (directories are created)")->group(kGroupOutput);
        addWriteOptions(app, a.write);
        app->add_flag("--skip-existing", a.skipExisting,
               "Skip the frames already written by the same settings (farm wrappers' retries; the frames before the "
               "last one to write are made again, not written); a frame written otherwise is refused (exit 1)")
            ->group(kGroupOutput);
        a.app = app;
        // --output's words map to detailOnly, which an old spelling of the table cannot say.
        legacy(
            app->add_option_function<std::string>(
                   "--output", [&a](const std::string& v) { a.seq.detailOnly = v == "detail"; }, "combined or detail")
                ->check(CLI::IsMember({"combined", "detail"})),
            "detailOnly");
        addSettings(
            app, static_cast<turb::run::SynthJob&>(a), turb::run::synthSettings(), turb::run::synthOldSpellings());
    };
    c.run = [args] { return runSynthCommand(*args); };
    return c;
}

} // namespace vdbturb
