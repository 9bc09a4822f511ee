/// @file Animate.h
/// @brief Animating a still picture of fluid from a video example (Okabe, Anjyo, Igarashi, Seidel 2009):
///        the whole pipeline of Fig. 2, and its synthesis steps (sections 5.4 and 5.5).
///
/// 1. The example is decomposed into A, v and R (VideoAnalysis.h).
/// 2. The target's flow is designed from strokes or a dense flow and refined by its gradients
///    (FlowDesign.h); W' warps by the designed flow.
/// 3. The residuals are transferred, the same matches for every frame (ResidualTransfer.h), and the Clone Brush's
///    strokes, if any, paste the example's residuals around their source strokes over them (CloneBrush.h, 5.3).
/// 4. The target average A' = Gaussian_{w_a}(motion blur of the target along the designed flow with
///    shutter Sh) (5.4). Sh is a length in frames of the designed flow's motion (the paper's Sh is a
///    shutter time in ms of its own tool, which does not carry over), w_a a standard deviation in pixels.
/// 5. Eq. 7, D'_i = sum_{k=i-tau}^{i-1} W'^{i-k-1}(R'_k) for tau <= i < N, computed incrementally: every
///    live term is warped once per frame (no term is recomputed from its residual); eq. 8 adjusts
///    contrast and brightness, D''_i = (D'_i - <D'>) alpha + beta with beta = mean(C),
///    alpha = sigma_C / sigma_D', C = target - A', per colour channel, over all frames and pixels
///    (weighted by the matte when there is one); F'_i = A' + D''_i. N - tau frames come out.
/// 6. Every frame is histogram-matched to the target (HistogramMatch.h).
/// With a matte, pixels outside it keep the target: out = m F + (1 - m) target, before and after the
/// matching.
///
/// @code
/// turb::AnimateSettings s;                 // the paper's defaults: w_f 12, tau 16, HM Rep 3, grid by resolution
/// turb::AnimateInput in;
/// in.exampleFrames = std::move(frames);    // C channels each
/// in.target = still;  in.strokes = &strokes;
/// turb::AnimateStats st = turb::animate(std::move(in), s, [&](const turb::AnimatedFrame& f) { write(f); }, &progress);
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/CloneBrush.h>
#include <turb/FlowDesign.h>
#include <turb/HistogramMatch.h>
#include <turb/Progress.h>
#include <turb/ResidualTransfer.h>
#include <turb/VideoAnalysis.h>

#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace turb {

/// Approximation of the target's average image (5.4).
struct AverageSettings
{
    double shutter = 16.0; ///< Sh: motion-blur length in frames of the designed flow, >= 0 (0 = none; default measured,
                           ///< docs/animate.md)
    double wa =
        4.0; ///< w_a: standard deviation in pixels of the Gaussian after the motion blur, >= 0 (default measured)
};

/// How section 5.6's histogram matching meets a sequence.
enum class HmApply {
    PerFrame, ///< every frame matched on its own (the paper)
    /// Beyond the paper, for smooth stills such as renders of smoke: the mean frame A' + mean_i D''_i is matched
    /// once, and every frame gets that same correction, HM(mean) - mean, then its own per-cell moments
    /// (cellMoments), so every frame's and cell's mean and std stay exact. Matching every frame to a still with
    /// little high frequency flattens the moving detail (the paper's "viscosity", section 7): the tracked motion
    /// of such outputs fell to 0.2-0.6 of the design (docs/animate.md); here the moving detail keeps eq. 8's
    /// contrast. On a textured still the correction lifts the mean frame's faint detail to the still's and
    /// holds it still: a static speckle, and the temporal std falls (0.69 of a dynamic texture's against 0.96).
    /// One match instead of one per frame: about 4x faster.
    Sequence
};

struct AnimateSettings
{
    AnalysisSettings analysis;  ///< example decomposition (features 100, window 10)
    StrokeSettings strokes;     ///< stroke interpolation (defaultSpeed is replaced by the example's mean speed)
    RefineSettings refine;      ///< w_f 12, gradient orientation, floor
    bool refineFlow = true;     ///< refine the rough field by the target's gradients (5.1)
    ResidualTransferSettings transfer; ///< residual transfer (16 px patches, search at 2x downsampling)
    CloneSettings clone;        ///< the Clone Brush's control points (every 2 px along the strokes)
    AverageSettings average;    ///< A' (Sh, w_a)
    int tau = 16;               ///< lifetime of a residual in frames (paper 16), >= 1
    bool histogramMatch = true; ///< section 5.6 (off: F' as synthesised)
    HistogramMatchSettings hm;  ///< HM Rep 3, grid by resolution, steerable (or the Laplacian preview)
    HmApply hmApply = HmApply::PerFrame; ///< every frame matched (the paper), or the sequence's mean frame once
    int batch = 4;                       ///< frames histogram-matched concurrently (memory: one frame each), >= 1
};

/// Throws ValueError naming the first setting out of range.
void validate(const AnimateSettings& s);

