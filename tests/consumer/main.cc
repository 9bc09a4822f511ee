// Uses one library entry point from each installed target and checks its answer.
#include <turb/Resample.h>
#include <turbio/Sequence.h>

#include <cstdio>

int main()
{
    turb::ScalarField f(turb::CoordBBox(turb::Coord(0), turb::Coord(7)), turb::Lattice{0.5, {0, 0, 0}}, 2.0f);
    const turb::ScalarField c = turb::boxDownsample(f, 4);
    const std::vector<int> frames = turbio::parseFrameList("1001-1005x2");
    const bool ok = c.dim() == turb::Coord(2) && c(1, 1, 1) == 2.0f && frames.size() == 3;
    std::printf("consumer: boxDownsample %s, frame list %zu frames: %s\n", ok ? "ok" : "WRONG", frames.size(),
        ok ? "PASS" : "FAIL");
    return ok ? 0 : 1;
}
