#include "GuardedRead.h"

#include <turb/Error.h>

#include <openvdb/io/Stream.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <poll.h>
#include <sstream>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

namespace turbio::detail {

namespace {

bool writeAll(int fd, const char* p, size_t n)
{
    while (n > 0) {
        const ssize_t w = ::write(fd, p, n);
        if (w < 0) {
            if (errno == EINTR) continue;
            return false;
        }
        p += w;
        n -= size_t(w);
    }
    return true;
}

// Virtual memory of this process in bytes, for the child's address-space limit.
size_t currentVirtualBytes()
{
    std::ifstream in("/proc/self/statm");
    size_t pages = 0;
    in >> pages;
    return pages * size_t(::sysconf(_SC_PAGESIZE));
}

// A failure crosses the pipe as 'E', the settings it names (turb::Error::settings, comma-separated: field
// names hold neither commas nor newlines), a newline and the message.
std::string errorPayload(const std::string& message, const std::vector<std::string>& settings = {})
{
    std::string names;
    for (const auto& s : settings) names += (names.empty() ? "" : ",") + s;
    return "E" + names + "\n" + message;
}

[[noreturn]] void throwPayload(const std::string& data)
{
    const size_t nl = data.find('\n');
    if (nl == std::string::npos) throw turb::IoError(data.substr(1));
    std::vector<std::string> settings;
    for (size_t at = 1; at < nl;) {
        const size_t comma = std::min(data.find(',', at), nl);
        settings.push_back(data.substr(at, comma - at));
        at = comma + 1;
    }
    throw turb::IoError(data.substr(nl + 1), settings);
}

extern "C" __attribute__((weak)) void __sanitizer_set_death_callback(void (*)(void));

[[noreturn]] void childMain(int fd, const std::string& path, const ReadBody& body)
{
    // The child must die of its own crash, reported by the parent as a damaged file: a crash handler inherited
    // from the parent (vdbturb's, a fuzzer's, a sanitizer's death callback) would report it as the parent's.
    for (int sig : {SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL}) std::signal(sig, SIG_DFL);
    if (__sanitizer_set_death_callback) __sanitizer_set_death_callback(nullptr);
    // glibc's heap-corruption reports would land in the user's log; the parent reports instead.
    const int devnull = ::open("/dev/null", O_WRONLY);
    if (devnull >= 0) ::dup2(devnull, STDERR_FILENO);
    // A damaged size field can ask for absurd allocations: make them fail with bad_alloc in the
    // child instead of waking the OOM killer.
    const size_t limit = currentVirtualBytes() + (size_t(16) << 30);
    struct rlimit rl
    {
        limit, limit
    };
    ::setrlimit(RLIMIT_AS, &rl);
    std::string payload;
    try {
        openvdb::io::File file(path);
        try {
            file.open(/*delayLoad=*/false);
        } catch (const std::exception& e) {
            throw turb::IoError(path + ": truncated or corrupt file (" + cleanMessage(e.what()) + ")");
        }
        openvdb::GridPtrVec grids;
        openvdb::MetaMap meta;
        body(file, grids, meta);
        file.close();
        std::ostringstream os(std::ios::binary);
        openvdb::io::Stream stream(os);
        stream.setCompression(openvdb::io::COMPRESS_ACTIVE_MASK); // lossless; 2D leaves are 7/8 inactive
        stream.setGridStatsMetadataEnabled(false);                // stats use TBB; not in a forked child
        stream.write(grids, meta);
        payload = "G" + os.str();
    } catch (const turb::Error& e) {
        payload = errorPayload(e.what(), e.settings());
    } catch (const std::bad_alloc&) {
        payload = errorPayload(path + ": corrupt file (a size field asks for more memory than exists)");
    } catch (const std::exception& e) {
        payload = errorPayload(path + ": truncated or corrupt file (" + cleanMessage(e.what()) + ")");
    } catch (...) {
        payload = errorPayload("unknown error");
    }
    const bool ok = writeAll(fd, payload.data(), payload.size());
    ::close(fd);
    ::_exit(ok ? 0 : 3);
}

} // namespace

std::string cleanMessage(const std::string& m)
{
    std::string out;
    for (char c : m) {
        if (out.size() >= 200) {
            out += "...";
            break;
        }
        const char p = (c >= 32 && c < 127) ? c : '?';
        if ((p == ' ' || p == '?') && !out.empty() && out.back() == p) continue; // squeeze runs
        out += p;
    }
    return out;
}

namespace {

// One forked reader. On a timeout sets `timedOut` and returns nothing; every other failure throws.
GuardedResult readInChild(const std::string& path, const ReadBody& body, double timeoutSeconds, bool& timedOut)
{
    timedOut = false;
    int fds[2];
    if (::pipe(fds) != 0) throw turb::IoError(path + ": cannot create pipe (" + std::strerror(errno) + ")");
    const pid_t pid = ::fork();
    if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw turb::IoError(path + ": cannot fork reader (" + std::strerror(errno) + ")");
    }
    if (pid == 0) {
        ::close(fds[0]);
        childMain(fds[1], path, body);
    }
    ::close(fds[1]);

