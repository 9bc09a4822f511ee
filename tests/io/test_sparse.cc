// Cost follows the smoke, not the bounding box. Caches are written with OpenVDB directly (sparse
// trees, tiles for large velocity boxes), read through turbio and transferred, so the crop is what is tested.
#include "TestUtil.h"

#include <turb/Error.h>
#include <turb/Transfer.h>
#include <turbio/Scan.h>
#include <turbio/Vdb.h>

#include <openvdb/openvdb.h>
#include <turb/NewGrid.h>
#include <openvdb/io/File.h>

#include <cmath>
#include <functional>
#include <vector>

using namespace turb;
using testutil::TempDir;

namespace {

constexpr double kVoxel = 0.1; // target voxel
constexpr int kRatio = 2;      // source voxel = kVoxel / kRatio
constexpr double kDt = 1.0 / 24.0;

// A smooth swirl plus a rise, in world units per second; the same function in every cache, so a voxel's
// velocity does not depend on the box it was written in.
Vec3f swirl(const Vec3d& x)
{
    const double a = std::sin(2.1 * x.y() + 0.3), b = std::cos(1.7 * x.z() - 0.2), c = std::sin(1.3 * x.x() + 0.5);
    return Vec3f(float(0.4 * a), float(1.0 + 0.3 * b), float(0.4 * c));
}

// Fine detail of the source: a few divergence-free shear modes at 3-6 source voxels.
Vec3f detail(const Vec3d& x)
{
    const double s = 2.0 * M_PI / (4.0 * kVoxel / kRatio);
    return Vec3f(float(0.3 * std::sin(s * x.y())), float(0.3 * std::sin(1.3 * s * x.z())),
        float(0.3 * std::sin(0.8 * s * x.x())));
}

struct Puff
{
    Vec3d centre;  // world
    double radius; // world, density 0 beyond
};

float puffDensity(const std::vector<Puff>& puffs, const Vec3d& x)
{
    float d = 0.0f;
    for (const auto& p : puffs) {
        const double r = (x - p.centre).length();
        if (r < p.radius) d += float(std::exp(-r * r / (0.5 * p.radius * p.radius)));
    }
    return d;
}

struct CacheSpec
{
    double voxel = kVoxel;
    std::vector<Puff> puffs;
    CoordBBox velBox;          // velocity written voxel by voxel from swirl (+ detail for a source)
    CoordBBox tileBox;         // larger box filled with swirl's value at the origin as tiles (empty: none)
    std::vector<Coord> strays; // stray density voxels (value 0.5)
    bool withDetail = false;
};

// Writes density (sparse: active only where > 0) and vel (cell-centred, world units) as Houdini would.
void writeCache(const std::string& path, const CacheSpec& s)
{
    openvdb::initialize();
    const auto xform = openvdb::math::Transform::createLinearTransform(s.voxel);
    auto den = turb::newGrid<openvdb::FloatGrid>(0.0f);
    den->setName("density");
    den->setGridClass(openvdb::GRID_FOG_VOLUME);
    den->setTransform(xform);
    auto vel = turb::newGrid<openvdb::Vec3SGrid>(openvdb::Vec3s(0.0f));
    vel->setName("vel");
    vel->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    vel->setTransform(xform);
    const auto world = [&](const Coord& c) { return c.asVec3d() * s.voxel; };
    if (!s.tileBox.empty()) {
        const Vec3f v0 = swirl(Vec3d(0.0));
        vel->tree().fill(s.tileBox, openvdb::Vec3s(v0.x(), v0.y(), v0.z()), true);
    }
    auto va = vel->getAccessor();
    auto da = den->getAccessor();
    for (auto it = s.velBox.begin(); it; ++it) {
        const Vec3d x = world(*it);
        Vec3f v = swirl(x);
        if (s.withDetail) v += detail(x);
        va.setValue(*it, openvdb::Vec3s(v.x(), v.y(), v.z()));
        const float d = puffDensity(s.puffs, x);
        if (d > 0.0f) da.setValue(*it, d);
    }
    for (const Coord& c : s.strays) da.setValue(c, 0.5f);
    openvdb::GridPtrVec grids{den, vel};
    openvdb::io::File file(path);
    file.write(grids);
    file.close();
}

turbio::ReadOptions readOptions()
{
    turbio::ReadOptions o;
    o.dt = kDt;
    o.fps = 24.0;
    o.cropMargin = 4; // smaller than the default 8 only to keep the transfers quick
    return o;
}

// The source: one puff at the target's scale, ratio kRatio finer, with detail.
std::string writeSource(
    const TempDir& dir, const std::string& name, const std::vector<Puff>& puffs, const CoordBBox& box)
{
    CacheSpec s;
    s.voxel = kVoxel / kRatio;
    s.puffs = puffs;
    s.velBox = box;
    s.withDetail = true;
    const std::string path = dir / name;
    writeCache(path, s);
    return path;
}

const Puff kPlume{Vec3d(1.6, 1.6, 1.6), 0.45}; // target index 16 +- 4.5: a 9^3 plume
const CoordBBox kSmallBox({0, 0, 0}, {31, 31, 31});

TransferSettings fastSettings(int threads = 0)
{
    TransferSettings s;
    s.threads = threads;
    return s;
}

void expectSameFrame(const Frame& a, const Frame& b)
{
    ASSERT_EQ(a.velocity.bbox(), b.velocity.bbox());
    ASSERT_EQ(a.density.bbox(), b.density.bbox());
    size_t diff = 0;
    for (size_t n = 0; n < a.velocity.size(); ++n) diff += a.velocity.data()[n] != b.velocity.data()[n];
    for (size_t n = 0; n < a.density.size(); ++n) diff += a.density.data()[n] != b.density.data()[n];
    EXPECT_EQ(diff, 0u);
}

double rms(const VectorField& v)
{
    double s = 0.0;
    for (const auto& x : v.values()) s += double(x.lengthSqr());
    return v.size() ? std::sqrt(s / double(v.size())) : 0.0;
}

} // namespace

