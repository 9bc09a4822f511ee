/// @file Warp.h
/// @brief Moving images along 2D motion fields: forward warping (splatting, LazyFluids' X-hat^{t-1}),
///        backward sampling, and synthetic motion blur by line convolution along the flow
///        (LazyFluids section 4.5, Fig. 9).
///
/// Motion fields are 2-channel ChannelImages in pixels per frame, x right and y down: pixel (x, y)
/// moves to (x + F0, y + F1) over one frame.
///
/// @code
/// turb::WarpResult w = turb::forwardWarp(previousOutput, motion);  // previous frame moved to this one
/// turb::ChannelImage blurred = turb::motionBlur(frame, motion, turb::MotionBlurSettings{0.5f});
/// @endcode
#pragma once

#include <turb/ChannelImage.h>

namespace turb {

struct WarpResult
{
    ChannelImage image;  ///< the warped image; pixels nothing landed on are 0
    ChannelImage weight; ///< 1 channel: splat weight received per pixel (0 = hole)
};

/// Forward warp by bilinear splatting: each source pixel deposits its value at its moved position with
/// bilinear weights, and every destination pixel is normalised by the weight it received (pixels
/// receiving less than `minWeight` become holes, 0). A translation by whole pixels is exact; a
/// fractional one is exact to bilinear interpolation error. Throws ValueError when `motion` is not a
/// 2-channel image of the image's size. Sequential: splatting order fixes the float sums.
WarpResult forwardWarp(const ChannelImage& image, const ChannelImage& motion, float minWeight = 1e-3f);

/// Backward warp: out(x) = image(x - motion(x)) sampled bilinearly (semi-Lagrangian; constant
/// extension at the borders).
ChannelImage backwardWarp(const ChannelImage& image, const ChannelImage& motion);

struct MotionBlurSettings
{
    float shutter = 0.5f; ///< blur length as a fraction of the frame's motion, >= 0 (0 = none, 1 = a full frame)
    int maxSamples = 33;  ///< most samples along a pixel's line, >= 3
};

/// Line convolution along the local motion with a Gaussian of standard deviation length/4 over the
/// line [-length/2, +length/2], length = shutter * |F| (anisotropic: only along the flow).
ChannelImage motionBlur(const ChannelImage& image, const ChannelImage& motion, const MotionBlurSettings& settings = {});

} // namespace turb
