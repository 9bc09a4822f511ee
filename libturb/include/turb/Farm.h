/// @file Farm.h
/// @brief Time chunks and space tiles for farm runs: how a frame range is split into chunks with pre-roll and
///        overlap, how the join cross-fades two chunks' overlap frames, how a target box is split into tiles with
///        halos, and how the join assembles the tiles' outputs. Pure math: planning a submission, reading and
///        writing frames live in the entry points (turb/run/Farm.h: `vdbturb farm`, docs/farm.md).
///
/// A chunk computes `preroll` frames before the first frame it keeps, so that its carried detail and
/// density are established when its frames start counting; consecutive chunks keep `overlap` common
/// frames, which the join cross-fades:
///   - detail U_h = U - up(u_t): U_h = w_a U_h,a + w_b U_h,b with w_a = cos(pi t / 2), w_b = sin(pi t / 2),
///     so w_a^2 + w_b^2 = 1 and two uncorrelated details keep their energy (a linear fade would lose up to
///     half of it at t = 1/2); where the two details correlate (rho, over the smoke), both weights are scaled by
///     one factor per frame so the blend still has w_a^2 E_a + w_b^2 E_b (the factor is 1 at rho = 0);
///   - density: linear, (1 - t) d_a + t d_b. Density is a conserved amount, not a random phase: weights
///     that sum to 1 keep its mass and the coarse means the density guide put on both chunks;
///   - temperature and flame are up-sampled from the target in both chunks (identical): taken from b.
/// t = (j + 1) / (overlap + 1) on the j-th overlap frame (j = 0 .. overlap - 1), so neither chunk's weight
/// is 0 or 1 inside the overlap.
///
/// @code
/// const auto chunks = turb::planTimeChunks(frames.size(), 10, 8, 10); // 10 chunks, P = 8, O = 10
/// // ... each chunk k runs transfer over frames[chunks[k].computeBegin .. chunks[k].end) ...
/// // the j-th frame chunks k and k+1 share, i = chunks[k + 1].keepBegin + j:
/// turb::BlendStats st;
/// turb::Frame out = turb::blendOverlap(fromA, fromB, cropped(upsample(target.velocity, f), fromB.velocity.bbox()),
///                                      turb::crossFade(j, 10), 0.01f, &st);
/// @endcode
#pragma once

#include <turb/Frame.h>

#include <cstddef>
#include <string>
#include <vector>

