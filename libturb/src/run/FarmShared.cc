// What farm plan, submit and join share (FarmShared.h).
#include "FarmShared.h"

#include <turb/Error.h>
#include <turbio/Vdb.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace turb::run::farm {

namespace fs = std::filesystem;

std::string shellQuote(const std::string& s)
{
    if (!s.empty() &&
        s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=/.,:@%#") ==
            std::string::npos)
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

std::string readText(const std::string& path)
{
    std::ifstream in(path);
    if (!in) throw turb::IoError(path + ": cannot read");
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

void writeText(const std::string& path, const std::string& text, bool executable)
{
    turbio::writeFileAtomic(path, text);
    if (executable)
        fs::permissions(
            path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec, fs::perm_options::add);
}

std::string chunkPattern(const std::string& dir, int k, const std::string& out, const char* word)
{
    char sub[32];
    std::snprintf(sub, sizeof(sub), "%ss/%03d/", word, k);
    fs::path name = fs::path(out).filename();
    if (turbio::outputFormatFor(name.string()) == turbio::OutputFormat::NanoVdb) name.replace_extension(".vdb");
    return (fs::path(dir) / sub / name).string();
}

bool isFormatOption(const std::string& arg)
{
    const std::string name = arg.substr(0, arg.find('='));
    return name == "--format" || name == "--nanovdb-quant";
}

} // namespace turb::run::farm
