#include <turb/Operators.h>

#include <turb/Parallel.h>

namespace turb {

namespace {

template<typename Out, typename Fn>
Field<Out> perVoxel(const VectorField& u, Fn fn)
{
    Field<Out> out(u.bbox(), u.lattice());
    const CoordBBox b = u.bbox();
    parallelFor(size_t(b.dim().x()), 1, [&](size_t x0, size_t x1) {
        for (size_t x = x0; x < x1; ++x) {
            const int i = b.min().x() + int(x);
            for (int j = b.min().y(); j <= b.max().y(); ++j)
                for (int k = b.min().z(); k <= b.max().z(); ++k) out(i, j, k) = fn(i, j, k);
        }
    });
    return out;
}

} // namespace

ScalarField divergence(const VectorField& u)
{
    return perVoxel<float>(u, [&](int i, int j, int k) { return jacobianAt(u, i, j, k).divergence(); });
}

VectorField curl(const VectorField& u)
{
    return perVoxel<Vec3f>(u, [&](int i, int j, int k) { return jacobianAt(u, i, j, k).curl(); });
}

ScalarField magnitude(const VectorField& u)
{
    return perVoxel<float>(u, [&](int i, int j, int k) { return u(i, j, k).length(); });
}

} // namespace turb
