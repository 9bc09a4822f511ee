/// @file Transfer.h
/// @brief Turbulence style transfer (Sato et al. 2018, section 3): moves the high-frequency
///        velocity of a high-resolution *source* simulation onto the motion of a low-resolution
///        *target* simulation.
///
/// Per frame:
/// 1. frequency split of the source: U_sl = up(boxdown(U_s)), U_sh = U_s - U_sl;
/// 2. density masks with threshold D_th;
/// 3. global search (eq. 1) over b^3 coarse patches (PCA + FLANN), only when smoke first enters a
///    local patch; afterwards the global patch follows the previous frame's best local patch;
/// 4. local search (eq. 2) for B^3 fine patches inside the global region, with the beta term on the
///    previous detail advected through the target velocity;
/// 5. paste U_h, then smooth seams (section 3.3) by EM: a conjugate-gradient E-step on
///    sum |grad X - grad Z|^2 + gamma (div X)^2 over a band around patch borders and an M-step that
///    re-picks the boundary patches Z on U_sh;
/// 6. output U = up(u_t) + U_h at source resolution, density advected through U.
///
/// Velocities are compared in "coarse cells per frame" (u * dt / dx of each sequence), the grid units
/// the paper's alpha/beta/gamma were tuned in, so world-unit conventions of the caches do not matter.
///
/// 2D: a target one voxel thick in z (isFlat) is a 2D transfer, and its source must be 2D too. Patches are then
/// B x B x 1 (local), b x b x 1 (global) and C x C x 1 (boundary), the seam band has no z borders (width
/// SeamSettings::bandWidth2D), fields are advected in their plane, and the output is one layer at the target
/// layer's index and world height (refineDomain, refinedLattice) with zero z velocity. 3D is unchanged.
///
/// @code
/// turb::TransferSettings s;                  // paper defaults: alpha 0.004, beta 0.5, gamma 10
/// turb::TurbulenceTransfer transfer(s);
/// for (...) {
///     turb::TransferResult r = transfer.process(targetFrame, sourceFrame, &progress);
///     write(r.frame);
/// }
/// @endcode
#pragma once

#include <turb/Advect.h>
#include <turb/DensityGuide.h>
#include <turb/Frame.h>
#include <turb/Progress.h>
#include <turb/Seams.h>

#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace turb {

/// How the source is aligned to the target before matching (beyond the paper, whose stated
/// limitation is sources whose flow differs in direction or speed).
enum class FlowAlignment {
    None,      ///< compare velocities as they are (the paper)
    Normalize, ///< divide each sequence's velocities by its RMS speed in the smoke region
    Rotate,    ///< rotate the source by the axis rotation that best maps its mean flow onto the target's
    Both       ///< rotate, then normalize
};

/// What the detail's energy is calibrated to, after seam smoothing and the coarse-part removal (both
/// remove some of it). The energy factor is one scalar per frame, bounded to [1/3, 3].
enum class DetailEnergy {
    None,   ///< leave U_h as the pipeline made it
    Pasted, ///< the energy of the pasted patches inside the smoke (undo the post-processing's losses)
    Source, ///< the source's mean high-frequency energy per smoke voxel: as much turbulence as the source
    /// beyond the paper: |U_h| remapped, voxel by voxel and monotonically, onto the distribution of the source
    /// detail's magnitudes over its smoke (rank for rank), then scaled as Source. Detail that one global factor
    /// would lift unevenly (kept where nothing dissipates it) cannot exceed the source's own peaks. Histogram
    /// matching as in Heeger and Bergen, "Pyramid-based texture analysis/synthesis" (1995), on |U_h| alone
    Distribution
};

/// The settings name of a DetailEnergy: "none", "pasted", "source" or "distribution".
const char* detailEnergyName(DetailEnergy e);

/// How the first frame's high-resolution density is advanced.
enum class DensityMode {
    Advect,  ///< carry the previous output density through U, plus the target's own emission
    LookBack ///< Ma et al.'s supplement: re-start from the target density m frames back and advect m times
};

