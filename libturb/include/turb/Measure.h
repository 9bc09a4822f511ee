/// @file Measure.h
/// @brief The quality numbers of an up-res (docs/measure.md): lf_err,
///        hf_ratio, div_rel, block, tcoh and the energy spectra, per frame.
///
/// Terms used throughout:
/// - f: the resolution ratio target voxel / output voxel (an integer; integerRatio throws otherwise).
/// - the refined target lattice: Lattice::refined(f) of the target over refineBox(target box, f) (refineDomain,
/// refinedLattice: one layer for a 2D target). The
///   output is brought onto it first (see Alignment), so fine voxel I lies in coarse voxel floor(I / f).
/// - up_f: cell-centred trilinear upsample; boxdown_f: mean over f^3 blocks (Resample.h).
/// - U_h = U_out - up_f(U_target) on the refined target lattice: the detail an up-res added.
/// - smoke region: density > threshold. On the output lattice from the output's density (or, when the
///   output has none, from up_f of the target's); on the coarse lattice from the target's density.
///
/// @code
/// turb::MeasureInput in;
/// in.output = &out; in.target = &tgt; in.source = &src;     // source optional
/// in.previousOutput = &out0; in.previousTarget = &tgt0;     // frame - 1, optional (tcoh)
/// turb::FrameMeasures m = turb::measureFrame(in, turb::MeasureSettings{});
/// if (m.lfErr) std::cout << *m.lfErr;
/// @endcode
#pragma once

#include <turb/Advect.h>
#include <turb/Field.h>
#include <turb/Farm.h>
#include <turb/Frame.h>
#include <turb/Progress.h>
#include <turb/Spectrum.h>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace turb {

/// How output voxels are matched to the refined target lattice.
enum class Alignment {
    /// Index when the output's box is exactly refineBox(target box, f) but the world transforms do not
    /// nest (Blender/Mantaflow put voxel 0's centre at the origin at every resolution, so its 32^3 and
    /// 128^3 caches of one domain disagree by (f-1)/2 fine voxels in world space); World otherwise.
    Auto,
    /// Trust the transforms: sample the output at the refined target voxels' world positions
    /// (a copy when the lattices nest up to a whole-voxel shift, else trilinear; zero outside the output).
    World,
    /// Trust the indices: output voxel I is refined target voxel I; translations are ignored.
    Index
};

const char* alignmentName(Alignment a);

/// air_detail's still air: coarse cells more than this many cells (Euclidean, centre to centre) from the
/// target's smoke cells.
constexpr double kAirCells = 4.0;
/// The quantile of |curl U| that vort_peak reports: the peak without its hottest voxels (0.1% of the smoke).
constexpr double kVortPeakQuantile = 0.999;

struct MeasureSettings
{
    float densityThreshold = 0.01f;   ///< smoke region is density > this (docs/measure.md: 0.01); >= 0
    int patchSize = 0;                ///< seam spacing for `block`, in output voxels; 0 = metadata "vdbturb_patch_size"
                                      ///< of the output frame; block is not computed when neither gives >= 2
    std::optional<Coord> patchOrigin; ///< an output voxel where a patch starts (seam planes at origin[a] + n *
                                      ///< patchSize); unset = metadata "vdbturb_patch_origin" ("x,y,z"), else (0,0,0)
    std::vector<TileBorder> tileBorders; ///< space-tile border planes (output voxels) for tile_block and tile_div_rel;
                                         ///< empty = metadata "vdbturb_tile_borders" of the output frame (farm join)
    int tileBorderWidth = 0; ///< output voxels either side of a border plane that tile_* cover; 0 = 2 patch sizes
                             ///< (16 without one): the issue's "within 2 patches of a tile border"
    double dt = 0.0;         ///< time per frame for tcoh's advection; 0 = the previous target frame's dt. tcoh
                             ///< advects over (frame - previous frame) times this: the real time between them
    Alignment alignment = Alignment::Auto; ///< how output voxels meet the refined target lattice
    bool spectra = true;                   ///< compute E(k) of output, target and source
    bool structure = true;                 ///< aniso, isotropy, lattice, vort_peak (source figures need a source)
    int upAxis = 2;                        ///< the world axis pointing up (0 x, 1 y, 2 z), for detail_profile
    SpectrumSettings spectrum;             ///< window and mean removal of the spectra
    AdvectSettings advect;                 ///< scheme advecting U_h(f-1) for tcoh (default BFECC + clamp)
    int threads = 0;                       ///< worker threads, 0 = all; results are identical at any count
};