namespace turb {

/// One chunk of a frame list, as indices into it (end exclusive).
struct TimeChunk
{
    int index = 0;
    size_t computeBegin = 0; ///< first frame computed (pre-roll starts here)
    size_t keepBegin = 0;    ///< first frame that counts (shared with the previous chunk for `overlap` frames)
    size_t end = 0;          ///< one past the last frame computed and kept (the last `overlap` shared with the next)
};

/// Splits `frameCount` frames into `chunks` chunks of nearly equal length that overlap by `overlap` frames, each
/// computing up to `preroll` frames before its first kept one (fewer at the start of the list). Chunk 0 starts
/// at frame 0 with no pre-roll. Throws ValueError when a chunk between two others would be shorter than two
/// overlaps (its two overlaps would meet: three chunks would share a frame), the first or last chunk would keep no
/// frame of its own, or the arguments are out of range.
std::vector<TimeChunk> planTimeChunks(size_t frameCount, int chunks, int preroll, int overlap);

/// The weights of the j-th of `overlap` overlap frames (a = the earlier chunk, b = the later one).
struct CrossFade
{
    double t = 0.0;        ///< position in the overlap, (j + 1) / (overlap + 1)
    double detailA = 1.0;  ///< cos(pi t / 2)
    double detailB = 0.0;  ///< sin(pi t / 2); detailA^2 + detailB^2 = 1
    double densityA = 1.0; ///< 1 - t
    double densityB = 0.0; ///< t
};
CrossFade crossFade(int j, int overlap);

/// What a blend did, over the voxels where either chunk's density exceeds the threshold.
struct BlendStats
{
    size_t smokeVoxels = 0;
    double correlation = 0.0; ///< <U_h,a, U_h,b> / (|U_h,a| |U_h,b|): 0 for independent details
    double energyA = 0.0;     ///< mean |U_h,a|^2
    double energyB = 0.0;     ///< mean |U_h,b|^2
    double energyOut = 0.0;   ///< mean |U_h|^2 of the blend: w_a^2 E_a + w_b^2 E_b
    double energyScale = 1.0; ///< factor on both detail weights that made it so: 1 / sqrt(1 + 2 w_a w_b rho sqrt(E_a
                              ///< E_b) / (w_a^2 E_a + w_b^2 E_b))
};

/// Cross-fades one overlap frame. `a` and `b` are the two chunks' outputs of the same target frame (same box and
/// lattice); `upTarget` is up(u_t) on that box (the coarse motion both share). The smoke (for rho and the
/// energies) is where either density exceeds `densityThreshold`. Returns b's frame with the blended
/// velocity and density; b's metadata is kept except the resume state, which belongs to b's own sequence.
/// Throws ValueError when the boxes or lattices differ.
Frame blendOverlap(const Frame& a, const Frame& b, const VectorField& upTarget, const CrossFade& w,
    float densityThreshold, BlendStats* stats = nullptr);

// ---------------------------------------------------------------------------------------------
// Space tiles: the target's box split into a grid of tiles. Each tile's transfer holds its core grown by a halo
// (target voxels); the join weighs the tiles' outputs with linear ramps of `ramp` output voxels centred on the
// borders between cores, a partition of unity (the weights of every output voxel sum to 1).
//
//   tile 0 core            | tile 1 core
//   ==========================|=========================
//   tile 0 held ================|~~ halo ~~]
//                 [~~ halo ~~|================ tile 1 held
//   weight 0:   1 ..... 1 \  ramp  \ 0 ........
//   weight 1:   0 ..... 0 /  ramp  / 1 ........
//
// The halo keeps the ramp away from the held box's edge, where a tile's transfer sees no flow coming in (its
// patches, seams and advected detail and density there differ from a run over the whole box).

/// One tile, in target voxel indices (inclusive boxes).
struct SpaceTile
{
    int index = 0;  ///< x fastest, then y, then z
    Coord cell{0};  ///< position in the tiling, 0 .. counts - 1 per axis
    CoordBBox core; ///< the voxels this tile owns: the tiles' cores partition the planned box
    CoordBBox held; ///< core grown by the halo, within the planned box: the box the tile's transfer holds
};

/// A tiling of one box.
struct TilePlan
{
    CoordBBox box;   ///< the whole target box (the union of the frames' held boxes)
    Coord counts{1}; ///< tiles per axis
    int halo = 0;    ///< target voxels each tile holds past its core (where a neighbour is)
    std::vector<SpaceTile> tiles;

