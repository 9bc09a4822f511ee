// What one frame leaves for the next, and its text form in the output file's metadata (--resume).
#include "Stages.h"

#include <turb/Error.h>

#include <cmath>
#include <sstream>

namespace turb::detail {

void carryState(CarriedState& c, const Frame& target, const Frame& source, const Frame& out, const TargetAtOutput& t,
    const ScalarField& emission, const FrameSetup& fs)
{
    if (fs.s->densityMode == DensityMode::LookBack) {
        c.history.push_back(LookBackStep{out.velocity, emission, target.density, 0.0});
        while (int(c.history.size()) > fs.s->lookBackFrames) c.history.pop_front();
    }
    c.prevDetail = VectorField(fs.fineBox, fs.fineLattice);
    for (size_t n = 0; n < c.prevDetail.size(); ++n) c.prevDetail.data()[n] = out.velocity.data()[n] - t.Ut.data()[n];
    c.prevTargetVelocity = target.velocity;
    c.prevTargetDensity = target.density;
    c.prevDensity = out.density;
    c.prevVelocity = out.velocity;
    c.prevDt = target.dt;
    c.prevNumber = target.number;
    c.prevSourceNumber = source.number;
    c.prevSourceDt = source.dt;
    c.havePrevious = true;
}

std::string saveStateText(const SavedState& st)
{
    // Version 3: corners between voxels, written with 17 significant digits so a resume reads back the same
    // doubles, and the source frame the continuation starts from.
    std::ostringstream os;
    os.precision(17);
    os << "v3 f=" << st.f << " B=" << st.B << " rot=" << (st.align.chosen ? st.align.rotation.id() : -1)
       << " src=" << st.sourceNumber << ',' << st.sourceDt << " tracks=";
    bool first = true;
    for (const auto& [P, m] : st.tracks) {
        os << (first ? "" : ";") << P.x() << ',' << P.y() << ',' << P.z() << ',' << m.x() << ',' << m.y() << ',' << m.z();
        first = false;
    }
    return os.str();
}

SavedState parseStateText(const std::string& text)
{
    const auto damaged = [&] {
        return ValueError("unrecognised or damaged transfer state in the previous output: '" + text.substr(0, 60) + "'");
    };
    std::istringstream is(text);
    std::string version, fField, bField, rotField, srcField, tracks;
    is >> version >> fField >> bField >> rotField;
    const bool v3 = version == "v3";
    if (v3) is >> srcField;
    is >> tracks;
    if ((version != "v2" && !v3) || fField.rfind("f=", 0) != 0 || bField.rfind("B=", 0) != 0 ||
        rotField.rfind("rot=", 0) != 0 || tracks.rfind("tracks=", 0) != 0 || (v3 && srcField.rfind("src=", 0) != 0))
        throw damaged();
    SavedState st;
    try {
        st.f = std::stoi(fField.substr(2));
        st.B = std::stoi(bField.substr(2));
        const int rot = std::stoi(rotField.substr(4));
        if (rot >= 0) {
            st.align.rotation = AxisRotation::fromId(rot);
            st.align.chosen = true;
        }
        if (v3) {
            const size_t comma = srcField.find(',');
            if (comma == std::string::npos) throw damaged();
            st.sourceNumber = std::stoi(srcField.substr(4, comma - 4));
            st.sourceDt = std::stod(srcField.substr(comma + 1));
        }
    } catch (const std::logic_error&) {
        throw damaged();
    }
    std::stringstream ts(tracks.substr(7));
    std::string item;
    while (std::getline(ts, item, ';')) {
        if (item.empty()) continue;
        int P[3];
        double m[3];
        char sep;
        std::istringstream one(item);
        bool ok = bool(one >> P[0]);
        for (int k = 1; k < 3 && ok; ++k) ok = bool(one >> sep >> P[k]) && sep == ',';
        for (int k = 0; k < 3 && ok; ++k) ok = bool(one >> sep >> m[k]) && sep == ',' && std::isfinite(m[k]);
        if (!ok) throw ValueError("damaged transfer state entry '" + item + "'");
        st.tracks[Coord(P[0], P[1], P[2])] = Vec3d(m[0], m[1], m[2]);
    }
    return st;
}

} // namespace turb::detail
