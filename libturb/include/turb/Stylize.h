/// @file Stylize.h
/// @brief Appearance transfer onto fluid motion: LazyFluids (Jamriška et al. 2015).
///
/// A target animation (alpha masks X_a^t and motion fields F^t) takes its look from an RGBA exemplar
/// Z (a still or a video Z^t). Each frame minimises eq. 7 under the uniformity constraint eq. 5 with
/// an EM pyramid (Kwatra et al. 2005, Wexler et al. 2007): the E-step is the reversed, uniform NNF
/// (UniformNnf.h) or, as an ablation, plain nearest neighbours (Kwatra: NnfMode::Standard); the M-step
/// is voting (Voting.h). Pixels have the 9 channels of eq. 8, compared with the weights of eq. 9:
///   current RGBA (1, 1, 1, 3), blurred alpha (eta), previous frame RGBA (lambda_q x (1, 1, 1, 3)).
/// The previous-frame channels are, on the target side, the previous output forward-warped by
/// F^{t-1} (Warp.h) and, on the exemplar side, Z^{t-1} (Z for a still). Temporal coherence enters only
/// through them: lambda_q = (1 - max(0, X_a^t - warped X_a^{t-1})) lambda (eq. 6), and the first frame
/// (or the first after a cut) has lambda = 0, then by default a pre-roll under the temporal term
/// (StylizeSettings::preroll). Patches match only inside their segment: boundary where
/// the blurred alpha lies in (l, u), interior where it is >= u (section 4.2).
///
/// Colours are straight (unassociated) RGBA in and out, in the exemplar's colour space (never
/// converted). Internally colours are premultiplied by alpha, so fully transparent exemplar pixels
/// compare and vote as (0, 0, 0, 0) whatever colour the file stores under them.
///
/// Beyond the paper: the pyramid, its levels and iterations are ours to choose (defaults measured in
/// docs/stylize.md); every frame starts its coarsest level from random exemplar patches of each target
/// patch's segment (Kwatra et al.'s initialisation; the paper notes uniform usage needs none in
/// particular, and it gives the standard NNF a fair, textured start); optional exemplar rotations by 90/180/270 degrees
/// (section 4.5, Lukáč et al.) and motion blur along the flow (Fig. 9).
///
/// @code
/// turb::StylizeSettings s;                 // the paper's defaults: patch 5, lambda 0.2, eta 3, r 3, l 0.1, u 0.9
/// turb::Stylizer styl(s);
/// for (int t = 0; t < n; ++t) {
///     turb::StylizeFrame in{&alpha[t], t ? &motion[t - 1] : nullptr, &motion[t], &exemplar, nullptr};
///     turb::StylizedFrame out = styl.next(in, &progress);  // out.image: straight RGBA
/// }
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/Progress.h>
#include <turb/RgbaImage.h>
#include <turb/UniformNnf.h>

#include <cstdint>
#include <optional>
#include <vector>

