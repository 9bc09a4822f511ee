/// @file HistogramMatch.h
/// @brief Heeger-Bergen histogram matching of animation frames to the target still (Okabe et al. 2009,
///        section 5.6, after Heeger and Bergen 1995), on a grid of overlapping cells, with a Laplacian
///        single-pass preview mode (section 6).
///
/// Per frame and per colour channel, in the target's colour PCA space (Heeger and Bergen's colour; with
/// independent RGB channels, near-grey images get colour fringes), then the final pixel passes in RGB so
/// that each channel's statistics are the target's:
///   match the pixel histogram; repeat `reps` times { build the steerable pyramid (SteerablePyramid.h),
///   match every sub-band's histogram (high-pass, oriented bands, low-pass residual) to the target's same
///   sub-band, collapse, match the pixel histogram }.
/// The preview mode (`pyramid = Laplacian`) runs the loop once on a Laplacian pyramid (the paper's
/// preview: "we adopt the Laplacian pyramid ... apply histogram matching once").
///
/// **Grid** (5.6). The image is split into cols x rows cells; every cell's statistics are taken over the
/// cell (grown by `reach` x its size on each side, 0 by default). Each value's match is the blend of its
/// cells' matches with weights that are 1 in a cell's core and ramp linearly across zones reaching
/// `overlap` x the cell size into each neighbour (a partition of unity): the paper's alpha-blended
/// overlaps, in every sub-band (the cells scaled by 2^-level) and in the pixel domain. Blending leaves a
/// cell's statistics a few per cent off where neighbours differ; the pixel-domain match is therefore run
/// `pixelPasses` times at the end, which brings most cells within about 1% of the target's, and then
/// (`cellMoments`, beyond the paper) one gain and offset per cell, blended alike, are solved so every cell's
/// mean and std are exact (measured, docs/animate.md). Unblended pixel matches (`blendPixels` = false) are
/// exact per cell but show seams at cell borders where cells differ strongly (a smoke edge next to background).
/// The default grid is proportional to the resolution, cells of about `cellSize` pixels (the paper's
/// Table 1 uses cells of 35..120 px, mostly about 60).
///
/// A histogram match maps each value through the source's cumulative histogram (`bins` bins over the
/// cell's range, linear within a bin) to the target's quantile table (`quantiles` entries, linear between).
///
/// @code
/// turb::HistogramMatchSettings s;          // steerable, 3 repetitions, grid of ~64 px cells
/// turb::HistogramMatcher hm(target, s);    // the target's pyramids and quantiles, once
/// turb::ChannelImage out = hm.match(frame); // thread-safe; frames may be matched concurrently
/// @endcode
#pragma once

#include <turb/ChannelImage.h>

#include <memory>
#include <utility>
#include <vector>

namespace turb {

enum class HmPyramid {
    Steerable, ///< Heeger-Bergen on the steerable pyramid, `reps` times (the paper's final render)
    Laplacian  ///< one pass on a Laplacian pyramid (the paper's fast preview)
};

struct HistogramMatchSettings
{
    int reps = 3;          ///< HM Rep: repetitions of the pyramid loop (paper 3), 1..10; Laplacian mode runs 1
    int gridCols = 0;      ///< HM Grid columns; 0 = from the resolution (cells of about cellSize px)
    int gridRows = 0;      ///< HM Grid rows; 0 = from the resolution
    int cellSize = 64;     ///< the automatic grid's cell size in pixels, >= 16
    double overlap = 0.25; ///< sub-band blend zones reach this fraction of a cell's size into each neighbour, [0, 0.5]
    bool blendPixels =
        true; ///< blend the pixel-domain matches too (false: each cell's is exact, but seams show where cells differ)
    int pixelPasses = 3; ///< pixel-domain matches at the end (blended ones converge to each cell's statistics), >= 1
    double reach =
        0.0; ///< a cell's statistics also take this fraction of its size around it, [0, 1] (0 = the cell itself)
    HmPyramid pyramid = HmPyramid::Steerable;
    int levels = 4;       ///< pyramid levels (clamped so the coarsest band keeps >= 8 px), >= 1
    int orientations = 4; ///< steerable orientations (Heeger-Bergen 4), 1..8
    int bins = 1024;      ///< source histogram bins (transfer functions are tabulated at their edges), >= 16
    int quantiles = 1024; ///< target quantile table entries, >= 16
    /// Last, per channel, one gain and offset per cell, blended with the pixel weights and solved together (Levenberg-
    /// Marquardt on 2 equations per cell) so every cell's mean and std are the target's: the blended matches alone
    /// leave cells next to very different ones a few per cent off (6% on the built-in river, docs/animate.md). Smooth,
    /// so no seams. Not applied when reach > 0. false = stop after the pixel passes.
    bool cellMoments = true;
    bool colorPca = true; ///< match in the target's colour PCA space (Heeger-Bergen's colour), then the pixel passes in
                          ///< RGB; false: every RGB channel alone (colour fringes on near-grey images)
};

/// Throws ValueError naming the first setting out of range.
void validate(const HistogramMatchSettings& s);

/// The grid (columns, rows) a matcher of a width x height target uses: the settings' grid, or cells of about
/// cellSize pixels, with cells at least 8 pixels wide and high (a finer grid is reduced to that).
std::pair<int, int> histogramGrid(int width, int height, const HistogramMatchSettings& s);

/// A cell of the grid: the core rectangle [x0, x1) x [y0, y1) and the pixels its statistics use.
struct HmCell
{
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;     ///< the cell (cells tile the image)
    int sx0 = 0, sy0 = 0, sx1 = 0, sy1 = 0; ///< its statistics region (grown by `reach`, clamped)
};

class HistogramMatcher
{
public:
    /// Precomputes the target's pyramids and per-cell quantile tables. `target` has 1..4 channels (colour
    /// PCA over the first 3 when there are 3+ and colorPca is set). With a `matte` (1 channel, target
    /// size), each cell's statistics, the target's and the frame's, come from its pixels with
    /// matte >= 0.5 only (when it has >= 16 of them in that band): the fluid is matched to the fluid, not to
    /// the still parts around it. Throws ValueError on an empty target, a mismatched matte or bad settings.
    HistogramMatcher(
        const ChannelImage& target, const HistogramMatchSettings& settings, const ChannelImage* matte = nullptr);
    ~HistogramMatcher();
    HistogramMatcher(HistogramMatcher&&) noexcept;
    HistogramMatcher& operator=(HistogramMatcher&&) noexcept;

    /// The frame matched to the target. Same size and channels as the target, else ValueError.
    /// With `cellMoments`, each cell's mean and std are exact for the frame as delivered: composited over the
    /// target through the matte (m x out + (1 - m) x target), over the whole cell. Const and thread-safe.
    ChannelImage match(const ChannelImage& frame) const;

    /// Only the last step of match(): each cell's mean and std made exact by the blended per-cell gains and offsets
    /// (settings.cellMoments; the frame unchanged without it). Same shape checks as match(). Const and thread-safe.
    ChannelImage matchMoments(const ChannelImage& frame) const;

    int gridCols() const;
    int gridRows() const;
    const std::vector<HmCell>& cells() const; ///< row by row
    int levels() const;                       ///< pyramid levels actually used

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

/// Mean and standard deviation of channel c over a rectangle [x0, x1) x [y0, y1).
struct MeanStd
{
    double mean = 0.0, std = 0.0;
};
MeanStd meanStd(const ChannelImage& img, int c, int x0, int y0, int x1, int y1);

} // namespace turb