struct TransferSettings
{
    // Matching (eqs. 1 and 2)
    float alpha = 0.004f;           ///< weight of the density-mask term, >= 0 (paper: 0.004)
    float beta = 0.5f;              ///< weight of the temporal term on the advected previous detail, >= 0 (paper: 0.5)
    float densityThreshold = 0.01f; ///< D_th: smoke where density > this (mask for patches and matching)
    int localPatch = 8;             ///< B: local patch edge in fine voxels, >= 2
    int globalPatch = 0;       ///< b: global patch edge in coarse voxels, odd; 0 = 2*ceil(B/f)+1 (> B/f as required)
    int pcaComponents = 16;    ///< PCA dimensions of global and local descriptors, >= 1
    int localStride = 2;       ///< spacing of candidate local-patch centres in the source, >= 1
    int refineCandidates = 24; ///< local candidates re-scored with the full-resolution energy E_h, >= 1
    bool trackGlobalPatches = true; ///< the paper's temporal rule; false = global search every frame
    bool followSourceFlow = true;   ///< beyond the paper: a patch that carried detail continues from where that detail
                                    ///< came from in the source, moved by the source's own flow (sub-voxel, tricubic);
                                    ///< without it the re-pasted detail stays put while the carried detail moves, and
                                    ///< the blend smears it into streaks along the flow
    float sourceSmoke = 0.5f;     ///< beyond the paper: a source patch is a candidate when this fraction of its voxels
                                  ///< holds smoke (relaxed to half the smokiest patch's share on thin first frames);
                                  ///< 0 = any smoke, the paper's rule, which let velocity alone pick patches outside
                                  ///< the source's smoke, where a cache like Blender's holds no detail
    float followTolerance = 1.0f; ///< the continuation is kept while its E_h is at most (1 + this) times the best
                                  ///< searched patch's, >= 0
    float coherence = 0.0f;       ///< beyond the paper: take a neighbour's continued source patch when its E_h is
                                  ///< within this fraction of the best (fewer seams); 0 = off
    int coherenceSweeps = 2;      ///< red-black sweeps of the coherence pass, >= 1
    int repeatRadius = 1;         ///< beyond the paper: fresh patches (no carried detail) within this many patches
                                  ///< of each other (Chebyshev) never take source patches overlapping by more than
                                  ///< half along every axis,
                                  ///< unless every candidate within repeatTolerance does (issue 42: the frame-1
                                  ///< lattice and the emitter band were one source patch repeated); 0 = off, the
                                  ///< paper; at most 4
    float repeatTolerance = 1.0f; ///< a repeat is avoided with a candidate whose E_h is at most (1 + this) times
                                  ///< the best, >= 0
    float evenPatches = 0.0f;     ///< beyond the paper: a variance-preserving correction of the seams: U_h's
                                  ///< strength evened out over the position in the patch (issue 42's lattice), this
                                  ///< fraction of the way (the exponent of the gain), on frames whose modulation is
                                  ///< clear (a largest gain of kEvenPatchesFrom = 1.2: a shot's first frames), in
                                  ///< [0, 1]; 0 = off (the default and the paper): at 0.5 the paper pair's frame-1
                                  ///< lattice fell from 0.18 to 0.14, but block rose to 1.05 on the farm test's
                                  ///< pair (1.06 at 1), over its goal
    float localEnergy = 0.5f;     ///< beyond the paper: after calibration each patch's detail rms moves toward the
                                  ///< rms of the source detail pasted into it, this fraction of the way in log
                                  ///< (gains in [1/3, 3], interpolated between patch centres), the frame's total
                                  ///< energy kept; in [0, 1], 0 = one factor per frame (before issue 42)
    float vorticityLimit = 1.0f;  ///< beyond the paper: after calibration, U_h is scaled down, smoothly, where
                                  ///< |curl(up(u_t) + U_h)| in the smoke exceeds this times the source's 0.999
                                  ///< quantile of |curl U_s| over its smoke (measure's vort_peak); 0 = off, >= 0
    float temporalBlend = 0.95f;  ///< beyond the paper: weight of last frame's detail (advected through the target)
                                  ///< mixed into patches that had detail, in [0, 0.999]; 0 = the paper
    float regenerate = 0.6f;      ///< beyond the paper: carried detail that the flow has stretched is
                             ///< regenerated from the freshly pasted patch faster. A patch's structure ratio is the
                             ///< gradient energy of U_h along up(u_t)'s mean direction over the mean across it;
                             ///< where the carried detail's is below this fraction of the fresh detail's (the
                             ///< smaller of the patch's own and all pasted patches' pooled), the patch takes
                             ///< regenerateBlend instead of temporalBlend. In [0, 1]; 0 = off (carried detail
                             ///< stretches into streaks over a long shot)
    float regenerateBlend = 0.5f;       ///< carried weight per frame in a regenerated patch, in [0, 0.999] (at most
                                        ///< temporalBlend is used)
    float regenerateBlend2D = 0.6f;     ///< the same for a 2D sequence (0.5 put block over 1.05 on 6 of 30 frames of
                                        ///< the built-in 2D pair, 0.6 on 4)
    float structureTolerance = 0.0f;    ///< beyond the paper: when the frame's blended detail is more than this
                                        ///< fraction off the source's anisotropy along the target's mean flow
                                        ///< (measure's aniso, estimated before the seam solve), more tracked
                                        ///< patches are regenerated, at regenerateBlend and then at its square,
                                        ///< those that move it most first, until it is within. The finished frame
                                        ///< is then measured; more than 3x this off, the blend, seam solve and
                                        ///< calibration run once more, aimed past the goal by the seams' drift,
                                        ///< and the closer of the two passes is kept
                                        ///< (TransferStats::structureRedone). In [0, 1); 0 = off (the 3D default)
    float structureTolerance2D = 0.05f; ///< the same for a 2D sequence (built-in 2D pair: aniso_ratio in range on
                                        ///< every frame from 4, against 15 of 26 from 5 without; docs/transfer.md)
    FlowAlignment alignment = FlowAlignment::None; ///< see FlowAlignment
    bool resampleSource = true; ///< beyond the paper: a source at a non-integer ratio is resampled trilinearly to
                                ///< the nearest integer ratio; false = such a source is an error

