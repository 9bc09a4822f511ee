#include <turb/run/Preflight.h>

#include "RunHelpers.h"

#include <turb/run/Flags.h>
#include <turb/run/Reporter.h>

#include <turb/Error.h>
#include <turb/Metadata.h>
#include <turb/Transfer.h>
#include <turbio/ImageIO.h>
#include <turbio/System.h>

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <set>
#include <sstream>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace turb::run {

using detail::fmt;

namespace {

bool dryOrVerbose() { return reporter().showsPlan(); }

} // namespace

turbio::SequenceScan checkInput(const std::string& command, const std::string& role, const turbio::Sequence& seq,
    const std::vector<int>& frames, const turbio::ReadOptions& read, LatticePolicy policy,
    const std::string& readPrefix)
{
    if (!seq.oneOfSequence.empty()) logInfo(role + ": " + seq.oneOfSequence);
    if (!seq.skippedFiles.empty()) warnOnce("skipped " + role, role + ": " + seq.skippedFiles);
    turbio::SequenceScan scan = turbio::scanSequence(seq, frames, read, /*readVoxelsIfNeeded=*/true);
    if (const turbio::FrameScan* failed = scan.firstFailure()) {
        turb::IoError error(failed->error, failed->errorSettings);
        error.qualifySettings(readPrefix);
        throw error;
    }
    if (!scan.blenderAdaptive.empty())
        throw turb::IoError(role + " " + seq.pattern.str() + ": " + scan.blenderAdaptive);
    if (!scan.changes.empty()) {
        const std::string what =
            role + " " + seq.pattern.str() + ": the lattice is not the same in every frame: " + scan.describeChanges();
        if (policy == LatticePolicy::Refuse)
            throw turb::IoError(
                what + ". " + command +
                " carries state from frame to frame on one lattice, so it refuses such a sequence before "
                "writing anything: run the frames of each lattice separately (--frames), or bring the cache "
                "onto one lattice first (e.g. Houdini's VDB Resample)");
        warnOnce("lattice " + role, what + "; each frame is read on its own lattice");
    }
    return scan;
}

TimingSources timingSources(const turbio::ReadReport& t, const std::string& readPrefix)
{
    const auto given = [&](const std::string& source, const std::string& setting) {
        return setting.empty() ? source : flagFor(setting, readPrefix);
    };
    TimingSources s;
    s.dt = given(t.dtSource, t.dtSetting);
    s.fps = given(t.fpsSource, t.fpsSetting);
    // "ReadOptions::velocityUnits frame" -> "--vel-units frame".
    s.units = t.unitsSetting.empty()
                  ? t.unitsSource
                  : flagFor(t.unitsSetting, readPrefix) + t.unitsSource.substr(t.unitsSource.rfind(' '));
    return s;
}

std::vector<std::string> timingLines(const std::string& role, const turbio::FrameScan& f, const std::string& readPrefix)
{
    const turbio::ReadReport& t = f.timing;
    const TimingSources source = timingSources(t, readPrefix);
    std::vector<std::string> lines;
    std::string dt = role + " dt: " + fmt("%.6g", t.dt) + " per frame (" + source.dt + ")";
    if (t.fpsSource != "not used") dt += ", fps " + fmt("%g", t.fps) + " (" + source.fps + ")";
    lines.push_back(dt);
    if (!f.velocityGrid.empty())
        lines.push_back(
            role + " velocity: grid '" + f.velocityGrid + "', " +
            (t.cells ? "grid cells per time unit x voxel " + fmt("%g", f.lattice.voxelSize) + " = world units"
                     : std::string("world units")) +
            " (" + source.units + ")");
    for (const auto& n : t.notes) lines.push_back(role + ": " + n);
    return lines;
}

void reportTiming(const std::string& role, const turbio::SequenceScan& scan, bool usesDt, const std::string& readPrefix)
{
    if (scan.frames.empty()) return;
    const turbio::FrameScan& f = scan.frames.front();
    if (dryOrVerbose())
        for (const auto& line : timingLines(role, f, readPrefix)) printData(line);
    else
        for (const auto& n : f.timing.notes) warnOnce("note " + role + n, role + ": " + n);
    if (usesDt && f.timing.conventionAssumed)
        warnOnce("fps " + role,
            role + " " + f.path + ": the cache records no frame rate; dt " + fmt("%.6g", f.timing.dt) +
                " assumes 24 fps" +
                (f.timing.dtSource.find("Blender") != std::string::npos ? " and Blender's time scale 1" : "") +
                ". Give " + flagFor("fps", readPrefix) + " or " + flagFor("dt", readPrefix) + " if the shot differs");
}

