// Beyond the paper: patches whose source position follows the source's own flow between frames.
//
// Target voxel x held, last frame, the detail found upstream at y = x - v_t dt. That detail came from source point
// s = track(Q) + (y - corner(Q)) of the patch Q containing y, and the source has since carried it to
// s' = s + v_s(s) dt_s. Pasting from s' therefore gives the detail the source itself evolved from what the output
// showed, moving with the target's flow; it differs from last frame's detail advected by about the source's own
// temporal change, and has the source's structure instead of a stretched copy of it.
#include "Stages.h"

#include <turb/Operators.h>
#include <turb/Parallel.h>

#include <cmath>

namespace turb::detail {

void followSourceFlow(PatchTracks& tracks, const CarriedState& c, const TargetAtOutput& t, const SourceBands& src,
    const Frame& source, const std::vector<uint8_t>& active, const FrameSetup& fs)
{
    const PatchLayout& L = fs.layout;
    tracks.following.assign(L.patchCount(), 0);
    tracks.follow.assign(L.patchCount(), Vec3d(0.0));
    if (!fs.s->followSourceFlow || !c.havePrevious || c.tracks.empty()) return;
    // A source that jumped back (a looping or ping-pong source) did not evolve from last frame's.
    const int sourceGap = source.number - c.prevSourceNumber;
    if (sourceGap < 0 || !(c.prevSourceDt > 0.0)) return;
    const double sourceElapsed = 0.5 * (c.prevSourceDt + source.dt) * sourceGap;
    const int B = fs.B;
    const double h = fs.fineLattice.voxelSize;
    // Centre of a patch from its corner; a 2D patch's one layer is its centre in z.
    const Vec3d half(0.5 * (fs.patch.x() - 1), 0.5 * (fs.patch.y() - 1), 0.5 * (fs.patch.z() - 1));
    const Coord origin = L.origin;
    const CoordBBox& sb = src.split.low.bbox();
    parallelFor(L.patchCount(), 64, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        for (size_t p = b; p < e; ++p) {
            if (!active[p]) continue;
            CoordBBox pb = L.patchBox(L.patchCoord(p));
            const Vec3d centre = pb.min().asVec3d() + half;
            pb.intersect(fs.fineBox);
            Vec3d vt(0.0);
            for (auto it = pb.begin(); it; ++it) {
                const Vec3f& v = t.Ut[*it];
                vt += Vec3d(v.x(), v.y(), v.z());
            }
            vt /= double(pb.volume());
            const Vec3d y = centre - vt * (fs.elapsed / h);
            const Coord Q(floorDiv(int(std::lround(y.x())), B), floorDiv(int(std::lround(y.y())), B),
                fs.flat ? 0 : floorDiv(int(std::lround(y.z())), B));
            const auto it = c.tracks.find(Q);
            if (it == c.tracks.end()) continue;
            // s: where the source held, last frame, the detail now upstream of this patch's centre; carried on by the
            // source's flow it becomes the centre of this patch's continuation.
            const Vec3d s = it->second + (y - Vec3d(Q.x() * B, Q.y() * B, fs.flat ? origin.z() : Q.z() * B));
            const Vec3f vs = sampleTrilinear(src.split.low, s);
            const Vec3d moved = s + Vec3d(vs.x(), vs.y(), vs.z()) * (sourceElapsed / h) - half;
            // The tricubic paste reads one voxel before and two after the patch (whether it still holds enough smoke
            // is the local search's to judge).
            bool inside = true;
            for (int a = 0; a < (fs.flat ? 2 : 3); ++a)
                inside &= moved[a] >= sb.min()[a] + 1 && moved[a] + B + 1 <= sb.max()[a];
            // In 2D the continuation stays on the source's layer (its flow has no z component).
            if (fs.flat && moved.z() != double(sb.min().z())) inside = false;
            if (!inside) continue;
            tracks.following[p] = 1;
            tracks.follow[p] = moved;
        }
    });
}

} // namespace turb::detail