/// What measureFrame needs. Frames are not copied; all pointers must outlive the call.
struct MeasureInput
{
    const Frame* output = nullptr; ///< required: the up-res (velocity, density or both; density only gives the
                                   ///< density numbers, as of Blender's noise up-res)
    const Frame* target = nullptr; ///< required: the low-res frame it was made from (velocity, density)
    const Frame* source = nullptr; ///< optional: the high-res source (velocity, density): hf_ratio, div_rel_source
    const Frame* previousOutput = nullptr; ///< optional: the previous processed output (any earlier frame), for tcoh
    const Frame* previousTarget = nullptr; ///< optional: the target of that same earlier frame, for tcoh
    const Frame* previousSource = nullptr; ///< optional: an earlier source frame, for tcoh_source
};

/// One frame's numbers. A metric that cannot be computed for this frame (no source, no smoke, no patch
/// size, no previous frame) is empty, and `notes` says why.
struct FrameMeasures
{
    int frame = 0;
    int ratio = 0;                          ///< f = target voxel / output voxel
    int sourceRatio = 0;                    ///< target voxel / source voxel (0 without a source)
    Alignment alignment = Alignment::World; ///< the alignment used (World or Index, never Auto)
    Vec3d alignmentOffset{0.0};             ///< output lattice origin minus refined target origin, in output voxels
    bool resampled = false;                 ///< the output was trilinearly resampled (World, not nesting)
    size_t smokeVoxels = 0;                 ///< output voxels in the smoke region
    size_t smokeCells = 0;                  ///< coarse (target) cells in the smoke region

