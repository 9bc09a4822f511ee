/// @file Strokes.h
/// @brief Reading the flow design of `vdbturb animate` (Okabe et al. 2009): orientation and speed strokes as a
///        JSON file, the file form of Okabe et al.'s Orientation and Speed Brushes (section 3.1).
///
/// The schema (version 1; scenes/animate/README.md has the full description and an example):
/// @code
/// {
///   "version": 1,
///   "canvas": [640, 480],                       // optional: the size the points were drawn on;
///                                               // they are scaled to the target's size
///   "strokes": [
///     {"brush": "orientation", "points": [[40, 400], [300, 260], [600, 120]]},
///     {"brush": "speed", "speed": 2.0, "points": [[40, 300], [600, 300]]},
///     {"brush": "speed", "speed": "example", "points": [[...]]},   // the example's mean speed
///     {"brush": "orientation", "mode": "local", "size": 60, "alpha": 0.8, "points": [[...], ...]}
///   ]
/// }
/// @endcode
/// Points are pixels of the target, x right, y down, pixel centres at integers; a stroke runs from its
/// first point to its last (the flow goes that way). "mode" is "global" (default) or "local"; local
/// strokes need "size" (brush diameter, pixels) and take "alpha" (default 1). Speeds are pixels per frame.
///
/// Every problem throws turb::IoError naming the file and, where it applies, the line: JSON syntax
/// errors (line and column from the parser), a missing or mistyped field, an unknown brush or mode,
/// a point outside the target (beyond half a pixel from its border), a stroke without direction, and a
/// design without a global orientation stroke.
#pragma once

#include <turb/CloneBrush.h>
#include <turb/FlowDesign.h>

#include <string>
#include <vector>

namespace turbio {

struct StrokeFile
{
    std::vector<turb::FlowStroke> strokes;
    std::vector<int> lines; ///< the line each stroke starts on (1-based), for messages
};

/// Reads and checks a stroke file against a target of width x height pixels.
StrokeFile readFlowStrokes(const std::string& path, int width, int height);

/// Parses stroke JSON from memory; `name` is used in messages (tests, stdin).
StrokeFile parseFlowStrokes(const std::string& text, const std::string& name, int width, int height);

/// The Clone Brush's stroke pairs (Okabe et al. section 5.3, turb/CloneBrush.h), version 1:
/// @code
/// {
///   "version": 1,
///   "example_canvas": [320, 240],               // optional: the size the sources were drawn on (scaled to the
///   "canvas": [320, 240],                       //   example's), and the destinations' (scaled to the target's)
///   "clones": [
///     {"source": [[40, 120], [40, 40]],         // on the video example, its pixels
///      "destination": [[200, 180], [230, 90]],  // on the target, its pixels
///      "size": 48, "alpha": 1.0}                // brush diameter (target pixels, > 0; scaled with the canvas)
///                                               // and opacity (default 1)
///   ]
/// }
/// @endcode
/// Points are pixels, x right, y down, pixel centres at integers. Every problem throws turb::IoError naming the file
/// and, where it applies, the line of the pair: JSON syntax errors, a missing or mistyped field, fewer than 2
/// points or all equal, a point outside its image (the source's the exampleWidth x exampleHeight example, the
/// destination's the target), size <= 0, alpha outside [0, 1].
struct CloneFile
{
    std::vector<turb::CloneStroke> clones;
    std::vector<int> lines; ///< the line each pair starts on (1-based), for messages
};
CloneFile readCloneStrokes(
    const std::string& path, int exampleWidth, int exampleHeight, int targetWidth, int targetHeight);
CloneFile parseCloneStrokes(const std::string& text, const std::string& name, int exampleWidth, int exampleHeight,
    int targetWidth, int targetHeight);

} // namespace turbio
