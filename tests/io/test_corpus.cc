// The bad-input corpus (tests/corpus/Cases.h) through every command that reads caches. Per case and command:
// the exit code; a message naming the file (and the grid, where the case says so); no output file, or only
// whole frames before the bad one; no signal death; no hang (a 120 s timeout). Results go to
// corpus/results.tsv in the build tree (docs/reliability.md's table is made from it).
#include "CliUtil.h"
#include "corpus/Cases.h"

#include <turbio/NanoVdb.h>
#include <turbio/Vdb.h>

#include <fstream>
#include <mutex>
#include <regex>
#include <sstream>
#include <sys/stat.h>

using namespace corpus;

namespace {

const std::string kRoot = CORPUS_DIR;

// The corpus is written by ctest's fixture (corpus_generate); a direct run writes it once itself.
class CorpusEnvironment : public ::testing::Environment
{
public:
    void SetUp() override
    {
        if (std::filesystem::exists(kRoot + "/done")) return;
        const auto r = clitest::shell(std::string(MAKE_CORPUS_EXE) + " " + kRoot + " 2>&1");
        ASSERT_EQ(r.code, 0) << r.out;
    }
};
const auto* const kEnv = ::testing::AddGlobalTestEnvironment(new CorpusEnvironment);

std::string pattern(const std::string& dir, char seq, unsigned flags)
{
    if (seq == 't' && (flags & kDirectory)) return dir + "/tdir";
    return dir + "/" + seq + (seq == 't' && (flags & kPadding3) ? ".###.vdb" : ".####.vdb");
}

std::string commandLine(const Case& c, int cmd, const std::string& dir, const std::string& out)
{
    const std::string T = "'" + pattern(dir, 't', c.flags) + "'", S = "'" + pattern(dir, 's', c.flags) + "'";
    const std::string subject = c.subject == Subject::Target ? T : S;
    std::string o = out;
    if (c.flags & kOutIsInput) o = "";
    const auto outArg = [&](const char* name) { return o.empty() ? subject : "'" + o + "/" + name + "'"; };
    switch (cmd) {
    case kInfo: return "info " + subject + " --validate";
    case kTransfer:
        return "transfer --target " + T + " --source " + S + " --out " + (o.empty() ? T : outArg("o.####.vdb"));
    case kSynth: return "synth --target " + subject + " --factor 1 --exemplar swirls:8 --out " + outArg("y.####.vdb");
    case kMeasure: return "measure --output " + S + " --target " + T + " --no-spectra";
    case kResample: return "resample " + subject + " --out " + outArg("r.####.vdb");
    case kPreview: return "preview " + subject + " --width 48 --out " + outArg("p.####.png");
    case kConvert: return "convert " + subject + " --out " + outArg("c.####.nvdb");
    }
    return "";
}

bool says(const std::string& text, const std::string& spec)
{
    // "a;b": all of; each part "x|y": any of.
    std::stringstream all(spec);
    std::string part;
    while (std::getline(all, part, ';')) {
        if (part.empty()) continue;
        bool any = false;
        std::stringstream alts(part);
        std::string alt;
        while (std::getline(alts, alt, '|')) any = any || text.find(alt) != std::string::npos;
        if (!any) return false;
    }
    return true;
}

// Every file a run left must be whole (a VDB that reads, a PNG with its end chunk) and, after a failure,
// belong to a frame before the bad one. Returns what is wrong, "" if nothing.
std::string checkOutputs(const std::string& out, int code, int badFrame)
{
    if (!std::filesystem::exists(out)) return "";
    std::string problems;
    for (const auto& e : std::filesystem::directory_iterator(out)) {
        const std::string name = e.path().filename().string();
        if (name[0] == '.' && !(name.size() > 5 && name.compare(name.size() - 5, 5, ".lock") == 0 && code != 0)) {
            problems += " temporary file " + name + " left;";
            continue;
        }
        const std::regex numbered(R"(\w\.(\d{4})\.(vdb|png|nvdb))");
        // transfer's exact resume state beside frames written in half floats or trimmed (its default): whole too.
        const std::regex state(R"(\w\.resume-state-(-?\d+-)?(odd|even)\.vdb)");
        std::smatch m;
        if (std::regex_match(name, state)) {
            try {
                turbio::ReadOptions any;
                any.requireDensity = any.requireVelocity = false;
                any.cropToSmoke = false;
                turbio::readFrame(e.path().string(), 1, any);
            } catch (const std::exception& x) {
                problems += std::string(" ") + name + " is not whole (" + x.what() + ");";
            }
            continue;
        }
        if (!std::regex_match(name, m, numbered)) {
            problems += " unexpected file " + name + ";";
            continue;
        }
        const int frame = std::stoi(m[1]);
        if (code != 0 && badFrame > 0 && frame >= badFrame)
            problems += " frame " + name + " written after the failure;";
        if (m[2] == "vdb") {
            try {
                turbio::ReadOptions any;
                any.requireDensity = any.requireVelocity = false;
                turbio::readFrame(e.path().string(), frame, any);
            } catch (const std::exception& x) {
                problems += std::string(" ") + name + " is not whole (" + x.what() + ");";
            }
        } else if (m[2] == "nvdb") {
            try {
                turbio::inspectNanoFile(e.path().string());
            } catch (const std::exception& x) {
                problems += std::string(" ") + name + " is not whole (" + x.what() + ");";
            }
        } else {
            const std::string b = clitest::slurp(e.path().string());
            if (b.size() < 20 || b.compare(1, 3, "PNG") != 0 || b.find("IEND") == std::string::npos)
                problems += " " + name + " is not a whole PNG;";
        }
    }
    return problems;
}

std::mutex gResultsMutex;

void record(const Case& c, int cmd, const clitest::Result& r)
{
    std::string first;
    std::stringstream lines(r.out);
    std::string line;
    while (std::getline(lines, line))
        if (line.find("error:") != std::string::npos) {
            first = line.substr(line.find("error:") + 7);
            break;
        }
    for (char& ch : first)
        if (ch == '\t') ch = ' ';
    // Paths inside the corpus are written relative to the case directory.
    const std::string prefix = kRoot + "/" + c.name + "/";
    for (size_t at; (at = first.find(prefix)) != std::string::npos;) first.erase(at, prefix.size());
    std::lock_guard<std::mutex> lock(gResultsMutex);
    std::ofstream(kRoot + "/results/" + c.name + "." + commandName(cmd) + ".tsv")
        << c.name << '\t' << commandName(cmd) << '\t' << r.code << '\t' << first << '\t' << c.what << '\n';
}

class Corpus : public ::testing::TestWithParam<size_t>
{};

} // namespace

