/// @file Fluidymation.h
/// @brief Stylizing an animation with the natural dynamics of an artistic medium: Fluidymation
///        (Platkevič, Curtis, Sýkora 2020), the `--method fluidymation` of `vdbturb stylize`.
///
/// A moving exemplar (l_S RGB frames S^rgb of ink or paint spreading, with binary masks S^mask and flows
/// S^flow) gives its look *and its motion* to a target animation (l_T binary masks T^mask and flows
/// T^flow). Frame by frame, every target pixel q picks a source patch p = (i, x, y) from *any* exemplar
/// frame, turned by theta = T^rot(q), minimising E = sum_q min_p D(p, q) with (eq. 2)
///     D = sum over the patch's pixel pairs (p', q') of
///         D^tex + w^bound D^bound + w^dir D^dir + w^ext D^ext + w^temp m(q') D^temp + w^uni Omega(p'),
/// - D^tex   = |S^rgb(p') - T^rgb(q')|^2;
/// - D^bound = (S^shape(p') - T^shape(q'))^2, the masks blurred by a Gaussian of radius b (sigma = b / 3);
/// - D^dir   = c min(|tan(S_theta^flow(p') + theta - T_theta^flow(q'))|, dirClamp): 0 for parallel and
///             antiparallel flows, the clamp for perpendicular ones. Rule for zero flow: c =
///             min(1, |S^flow| / eps) min(1, |T^flow| / eps), so a flow slower than eps has (nearly) no
///             direction and costs nothing;
/// - D^ext   = (S+ext - T+ext)^2 + (S-ext - T-ext)^2, each side's extents divided by its own unit
///             (by default its 95th percentile: relative motion amounts, so a target that moves ten times
///             more than the exemplar still maps its most-moving parts to the exemplar's; set both units
///             to one value for absolute matching), with T+ and T- swapped when the rotated source flow and
///             the target flow are opposite (patch means). Delta i* always uses absolute pixels;
/// - D^temp  = |S^rgb(p') - T^temp(q')|^2, T^temp voted from the previous frame's NNF with every source
///             frame index shifted by Delta i* (section 3.4; `bestTimeShift`), modulated per pixel by
///             m = 0 where T^mask(j-1) = 0, else 1 - smoothstep(|T^dist - S^dist(i + Delta i, x, y)|, m_l, m_u).
///             As printed the paper's m = smoothstep(...) would *raise* the temporal weight where source and
///             target distances disagree, the case its text says must be relaxed (the patch would lag):
///             we use 1 - smoothstep (`temporalModulation`);
/// - Omega(p') = Omega*(p') / (n^2 omega*): Omega* counts the target patches whose rotated
///             n x n x (2r+1) cuboid covers source voxel p', omega* = n^2 (2r+1) |T_seg| / |S_seg| per
///             segment (boundary: within `boundaryWidth` pixels inside the mask and the ring of patch
///             centres outside it; interior: the rest), so a patch used as often as uniform usage allows
///             costs w^uni (section 3.5, after Kaspar et al. 2015). Rebuilt before every PatchMatch sweep.
///
/// Optimisation (section 3.6, Algorithms 1 and 2): an EM pyramid of floor(log2(d_min / n)) levels; the
/// E-step is generalized PatchMatch over (i, x, y, theta) (propagation with rotated offsets, random
/// search in x, y and i, uniform draws, the neighbouring source frames), where every sampled (i, x, y)
/// is tried only with the rotations that minimise D^dir (the patch-mean flows aligned, or opposite); the
/// M-step is voting of rotated patches (Voting.h). The coarsest level of frame 1 starts at random; every
/// other start is UPSCALENNF of the coarser level, merged per pixel (smaller D wins) with DOWNSCALENNF
/// of the previous frame's shifted NNF (RotatedNnf.h).
///
/// Beyond or besides the paper (all in docs/stylize.md): the sign of Appendix A's flow (MotionGuides.h);
/// the smoothstep direction; the clamp and zero-flow rule of D^dir; the extent units; rotations
/// quantised to 64 steps with nearest-pixel sampling in the search (bilinear in voting); iteration
/// counts. Output alpha is the voted exemplar mask.
///
/// @code
/// turb::MotionSequence ex(w, h), target(W, H);
/// for (...) ex.addFrame(exMask[i]);  ex.finish();          // exemplar flows estimated (Appendix A)
/// for (...) target.addFrame(tMask[j], &tFlow[j]);  target.finish();
/// turb::Fluidymator f(turb::FluidySettings{}, exRgb, ex, target);
/// for (int j = 0; j < target.frames(); ++j) {
///     turb::FluidyFrame out = f.next();                    // out.image: RGBA, out.rotation: T^rot
/// }
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/MotionGuides.h>
#include <turb/Progress.h>
#include <turb/RgbaImage.h>
#include <turb/RotatedNnf.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace turb {

