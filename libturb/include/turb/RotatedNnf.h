/// @file RotatedNnf.h
/// @brief Nearest-neighbour fields into a video with rotated patches: the (i, x, y, theta) field of
///        Fluidymation (Platkevič et al. 2020, section 3.6), its rotation tables, and the
///        pyramid operations UPSCALENNF and DOWNSCALENNF of Algorithm 1.
///
/// A target pixel q = (x^, y^) maps to the source patch centred on pixel (x, y) of source frame i, turned
/// by theta: the target offset o from q reads the source at (x, y) + R_{-theta} o (the patch is rotated by
/// theta onto the target), and a source direction alpha appears in the target as alpha + theta. R_theta
/// acts in image axes (x right, y down): R_theta(x, y) = (x cos - y sin, x sin + y cos), which turns
/// clockwise on screen for theta > 0. Rotations are quantised to kRotations steps (5.6 degrees):
/// nearest-pixel offset tables per step make the search's patch distance as cheap as an unrotated one.
///
/// @code
/// turb::RotatedNnf coarse = ...;                                   // level l + 1
/// turb::RotatedNnf up = turb::upscaleNnf(coarse, W, H);           // level l, the paper's rotated offsets
/// turb::RotatedNnf prev = turb::downscaleNnf(previousFine, 2, W / 4, H / 4); // mode of 4x4 blocks
/// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace turb {

/// Rotation steps per full turn.
constexpr int kRotations = 64;

/// theta of rotation step k, radians in [0, 2 pi).
double rotationAngle(int k);

/// The step nearest to `theta` (any real; wrapped), in [0, kRotations).
int rotationIndex(double theta);

/// One match: source frame, source centre pixel, rotation step. frame < 0 means "no match".
struct PatchRef
{
    std::int16_t frame = -1;
    std::int16_t x = 0, y = 0;
    std::uint8_t rotation = 0;

    bool valid() const { return frame >= 0; }
    bool operator==(const PatchRef& o) const
    {
        return frame == o.frame && x == o.x && y == o.y && rotation == o.rotation;
    }
    bool operator!=(const PatchRef& o) const { return !(*this == o); }
};

/// A field over a width x height target grid (row-major), with the patch distance of each match.
struct RotatedNnf
{
    int width = 0, height = 0;
    std::vector<PatchRef> match;
    std::vector<float> distance;
};

/// A field of that size with no matches (distances infinite).
RotatedNnf emptyRotatedNnf(int width, int height);

/// R_{-theta_k} (dx, dy): where the target offset (dx, dy) reads the source patch of rotation step k.
void sourceOffset(int k, double dx, double dy, double& sx, double& sy);

/// For every rotation step, the nearest-pixel source offsets of a (2r+1)^2 patch's target offsets
/// (row by row, dy then dx from -r): offsets(k)[2 t], offsets(k)[2 t + 1].
class RotationTable
{
public:
    explicit RotationTable(int radius);
    int radius() const { return mRadius; }
    /// Every offset of every step lies within this many pixels of the centre (the margin a centre needs).
    int reach() const { return mReach; }
    const int* offsets(int k) const { return mOffsets.data() + std::size_t(k) * std::size_t(2 * mCount); }
    int count() const { return mCount; }

private:
    int mRadius = 0, mCount = 0, mReach = 0;
    std::vector<int> mOffsets;
};

/// UPSCALENNF (section 3.6, Fig. 6): fine pixel (x^, y^) takes (i, x', y', theta) from coarse pixel
/// (floor(x^/2), floor(y^/2)) and becomes (i, x_up, y_up, theta) with
///     (x_up, y_up) = 2 (x', y') + c + R_{-theta}((x^ mod 2, y^ mod 2) - c),  c = (1/2, 1/2),
/// rounded to the nearest pixel. At theta = 0 this is plain upsampling: 2 (x', y') + (x^ mod 2, y^ mod 2).
/// Fine pixels whose coarse pixel has no match get none. Coordinates may leave the source: callers
/// check them against their own source domain.
RotatedNnf upscaleNnf(const RotatedNnf& coarse, int fineWidth, int fineHeight);

/// DOWNSCALENNF (section 3.6, Fig. 7) by `levels` halvings: coarse pixel (X, Y) gathers the valid matches
/// of the 2^levels square of fine pixels whose top-left corner is 2^levels (X, Y), maps each through the
/// inverse of the upscaling, (x', y') = (x - R_{-theta}(o - c_l) - c_l) / 2^levels with o the offset in
/// the square and c_l = (2^levels - 1) / 2 (rounded), and keeps the most frequent (i, x', y'), with the
/// rotation of its first occurrence in scan order (ties: the first key reached). No valid match: none.
RotatedNnf downscaleNnf(const RotatedNnf& fine, int levels, int coarseWidth, int coarseHeight);

} // namespace turb
