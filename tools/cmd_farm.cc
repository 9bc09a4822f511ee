// vdbturb farm: a transfer split into time chunks that run as Slurm array tasks, and the join that cross-fades
// their overlaps (docs/farm.md). The scheduling is Slurm's: this writes sbatch scripts and a JSON plan, and
// calls sbatch. The blend math is libturb's (turb/Farm.h).
#include "Commands.h"
#include "Console.h"
#include "RunReport.h"

#include <turb/Error.h>
#include <turb/Farm.h>
#include <turb/Metadata.h>
#include <turb/Resample.h>
#include <turbio/Sequence.h>
#include <turbio/Vdb.h>

#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <unistd.h>

namespace vdbturb {

namespace {

namespace fs = std::filesystem;

// Defaults from the Blender pair measurements in docs/farm.md: O = 10 kept seam frames at 1.4-1.6x the sequential
// median tcoh (the cross-fade step falls as 1/(O+1)); P = 8 gave the later chunk a settled detail.
constexpr int kDefaultPreroll = 8;
constexpr int kDefaultOverlap = 10;

struct FarmArgs
{
    // plan
    std::string dir = "farm";
    std::string target, source, out, frames;
    int chunks = 2, preroll = kDefaultPreroll, overlap = kDefaultOverlap;
    int cpus = 2, retries = 2;
    std::string exe, partition, time, mem, name = "vdbturb";
    std::vector<std::string> transferArgs;
    // join
    bool keepScratch = true;
    bool json = false;
    turbio::ReadOptions targetRead;
    turbio::WriteOptions write;
};

std::string shellQuote(const std::string& s)
{
    if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=/.,:@%#") == std::string::npos)
        return s;
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

std::string joinCommand(const std::vector<std::string>& argv)
{
    std::string s;
    for (const auto& a : argv) s += (s.empty() ? "" : " ") + shellQuote(a);
    return s;
}

std::string absolute(const std::string& p) { return fs::absolute(fs::path(p)).lexically_normal().string(); }

std::string selfExe()
{
    std::error_code ec;
    const fs::path p = fs::read_symlink("/proc/self/exe", ec);
    return ec ? std::string("vdbturb") : p.string();
}

std::string readText(const std::string& path)
{
    std::ifstream in(path);
    if (!in) throw turb::IoError(path + ": cannot read");
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

void writeText(const std::string& path, const std::string& text, bool executable = false)
{
    turbio::writeFileAtomic(path, text);
    if (executable) fs::permissions(path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec, fs::perm_options::add);
}

// The chunk's scratch pattern: every frame it computes, pre-roll included, so --resume can continue a killed task.
std::string chunkPattern(const std::string& dir, int k, const std::string& out)
{
    char sub[32];
    std::snprintf(sub, sizeof(sub), "chunks/%03d/", k);
    return (fs::path(dir) / sub / fs::path(out).filename()).string();
}

// The transfer's options the join needs too: the target's read options (it reads u_t as the chunks did) and the
// output options (blended frames are written like the chunks' own).
std::vector<std::string> joinArgs(const std::vector<std::string>& args)
{
    std::vector<std::string> out;
    for (size_t i = 0; i < args.size(); ++i)
        if (args[i].rfind("--target-", 0) == 0 || args[i].rfind("--style", 0) == 0 ||
            args[i].rfind("--velocity-margin", 0) == 0 || args[i].rfind("--clipping", 0) == 0) {
            out.push_back(args[i]);
            if (args[i].find('=') == std::string::npos && i + 1 < args.size()) out.push_back(args[++i]);
        } else if (args[i] == "--half") {
            out.push_back(args[i]);
        }
    return out;
}

int runPlan(FarmArgs& a)
{
    for (const auto& t : a.transferArgs)
        if (t == "--frames" || t == "--out" || t == "--target" || t == "--source" || t == "--resume" || t == "--threads" ||
            t.rfind("--frames=", 0) == 0 || t.rfind("--out=", 0) == 0)
            throw turb::ValueError("'" + t + "' after -- is set by farm plan itself; give --target/--source/--out/--frames to farm plan");
    const turbio::Sequence target = turbio::resolveSequence(a.target, a.frames);
    if (!target.missing.empty())
        throw turb::IoError(target.pattern.str() + ": missing target frames " + turbio::formatFrameList(target.missing));
    const std::vector<int>& frames = target.frames;
    const std::vector<turb::TimeChunk> chunks = turb::planTimeChunks(frames.size(), a.chunks, a.preroll, a.overlap);
    if (!turbio::FramePattern::parse(a.out).numbered()) throw turb::ValueError("--out '" + a.out + "' has no frame token (####)");

    const std::string dir = absolute(a.dir);
    const std::string exe = a.exe.empty() ? selfExe() : a.exe;
    const std::string targetAbs = absolute(a.target), sourceAbs = absolute(a.source), outAbs = absolute(a.out);
    fs::create_directories(fs::path(dir) / "logs");
    const auto sub = [&](size_t b, size_t e) { return std::vector<int>(frames.begin() + long(b), frames.begin() + long(e)); };

    nlohmann::json plan;
    plan["version"] = 1;
    plan["kind"] = "time_chunks";
    plan["dir"] = dir;
    plan["vdbturb"] = exe;
    plan["target"] = targetAbs;
    plan["source"] = sourceAbs;
    plan["out"] = outAbs;
    plan["frames"] = turbio::formatFrameList(frames);
    plan["chunks"] = a.chunks;
    plan["preroll"] = a.preroll;
    plan["overlap"] = a.overlap;
    plan["transfer_args"] = a.transferArgs;
    plan["exit_codes"] = {{"0", "done"}, {"1", "a frame failed: retry (resumes from the last whole frame)"},
        {"2", "usage error: do not retry"}, {"130", "interrupted: retry"}};
    nlohmann::json tasks = nlohmann::json::array();
    std::string cases;
    for (const auto& c : chunks) {
        const std::string pattern = chunkPattern(dir, c.index, a.out);
        std::vector<std::string> argv = {exe, "transfer", "--target", targetAbs, "--source", sourceAbs, "--out", pattern,
            "--frames", turbio::formatFrameList(sub(c.computeBegin, c.end)), "--resume", "--threads", std::to_string(a.cpus),
            // Every chunk holds the target's whole domain: held over the smoke of its own frames only, chunks would
            // get different output boxes and the join could not blend them.
            "--target-no-crop", "--source-no-crop"};
        argv.insert(argv.end(), a.transferArgs.begin(), a.transferArgs.end());
        nlohmann::json t;
        t["name"] = "chunk" + std::to_string(c.index);
        t["array_index"] = c.index;
        t["frames_computed"] = turbio::formatFrameList(sub(c.computeBegin, c.end));
        t["frames_preroll"] = turbio::formatFrameList(sub(c.computeBegin, c.keepBegin));
        t["frames_kept"] = turbio::formatFrameList(sub(c.keepBegin, c.end));
        t["out"] = pattern;
        t["log"] = dir + "/logs/chunk_" + std::to_string(c.index) + ".log";
        t["command"] = argv;
        t["depends_on"] = nlohmann::json::array();
        t["retry_exit_codes"] = {1, 130, 137, 143};
        tasks.push_back(t);
        cases += "  " + std::to_string(c.index) + ") set -- " + joinCommand(argv) + " ;;\n";
    }
    std::vector<std::string> joinArgv = {exe, "farm", "join", "--dir", dir, "--threads", std::to_string(a.cpus)};
    for (const auto& r : joinArgs(a.transferArgs)) joinArgv.push_back(r);
    nlohmann::json join;
    join["name"] = "join";
    join["frames"] = turbio::formatFrameList(frames);
    join["out"] = outAbs;
    join["log"] = dir + "/logs/join.log";
    join["command"] = joinArgv;
    nlohmann::json deps = nlohmann::json::array();
    for (const auto& c : chunks) deps.push_back("chunk" + std::to_string(c.index));
    join["depends_on"] = deps;
    tasks.push_back(join);
    plan["tasks"] = tasks;
    nlohmann::json overlaps = nlohmann::json::array();
    for (size_t k = 0; k + 1 < chunks.size(); ++k)
        for (int j = 0; j < a.overlap; ++j) {
            const turb::CrossFade w = turb::crossFade(j, a.overlap);
            overlaps.push_back({{"frame", frames[chunks[k + 1].keepBegin + size_t(j)]}, {"a", int(k)}, {"b", int(k + 1)},
                {"t", w.t}, {"detail_a", w.detailA}, {"detail_b", w.detailB}, {"density_a", w.densityA}, {"density_b", w.densityB}});
        }
    plan["overlaps"] = overlaps;
    plan["slurm"] = {{"chunks_script", dir + "/chunks.sbatch"}, {"join_script", dir + "/join.sbatch"}};

    std::string common = "#SBATCH --cpus-per-task=" + std::to_string(a.cpus) + "\n";
    if (!a.partition.empty()) common += "#SBATCH --partition=" + a.partition + "\n";
    if (!a.time.empty()) common += "#SBATCH --time=" + a.time + "\n";
    if (!a.mem.empty()) common += "#SBATCH --mem=" + a.mem + "\n";
    // A task that failed (exit 1), was interrupted (130) or killed (137, 143) requeues itself up to --retries
    // times; transfer --resume then continues from the last whole frame in the chunk's scratch directory. A usage
    // error (2) would fail again and is not retried. Slurm's own --requeue covers node failure and preemption.
    const std::string chunksScript =
        "#!/bin/sh\n"
        "# Written by vdbturb farm plan: one array task per time chunk (plan.json has the same plan as JSON).\n"
        "#SBATCH --job-name=" + a.name + "-chunks\n"
        "#SBATCH --array=0-" + std::to_string(chunks.size() - 1) + "\n"
        "#SBATCH --requeue\n"
        "#SBATCH --open-mode=append\n"
        "#SBATCH --output=" + dir + "/logs/chunk_%a.log\n" + common +
        "case \"$SLURM_ARRAY_TASK_ID\" in\n" + cases +
        "  *) echo \"farm: no chunk $SLURM_ARRAY_TASK_ID\" >&2; exit 2 ;;\n"
        "esac\n"
        "echo \"farm: chunk $SLURM_ARRAY_TASK_ID start (restart ${SLURM_RESTART_COUNT:-0}) on $(hostname)\" >&2\n"
        "\"$@\"\n"
        "rc=$?\n"
        "echo \"farm: chunk $SLURM_ARRAY_TASK_ID exit $rc\" >&2\n"
        "case $rc in\n"
        "  0|2) exit $rc ;;\n"
        "esac\n"
        "if [ \"${SLURM_RESTART_COUNT:-0}\" -lt " + std::to_string(a.retries) + " ]; then\n"
        "  echo \"farm: chunk $SLURM_ARRAY_TASK_ID requeued; it resumes from its last whole frame\" >&2\n"
        "  scontrol requeue \"${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\"\n"
        "  sleep 30 # the requeue ends this job; do not let it finish as failed first\n"
        "fi\n"
        "exit $rc\n";
    const std::string joinScript =
        "#!/bin/sh\n"
        "# Written by vdbturb farm plan: assembles the chunks and cross-fades their overlaps (after every chunk succeeded).\n"
        "#SBATCH --job-name=" + a.name + "-join\n"
        "#SBATCH --output=" + dir + "/logs/join.log\n"
        "#SBATCH --open-mode=append\n" + common +
        "exec " + joinCommand(joinArgv) + "\n";
    writeText(dir + "/plan.json", plan.dump(2) + "\n");
    writeText(dir + "/chunks.sbatch", chunksScript, true);
    writeText(dir + "/join.sbatch", joinScript, true);

    printData("plan: " + std::to_string(frames.size()) + " frames " + turbio::formatFrameList(frames) + " in " +
              std::to_string(chunks.size()) + " chunks, pre-roll " + std::to_string(a.preroll) + ", overlap " + std::to_string(a.overlap));
    for (const auto& c : chunks)
        printData("  chunk " + std::to_string(c.index) + ": computes " + turbio::formatFrameList(sub(c.computeBegin, c.end)) +
                  ", keeps " + turbio::formatFrameList(sub(c.keepBegin, c.end)));
    printData("wrote " + dir + "/plan.json, chunks.sbatch, join.sbatch; submit with: vdbturb farm submit --dir " + dir);
    return kOk;
}

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

int runSubmit(FarmArgs& a)
{
    const std::string dir = absolute(a.dir);
    if (!fs::exists(dir + "/plan.json")) throw turb::IoError(dir + "/plan.json: no plan (vdbturb farm plan --dir " + dir + " first)");
    // --parsable prints "jobid[;cluster]".
    std::string chunks = trim(runCapture("sbatch --parsable " + shellQuote(dir + "/chunks.sbatch")));
    chunks = chunks.substr(0, chunks.find(';'));
    std::string join = trim(runCapture("sbatch --parsable --dependency=afterok:" + chunks + " " + shellQuote(dir + "/join.sbatch")));
    join = join.substr(0, join.find(';'));
    nlohmann::json j = {{"chunks_job", chunks}, {"join_job", join}};
    writeText(dir + "/submitted.json", j.dump() + "\n");
    if (a.json) std::printf("%s\n", j.dump().c_str());
    printData("submitted: chunks job " + chunks + " (array), join job " + join + " (after the chunks succeed)", a.json);
    return kOk;
}

void copyAtomic(const std::string& from, const std::string& to)
{
    const std::string tmp = to + ".farm-tmp";
    fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
    fs::rename(tmp, to);
}

int runJoin(FarmArgs& a)
{
    const std::string dir = absolute(a.dir);
    const nlohmann::json plan = nlohmann::json::parse(readText(dir + "/plan.json"));
    const std::vector<int> frames = turbio::parseFrameList(plan.at("frames").get<std::string>());
    const int n = plan.at("chunks").get<int>(), P = plan.at("preroll").get<int>(), O = plan.at("overlap").get<int>();
    const std::vector<turb::TimeChunk> chunks = turb::planTimeChunks(frames.size(), n, P, O);
    const std::string out = plan.at("out").get<std::string>();
    const turbio::FramePattern outPattern = turbio::FramePattern::parse(out);
    const turbio::Sequence target = turbio::resolveSequence(plan.at("target").get<std::string>(), plan.at("frames").get<std::string>());
    float threshold = 0.01f;
    const auto& ta = plan.at("transfer_args");
    for (size_t i = 0; i + 1 < ta.size(); ++i)
        if (ta[i] == "--density-threshold") threshold = std::stof(ta[i + 1].get<std::string>());

    // Check every chunk is complete before writing anything: a join of a partial chunk would leave holes.
    for (const auto& c : chunks) {
        const turbio::FramePattern p = turbio::FramePattern::parse(chunkPattern(dir, c.index, out));
        for (size_t i = c.keepBegin; i < c.end; ++i)
            if (!fs::exists(p.format(frames[i])))
                throw turb::IoError("chunk " + std::to_string(c.index) + " is not complete: " + p.format(frames[i]) +
                                    " is missing (rerun it: sbatch --array=" + std::to_string(c.index) + " " + dir + "/chunks.sbatch)");
    }
    RunReport report("farm join", a.json);
    const int count = int(frames.size());
    for (size_t k = 0; k < chunks.size(); ++k) {
        const auto& c = chunks[k];
        const turbio::FramePattern p = turbio::FramePattern::parse(chunkPattern(dir, c.index, out));
        // Frames this chunk alone owns; the last O (shared with the next chunk) are blended below.
        const size_t ownEnd = k + 1 < chunks.size() ? chunks[k + 1].keepBegin : c.end;
        const size_t ownBegin = k > 0 ? c.keepBegin + size_t(O) : c.keepBegin;
        for (size_t i = ownBegin; i < ownEnd; ++i) {
            const auto t0 = std::chrono::steady_clock::now();
            const std::string dst = outPattern.format(frames[i]);
            turbio::ensureParentDirectory(dst);
            copyAtomic(p.format(frames[i]), dst);
            report.frameDone(frames[i], int(i), count, secondsSince(t0), "chunk " + std::to_string(c.index) + " -> " + dst,
                {{"chunk", c.index}, {"out", dst}});
        }
        if (k + 1 == chunks.size()) break;
        const turbio::FramePattern pb = turbio::FramePattern::parse(chunkPattern(dir, chunks[k + 1].index, out));
        for (int j = 0; j < O; ++j) {
            const size_t i = chunks[k + 1].keepBegin + size_t(j);
            const int t = frames[i];
            const auto t0 = std::chrono::steady_clock::now();
            turbio::ReadOptions ro;
            ro.cropToSmoke = false; // the chunks' whole (shared) domain
            turb::Frame fa = turbio::readFrame(p.format(t), t, ro);
            turb::Frame fb = turbio::readFrame(pb.format(t), t, ro);
            turbio::ReadOptions tro = a.targetRead;
            tro.cropToSmoke = false;
            const turb::Frame ft = readingAs("target", [&] { return turbio::readFrame(target.path(t), t, tro); });
            const auto r = fb.metadata.find(turb::meta::kRatio);
            if (r == fb.metadata.end()) throw turb::IoError(pb.format(t) + ": no " + std::string(turb::meta::kRatio) + " metadata: not a transfer output");
            const turb::VectorField up = turb::cropped(turb::upsample(ft.velocity, std::stoi(r->second)), fb.velocity.bbox());
            // Chunks written with --velocity-margin hold up(u_t) where no velocity was written: blend what they mean.
            for (turb::Frame* fr : {&fa, &fb})
                if (fr->metadata.count(turb::meta::kVelocityMargin)) turb::fillUnwrittenVelocity(fr->velocity, up);
            const turb::CrossFade w = turb::crossFade(j, O);
            turb::BlendStats st;
            turb::Frame blended = turb::blendOverlap(fa, fb, up, w, threshold, &st);
            char note[160];
            std::snprintf(note, sizeof(note), "%.4f,%.4f,%.4f,%.4f", w.detailA, w.detailB, w.densityA, w.densityB);
            blended.metadata["vdbturb_farm_blend"] = std::string(note);
            const std::string dst = outPattern.format(t);
            turbio::ensureParentDirectory(dst);
            turbio::writeFrame(dst, blended, a.write);
            const double expected = w.detailA * w.detailA * st.energyA + w.detailB * w.detailB * st.energyB;
            char human[200];
            std::snprintf(human, sizeof(human), "blend chunks %d+%d, w_detail %.3f/%.3f x %.3f (correlation %.3f), w_density %.3f/%.3f -> ",
                c.index, chunks[k + 1].index, w.detailA, w.detailB, st.energyScale, st.correlation, w.densityA, w.densityB);
            report.frameDone(t, int(i), count, secondsSince(t0), std::string(human) + dst,
                {{"chunks", {c.index, chunks[k + 1].index}}, {"out", dst}, {"detail_a", w.detailA}, {"detail_b", w.detailB},
                    {"density_a", w.densityA}, {"density_b", w.densityB}, {"correlation", st.correlation},
                    {"energy_scale", st.energyScale}, {"energy_ratio", expected > 0.0 ? st.energyOut / expected : 1.0}});
        }
    }
    report.finish();
    return kOk;
}

} // namespace

Command farmCommand()
{
    auto args = std::make_shared<FarmArgs>();
    Command c;
    c.name = "farm";
    c.help = "Split a transfer into time chunks run as Slurm array tasks, and join them (docs/farm.md)";
    c.globals = kVerbosity | kThreads;
    auto subs = std::make_shared<std::array<CLI::App*, 3>>();
    c.setup = [args, subs](CLI::App* app) {
        FarmArgs& a = *args;
        app->require_subcommand(1);
        app->fallthrough(); // -v, -q, --threads may follow the plan/submit/join word
        CLI::App* plan = app->add_subcommand("plan", "Write sbatch scripts (an array of chunks + a dependent join) and plan.json");
        plan->add_option("--dir", a.dir, "Farm directory: scripts, plan.json, logs, chunk scratch (default farm)");
        plan->add_option("--target", a.target, "Low-res target cache, as for transfer")->required();
        plan->add_option("--source", a.source, "High-res source cache, as for transfer")->required();
        plan->add_option("--out", a.out, "Final output pattern, as for transfer")->required();
        plan->add_option("--frames", a.frames, "Target frames (default: all on disk)")->check(frameListCheck());
        plan->add_option("--chunks", a.chunks, "Number of time chunks (array tasks; default 2)")->check(CLI::Range(1, 100000));
        plan->add_option("--preroll", a.preroll, "P: frames computed before a chunk's first kept frame (default 8)")->check(CLI::Range(0, 10000));
        plan->add_option("--overlap", a.overlap, "O: frames two consecutive chunks share and the join cross-fades (default 10)")
            ->check(CLI::Range(0, 10000));
        plan->add_option("--cpus", a.cpus, "CPUs per task (sbatch --cpus-per-task and transfer --threads; default 2)")->check(CLI::Range(1, 1024));
        plan->add_option("--retries", a.retries, "Times a failed task requeues itself (default 2)")->check(CLI::Range(0, 100));
        plan->add_option("--vdbturb", a.exe, "vdbturb binary the tasks run (default: this one)");
        plan->add_option("--partition", a.partition, "sbatch --partition");
        plan->add_option("--time", a.time, "sbatch --time per task");
        plan->add_option("--mem", a.mem, "sbatch --mem per task");
        plan->add_option("--name", a.name, "Job name prefix (default vdbturb)");
        plan->add_option("transfer_args", a.transferArgs, "After --: further transfer options, given to every chunk");
        CLI::App* submit = app->add_subcommand("submit", "Submit a plan with sbatch: the chunk array, then the join with afterok");
        submit->add_option("--dir", a.dir, "Farm directory written by farm plan (default farm)");
        submit->add_flag("--json", a.json, "Print the job ids as JSON on stdout");
        CLI::App* join = app->add_subcommand("join", "Assemble the chunks' frames into the output, cross-fading the overlaps");
        join->add_option("--dir", a.dir, "Farm directory written by farm plan (default farm)");
        join->add_flag("--json", a.json, "One JSON line per frame and a summary on stdout");
        addReadOptions(join, a.targetRead, "target");
        addWriteOptions(join, a.write);
        join->add_option("--velocity-margin", a.write.velocityMargin,
                "Write the blended frames' velocity only within N voxels of the smoke, as transfer does (default -1: "
                "the whole box; farm plan passes the chunks' value)")
            ->check(CLI::Range(-1, 64));
        (*subs)[0] = plan;
        (*subs)[1] = submit;
        (*subs)[2] = join;
    };
    c.run = [args, subs] {
        if ((*subs)[0]->parsed()) return runPlan(*args);
        if ((*subs)[1]->parsed()) return runSubmit(*args);
        return runJoin(*args);
    };
    return c;
}

} // namespace vdbturb