TEST_P(Corpus, EveryCommandFailsCleanlyOrSucceeds)
{
    const Case& c = cases()[GetParam()];
    const std::string dir = kRoot + "/" + c.name;
    std::filesystem::create_directories(kRoot + "/results");
    const bool nobody = (c.flags & kAsNobody) && ::geteuid() == 0;
    const std::string bad = c.badFrame > 0
                                ? std::string(1, c.subject == Subject::Target ? 't' : 's') + "." +
                                      std::string(c.badFrame < 10 ? "000" : "00") + std::to_string(c.badFrame) + ".vdb"
                                : std::string();
    for (int cmd = 0; cmd < kCommands; ++cmd) {
        std::string out = dir + "/out_" + commandName(cmd);
        std::filesystem::remove_all(out);
        if (c.flags & kOutReadOnly) out = dir + "/ro";
        else if (c.flags & kOutUnderFile) out = dir + "/afile";
        else {
            std::filesystem::create_directories(out);
            ::chmod(out.c_str(), 0777); // an unprivileged run writes here
        }
        const std::string line = commandLine(c, cmd, dir, out);
        const std::string run = std::string("VDBTURB_READ_TIMEOUT_S=2 timeout 120 ") +
                                (nobody ? "setpriv --reuid=65534 --regid=65534 --clear-groups " : "") + VDBTURB_EXE +
                                " " + line + " 2>&1";
        const clitest::Result r = clitest::shell(run);
        record(c, cmd, r);
        SCOPED_TRACE(std::string(commandName(cmd)) + ": vdbturb " + line + "\n" + r.out.substr(0, 2000));
        EXPECT_NE(r.code, 124) << "hang: stopped by the 120 s timeout";
        EXPECT_EQ(r.signal, 0) << "died of signal " << r.signal;
        const int want = c.expect[cmd];
        if (want == kEither) EXPECT_TRUE(r.code == 0 || r.code == 1) << "exit " << r.code;
        else EXPECT_EQ(r.code, want);
        if (r.code != 0) {
            EXPECT_NE(r.out.find("vdbturb: error: "), std::string::npos) << "a one-line error";
            EXPECT_NE(r.out.find(dir), std::string::npos) << "the message names a file of the case";
            if (!bad.empty() && c.flags == kNone)
                EXPECT_NE(r.out.find(bad), std::string::npos) << "the message names " << bad;
            if (want != kEither) EXPECT_TRUE(says(r.out, c.says)) << "the message says: " << c.says;
        }
        if (!(c.flags & (kOutReadOnly | kOutUnderFile | kOutIsInput))) {
            const std::string problems = checkOutputs(out, r.code, c.badFrame);
            EXPECT_TRUE(problems.empty()) << problems;
        }
    }
}

INSTANTIATE_TEST_SUITE_P(Cases, Corpus, ::testing::Range<size_t>(0, cases().size()),
    [](const ::testing::TestParamInfo<size_t>& info) { return std::string(cases()[info.param].name); });
