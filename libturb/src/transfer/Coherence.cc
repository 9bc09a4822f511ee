// Beyond the paper, as in Ashikhmin's and k-coherence texture synthesis: a patch takes a neighbour's continuation
// when it matches almost as well, so neighbouring patches come from neighbouring source positions and many borders
// have no seam at all.
#include "Stages.h"

#include <turb/Parallel.h>

namespace turb::detail {

void coherencePass(
    LocalSearchResult& local, const PatchEnergy& energy, const std::vector<uint8_t>& active, const PatchTracks& tracks)
{
    const FrameSetup& fs = energy.fs;
    const TransferSettings& s = *fs.s;
    if (!(s.coherence > 0.0f)) return;
    const PatchLayout& L = fs.layout;
    const bool temporalAll = !energy.advectedDetail.empty();
    // Red-black sweeps: a patch reads only neighbours of the other colour, so the result does not depend on the
    // thread count.
    for (int sweep = 0; sweep < 2 * s.coherenceSweeps; ++sweep) {
        const int colour = sweep % 2;
        parallelFor(local.activeList.size(), 8, [&](size_t b, size_t e) {
            checkCancelled(fs.progress);
            for (size_t i = b; i < e; ++i) {
                const size_t p = local.activeList[i];
                const Coord P = L.patchCoord(p);
                if (((P.x() + P.y() + P.z()) & 1) != colour) continue;
                const Coord tCorner = L.patchBox(P).min();
                const bool temporal = temporalAll && tracks.tracked[p];
                double bestE = local.energy[p];
                Coord bestC = local.chosen[p];
                for (int nb = 0; nb < 6; ++nb) {
                    Coord Q = P;
                    Q[nb / 2] += (nb % 2) ? 1 : -1;
                    if (Q[nb / 2] < 0 || Q[nb / 2] >= L.count[nb / 2]) continue;
                    const size_t q = L.patchIndex(Q);
                    if (!active[q]) continue;
                    // The neighbour's source patch, continued across the border.
                    const Coord c = local.chosen[q] + (tCorner - L.patchBox(Q).min());
                    if (!local.corners.isInside(c) || c == bestC) continue;
                    const double en = energy(tCorner, c, temporal);
                    if (en <= (1.0 + s.coherence) * local.energy[p] && en < bestE) {
                        bestE = en;
                        bestC = c;
                    }
                }
                if (bestC != local.chosen[p]) local.chosenExact[p] = bestC.asVec3d();
                local.chosen[p] = bestC;
                local.energy[p] = bestE;
            }
        });
    }
}

} // namespace turb::detail