void checkOutputs(
    const std::vector<std::string>& outputs, const std::vector<std::string>& inputs, bool noClobber, bool skipExisting)
{
    std::vector<fs::path> in;
    for (const auto& p : inputs) {
        std::error_code ec;
        if (fs::exists(p, ec)) in.push_back(fs::canonical(p, ec));
    }
    std::string checkedDir;
    for (const auto& out : outputs) {
        std::error_code ec;
        const fs::path path(out);
        if (fs::exists(path, ec)) {
            if (fs::is_directory(path, ec))
                throw turb::IoError(out + ": is a directory; the output must be a file name");
            const fs::path c = fs::canonical(path, ec);
            for (const auto& i : in)
                if (c == i) throw turb::IoError(out + ": is an input of this run; give another --out");
            if (noClobber && !skipExisting) throw turb::IoError(out + ": exists, not replaced (--no-clobber)");
        }
        // The first existing ancestor must be a writable directory (the rest is created).
        fs::path dir = path.parent_path();
        if (dir.empty()) dir = ".";
        if (dir.string() == checkedDir) continue;
        checkedDir = dir.string();
        fs::path probe = dir;
        while (!fs::exists(probe, ec) && probe.has_parent_path() && probe != probe.parent_path())
            probe = probe.parent_path();
        if (!fs::exists(probe, ec)) continue;
        if (!fs::is_directory(probe, ec))
            throw turb::IoError(
                out + ": cannot create its directory: " + probe.string() + " is a file, not a directory");
        if (::access(probe.c_str(), W_OK | X_OK) != 0)
            throw turb::IoError(out + ": cannot write into " + probe.string() + " (" + std::strerror(errno) + ")");
        // access() says yes to root on file systems that refuse new files (/sys, /proc, read-only mounts): create
        // and remove a probe file, so the run stops here and not after its first frame.
        const fs::path test = probe / (".vdbturb_probe_" + std::to_string(::getpid()));
        const int fd = ::open(test.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
        if (fd < 0)
            throw turb::IoError(out + ": cannot write into " + probe.string() + " (" + std::strerror(errno) + ")");
        ::close(fd);
        ::unlink(test.c_str());
    }
}

void checkMemory(double estimateBytes, const std::string& what, const std::string& whatFits)
{
    const turbio::MemoryLimit limit = turbio::memoryLimit();
    reporter().memoryEstimate(estimateBytes); // for an out-of-memory failure's message
    const std::string line = "memory: about " + turbio::formatBytes(estimateBytes) + " at peak (" + what + ")" +
                             (limit.bytes > 0 ? "; this process may use " + limit.describe() : "");
    if (dryOrVerbose()) printData(line);
    if (limit.bytes > 0 && estimateBytes > 0.9 * double(limit.bytes)) {
        const std::string message = "not enough memory for this run: it needs about " +
                                    turbio::formatBytes(estimateBytes) + " (" + what + "), this process may use " +
                                    limit.describe();
        // Held back by a job's limit or by other processes, on a machine that has the memory: a retry elsewhere
        // (or later) can run it (exit 75). More than the machine has: only other settings can (exit 1).
        if (estimateBytes < 0.9 * double(turbio::machineMemoryBytes()))
            throw turb::TransientError(message + "; it fits this machine's memory where more is free. " + whatFits);
        throw turb::IoError(message + ". " + whatFits);
    }
}

bool writtenWithSettings(const std::string& path, const std::string& command, const std::string& settings)
{
    std::error_code ec;
    if (!fs::exists(path, ec)) return false;
    std::string madeBy, madeWith;
    std::string ext = fs::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".vdb") {
        const turbio::FileInfo info = turbio::inspectFile(path, false);
        madeBy = info.command;
        madeWith = info.settings;
    } else {
        const turbio::ImageFileInfo info = turbio::inspectImage(path);
        madeBy = info.attribute(turb::meta::kCommand);
        madeWith = info.attribute(turb::meta::kSettings);
    }
    std::vector<std::string> diff;
    if (madeBy != command)
        diff.push_back("written by " + (madeBy.empty() ? std::string("another program") : "vdbturb " + madeBy) +
                       ", not vdbturb " + command);
    else if (madeWith.empty()) diff.push_back("no vdbturb_settings metadata (written by an older vdbturb)");
    else diff = turb::settingsDifferences(madeWith, settings);
    if (diff.empty()) return true;
    std::string list;
    for (const std::string& d : diff) list += "\n  " + d;
    throw turb::ValueError(path + " exists and was made otherwise; --skip-existing skips only frames of the same run:" +
                           list + "\n  (remove it, or run without --skip-existing to replace it)");
}

SkipPlan planSkips(const std::vector<std::string>& outputs, const std::vector<int>& frames, const std::string& command,
    const std::string& settings, bool skipExisting)
{
    return planSkips(outputs, frames, command, std::vector<std::string>(outputs.size(), settings), skipExisting);
}

