/// @file CloneBrush.h
/// @brief The Clone Brush (Okabe, Anjyo, Igarashi, Seidel 2009, sections 3.2 and 5.3): the residuals of the video
///        example around a source stroke are cut out and pasted around a destination stroke on the target, deformed
///        so that the source stroke fits the destination stroke; brush size and alpha control how much they replace
///        the residuals already there.
///
/// - **Deformation.** The paper deforms a triangle mesh over the example as rigidly as possible (Igarashi et al.
///   2005) with the strokes' vertices as positional constraints. Here the same constraints drive a moving least
///   squares rigid deformation (Schaefer, McPhail, Warren 2006): both strokes are resampled at the same fractions of
///   their arc length (control points p_j on the destination, q_j on the source), and each target pixel x takes the
///   rotation and translation that best carry the p_j onto the q_j, weighted by w_j = 1 / |p_j - x|^2:
///   f(x) = R (x - p*) + q*, with p*, q* the weighted centroids and R the weighted Procrustes rotation. Why this
///   instead of a mesh: it is the same family (locally rigid, exact at the constraints, the rigid motion itself when
///   the strokes differ by one), needs no mesh or solve, is evaluated per pixel independently (deterministic at any
///   thread count), and is smooth wherever a pixel is not on a control point. Strokes of different lengths stretch
///   the region along the stroke near it and leave it rigid far from it.
/// - **Sampling.** f maps every target pixel to an example position (backward mapping, as the paper's sampling
///   through the deformed mesh); its residual is read there bilinearly (4 taps). The same map serves every frame
///   (temporal coherence, as the automatic transfer). Positions more than half a pixel outside the example take
///   nothing from the brush.
/// - **Matte.** The destination stroke's brush is `alpha` within size/2 of the polyline and falls smoothly
///   (smoothstep) to 0 at distance `size`, as the local flow strokes' (FlowDesign.h). A pixel's residual becomes
///   (1 - m) R'(x) + m R(f(x)): the transferred residual under it keeps weight 1 - m. Strokes apply in order, each
///   over the result of the ones before.
///
/// @code
/// turb::CloneStroke c;
/// c.source = {{40, 120}, {40, 40}};            // on the example (its pixels)
/// c.destination = {{200, 180}, {230, 90}};     // on the target (its pixels)
/// c.size = 48; c.alpha = 1.0;
/// turb::TransferMap map = turb::matchResiduals(exampleFlow, designedFlow, transferSettings);
/// turb::applyCloneStrokes(map, {c});          // then map.apply(R_i) is R'_i with the clone
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/FlowDesign.h>
#include <turb/ResidualTransfer.h>

#include <vector>

namespace turb {

/// One Clone Brush stroke pair. Points are pixels, x right, y down, pixel centres at integers.
struct CloneStroke
{
    std::vector<StrokePoint> source;      ///< on the video example: >= 2 points, not all equal, inside the example
    std::vector<StrokePoint> destination; ///< on the target: >= 2 points, not all equal, inside the target
    double size = 32.0;                   ///< brush diameter in target pixels, > 0 (full alpha within size/2)
    double alpha = 1.0;                   ///< brush opacity, [0, 1]
};

struct CloneSettings
{
    double sampleSpacing = 2.0; ///< control points along the longer stroke every this many pixels, > 0
    int maxSamples = 256;       ///< most control points per stroke pair (the cost per pixel is linear in them), >= 2
};

/// Throws ValueError naming the stroke pair (0-based) that is malformed: fewer than 2 points or all points equal
/// on either side, a point outside its image (beyond half a pixel from the border: the source against the
/// exampleWidth x exampleHeight example, the destination against the target), a size that is not > 0 and finite,
/// an alpha outside [0, 1]; or settings out of range.
void validateCloneStrokes(const std::vector<CloneStroke>& strokes, int exampleWidth, int exampleHeight, int targetWidth,
    int targetHeight, const CloneSettings& settings = {});

/// The deformation of one stroke pair: target position -> example position (moving least squares, rigid).
class CloneDeformation
{
public:
    /// Throws ValueError on a stroke with fewer than 2 points or all points equal, or settings out of range.
    explicit CloneDeformation(const CloneStroke& stroke, const CloneSettings& settings = {});
    /// f(x, y): the example position whose residual lands at target position (x, y). Exact on the control points
    /// (a destination stroke vertex maps onto the matching source point).
    StrokePoint operator()(double x, double y) const;
    int controlPoints() const { return int(mP.size()); }

private:
    std::vector<StrokePoint> mP, mQ; // destination and source control points
};

/// The brush matte of a stroke pair at target position (x, y): alpha within size/2 of the destination polyline,
/// smoothstep to 0 at distance size.
double cloneMatte(const CloneStroke& stroke, double x, double y);

/// Applies the strokes, in order, to `map` (target size, the example's size as its source): within each destination
/// brush, every pixel's taps become (1 - m) x its own + m x the 4 bilinear taps of the deformed example position.
/// Where more than TransferMap::kTaps taps result, the lightest are dropped and the rest rescaled to the same total.
/// `targetMatte` (1 channel, target size; may be null): pixels outside the fluid (matte <= 0) are left alone, as the
/// automatic transfer leaves them. Sets map.stats.cloned. Returns the brushes' combined matte (1 channel, target
/// size, [0, 1]: the weight the clones hold at each pixel). Throws ValueError as validateCloneStrokes, or when the
/// matte has the wrong shape.
ChannelImage applyCloneStrokes(TransferMap& map, const std::vector<CloneStroke>& strokes,
    const ChannelImage* targetMatte = nullptr, const CloneSettings& settings = {});

} // namespace turb
