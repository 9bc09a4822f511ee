/// @file VideoAnalysis.h
/// @brief Decomposition of a video example into an average image, a flow field and residuals
///        (Okabe, Anjyo, Igarashi, Seidel 2009, "Animating Pictures of Fluid using Video Examples",
///        section 4).
///
/// For frames F_0..F_{N-1} (C float channels each, one size):
/// - the average image A = (1/N) sum_i F_i and the differences D_i = F_i - A (4.1);
/// - the flow v: per consecutive pair (D_i, D_{i+1}), Shi-Tomasi features (100) tracked by pyramidal
///   Lucas-Kanade (window 10; OpenCV), interpolated over the image with phi(r) = r, and averaged over
///   all pairs into one field constant in time (4.2). Pixels per frame, x right, y down;
/// - the warp W(I)(x) = I(x - v(x)), bilinear (4.3; OpenCV remap, one fixed linear operator);
/// - the residuals R_i = D_{i+1} - W(D_i), i = 0..N-2 (eq. 1).
/// Eq. 4, D_i = W^i(D_0) + sum_{k<i} W^{i-k-1}(R_k), then reconstructs every frame exactly (up to float
/// rounding) because W is linear: see reconstructExample().
///
/// Features are found on the luminance of D (Rec. 709 weights on 3+ channels, else channel 0), mapped to
/// 8 bits with +-3 standard deviations of all D across the range (OpenCV's tracker takes 8-bit images).
/// Each tracked displacement d of a feature at p is a sample of v at the midpoint p + d/2. Tracks
/// failing the forward-backward check are dropped.
///
/// @code
/// turb::AnalysisSettings s;                              // 100 features, window 10
/// turb::ExampleDecomposition ex = turb::decomposeExample(std::move(frames), s, &progress);
/// std::vector<turb::ChannelImage> back = turb::reconstructExample(ex); // == frames (eq. 4)
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/Progress.h>

#include <vector>

