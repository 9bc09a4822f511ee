/// @file DensityGuide.h
/// @brief Keeps a high-resolution density's coarse cell means on the low-resolution target's, so an up-res
///        keeps the target's smoke at the target's scale while the detail redistributes it inside the cells.
///
/// Density advected at high resolution through the detailed velocity drifts from the target's over a shot: it is
/// less diffused than the coarse simulation's, and the detail mixes it across cell borders (measured on a Blender
/// 32^3 plume up-ressed 4x: the coarse density error grew from 0.16 at frame 1 to 0.30 at frame 30). The guide
/// removes that drift once per frame, in the spirit of Houdini's "Gas Match Field"/guided simulation: each target
/// smoke cell's mean is moved toward the target's by a smooth multiplicative gain, so the fine structure inside a
/// cell is kept (a gain scales it, it does not replace it), and no value exceeds the target's peak.
///
/// Coarse cell c holds the fine voxels I with floor(I / f) = c (Lattice::refined). Cells where the target's density
/// exceeds `threshold` are guided. How much of a cell's correction a fine voxel takes is a weight of the trilinear
/// up(coarse) at the voxel: 0 at `threshold`, rising linearly to 1 at (1 + rampFactor) x threshold. The mass
/// the guide adds (or, if more, the mass beyond the target's) is taken from the voxels with weight below 1 in
/// proportion to (1 - weight); what is still beyond the target's mass then comes in proportion to
/// 1 - up(indicator of the guided cells). Nothing changes abruptly at a cell face, so the output's silhouette
/// follows the target's smooth density, not its cells (measure's density_imprint). The cost: a target with a hard
/// edge keeps more coarse error in its border cells (the trilinear weights cannot fill them without spilling).
///
/// @code
/// turb::DensityGuideSettings s;                 // strength 1: remove the whole error each frame
/// turb::DensityGuideStats st = turb::guideDensity(fineDensity, targetDensity, 4, s);
/// @endcode
#pragma once

#include <turb/Field.h>

namespace turb {

struct DensityGuideSettings
{
    float strength = 1.0f;   ///< fraction of each guided cell's mean error removed per call, in [0, 1]; 0 = off
    int passes = 3;          ///< correction passes, >= 1: a trilinear gain spills into neighbouring cells, so one
                             ///< pass leaves a residual that the next ones take out
    float threshold = 0.01f; ///< coarse cells whose target density exceeds this are guided, >= 0
    float maxGain = 4.0f;    ///< bound on one pass's multiplicative gain, >= 1; cells with (almost) no fine smoke
                             ///< receive the missing mass evenly instead
    float rampFactor = 4.0f; ///< >= 0: the weight reaches 1 at (1 + rampFactor) x threshold of up(coarse); 0 = a
                             ///< step at the threshold
};

struct DensityGuideStats
{
    double errorBefore = 0.0; ///< coarseDensityError (Measure.h) over the guided cells, before
    double errorAfter = 0.0;  ///< the same after; both 0 when no cell is guided
    size_t guidedCells = 0;   ///< coarse cells with target smoke
};

/// Moves the f^3 block means of `fine` toward `coarse` where the target has smoke. First every value is capped at
/// the target's peak (a pile-up, not detail). Mass the guide adds is taken first from smoke where the target has
/// little or none (see the weight above), so guiding moves smoke into the target's cells before it makes any.
/// `fine` must cover exactly refineDomain(coarse.bbox(), f) (one layer for a 2D pair); values stay in
/// [0, the target's peak].
/// Throws ValueError on a box mismatch, f < 1 or settings out of range.
DensityGuideStats guideDensity(ScalarField& fine, const ScalarField& coarse, int f, const DensityGuideSettings& s = {});

} // namespace turb
