#include "GuardedRead.h"

#include <turbio/NanoVdb.h>
#include <turbio/System.h>

#include <turb/Error.h>

#include <openvdb/io/Stream.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <mutex>
#include <poll.h>
#include <sstream>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

namespace turbio::detail {

void keepInChild(const openvdb::GridBase::Ptr& grid)
{
    // Never destroyed: filled in a child only, which leaves by _exit.
    static auto* kept = new std::vector<openvdb::GridBase::Ptr>();
    if (grid) kept->push_back(grid);
}

std::mutex& forkGuard()
{
    static std::mutex m;
    return m;
}

namespace {

// Ends a 'G' payload, so the parent knows it arrived whole without waiting for the child's exit status.
const std::string kTrailer = "\nvdbturb: end of grids\n";

bool wholePayload(const std::string& data)
{
    return data.size() > kTrailer.size() && data[0] == 'G' &&
           data.compare(data.size() - kTrailer.size(), kTrailer.size(), kTrailer) == 0;
}

// The child's stream of grids. Not io::Stream: OpenVDB 10's Archive::writeGrid builds delayed-load metadata with a
// LeafManager, whose tbb::parallel_for in a forked child can wait for ever on pool threads the fork did not copy (a
// 10 s stall, then a second reader, on about 1 run in 12 of a 30-frame 2D transfer; gdb showed the child in
// LeafManager::initLeafArray under Archive::writeGrid). The grids' own serial writers are used instead, framed as
// Archive frames them: file metadata, a count, then per grid its type, half-float flag, metadata, transform,
// topology and buffers, with the per-grid stream state Archive sets (mask compression only: lossless).
constexpr uint32_t kPayloadCompression = openvdb::io::COMPRESS_ACTIVE_MASK;

void prepareStream(std::ios_base& strm)
{
    const openvdb::VersionId library(openvdb::OPENVDB_LIBRARY_MAJOR_VERSION, openvdb::OPENVDB_LIBRARY_MINOR_VERSION);
    openvdb::io::setVersion(strm, library, openvdb::OPENVDB_FILE_VERSION);
    openvdb::io::setDataCompression(strm, kPayloadCompression);
}

void writeGrids(std::ostream& os, const openvdb::GridPtrVec& grids, const openvdb::MetaMap& meta)
{
    prepareStream(os);
    meta.writeMeta(os);
    const int32_t count = int32_t(std::count_if(grids.begin(), grids.end(), [](const auto& g) { return bool(g); }));
    os.write(reinterpret_cast<const char*>(&count), sizeof(count));
    for (const openvdb::GridBase::Ptr& grid : grids) {
        if (!grid) continue;
        openvdb::writeString(os, grid->type());
        const uint8_t half = grid->saveFloatAsHalf() ? 1 : 0;
        os.write(reinterpret_cast<const char*>(&half), 1);
        auto sm = std::make_shared<openvdb::io::StreamMetadata>();
        sm->setHalfFloat(half != 0);
        sm->gridMetadata() = static_cast<const openvdb::MetaMap&>(*grid);
        openvdb::io::setStreamMetadataPtr(os, sm, /*transfer=*/false);
        openvdb::io::setDataCompression(os, kPayloadCompression);
        openvdb::io::setGridClass(os, grid->getGridClass());
        grid->writeMeta(os);
        grid->writeTransform(os);
        grid->writeTopology(os);
        grid->writeBuffers(os);
        openvdb::io::StreamMetadata::Ptr none; // the grid's state ends with it
        openvdb::io::setStreamMetadataPtr(os, none, false);
    }
}

// The parent's side of writeGrids (a trusted stream; throws what OpenVDB throws if it is cut short).
GuardedResult readGrids(std::istream& is)
{
    prepareStream(is);
    GuardedResult result;
    result.meta = std::make_shared<openvdb::MetaMap>();
    result.meta->readMeta(is);
    int32_t count = 0;
    is.read(reinterpret_cast<char*>(&count), sizeof(count));
    if (!is || count < 0) throw std::runtime_error("grid count missing");
    for (int32_t n = 0; n < count; ++n) {
        const std::string type = openvdb::readString(is);
        uint8_t half = 0;
        is.read(reinterpret_cast<char*>(&half), 1);
        if (!is) throw std::runtime_error("grid header cut short");
        openvdb::GridBase::Ptr grid = openvdb::GridBase::createGrid(type);
        auto sm = std::make_shared<openvdb::io::StreamMetadata>();
        sm->setHalfFloat(half != 0);
        openvdb::io::setStreamMetadataPtr(is, sm, /*transfer=*/false);
        openvdb::io::setDataCompression(is, kPayloadCompression);
        grid->readMeta(is);
        sm->gridMetadata() = static_cast<openvdb::MetaMap&>(*grid);
        openvdb::io::setGridClass(is, grid->getGridClass());
        grid->readTransform(is);
        grid->readTopology(is);
        grid->readBuffers(is);
        grid->setSaveFloatAsHalf(half != 0);
        openvdb::io::StreamMetadata::Ptr none;
        openvdb::io::setStreamMetadataPtr(is, none, false);
        if (!is) throw std::runtime_error("grid '" + grid->getName() + "' cut short");
        result.grids.push_back(grid);
    }
    return result;
}

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

// An OpenVDB file, as io::File reads it.
class VdbSource : public GridSource
{
public:
    explicit VdbSource(const std::string& path) : mFile(path)
    {
        try {
            mFile.open(/*delayLoad=*/false);
        } catch (const std::exception& e) {
            throw turb::IoError(path + ": truncated or corrupt file (" + cleanMessage(e.what()) + ")");
        }
    }
    ~VdbSource() override { mFile.close(); }
    std::vector<std::string> names() override
    {
        std::vector<std::string> out;
        for (auto it = mFile.beginName(); it != mFile.endName(); ++it) out.push_back(*it);
        return out;
    }
    openvdb::GridBase::Ptr readGridMetadata(const std::string& unique) override
    {
        return mFile.readGridMetadata(unique);
    }
    openvdb::GridBase::Ptr readGrid(const std::string& unique) override { return mFile.readGrid(unique); }
    openvdb::GridPtrVec readAll() override
    {
        const openvdb::GridPtrVecPtr all = mFile.getGrids();
        return all ? *all : openvdb::GridPtrVec();
    }
    openvdb::MetaMap::Ptr getMetadata() override { return mFile.getMetadata(); }
    uint32_t fileVersion() const override { return mFile.fileVersion(); }
    std::pair<int, int> libraryVersion() const override
    {
        const auto v = mFile.libraryVersion();
        return {int(v.first), int(v.second)};
    }

private:
    openvdb::io::File mFile;
};

extern "C" __attribute__((weak)) void __sanitizer_set_death_callback(void (*)(void));

[[noreturn]] void childMain(int fd, const std::string& path, const ReadBody& body, bool nano)
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
        // Never destroyed here (keepInChild): the source holds what it read, the NanoVDB buffers too.
        GridSource& file = *(nano ? openNanoSource(path) : std::make_unique<VdbSource>(path)).release();
        openvdb::GridPtrVec& grids = *new openvdb::GridPtrVec();
        openvdb::MetaMap meta;
        body(file, grids, meta);
        std::ostringstream os(std::ios::binary);
        writeGrids(os, grids, meta);
        payload = "G" + os.str() + kTrailer;
    } catch (const turb::Error& e) {
        payload = errorPayload(e.what(), e.settings());
    } catch (const std::bad_alloc&) {
        // Either a damaged size field or a tree genuinely too large to hold (a 761 MB file of active tiles over
        // 2^35 voxels was called corrupt): say both, with the file's size to tell them apart.
        struct stat st
        {};
        const std::string size = ::stat(path.c_str(), &st) == 0 ? formatBytes(double(st.st_size)) : std::string("?");
        payload = errorPayload(path +
                               ": reading it asked for more than 16 GB of memory: a damaged size field, or "
                               "grids too large to hold (the file is " +
                               size + ")");
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

// Children whose result arrived whole and parsed are not waited for: their exit (tearing down a copy of this
// process's address space) takes milliseconds the caller need not spend. They are reaped without blocking at the
// next read. A result that does not parse waits for the child's status, which names the crash.
std::mutex gUnreapedMutex;
std::vector<pid_t> gUnreaped;

void reapExited()
{
    const std::lock_guard<std::mutex> lock(gUnreapedMutex);
    gUnreaped.erase(std::remove_if(gUnreaped.begin(), gUnreaped.end(),
                        [](pid_t pid) {
                            int status = 0;
                            pid_t r;
                            while ((r = ::waitpid(pid, &status, WNOHANG)) < 0 && errno == EINTR) {}
                            return r != 0; // exited (reaped now) or no longer ours (ECHILD)
                        }),
        gUnreaped.end());
}

// The grids of a child's 'G' payload; throws what OpenVDB throws on a damaged stream.
GuardedResult parsePayload(const std::string& data)
{
    const std::lock_guard<std::mutex> parsing(forkGuard());
    std::istringstream is(data.substr(1, data.size() - 1 - kTrailer.size()), std::ios::binary);
    return readGrids(is);
}

// Forks the reader child, which runs childMain on `path` and writes its result to the pipe; returns its pid and the
// pipe's read end in `readFd`.
pid_t forkReader(const std::string& path, const ReadBody& body, bool nano, int& readFd)
{
    int fds[2];
    if (::pipe(fds) != 0) throw turb::IoError(path + ": cannot create pipe (" + std::strerror(errno) + ")");
    std::unique_lock<std::mutex> forking(forkGuard());
    const pid_t pid = ::fork();
    forking.unlock(); // (in the child too: its copy is never used again)
    if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw turb::IoError(path + ": cannot fork reader (" + std::strerror(errno) + ")");
    }
    if (pid == 0) {
        ::close(fds[0]);
        childMain(fds[1], path, body, nano);
    }
    ::close(fds[1]);
    readFd = fds[0];
    return pid;
}

// Everything the child writes to `fd` until it closes the pipe, or until the deadline (then `timedOut`); closes fd.
std::string readPipe(int fd, double timeoutSeconds, bool& timedOut)
{
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
            fd, POLLIN, 0
        };
        const int pr = ::poll(&pfd, 1, int(std::min<long long>(left, 1000)));
        if (pr < 0 && errno != EINTR) break;
        if (pr <= 0) continue;
        const ssize_t n = ::read(fd, buf, sizeof(buf));
        if (n < 0) {
            if (errno == EINTR) continue;
            break;
        }
        if (n == 0) break; // EOF: the child is done
        data.append(buf, size_t(n));
    }
    ::close(fd);
    return data;
}