    std::optional<double> lfErr;             ///< |boxdown(U_out - up(U_t))| / |boxdown(up(U_t))| over smoke cells
    std::optional<double> hfEnergy;          ///< E_hf(U_out) = mean |U - up(boxdown(U))|^2, world units^2
    std::optional<double> hfEnergySource;    ///< E_hf(U_src) with the source's ratio to the target
    std::optional<double> hfRatio;           ///< hfEnergy / hfEnergySource
    std::optional<double> divRel;            ///< rms(div U_out) / rms(|grad U_out|), central differences
    std::optional<double> divRelSource;      ///< the same of the source, for reference
    std::optional<double> block;             ///< mean |dU_h| across seam planes / mean elsewhere
    std::optional<double> tileBlock;         ///< block over the smoke within tileBorderWidth of a tile border plane
    std::optional<double> tileDivRel;        ///< div_rel over the same voxels
    std::optional<double> tileHfRatio;       ///< hf_ratio over the same voxels: the detail's strength at the borders
                                             ///< (a linear fade of independent tiles' details would dip it)
    size_t tileVoxels = 0;                   ///< output voxels of the smoke near a tile border
    int patchSize = 0;                       ///< the seam spacing block used (0 = none)
    Coord patchOrigin{0};                    ///< the patch origin block used, in output voxels
    std::optional<double> tcoh;              ///< rms(U_h(f) - advect(U_h(f-1), U_t(f-1), dt)) / rms(U_h(f))
    double dt = 0.0;                         ///< the time tcoh advected over: frame gap x time per frame (0 = no tcoh)
    std::optional<double> tcohSource;        ///< the source's own: its detail U_s - up(boxdown(U_s)) carried by
                                             ///< its boxdown velocity, for reference
    std::optional<double> massRatio;         ///< output density mass / target density mass (sum of density x voxel
                                             ///< volume over each whole frame); 0.9-1.1 keeps the target's smoke
    std::optional<double> peakDensity;       ///< the output's largest density
    std::optional<double> peakRatio;         ///< peakDensity / the target's largest density (<= 1.05: no pile-up)
    std::optional<double> densityErr;        ///< rms(boxdown_f(D_out) - D_t) / rms(D_t) over the target's smoke cells:
                                             ///< the output keeps the target's density at its scale (<= 0.1)
    std::optional<double> densityImprint;    ///< densityImprint(): the target's cell faces printed into the output
                                             ///< density (about 1: none; a blocky staircase silhouette: well above 1)
    std::optional<double> densityFray;       ///< densityFray() of the output (on the refined target lattice)
    std::optional<double> densityFraySource; ///< the same of the source at its own ratio
    std::optional<double> densityFrayRatio;  ///< densityFray / densityFraySource: well above 1 for a silhouette
                                             ///< frayed into fine hairs where the source's is soft
    std::optional<double> edgeCrispness;       ///< edgeCrispness() of the output (on the refined target lattice)
    std::optional<double> edgeCrispnessSource; ///< the same of the source at its own ratio
    std::vector<std::optional<double>> detailProfile;       ///< detailProfile() of the output over its smoke
    std::vector<std::optional<double>> detailProfileSource; ///< the same of the source over its smoke
    std::optional<double> detailProfileRatio; ///< detailProfileRatio(): the worst height band against the source's
    std::optional<double> aniso;       ///< detail anisotropy along the target's mean flow (detailAnisotropy): about 1
                                       ///< for isotropic detail, well below 1 for streaks stretched along the flow
    std::optional<double> anisoSource; ///< the same of the source's detail, along the same direction
    std::optional<double> anisoRatio;  ///< aniso / anisoSource: 0.8-1.25 keeps the source's structure
    std::optional<double> detailScale; ///< highBandScale of the output's detail, world units
    std::optional<double> detailScaleSource; ///< the same of the source's detail
    std::optional<double> detailScaleRatio;  ///< detailScale / detailScaleSource: well below 1 for detail finer than
                                             ///< the source's
    std::optional<double> isotropy; ///< detailIsotropy of the output: direction-free, catches streaks along any axis
    std::optional<double> isotropySource; ///< the same of the source
    std::optional<double> lattice;        ///< latticeImprint() of the output on its patch lattice (needs patchSize)
    std::optional<double> latticeSource;  ///< the same of the source on a lattice of the same size: the chance level
    std::optional<double> vortPeak;       ///< vorticityPeak(U_out, 0.999) over the output's smoke, 1/time unit
    std::optional<double> vortPeakSource; ///< the same of the source
    std::optional<double> vortPeakRatio;  ///< vortPeak / vortPeakSource: hot spots hotter than the source's
    std::optional<double> airDetail;      ///< rms(U_h) over still air (refined voxels whose coarse cell lies more than
                                          ///< kAirCells cells from the target's smoke cells) / rms(U_h) over the smoke
                                          ///< cells, both within the output's box as read: detail that leaks into
                                          ///< air far from the smoke (<= 0.1)

    double targetNyquist = 0.0;                              ///< pi / target voxel size, radians per world unit
    Spectrum spectrumOutput, spectrumTarget, spectrumSource; ///< empty when not computed
    std::vector<std::string> notes;                          ///< why a metric is missing, or what was assumed

    /// The scalar metrics by their report names (lf_err, hf_ratio, ...), in report order.
    std::vector<std::pair<std::string, std::optional<double>>> scalars() const;
};

/// All metrics of one frame. An output with density but no velocity (Blender's noise up-res) gets the density
/// numbers alone (mass, peak, density_err, imprint, fray, crispness) and a note. Throws ValueError on broken
/// preconditions: an output with neither grid, a target without velocity or density, a source without either, a
/// non-integer resolution ratio.
FrameMeasures measureFrame(const MeasureInput& in, const MeasureSettings& s = {}, Progress* progress = nullptr);

/// Statistics of one metric over frames (only the frames where it exists).
struct MetricStats
{
    int count = 0;
    double mean = 0.0, median = 0.0, min = 0.0, max = 0.0;
};
/// Per metric name (as in FrameMeasures::scalars), over the frames. Metrics present in no frame are absent.
std::map<std::string, MetricStats> summarize(const std::vector<FrameMeasures>& frames);