struct FluidySettings
{
    int patchSize = 5; ///< n: patch edge in pixels (Table 1: 5), odd, 3..15
    double boundaryBlur =
        30.0; ///< b: radius in pixels of the Gaussian making S/T^shape (Table 1: 30; sigma = b / 3), > 0
    int cuboidFrames =
        5; ///< r: Omega's cuboids span 2r + 1 source frames (Table 1: 5), 0..50; the exemplar needs >= 2r + 1 frames
    float wBound = 4.0f;       ///< w^bound (Table 1: 4), >= 0; 0 = ablation
    float wExt = 0.25f;        ///< w^ext (Table 1: 0.25), >= 0
    float wDir = 1.0f;         ///< w^dir (Table 1: 1), >= 0
    float wTemp = 4.0f;        ///< w^temp (Table 1: 4), >= 0
    float wUni = 1.0f;         ///< w^uni (Table 1: 1), >= 0
    double mLower = 0.01;      ///< m_l as a fraction of d, the target's larger side (Table 1: 0.01), >= 0
    double mUpper = 0.1;       ///< m_u as a fraction of d (Table 1: 0.1), > mLower
    float dirClamp = 10.0f;    ///< D^dir clamp of |tan| per pixel pair (10: 84 degrees apart), > 0
    float flowEpsilon = 0.05f; ///< eps: pixels per frame below which a flow's direction fades out of D^dir, > 0
    double extentScale =
        0.0; ///< pixels: the exemplar's extents enter D^ext in these units; 0 = their 95th percentile, >= 0
    double targetExtentScale = 0.0; ///< pixels: the target's extent unit; 0 = the target's 95th percentile, >= 0
    int boundaryWidth = 0;          ///< pixels of the boundary segment inside the mask, at each level; 0 = n, >= 0
    int levels = 0;                 ///< pyramid levels; 0 = floor(log2(d_min / n)) (section 3.6), 0..8
    int iterations = 3;             ///< EM iterations (FINDNNF + VOTE) on each coarser level, >= 1
    int fineIterations = 2;         ///< EM iterations on the finest level, >= 1
    int sweeps = 2;                 ///< PatchMatch sweeps per FINDNNF on coarser levels, >= 1
    int fineSweeps = 1;             ///< PatchMatch sweeps per FINDNNF on the finest level, >= 1
    int randomCandidates = 2;       ///< uniform draws from all source centres per pixel and sweep, >= 0
    bool reusePrevious = true; ///< start from the previous frame's shifted NNF (section 3.6); false = random each frame
    std::uint64_t seed = 1;    ///< same seed, same frames at any thread count
};

/// Throws ValueError naming the first setting out of its range.
void validate(const FluidySettings& s);

/// The pyramid's level count (section 3.6): floor(log2(d_min / n)), at least 1, where d_min is the
/// smallest side of the source and target frames; the coarsest level's short side lies in [2n, 4n).
int fluidyLevels(int sourceWidth, int sourceHeight, int targetWidth, int targetHeight, int patchSize);

/// D^dir of one pixel pair with both flows defined: min(|tan(sourceAngle + rotation - targetAngle)|, clamp).
float dirCost(double sourceAngle, double rotation, double targetAngle, float clamp);

/// The temporal weight's modulation m (section 3.4) where the previous mask covers the pixel:
/// 1 - smoothstep(v, lower, upper): 1 for v <= lower, 0 for v >= upper, 3t^2 - 2t^3 between (t = (v-l)/(u-l)).
double temporalModulation(double distanceDifference, double lower, double upper);

/// Delta i* (section 3.4) at one source pixel: the shift of source frame i whose motion amount best
/// matches the target's `targetIncrement` (T+ext(j) - T+ext(j-1), pixels). plus[k * stride] and
/// minus[k * stride] are S+ext and S-ext of source frame k at the pixel (k in [0, frames)). Forward
/// (opposite = false): argmin over Delta i >= 0 of |increment - (S+ext(i + Delta i) - S+ext(i))|;
/// opposite flows: argmin over Delta i <= 0 of |increment - (S-ext(i + Delta i) - S-ext(i))|. Ties go to
/// the smallest |Delta i|; the result keeps i + Delta i inside [0, frames).
int bestTimeShift(
    const float* plus, const float* minus, size_t stride, int frames, int i, double targetIncrement, bool opposite);