// The grids of a whole 'G' payload from child `pid`, which is left to exit on its own and reaped later.
GuardedResult takeWholePayload(const std::string& path, pid_t pid, const std::string& data)
{
    GuardedResult whole;
    try {
        whole = parsePayload(data);
    } catch (const std::exception& e) {
        ::kill(pid, SIGKILL); // it wrote everything; nothing of it is needed now
        while (::waitpid(pid, nullptr, 0) < 0 && errno == EINTR) {}
        throw turb::IoError(path + ": internal error passing grids from the reader (" + std::string(e.what()) + ")");
    }
    {
        const std::lock_guard<std::mutex> lock(gUnreapedMutex);
        gUnreaped.push_back(pid);
    }
    reapExited();
    // The last children are waited for when the process exits: a farm agent that adopts orphans and never
    // reaps them would otherwise collect zombies. Registered after the list's construction, so it runs first.
    static std::once_flag atExit;
    std::call_once(atExit, [] {
        std::atexit([] {
            const std::lock_guard<std::mutex> lock(gUnreapedMutex);
            for (pid_t child : gUnreaped)
                while (::waitpid(child, nullptr, 0) < 0 && errno == EINTR) {}
            gUnreaped.clear();
        });
    });
    return whole;
}

// A child that exited (with `status`) without a whole payload: its crash, its error payload, or no result.
[[noreturn]] void throwChildFailure(const std::string& path, int status, const std::string& data, bool nano)
{
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        throw turb::IoError(path + ": corrupt file: " + (nano ? "NanoVDB" : "OpenVDB") + "'s reader crashed on it (" +
                            ::strsignal(sig) + "); the file is damaged or not a complete " +
                            (nano ? "NanoVDB file" : "VDB"));
    }
    if (data.empty() || (WIFEXITED(status) && WEXITSTATUS(status) != 0 && data[0] != 'E'))
        throw turb::IoError(path + ": corrupt file: the reader stopped without a result");
    if (data[0] == 'E') throwPayload(data);

    // Exited cleanly, yet the grids did not arrive whole.
    throw turb::IoError(path + ": corrupt file: the reader stopped without a result");
}

