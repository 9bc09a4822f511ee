/// @file Synth.h
/// @brief Motion-field texture synthesis (Ma, Wei, Guo, Zhou, "Motion Field Texture
///        Synthesis", SIGGRAPH Asia 2009): detail motion H synthesised from small vector-field
///        exemplars, oriented along a coarse flow L, and combined as F = up(L) + omega * H.
///
/// The stages, in the order of the paper's Pseudocode 1:
/// 1. `SynthExemplars` prepares each view once per sequence: exemplar pyramid, neighbourhood
///    descriptors, PCA and a FLANN tree (turb::PatchIndex), and k-coherence similarity sets.
/// 2. `synthesizeDetail` runs texture optimisation on vectors (Kwatra et al. 2005) over a pyramid:
///    a search step (tree search, or k-coherence, section 3.7) and a least-squares assignment step
///    (Eq. 1), with neighbourhoods sampled in the local frame of L (sections 3.1, 3.3), the view
///    projection of section 3.2 (a view matches only its two in-plane components, and each component
///    of a voxel averages the views that see it, Eq. 2, weighted per view), and the soft wall term
///    E_n of Eq. 3. The first frame starts from random exemplar samples; later frames from the
///    previous detail advected through L (section 3.4). The synthesised H is in local coordinates;
///    the coordinate transformation to world axes is the post-process of section 3.1.
/// 3. `combineMotion` forms F = up(L) + omega * H' (section 3.5), omega constant or proportional to
///    the kinetic energy or vorticity of L. Projection.h can then make F divergence-free (3.6).
/// 4. `LookbackDensity` integrates density over the last m frames only (supplement A).
///
/// Local frames: e1 follows L. In 2D e2 is e1 turned 90 degrees and e3 = z. In 3D e2 comes from the
/// density gradient or a given vector, made orthogonal to e1, and e3 = e1 x e2. A 2D view looking
/// along local axis a covers the plane (e2, e3) for a = 0, (e1, e3) for a = 1 and (e1, e2) for a = 2,
/// with exemplar x along the first axis and y along the second: the flow direction is the exemplar's
/// x axis in the two views that contain it, as in the paper's 2D case.
///
/// A 2D synthesis is a coarse field one voxel thick in z: the output is one voxel thick too, and the
/// single view looks along z. Units: exemplars are normalised to unit rms, so H has about unit rms
/// speed, and omega carries the units (or is relative to the rms speed of L).
///
/// @code
/// turb::SynthSettings s;                                  // paper defaults
/// turb::SynthView v{turb::proceduralExemplar({}), 2, 1.0f};
/// turb::SynthExemplars ex({v}, s, /*volume=*/false);
/// turb::SynthInput in; in.coarse = &L; in.factor = 4;
/// turb::DetailField H = turb::synthesizeDetail(ex, in, s);
/// turb::VectorField F = turb::combineMotion(L, H.world, turb::CombineSettings{});
/// @endcode
#pragma once

#include <turb/Advect.h>
#include <turb/Exemplar.h>
#include <turb/Field.h>
#include <turb/Projection.h>
#include <turb/Progress.h>

#include <cstdint>
#include <deque>
#include <array>
#include <memory>
#include <string>
#include <vector>

