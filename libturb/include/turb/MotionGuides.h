/// @file MotionGuides.h
/// @brief The motion description of a masked image sequence, as Fluidymation (Platkevič et al. 2020)
///        needs it on both sides: binary masks, a flow per frame (given, or estimated from the
///        masks by the paper's Appendix A), signed distance fields, and the motion-extent channels
///        I+ext and I-ext of section 3.3.
///
/// Conventions (ChannelImage's): x right, y down, pixel centres at integer positions. A flow F^i is in
/// pixels per frame and moves frame i onto frame i+1, like every motion field in vdbturb (Warp.h,
/// CameraBridge.h). A pixel is inside a mask when its value is >= the threshold (0.5 by default).
///
/// Appendix A, as implemented here (`estimateMaskFlows`):
/// 1. phi_i = signedDistance(mask_i) (Felzenszwalb & Huttenlocher 2012; negative inside, so phi grows
///    outwards and its gradient is the outward normal);
/// 2. on the boundary pixels of mask i (inside, with a 4-neighbour outside), the level-set normal speed
///        F^i = -(phi_{i+1} - phi_i) grad(phi_i) / |grad(phi_i)|,
///    a growing mask giving an outward flow. The paper prints (I^dist_i - I^dist_{i-1}) times the unit
///    gradient, which with either sign convention of the distance points inwards for a growing mask (the
///    backward motion); we use the sign that moves the boundary the way it moves, and the next frame so
///    F^i moves frame i onto i+1 (the last frame uses the previous one). Speeds are clamped to
///    `maxBoundarySpeed` (a blob appearing or vanishing is not a motion);
/// 3. inside, the boundary values are diffused (Johnston 2002: the membrane / Laplace interpolation with
///    the boundary pixels fixed), solved coarse to fine on a pyramid with red-black Gauss-Seidel;
/// 4. the flows are smoothed in time by a Gaussian of radius 3 frames (sigma = radius / 3), normalised
///    over the frames whose mask holds the pixel. Outside its mask a flow is 0.
///
/// Motion extent (section 3.3), per pixel (Eulerian, as the paper): acc+(0) = 0,
/// acc+(i) = acc+(i-1) + F^{i-1} inside mask i and 0 outside; acc-(last) = 0,
/// acc-(i) = acc-(i+1) + F^i inside mask i and 0 outside; I+ext = |acc+|, I-ext = |acc-|.
///
/// Storage is sparse: per frame, the masked pixels' indices, flows and extents (20 bytes per masked
/// pixel), so long targets fit in memory (e.g. 123k masked pixels: 2.5 MB per frame).
///
/// @code
/// turb::MotionSequence seq(width, height);
/// for (const auto& m : masks) seq.addFrame(m);          // no flows: Appendix A estimates them
/// seq.finish(turb::MotionGuideSettings{});
/// turb::ChannelImage f = seq.flow(3), e = seq.extents(3); // 2 channels each
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/Progress.h>

#include <cstdint>
#include <vector>

namespace turb {

/// Signed Euclidean distance to the boundary of the binary mask (mask >= threshold inside), in pixels:
/// inside -(distance to the nearest outside pixel - 1/2), outside +(distance to the nearest inside pixel
/// - 1/2), so the two pixels either side of an edge get -1/2 and +1/2. A mask with no outside (inside)
/// pixel gives -(W + H) (+(W + H)) everywhere. Exact (Felzenszwalb & Huttenlocher 2012). 1 channel.
ChannelImage signedDistance(const ChannelImage& mask, float threshold = 0.5f);

/// Pixels inside the mask with a 4-neighbour outside it (the image border does not count). Row-major.
std::vector<char> boundaryPixels(const ChannelImage& mask, float threshold = 0.5f);

/// Harmonic (membrane) interpolation: every pixel with inside[i] && !fixed[i] gets the value that makes
/// it the mean of its 4-neighbours that are inside; fixed pixels keep `values`; outside pixels are 0.
/// Solved coarse to fine on a pyramid, `sweeps` red-black Gauss-Seidel sweeps per level. Any channel
/// count. Deterministic at any thread count.
ChannelImage diffuseFromBoundary(
    const ChannelImage& values, const std::vector<char>& fixed, const std::vector<char>& inside, int sweeps = 40);

struct MotionGuideSettings
{
    double smoothingRadius =
        3.0; ///< Appendix A: temporal Gaussian radius in frames (sigma = radius / 3), >= 0; 0 = none
    float maxBoundarySpeed = 8.0f; ///< clamp of an estimated boundary speed, pixels per frame, > 0
    int diffusionSweeps = 40;      ///< Gauss-Seidel sweeps per pyramid level of the interior diffusion, >= 1
};

/// Appendix A for one frame, before temporal smoothing: the flow on `mask`'s boundary from the distance
/// fields of `mask` and `other` (the next frame, or the previous one when `otherIsNext` is false),
/// diffused inside, 0 outside. 2 channels, pixels per frame.
ChannelImage maskFlow(
    const ChannelImage& mask, const ChannelImage& other, bool otherIsNext, const MotionGuideSettings& settings = {});

/// Masks, flows and motion extents of one sequence (see the file comment).
class MotionSequence
{
public:
    MotionSequence() = default;
    /// An empty sequence of width x height frames. Throws ValueError for sizes < 1.
    MotionSequence(int width, int height);

    /// Appends a frame. `mask`: 1 channel (inside where >= threshold); `flow`: 2 channels in pixels per
    /// frame or null (then every frame must come without flow, and finish() estimates them). Throws
    /// ValueError naming the frame (0-based) on a size or channel mismatch, non-finite flow values, or
    /// frames mixing given and missing flows.
    void addFrame(const ChannelImage& mask, const ChannelImage* flow = nullptr, float threshold = 0.5f);

    /// Estimates the flows when none were given (Appendix A) and computes the extents. Call once, after
    /// the last addFrame. Throws ValueError when there is no frame; Cancelled when `progress` asks.
    void finish(const MotionGuideSettings& settings = {}, Progress* progress = nullptr);

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    int frames() const { return int(mFrames.size()); }
    bool finished() const { return mFinished; }
    bool flowsEstimated() const { return mEstimated; }
    /// Masked pixels of frame i.
    long long maskedPixels(int i) const { return (long long)mFrames.at(size_t(i)).pixels.size(); }

    /// Frame i as dense images: the mask (1 channel, 0 or 1), the flow (2 channels), the extents
    /// (2 channels: I+ext, I-ext, pixels), the signed distance of the mask (1 channel).
    ChannelImage mask(int i) const;
    ChannelImage flow(int i) const;
    ChannelImage extents(int i) const;
    ChannelImage distance(int i) const;

private:
    struct Frame
    {
        std::vector<std::int32_t> pixels; // masked pixel indices, increasing
        std::vector<float> flow;          // 2 per masked pixel
        std::vector<float> ext;           // 2 per masked pixel: ext+, ext-
    };
    ChannelImage scatter(const Frame& f, const std::vector<float>& values, int channels) const;

    int mWidth = 0, mHeight = 0;
    std::vector<Frame> mFrames;
    bool mFlowGiven = false, mEstimated = false, mFinished = false;
};

} // namespace turb