    std::string data;
    char buf[1 << 16];
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeoutSeconds);
    for (;;) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
        if (left <= 0) {
            timedOut = true;
            break;
        }
        struct pollfd pfd
        {
            fds[0], POLLIN, 0
        };
        const int pr = ::poll(&pfd, 1, int(std::min<long long>(left, 1000)));
        if (pr < 0 && errno != EINTR) break;
        if (pr <= 0) continue;
        const ssize_t n = ::read(fds[0], buf, sizeof(buf));
        if (n < 0) {
            if (errno == EINTR) continue;
            break;
        }
        if (n == 0) break; // EOF: the child is done
        data.append(buf, size_t(n));
    }
    ::close(fds[0]);
    if (timedOut) ::kill(pid, SIGKILL);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {}

    if (timedOut) return {};
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        throw turb::IoError(path + ": corrupt file: OpenVDB's reader crashed on it (" + ::strsignal(sig) +
                            "); the file is damaged or not a complete VDB");
    }
    if (data.empty() || (WIFEXITED(status) && WEXITSTATUS(status) != 0 && data[0] != 'E'))
        throw turb::IoError(path + ": corrupt file: the reader stopped without a result");
    if (data[0] == 'E') throwPayload(data);

    GuardedResult result;
    try {
        std::istringstream is(data.substr(1), std::ios::binary);
        openvdb::io::Stream stream(is, /*delayLoad=*/false);
        if (auto g = stream.getGrids()) result.grids = *g;
        result.meta = stream.getMetadata();
    } catch (const std::exception& e) {
        throw turb::IoError(path + ": internal error passing grids from the reader (" + std::string(e.what()) + ")");
    }
    if (!result.meta) result.meta = std::make_shared<openvdb::MetaMap>();
    return result;
}

} // namespace

GuardedResult guardedRead(const std::string& path, const ReadBody& body, double timeoutSeconds)
{
    bool timedOut = false;
    GuardedResult r = readInChild(path, body, timeoutSeconds, timedOut);
    if (!timedOut) return r;
    // The child is a fork of a threaded process: it can inherit a lock that a pool thread held at that instant
    // (the pool winding down after parallel work) and wait on it forever. That is a race; a damaged file that
    // makes OpenVDB loop loops every time. A second reader tells the two apart.
    r = readInChild(path, body, timeoutSeconds, timedOut);
    if (!timedOut) return r;
    std::ostringstream os;
    os << path << ": corrupt file: OpenVDB's reader did not finish within " << int(timeoutSeconds + 0.5)
       << " s (twice)";
    throw turb::IoError(os.str());
}

} // namespace turbio::detail
