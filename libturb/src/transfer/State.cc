// What one frame leaves for the next, and its text form in the output file's metadata (--resume).
#include "Stages.h"

#include <turb/Error.h>

#include <sstream>

namespace turb::detail {

void carryState(CarriedState& c, const Frame& target, const Frame& out, const TargetAtOutput& t,
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
    c.havePrevious = true;
}

std::string saveStateText(int f, int B, const AlignmentState& align, const std::map<Coord, Coord>& tracks)
{
    std::ostringstream os;
    os << "v2 f=" << f << " B=" << B << " rot=" << (align.chosen ? align.rotation.id() : -1) << " tracks=";
    bool first = true;
    for (const auto& [P, m] : tracks) {
        os << (first ? "" : ";") << P.x() << ',' << P.y() << ',' << P.z() << ',' << m.x() << ',' << m.y() << ',' << m.z();
        first = false;
    }
    return os.str();
}

SavedState parseStateText(const std::string& text)
{
    std::istringstream is(text);
    std::string version, fField, bField, rotField, tracks;
    is >> version >> fField >> bField >> rotField >> tracks;
    if (version != "v2" || fField.rfind("f=", 0) != 0 || bField.rfind("B=", 0) != 0 || rotField.rfind("rot=", 0) != 0 ||
        tracks.rfind("tracks=", 0) != 0)
        throw ValueError("unrecognised transfer state in the previous output: '" + text.substr(0, 60) + "'");
    SavedState st;
    try {
        st.f = std::stoi(fField.substr(2));
        st.B = std::stoi(bField.substr(2));
        const int rot = std::stoi(rotField.substr(4));
        if (rot >= 0) {
            st.align.rotation = AxisRotation::fromId(rot);
            st.align.chosen = true;
        }
    } catch (const std::logic_error&) {
        throw ValueError("damaged transfer state in the previous output: '" + text.substr(0, 60) + "'");
    }
    std::stringstream ts(tracks.substr(7));
    std::string item;
    while (std::getline(ts, item, ';')) {
        if (item.empty()) continue;
        int v[6];
        char sep;
        std::istringstream one(item);
        bool ok = bool(one >> v[0]);
        for (int k = 1; k < 6 && ok; ++k) ok = bool(one >> sep >> v[k]) && sep == ',';
        if (!ok) throw ValueError("damaged transfer state entry '" + item + "'");
        st.tracks[Coord(v[0], v[1], v[2])] = Coord(v[3], v[4], v[5]);
    }
    return st;
}

} // namespace turb::detail