namespace turb {

enum class NnfMode {
    Uniform, ///< reversed NNF with uniform patch usage (LazyFluids section 4.1; the default)
    Standard ///< each target patch takes its nearest exemplar patch (Kwatra et al. 2005): the wash-out ablation
};

struct StylizeSettings
{
    int patchSize = 5;        ///< patch edge in pixels (paper 5), odd, 3..15
    float lambda = 0.2f;      ///< temporal coherence lambda (paper 0.2), >= 0; 0 = frames independent
    float eta = 3.0f;         ///< weight of the blurred-alpha guide eta (paper 3), >= 0
    float alphaWeight = 3.0f; ///< weight of alpha against one colour channel (paper 3), >= 0
    double blurRadius = 3.0;  ///< r: standard deviation in pixels of the blur making the guide alpha (paper 3), > 0
    float lower = 0.1f;       ///< l: boundary where the blurred alpha lies in (l, u) (paper 0.1), [0, u)
    float upper = 0.9f;       ///< u: interior where the blurred alpha >= u (paper 0.9), (l, 1]
    NnfMode nnf = NnfMode::Uniform;
    int levels = 0;          ///< pyramid levels; 0 = as many as keep both images' short side >= 32 px (at most 5)
    /// EM iterations (NNF + vote) on each coarser level, >= 1. 8 and 4 (below) rather than the knee of the energy
    /// curve (4, 2): single frames' interior gradient energy then swings +-2.4% (sd) instead of +-3.9% around its
    /// settled value, which keeps a shot within 15% of its frame 1 (docs/stylize.md), at 1.7x the time.
    int iterations = 8;
    int fineIterations = 4; ///< EM iterations on the finest level, >= 1
    int sweeps = 2;          ///< PatchMatch sweeps per uniform round (standard mode: 2 x sweeps), >= 1
    bool rotations = false;  ///< also use the exemplar rotated by 90, 180 and 270 degrees (section 4.5)
    float motionBlur = 0.0f; ///< shutter: blur along F^t by this fraction of a frame's motion (Fig. 9), >= 0; 0 = none
    std::uint64_t seed = 1;  ///< same seed, same output at any thread count
    /// Beyond the paper: each vote is weighted by exp(-D / (voteWeight x the 75th percentile of D over the level's
    /// matched patches)), D a patch's distance (Wexler et al. 2007's weighted voting), so the patches that fit
    /// dominate where overlapping ones disagree; >= 0, 0 = the plain average (the paper). Measured on the wash-out
    /// target (docs/stylize.md): at 1 the gradient ratio is 0.74 instead of 0.67 from frame 5 on, the std ratio
    /// 0.84-0.90 instead of 0.93-0.95; not the default.
    float voteWeight = 0.0f;
    /// Beyond the paper: from the second frame on, every pyramid level's EM starts from the previous output advected
    /// to this frame (the target's previous-frame guide, reduced to the level) instead of the coarser level's result
    /// enlarged. Later frames then keep frame 1's sharpness and change 2.5x less, but the coherence no longer comes
    /// through the guide channels alone (lambda 0 gives nearly the same output), which the paper's design and issue
    /// 15 require: an option, not the default. false = the paper's coarse-to-fine start on every frame.
    bool startFromPrevious = false;
    /// Beyond the paper: a first frame (or the first after a cut) is synthesised again this many times as a later frame
    /// of a shot held still, its previous output its own last result moved by its own motion F^t, before it is
    /// returned. Under the temporal term (lambda > 0) the interior gradient energy settles about 23% below a frame made
    /// without it within 5 frames (docs/stylize.md); the pre-roll makes frame 1 in that settled state, so the look does
    /// not step between frames 1 and 5. >= 0; 0 = the paper's first frame (lambda = 0); ignored when lambda is 0.
    /// Costs preroll extra syntheses of each first frame.
    int preroll = 4;
};

/// Throws ValueError naming the first setting out of its range.
void validate(const StylizeSettings& s);

/// One target frame's inputs. Images are not owned; all target images share one size.
struct StylizeFrame
{
    const ChannelImage* alpha = nullptr;         ///< X_a^t: 1 channel in [0, 1] (values outside are clamped)
    const ChannelImage* motionIn = nullptr;      ///< F^{t-1} (2 channels, pixels per frame): moves the previous
                                                 ///< output onto this frame; null = first frame or a cut (lambda = 0)
    const ChannelImage* motionOut = nullptr;     ///< F^t, only for motion blur; may be null
    const RgbaImage* exemplar = nullptr;         ///< Z^t: straight RGBA
    const RgbaImage* exemplarPrevious = nullptr; ///< Z^{t-1} of a video exemplar; null = a still (Z^t itself)
    std::optional<int> number;                   ///< the frame's number: its random draws follow it (none: its
                                                 ///< place in the run, 0 for the first frame given)
};

/// What a frame's synthesis measured (the numbers `vdbturb stylize --json` prints).
struct StylizeStats
{
    std::vector<SegmentUsage> usage;      ///< exemplar patch usage at the finest level's last E-step, per segment
    double coverage = 0.0;                ///< fraction of exemplar patches used at least once, all segments
    int rounds = 0;                       ///< reversed-NNF retrieval rounds, summed over the frame
    double energy = 0.0;                  ///< eq. 7 per target patch at the finest level's last E-step (mean D)
    double stdRatio = 0.0;                ///< interior luminance standard deviation, output / exemplar
    double gradientRatio = 0.0;           ///< interior mean |grad luminance|^2, output / exemplar
    std::optional<double> temporalChange; ///< mean |X^t - warped X^{t-1}| (premultiplied RGBA, per channel) where
                                          ///< lambda_q / lambda >= 0.5 and X_a^t >= 0.05; none on a first frame
    double temporalPixels = 0.0;          ///< fraction of target pixels in that region
    bool shotStart = false;               ///< a first frame, or the first after a cut (no previous output to follow)
    int preroll = 0;                      ///< pre-roll syntheses run before this frame was returned (shot starts)
    double iou = 0.0;                     ///< IoU of (output alpha >= 0.5) with (target alpha >= 0.5)
    std::vector<double> boundaryGradient; ///< histogram of |grad alpha| in the target's boundary segment
                                          ///< (16 bins of 1/32 per pixel, the last open), normalised
    std::vector<double> exemplarBoundaryGradient; ///< the same over the exemplar's boundary segment
    double boundaryGradientMatch = 0.0;           ///< histogram intersection of the two, [0, 1]; 1 = identical
    int levels = 0;                               ///< pyramid levels used
    int width = 0, height = 0;                    ///< target size
    double secondsGuides = 0.0, secondsNnf = 0.0, secondsVote = 0.0, secondsWarp = 0.0, secondsStats = 0.0;
};

struct StylizedFrame
{
    RgbaImage image; ///< straight RGBA, the exemplar's colour space
    StylizeStats stats;
};

/// Synthesises a sequence frame by frame, keeping the previous output for the temporal guide.
class Stylizer
{
public:
    /// Throws ValueError on settings out of range.
    explicit Stylizer(const StylizeSettings& settings);

    /// Synthesises the next frame. Throws ValueError naming the problem when inputs are missing or of
    /// mismatched sizes, the exemplar is smaller than a patch or has no usable alpha (no boundary or no
    /// interior segment that the target needs); Cancelled when `progress` asks.
    StylizedFrame next(const StylizeFrame& frame, Progress* progress = nullptr);

    /// Forgets the previous output: the next frame starts a new shot (lambda = 0).
    void reset();

    const StylizeSettings& settings() const { return mSettings; }

private:
    StylizeSettings mSettings;
    ChannelImage mPrevious; // previous output, premultiplied RGBA; empty before the first frame
    int mFrames = 0;
};

/// Luminance statistics of an image's interior (blurred alpha >= upper, with the settings' blur):
/// standard deviation of Y = 0.2126 R + 0.7152 G + 0.0722 B and mean |grad Y|^2 (central differences).
struct InteriorStats
{
    double stdLuminance = 0.0, gradientEnergy = 0.0;
    long long pixels = 0;
};
InteriorStats interiorStats(const RgbaImage& img, const StylizeSettings& s);

} // namespace turb