TEST(SparseRead, StrayVoxelFarAwayIsLeftOutAndReported)
{
    TempDir dir;
    CacheSpec s;
    s.puffs = {kPlume};
    s.velBox = kSmallBox;
    s.strays = {Coord(1000, 1000, 1000)};
    writeCache(dir / "stray.vdb", s);

    // Today's behaviour (the whole span densely) refuses the frame: the case that used to fail.
    turbio::ReadOptions whole = readOptions();
    whole.cropToSmoke = false;
    EXPECT_THROW(turbio::readFrame(dir / "stray.vdb", 1, whole), IoError);

    turbio::ReadReport rep;
    const Frame f = turbio::readFrame(dir / "stray.vdb", 1, readOptions(), &rep);
    ASSERT_EQ(rep.region.strays.size(), 1u);
    EXPECT_EQ(rep.region.strays[0].voxels, 1);
    EXPECT_GE(rep.region.strays[0].distance, 1000 - 21);
    EXPECT_NE(rep.region.describeStrays().find("1 voxel of density far from the smoke"), std::string::npos)
        << rep.region.describeStrays();
    EXPECT_LT(f.density.bbox().volume(), 32u * 32u * 32u);
    EXPECT_TRUE(f.density.bbox().isInside(rep.region.smoke));
    EXPECT_EQ(f.velocity.bbox(), f.density.bbox());

    // The header scan (preflight, dry runs) agrees and does not refuse either.
    const turbio::FrameScan scan = turbio::scanFrame(dir / "stray.vdb", 1, readOptions());
    EXPECT_EQ(scan.error, "");
    EXPECT_TRUE(scan.regionFromVoxels);
    EXPECT_EQ(scan.domain, f.density.bbox());
    EXPECT_EQ(scan.region.strays.size(), 1u);
}

TEST(SparseRead, HeldBoxIsTheSmokeAndItsMarginInsideTheSpan)
{
    TempDir dir;
    CacheSpec s;
    s.puffs = {kPlume};
    s.velBox = kSmallBox;
    writeCache(dir / "a.vdb", s);
    turbio::ReadOptions o = readOptions();
    turbio::ReadReport rep;
    const Frame f = turbio::readFrame(dir / "a.vdb", 1, o, &rep);
    CoordBBox want = rep.region.smoke;
    want.expand(o.cropMargin);
    want.intersect(kSmallBox);
    EXPECT_EQ(f.velocity.bbox(), want);
    EXPECT_EQ(rep.span, kSmallBox);
    // Every density voxel of the file is inside the held box: nothing of the smoke is lost.
    double inFile = 0.0, held = 0.0;
    for (auto it = kSmallBox.begin(); it; ++it) inFile += puffDensity({kPlume}, (*it).asVec3d() * kVoxel);
    for (float d : f.density.values()) held += d;
    EXPECT_NEAR(held, inFile, 1e-3 * inFile);
}