    // Seam smoothing (section 3.3)
    SeamSettings seams; ///< band width, boundary patch size, gamma, EM and CG tolerances

    // Output
    bool compensateTargetDivergence =
        true; ///< the seam solve's gamma term penalises div(up(u_t) + U_h), not
              ///< div(U_h) alone, so the band also cancels the up-sampled target's divergence
    bool solveFreshPatchesWhole = false; ///< beyond the paper: patches without carried detail (first frames, smoke
                                         ///< entering) join the seam solve whole, so its divergence term reaches their
                                         ///< insides; lowers early frames' div_rel, costs some tcoh later
    bool removeCoarseDetail = true;      ///< reduce the smooth part of U_h whose box means are not zero (bounds lf_err)
    float coarseTolerance = 0.04f; ///< beyond the paper: U_h's coarse-cell means are reduced only until they are this
                                   ///< fraction of the target's coarse speed (rms over the smoke cells, lf_err's
                                   ///< definition); 0 = removed exactly. What stays is carried detail that advection
                                   ///< moved into the means: removing it is a change every frame (tcoh)
    DetailEnergy detailEnergy = DetailEnergy::Distribution; ///< what U_h's magnitudes and energy are calibrated to
    /// The same on 2D (one z layer) caches. Source there: on the built-in 2D pair matching the magnitudes put
    /// aniso_ratio in range on 6 of 26 frames against 15 with one factor, which shows no hot spots in 2D
    DetailEnergy detailEnergy2D = DetailEnergy::Source;
    DensityMode densityMode = DensityMode::Advect; ///< how the output density is produced
    /// Scheme of the output density's advection (OpenVDB VolumeAdvection, clamped): BFECC traces back three times
    /// per substep; MacCormack twice (28% less density time at frame 30 on the Blender pair with the same
    /// numbers there, but mass 1.13x the target's on the inflow test, so not the default); semi-Lagrangian once,
    /// showing the coarse cells' staircase at the smoke's edge (docs/performance.md).
    AdvectSettings::Scheme densityScheme = AdvectSettings::Scheme::BFECC;
    DensityGuideSettings
        densityGuide;        ///< beyond the paper: the output density's coarse means are moved onto the
                             ///< target's every frame (strength 0 = off), so it does not drift from the target
    /// Beyond the paper (issue 42's fur): the advected output density's edge shaped every frame before the guide
    /// (3D only; DensityShaping.h): interface compression at this speed in voxels per frame, in [0, 1], 0 = off.
    /// With levelSetDiffusion 0.15 (docs/look.md, 30 frames of three Blender pairs): density_fray 0.287 -> 0.161,
    /// 0.479 -> 0.443 and 0.408 -> 0.348, edge_crispness 2.40 -> 2.52, 4.57 -> 4.76 and 3.43 -> 4.85, ~20% time
    float interfaceCompression = 0.5f;
    float levelSetDiffusion = 0.15f; ///< then diffusion along the density's level sets, k per pass in [0, 1/6], 0 = off
    int levelSetDiffusionPasses = 3; ///< passes of it per frame, >= 0
    int lookBackFrames = 12; ///< m for DensityMode::LookBack (Ma et al. suggest 10-20)
    int threads = 0;         ///< worker threads, 0 = all; results do not depend on it
};