SkipPlan planSkips(const std::vector<std::string>& outputs, const std::vector<int>& frames, const std::string& command,
    const std::vector<std::string>& settings, bool skipExisting)
{
    SkipPlan plan;
    plan.skip.assign(outputs.size(), false);
    for (size_t i = 0; i < outputs.size(); ++i) {
        if (skipExisting) plan.skip[i] = writtenWithSettings(outputs[i], command, settings[i]);
        if (!plan.skip[i]) {
            plan.writing.push_back(frames[i]);
            plan.end = i + 1;
        }
    }
    return plan;
}

std::vector<std::string> sequentialSettings(const std::string& settings, const std::vector<int>& frames)
{
    std::vector<std::string> out;
    for (size_t i = 0; i < frames.size(); ++i)
        out.push_back(settings + "shot_frames=" +
                      turbio::formatFrameList(std::vector<int>(frames.begin(), frames.begin() + long(i) + 1)) + ";");
    return out;
}

void printSkipPlan(const SkipPlan& plan, const std::vector<std::string>& outputs)
{
    for (size_t i = 0; i < outputs.size(); ++i)
        printData((plan.skipped(i) ? "would skip " : "would write ") + outputs[i] +
                  (plan.skipped(i) ? " (written by the same settings)" : ""));
}

std::vector<std::pair<std::string, std::string>> frameMetadata(const std::string& command, const std::string& settings)
{
    return {{turb::meta::kCommand, command}, {turb::meta::kSettings, settings}};
}

namespace {

// The lock files this process holds frames in, removed when it ends normally (a kill leaves them: the next run
// takes them over, and removes them when it is the last holder).
struct HeldLocks
{
    std::vector<std::pair<int, std::string>> files; // descriptor, path
    ~HeldLocks() { release(); }
    void release()
    {
        for (const auto& [fd, path] : files) {
            // Only the last holder removes it: a lock on the whole file is granted when no other process holds a
            // frame (this process's own locks never conflict with it).
            struct flock all
            {};
            all.l_type = F_WRLCK;
            all.l_whence = SEEK_SET;
            if (::fcntl(fd, F_SETLK, &all) == 0) ::unlink(path.c_str());
            ::close(fd);
        }
        files.clear();
    }
};

HeldLocks& heldLocks()
{
    static HeldLocks h;
    return h;
}

} // namespace

void lockOutputFrames(const turbio::FramePattern& pattern, const std::vector<int>& frames)
{
    if (frames.empty()) return;
    const fs::path first(pattern.format(frames.front()));
    const fs::path lockPath = first.parent_path() / ("." + fs::path(pattern.str()).filename().string() + ".lock");
    std::error_code ec;
    if (!first.parent_path().empty()) fs::create_directories(first.parent_path(), ec);
    for (int attempt = 0; attempt < 8; ++attempt) {
        const int fd = ::open(lockPath.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        if (fd < 0) return; // no lock without a writable folder; the frame's own write reports that
        for (const int f : frames) {
            struct flock l
            {};
            l.l_type = F_WRLCK;
            l.l_whence = SEEK_SET;
            l.l_start = off_t(int64_t(f) + (int64_t(1) << 31)); // negative frame numbers too
            l.l_len = 1;
            if (::fcntl(fd, F_SETLK, &l) == 0) continue;
            const int err = errno;
            struct flock who = l;
            const bool known = ::fcntl(fd, F_GETLK, &who) == 0 && who.l_type != F_UNLCK;
            ::close(fd);                                // drops the frames locked so far
            if (err != EACCES && err != EAGAIN) return; // a file system without locks: go on unguarded
            throw turb::TransientError(pattern.format(f) + ": another vdbturb" +
                                       (known ? " (pid " + std::to_string(who.l_pid) + ")" : std::string()) +
                                       " is writing this frame (lock " + lockPath.string() +
                                       "); two tasks never write one frame: retry when it is done");
        }
        // The last holder of another run may have removed the file between the open and the locks: lock the file
        // the name now gives, or another process could hold the same frames in a new one.
        struct stat byName
        {
        }, byFd{};
        if (::stat(lockPath.c_str(), &byName) == 0 && ::fstat(fd, &byFd) == 0 && byName.st_ino == byFd.st_ino &&
            byName.st_dev == byFd.st_dev) {
            heldLocks().files.emplace_back(fd, lockPath.string());
            return;
        }
        ::close(fd);
    }
}

void releaseOutputLocks() { heldLocks().release(); }

int upAxisOf(const std::string& path, const std::string& requested, std::string& why)
{
    why.clear();
    if (requested != "auto") return requested == "y" ? 1 : 2;
    const turbio::FileInfo fi = turbio::inspectFile(path, false);
    if (!fi.upAxis.empty()) {
        why = "vdbturb_up_axis metadata";
        return fi.upAxis == "y" ? 1 : 2;
    }
    if (fi.creator.find("Houdini") != std::string::npos) {
        why = "written by Houdini ('" + fi.creator + "')";
        return 1;
    }
    return 2;
}

} // namespace turb::run