// ---------------------------------------------------------------------------------------------
// Building blocks, public for tests and for stages that want the same definitions.

/// The output lattice factor over the target: integerRatio(target voxel, output voxel).
int resolutionRatio(const Frame& target, const Frame& output);

/// `field` brought onto `lattice` over `box` under an explicit World or Index alignment.
template<typename T>
Field<T> realign(const Field<T>& field, const Lattice& lattice, const CoordBBox& box, Alignment a);

/// Resolves Auto for an output over the refined target lattice/box.
Alignment resolveAlignment(
    Alignment requested, const Field<Vec3f>& output, const Lattice& refined, const CoordBBox& refinedBox);
/// The same for an output that holds density only (Blender's noise up-res writes no velocity).
Alignment resolveAlignment(
    Alignment requested, const Field<float>& output, const Lattice& refined, const CoordBBox& refinedBox);

/// density > threshold as a 0/1 mask on density's box.
std::vector<unsigned char> smokeMask(const ScalarField& density, float threshold);
/// The bounding box of density > threshold (empty when there is none).
CoordBBox smokeBBox(const ScalarField& density, float threshold);

/// Density numbers of an up-res against its target (FrameMeasures::massRatio ... densityErr).
struct DensityMeasures
{
    std::optional<double> massRatio, peak, peakRatio, coarseErr, imprint;
};
/// `output` is the up-res density on its own lattice, `outputOnRefined` the same on the refined target lattice
/// over refineBox(target box, f); `target` the coarse density. Entries are empty when their denominator is zero.
DensityMeasures densityMeasures(
    const ScalarField& output, const ScalarField& outputOnRefined, const ScalarField& target, int f, float threshold);
/// The coarse lattice printed into a fine density: the mean |D(I+e_a) - D(I)| over neighbour pairs of `fine` whose
/// shared face is a face of the coarse cells (floor(I_a / f) != floor((I+e_a)_a / f)), over the same mean for all
/// other pairs, counting the pairs where either voxel exceeds `threshold` (the smoke and its edge). About 1 for
/// density with no relation to the coarse cells, including a trilinear up(coarse), whose kinks lie at the cell
/// centres; well above 1 when whole coarse cells were scaled or cut (a staircase silhouette). `fine` lies on the
/// refined lattice (fine voxel I in coarse cell floor(I / f)); a one-layer (2D) field has no z pairs. nullopt for
/// f < 2 or when either set of pairs is empty or has no jumps. Beyond the papers: added when a picture of the
/// demo's output showed coarse-cell blocks at the smoke's edge that no other number caught.
std::optional<double> densityImprint(const ScalarField& fine, int f, float threshold);

/// How frayed the density's surface is: the share of |grad D|^2 that lies across the normal of D's smooth part,
/// sum |grad D - (grad D . n) n|^2 / sum |grad D|^2 with n = grad L / |grad L|, L = up_f(boxdown_f(D)) (f^3 blocks
/// from the box's min corner, f^2 in 2D), central differences, over the voxels where D or L exceeds `threshold`.
/// |grad D|^2 weights the sums, so the smoke's edge dominates: a soft or sharp but smooth silhouette reads near 0
/// (its gradient follows the normal), one frayed into hairs or streaks along it reads high. Compare an up-res's
/// against its source's at the same f (density_fray_ratio). In [0, 1]; nullopt for f < 2 or no smoke. Beyond the
/// papers: added when the density sheets of the Blender plume2 and demo transfers showed a "furry" silhouette
/// where the source's and the target's are soft, which no other number caught.
std::optional<double> densityFray(const ScalarField& D, int f, float threshold);