/// Where one frame's time went, in seconds (steady clock).
struct TransferTimings
{
    double split = 0.0;        ///< target up-sampling, emission estimate, source frequency split
    double density = 0.0;      ///< output density: advection or look-back, emission, guide
    double advectDetail = 0.0; ///< U_h(i-1) advected through the target
    double global = 0.0;       ///< global search (eq. 1)
    double local = 0.0;        ///< local search (eq. 2) and the coherence pass
    double paste = 0.0;        ///< pasting U_h
    double seams = 0.0;        ///< temporal blend, coarse part, seam smoothing (section 3.3)
    double look = 0.0;         ///< issue 42's steps after calibration: local strength, even patches, vorticity cap
    double output = 0.0;       ///< coarse part, energy, assembling the frame
    double total = 0.0;        ///< the whole process() call
    /// (name, seconds) in report order; the names are the JSON keys of `steps_s`.
    std::vector<std::pair<const char*, double>> named() const
    {
        return {{"split", split}, {"advect_detail", advectDetail}, {"global", global}, {"local", local},
            {"paste", paste}, {"seams", seams}, {"look", look}, {"output", output}, {"density", density},
            {"total", total}};
    }
};

/// Numbers a TD or a log wants per frame.
struct TransferStats
{
    int ratio = 0;                ///< resolution ratio f
    double sourceRatio = 0.0;     ///< target voxel / source voxel as given
    bool sourceResampled = false; ///< sourceRatio was not an integer: the source was resampled to f
    int localPatches = 0;         ///< local patches holding smoke
    int globalSearches = 0;       ///< patches that ran the global search this frame
    int trackedPatches = 0;       ///< patches whose global patch followed the previous frame
    int continuations = 0;        ///< patches with a continuation in the source's flow this frame
    int followedPatches = 0;      ///< patches that took it (followSourceFlow, followTolerance)
    int regeneratedPatches = 0;   ///< patches whose stretched carried detail was regenerated (regenerate)
    int structureRegenerated = 0; ///< of those, the ones the structure goal added (structureTolerance)
    double patchStrengthGain = 1.0;       ///< the largest gain evenPatches applied (1 = the detail had no lattice)
    size_t vorticityLimited = 0;          ///< smoke voxels whose vorticity exceeded the cap (vorticityLimit)
    int repeatsAvoided = 0;               ///< patches that took another candidate than their best (repeatRadius)
    std::optional<double> structureRatio; ///< with the structure goal: the finished detail's anisotropy along the
                                          ///< target's mean flow over the source's (`measure`'s aniso_ratio up to
                                          ///< the source's side: within 7% on the built-in 2D pair); also on a
                                          ///< shot's first frame, which has nothing to regenerate; empty without a
                                          ///< goal or where undefined
    bool structureRedone = false; ///< the blend, seam solve and calibration ran a second time, because the first
                                  ///< finished more than 3x structureTolerance off the source's anisotropy; the
                                  ///< closer of the two passes is the output (and structureRatio)
    std::optional<double> structureFirstRatio; ///< where redone: the first pass's finished ratio
    double meanLocalEnergy = 0.0; ///< mean E_h of the chosen local patches
    double energyScale = 1.0;     ///< factor applied to U_h to meet TransferSettings::detailEnergy
    double coarseKept = 0.0;      ///< fraction of U_h's coarse part left in (coarseTolerance): 0 = removed exactly,
                                  ///< 1 = all kept (also with removeCoarseDetail off)
    double lfErr = 0.0;           ///< rms of U_h's coarse-cell means / rms of the target's, over its smoke cells
                                  ///< (0 when the target is at rest there)
    std::optional<double>
        detailChange; ///< rms(U_h - U_h(i-1) advected) / rms(U_h) over the output's smoke: `measure`'s
                      ///< tcoh when both advect the same way (BFECC: temporal blend on, the default); empty
                      ///< without carried detail (first frame, after an empty frame, beta = blend = 0)
    double densityErrBefore = 0.0; ///< coarse density error (measure's density_err) before the density guide
    double densityErr = 0.0;       ///< the same after it: what the written density has
    double detailGrowth = 0.0;     ///< rms(U_h) / rms(U_h(i-1) advected) over the output's smoke; no field of this
                                   ///< energy is closer to the advected one than 1 - 1/growth (tcoh's floor)
    SeamStats seams;               ///< EM/CG log of the seam smoothing
    TransferTimings seconds;       ///< where the time went
};

