/// @file Targets2D.h
/// @brief Built-in 2D target animations and a procedural exemplar for `vdbturb stylize`: runnable
///        examples, and the inputs of its tests, wash-out measurements and benchmark.
///
/// Targets are exact: the alpha of frame t is a shape carried by the motion field analytically (no
/// numerical advection), so F^t moves alpha^t onto alpha^{t+1}.
/// - `rotate`: a three-lobed blob turning rigidly about the image centre (LazyFluids Fig. 2 uses a pure
///   rotation: the flow that exposes wash-out);
/// - `swirl`: the same blob in a vortex whose angular speed falls off with the radius (it shears);
/// - `rise`: a round blob moving up at constant speed, wrapping around the image;
/// - `fill`: the whole image is fluid (alpha 1) in a rigid rotation: the benchmark's worst case;
/// - `grow`: a wobbly disc spreading (uniform dilation at speed x the short side per frame) until it
///   reaches 0.42 of the short side, then resting (Fluidymation's watercolour blot);
/// - `stroke`: a brush stroke along a wave whose tip advances speed x W pixels a frame while the body
///   already painted rests (stationary and moving regions in one frame).
/// Motion is in pixels per frame, x right, y down (ChannelImage's convention).
///
/// @code
/// turb::scenes::Target2DSettings s;   // rotate, 256 x 256
/// turb::scenes::Target2D t = turb::scenes::target2D(s, 12);  // frame 12: alpha (1 ch), motion (2 ch)
/// turb::RgbaImage ex = turb::scenes::fireExemplar(128, 1);
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/RgbaImage.h>

#include <cstdint>
#include <string>

namespace turb::scenes {

struct Target2DSettings
{
    std::string kind = "rotate"; ///< rotate, swirl, rise, fill, grow or stroke
    int width = 256;             ///< pixels, >= 16
    int height = 256;            ///< pixels, >= 16
    double speed = 0.02; ///< rotate/swirl: radians per frame at the centre; rise, stroke: pixels per frame / width;
                         ///< grow: / short side
};

struct Target2D
{
    ChannelImage alpha;  ///< 1 channel in [0, 1]
    ChannelImage motion; ///< 2 channels, F^t in pixels per frame
};

/// Frame `frame` (any integer; frame 0 is the shape at rest) of a built-in target. Throws
/// turb::ValueError for an unknown kind or a size below 16.
Target2D target2D(const Target2DSettings& settings, int frame);

/// A fire-coloured RGBA exemplar of n x n pixels (n >= 16) with a soft, ragged alpha edge: its left part
/// is smooth (a vertical colour ramp), its right part textured (seeded multi-octave value noise),
/// blended over the middle fifth; the
/// mix LazyFluids' wash-out needs to show. Straight alpha, sRGB-encoded colours.
RgbaImage fireExemplar(int n, std::uint64_t seed);

} // namespace turb::scenes
