/// @file Preview.h
/// @brief `vdbturb preview` as a library call (turb::run, the entry points' layer): pictures of caches (a lit
///        density render, speed and vorticity slices, LIC) and labelled contact sheets, from files to image files.
///
/// @code
/// turb::run::PreviewJob job;
/// job.inputs = {"target=lowres/smoke.####.vdb", "up=up/turb.####.vdb"};
/// job.modes = "density,vorticity";
/// job.sheet = "pics/sheet.png";
/// turb::run::runPreview(job); // words and frames go to turb::run::reporter()
/// @endcode
///
/// Every input frame's headers are read before the first picture (what a dry run does), and each input is drawn
/// over one box for the whole run (the union of its frames' domains, shared by the columns of one scene), with its
/// colour ranges fixed from the last row's frame, so flipbooks do not jump and sheet columns line up. A 2D cache
/// (one z layer) is drawn in its own plane whatever the view.
#pragma once

#include <turb/Camera.h>
#include <turbio/Vdb.h>

#include <string>
#include <utility>
#include <vector>

namespace turb::run {

/// What a picture shows.
enum class PreviewMode {
    Density,   ///< a lit ray march of the density (a 2D cache: a colour-mapped slice)
    Speed,     ///< a slice of |velocity|
    Vorticity, ///< a slice of |curl velocity|
    Lic        ///< a line-integral-convolution texture of the flow in a slice
};

/// --mode's comma list (density, speed, vorticity, lic, all) as modes, in order. Throws turb::ValueError naming an
/// unknown mode, or for an empty list.
std::vector<PreviewMode> parsePreviewModes(const std::string& text);

/// The cameras by their names (--view): front (along +y), side (along +x), top (down -z), for a z-up cache.
const std::vector<std::pair<std::string, turb::View>>& previewViews();

/// A preview run: the CLI's options as plain values (same names, same defaults).
struct PreviewJob
{
    std::vector<std::string> inputs; ///< caches as [LABEL=]PATTERN (####, %04d, $F4 or one real file); the label
                                     ///< defaults to the file name. Several go side by side, into `sheet` only
    std::string modes = "density";   ///< parsePreviewModes' list
    std::string frames; ///< frame list ("10,30,60"); empty: every frame on disk (a sheet: three spread frames)
    std::string out;    ///< one picture per frame (.png, .exr: linear half float, .tif, .jpg); a frame token for
                        ///< several frames; its folders are made. Give this or `sheet`
    std::string sheet;  ///< one contact sheet instead: rows = frames, columns = caches x modes
    std::string title;  ///< the sheet's title; empty: the labels and the view
    turb::View view = turb::View::Front;
    double slice = 0.5;        ///< speed/vorticity/LIC slice position, a fraction along the view axis in [0, 1]
    int width = 320;           ///< each picture's width in pixels, [16, 8192]
    float exposure = 1.0f;     ///< the density render's exposure (> 0), fixed for all frames
    float extinction = 6.0f;   ///< optical depth per unit density per world unit (> 0)
    float speedMax = 0.0f;     ///< speed (world units/s) at the colour map's top; 0: the last row's 99.5th percentile
    float vorticityMax = 0.0f; ///< vorticity (1/s) at the colour map's top; 0: each cache's 99th percentile
    std::string up = "auto";   ///< the world axis drawn upward: auto (upAxisOf), y or z
    bool matchDensity = false; ///< draw each cache's density at the first cache's peak (Blender's noise up-res)
    turbio::ReadOptions read;
    bool dryRun = false; ///< check and plan (printData, "would write PATH"), draw nothing
    int threads = 0;     ///< 0 = all cores
};

/// What a run wrote.
struct PreviewRun
{
    std::vector<std::string> written; ///< the pictures, one per frame, or the one sheet; empty for a dry run
};

/// Runs `job`: one picture per frame (the modes side by side) or one contact sheet, each frame reported to
/// reporter(). Throws UsageError (neither `out` nor `sheet`; several caches without a sheet; an `out` without a frame
/// token for several frames; an unknown picture extension), turb::ValueError (a bad mode) and turb::IoError (a
/// missing or damaged input, no frames, an output that is an input or cannot be written). Pictures written before a
/// throw stay.
PreviewRun runPreview(const PreviewJob& job);

} // namespace turb::run
