// vdbturb: command-line entry point. Table-driven: see Commands.h.
#include "Commands.h"
#include "Console.h"

#include <turb/Error.h>

#include <iostream>

#include <malloc.h>

using namespace vdbturb;

namespace vdbturb {

void addReadOptions(CLI::App* app, turbio::ReadOptions& opt, const std::string& prefix)
{
    const std::string p = prefix.empty() ? "--" : "--" + prefix + "-";
    app->add_option(p + "density-grid", opt.densityGrid, "Density grid name (default: density, density_noise)");
    app->add_option(p + "vel-grid", opt.velocityGrid,
        "Velocity grid name, or the stem of NAME.x/.y/.z (default: vel, velocity, v)");
    app->add_option_function<std::string>(p + "vel-units",
           [&opt](const std::string& s) {
               opt.velocityUnits = s == "world" ? turbio::VelocityUnits::World
                                   : s == "cells" ? turbio::VelocityUnits::Cells
                                                  : turbio::VelocityUnits::Auto;
           },
           "Velocity units: world, cells (grid cells per time unit, Blender), auto (default: detect)")
        ->check(CLI::IsMember({"auto", "world", "cells"}));
    app->add_option(p + "dt", opt.dt,
           "Time per frame in the velocity's time unit (default: from vdbturb metadata; Blender 0.1*25/fps; else 1/fps)")
        ->check(CLI::PositiveNumber);
    app->add_option(p + "fps", opt.fps, "Frames per second, for the default time per frame (default 24)")
        ->check(CLI::PositiveNumber);
}

void addWriteOptions(CLI::App* app, turbio::WriteOptions& opt)
{
    app->add_option_function<std::string>("--style",
           [&opt](const std::string& s) {
               opt.style = s == "blender" ? turbio::WriteStyle::Blender : turbio::WriteStyle::Houdini;
           },
           "Output grid convention: houdini (vel + density, world units; default) or blender (staggered "
           "velocity in cells + density)")
        ->check(CLI::IsMember({"houdini", "blender"}));
    app->add_flag("--no-clobber", opt.noClobber, "Never replace an existing output file");
    app->add_flag("--half", opt.halfFloat, "Store floats as half precision (smaller files)");
}

std::vector<Command> allCommands() { return {infoCommand(), transferCommand(), measureCommand(), simCommand(), previewCommand(), synthCommand(), stylizeCommand(), animateCommand(), resampleCommand()}; }

} // namespace vdbturb

int main(int argc, char** argv)
{
    // Image stages allocate and free many frame-sized buffers (a few MB each). Keep them in the heap
    // instead of mapping fresh pages for each one: measured 0.70 -> 0.52 CPU-s per 640x480 frame of
    // animate's histogram matching (docs/performance.md).
    mallopt(M_MMAP_THRESHOLD, 64 << 20);
    mallopt(M_TRIM_THRESHOLD, 256 << 20);
    CLI::App app{"vdbturb: turbulence up-res for smoke caches (VDB in, VDB out)"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("vdbturb ") + VDBTURB_VERSION_STRING);

    std::vector<Command> commands = allCommands();
    std::vector<std::pair<CLI::App*, Command*>> subs;
    for (auto& c : commands) {
        CLI::App* sub = app.add_subcommand(c.name, c.help);
        addGlobalOptions(sub);
        c.setup(sub);
        subs.emplace_back(sub, &c);
    }
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int rc = app.exit(e);
        return rc == 0 ? kOk : kUsage;
    }
    installSignalHandlers();
    for (auto& [sub, cmd] : subs) {
        if (!sub->parsed()) continue;
        try {
            return cmd->run();
        } catch (const turb::Cancelled&) {
            logError("interrupted");
            return kInterrupted;
        } catch (const turb::ValueError& e) {
            logError(e.what());
            return kFailed;
        } catch (const turb::Error& e) {
            logError(e.what());
            return kFailed;
        } catch (const std::exception& e) {
            logError(std::string("unexpected: ") + e.what());
            return kFailed;
        }
    }
    return kUsage;
}
