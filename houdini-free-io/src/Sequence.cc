#include <turbio/Sequence.h>

#include <turb/Error.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <map>
#include <numeric>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace turbio {

namespace {

struct Token
{
    size_t pos = std::string::npos;
    size_t len = 0;
    int width = 0;
};

// A padding width from its digits; absurd widths (which std::stoi cannot hold) become 1000, refused by parse().
int widthOf(const std::string& digits)
{
    if (digits.empty()) return 0;
    return digits.size() > 4 ? 1000 : std::stoi(digits);
}

// Finds every frame token in `s` (used to reject patterns with two).
std::vector<Token> findTokens(const std::string& s)
{
    std::vector<Token> out;
    for (size_t i = 0; i < s.size();) {
        const char c = s[i];
        if (c == '#' || c == '@') {
            size_t j = i;
            while (j < s.size() && s[j] == c) ++j;
            const int run = int(j - i);
            out.push_back({i, j - i, (c == '@' && run == 1) ? 0 : run});
            i = j;
        } else if (c == '%') {
            // %d, %4d, %04d
            size_t j = i + 1;
            while (j < s.size() && std::isdigit(static_cast<unsigned char>(s[j]))) ++j;
            if (j < s.size() && s[j] == 'd') {
                const std::string digits = s.substr(i + 1, j - i - 1);
                out.push_back({i, j + 1 - i, widthOf(digits)});
                i = j + 1;
            } else {
                ++i;
            }
        } else if (c == '$' && i + 2 < s.size() && s[i + 1] == '{' && s[i + 2] == 'F') {
            // Houdini's braced form ${F} / ${F4}; without the closing brace it is not a token.
            size_t j = i + 3;
            while (j < s.size() && std::isdigit(static_cast<unsigned char>(s[j]))) ++j;
            if (j < s.size() && s[j] == '}') {
                const std::string digits = s.substr(i + 3, j - i - 3);
                out.push_back({i, j + 1 - i, widthOf(digits)});
                i = j + 1;
            } else {
                ++i;
            }
        } else if (c == '$' && i + 1 < s.size() && s[i + 1] == 'F') {
            size_t j = i + 2;
            while (j < s.size() && std::isdigit(static_cast<unsigned char>(s[j]))) ++j;
            const std::string digits = s.substr(i + 2, j - i - 2);
            out.push_back({i, j - i, widthOf(digits)});
            i = j;
        } else {
            ++i;
        }
    }
    return out;
}

std::string trim(const std::string& s)
{
    size_t a = 0, b = s.size();
    while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
    while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
    return s.substr(a, b - a);
}

bool parseInt(const std::string& s, int& out)
{
    if (s.empty()) return false;
    size_t i = (s[0] == '-' || s[0] == '+') ? 1 : 0;
    if (i == s.size()) return false;
    for (size_t k = i; k < s.size(); ++k)
        if (!std::isdigit(static_cast<unsigned char>(s[k]))) return false;
    try {
        out = std::stoi(s);
    } catch (...) {
        return false;
    }
    return true;
}

} // namespace

FramePattern FramePattern::parse(const std::string& text)
{
    FramePattern p;
    const std::vector<Token> tokens = findTokens(text);
    if (tokens.size() > 1) throw turb::ValueError("pattern '" + text + "' has more than one frame token");
    if (tokens.empty()) {
        p.mPrefix = text;
        p.mText = text;
        return p;
    }
    p.mText = text;
    p.mPrefix = text.substr(0, tokens[0].pos);
    p.mSuffix = text.substr(tokens[0].pos + tokens[0].len);
    if (tokens[0].width > 32)
        throw turb::ValueError(
            "pattern '" + text + "': frame padding " + std::to_string(tokens[0].width) + " is wider than 32 digits");
    p.mWidth = tokens[0].width;
    p.mNumbered = true;
    return p;
}