TEST(SparseRead, TwoPuffsFarApartAreBothKept)
{
    TempDir dir;
    const Puff a{Vec3d(1.0, 1.0, 1.0), 0.4}, b{Vec3d(7.0, 1.0, 1.0), 0.4}; // 60 target voxels apart
    CacheSpec s;
    s.puffs = {a, b};
    s.velBox = CoordBBox({0, 0, 0}, {85, 22, 22});
    writeCache(dir / "two.vdb", s);
    turbio::ReadReport rep;
    const Frame f = turbio::readFrame(dir / "two.vdb", 1, readOptions(), &rep);
    EXPECT_TRUE(rep.region.strays.empty()) << rep.region.describeStrays();
    EXPECT_TRUE(f.density.bbox().isInside(Coord(10, 10, 10)));
    EXPECT_TRUE(f.density.bbox().isInside(Coord(70, 10, 10)));
}

class SparseTransfer : public ::testing::Test
{
protected:
    void SetUp() override
    {
        source = writeSource(
            dir, "src.vdb", {Puff{kPlume.centre, kPlume.radius * 1.2}}, CoordBBox({12, 12, 12}, {51, 51, 51}));
    }
    TransferResult run(const std::string& target, int threads = 0)
    {
        TurbulenceTransfer t(fastSettings(threads));
        const Frame tf = turbio::readFrame(target, 1, readOptions());
        turbio::ReadOptions so = readOptions();
        so.extendVelocity = 4;
        const Frame sf = turbio::readFrame(source, 1, so);
        return t.process(tf, sf);
    }
    TempDir dir;
    std::string source;
};

TEST_F(SparseTransfer, StrayVoxelThousandVoxelsAwayGivesTheSameOutput)
{
    CacheSpec s;
    s.puffs = {kPlume};
    s.velBox = kSmallBox;
    writeCache(dir / "clean.vdb", s);
    s.strays = {Coord(1000, 1000, 1000)};
    writeCache(dir / "stray.vdb", s);
    const TransferResult a = run(dir / "clean.vdb");
    const TransferResult b = run(dir / "stray.vdb");
    ASSERT_FALSE(a.empty);
    EXPECT_GT(a.stats.localPatches, 0);
    EXPECT_GT(rms(a.frame.velocity), 0.5);
    expectSameFrame(a.frame, b.frame);
}

TEST_F(SparseTransfer, PlumeIn256BoxEqualsPlumeIn32Box)
{
    CacheSpec s;
    s.puffs = {kPlume};
    s.velBox = kSmallBox;
    writeCache(dir / "small.vdb", s);
    s.tileBox = CoordBBox({-112, -112, -112}, {143, 143, 143}); // 256^3, the same voxels in the 32^3 part
    writeCache(dir / "large.vdb", s);
    turbio::ReadReport rep;
    turbio::readFrame(dir / "large.vdb", 1, readOptions(), &rep);
    EXPECT_EQ(rep.span.dim(), Coord(256, 256, 256));
    EXPECT_TRUE(kSmallBox.isInside(rep.held));
    const TransferResult a = run(dir / "small.vdb");
    const TransferResult b = run(dir / "large.vdb");
    ASSERT_FALSE(a.empty);
    EXPECT_LE(b.frame.velocity.bbox().volume(), size_t(32 * kRatio) * size_t(32 * kRatio) * size_t(32 * kRatio));
    expectSameFrame(a.frame, b.frame);
}

TEST_F(SparseTransfer, DeterministicAtOneAndTwoThreads)
{
    CacheSpec s;
    s.puffs = {kPlume};
    s.velBox = kSmallBox;
    s.strays = {Coord(600, 600, 600), Coord(-300, 5, 5)};
    writeCache(dir / "t.vdb", s);
    const TransferResult a = run(dir / "t.vdb", 1);
    const TransferResult b = run(dir / "t.vdb", 2);
    expectSameFrame(a.frame, b.frame);
}