namespace turb {

/// What v is when the caller gives a flow (decomposeExample's givenFlow, e.g. a cache's projected velocity).
enum class GivenFlow {
    /// The one of the given and the tracked flow (4.2) that leaves the smaller residual energy (eq. 1), the
    /// decomposition's own measure of a flow that explains the video. A cache's velocity need not describe how its
    /// renders move: the density pattern of the shared steady Blender plume moves at about half of
    /// velocity x dt (docs/animate.md), and residuals left by a flow that misses the motion carry that motion into
    /// the output, whatever the design.
    Best,
    Use,  ///< the given flow, never tracked
    Track ///< the tracked flow, as without one (the paper)
};

struct AnalysisSettings
{
    int features = 100;        ///< Shi-Tomasi features per frame pair (paper 100), >= 1
    int window = 10;           ///< Lucas-Kanade window in pixels (paper 10), 3..64
    int levels = 3;            ///< Lucas-Kanade pyramid levels above the base (Bouguet), 0..6
    double maxRoundTrip = 0.5; ///< drop tracks whose forward-backward round trip misses by more (pixels), > 0
    int rbfStep = 4;           ///< the interpolated flow is evaluated every rbfStep pixels, bilinear between, 1..16
    GivenFlow givenFlow = GivenFlow::Best; ///< v when a flow is given
};

/// Throws ValueError naming the first setting out of range.
void validate(const AnalysisSettings& s);

struct AnalysisStats
{
    int pairs = 0;              ///< consecutive pairs (N - 1)
    int pairsUsed = 0;          ///< pairs with >= 1 kept track (only these enter the average)
    double tracksPerPair = 0.0; ///< mean kept tracks per used pair
    double trackSpeed = 0.0;    ///< mean |displacement| of the kept tracks, pixels per frame (0: none tracked)
    /// The example's speed, pixels per frame (what a Speed Brush fetches): a given flow's mean |v| where it moves
    /// (|v| >= 10% of its 99th percentile); a tracked flow's, the tracks' own mean speed (trackSpeed) when there
    /// are tracks: between and beyond them the interpolant is an extrapolation (phi = r grows linearly away from the
    /// tracks: 4.7 px/frame over a plume start-up's empty background, its tracks 1.6).
    double meanSpeed = 0.0;
    double rmsDifference = 0.0; ///< rms of D_{i+1} - D_i over all pairs and channels
    double rmsResidual = 0.0;   ///< rms of R_i over all pairs and channels
    bool flowGiven = false;     ///< v came from the caller (e.g. a cache's projected velocity), not from tracking
    /// GivenFlow::Best: the rms residual each candidate leaves (as rmsResidual); 0 when it was not compared.
    double rmsResidualGiven = 0.0, rmsResidualTracked = 0.0;
};

struct ExampleDecomposition
{
    ChannelImage average;                ///< A: C channels
    ChannelImage flow;                   ///< v: 2 channels, pixels per frame
    ChannelImage first;                  ///< D_0 = F_0 - A (C channels): with R, eq. 4 rebuilds every frame
    std::vector<ChannelImage> residuals; ///< R_0..R_{N-2}, C channels each
    AnalysisStats stats;
    int frames() const { return int(residuals.size()) + 1; }
};

/// Decomposes the example. `frames` is consumed (the residuals reuse its memory). When `givenFlow`
/// is non-null (2 channels, the frames' size) v is chosen by settings.givenFlow: by default the one of it and the
/// tracked flow that leaves the smaller residuals.
/// Throws ValueError on fewer than 2 frames, frames of different sizes or channel counts, a given flow
/// of the wrong shape, or settings out of range; Cancelled when `progress` asks.
ExampleDecomposition decomposeExample(std::vector<ChannelImage> frames, const AnalysisSettings& settings,
    Progress* progress = nullptr, const ChannelImage* givenFlow = nullptr);

/// One feature tracked from frame `pair` to frame `pair + 1`.
struct FlowTrack
{
    int pair = 0;
    float x = 0.0f, y = 0.0f;   ///< position in frame `pair` (pixels, x right, y down)
    float dx = 0.0f, dy = 0.0f; ///< displacement to the next frame (pixels per frame)
};

/// The mean flow of a sequence alone (section 4.2), e.g. to analyse an output: the frames' own average
/// is removed first. Returns v (2 channels), fills `stats` when given, and `tracks` with the tracks it was
/// interpolated from (those of trackFlow, from the same single tracking pass) when given.
ChannelImage estimateMeanFlow(const std::vector<ChannelImage>& frames, const AnalysisSettings& settings,
    AnalysisStats* stats = nullptr, Progress* progress = nullptr, std::vector<FlowTrack>* tracks = nullptr);

/// The tracks behind estimateMeanFlow, before any interpolation: the Lucas-Kanade tracks of section 4.2 between
/// consecutive frames of the differences from the frames' own average that pass the round-trip and
/// neighbour-consistency checks. A sequence whose rms difference from its mean is at most 1e-4 (a fortieth of an
/// 8-bit level) counts as still and gives no tracks. Throws as decomposeExample.
std::vector<FlowTrack> trackFlow(
    const std::vector<ChannelImage>& frames, const AnalysisSettings& settings, Progress* progress = nullptr);

/// The frames rebuilt from the decomposition by eq. 4: F_i = A + W^i(D_0) + sum_{k<i} W^{i-k-1}(R_k),
/// evaluated incrementally as D_{i+1} = W(D_i) + R_i (the same sum, by linearity of W).
std::vector<ChannelImage> reconstructExample(const ExampleDecomposition& ex);

/// W(I)(x) = I(x - flow(x)): the warp of section 4.3 (bilinear; borders replicated). For tests and
/// for callers that warp once; stages that warp repeatedly build the operator once internally.
ChannelImage warpByFlow(const ChannelImage& image, const ChannelImage& flow);

/// Luminance of a C-channel image: Rec. 709 weights on channels 0..2 when C >= 3, else channel 0.
ChannelImage luminance(const ChannelImage& img);

} // namespace turb