std::optional<std::pair<FramePattern, int>> FramePattern::fromFileName(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    const size_t nameStart = (slash == std::string::npos) ? 0 : slash + 1;
    // The last run of digits in the file name that ends the stem: followed by nothing or by the extension.
    size_t end = std::string::npos;
    for (size_t i = path.size(); i > nameStart; --i) {
        if (std::isdigit(static_cast<unsigned char>(path[i - 1]))) {
            end = i;
            break;
        }
    }
    if (end == std::string::npos) return std::nullopt;
    if (end < path.size() && path[end] != '.') return std::nullopt;
    size_t begin = end;
    while (begin > nameStart && std::isdigit(static_cast<unsigned char>(path[begin - 1]))) --begin;
    const std::string digits = path.substr(begin, end - begin);
    if (digits.size() > 9) return std::nullopt; // not a frame number an int holds
    // A version token ("_v02", ".v3", "-V12" at the end of the stem) is not a frame: pipelines version caches
    // that way, and reading vel_bound_v02.vdb as frame 2 would take frame 1 for a missing frame.
    if (begin > nameStart && (path[begin - 1] == 'v' || path[begin - 1] == 'V') &&
        (begin - 1 == nameStart || !std::isalnum(static_cast<unsigned char>(path[begin - 2]))))
        return std::nullopt;
    // A minus sign: "smoke.-001.vdb" (Houdini's $F4 at frame -1, printf's %04d) is frame -1, the sign counted in the
    // width. A '-' after a letter or digit separates ("smoke-001.vdb" is frame 1, as in Blender's own examples), and
    // so does one before zeros alone: there is no frame -0, and "x.-000.vdb" read as frame 0 would be named
    // "x.0000.vdb" (found by fuzz_frame_pattern).
    const bool negative = begin > nameStart && path[begin - 1] == '-' &&
                          (begin - 1 == nameStart || !std::isalnum(static_cast<unsigned char>(path[begin - 2]))) &&
                          digits.find_first_not_of('0') != std::string::npos;
    FramePattern p;
    p.mPrefix = path.substr(0, negative ? begin - 1 : begin);
    p.mSuffix = path.substr(end);
    // "0001" is padded to 4; "1001" may or may not be padded, and padding 4 formats it the same.
    p.mWidth = int(digits.size()) + (negative ? 1 : 0);
    p.mNumbered = true;
    int frame = 0;
    if (!parseInt(digits, frame)) return std::nullopt;
    return std::make_pair(p, negative ? -frame : frame);
}

FramePattern FramePattern::withWidth(int width) const
{
    FramePattern p = *this;
    p.mWidth = width;
    p.mText.clear();
    return p;
}

std::string FramePattern::format(int frame) const
{
    if (!mNumbered) return mPrefix;
    char buf[48];
    if (frame < 0 && mNegativeDigitsPadded) std::snprintf(buf, sizeof(buf), "-%0*lld", mWidth, -(long long)frame);
    else std::snprintf(buf, sizeof(buf), "%0*d", mWidth, frame); // printf's padding: "-001" for -1 at width 4
    return mPrefix + buf + mSuffix;
}

std::optional<int> FramePattern::match(const std::string& path) const
{
    if (!mNumbered) return path == mPrefix ? std::optional<int>(0) : std::nullopt;
    if (path.size() <= mPrefix.size() + mSuffix.size()) return std::nullopt;
    if (path.compare(0, mPrefix.size(), mPrefix) != 0) return std::nullopt;
    if (path.compare(path.size() - mSuffix.size(), mSuffix.size(), mSuffix) != 0) return std::nullopt;
    const std::string mid = path.substr(mPrefix.size(), path.size() - mPrefix.size() - mSuffix.size());
    int frame = 0;
    if (!parseInt(mid, frame)) return std::nullopt;
    // Padded patterns only match names formatted exactly as format() would write them; a negative frame padded
    // either way ("-001" or "-0001" at width 4).
    if (format(frame) == path) return frame;
    if (frame < 0) {
        FramePattern other = *this;
        other.mNegativeDigitsPadded = !mNegativeDigitsPadded;
        if (other.format(frame) == path) return frame;
    }
    return std::nullopt;
}

