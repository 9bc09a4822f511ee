// libFuzzer target: the resume-state parser (TurbulenceTransfer::restore, fed the vdbturb_state metadata of
// the last frame written). A damaged or hostile state must be refused with turb::Error, never crash, hang or
// allocate without bound.
#include <turb/Error.h>
#include <turb/Transfer.h>

#include <cmath>
#include <cstdint>
#include <string>

namespace {

// Frame 1 of a tiny target (4^3, voxel 0.4), the output made from it at ratio 4 (16^3, voxel 0.1), the target's
// frame 2 and a source (16^3, voxel 0.1) with some structure to match against: small, so a restored state's
// next frame runs in milliseconds and the fuzzer keeps its pace.
struct Frames
{
    turb::Frame target, output, next, source;
    Frames()
    {
        const turb::Lattice coarse{0.4, turb::Vec3d(0.2)};
        const turb::CoordBBox cb(turb::Coord(0), turb::Coord(3));
        target.number = 1;
        target.dt = 1.0 / 24.0;
        target.velocity = turb::VectorField(cb, coarse, turb::Vec3f(0.1f, 0.2f, 0.0f));
        target.density = turb::ScalarField(cb, coarse, 0.5f);
        next = target;
        next.number = 2;
        const turb::Lattice fine = coarse.refined(4);
        const turb::CoordBBox fb(turb::Coord(0), turb::Coord(15));
        output.number = 1;
        output.dt = target.dt;
        output.velocity = turb::VectorField(fb, fine, turb::Vec3f(0.1f, 0.2f, 0.05f));
        output.density = turb::ScalarField(fb, fine, 0.5f);
        source = output;
        for (size_t n = 0; n < source.velocity.size(); ++n) {
            const turb::Coord c = source.velocity.coordOf(n);
            source.velocity.data()[n] =
                turb::Vec3f(std::sin(0.7f * c.y()), std::cos(0.5f * c.z()), std::sin(0.3f * c.x()));
        }
    }
};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    static const Frames frames;
    const std::string state(reinterpret_cast<const char*>(data), size);
    turb::TransferSettings s;
    s.threads = 1;
    s.pcaComponents = 4; // cheap search and seams: the state, not the solver, is under test
    s.refineCandidates = 4;
    s.seams.maxEmIterations = 1;
    s.seams.maxCgIterations = 10;
    turb::TurbulenceTransfer t(s);
    try {
        t.restore(state, frames.output, frames.target);
    } catch (const turb::Error&) {
        return 0;
    }
    // A state that restores must also run: its patch tracks steer the next frame's search.
    try {
        t.process(frames.next, frames.source);
    } catch (const turb::Error&) {}
    return 0;
}
