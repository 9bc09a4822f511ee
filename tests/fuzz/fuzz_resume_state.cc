// libFuzzer target: the resume-state parser (TurbulenceTransfer::restore, fed the vdbturb_state metadata of
// the last frame written). A damaged or hostile state must be refused with turb::Error, never crash, hang or
// allocate without bound.
#include <turb/Error.h>
#include <turb/Transfer.h>

#include <cstdint>
#include <string>

namespace {

// A small target frame (8^3, voxel 0.4) and the output frame made from it at ratio 4 (32^3, voxel 0.1).
struct Frames
{
    turb::Frame target, output;
    Frames()
    {
        const turb::Lattice coarse{0.4, turb::Vec3d(0.2)};
        const turb::CoordBBox cb(turb::Coord(0), turb::Coord(7));
        target.number = 1;
        target.dt = 1.0 / 24.0;
        target.velocity = turb::VectorField(cb, coarse, turb::Vec3f(0.1f, 0.2f, 0.0f));
        target.density = turb::ScalarField(cb, coarse, 0.5f);
        const turb::Lattice fine = coarse.refined(4);
        const turb::CoordBBox fb(turb::Coord(0), turb::Coord(31));
        output.number = 1;
        output.dt = target.dt;
        output.velocity = turb::VectorField(fb, fine, turb::Vec3f(0.1f, 0.2f, 0.05f));
        output.density = turb::ScalarField(fb, fine, 0.5f);
    }
};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    static const Frames frames;
    const std::string state(reinterpret_cast<const char*>(data), size);
    turb::TransferSettings s;
    s.threads = 1;
    try {
        turb::TurbulenceTransfer t(s);
        t.restore(state, frames.output, frames.target);
    } catch (const turb::Error&) {
    }
    return 0;
}
