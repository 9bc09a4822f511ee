/// @file Plot.h
/// @brief Line plots drawn into a turb::Image: linear or logarithmic axes with ticks and labels, a
///        legend, and reference lines (a Nyquist wavenumber, a quality threshold).
///
/// Small on purpose: enough for the figures `vdbturb measure --plot` writes, with no dependency on a
/// plotting package. Text is laid out with Image's caption metrics and drawn by the IO layer.
///
/// @code
/// turb::PlotSeries s{"output", k, e, turb::Rgb(0.1f, 0.3f, 0.8f)};
/// turb::PlotSettings ps; ps.logX = ps.logY = true; ps.xLabel = "k"; ps.title = "E(k)";
/// turb::Image img = turb::linePlot({s}, ps, {turb::PlotRule{true, kNyquist, "target Nyquist"}});
/// @endcode
#pragma once

#include <turb/Image.h>

#include <limits>
#include <string>
#include <vector>

namespace turb {

struct PlotSeries
{
    std::string label;          ///< legend text; empty = not in the legend
    std::vector<double> x, y;   ///< same length; non-finite points (and <= 0 on a log axis) break the line
    Rgb color{0.12f, 0.35f, 0.75f};
    bool markers = false;       ///< a small square at every point (short series such as metric curves)
    bool dashed = false;        ///< dashed line
};

/// A straight reference line across the plot area.
struct PlotRule
{
    bool vertical = true;       ///< vertical at x = value, else horizontal at y = value
    double value = 0.0;
    std::string label;          ///< drawn next to the line
    Rgb color{0.75f, 0.15f, 0.15f};
};

struct PlotSettings
{
    int width = 900;            ///< image size in pixels, >= 200
    int height = 600;           ///< >= 150
    std::string title, xLabel, yLabel;
    bool logX = false, logY = false; ///< logarithmic axes (decade ticks)
    double xMin = std::numeric_limits<double>::quiet_NaN(); ///< axis ranges; NaN = from the data
    double xMax = std::numeric_limits<double>::quiet_NaN();
    double yMin = std::numeric_limits<double>::quiet_NaN();
    double yMax = std::numeric_limits<double>::quiet_NaN();
    int textScale = 2;          ///< caption scale (font size 10 x scale pixels)
};

/// Draws the series. Rules outside the axis range are not drawn. A plot with no finite points shows
/// its axes and "no data".
Image linePlot(const std::vector<PlotSeries>& series, const PlotSettings& settings,
    const std::vector<PlotRule>& rules = {});

/// Tiles images left to right, top to bottom, `columns` per row, on a white background.
Image tileImages(const std::vector<Image>& images, int columns, int gap = 8);

/// "Nice" tick positions (1, 2, 5 x 10^n steps) covering [lo, hi], about `target` of them.
std::vector<double> niceTicks(double lo, double hi, int target = 6);

} // namespace turb
