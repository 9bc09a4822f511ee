// Eq. 1: the global search over b^3 coarse patches (b^2 in 2D), run only where smoke newly entered a local patch;
// elsewhere the search region follows the previous frame's best local patch (section 3.2).
#include "Stages.h"

#include <turb/Error.h>
#include <turb/Parallel.h>

namespace turb::detail {

GlobalSearchResult globalSearch(const Frame& target, const SourceBands& src, const std::vector<uint8_t>& active,
    const PatchTracks& tracks, const FrameSetup& fs, const MatchWeights& w)
{
    const TransferSettings& s = *fs.s;
    const int f = fs.f, fz = fs.flat ? 1 : fs.f; // a 2D pair is refined in x and y only
    GlobalSearchResult out;
    out.regionCentre.assign(fs.layout.patchCount(), Coord(0));
    std::vector<size_t> needGlobal;
    for (size_t p = 0; p < active.size(); ++p) {
        if (!active[p]) continue;
        if (s.trackGlobalPatches && tracks.tracked[p]) {
            out.regionCentre[p] = tracks.match[p] + fs.half;
            ++out.tracked;
        } else {
            needGlobal.push_back(p);
        }
    }
    out.searches = int(needGlobal.size());
    if (needGlobal.empty()) return out;

    GlobalIndex index;
    index.build(src.split.coarse, src.ds, fs.globalPatch, fs.globalDepth, src.ks, w, s.pcaComponents);
    if (index.empty()) throw ValueError("the source has no smoke to match against");
    const size_t dim = globalDescriptorSize(fs.globalPatch, fs.globalDepth);
    parallelFor(needGlobal.size(), 16, [&](size_t b, size_t e) {
        checkCancelled(fs.progress);
        std::vector<float> desc(dim);
        for (size_t i = b; i < e; ++i) {
            const size_t p = needGlobal[i];
            const Coord centreFine = fs.layout.patchBox(fs.layout.patchCoord(p)).min() + fs.half;
            const Coord c(floorDiv(centreFine.x(), f), floorDiv(centreFine.y(), f), floorDiv(centreFine.z(), fz));
            globalDescriptor(
                target.velocity, target.density, c, fs.globalPatch, fs.globalDepth, src.kt, w, desc.data());
            const Coord q = index.nearest(desc.data());
            out.regionCentre[p] = Coord(q.x() * f + f / 2, q.y() * f + f / 2, q.z() * fz + fz / 2);
        }
    });
    return out;
}

} // namespace turb::detail
