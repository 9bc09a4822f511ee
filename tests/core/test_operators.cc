// Finite differences (Operators.h) against analytic fields.
#include <turb/Operators.h>

#include <gtest/gtest.h>

using namespace turb;

TEST(Operators, AnalyticDivergenceAndCurl)
{
    const Lattice lat{0.2, {0.0, 0.0, 0.0}};
    VectorField u(CoordBBox({0, 0, 0}, {9, 9, 9}), lat);
    VectorField w(u.bbox(), lat);
    for (size_t n = 0; n < u.size(); ++n) {
        const Vec3d x = lat.indexToWorld(u.coordOf(n).asVec3d());
        u.data()[n] = Vec3f(float(x.x()), float(x.y()), float(-2 * x.z())); // div 0
        w.data()[n] = Vec3f(float(-x.y()), float(x.x()), 0.0f);             // curl (0,0,2)
    }
    const ScalarField d = divergence(u);
    const VectorField c = curl(w);
    for (size_t n = 0; n < d.size(); ++n) {
        ASSERT_NEAR(d.data()[n], 0.0f, 1e-4f);
        ASSERT_NEAR((c.data()[n] - Vec3f(0, 0, 2)).length(), 0.0f, 1e-4f);
    }
}
