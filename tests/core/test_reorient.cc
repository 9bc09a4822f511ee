// Exact grid reorientations and whole-frame box downsampling (Reorient.h): quarter turns are rotations, fields and
// their vectors turn together, a downsampled frame lands on the coarse lattice.
#include <turb/Reorient.h>

#include <gtest/gtest.h>

using namespace turb;

TEST(Reorient, QuarterTurnsAreExactRotations)
{
    // +90 degrees about z takes x to y; four turns are the identity; turns compose.
    const AxisRotation z1 = AxisRotation::quarterTurns(2, 1);
    EXPECT_EQ(z1.apply(Vec3f(1, 0, 0)), Vec3f(0, 1, 0));
    EXPECT_EQ(z1.apply(Vec3f(0, 1, 0)), Vec3f(-1, 0, 0));
    EXPECT_TRUE(AxisRotation::quarterTurns(1, 4).isIdentity());
    EXPECT_EQ(AxisRotation::quarterTurns(0, 2).apply(Vec3f(1, 2, 3)), Vec3f(1, -2, -3));
    // A field and its vectors turn together: the rotated field at R*c is R times the field at c.
    VectorField u(CoordBBox({0, 1, 2}, {4, 6, 5}), Lattice{});
    for (size_t n = 0; n < u.size(); ++n) {
        const Coord c = u.coordOf(n);
        u.data()[n] = Vec3f(float(c.x()), float(2 * c.y()), float(-c.z()));
    }
    const AxisRotation y1 = AxisRotation::quarterTurns(1, 1);
    const VectorField r = rotated(u, y1);
    EXPECT_EQ(r.size(), u.size());
    for (size_t n = 0; n < u.size(); ++n) {
        const Coord c = u.coordOf(n);
        const Vec3f rc = y1.apply(Vec3f(float(c.x()), float(c.y()), float(c.z())));
        const Coord d(int(rc.x()), int(rc.y()), int(rc.z()));
        ASSERT_EQ(r[d], y1.apply(u.data()[n]));
    }
    // Downsampling a frame averages every grid onto the coarse lattice.
    Frame f;
    f.velocity = u;
    f.density = ScalarField(u.bbox(), Lattice{}, 1.0f);
    const Frame d = downsampleFrame(f, 2);
    EXPECT_EQ(d.density.bbox(), coarsenBox(u.bbox(), 2));
    EXPECT_NEAR(d.lattice().voxelSize, 2.0, 1e-12);
}
