/// @file Animate2D.h
/// @brief Built-in inputs for `vdbturb animate` (Okabe et al. 2009): a procedural river video example, a still
///        of another river with banks (and its matte), for the demo, the tests and the benchmark.
///
/// - `riverExample`: water flowing right under a shear flow, speed s(y) = 1 + fast (1 - (2y/H - 1)^2)
///   pixels per frame (fastest mid-stream). Frame t is a periodic ripple texture carried exactly by the
///   flow (sampled at x - s(y) t), plus glints that appear and fade within a few frames while drifting
///   with the water: the non-translational part the residuals capture. Deterministic in the seed.
/// - `riverStill`: a different river (colours, ripples) winding between grassy banks, for the target;
///   `riverMatte` is 1 on its water, 0 on the banks, with a 2-pixel soft edge.
/// - scenes/animate/river_strokes.json is a flow design for the still (canvas 320 x 240, scaled to any size).
/// All images are RGB (3 channels) in [0, 1], display-referred (sRGB-encoded when written).
///
/// @code
/// std::vector<turb::ChannelImage> ex = turb::scenes::riverExample({320, 240, 60, 1});
/// turb::ChannelImage still = turb::scenes::riverStill(320, 240, 2);
/// @endcode
#pragma once

#include <turb/ChannelImage.h>

#include <cstdint>
#include <vector>

namespace turb::scenes {

struct RiverSettings
{
    int width = 320;  ///< pixels, >= 16
    int height = 240; ///< pixels, >= 16
    int frames = 60;  ///< >= 1
    std::uint64_t seed = 1;
    double fast = 1.0; ///< extra speed mid-stream, pixels per frame (the banks move at 1)
};

std::vector<ChannelImage> riverExample(const RiverSettings& s);
ChannelImage riverStill(int width, int height, std::uint64_t seed);
ChannelImage riverMatte(int width, int height);

} // namespace turb::scenes
