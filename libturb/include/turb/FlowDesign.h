/// @file FlowDesign.h
/// @brief The target's flow field: rough design from orientation and speed strokes, and its automatic
///        refinement by the target image's gradients (Okabe et al. 2009, sections 3.1 and 5.1).
///
/// **Rough field** (5.1). Orientation strokes give the unit tangent of the polyline at samples along it;
/// speed strokes give their speed (pixels per frame). Samples are interpolated over the image with the
/// radial basis phi(r) = r (x and y components separately for orientation, then normalised), giving
/// Phi_o (2 channels, unit) and Phi_s (1 channel). Global strokes form the base layer; each local
/// stroke makes its own layer (its samples interpolated alone) with a matte of its brush size and alpha,
/// composited over the result in file order: value = (1 - m) value + m layer, where
/// m(d) = alpha for distances d to the polyline <= size/2, falling smoothly (smoothstep) to 0 at d = size.
/// Without a global speed stroke the base speed is `defaultSpeed` (the command passes the example's
/// mean speed: "the user can fetch the speed value from the video example").
///
/// **Refinement** (5.1). The target's luminance is blurred by a 5x5 Gaussian and differentiated by a
/// Sobel filter (OpenCV): G. Psi_o is the unit vector parallel to G (or perpendicular, an option beyond
/// the paper: streaks in water often run across the gradient) signed so that Psi_o . Phi_o > 0, blurred
/// by a Gaussian of standard deviation w_f and normalised; Psi_s = (Psi_o . Phi_o) Phi_s, clamped at 0;
/// the refined flow is Psi_s Psi_o.
///
/// **Where the gradient vanishes** (the paper does not say): G has no direction there, so Psi_o leans on
/// the design. Before the blur, Psi_o = normalise(w s G/|G| + (1 - w) Phi_o) with
/// w = |G|^2 / (|G|^2 + eps^2), eps = gradientFloor x the 90th percentile of |G|; flat areas therefore
/// keep the designed orientation at the designed speed, strong edges follow the image. Where the
/// blurred vector cancels (|.| < 1e-3), Psi_o = Phi_o.
///
/// @code
/// std::vector<turb::FlowStroke> strokes = ...;            // e.g. turbio::readFlowStrokes("strokes.json", W, H)
/// turb::RoughFlow rough = turb::interpolateStrokes(strokes, W, H, turb::StrokeSettings{});
/// turb::RefinedFlow refined = turb::refineFlow(target, rough, turb::RefineSettings{}); // refined.flow: 2 channels
/// @endcode
#pragma once

#include <turb/ChannelImage.h>

#include <string>
#include <vector>

namespace turb {

enum class StrokeKind {
    Orientation, ///< Orientation Brush: the flow runs along the stroke, in its drawing direction
    Speed        ///< Speed Brush: the flow's speed under the stroke
};

struct StrokePoint
{
    double x = 0.0, y = 0.0; ///< pixels, x right, y down, pixel centres at integers
};

struct FlowStroke
{
    StrokeKind kind = StrokeKind::Orientation;
    bool local = false;              ///< local mode: its own layer with a matte (size, alpha); else global
    double size = 32.0;              ///< local: brush diameter in pixels, > 0
    double alpha = 1.0;              ///< local: brush opacity, [0, 1]
    double speed = 0.0;              ///< speed strokes: pixels per frame, >= 0
    bool exampleSpeed = false;       ///< speed strokes: use StrokeSettings::defaultSpeed instead (the example's
                                     ///< mean speed in `animate`: the paper's "fetch the speed from the video example")
    std::vector<StrokePoint> points; ///< the polyline, >= 2 points, not all equal
};

struct StrokeSettings
{
    double sampleSpacing =
        4.0; ///< samples along a stroke every this many pixels, > 0 (raised so a layer keeps <= maxSamples)
    int maxSamples = 400;      ///< most RBF centres per layer (the dense solve is cubic in them), >= 8
    int rbfStep = 4;           ///< the interpolant is evaluated every rbfStep pixels, bilinear between, 1..16
    double defaultSpeed = 1.0; ///< base speed without a global speed stroke, and the speed of exampleSpeed strokes,
                               ///< pixels per frame, >= 0
};

/// Throws ValueError naming the stroke (0-based index) that is malformed: too few points, all points
/// equal, a point outside the width x height image (beyond half a pixel from the border), size <= 0,
/// alpha outside [0, 1], a negative or non-finite speed. Also throws when there is no global orientation
/// stroke (the base layer needs one).
void validateStrokes(const std::vector<FlowStroke>& strokes, int width, int height);

/// Phi_o and Phi_s, and the rough flow Phi_s Phi_o.
struct RoughFlow
{
    ChannelImage orientation;  ///< Phi_o: 2 channels, unit length (0 where the interpolated components cancel)
    ChannelImage speed;        ///< Phi_s: 1 channel, pixels per frame
    ChannelImage flow() const; ///< Phi_s Phi_o, 2 channels
};

/// The rough field from strokes (see the file comment). Throws ValueError as validateStrokes.
RoughFlow interpolateStrokes(
    const std::vector<FlowStroke>& strokes, int width, int height, const StrokeSettings& settings);

/// A dense designed flow (2 channels, pixels per frame) as a rough field: Phi_o = flow / |flow|
/// (0 where |flow| < 1e-6), Phi_s = |flow|.
RoughFlow roughFromFlow(const ChannelImage& flow);

enum class GradientOrientation {
    Parallel,     ///< Psi_o parallel to the image gradient (the paper)
    Perpendicular ///< Psi_o along the image's edges (across the gradient)
};

struct RefineSettings
{
    double wf = 12.0; ///< w_f: standard deviation in pixels of the blur of Psi_o (paper 12), > 0
    GradientOrientation orient = GradientOrientation::Parallel;
    double gradientFloor = 0.1; ///< eps = this x the 90th percentile of |G|: below it the design wins, >= 0
    int gradientKernel = 5;     ///< the Gaussian before Sobel, in pixels (paper 5x5), odd, >= 1
};

/// Throws ValueError naming the first setting out of range.
void validate(const RefineSettings& s);

struct RefinedFlow
{
    ChannelImage gradient;    ///< G: 2 channels (d/dx, d/dy of the luminance, per pixel)
    ChannelImage orientation; ///< Psi_o: 2 channels, unit
    ChannelImage speed;       ///< Psi_s: 1 channel, pixels per frame, >= 0
    ChannelImage flow;        ///< Psi_s Psi_o: the designed flow W' warps by, 2 channels
};

/// Refines the rough field by the target's gradients. `target` has 1..4 channels (luminance by
/// Rec. 709 on 3+); the rough field must have its size. Throws ValueError otherwise.
RefinedFlow refineFlow(const ChannelImage& target, const RoughFlow& rough, const RefineSettings& settings);

} // namespace turb
