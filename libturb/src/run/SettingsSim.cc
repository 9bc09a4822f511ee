// sim's second tier as a settings table (turb/run/Settings.h): the solver's advection and pressure projection
// (docs/scenes.md has their measured effects), in the order --help-all lists them.
#include "SettingsRows.h"

#include <turb/run/Sim.h>

namespace turb::run {

namespace {

using detail::add;
using Table = SettingsTable<SimJob>;

// The preconditioner by name: SimJob keeps it as a bool (turb::scenes::SmokeSettings::pressureIncompleteCholesky).
enum Preconditioner { kIncompleteCholesky, kJacobi };

FieldRef preconditioner(SimJob& job)
{
    return EnumField{[&job] { return job.incompleteCholesky ? kIncompleteCholesky : kJacobi; },
        [&job](int v) { job.incompleteCholesky = v == kIncompleteCholesky; }};
}

} // namespace

const SettingsTable<SimJob>& simSettings()
{
    using Scheme = AdvectSettings::Scheme;
    static const Table table = [] {
        Table t;
        add(t, "scheme", "",
            "Advection of density, temperature and velocity: semi (semi-Lagrangian), maccormack, bfecc",
            TURB_FIELD(scheme))
            .choices = {{"semi", int(Scheme::SemiLagrangian)}, {"maccormack", int(Scheme::MacCormack)},
            {"bfecc", int(Scheme::BFECC)}};
        add(t, "pressureTolerance", "tolerance", "Pressure solve: max|div| after / before",
            TURB_FIELD(pressureTolerance), 1e-12, 0.5);
        add(t, "preconditioner", "",
            "Pressure solve preconditioner: ic (incomplete Cholesky, one thread) or jacobi (all threads)",
            preconditioner)
            .choices = {{"ic", kIncompleteCholesky}, {"jacobi", kJacobi}};
        add(t, "cfl", "", "Voxels the fastest flow may cross per substep", TURB_FIELD(cfl), 0.0).lowOpen = true;
        add(t, "maxSubsteps", "max-substeps", "Substeps per frame at most", TURB_FIELD(maxSubsteps), 1, 64);
        return t;
    }();
    return table;
}

} // namespace turb::run