/// The terms of D(p, q) for one pair of patches, weighted (Fluidymator::terms).
struct FluidyTerms
{
    double tex = 0.0, bound = 0.0, dir = 0.0, ext = 0.0, temp = 0.0, uni = 0.0;
    bool swapped = false; ///< T+ext and T-ext were swapped (opposite flows)
    double total() const { return tex + bound + dir + ext + temp + uni; }
};

/// What a frame's synthesis measured (the numbers `vdbturb stylize --method fluidymation --json` prints).
struct FluidyStats
{
    int frame = 0, levels = 0, width = 0, height = 0;
    long long maskedPixels = 0;       ///< target mask pixels
    long long centres = 0;            ///< target patch centres (the mask and a ring of n/2 pixels around it)
    FluidyTerms energy;               ///< mean weighted terms per centre at the finest level's last E-step
    std::optional<double> meanAbsSin; ///< direction: mean |sin| of (rotated source flow, target flow) where both move
                                      ///< (>= movingSpeed); none if none do
    long long movingPixels = 0;
    double speedCorrelation = 0.0;  ///< extent: Pearson correlation of |T^flow(q)| and |S^flow(p)| over mask pixels
    double extentCorrelation = 0.0; ///< Pearson correlation of T+ext(q) and S+ext(p) over mask pixels
    std::optional<double> stationaryChange; ///< flicker: mean |T^j - T^{j-1}| (RGB) where both masks hold and the flow
                                            ///< is < stillSpeed; none on a shot's first frame
    long long stationaryPixels = 0;
    double coverage = 0.0; ///< fraction of source patch centres (i, x, y) covered by some target cuboid (Omega* > 0)
    double distinctPatches = 0.0; ///< distinct source patches used / target centres
    double contrastRatio = 0.0;   ///< luminance std inside the target mask / inside the exemplar masks (all frames)
    double meanShift = 0.0;       ///< mean Delta i* of the reused previous NNF
    double reusedFraction = 0.0;  ///< finest-level centres whose start came from the previous frame (merge)
    double secondsGuides = 0.0, secondsSearch = 0.0, secondsVote = 0.0, secondsOmega = 0.0, secondsStats = 0.0;
};

/// Thresholds of the measurements in FluidyStats, pixels per frame.
constexpr double kMovingSpeed = 0.2, kStillSpeed = 0.05;

struct FluidyFrame
{
    RgbaImage image;       ///< RGB voted from the exemplar (its colour space), alpha the voted exemplar mask
    ChannelImage rotation; ///< T^rot: 2 channels, theta in radians [0, 2 pi) and 1 where a patch is centred (else 0, 0)
    RotatedNnf nnf;        ///< the finest level's field: (i, x, y, theta step) per target pixel
    FluidyStats stats;
};

/// Synthesises the target frame by frame (Algorithm 1).
class Fluidymator
{
public:
    /// Builds the exemplar's pyramid. `exemplarRgb`: l_S images of 3 channels (RGB; more are ignored),
    /// the size of `exemplarMotion`'s frames; both motion sequences finished. `target` must outlive the
    /// object. Throws ValueError on settings out of range, frame counts that differ, an exemplar shorter
    /// than 2r + 1 frames, an exemplar or target smaller than the patch, an empty exemplar mask, or a
    /// target whose masks are empty in every frame.
    Fluidymator(const FluidySettings& settings, const std::vector<ChannelImage>& exemplarRgb,
        const MotionSequence& exemplarMotion, const MotionSequence& target, Progress* progress = nullptr);
    ~Fluidymator();
    Fluidymator(const Fluidymator&) = delete;
    Fluidymator& operator=(const Fluidymator&) = delete;

    /// Synthesises the next target frame (0, 1, ...). A frame with an empty mask gives a transparent
    /// image and starts a new shot. Throws ValueError past the last frame; Cancelled when asked.
    FluidyFrame next(Progress* progress = nullptr);

    /// The weighted terms of D between source patch p and the target patch at (x, y), at the finest
    /// level of the frame last synthesised (for tests and inspection). Throws ValueError before the
    /// first frame or for p outside the exemplar's patch centres.
    FluidyTerms terms(const PatchRef& p, int x, int y) const;

    int levels() const;
    int frame() const;                ///< frames synthesised so far
    double extentScale() const;       ///< the exemplar's D^ext unit in use, pixels
    double targetExtentScale() const; ///< the target's D^ext unit in use, pixels
    const FluidySettings& settings() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace turb
