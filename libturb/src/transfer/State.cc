// What one frame leaves for the next, and its text form in the output file's metadata (--resume).
#include "Stages.h"

#include <turb/Error.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
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
        os << (first ? "" : ";") << P.x() << ',' << P.y() << ',' << P.z() << ',' << m.x() << ',' << m.y() << ','
           << m.z();
        first = false;
    }
    return os.str();
}

SavedState parseStateText(const std::string& text)
{
    const auto damaged = [&] {
        return ValueError(
            "unrecognised or damaged transfer state in the previous output: '" + text.substr(0, 60) + "'");
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
    // The state comes from a file: a damaged one is refused, never a crash (tests/fuzz/fuzz_resume_state.cc).
    const auto integer = [&](const std::string& field, long long lo, long long hi) {
        char* end = nullptr;
        errno = 0;
        const long long v = std::strtoll(field.c_str(), &end, 10);
        if (field.empty() || *end != '\0' || errno == ERANGE || v < lo || v > hi)
            throw ValueError("damaged transfer state in the previous output: '" + field.substr(0, 40) +
                             "' is not a number in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
        return int(v);
    };
    SavedState st;
    st.f = integer(fField.substr(2), 1, 256);
    st.B = integer(bField.substr(2), 2, 1024);
    const int rot = integer(rotField.substr(4), -1, 1 << 20);
    if (rot >= 0) {
        st.align.rotation = AxisRotation::fromId(rot);
        st.align.chosen = true;
    }
    if (v3) {
        const size_t comma = srcField.find(',');
        if (comma == std::string::npos) throw damaged();
        st.sourceNumber = integer(srcField.substr(4, comma - 4), -(1 << 30), 1 << 30);
        const std::string dtText = srcField.substr(comma + 1);
        char* end = nullptr;
        st.sourceDt = std::strtod(dtText.c_str(), &end);
        if (dtText.empty() || *end != '\0' || !std::isfinite(st.sourceDt) || st.sourceDt < 0.0) throw damaged();
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
        // Far-out coordinates would overflow the lattice arithmetic downstream.
        for (int k = 0; k < 3 && ok; ++k) ok = std::abs(P[k]) < (1 << 24) && std::abs(m[k]) < double(1 << 24);
        if (!ok) throw ValueError("damaged transfer state entry '" + item.substr(0, 60) + "'");
        st.tracks[Coord(P[0], P[1], P[2])] = Vec3d(m[0], m[1], m[2]);
    }
    return st;
}

} // namespace turb::detail