std::string FramePattern::str() const
{
    if (!mText.empty()) return mText;
    if (!mNumbered) return mPrefix;
    return mPrefix + std::string(size_t(std::max(mWidth, 1)), mWidth == 0 ? '@' : '#') + mSuffix;
}

std::vector<int> parseFrameList(const std::string& spec)
{
    std::set<int> frames;
    std::stringstream ss(spec);
    std::string piece;
    while (std::getline(ss, piece, ',')) {
        piece = trim(piece);
        if (piece.empty()) continue;
        const auto bad = [&](const std::string& why) {
            return turb::ValueError("frame list '" + spec + "': bad piece '" + piece + "' (" + why + ")");
        };
        int step = 1;
        std::string range = piece;
        const size_t x = piece.find_first_of("xX");
        if (x != std::string::npos) {
            if (!parseInt(piece.substr(x + 1), step) || step <= 0) throw bad("step must be a positive integer");
            range = piece.substr(0, x);
        }
        // A '-' after the first character separates a range; a leading '-' is a sign.
        const size_t dash = range.find('-', 1);
        int a = 0, b = 0;
        if (dash == std::string::npos) {
            if (!parseInt(range, a)) throw bad("not a number");
            b = a;
        } else {
            if (!parseInt(range.substr(0, dash), a) || !parseInt(range.substr(dash + 1), b))
                throw bad("expected FIRST-LAST");
            if (b < a) throw bad("range runs backwards");
        }
        if ((double(b) - double(a)) / step > 1e6) throw bad("more than a million frames");
        for (long long f = a; f <= b; f += step) frames.insert(int(f));
    }
    if (frames.empty()) throw turb::ValueError("frame list '" + spec + "' names no frames");
    return {frames.begin(), frames.end()};
}

std::string formatFrameList(const std::vector<int>& in)
{
    std::vector<int> f(in);
    std::sort(f.begin(), f.end());
    f.erase(std::unique(f.begin(), f.end()), f.end());
    std::ostringstream os;
    size_t i = 0;
    bool first = true;
    while (i < f.size()) {
        // Longest arithmetic run starting at i.
        size_t j = i + 1;
        const long long step = (j < f.size()) ? (long long)f[j] - f[i] : 1;
        while (j < f.size() && (long long)f[j] - f[j - 1] == step) ++j;
        if (!first) os << ',';
        first = false;
        if (j - i >= 3) {
            os << f[i] << '-' << f[j - 1];
            if (step != 1) os << 'x' << step;
            i = j;
        } else {
            os << f[i];
            ++i;
        }
    }
    return os.str();
}

std::vector<int> scanFrames(const FramePattern& pattern)
{
    std::vector<int> frames;
    if (!pattern.numbered()) {
        std::error_code ec;
        if (fs::is_regular_file(pattern.prefix(), ec)) frames.push_back(0);
        return frames;
    }
    const std::string prefix = pattern.prefix();
    const size_t slash = prefix.find_last_of('/');
    const std::string dir = (slash == std::string::npos) ? std::string(".") : prefix.substr(0, slash + 1);
    std::error_code ec;
    fs::directory_iterator it(dir, ec);
    if (ec) return frames;
    for (const auto& entry : it) {
        std::string name = entry.path().filename().string();
        const std::string full = (slash == std::string::npos) ? name : dir + name;
        if (auto f = pattern.match(full)) frames.push_back(*f);
    }
    std::sort(frames.begin(), frames.end());
    return frames;
}

