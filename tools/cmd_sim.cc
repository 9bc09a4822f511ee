// vdbturb sim SCENE: simulate a built-in smoke scene into a VDB sequence. Parses the options into a
// turb::run::SimJob and runs it (libturb/src/run/Sim.cc).
#include "Commands.h"
#include "Console.h"
#include "Preflight.h"

#include <scenes/Smoke.h>
#include <turb/Error.h>
#include <turb/run/Sim.h>

#include <algorithm>
#include <memory>

namespace vdbturb {

namespace {

using turb::run::parseResolution;

using turb::run::SimJob;

struct SimArgs : SimJob
{
    bool json = false;
    bool list = false;
    const CLI::App* app = nullptr; ///< for the settings its frames record (--skip-existing)
};

int runSim(SimArgs& a)
{
    if (a.list) {
        writeData(turb::run::sceneListText());
        return kOk;
    }
    // Frame k of a scene depends on its settings, --start and k only: the settings say all of it.
    if (a.scene != "ink") a.settingsText = commandSettingsText(*a.app, {});
    a.dryRun = globals().dryRun;
    a.threads = globals().threads;
    turb::run::runSim(a);
    return kOk;
}

// CLI11's own checks name only the range: say what a resolution is.
CLI::Validator resolutionCheck()
{
    return CLI::Validator(
        [](std::string& v) {
            try {
                if (std::count(v.begin(), v.end(), 'x') + std::count(v.begin(), v.end(), 'X') == 1)
                    return std::string(); // 2D (ink)
                parseResolution(v);
            } catch (const turb::ValueError& e) {
                return std::string(e.what());
            }
            return std::string();
        },
        "NXxNYxNZ");
}

CLI::Validator frameCountCheck()
{
    return CLI::Validator(
        [](std::string& v) {
            return v.find_first_not_of("0123456789") == std::string::npos && !v.empty() &&
                           std::stoll(v.substr(0, 9)) > 0
                       ? std::string()
                       : "sim --frames is a number of frames (e.g. 24), not a frame list; got '" + v + "'";
        },
        "COUNT");
}

} // namespace

Command simCommand()
{
    auto args = std::make_shared<SimArgs>();
    Command c;
    c.name = "sim";
    c.help = "Simulate a built-in smoke scene (plume, swirl, obstacle, wind) into a VDB sequence, or the 2D ink "
             "exemplar into images";
    c.setup = [args](CLI::App* app) {
        SimArgs& a = *args;
        std::vector<std::string> names;
        for (const auto& s : turb::scenes::sceneList()) names.push_back(s.name);
        names.push_back("ink");
        app->add_option("scene", a.scene, "Scene: plume, swirl, obstacle, wind, or the 2D ink (see --list)")
            ->check(CLI::IsMember(names));
        app->add_flag("--list", a.list, "List the scenes and exit");
        app->add_option("--res", a.res, "Cells NXxNYxNZ along x, y, z (z up), or N for a cube; NZ = 1 simulates in 2D")
            ->check(resolutionCheck());
        app->add_option("--frames", a.frames, "Number of frames to simulate, at 24 per second")
            ->check(frameCountCheck());
        app->add_option("--start", a.start, "Number of the first frame written");
        app->add_option("--seed", a.seed, "Emitter noise seed; the same seed gives identical caches");
        app->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        app->add_option(
               "--out", a.out, "Output pattern, e.g. sim/plume.####.vdb (default: sim/SCENE_RES/SCENE.####.vdb)")
            ->group(kGroupOutput);
        addWriteOptions(app, a.write);
        app->add_flag("--skip-existing", a.skipExisting,
               "Skip the frames already written by the same settings (farm wrappers' retries; the frames before the "
               "last one to write are simulated again, not written); a frame written otherwise is refused (exit 1)")
            ->group(kGroupOutput);
        // The second tier: the solver's advection and pressure projection (docs/scenes.md).
        addSettings(app, static_cast<SimJob&>(a), turb::run::simSettings());
        a.app = app;
    };
    c.run = [args] { return runSim(*args); };
    return c;
}

} // namespace vdbturb
