/// @file Figures.h
/// @brief `measure --plot`'s figures (turb::run, the entry points' layer), drawn by gnuplot (Debian: gnuplot-nox):
///        a charting program draws them, not the algorithm library. Each figure is a gnuplot script with its data
///        inline, written beside the picture (PATH.gp) so it can be restyled and rerun, and rendered to PATH by
///        `gnuplot` on the PATH. PNG, SVG and PDF come from gnuplot's cairo terminals; EXR and TIFF are the PNG
///        converted by OpenImageIO (turbio/ImageIO.h). A caller of runMeasure (turb/run/Measure.h) draws them as it
///        goes: a spectrum per measured frame, the metrics once the run is done.
#pragma once

#include <turb/Measure.h>

#include <string>
#include <vector>

namespace turb::run {

/// Whether `gnuplot` runs here, and if not, what to install.
bool gnuplotAvailable(std::string& why);

/// Log-log E(k) of output, target and source of one frame, with the target's Nyquist wavenumber marked. Writes PATH
/// and PATH.gp; throws turb::IoError naming PATH when gnuplot fails.
void writeSpectrumFigure(const std::string& path, const turb::FrameMeasures& m, const std::string& title);

/// One panel per metric over the frames, with the targets of docs/measure.md as reference lines. Writes PATH and
/// PATH.gp; throws turb::IoError naming PATH when gnuplot fails.
void writeMetricsFigure(
    const std::string& path, const std::vector<turb::FrameMeasures>& frames, const std::string& title);

} // namespace turb::run
