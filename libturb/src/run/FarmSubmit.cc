// turb::run::runFarmSubmit: vdbturb farm submit, a plan's scripts handed to sbatch (turb/run/Farm.h).
#include <turb/run/Farm.h>

#include "FarmShared.h"

#include <turb/run/Reporter.h>

#include <turb/Error.h>

#include <array>
#include <cstdio>
#include <filesystem>

namespace turb::run {

using namespace farm;

namespace {

// Runs a command, returns its stdout; throws with its output when it fails.
std::string runCapture(const std::string& cmd)
{
    std::array<char, 4096> buf{};
    std::string out;
    FILE* p = popen((cmd + " 2>&1").c_str(), "r");
    if (!p) throw turb::IoError("cannot run: " + cmd);
    while (fgets(buf.data(), int(buf.size()), p)) out += buf.data();
    const int rc = pclose(p);
    if (rc != 0) throw turb::IoError(cmd + " failed: " + out);
    return out;
}

std::string trim(std::string s)
{
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ' || s.back() == '\r')) s.pop_back();
    return s;
}

// sbatch --parsable's job id ("jobid[;cluster]") for `args`.
std::string sbatch(const std::string& args)
{
    const std::string id = trim(runCapture("sbatch --parsable " + args));
    return id.substr(0, id.find(';'));
}

} // namespace

FarmSubmitRun runFarmSubmit(const FarmSubmitJob& job)
{
    const std::string dir = absolute(job.dir);
    if (!std::filesystem::exists(dir + "/plan.json"))
        throw turb::IoError(dir + "/plan.json: no plan (vdbturb farm plan --dir " + dir + " first)");
    const nlohmann::json plan = nlohmann::json::parse(readText(dir + "/plan.json"));
    const std::string word = plan.value("kind", "time_chunks") == "space_tiles" ? "tile" : "chunk";
    FarmSubmitRun run;
    if (job.dryRun) {
        printData("would run: sbatch --parsable " + shellQuote(dir + "/" + word + "s.sbatch") +
                  ", then sbatch --parsable --dependency=afterok:<that job> " + shellQuote(dir + "/join.sbatch"));
        return run;
    }
    // --output on the command line too: it wins over the script's, and holds any directory name.
    run.tasksJob = sbatch(
        "--output=" + shellQuote(dir + "/logs/" + word + "_%a.log") + " " + shellQuote(dir + "/" + word + "s.sbatch"));
    run.joinJob = sbatch("--dependency=afterok:" + run.tasksJob + " --output=" + shellQuote(dir + "/logs/join.log") +
                         " " + shellQuote(dir + "/join.sbatch"));
    const nlohmann::json j = {{word + "s_job", run.tasksJob}, {"join_job", run.joinJob}};
    writeText(dir + "/submitted.json", j.dump() + "\n");
    if (job.json) job.json(j.dump() + "\n");
    printData("submitted: " + word + "s job " + run.tasksJob + " (array), join job " + run.joinJob + " (after the " +
                  word + "s succeed)",
        bool(job.json));
    return run;
}

} // namespace turb::run
