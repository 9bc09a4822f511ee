// Private to the transfer: the stages of Sato et al. 2018, section 3, as named functions over one frame. Each
// lives in its own file under src/transfer/ and returns a small struct; TurbulenceTransfer::process (Transfer.cc)
// calls them in the paper's order. Units: velocities in world units per time unit, positions in fine (output)
// voxels unless a name says "coarse".
#pragma once

#include "Align.h"
#include "PatchSearch.h"

#include <turb/Advect.h>
#include <turb/Resample.h>
#include <turb/Seams.h>
#include <turb/Transfer.h>

#include <deque>
#include <map>
#include <optional>
#include <vector>

namespace turb::detail {

/// The transfer's advection settings: OpenVDB's defaults, and 2D (one-layer) fields advected in their plane
/// (AdvectSettings::inPlane; 3D fields are unaffected).
inline AdvectSettings inPlane()
{
    AdvectSettings a;
    a.inPlane = true;
    return a;
}

/// What is fixed over one frame: the ratio, the boxes, the patch layout on the absolute lattice of multiples of
/// B, and the time since the previous processed frame.
struct FrameSetup
{
    const TransferSettings* s = nullptr;
    int f = 0;           ///< resolution ratio
    int B = 8;           ///< local patch edge (fine voxels)
    int globalPatch = 3; ///< b (coarse voxels)
    bool flat = false;   ///< 2D: the target is one z layer (isFlat), and so are the source and the output
    Coord patch{8};      ///< local patch extent per axis: (B, B, B), or (B, B, 1) in 2D
    Coord half{4};       ///< offset of a local patch's centre voxel from its corner: patch / 2 per axis
    int globalDepth = 3; ///< global patch extent along z (coarse voxels): b, or 1 in 2D
    /// Key of layout patch P in the absolute patch lattice (CarriedState::tracks): P + origin / B per axis; a 2D
    /// layout's one layer of patches is layer 0.
    Coord absolutePatch(const Coord& P) const
    {
        return P + Coord(layout.origin.x() / B, layout.origin.y() / B, flat ? 0 : layout.origin.z() / B);
    }
    Lattice targetLattice, fineLattice;
    CoordBBox targetBox, fineBox;
    PatchLayout layout;
    double elapsed = 0.0;               ///< time since the previous processed frame; 0 on a first frame
    int frameGap = 1;                   ///< frame-number gap to that frame
    const Progress* progress = nullptr; ///< asked before every parallel chunk of the stages: Ctrl-C stops a search
    /// What U_h is calibrated to on this frame: detailEnergy, or detailEnergy2D on a 2D layout.
    DetailEnergy detailEnergy() const { return flat ? s->detailEnergy2D : s->detailEnergy; }
};

/// One look-back step (DensityMode::LookBack).
struct LookBackStep
{
    VectorField velocity;      ///< U(j)
    ScalarField emission;      ///< coarse emission estimate injected at step j
    ScalarField targetDensity; ///< up-sampled when a look-back starts here; bounds the emission
    double elapsed = 0.0;      ///< time from frame j to the next processed frame (set when it arrives)
};

/// What the previous frames leave for this one.
struct CarriedState
{
    bool havePrevious = false;
    VectorField prevDetail;           ///< U_h(i-1), output lattice
    VectorField prevTargetVelocity;   ///< u_t(i-1), target lattice
    ScalarField prevTargetDensity;    ///< d_t(i-1)
    ScalarField prevDensity;          ///< D(i-1), output lattice
    VectorField prevVelocity;         ///< U(i-1), output lattice
    double prevDt = 0.0;              ///< time per frame at frame i-1
    int prevNumber = 0;               ///< frame number of i-1, the previous *processed* frame
    std::deque<LookBackStep> history; ///< LookBack mode: the last m frames
    int prevSourceNumber = 0;         ///< source frame number used at i-1
    double prevSourceDt = 0.0;        ///< and its time per frame
    /// Patch (on the absolute patch lattice, fine index / B) -> source corner (fine source voxels, possibly between
    /// voxels when it followed the source's flow) of its detail last frame. Keyed absolutely so a target whose
    /// active box grows or moves keeps its tracks.
    std::map<Coord, Vec3d> tracks;
};

/// This frame's view of the tracks, per patch of the layout.
struct PatchTracks
{
    std::vector<uint8_t> tracked;   ///< 1 where the patch has a track
    std::vector<Coord> match;       ///< that track's source corner (rounded)
    std::vector<uint8_t> following; ///< 1 where followSourceFlow found a continuation
    std::vector<Vec3d> follow;      ///< its source corner, carried by both flows to this frame
};

// --- Split (section 3.1) ------------------------------------------------------------------------------

/// The target at output resolution and its density sources.
struct TargetAtOutput
{
    VectorField Ut;       ///< up(u_t)
    ScalarField Dt;       ///< up(d_t)
    ScalarField emission; ///< coarse: max(0, d_t - advect(d_t(i-1))) over the elapsed time; zero on a first frame
};
TargetAtOutput splitTarget(const Frame& target, const CarriedState& c, const FrameSetup& fs);

/// The source's bands and the velocity scales matching compares them in.
struct SourceBands
{
    FrequencySplit split;       ///< U_sl (low), U_sh (high) and u_s (coarse); high without its box means
    ScalarField Ds, ds;         ///< source density, and its box means on the coarse lattice
    double reference = 0.0;     ///< the source's high-frequency energy per smoke voxel, in output units^2
    float kt = 1.0f, ks = 1.0f; ///< target and source velocity -> matching units (coarse cells per frame)
    float detailScale = 1.0f;   ///< U_sh (source world units) -> output world units
    /// DetailEnergy::Distribution: |U_sh| (output units, coarse part out) over the source's smoke at
    /// kMagnitudeRanks + 1 evenly spaced ranks, smallest first; empty otherwise
    std::vector<float> magnitudes;
    double vortPeak = 0.0; ///< the 0.999 quantile of |curl U_s| over the source's smoke, output units (0 = not taken)
};
constexpr int kMagnitudeRanks = 1024;
/// `values` sorted and sampled at ranks + 1 evenly spaced ranks (linear between neighbours); empty for no values.
std::vector<float> rankTable(std::vector<float> values, int ranks);
/// Sequence-wide alignment of the source (chosen once, so it does not flip between frames).
struct AlignmentState
{
    bool chosen = false;
    AxisRotation rotation;
};
SourceBands splitSource(const Frame& source, const Frame& target, const FrameSetup& fs, AlignmentState& align);

// --- Density ------------------------------------------------------------------------------------------

struct DensityStep
{
    ScalarField density;      ///< D(i) on the fine box
    double errorBefore = 0.0; ///< coarse density error before the guide
    double errorAfter = 0.0;  ///< and after it
};
/// The output density: advected (or looked back), the target's emission added up to the target's density, then
/// guided onto the target's coarse means. Needs only past velocities, so it comes before this frame's detail.
DensityStep advanceDensity(const Frame& target, const TargetAtOutput& t, const CarriedState& c, const FrameSetup& fs);

/// Per patch of the layout: 1 where the target or the output density has smoke (the patches eq. 2 runs for).
std::vector<uint8_t> activePatches(const FrameSetup& fs, const ScalarField& Dt, const ScalarField& density);

// --- Temporal terms -----------------------------------------------------------------------------------

/// U_h(i-1) advected through u_t(i-1) over the elapsed time (the beta term's U^_h, and the carried detail); empty
/// on a first frame or when neither beta nor the temporal blend needs it.
VectorField advectPreviousDetail(const CarriedState& c, const FrameSetup& fs);

/// Beyond the paper: for each active patch, where the detail that flowed into it came from in the source, moved on
/// by the source's own flow to this frame. Pasting from there gives the source's detail as it evolved, moving with
/// the target's flow; re-pasting a fixed source position while carrying the last frame's detail smears it into
/// streaks along the flow. Fills `tracks.following` and `tracks.follow`.
void followSourceFlow(PatchTracks& tracks, const CarriedState& c, const TargetAtOutput& t, const SourceBands& src,
    const Frame& source, const std::vector<uint8_t>& active, const FrameSetup& fs);

// --- Global search (eq. 1) ----------------------------------------------------------------------------

struct GlobalSearchResult
{
    std::vector<Coord> regionCentre; ///< per patch: fine source voxel at the centre of its search region
    int searches = 0;                ///< patches that ran the global search
    int tracked = 0;                 ///< patches whose region followed last frame's match
};
GlobalSearchResult globalSearch(const Frame& target, const SourceBands& src, const std::vector<uint8_t>& active,
    const PatchTracks& tracks, const FrameSetup& fs, const MatchWeights& w);

// --- Local search (eq. 2) and coherence ---------------------------------------------------------------

/// Full-resolution E_h of a target patch (corner) against a source corner, with or without the beta term.
struct PatchEnergy
{
    const FrameSetup& fs;
    const TargetAtOutput& t;
    const SourceBands& src;
    const VectorField& advectedDetail;
    double operator()(const Coord& targetCorner, const Coord& sourceCorner, bool temporal) const;
    /// The same at a source corner between voxels (trilinear samples).
    double at(const Coord& targetCorner, const Vec3d& sourceCorner, bool temporal) const;
};

struct LocalSearchResult
{
    std::vector<size_t> activeList; ///< indices of the active patches, ascending
    std::vector<Coord> chosen;      ///< per patch: the chosen source corner (rounded when it is between voxels)
    std::vector<Vec3d> chosenExact; ///< per patch: the chosen source corner
    int followed = 0;               ///< patches that took their continuation (followSourceFlow)
    std::vector<double> energy;     ///< per patch: its E_h
    CoordBBox corners;              ///< allowed source corners
    int repeatsAvoided = 0;         ///< patches that took another candidate than their best (avoidRepeats)
    double meanEnergy() const;
};
/// TransferSettings::repeatRadius: patches within that many patches of each other do not take overlapping source
/// patches. `ranked` holds every patch's re-scored candidates, best first; `fixed` patches keep their choice.
/// Returns the patches changed.
int avoidRepeats(LocalSearchResult& out, const std::vector<std::vector<std::pair<double, Coord>>>& ranked,
    const std::vector<uint8_t>& fixed, const FrameSetup& fs);
LocalSearchResult localSearch(const PatchEnergy& energy, const std::vector<uint8_t>& active,
    const GlobalSearchResult& global, const PatchTracks& tracks, const MatchWeights& w);

/// Beyond the paper: red-black sweeps where a patch takes a neighbour's continued source patch when its E_h is
/// within TransferSettings::coherence of its own. Deterministic at any thread count.
void coherencePass(
    LocalSearchResult& local, const PatchEnergy& energy, const std::vector<uint8_t>& active, const PatchTracks& tracks);

// --- Paste, temporal blend, seams ---------------------------------------------------------------------

struct PasteResult
{
    VectorField detail;         ///< U_h over the fine box, zero outside active patches
    std::vector<Coord> offsets; ///< per patch: source voxel = output voxel + offset
};
PasteResult pastePatches(const LocalSearchResult& local, const SourceBands& src, const FrameSetup& fs);

/// Beyond eq. 2's beta term: mixes last frame's advected detail into the patches it reaches, lambda^gap where the
/// patch carried detail (regenerateBlend^gap where the flow has stretched it: TransferSettings::regenerate), and as
/// much as flowed in where smoke just arrived.
/// What the blend keeps the frame's detail structure near (TransferSettings::structureTolerance): the source's
/// anisotropy along the target's mean flow direction `d`; tolerance 0 = no goal.
struct StructureGoal
{
    Vec3d d{0.0};        ///< the target's mean flow direction (unit)
    double source = 0.0; ///< the source's detail anisotropy along d
    double aim = 0.0;    ///< what the blend's pre-seam estimate aims at: `source`, moved by the seams' drift
    double tolerance = 0.0;
};
/// The goal for this frame: d the mean of up(u_t) over the target's smoke, the source's detail anisotropy over
/// its smoke along d (as `measure` computes both); no goal when off or when either is undefined.
StructureGoal structureGoal(const TargetAtOutput& t, const SourceBands& bands, const FrameSetup& fs);
/// The finished frame's anisotropy along goal.d as `measure` computes it: U = up(u_t) + detail over the output's
/// smoke (density > densityThreshold). nullopt where it is undefined (no smoke, no gradient).
std::optional<double> finishedAnisotropy(const VectorField& detail, const TargetAtOutput& t, const ScalarField& density,
    const StructureGoal& goal, const FrameSetup& fs);

struct TemporalBlend
{
    std::vector<float> weight;       ///< per layout patch; empty without carried detail
    int regenerated = 0;             ///< patches that took the regeneration weight
    int regeneratedForStructure = 0; ///< of those, the ones the structure goal added
    double estimate = 0.0;           ///< the goal's estimate of the frame's anisotropy after it (0 without a goal)
};
TemporalBlend blendTemporal(VectorField& detail, const TargetAtOutput& t, const VectorField& advectedDetail,
    const LocalSearchResult& local, const PatchTracks& tracks, const FrameSetup& fs, const StructureGoal& goal);

/// What the seam stage is given besides the detail.
struct SeamInputs
{
    const TargetAtOutput& t;
    const SourceBands& src;
    const std::vector<uint8_t>& active;
    const std::vector<Coord>& offsets;
    const VectorField& advectedDetail;
    const std::vector<float>& blendWeight;
    double scaleEstimate = 1.0; ///< the energy factor this frame's detail is expected to get
};
/// Section 3.3 with this project's additions (target-divergence term, box rows, temporal targets).
SeamStats smoothPatchSeams(VectorField& detail, const SeamInputs& in, const FrameSetup& fs, Progress* progress);

// --- Coarse part and energy ---------------------------------------------------------------------------

/// Mean |u|^2 (of u - less, when given) per voxel of the output's smoke.
struct SmokeEnergy
{
    const ScalarField& density;
    float threshold;
    size_t voxels;
    SmokeEnergy(const ScalarField& d, float th);
    double operator()(const VectorField& u, const VectorField* less = nullptr) const;
};

/// The factor that brings detail of mean energy `now` to `reference`, bounded to [1/3, 3].
double energyFactor(double reference, double now);

/// Before the seam solve: the energy factor this frame will get (estimated on the detail without its coarse
/// part), and the coarse part reduced to the tolerance under that factor. Returns the estimate.
double reduceCoarsePartBeforeSeams(VectorField& detail, const TargetAtOutput& t, const Frame& target,
    const SmokeEnergy& smoke, double referenceEnergy, const FrameSetup& fs);

/// After the seam solve: the coarse part out, the energy factor applied, the coarse part put back within the
/// tolerance. Fills energyScale, coarseKept and lfErr.
/// Per patch of `layout`: the rms of `detail` over the patch's voxels where density > threshold (0 without smoke).
std::vector<double> patchRms(
    const VectorField& detail, const ScalarField& density, float threshold, const PatchLayout& layout);
/// Multiplies `detail` by per-patch gains interpolated trilinearly between patch centres (no step at a seam).
void applyPatchGain(VectorField& detail, const std::vector<float>& gain, const PatchLayout& layout);
/// Beyond the paper (TransferSettings::localEnergy): each patch's rms over its smoke moves toward `pastedRms` (the
/// source detail pasted into it), `strength` of the way in log, gains in [1/3, 3] interpolated between patch centres;
/// the frame's mean energy over the smoke is kept. One energy factor per frame lifted detail that nothing carries
/// away (the floor under an emitter) every frame, issue 42's band.
void matchPatchStrength(VectorField& detail, const std::vector<double>& pastedRms, const SmokeEnergy& smoke,
    const PatchLayout& layout, float strength);
/// Removes from `detail` the coarse-cell means of its change since `before` (the box means a voxel-by-voxel gain puts
/// in), so that a post-step leaves the target's coarse motion (lf_err) as calibration set it.
void keepCoarseMeans(VectorField& detail, const VectorField& before, int f);
/// Beyond the paper (TransferSettings::evenPatches): a variance-preserving correction of the blend at the seams. The
/// seam solve averages neighbouring patches' gradients, and an average of unrelated fields is weaker than either, so
/// the detail's strength rose and fell with the patch period (issue 42's lattice). U_h is scaled by a per-axis gain
/// of the voxel's position in its patch that evens out the mean |U_h|^2 over the smoke (clamped to [0.5, 2],
/// circularly smoothed) raised to `strength` (in (0, 1]: how far to go), twice. Returns the largest full gain (or its
/// inverse) of the first pass: the lattice it found.
/// The smallest lattice (largest gain of evenPatchStrength's first pass) that is evened.
constexpr double kEvenPatchesFrom = 1.2;
double evenPatchStrength(
    VectorField& detail, const ScalarField& density, float threshold, const PatchLayout& layout, float strength);
/// Scales U_h down where |curl(up(u_t) + U_h)| exceeds `cap` inside the smoke (density > threshold): gain cap / |curl|
/// there, spread over its 3^3 neighbourhood and smoothed. Returns the voxels that were over the cap.
size_t limitVorticity(
    VectorField& detail, const VectorField& Ut, const ScalarField& density, float threshold, double cap);
void calibrateDetail(VectorField& detail, const TargetAtOutput& t, const Frame& target, const SmokeEnergy& smoke,
    double referenceEnergy, const std::vector<float>& sourceMagnitudes, const FrameSetup& fs, TransferStats& st);

// --- Output and state ---------------------------------------------------------------------------------

/// rms(U_h - U^_h) / rms(U_h) and rms(U_h) / rms(U^_h) over the output's smoke (nullopt without carried detail).
void detailChange(const VectorField& detail, const VectorField& advectedDetail, const ScalarField& density,
    float threshold, TransferStats& st);

/// U = up(u_t) + U_h, the density, up-sampled temperature and flame, and the metadata a later measure or resume
/// reads.
Frame assembleOutput(
    const Frame& target, const TargetAtOutput& t, const VectorField& detail, ScalarField density, const FrameSetup& fs);

/// Carries this frame into `c` for the next one: the detail is recomputed from the output velocity exactly as
/// restoreState must do from the written file, so a --resume continues bit-identically.
void carryState(CarriedState& c, const Frame& target, const Frame& source, const Frame& out, const TargetAtOutput& t,
    const ScalarField& emission, const FrameSetup& fs);

/// The compact text form of the tracks, the alignment and the source frame, and its inverse (throws ValueError on
/// damage; reads the integer tracks of version 2 too).
struct SavedState
{
    int f = 0, B = 0;
    AlignmentState align;
    std::map<Coord, Vec3d> tracks;
    int sourceNumber = 0;
    double sourceDt = 0.0; ///< 0 when unknown (version 2): no continuation on the first resumed frame
};
std::string saveStateText(const SavedState& state);
SavedState parseStateText(const std::string& text);

} // namespace turb::detail
