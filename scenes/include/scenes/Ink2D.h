/// @file Ink2D.h
/// @brief A built-in moving exemplar for Fluidymation (`vdbturb stylize --method fluidymation`):
///        a drop of ink spreading over wet paper, simulated in 2D and painted like watercolour.
///
/// No video of a real medium ships with Debian, so this is the exemplar of the tests, docs and
/// benchmark (`vdbturb sim ink` writes it to disk; `--exemplar builtin:ink` uses it directly).
/// The simulation, in pixels and frames:
/// - capillary spreading: the wet front (mean radius R(t)) moves outwards at V(t) = speed / (1 + t / decay),
///   the paint behind it comes to rest (u_r = V (r / R)^2 inside, V R / r beyond), so the rim moves and
///   the middle is nearly still, and the late frames slow down; the front speed wobbles along the rim
///   with slowly changing noise (fingers), plus a weak divergence-free swirl (curl noise);
/// - the wetness c and a pigment texture p are advected semi-Lagrangian (4 substeps a frame, bilinear);
/// - colour: paper (off-white with a fixed fibre texture that does not move) times
///   exp(-1.6 k (c (0.12 + 0.88 p^2) + 1.1 e)), an indigo pigment, where e darkens the rim (the difference
///   of two blurs of c: the coffee-ring edge of watercolour);
/// - mask: c >= 0.5; flow: the velocity at the frame's time (pixels per frame), zero outside the mask.
///
/// @code
/// turb::scenes::InkSettings s;                     // 320 x 240, 30 frames
/// turb::scenes::InkSequence ink = turb::scenes::inkExemplar(s);  // ink.rgb[i], ink.mask[i], ink.flow[i]
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/RgbaImage.h>

#include <cstdint>
#include <vector>

namespace turb::scenes {

struct InkSettings
{
    int width = 320;        ///< pixels, >= 32 (the drop starts at a radius of 0.1 x the short side)
    int height = 240;       ///< pixels, >= 32
    int frames = 30;        ///< >= 1
    double speed = 3.5;     ///< the front's speed in frame 0, pixels per frame, > 0
    double decay = 10.0;    ///< frames over which the front's speed halves (speed / (1 + t / decay)), > 0
    std::uint64_t seed = 1; ///< noise seed: the same seed, the same sequence
};

struct InkSequence
{
    std::vector<RgbaImage> rgb;     ///< opaque colours (sRGB-encoded), paper included
    std::vector<ChannelImage> mask; ///< 1 channel, 0 or 1
    std::vector<ChannelImage> flow; ///< 2 channels, pixels per frame (x right, y down), 0 outside the mask
};

/// Simulates and paints the sequence. Deterministic. Throws turb::ValueError on settings out of range.
InkSequence inkExemplar(const InkSettings& settings);

} // namespace turb::scenes