std::vector<std::pair<std::string, int>> sequencesInDirectory(const std::string& dir)
{
    std::map<std::string, int> counts; // pattern -> files
    std::error_code ec;
    fs::directory_iterator it(dir, ec);
    if (ec) return {};
    const std::string base = (dir.empty() || dir.back() == '/') ? dir : dir + "/";
    for (const auto& entry : it) {
        if (!entry.is_regular_file(ec)) continue;
        const std::string name = entry.path().filename().string();
        if (!name.empty() && name[0] == '.') continue; // temporary and hidden files
        if (auto d = FramePattern::fromFileName(base + name)) ++counts[d->first.str()];
        else ++counts[base + name];
    }
    std::vector<std::pair<std::string, int>> out(counts.begin(), counts.end());
    std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
    return out;
}

namespace {

std::string listSequences(const std::vector<std::pair<std::string, int>>& seqs, size_t most)
{
    std::string s;
    for (size_t i = 0; i < seqs.size() && i < most; ++i)
        s += (i ? ", " : "") + seqs[i].first + " (" + std::to_string(seqs[i].second) + " file" +
             (seqs[i].second == 1 ? "" : "s") + ")";
    if (seqs.size() > most) s += ", ...";
    return s;
}

// Why nothing matched `pattern`, and what is there instead: the same name with other frame-number
// widths, or the sequences of its directory.
std::string noMatchMessage(const FramePattern& pattern)
{
    const std::string prefix = pattern.prefix();
    const size_t slash = prefix.find_last_of('/');
    const std::string dir = (slash == std::string::npos) ? std::string(".") : prefix.substr(0, slash + 1);
    const std::string head = pattern.str() + ": no file matches this pattern";
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) return head + " (directory " + dir + " does not exist)";
    const std::string stem = (slash == std::string::npos) ? prefix : prefix.substr(slash + 1);
    std::map<int, int> widths; // digits -> files
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        const std::string name = entry.path().filename().string();
        const std::string& suffix = pattern.suffix();
        if (name.size() <= stem.size() + suffix.size() || name.compare(0, stem.size(), stem) != 0 ||
            name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
            continue;
        const std::string mid = name.substr(stem.size(), name.size() - stem.size() - suffix.size());
        if (std::all_of(mid.begin(), mid.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); }))
            ++widths[int(mid.size())];
    }
    if (!widths.empty()) {
        std::string w;
        for (const auto& [digits, files] : widths) {
            FramePattern p = FramePattern::parse(prefix + std::string(size_t(digits), '#') + pattern.suffix());
            w += (w.empty() ? "" : ", ") + p.str() + " (" + std::to_string(files) + " file" + (files == 1 ? "" : "s") +
                 ", " + std::to_string(digits) + "-digit frame numbers)";
        }
        const std::string want =
            pattern.width() <= 1 ? "unpadded numbers" : std::to_string(pattern.width()) + "-digit numbers";
        return head + ", which asks for " + want + "; these exist: " + w + ". Use as many # (or $F" +
               std::to_string(widths.rbegin()->first) + ") as the files have digits";
    }
    const auto seqs = sequencesInDirectory(dir);
    if (seqs.empty()) return head + " (directory " + dir + " is empty)";
    return head + "; " + dir + " holds " + listSequences(seqs, 4);
}