// One forked reader. On a timeout sets `timedOut` and returns nothing; every other failure throws.
GuardedResult readInChild(
    const std::string& path, const ReadBody& body, bool nano, double timeoutSeconds, bool& timedOut)
{
    timedOut = false;
    int readFd = -1;
    const pid_t pid = forkReader(path, body, nano, readFd);
    const std::string data = readPipe(readFd, timeoutSeconds, timedOut);
    if (!timedOut && wholePayload(data)) return takeWholePayload(path, pid, data);
    if (timedOut) ::kill(pid, SIGKILL);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {}

    if (timedOut) return {};
    throwChildFailure(path, status, data, nano);
}

} // namespace

GuardedResult guardedRead(const std::string& path, const ReadBody& body, double timeoutSeconds)
{
    bool timedOut = false;
    const bool nano = isNanoVdbFile(path);
    GuardedResult r = readInChild(path, body, nano, timeoutSeconds, timedOut);
    if (!timedOut) return r;
    // The child is a fork of a threaded process: it can inherit a lock that a pool thread held at that instant
    // (the pool winding down after parallel work) and wait on it forever. That is a race; a damaged file that
    // makes OpenVDB loop loops every time. A second reader tells the two apart.
    r = readInChild(path, body, nano, timeoutSeconds, timedOut);
    if (!timedOut) return r;
    std::ostringstream os;
    os << path << ": corrupt file: " << (nano ? "NanoVDB" : "OpenVDB") << "'s reader did not finish within "
       << int(timeoutSeconds + 0.5) << " s (twice)";
    throw turb::IoError(os.str());
}

} // namespace turbio::detail
