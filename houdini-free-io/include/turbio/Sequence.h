/// @file Sequence.h
/// @brief Frame-sequence names: patterns (####, @, %04d, $F4, ${F4}), frame lists (1001-1100x2,1200),
///        auto-detection from one real file name, and scanning a directory for the frames present.
///
/// @code
/// auto seq = turbio::FramePattern::parse("cache/pyro.$F4.vdb");
/// seq.format(1001);                          // "cache/pyro.1001.vdb"
/// auto frames = turbio::parseFrameList("1001-1010x3,1200"); // {1001,1004,1007,1010,1200}
/// @endcode
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace turbio {

/// A file-name pattern with at most one frame-number token.
class FramePattern
{
public:
    /// Parses a pattern. Recognised tokens: runs of '#' (width = run length), '@' (one '@' means
    /// unpadded, a run of n means width n), printf '%d' / '%0Nd', Houdini '$F' / '$FN' / '${F}' /
    /// '${FN}'. A name with no token is a single file (numbered() is false). Throws turb::ValueError on
    /// two tokens.
    static FramePattern parse(const std::string& text);

    /// The frame number of a real file name, as Houdini, Blender and renderers read it: the run of digits
    /// that ends the name's stem (followed only by the extension, e.g. ".vdb" or ".bgeo.sc"):
    /// "fluid_data_0001.vdb" -> "fluid_data_####.vdb", frame 1. nullopt if the stem does not end in digits
    /// ("smoke.vdb", "smoke2_final.vdb"). Digits in the directory never count.
    static std::optional<std::pair<FramePattern, int>> fromFileName(const std::string& path);

    /// The file name of frame `frame`. For an unnumbered pattern, the pattern itself. A negative frame is padded as
    /// printf's "%04d" pads it, and as Houdini's $F4, Nuke and 3ds Max name it: the sign counts in the width ("-001"
    /// for -1 at width 4), unless setNegativeDigitsPadded(true) was called (a sequence named "-0001" on disk).
    std::string format(int frame) const;
    /// The frame number encoded by `path`, when it matches this pattern. A negative frame matches padded either way
    /// ("-001" and "-0001" at width 4).
    std::optional<int> match(const std::string& path) const;
    /// Whether negative frames pad their digits to the width, the sign in front ("-0001" at width 4; vdbturb wrote
    /// them so before issue 49), instead of counting the sign in the width ("-001").
    void setNegativeDigitsPadded(bool padded) { mNegativeDigitsPadded = padded; }
    /// The same pattern with another padding width (0: unpadded); str() then shows it with '#' (or '@').
    FramePattern withWidth(int width) const;

    bool numbered() const { return mNumbered; }
    int width() const { return mWidth; }
    /// The pattern as the user wrote it (e.g. "pyro.$F.vdb"), or with '#' padding when it was detected
    /// from a file name; for messages.
    std::string str() const;
    const std::string& prefix() const { return mPrefix; }
    const std::string& suffix() const { return mSuffix; }

private:
    std::string mPrefix, mSuffix;
    std::string mText; // as given to parse(); empty when detected from a file name
    int mWidth = 0;    // zero-padding width; 0 or 1 = unpadded
    bool mNumbered = false;
    bool mNegativeDigitsPadded = false; // "-0001" rather than "-001" at width 4
};

/// Parses "1001-1100x2,1200,1300-1302": ranges with an optional step, comma-separated. Sorted,
/// duplicates removed. Throws turb::ValueError naming the bad piece.
std::vector<int> parseFrameList(const std::string& spec);

/// Formats frames compactly ("1-10,12,14-20x2") for messages and reports.
std::string formatFrameList(const std::vector<int>& frames);

/// The frames of `pattern` that exist on disk, sorted. Lists the pattern's directory once.
std::vector<int> scanFrames(const FramePattern& pattern);

/// A sequence resolved against the disk: what the user asked for, what exists, what is missing.
struct Sequence
{
    FramePattern pattern;
    std::vector<int> frames;  ///< requested frames that exist
    std::vector<int> missing; ///< requested frames that do not exist
    /// Set when one real file of a longer sequence was named without a frame list: "fluid_data_0010.vdb is frame 10
    /// of fluid_data_####.vdb (frames 1-30 on disk): give that pattern or --frames for more". Commands say it once.
    std::string oneOfSequence;
    /// Set when files of the pattern's name exist that it does not take: frame numbers written with another padding
    /// (Houdini's unpadded $F has smoke.999.vdb beside smoke.1000.vdb, which smoke.####.vdb skips) or sub-frames
    /// (Houdini's $FF: pyro.1001.5.vdb). Says which, and the pattern that reads them. Commands warn once.
    std::string skippedFiles;

    std::string path(int frame) const { return pattern.format(frame); }
};

/// Resolves user input to a sequence. `text` may be a pattern or one real file name. A file name means that
/// file, as in oiiotool, vdb_print and Houdini's File SOP: its frame is the digits that end its stem
/// (pyro.1001.vdb is frame 1001; smoke.vdb frame 0), and siblings on disk only fill `oneOfSequence`. With
/// `frameSpec` (parseFrameList syntax) a file name stands for the numbered sequence it belongs to, and the list
/// restricts or extends the request; a pattern with an empty `frameSpec` means "every frame on disk". Throws
/// turb::IoError when no file matches at all; the message says what is there instead (other paddings of the same name,
/// the sequences in a directory given as the cache).
Sequence resolveSequence(const std::string& text, const std::string& frameSpec = "");

/// The frame sequences in directory `dir`, as patterns with '#' padding and their frame counts, most
/// frames first (for messages such as "a directory is not a cache: it holds fluid_data_####.vdb").
std::vector<std::pair<std::string, int>> sequencesInDirectory(const std::string& dir);

/// How a target frame picks its source frame when the sequences differ in length.
enum class SourceWrap {
    Loop,     ///< run through the source again from its first frame
    PingPong, ///< run back and forth through the source
    Clamp,    ///< hold the first/last source frame
    Error     ///< a target frame without its source frame is an error
};

/// The source frame for target frame `targetFrame`: the same number plus `offset`, wrapped into
/// [first, last] of `sourceFrames` (sorted) as `wrap` says. Throws turb::ValueError when the frame is
/// missing inside the range (a gap) or out of range with SourceWrap::Error.
int mapSourceFrame(int targetFrame, const std::vector<int>& sourceFrames, int offset, SourceWrap wrap);

/// Creates the directory that will hold `path` (and its parents). Throws turb::IoError on failure.
void ensureParentDirectory(const std::string& path);

} // namespace turbio