struct TransferResult
{
    Frame frame; ///< velocity (world units, source resolution), density, upsampled temperature/flame
    TransferStats stats;
    bool empty = false; ///< the target frame had no smoke: the frame is the upsampled target (defined no-op)
};

/// The settings that change a transfer's output, as (name, value) pairs in a fixed order; names are the command
/// line's option names without dashes. `threads` is left out: results do not depend on it. Saved with every output
/// frame (meta::kSettings) so that `--resume` can refuse to continue a run made with other settings, naming them.
std::vector<std::pair<std::string, std::string>> outputSettings(const TransferSettings& s);

/// Names of the settings whose values differ between two outputSettings() texts ("name=value;..."), each as
/// "name: saved -> now", numbers shown at float precision. A setting that outputSettings() records only when
/// changed stands at its default where a text lacks it; any other name present in only one text counts as
/// differing ("(not recorded)", "(unknown to this version)"). Empty when they agree.
std::vector<std::string> settingsDifferences(const std::string& saved, const std::string& now);

/// outputSettings() as one "name=value;name=value" text.
std::string outputSettingsText(const TransferSettings& s);

/// The resolution ratio a transfer runs at: target voxel / source voxel when that is an integer, else (with
/// `resampleSource`) the nearest integer, the source then being resampled to it. Throws ValueError, saying
/// why, for a ratio that rounds below 2 or, without `resampleSource`, is not an integer.
int transferRatio(double targetVoxel, double sourceVoxel, bool resampleSource);

/// Streaming transfer over a sequence: call process() once per frame, in order. Holds only what the
/// method needs between frames (previous detail, previous output velocity/density, patch tracks).
class TurbulenceTransfer
{
public:
    explicit TurbulenceTransfer(const TransferSettings& settings);
    ~TurbulenceTransfer();
    TurbulenceTransfer(TurbulenceTransfer&&) noexcept;
    TurbulenceTransfer& operator=(TurbulenceTransfer&&) noexcept;

    /// Processes the next frame. `target` needs velocity and density; `source` needs velocity and
    /// density on a lattice whose voxel size divides the target's by an integer >= 1.
    TransferResult process(const Frame& target, const Frame& source, Progress* progress = nullptr);

    /// The state needed to continue after the last processed frame (patch tracks), as a compact string
    /// to store in the output file's metadata. The previous detail and density come from that file.
    std::string saveState() const;
    /// Restores a sequence: `state` from saveState(), `previousOutput` the frame written last and
    /// `previousTarget` the target frame it was made from. Exact (the next frame is bit-identical to an
    /// uninterrupted run's) when `previousOutput` holds process()'s velocity and density in full over the box.
    /// A velocity voxel that is exactly zero counts as not written and becomes up(u_t), i.e. no detail there:
    /// a file trimmed to the smoke (WriteOptions::velocityMargin) resumes approximately. Throws ValueError
    /// when the lattice or local patch size does not match the state.
    void restore(const std::string& state, const Frame& previousOutput, const Frame& previousTarget);

    const TransferSettings& settings() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace turb
