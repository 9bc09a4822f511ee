// libFuzzer target: frame patterns and frame lists. Parsing must refuse with turb::ValueError or give a
// pattern whose format() and match() invert each other, and a frame list that formats and re-parses to itself.
#include <turb/Error.h>
#include <turbio/Sequence.h>

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const turbio::FramePattern p = turbio::FramePattern::parse(text);
        (void)p.str();
        if (p.numbered())
            for (int frame : {0, 1, 7, 1001, 123456, -3}) {
                const std::string name = p.format(frame);
                const auto back = p.match(name);
                // A pattern whose literal text contains digits next to the token can read back another number
                // ("a1####" formats 7 as a10007); only the round trip of the digits written is required.
                if (!back) std::abort();
                if (p.format(*back) != name) std::abort();
            }
    } catch (const turb::ValueError&) {}
    if (auto d = turbio::FramePattern::fromFileName(text)) {
        if (d->first.format(d->second) != text) std::abort();
    }
    try {
        const std::vector<int> frames = turbio::parseFrameList(text);
        const std::string again = turbio::formatFrameList(frames);
        if (turbio::parseFrameList(again) != frames) std::abort();
    } catch (const turb::ValueError&) {}
    return 0;
}
