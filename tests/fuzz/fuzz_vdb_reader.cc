// libFuzzer target: the VDB frame reader through the guarded path every command uses (turbio::readFrame and
// turbio::inspectFile: header checks in this process, OpenVDB in a forked child, the trusted stream back).
// Any turb::Error is a clean refusal; anything else escaping, a crash or a hang of this process is a finding.
#include <turb/Error.h>
#include <turbio/Vdb.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <unistd.h>

namespace {

std::string scratchPath()
{
    // One file per process, in memory when /dev/shm exists; rewritten for every input.
    const char* dir = std::getenv("VDBTURB_FUZZ_DIR");
    return std::string(dir ? dir : "/dev/shm") + "/vdbturb_fuzz_" + std::to_string(::getpid()) + ".vdb";
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    // Damage that makes OpenVDB loop is ended by the guard; keep that short so the fuzzer keeps moving.
    ::setenv("VDBTURB_READ_TIMEOUT_S", "1", 0);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    static const std::string path = scratchPath();
    {
        std::FILE* f = std::fopen(path.c_str(), "wb");
        if (!f) return 0;
        std::fwrite(data, 1, size, f);
        std::fclose(f);
    }
    turbio::ReadOptions any;
    any.requireDensity = false;
    any.requireVelocity = false;
    any.extendVelocity = 2;
    try {
        turbio::inspectFile(path, /*readValues=*/true);
    } catch (const turb::Error&) {}
    try {
        turbio::readFrame(path, 1, any);
    } catch (const turb::Error&) {}
    return 0;
}