// Files in the pattern's directory with its name around the frame token that the pattern does not take: frame numbers
// padded otherwise (Houdini's unpadded $F: smoke.999.vdb beside smoke.1000.vdb, which smoke.####.vdb skips) and
// sub-frames (Houdini's $FF: pyro.1001.5.vdb). "" when there are none; else what they are and what reads them.
std::string skippedFilesNote(const FramePattern& pattern)
{
    if (!pattern.numbered()) return "";
    const std::string prefix = pattern.prefix();
    const size_t slash = prefix.find_last_of('/');
    const std::string dir = (slash == std::string::npos) ? std::string(".") : prefix.substr(0, slash + 1);
    const std::string stem = (slash == std::string::npos) ? prefix : prefix.substr(slash + 1);
    const std::string& suffix = pattern.suffix();
    std::map<int, std::vector<std::pair<int, std::string>>> widths; // digits -> (frame, name) of the skipped
    std::vector<std::string> subFrames;
    bool anyLeadingZero = false;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        const std::string name = entry.path().filename().string();
        if (name.size() <= stem.size() + suffix.size() || name.compare(0, stem.size(), stem) != 0 ||
            name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
            continue;
        const std::string mid = name.substr(stem.size(), name.size() - stem.size() - suffix.size());
        const std::string digits = mid[0] == '-' ? mid.substr(1) : mid;
        const size_t dot = digits.find('.');
        const auto allDigits = [](const std::string& t) {
            return !t.empty() &&
                   std::all_of(t.begin(), t.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); });
        };
        if (dot != std::string::npos) {
            if (allDigits(digits.substr(0, dot)) && allDigits(digits.substr(dot + 1))) subFrames.push_back(name);
            continue;
        }
        if (!allDigits(digits) || digits.size() > 9) continue;
        if (digits.size() > 1 && digits[0] == '0') anyLeadingZero = true;
        const std::string full = (slash == std::string::npos) ? name : dir + name;
        if (pattern.match(full)) continue;
        int frame = 0;
        if (!parseInt(mid, frame)) continue;
        widths[int(digits.size())].push_back({frame, name});
    }
    std::string note;
    if (!widths.empty()) {
        size_t count = 0;
        std::vector<int> frames;
        std::string kinds;
        for (auto& [digits, files] : widths) {
            std::sort(files.begin(), files.end());
            count += files.size();
            for (const auto& f : files) frames.push_back(f.first);
            kinds += (kinds.empty() ? "" : ", ") + std::to_string(digits) + "-digit: " + files.front().second +
                     (files.size() > 1 ? " ..." : "");
        }
        note = pattern.str() + " does not take " + std::to_string(count) + " file" + (count == 1 ? "" : "s") +
               " of this name numbered with another padding (" + kinds + "; frame" + (count == 1 ? " " : "s ") +
               formatFrameList(frames) + ")";
        if (!anyLeadingZero)
            note += ": the cache is numbered without padding (Houdini's $F); give " + prefix + "$F" + suffix +
                    " to read every frame";
    }
    if (!subFrames.empty()) {
        std::sort(subFrames.begin(), subFrames.end());
        note += std::string(note.empty() ? pattern.str() + " leaves out " : "; it also leaves out ") +
                std::to_string(subFrames.size()) + " sub-frame file" + (subFrames.size() == 1 ? "" : "s") + " (" +
                subFrames.front() + (subFrames.size() > 1 ? " ..." : "") +
                ": a cache written at sub-frames, Houdini's $FF): vdbturb reads whole frames";
    }
    return note;
}

// A negative frame's file padded "-0001" on disk (vdbturb's own before issue 49) where format() gives "-001": the
// pattern then names negative frames that way.
void adoptNegativePadding(FramePattern& pattern, const std::vector<int>& onDisk)
{
    std::error_code ec;
    for (int f : onDisk) {
        if (f >= 0) break;
        if (fs::exists(pattern.format(f), ec)) return;
        FramePattern other = pattern;
        other.setNegativeDigitsPadded(true);
        if (fs::exists(other.format(f), ec)) {
            pattern = other;
            return;
        }
    }
}

// "pyro.1001.5.vdb" beside "pyro.1001.vdb": sub-frame 1001.5 of a cache written at sub-frames (Houdini's $FF), which
// the frame-number rule would read as frame 5. Returns "1001.5" and the whole frame's name, or nothing.
std::optional<std::pair<std::string, std::string>> subFrameOf(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    const size_t nameStart = (slash == std::string::npos) ? 0 : slash + 1;
    const auto detected = FramePattern::fromFileName(path);
    if (!detected) return std::nullopt;
    const std::string& prefix = detected->first.prefix(); // ".../pyro.1001."
    if (prefix.size() < nameStart + 3 || prefix.back() != '.') return std::nullopt;
    size_t b = prefix.size() - 1;
    while (b > nameStart && std::isdigit(static_cast<unsigned char>(prefix[b - 1]))) --b;
    if (b == prefix.size() - 1) return std::nullopt; // no digits before the '.'
    const std::string whole = prefix.substr(b, prefix.size() - 1 - b);
    const std::string wholePath = prefix.substr(0, prefix.size() - 1) + detected->first.suffix();
    std::error_code ec;
    if (!fs::is_regular_file(wholePath, ec)) return std::nullopt;
    const std::string fraction =
        path.substr(prefix.size(), path.size() - prefix.size() - detected->first.suffix().size());
    return std::make_pair(whole + "." + fraction, wholePath);
}

