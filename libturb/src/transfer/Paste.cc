// Pasting the chosen source patches' high band U_sh into U_h (section 3.2).
#include "Stages.h"

#include <turb/Parallel.h>

namespace turb::detail {

PasteResult pastePatches(const LocalSearchResult& local, const SourceBands& src, const FrameSetup& fs)
{
    PasteResult out;
    out.detail = VectorField(fs.fineBox, fs.fineLattice);
    out.offsets.assign(fs.layout.patchCount(), Coord(0));
    parallelFor(local.activeList.size(), 16, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            const size_t p = local.activeList[i];
            const CoordBBox full = fs.layout.patchBox(fs.layout.patchCoord(p));
            CoordBBox pb = full;
            pb.intersect(fs.fineBox);
            const Coord off = local.chosen[p] - full.min();
            out.offsets[p] = off;
            for (int x = pb.min().x(); x <= pb.max().x(); ++x)
                for (int y = pb.min().y(); y <= pb.max().y(); ++y)
                    for (int z = pb.min().z(); z <= pb.max().z(); ++z)
                        out.detail(x, y, z) = src.split.high(x + off.x(), y + off.y(), z + off.z()) * src.detailScale;
        }
    });
    return out;
}

} // namespace turb::detail
