// The output frame, U = up(u_t) + U_h (section 3.4), and the per-frame change of the detail.
#include "Stages.h"

#include <turb/Metadata.h>

#include <cmath>
#include <sstream>

namespace turb::detail {

void detailChange(const VectorField& detail, const VectorField& advected, const ScalarField& density, float threshold,
    TransferStats& st)
{
    if (advected.empty()) return;
    double change = 0.0, now = 0.0, before = 0.0;
    for (size_t n = 0; n < detail.size(); ++n) {
        if (!(density.data()[n] > threshold)) continue;
        change += double((detail.data()[n] - advected.data()[n]).lengthSqr());
        now += double(detail.data()[n].lengthSqr());
        before += double(advected.data()[n].lengthSqr());
    }
    // Without carried detail (after an empty frame) there is nothing to compare with.
    if (now > 0.0 && before > 0.0) {
        st.detailChange = std::sqrt(change / now);
        st.detailGrowth = std::sqrt(now / before);
    }
}

Frame assembleOutput(
    const Frame& target, const TargetAtOutput& t, const VectorField& detail, ScalarField density, const FrameSetup& fs)
{
    const TransferSettings& s = *fs.s;
    Frame out;
    out.number = target.number;
    out.dt = target.dt;
    out.timeUnit = target.timeUnit;
    out.velocity = VectorField(fs.fineBox, fs.fineLattice);
    for (size_t n = 0; n < out.velocity.size(); ++n) out.velocity.data()[n] = t.Ut.data()[n] + detail.data()[n];
    if (target.temperature) out.temperature = upsample(*target.temperature, fs.f);
    if (target.flame) out.flame = upsample(*target.flame, fs.f);
    out.density = std::move(density);
    const Coord& o = fs.layout.origin;
    const CoordBBox& fb = fs.fineBox;
    out.metadata[meta::kDomain] = std::to_string(fb.min().x()) + " " + std::to_string(fb.min().y()) + " " +
                                  std::to_string(fb.min().z()) + " " + std::to_string(fb.max().x()) + " " +
                                  std::to_string(fb.max().y()) + " " + std::to_string(fb.max().z());
    out.metadata[meta::kPatchSize] = std::to_string(fs.B);
    out.metadata[meta::kRatio] = std::to_string(fs.f);
    out.metadata[meta::kGlobalPatch] = std::to_string(fs.globalPatch);
    out.metadata[meta::kPatchOrigin] =
        std::to_string(o.x()) + "," + std::to_string(o.y()) + "," + std::to_string(o.z());
    const auto number = [](float v) {
        std::ostringstream os;
        os << v;
        return os.str();
    };
    out.metadata[meta::kAlpha] = number(s.alpha);
    out.metadata[meta::kBeta] = number(s.beta);
    out.metadata[meta::kGamma] = number(s.seams.gamma);
    return out;
}

} // namespace turb::detail