struct AnimateInput
{
    std::vector<ChannelImage> exampleFrames; ///< F_0..F_{N-1}: 1..4 channels, one size; consumed
    const ChannelImage* exampleFlow =
        nullptr;                         ///< optional v (2 channels, example size): e.g. a cache's projected velocity
    ChannelImage target;                 ///< the still: the example's channel count
    const ChannelImage* matte = nullptr; ///< optional fluid matte (1 channel, target size, [0, 1])
    const std::vector<FlowStroke>* strokes = nullptr; ///< the flow design, or:
    const ChannelImage* designedFlow = nullptr; ///< a dense designed flow (2 channels, target size, pixels per frame)
    /// Optional Clone Brush strokes (5.3): sources in example pixels, destinations in target pixels, applied in order.
    const std::vector<CloneStroke>* clones = nullptr;
};

/// One output frame.
struct AnimatedFrame
{
    int index = 0;              ///< 0 .. N - tau - 1
    int exampleIndex = 0;       ///< i of eq. 7 (tau .. N - 1)
    ChannelImage image;         ///< the target's channels
    double meanError = 0.0;     ///< max over channels of |mean(out) - mean(target)| / max(|mean(target)|, 0.01)
    double stdError = 0.0;      ///< max over channels of |std(out) - std(target)| / max(std(target), 0.01)
    double cellMeanError = 0.0; ///< the same per histogram-matching cell, worst cell
    double cellStdError = 0.0;
    double seconds = 0.0; ///< synthesis + matching of this frame
};

struct AnimateStats
{
    AnalysisStats analysis;
    ResidualTransferStats transfer;
    int frames = 0;                            ///< N - tau
    int gridCols = 0, gridRows = 0;            ///< histogram matching grid
    std::vector<double> alpha, beta;           ///< eq. 8 per channel
    std::vector<double> meanD, sigmaD, sigmaC; ///< <D'>, sigma_D', sigma_C per channel
    double designMeanSpeed = 0.0;              ///< mean |designed flow| inside the matte, pixels per frame
    double secondsAnalysis = 0.0, secondsDesign = 0.0, secondsTransfer = 0.0, secondsAverage = 0.0,
           secondsSynthesis = 0.0, secondsMatching = 0.0;
};

/// Intermediate images for inspection (`vdbturb animate --dump`): called with a name and, for
/// sequences, an index (-1 otherwise). Names: "A" (average), "v" (example flow), "R" (residual k),
/// "rough" (Phi_s Phi_o), "refined" (the designed flow), "gradient" (G), "clone" (the Clone Brush's matte, when
/// there are clone strokes), "Aprime" (A'),
/// "Rprime" (transferred residual k), "Dsecond" (D''_i before composition and matching).
using InspectFn = std::function<void(const std::string& name, int index, const ChannelImage& image)>;

/// The whole pipeline. `sink` receives the N - tau frames in order (on the calling thread).
/// Throws ValueError when the example is shorter than tau + 2 frames, its frames differ in size, the
/// target has no strokes or designed flow (or both), a stroke or clone stroke is malformed or outside its image, images
/// have mismatched sizes or channel counts, or a setting is out of range; Cancelled when asked.
AnimateStats animate(AnimateInput input, const AnimateSettings& settings,
    const std::function<void(const AnimatedFrame&)>& sink, Progress* progress = nullptr, const InspectFn& inspect = {});

/// A' (5.4): the target blurred along the flow over Sh frames of motion (Warp.h's line convolution),
/// then by a Gaussian of standard deviation w_a. With a `matte` (1 channel, target size) the blur is
/// normalised, blur(m T) / blur(m), so still parts around the fluid do not bleed into its average.
ChannelImage approximateAverage(const ChannelImage& target, const ChannelImage& flow, const AverageSettings& settings,
    const ChannelImage* matte = nullptr);

/// Eq. 7, incrementally: push R'_0, R'_1, ...; after R'_{i-1} it returns D'_i once i >= tau (else
/// an empty image). Each push warps every live term once (at most tau - 1 warps).
class DifferenceSynthesizer
{
public:
    /// `flow`: the designed flow W' warps by (2 channels). Throws ValueError on tau < 1.
    DifferenceSynthesizer(const ChannelImage& flow, int tau);
    ~DifferenceSynthesizer();
    ChannelImage push(const ChannelImage& residual);
    int pushed() const { return mPushed; }

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
    int mTau = 1, mPushed = 0;
};

/// Eq. 8's parameters per channel, from the synthesised differences and C = target - A'.
struct ContrastAdjustment
{
    std::vector<double> mean, alpha, beta; ///< <D'>, sigma_C / sigma_D', mean(C)
    std::vector<double> sigmaD, sigmaC;
    /// D'' = (D' - <D'>) alpha + beta, in place.
    void apply(ChannelImage& d) const;
};

/// Computes eq. 8's parameters over all frames of `differences` and pixels (weighted by `matte` when
/// given). sigma_D' = 0 gives alpha = 0.
ContrastAdjustment contrastAdjustment(
    const std::vector<ChannelImage>& differences, const ChannelImage& c, const ChannelImage* matte = nullptr);

} // namespace turb