/// How crisp the density's edges and billows are at the fine voxel size: the energy of grad D along the normal of
/// D's smooth part over the energy of that smooth part's own gradient,
///   sum (grad D . n)^2 / sum |grad L|^2,  n = grad L / |grad L|,  L = up_f(boxdown_f(D)),
/// over the voxels and with the differences densityFray uses. About 1 (a little below) for a density no sharper
/// than the coarse lattice resolves (a trilinear up-sampling, a blurred copy); about f / w for edges w fine voxels
/// wide (a one-voxel step reads near f); hairs across the surface add little, since their gradient lies across n
/// (densityFray counts them). Compare against a reference at the same f (Blender's high-res simulation of the scene,
/// Blender's noise up-res). >= 0; nullopt for f < 2 or no smoke. Beyond the papers: added for issue 42 (a "soft,
/// furry" output beside Blender's crisp billows); docs/measure.md shows how it ranks a crisp, a blurred and a hairy
/// density.
std::optional<double> edgeCrispness(const ScalarField& D, int f, float threshold);

/// densityFray and edgeCrispness from one pass over the density's edge (each nullopt as the function says).
struct DensityEdge
{
    std::optional<double> fray, crispness;
};
DensityEdge densityEdge(const ScalarField& D, int f, float threshold);

/// Detail strength against height: the rms of H = U - up_f(boxdown_f(U)) over the mask's voxels in each of `bands`
/// equal slabs of the mask's extent along `upAxis` (0 x, 1 y, 2 z; band 0 at the bottom, where an emitter sits),
/// each over the rms over the whole mask. A band holding fewer than 1% of the mask's voxels is nullopt. An empty
/// vector when the mask is empty or H is zero. Beyond the papers: issue 42's "band at the emitter" (detail at full
/// strength along the inflow where the source has little) is a bottom band far above the source's profile.
std::vector<std::optional<double>> detailProfile(
    const VectorField& u, const std::vector<unsigned char>& mask, int f, int upAxis, int bands = 8);

/// The worst band of two detailProfile()s: max over bands present in both of max(r, 1/r), r = output / source
/// (1 = the source's profile; issue 42's goal: <= 1.5). nullopt when no band is present in both.
std::optional<double> detailProfileRatio(
    const std::vector<std::optional<double>>& output, const std::vector<std::optional<double>>& source);

/// rms(boxdown_f(fine) - coarse) / rms(coarse) over the coarse cells where `coarse` exceeds `threshold` (0 when
/// there are none): density_err. `fine` must cover refineDomain(coarse box, f); throws ValueError otherwise.
double coarseDensityError(const ScalarField& fine, const ScalarField& coarse, int f, float threshold);

/// Anisotropy of the detail H = U - up_f(boxdown_f(U)) along a unit direction d, over the mask:
///   a = mean|(d.grad)H|^2 / (1/2 (mean|grad H|^2 - mean|(d.grad)H|^2))
/// (central differences). Isotropic detail gives 1; detail stretched along d (streaks) gives well below 1, and
/// detail squashed along d above 1. nullopt when the mask is empty, d is zero or H has no gradient.
std::optional<double> detailAnisotropy(
    const VectorField& u, const std::vector<unsigned char>& mask, int f, const Vec3d& direction);

/// The detail's length scale, world units: sqrt(mean|H|^2 / mean|grad H|^2) over the mask (|grad H|^2 the squared
/// Frobenius norm of the Jacobian, central differences; Taylor's microscale of H up to a constant). For H =
/// sin(k x) sampled at voxel size h it is h / sin(k h), about 1/k. Compare the output's with the source's
/// (detail_scale_ratio): well below 1 means finer detail than the source's, such as short stacked arcs where the
/// source has long smooth sheets. Beyond the papers: added after the 2D pair's vorticity showed such arcs at an
/// aniso_ratio near 1. nullopt when the mask is empty or H has no gradient; ValueError for a wrong mask.
std::optional<double> highBandScale(const VectorField& H, const std::vector<unsigned char>& mask);

/// detailAnisotropy of a detail already split off: H = splitFrequencies(u, f).high, or any high band. Throws
/// ValueError when `mask` is not one byte per voxel of H.
std::optional<double> highBandAnisotropy(
    const VectorField& H, const std::vector<unsigned char>& mask, const Vec3d& direction);

/// Direction-free structure: the energy-weighted mean, over `block`^3 tiles of the box with at least half their
/// voxels in the mask, of lambda_min / lambda_max of the tile's gradient structure tensor sum_c grad H_c grad H_c^T
/// (H = U - up_f(boxdown_f(U)), central differences, masked voxels only). Near 1 where the detail has no preferred
/// direction, near 0 where it is stretched into sheets or streaks along any direction. nullopt without such tiles.
std::optional<double> detailIsotropy(
    const VectorField& u, const std::vector<unsigned char>& mask, int f, int block = 8);