namespace turb {

/// One input view (section 3.2): an exemplar and the local axis it looks along.
struct SynthView
{
    Exemplar exemplar; ///< planar (2 channels) or volumetric (3 channels)
    int normal = 2; ///< planar exemplars: local axis the view looks along (0 = e1 along L, 1 = e2, 2 = e3); ignored for
                    ///< volumetric ones
    float weight =
        1.0f; ///< weight of this view in the assignment (Eq. 2 generalised), > 0; a large weight lets one view dominate
};

enum class SearchMethod {
    Tree,      ///< exact k-d tree over PCA-reduced neighbourhoods (the paper's default)
    KCoherence ///< k-coherence candidates (section 3.7): constant time per sample, discrete assignment
};

struct OrientationSettings
{
    bool follow =
        true; ///< sample neighbourhoods in the local frame of L and rotate H into it (3.1, 3.3); false = world axes
    bool densitySecondary = true; ///< 3D: e2 from the coarse density gradient where there is one, else `secondary`
    Vec3d secondary{0, 1, 0};     ///< 3D: the given secondary direction (world) when autoSecondary is off
    /// 3D (beyond the paper): the secondary direction is n x e1, with n the direction L has least of
    /// (the eigenvector of the smallest eigenvalue of sum L L^T over the box: the normal of a planar vortex, a
    /// horizontal axis for a rising plume). For a flow in a plane this is 2D's frame (e2 = z x e1). A fixed axis s
    /// that L crosses turns the frame 180 degrees there (e2 = s - (s.e1) e1 changes sign where e1 passes s),
    /// which mirrors the texture's sense of rotation across a plane. With a density gradient, n x e1 replaces
    /// `secondary` as the gradient's fallback.
    bool autoSecondary = true;
    Vec3d fallback{1, 0, 0};     ///< direction of e1 where L is (nearly) still
    double stillFraction = 0.05; ///< |L| below about this fraction of rms|L| blends e1 toward `fallback`, in (0, 1]
};

struct BoundarySettings
{
    unsigned walls = 0;   ///< domain faces that are walls: bit 2a is the min face of axis a, bit 2a+1 the max face
    double lambda = 50.0; ///< E_n weight (Eq. 3) on the wall relative to the texture term: the normal component shrinks
                          ///< by 1/(1+lambda) there; >= 0
    double width = 1.5;   ///< Gaussian sigma of lambda in voxels of each pyramid level: wider at coarse levels, sharper
                          ///< at fine ones (paper), > 0
};

struct SynthSettings
{
    int levels = 0; ///< pyramid levels; 0 = paper: 3, or 2 when the exemplar is <= 16^2 (fewer when the output is tiny)
    int largeRadius = 8;     ///< 2D: first neighbourhood (2r+1)^2 per level; 8 = 17^2 (paper)
    int largeIterations = 4; ///< 2D: iterations per level at the large neighbourhood; paper 3-5
    int smallRadius = 4;     ///< second neighbourhood; 4 = 9^2 (paper); in 3D the only size (9^2 slices, 9^3 volumes)
    int smallIterations = 4; ///< iterations per level at the small neighbourhood; paper 3-5
    int volumeTapStep = 2;   ///< volumetric exemplars: a tap every n voxels over the 9^3 footprint (2: 5^3 taps), >= 1
    int spacing =
        0; ///< distance between optimised neighbourhood centres in voxels; 0 = auto ((2r+1)/4 in 2D, Kwatra; 3 in 3D)
    double robustExponent = 0.8; ///< Kwatra's robust weights |x_p - z_p|^(r-2); 2 = plain least squares; in (0, 2]
    bool matchVariance =
        true; ///< components shared by several views keep the views' mean and spread (a moment match in the spirit of
              ///< Kopf et al.'s histogram matching; false = the paper's plain average)
    int pcaComponents = 16;                   ///< PCA dimensions for the tree search, >= 1
    SearchMethod search = SearchMethod::Tree; ///< tree search or k-coherence (section 3.7)
    int kSimilar = 5;                         ///< k-coherence: exemplar neighbourhoods kept per pixel, >= 1
    int treeIterationsPerLevel =
        1; ///< k-coherence: first iterations of each level that still use the tree (0 = pure k-coherence)
    int continueIterations =
        3; ///< frames after the first: iterations at the finest level from the advected detail, >= 1
    double temporalWeight =
        0.5;                ///< frames after the first: pull toward the advected detail (the O(x) term of Eq. 1), >= 0
    std::uint64_t seed = 1; ///< random initialisation and centre jitter; the same seed gives the same output
    int threads = 0;        ///< worker threads, 0 = all; results do not depend on it
    OrientationSettings orientation; ///< local frames (sections 3.1, 3.3)
    BoundarySettings boundary;       ///< soft wall constraint (section 3.6, Eq. 3)
    /// Beyond the paper: coarse cells synthesised around L's box on every face that is not a wall
    /// (L and its density extended by their face values), then cut off. A voxel at a face otherwise gets votes
    /// from fewer neighbourhoods than an interior one, and the texture shows straight lines along the faces.
    /// 0 = the box alone (the paper); >= 0. Costs about (1 + 2 pad / cells)^3 in time.
    int facePadding = 2;
    bool traceDescent = false; ///< fill SynthLevelStats::descent (costs two more neighbourhood passes per iteration)
    AdvectSettings advect;     ///< advection of the previous frame's detail
};

/// Exemplar pyramids and search structures of a set of views, built once and shared by every frame.
class SynthExemplars
{
public:
    /// `volume`: the output is 3D (else 2D: exactly one planar view looking along e3).
    /// Throws ValueError on inconsistent views.
    SynthExemplars(
        std::vector<SynthView> views, const SynthSettings& settings, bool volume, Progress* progress = nullptr);
    ~SynthExemplars();
    SynthExemplars(SynthExemplars&&) noexcept;
    SynthExemplars& operator=(SynthExemplars&&) noexcept;

