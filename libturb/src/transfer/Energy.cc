// The detail's energy inside the smoke, and the factor that calibrates it (DetailEnergy).
#include "Stages.h"

#include <turb/Parallel.h>

#include <algorithm>
#include <cmath>

namespace turb::detail {

SmokeEnergy::SmokeEnergy(const ScalarField& d, float th) : density(d), threshold(th), voxels(0)
{
    for (float v : d.values()) voxels += v > th;
}

double SmokeEnergy::operator()(const VectorField& u, const VectorField* less) const
{
    if (voxels == 0) return 0.0;
    // Inside the smoke, where the turbulence is seen (and measured).
    const double sum = parallelSum(u.size(), 1 << 16, [&](size_t b, size_t e) {
        double acc = 0.0;
        for (size_t n = b; n < e; ++n)
            if (density.data()[n] > threshold)
                acc += double((less ? u.data()[n] - less->data()[n] : u.data()[n]).lengthSqr());
        return acc;
    });
    return sum / double(voxels);
}

double energyFactor(double reference, double now)
{
    // Bounded: a large factor would mean the pipeline lost the detail, not something to amplify.
    return now > 0.0 ? std::clamp(std::sqrt(reference / now), 1.0 / 3.0, 3.0) : 1.0;
}

} // namespace turb::detail