TEST_F(SparseTransfer, BoxGrowingEveryFrameAndEmptyFramesBetweenSmokyOnes)
{
    // Frames 1-3 grow (the plume widens and rises), 4 is empty (density grid without active voxels), 5 smoky
    // again; the velocity box is large and fixed, as a Houdini container's.
    TurbulenceTransfer transfer(fastSettings());
    turbio::ReadOptions so = readOptions();
    so.extendVelocity = 4;
    const Frame sf = turbio::readFrame(source, 1, so);
    CoordBBox prevHeld;
    for (int frame = 1; frame <= 5; ++frame) {
        CacheSpec s;
        if (frame != 4) s.puffs = {Puff{kPlume.centre + Vec3d(0.0, 0.1 * frame, 0.0), 0.3 + 0.1 * frame}};
        s.velBox = CoordBBox({0, 0, 0}, {39, 39, 39});
        s.tileBox = CoordBBox({-40, -40, -40}, {87, 87, 87});
        const std::string path = dir / ("t." + std::to_string(frame) + ".vdb");
        writeCache(path, s);
        Frame tf = turbio::readFrame(path, frame, readOptions());
        const TransferResult r = transfer.process(tf, sf);
        EXPECT_EQ(r.frame.velocity.bbox(), refineBox(tf.velocity.bbox(), kRatio)) << "frame " << frame;
        if (frame == 4) {
            EXPECT_TRUE(r.empty);
            EXPECT_EQ(tf.velocity.bbox().volume(), 8u) << "an empty frame holds 2^3 voxels, not the velocity box";
            continue;
        }
        ASSERT_FALSE(r.empty) << "frame " << frame;
        EXPECT_GT(r.stats.localPatches, 0);
        if (frame > 1 && frame < 4) {
            EXPECT_TRUE(tf.velocity.bbox().isInside(prevHeld)) << "the held box grows with the smoke";
            EXPECT_NE(tf.velocity.bbox(), prevHeld);
            EXPECT_GT(r.stats.trackedPatches, 0) << "tracks follow the growing box";
            EXPECT_TRUE(r.stats.detailChange.has_value()) << "detail is carried from the previous frame";
        }
        for (const auto& v : r.frame.velocity.values()) ASSERT_TRUE(std::isfinite(v.x() + v.y() + v.z()));
        prevHeld = tf.velocity.bbox();
    }
}

TEST_F(SparseTransfer, SourceWhoseSmokeIsTwoPuffsFarApart)
{
    // The source's smoke: the plume's puff and a second one 100 source voxels along x. Both hold half the mass,
    // so both are held (no strays), and the transfer matches patches from either.
    const Puff near{kPlume.centre, kPlume.radius * 1.2}, far{kPlume.centre + Vec3d(5.0, 0.0, 0.0), kPlume.radius * 1.2};
    const std::string two = writeSource(dir, "two.vdb", {near, far}, CoordBBox({12, 12, 12}, {151, 51, 51}));
    turbio::ReadOptions so = readOptions();
    so.extendVelocity = 4;
    turbio::ReadReport rep;
    const Frame sf = turbio::readFrame(two, 1, so, &rep);
    EXPECT_TRUE(rep.region.strays.empty()) << rep.region.describeStrays();
    EXPECT_TRUE(sf.density.bbox().isInside(Coord(32, 32, 32)));
    EXPECT_TRUE(sf.density.bbox().isInside(Coord(132, 32, 32)));

    CacheSpec s;
    s.puffs = {kPlume};
    s.velBox = kSmallBox;
    writeCache(dir / "t.vdb", s);
    TurbulenceTransfer transfer(fastSettings());
    const TransferResult r = transfer.process(turbio::readFrame(dir / "t.vdb", 1, readOptions()), sf);
    ASSERT_FALSE(r.empty);
    EXPECT_GT(r.stats.localPatches, 0);
    EXPECT_GT(r.stats.meanLocalEnergy, 0.0);
    for (const auto& v : r.frame.velocity.values()) ASSERT_TRUE(std::isfinite(v.x() + v.y() + v.z()));
    EXPECT_GT(rms(r.frame.velocity), 0.5);
}
