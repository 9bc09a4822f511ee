// Running the vdbturb executable from tests: exit codes, output, and processes to signal.
#pragma once

#include "TestUtil.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace clitest {

struct Result
{
    int code = -1;   ///< exit status, or -1 when killed by a signal
    int signal = 0;  ///< the signal that ended it, 0 if it exited
    std::string out; ///< stdout + stderr (or stdout only with run(..., false))
};

/// Runs shell command `cmd`; its stdout is captured (add 2>&1 for stderr).
inline Result shell(const std::string& cmd)
{
    Result r;
    FILE* p = ::popen(cmd.c_str(), "r");
    if (!p) return r;
    std::array<char, 4096> buf;
    size_t n;
    while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
    const int status = ::pclose(p);
    if (WIFEXITED(status)) r.code = WEXITSTATUS(status);
    // The shell reports a signalled child as 128 + signal.
    if (r.code > 128 && r.code < 160) r.signal = r.code - 128;
    return r;
}

/// `s` as one word for sh: single-quoted, a single quote written as '\''.
inline std::string shellQuote(const std::string& s)
{
    std::string q = "'";
    for (const char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

/// Runs `vdbturb ARGS` through the shell (ARGS is shell text: quote patterns with $). `stderrToo` merges it.
inline Result run(const std::string& args, bool stderrToo = true)
{
    return shell(std::string(VDBTURB_EXE) + " " + args + (stderrToo ? " 2>&1" : " 2>/dev/null"));
}

/// A vdbturb process started in the background (its output goes to `log`), to signal mid-run.
class Process
{
public:
    Process(const std::string& args, const std::string& log, const std::string& env = "")
    {
        mPid = ::fork();
        if (mPid == 0) {
            ::setpgid(0, 0);
            const std::string cmd = env + " exec " + std::string(VDBTURB_EXE) + " " + args + " >" + log + " 2>&1";
            ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
            ::_exit(127);
        }
    }
    ~Process()
    {
        if (mPid > 0 && !mDone) {
            ::kill(mPid, SIGKILL);
            wait();
        }
    }
    /// Waits until `path` exists or `seconds` pass; false on timeout or if the process ended first.
    bool waitForFile(const std::string& path, double seconds)
    {
        const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
        while (std::chrono::steady_clock::now() < end) {
            if (std::filesystem::exists(path)) return true;
            int status = 0;
            if (::waitpid(mPid, &status, WNOHANG) == mPid) {
                mDone = true;
                mStatus = status;
                return std::filesystem::exists(path);
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return false;
    }
    void signal(int sig) { ::kill(mPid, sig); }
    /// Waits for the end; returns the raw wait status.
    int wait()
    {
        if (!mDone) {
            while (::waitpid(mPid, &mStatus, 0) < 0 && errno == EINTR) {}
            mDone = true;
        }
        return mStatus;
    }

private:
    pid_t mPid = -1;
    bool mDone = false;
    int mStatus = 0;
};

inline std::string slurp(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline bool has(const std::string& text, const std::string& piece) { return text.find(piece) != std::string::npos; }

/// OpenVDB writes a fresh random UUID into every file's header (36 characters from byte 21): two VDB files hold the
/// same grids and metadata, bit for bit, when every other byte agrees.
inline bool sameVdbButUuid(const std::string& a, const std::string& b)
{
    std::string x = slurp(a), y = slurp(b);
    if (x.size() != y.size() || x.size() < 57) return false;
    x.replace(21, 36, 36, ' ');
    y.replace(21, 36, 36, ' ');
    return x == y;
}

/// The names in `dir`, sorted (hidden ones too: temporary files, the frame lock).
inline std::vector<std::string> listing(const std::string& dir)
{
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

/// `info --checksum` of every frame of `pattern`: its "frame N" lines and each grid's checksum line (name, type, active
/// voxels, values' and metadata's checksums), without the paths; "" when info fails (a frame that does not read).
inline std::string gridChecksums(const std::string& pattern)
{
    const Result r = shell(std::string(VDBTURB_EXE) + " info --checksum " + shellQuote(pattern) + " 2>/dev/null");
    if (r.code != 0) return "";
    std::string sums;
    std::istringstream lines(r.out);
    const std::regex frame(R"(^(frame -?\d+):.*)"), grid(R"(^  \S+ +\S+ +\d+ +[0-9a-f]{16} +[0-9a-f]{16}$)");
    std::smatch m;
    for (std::string line; std::getline(lines, line);) {
        if (std::regex_match(line, m, frame)) sums += m[1].str() + "\n";
        else if (std::regex_match(line, grid)) sums += line + "\n";
    }
    return sums;
}

/// The shared Blender plume pair (../shared/data): `res` 32 or 128; frame < 0 gives the fluid_data_####.vdb pattern.
inline std::string plume(int res, int frame = -1)
{
    char name[48];
    if (frame < 0) std::snprintf(name, sizeof(name), "blender-plume-%d/fluid_data_####.vdb", res);
    else std::snprintf(name, sizeof(name), "blender-plume-%d/fluid_data_%04d.vdb", res, frame);
    return testutil::dataPath(name);
}

/// The shared plume pair's target (32^3) and source (128^3): the pattern, or frame `frame`'s file.
inline std::string plumeLo(int frame = -1) { return plume(32, frame); }
inline std::string plumeHi(int frame = -1) { return plume(128, frame); }

/// `vdbturb ARGS` with stdout only (JSON lines, a dry run's plan).
inline Result runStdout(const std::string& args) { return run(args, false); }

inline size_t count(const std::string& text, const std::string& what)
{
    size_t n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
}

} // namespace clitest