// A text that names no existing file: say what its directory holds instead.
[[noreturn]] void throwNoSuchFile(const std::string& text)
{
    std::error_code ec;
    const size_t slash = text.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : text.substr(0, slash + 1);
    std::string why = text + ": no such file";
    if (!fs::is_directory(dir, ec)) why += " (directory " + dir + " does not exist)";
    else if (const auto seqs = sequencesInDirectory(dir); !seqs.empty())
        why += "; " + dir + " holds " + listSequences(seqs, 4);
    throw turb::IoError(why);
}

// An existing file with a frame number: refuses a sub-frame file, and prefers the unpadded pattern where it takes
// more frames.
void checkNumberedFile(const std::string& text, std::optional<std::pair<FramePattern, int>>& detected)
{
    if (const auto sub = subFrameOf(text)) {
        const auto whole = FramePattern::fromFileName(sub->second);
        throw turb::IoError(text + ": sub-frame " + sub->first + " of a cache written at sub-frames (Houdini's " +
                            "$FF; " + sub->second + " is its frame " + sub->first.substr(0, sub->first.find('.')) +
                            "): vdbturb reads whole frames. Give " + (whole ? whole->first.str() : sub->second) +
                            ", which leaves the sub-frame files out");
    }
    // "smoke.1000.vdb" of a cache numbered without padding ($F: smoke.999.vdb beside it): the unpadded
    // pattern takes every frame, where "####" would skip 998 and 999.
    const std::string digits = std::to_string(std::abs(detected->second));
    if (detected->second >= 0 && int(digits.size()) == detected->first.width()) {
        const FramePattern unpadded = detected->first.withWidth(0);
        if (scanFrames(unpadded).size() > scanFrames(detected->first).size()) detected->first = unpadded;
    }
}

// One real file name: a member of a numbered sequence (siblings found by scanning), a lone frame
// (pyro.1001.vdb is frame 1001, as in Houdini and Blender), or a file without a frame number. Returns the
// sequence when the name settles it; otherwise sets `pattern` to the detected one (frames from frameSpec).
std::optional<Sequence> resolveFileName(const std::string& text, const std::string& frameSpec, FramePattern& pattern)
{
    Sequence seq;
    std::error_code ec;
    const bool exists = fs::is_regular_file(text, ec);
    auto detected = FramePattern::fromFileName(text);
    if (detected && exists) checkNumberedFile(text, detected);
    if (detected && (exists || !frameSpec.empty())) {
        pattern = detected->first;
        if (frameSpec.empty()) { // a file name means that file; its siblings are only mentioned
            const std::vector<int> siblings = scanFrames(pattern);
            adoptNegativePadding(pattern, siblings);
            seq.pattern = pattern;
            seq.frames = {detected->second};
            if (siblings.size() > 1)
                seq.oneOfSequence = text + " is frame " + std::to_string(detected->second) + " of " + pattern.str() +
                                    " (frames " + formatFrameList(siblings) +
                                    " on disk): give that pattern, or --frames, for more than this file";
            return seq;
        }
    } else if (exists) {
        seq.pattern = pattern;
        seq.frames = {0};
        return seq;
    } else if (fs::exists(text, ec)) {
        throw turb::IoError(text + ": not a regular file");
    } else {
        throwNoSuchFile(text);
    }
    return std::nullopt;
}

