/// @file Frame.h
/// @brief The one in-memory frame type every stage reads and writes.
///
/// Conventions, enforced by the IO layer when it loads a cache:
/// - velocity is cell-centred (staggered MAC grids are converted) and in world units per time unit;
/// - all fields share one Lattice and cover one box: the region of the cache that matters (the IO layer crops
///   a cache to its smoke and a margin, so a small plume in a large domain costs what the plume costs);
/// - `dt` is the time between consecutive frames in the velocity's time unit, so a voxel moves
///   `velocity * dt / voxelSize` voxels per frame. 0 means "unknown" and a stage needing it must ask;
/// - `timeUnit` is how many seconds that time unit lasts: 1 for Houdini, EmberGen and vdbturb's own output (world
///   units per second), 0.4 for Blender/Mantaflow at time scale 1 (Blender's frame length 0.1 x 25/fps time units
///   is 1/fps seconds). Writers for Houdini and renderers convert to per second with it (turb::toTimeUnit).
#pragma once

#include <turb/Field.h>

#include <map>
#include <optional>
#include <string>

namespace turb {

struct Frame
{
    int number = 0;                              ///< frame number as in the file name (1001, ...)
    VectorField velocity;                        ///< cell-centred, world units per time unit; empty if absent
    ScalarField density;                         ///< smoke density (fog volume); empty if absent
    std::optional<ScalarField> temperature;      ///< optional, carried along and upsampled by stages
    std::optional<ScalarField> flame;            ///< optional, carried along and upsampled by stages
    double dt = 0.0;                             ///< time per frame in the velocity's time unit; 0 = unknown
    double timeUnit = 1.0;                       ///< seconds per time unit of velocity and dt, > 0
    std::map<std::string, std::string> metadata; ///< written to / read from the output file

    bool hasVelocity() const { return !velocity.empty(); }
    bool hasDensity() const { return !density.empty(); }

    /// The lattice of the frame's fields (velocity's if present, else density's).
    const Lattice& lattice() const { return hasVelocity() ? velocity.lattice() : density.lattice(); }
    /// The index box the frame's fields cover.
    const CoordBBox& bbox() const { return hasVelocity() ? velocity.bbox() : density.bbox(); }
};

/// A frame with `fn` (callable on ScalarField and VectorField) applied to each field it holds; number,
/// dt and metadata are kept and absent fields stay absent.
template<typename Fn>
Frame mapFields(const Frame& f, Fn&& fn)
{
    Frame out;
    out.number = f.number;
    out.dt = f.dt;
    out.timeUnit = f.timeUnit;
    out.metadata = f.metadata;
    if (f.hasVelocity()) out.velocity = fn(f.velocity);
    if (f.hasDensity()) out.density = fn(f.density);
    if (f.temperature) out.temperature = fn(*f.temperature);
    if (f.flame) out.flame = fn(*f.flame);
    return out;
}

/// Re-expresses `f`'s velocity and dt in a time unit of `seconds` seconds (1 = world units per second):
/// velocity is scaled by seconds / f.timeUnit, dt by the inverse, so velocity x dt (the motion per frame) is
/// unchanged. A no-op when the units already agree. Throws ValueError unless `seconds` is finite and > 0.
void toTimeUnit(Frame& f, double seconds);

} // namespace turb
