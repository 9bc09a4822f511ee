/// @file Farm.h
/// @brief Time chunks for farm runs: how a frame range is split into chunks with pre-roll and overlap, and
///        how the join cross-fades two chunks' overlap frames. Pure math: planning a submission, reading
///        and writing frames live in tools/ (`vdbturb farm`, docs/farm.md).
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
/// at frame 0 with no pre-roll. Throws ValueError when a chunk would be shorter than two overlaps (its two
/// overlaps would meet) or the arguments are out of range.
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

} // namespace turb