// Gaps inside the range on disk are missing frames. A sequence cached on every n-th frame (all gaps multiples of
// n) only misses multiples of n.
std::vector<int> missingFrames(const std::vector<int>& onDisk)
{
    std::vector<int> missing;
    long long step = 0;
    for (size_t i = 1; i < onDisk.size(); ++i) step = std::gcd(step, (long long)onDisk[i] - onDisk[i - 1]);
    if (step <= 0) step = 1;
    // A few files far apart would list millions of missing frames: only gaps the size of a shot count.
    if ((double(onDisk.back()) - onDisk.front()) / double(step) <= 1e6)
        for (long long f = onDisk.front(); f <= onDisk.back(); f += step)
            if (!std::binary_search(onDisk.begin(), onDisk.end(), int(f))) missing.push_back(int(f));
    return missing;
}

} // namespace

Sequence resolveSequence(const std::string& text, const std::string& frameSpec)
{
    Sequence seq;
    std::error_code ec;
    if (fs::is_directory(text, ec)) {
        const auto seqs = sequencesInDirectory(text);
        throw turb::IoError(
            text + ": is a directory, not a cache: give a file pattern" +
            (seqs.empty() ? std::string(" (the directory is empty)") : "; it holds " + listSequences(seqs, 4)));
    }
    FramePattern pattern = FramePattern::parse(text);
    if (!pattern.numbered())
        if (std::optional<Sequence> one = resolveFileName(text, frameSpec, pattern)) return std::move(*one);
    const std::vector<int> onDisk = scanFrames(pattern);
    adoptNegativePadding(pattern, onDisk);
    seq.pattern = pattern;
    seq.skippedFiles = skippedFilesNote(pattern);
    if (frameSpec.empty()) {
        if (onDisk.empty()) throw turb::IoError(noMatchMessage(pattern));
        seq.frames = onDisk;
        seq.missing = missingFrames(onDisk);
        return seq;
    }
    for (int f : parseFrameList(frameSpec)) {
        if (std::binary_search(onDisk.begin(), onDisk.end(), f)) seq.frames.push_back(f);
        else seq.missing.push_back(f);
    }
    if (seq.frames.empty() && onDisk.empty()) throw turb::IoError(noMatchMessage(pattern));
    return seq;
}

int mapSourceFrame(int targetFrame, const std::vector<int>& sourceFrames, int offset, SourceWrap wrap)
{
    if (sourceFrames.empty()) throw turb::ValueError("the source sequence has no frames");
    // 64-bit arithmetic: frame numbers and offsets near the int limits must not overflow.
    const long long first = sourceFrames.front(), last = sourceFrames.back();
    const long long len = last - first + 1;
    long long s = (long long)targetFrame + offset;
    if (s < first || s > last) {
        switch (wrap) {
        case SourceWrap::Loop: s = first + ((s - first) % len + len) % len; break;
        case SourceWrap::PingPong: {
            const long long period = std::max(1LL, 2 * (len - 1));
            long long k = ((s - first) % period + period) % period;
            if (k >= len) k = period - k;
            s = first + k;
            break;
        }
        case SourceWrap::Clamp: s = std::min(std::max(s, first), last); break;
        case SourceWrap::Error:
            throw turb::ValueError("target frame " + std::to_string(targetFrame) + " needs source frame " +
                                   std::to_string(s) + ", outside the source's frames " + std::to_string(first) + "-" +
                                   std::to_string(last) + " (the wrap mode is error)");
        }
    }
    if (!std::binary_search(sourceFrames.begin(), sourceFrames.end(), int(s)))
        throw turb::ValueError("source frame " + std::to_string(s) + " (for target frame " +
                               std::to_string(targetFrame) + ") is missing from the source sequence");
    return int(s);
}

void ensureParentDirectory(const std::string& path)
{
    const fs::path parent = fs::path(path).parent_path();
    if (parent.empty()) return;
    std::error_code ec;
    fs::create_directories(parent, ec);
    if (ec) throw turb::IoError(parent.string() + ": cannot create directory (" + ec.message() + ")");
}

} // namespace turbio