/// The patch lattice printed into the detail's strength: the rms relative modulation of e = |curl H|^2
/// (H = U - up_f(boxdown_f(U)), central differences, masked voxels) with the position modulo `patch` along each
/// axis, beyond the modulation at the unrelated periods patch - 1 and patch + 1:
///   V_P = mean over axes a of var_r(mean{e : I_a mod P = r}) / mean(e)^2,
///   lattice = sqrt(max(0, V_patch - (V_{patch-1} + V_{patch+1}) / 2)).
/// Dimensionless, >= 0. About 0 for detail with no relation to the lattice (chance variations and smooth trends
/// along an axis fold about equally into the three periods); 0.3 means the detail is about 30% stronger or weaker
/// at some positions within every patch, which a vorticity slice shows as a grid of blobs or lines. Axes shorter
/// than 2 (patch + 1) voxels are left out (2D caches: z). nullopt without masked detail or such axes. Throws
/// ValueError when patch < 3 or the mask does not match. The patch origin does not matter: another origin permutes
/// the residues cyclically. Beyond the papers: added after the demo's vorticity showed a patch grid at frame 3 that
/// `block` (jumps across seam planes) did not catch.
std::optional<double> latticeImprint(const VectorField& u, const std::vector<unsigned char>& mask, int f, int patch);

/// detailAnisotropy (along `direction`), detailIsotropy (8^3 tiles) and, when `patch` is not 0, latticeImprint of
/// u's detail, from one frequency split (measureFrame needs all three of the output and of the source). Throws as
/// the three do (patch 1 or 2 included).
struct DetailStructure
{
    std::optional<double> aniso, isotropy, lattice;
    std::optional<double> scale; ///< highBandScale of the detail
};
DetailStructure detailStructure(
    const VectorField& u, const std::vector<unsigned char>& mask, int f, const Vec3d& direction, int patch);

/// The `quantile` (in [0, 1]) of |curl U| over the mask, 1/time unit: 0.999 gives the peak vorticity without the
/// hottest 0.1% of the voxels. nullopt when the mask is empty; ValueError for a quantile outside [0, 1] or a
/// wrong mask.
std::optional<double> vorticityPeak(const VectorField& u, const std::vector<unsigned char>& mask, double quantile);

/// mean over the mask of |U - up_f(boxdown_f(U))|^2 (nullopt if the mask is empty).
std::optional<double> highFrequencyEnergy(const VectorField& u, const std::vector<unsigned char>& mask, int f);
/// rms(div U) / rms(|grad U|) over the mask, central differences (nullopt if the gradient is zero).
std::optional<double> relativeDivergence(const VectorField& u, const std::vector<unsigned char>& mask);
/// lf_err: rms of boxdown_f(detail) over rms of boxdown_f(up) over the coarse cells where `coarseMask` is 1, the two
/// sums per x-slab added in slab order. `detail` is U_h and `up` is up_f(U_t), both on the refined target lattice
/// over the same box (world units per time unit); `coarseMask` has one byte per cell of boxdown_f's coarse box, in
/// Field order (smokeMask of the target's density). Dimensionless, >= 0; 0 when the detail adds no coarse motion.
/// nullopt when the mask is empty or up is zero on it (a target at rest). Throws ValueError when the boxes differ or
/// the mask does not cover the coarse box.
std::optional<double> lowFrequencyError(
    const VectorField& detail, const VectorField& up, const std::vector<unsigned char>& coarseMask, int f);
/// Mean |U(I+e_a) - U(I)| over voxel pairs inside the mask whose shared face lies on a seam plane
/// (I+e_a)[a] = origin[a] + n * patch, over the same mean elsewhere (nullopt when either set is empty or zero).
std::optional<double> blockRatio(
    const VectorField& u, const std::vector<unsigned char>& mask, int patch, const Coord& origin = Coord(0));

} // namespace turb