    /// Weight of tile `k` at output voxel `v` of a transfer at ratio `ratio` (refineDomain of the boxes): the
    /// product over axes of a linear ramp across each border of its core that has a neighbour, `ramp` output voxels
    /// wide and centred on the border plane; 1 inside, 0 outside. Over the tiles, the weights sum to 1 at every voxel
    /// of refineDomain(box) when 1 <= ramp <= the smallest core's width in output voxels (joinTiles checks that, and
    /// that ramp / 2 fits in the halo).
    double weight(size_t k, const Coord& v, int ratio, int ramp) const;
};

/// Splits `box` (target voxels) into counts.x() x counts.y() x counts.z() tiles of nearly equal size, their borders
/// rounded to multiples of `align` voxels (absolute indices, so that tiles of the same box agree at any count), each
/// held with `halo` voxels more toward every neighbour. A flat (2D) box takes one tile in z. Throws ValueError when a
/// count is < 1, a tile's core would be narrower than its halo, or a flat (2D) box is split in z.
TilePlan planSpaceTiles(const CoordBBox& box, const Coord& counts, int halo, int align = 1);

/// Throws ValueError unless a join ramp of `ramp` output voxels fits the plan at ratio `ratio`: at least 1, at most
/// the narrowest core along a split axis and at most twice the halo (so the ramp stays inside the held boxes).
void checkTileRamp(const TilePlan& plan, int ratio, int ramp);

/// A box as `transfer --tile-box` takes it: "X0,Y0,Z0,X1,Y1,Z1" (inclusive voxel indices).
std::string formatTileBox(const CoordBBox& box);
/// The inverse of formatTileBox. Throws ValueError naming the text unless it is six indices with min <= max.
CoordBBox parseTileBox(const std::string& text);

/// A border plane between two tiles' cores on the output lattice: output voxels with index >= `plane` along `axis`
/// belong to the upper tile's core.
struct TileBorder
{
    int axis = 0;
    int plane = 0;
};

/// Every distinct border plane of a plan at ratio `ratio` (refineDomain's factors; sorted by axis, then plane).
std::vector<TileBorder> tileBorders(const TilePlan& plan, int ratio);

/// "x:64,128;y:64" (the metadata and `measure --tile-borders` form); "" without borders.
std::string formatTileBorders(const std::vector<TileBorder>& borders);
/// The inverse of formatTileBorders. Throws ValueError naming the text when it does not parse.
std::vector<TileBorder> parseTileBorders(const std::string& text);

/// What a tile join did.
struct TileJoinStats
{
    size_t seamVoxels = 0;       ///< output voxels of the smoke where two or more tiles have weight
    double disagreement = 0.0;   ///< over those: sqrt(sum_k lambda_k |U_k - U|^2 / sum |U - up(u_t)|^2), the tiles'
                                 ///< spread over the detail's rms (0 where the tiles agree; about 0.7 when independent)
    double correlation = 1.0;    ///< the tiles' f_k's correlation rho over the smoke they share, all pairs pooled
                                 ///< (1 without shared smoke or without up(u_t))
    double minCorrelation = 1.0; ///< the lowest pair's
};

/// Assembles one frame from the tiles' outputs (`tiles[k]` made over plan.tiles[k].held at ratio `ratio`: its fields
/// cover at least refineDomain(held) where its weight is not zero). With lambda_k the weights of TilePlan::weight
/// (`ramp` output voxels):
///   - density, temperature and flame: sum_k lambda_k f_k (the mass is kept, tiles that agree give their field);
///   - velocity, with `upTarget` = up(u_t) covering refineDomain(plan.box): each tile's detail U_k - up splits into
///     its coarse-cell means c_k (piecewise constant over the target's cells: the coarse motion lf_err measures) and
///     the rest f_k; U = up + sum_k lambda_k c_k + s sum_k sqrt(lambda_k) f_k. The means blend linearly, as motion;
///     sum lambda_k = 1 keeps the energy of independent f_k (a linear fade loses up to half of it mid-ramp, where
///     tiles split along the flow are nearly independent); s = 1 / sqrt(1 + sum_{k != l} sqrt(lambda_k lambda_l)
///     rho_kl) brings correlated f_k back to that energy, rho_kl being the pair's correlation over the smoke they
///     share this frame (tiles that agree exactly give their common detail).
///     Without `upTarget` (empty), the velocity is the lambda-weighted sum.
/// Metadata is tile 0's without the resume state. Throws ValueError when the counts differ, the tiles' lattices
/// differ, a field is missing from some tiles only, a voxel with weight is not covered by its tile, or the ramp is
/// below 1, wider than a tile or wider than twice the halo.
Frame joinTiles(const std::vector<Frame>& tiles, const TilePlan& plan, int ratio, int ramp, float densityThreshold,
    const VectorField& upTarget, TileJoinStats* stats = nullptr);

} // namespace turb
