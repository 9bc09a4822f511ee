// Shared helpers for the test suites: temporary directories, the shared data folder, small VDB writers.
#pragma once

#include <turb/Frame.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>

namespace testutil {

/// ../shared/data, as configured by CMake.
inline std::string dataDir() { return VDBTURB_SHARED_DATA; }
inline std::string dataPath(const std::string& rel) { return dataDir() + "/" + rel; }
inline bool haveData() { return std::filesystem::exists(dataDir() + "/README.md"); }

/// A fresh empty directory under the build tree, removed at destruction.
class TempDir
{
public:
    TempDir()
    {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        std::string name = info ? std::string(info->test_suite_name()) + "_" + info->name() : "tmp";
        mPath = std::filesystem::absolute("test_tmp/" + name).string();
        std::filesystem::remove_all(mPath);
        std::filesystem::create_directories(mPath);
    }
    ~TempDir() { std::filesystem::remove_all(mPath); }
    const std::string& path() const { return mPath; }
    std::string operator/(const std::string& f) const { return mPath + "/" + f; }

private:
    std::string mPath;
};

/// Number of entries in a directory (to check that no temporary or partial files were left).
inline size_t countEntries(const std::string& dir)
{
    size_t n = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++n;
    return n;
}

/// A frame with velocity vel(world position) and density den(voxel) over `box`.
inline turb::Frame makeFrame(int number, const turb::CoordBBox& box, const turb::Lattice& lat,
    const std::function<turb::Vec3f(const turb::Vec3d&)>& vel, const std::function<float(const turb::Coord&)>& den,
    double dt = 0.1)
{
    turb::Frame f;
    f.number = number;
    f.dt = dt;
    f.velocity = turb::VectorField(box, lat);
    f.density = turb::ScalarField(box, lat);
    for (size_t n = 0; n < f.velocity.size(); ++n) {
        const turb::Coord c = f.velocity.coordOf(n);
        f.velocity.data()[n] = vel(lat.indexToWorld(c.asVec3d()));
        f.density.data()[n] = den(c);
    }
    return f;
}

/// Largest |value| of a scalar field (0 for an empty one).
inline double maxAbs(const turb::ScalarField& f)
{
    double m = 0;
    for (float v : f.values()) m = std::max(m, double(std::abs(v)));
    return m;
}

/// Same box and the same bytes: results that must not depend on the thread count.
template<typename T>
bool bitIdentical(const turb::Field<T>& a, const turb::Field<T>& b)
{
    return a.bbox() == b.bbox() && a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

} // namespace testutil
