// Internal: advection of the smoke state by a MAC velocity through OpenVDB's VolumeAdvection.
#pragma once

#include <turb/Advect.h>
#include <turb/Field.h>
#include <turb/Projection.h>

#include <array>
#include <vector>

namespace turb {
namespace scenes {
namespace detail {

struct MacAdvectSettings
{
    AdvectSettings::Scheme scalarScheme = AdvectSettings::Scheme::MacCormack;   ///< for cell-centred fields
    AdvectSettings::Scheme velocityScheme = AdvectSettings::Scheme::MacCormack; ///< for the face components
    bool revert = true;              ///< limiter: revert to semi-Lagrangian out of the local range (else clamp)
    std::array<Boundary, 6> faces{}; ///< closed faces get copied ghost values (nothing flows in); open faces see zero
};

/// Advects the cell-centred `scalars` (on cellBox(mac.bbox())) and the MAC velocity itself by the MAC
/// velocity over `dt` seconds. Every field is advected by the velocity as it was on entry.
void advectMac(VectorField& mac, const std::vector<ScalarField*>& scalars, double dt, const MacAdvectSettings& s);

} // namespace detail
} // namespace scenes
} // namespace turb