    int levels() const;
    bool volume() const;
    const std::vector<SynthView>& views() const;
    /// Fraction of descriptor variance the PCA keeps, per view, at the finest level and small radius.
    std::vector<double> explainedVariance() const;

    struct Impl;
    const Impl& impl() const { return *mImpl; }

private:
    std::unique_ptr<Impl> mImpl;
};

struct DetailField;

/// One frame's inputs.
struct SynthInput
{
    const VectorField* coarse = nullptr;        ///< L: coarse motion, world units (required)
    const ScalarField* coarseDensity = nullptr; ///< optional, same lattice: 3D secondary axis from its gradient
    const ScalarField* obstacle = nullptr; ///< optional obstacle signed distance (world units, < 0 inside), any lattice
    int factor = 4;                        ///< output voxel = coarse voxel / factor, >= 1
    const DetailField* previous = nullptr; ///< the previous frame's detail: initialise by advection (section 3.4)
    double dt = 0.0;                       ///< time from the previous frame to this one (L * dt is a displacement)
};

/// Per pyramid level: what was run and the texture energy after each iteration.
struct SynthLevelStats
{
    int level = 0;              ///< 0 = coarsest
    Coord dim{0};               ///< output size at this level
    std::vector<int> radius;    ///< neighbourhood radius of each iteration
    std::vector<bool> tree;     ///< each iteration searched the tree (else k-coherence)
    std::vector<double> energy; ///< mean squared neighbourhood distance per channel after each search
    /// With SynthSettings::traceDescent, per iteration: Kwatra's objective (the robust-weighted mean distance) of
    /// that iteration's centres and matches at the search, after the weighted average (the M-step proper) and
    /// after the moment match, temporal and wall terms. Empty otherwise.
    std::vector<std::array<double, 3>> descent;
};

/// The synthesised detail motion of one frame.
struct DetailField
{
    VectorField world;  ///< H' = R H: detail in world axes on the fine lattice, about unit rms speed
    VectorField local;  ///< H: the same in each voxel's local frame (what the synthesis matched)
    VectorField padded; ///< H' over the box grown by SynthSettings::facePadding: what the next frame continues
                        ///< from (empty without padding; `world` is its crop to the output box)
    std::vector<SynthLevelStats> levels; ///< per level, coarsest first
    bool fromPrevious = false;           ///< initialised by advecting the previous frame
    double finalEnergy() const
    {
        return levels.empty() || levels.back().energy.empty() ? 0.0 : levels.back().energy.back();
    }
};

/// Synthesises the detail field H of one frame on the lattice refined `factor` times from L's. Throws ValueError
/// on a missing or non-finite L, a density on another box, a negative face padding or non-finite directions.
DetailField synthesizeDetail(const SynthExemplars& exemplars, const SynthInput& input, const SynthSettings& settings,
    Progress* progress = nullptr);

/// The fine box and lattice of the output for a coarse field: refineBox/refined in 3D; in 2D (a
/// coarse box one voxel thick in z) the output stays one voxel thick, at the coarse slice's height.
struct FineDomain
{
    CoordBBox box;
    Lattice lattice;
    bool twoD = false;
};
FineDomain fineDomain(const CoordBBox& coarseBox, const Lattice& coarseLattice, int factor);
inline FineDomain fineDomain(const VectorField& coarse, int factor)
{
    return fineDomain(coarse.bbox(), coarse.lattice(), factor);
}

/// up(L): L sampled cell-centred trilinearly on the fine domain (constant extension at the faces).
VectorField upsampleCoarse(const VectorField& coarse, int factor);
ScalarField upsampleCoarse(const ScalarField& coarse, int factor);

struct CombineSettings
{
    enum class Weighting {
        Constant,      ///< omega everywhere (paper's default, supplement B)
        KineticEnergy, ///< omega * e(x) / mean(e), e = |L|^2 / 2 (Kim et al. 2008)
        Vorticity      ///< omega * |curl L|(x) / mean|curl L| (Fedkiw et al. 2001)
    };
    Weighting weighting =
        Weighting::Constant; ///< spatial shape of omega (section 3.5); means are over moving voxels (|L| > 5% of max)
    double omega = 0.5;   ///< detail strength, >= 0; relative: times rms|L| over moving voxels (|L| > 5% of max); else
                          ///< world units per time
    bool relative = true; ///< omega relative to the rms speed of L (true) or absolute velocity units (false)
    bool removeCoarsePart = true; ///< beyond the paper: take omega * H''s coarse-cell means (spread
                                  ///< trilinearly, five passes) out of the detail, so F keeps L's coarse motion;
                                  ///< false = the paper's F = up(L) + omega * H'
    /// Beyond the paper: take the gradient part out of omega * H' after its coarse part, so that its
    /// central-difference divergence (what `measure`'s div_rel counts) is zero to `solenoidalTolerance`
    /// (removeCentralDivergence), then one more pass of the coarse part (removeCoarsePart) for the means the
    /// gradient part carried: F's divergence is about up(L)'s, and its div_rel below up(L)'s own (docs/synth.md).
    /// false = the detail's divergence is left in (the paper).
    bool solenoidalDetail = true;
    double solenoidalTolerance = 1e-2; ///< relative rms divergence left in the detail, in (0, 1)
    int solenoidalIterations = 500;    ///< conjugate-gradient cap of that solve, >= 1
    /// Beyond the paper: where the detail goes. With a coarse density (L's box and lattice), omega is
    /// multiplied by a weight that is 1 within `smokeMargin` coarse cells of the smoke (density >
    /// `smokeThreshold`), falls as a half cosine to 0 over the next `smokeFalloff` cells, and is 0 beyond: still
    /// air far from the smoke keeps L's motion. nullptr = detail everywhere (the paper).
    const ScalarField* smoke = nullptr;
    float smokeThreshold = 0.01f; ///< smoke is coarse density > this, >= 0
    double smokeMargin = 2.0;     ///< coarse cells of full detail around the smoke, >= 0
    double smokeFalloff = 2.0;    ///< coarse cells over which the detail fades to zero beyond the margin, > 0
};

/// The weight CombineSettings::smoke applies, on the coarse density's box and lattice: 1 within `margin` cells of
/// a cell with density > threshold, 0.5 (1 + cos(pi (d - margin) / falloff)) out to margin + falloff, 0 beyond
/// (d: Euclidean distance between cell centres, distanceToSmoke). All zeros when no cell is smoke. Throws
/// ValueError on a negative threshold or margin, or a falloff <= 0.
ScalarField smokeDetailWeight(const ScalarField& coarseDensity, float threshold, double margin, double falloff);

/// F = up(L) + omega * H' on H's box and lattice (section 3.5), less the detail's coarse part unless
/// settings.removeCoarsePart is off, and less its divergence with settings.solenoidalDetail (whose solve
/// `diagnostics` receives when given). Throws ValueError on empty fields, a negative omega, a detail that does not
/// cover the refined coarse box, or a solenoidal tolerance outside (0, 1).
VectorField combineMotion(const VectorField& coarse, const VectorField& detailWorld, const CombineSettings& settings,
    CentralDivergenceResult* diagnostics = nullptr);

struct LookbackSettings
{
    int frames = 12;       ///< m: frames of look-back integration (supplement A, paper: 10-20); 0 = naive (all frames)
    AdvectSettings advect; ///< the advection scheme
};

/// Density for rendering, integrated over the last m frames only (supplement A, Pseudocode 4):
/// D_i starts from O_{i-m}, the density advected through the coarse motion alone, and is moved
/// through F_{i-m+1}..F_i, adding each frame's sources after its advection. Frames before m start
/// from an empty field. With m = 0 it is the naive scheme D_i = advect(D_{i-1}, F_i) + S_i.
class LookbackDensity
{
public:
    explicit LookbackDensity(const LookbackSettings& settings);
    /// Adds frame i: its combined motion F_i, its sources S_i and its coarse-only density O_i (all on
    /// the fine lattice; O_i may be empty when m = 0). `dt` is the time since the previous call's frame (frame
    /// gap x time per frame). Returns D_i.
    ScalarField step(const VectorField& motion, const ScalarField& sources, const ScalarField& coarseOnly, double dt,
        Progress* progress = nullptr);

private:
    LookbackSettings mSettings;
    std::deque<VectorField> mMotion;  // F of the last m frames
    std::deque<ScalarField> mSources; // S of the last m frames
    std::deque<double> mDt;           // time from the frame before each of them (frame gaps differ)
    std::deque<ScalarField> mCoarse;  // O of the last m + 1 frames
    ScalarField mNaive;               // m = 0
};

/// How well a synthesised field reproduces an exemplar's neighbourhoods (the statistical test):
/// the mean over sampled output neighbourhoods of the squared distance to the nearest exemplar
/// neighbourhood (exact search, per channel), for the field and for a shuffled copy of it.
struct TextureMatch
{
    double distance = 0.0;          ///< mean nearest-neighbour squared distance per channel, synthesised field
    double shuffled = 0.0;          ///< the same for the field's vectors shuffled over its voxels
    double fieldRms[2] = {0, 0};    ///< rms of the field's two in-plane components over the compared slices
    double exemplarRms[2] = {0, 0}; ///< rms of the exemplar's two components
    int samples = 0;                ///< neighbourhoods compared
    double ratio() const { return shuffled > 0.0 ? distance / shuffled : 0.0; }
};

struct TextureMatchSettings
{
    int radius = 4;         ///< neighbourhood radius of the comparison (9^2)
    int axis = 2;           ///< the slices compared: perpendicular to this world axis, view convention
    int stride = 4;         ///< distance between sampled neighbourhood centres
    std::uint64_t seed = 7; ///< shuffle
};

/// Compares world-axis slices of a local-frame field `local` (use DetailField::local) with a planar
/// exemplar. Only centres whose whole neighbourhood is inside the field count.
TextureMatch textureMatch(const Exemplar& exemplar, const VectorField& local, const TextureMatchSettings& settings);

/// Built-in analytic coarse flows (for tests, demos and benchmarks without a cache).
struct AnalyticFlowSettings
{
    enum class Kind {
        Uniform, ///< constant velocity `speed` along angle `angleDegrees` in the xy plane
        Vortex,  ///< solid-body rotation about the domain's z axis (speed at the half-width)
        Shear    ///< u_x varies linearly in y from -speed to +speed
    };
    Kind kind = Kind::Uniform; ///< which flow
    Coord res{32, 32, 1};      ///< coarse resolution; z = 1 gives a 2D flow
    double voxelSize = 1.0;    ///< world units per coarse voxel, > 0
    double speed = 1.0;        ///< world units per time
    double angleDegrees = 0.0; ///< Uniform: direction in the xy plane, counter-clockwise from +x
};
VectorField analyticFlow(const AnalyticFlowSettings& settings);

} // namespace turb
