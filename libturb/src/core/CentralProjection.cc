// The central-difference projection of Projection.h (removeCentralDivergence): Eigen's conjugate gradient on the
// normal equations G^T G psi = G^T u, with G^T G applied matrix-free over the field's box.
#include <turb/Projection.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <Eigen/IterativeLinearSolvers>

#include <cmath>

namespace turb::detail {
class CentralNormalOperator;
} // namespace turb::detail

namespace Eigen::internal {
template<>
struct traits<turb::detail::CentralNormalOperator> : public Eigen::internal::traits<Eigen::SparseMatrix<double>>
{};
} // namespace Eigen::internal

namespace turb::detail {

// G^T G over a box, in index units: G psi = (psi(i + e_a) - psi(i - e_a))_a and G^T v = -sum_a (v_a(i + e_a) -
// v_a(i - e_a)), both with zero outside the box. Axes of extent 1 are left out (a 2D field has no z derivatives).
class CentralNormalOperator : public Eigen::EigenBase<CentralNormalOperator>
{
public:
    using Scalar = double;
    using RealScalar = double;
    using StorageIndex = int;
    enum { ColsAtCompileTime = Eigen::Dynamic, MaxColsAtCompileTime = Eigen::Dynamic, IsRowMajor = false };

    explicit CentralNormalOperator(const CoordBBox& box)
        : mDim(box.dim()), mStride{size_t(mDim.y()) * size_t(mDim.z()), size_t(mDim.z()), 1},
          mSize(size_t(mDim.x()) * size_t(mDim.y()) * size_t(mDim.z())), mGrad(mSize * 3)
    {}
    Eigen::Index rows() const { return Eigen::Index(mSize); }
    Eigen::Index cols() const { return Eigen::Index(mSize); }

    template<typename Rhs>
    Eigen::Product<CentralNormalOperator, Rhs, Eigen::AliasFreeProduct> operator*(const Eigen::MatrixBase<Rhs>& x) const
    {
        return Eigen::Product<CentralNormalOperator, Rhs, Eigen::AliasFreeProduct>(*this, x.derived());
    }

    /// g = G psi (3 values per voxel).
    void gradient(const double* psi, double* g) const
    {
        eachX([&](size_t i, int j, int k, size_t o) {
            const int p[3] = {int(i), j, k};
            for (int a = 0; a < 3; ++a) {
                double d = 0.0;
                if (mDim[a] > 1) {
                    if (p[a] + 1 < mDim[a]) d += psi[o + mStride[a]];
                    if (p[a] > 0) d -= psi[o - mStride[a]];
                }
                g[3 * o + size_t(a)] = d;
            }
        });
    }
    /// out = G^T v for v with 3 values per voxel.
    void transposed(const double* v, double* out) const
    {
        eachX([&](size_t i, int j, int k, size_t o) {
            const int p[3] = {int(i), j, k};
            double d = 0.0;
            for (int a = 0; a < 3; ++a) {
                if (mDim[a] <= 1) continue;
                if (p[a] + 1 < mDim[a]) d -= v[3 * (o + mStride[a]) + size_t(a)];
                if (p[a] > 0) d += v[3 * (o - mStride[a]) + size_t(a)];
            }
            out[o] = d;
        });
    }
    /// out = G^T G x.
    void apply(const double* x, double* out) const
    {
        gradient(x, mGrad.data());
        transposed(mGrad.data(), out);
    }
    /// G psi into the operator's own buffer (3 values per voxel), valid until the next product.
    const std::vector<double>& gradientOf(const double* psi) const
    {
        gradient(psi, mGrad.data());
        return mGrad;
    }

private:
    template<typename Fn>
    void eachX(Fn&& fn) const
    {
        parallelFor(size_t(mDim.x()), 1, [&](size_t x0, size_t x1) {
            for (size_t i = x0; i < x1; ++i)
                for (int j = 0; j < mDim.y(); ++j)
                    for (int k = 0; k < mDim.z(); ++k) fn(i, j, k, i * mStride[0] + size_t(j) * mStride[1] + size_t(k));
        });
    }

    Coord mDim;
    size_t mStride[3];
    size_t mSize;
    mutable std::vector<double> mGrad;
};

} // namespace turb::detail

namespace Eigen::internal {

template<typename Rhs>
struct generic_product_impl<turb::detail::CentralNormalOperator, Rhs, SparseShape, DenseShape, GemvProduct>
    : generic_product_impl_base<turb::detail::CentralNormalOperator, Rhs,
          generic_product_impl<turb::detail::CentralNormalOperator, Rhs>>
{
    using Scalar = typename Product<turb::detail::CentralNormalOperator, Rhs>::Scalar;

    template<typename Dest>
    static void scaleAndAddTo(
        Dest& dst, const turb::detail::CentralNormalOperator& op, const Rhs& rhs, const Scalar& alpha)
    {
        // CG hands over its own contiguous vectors: read them in place, no copy per product.
        const Eigen::Ref<const Eigen::VectorXd> x(rhs);
        Eigen::VectorXd y(x.size());
        op.apply(x.data(), y.data());
        dst += alpha * y;
    }
};

} // namespace Eigen::internal

namespace turb {

CentralDivergenceResult removeCentralDivergence(VectorField& u, double tolerance, int maxIterations)
{
    if (!(tolerance > 0.0 && tolerance < 1.0)) throw ValueError("removeCentralDivergence: tolerance must be in (0, 1)");
    if (maxIterations < 1) throw ValueError("removeCentralDivergence: maxIterations must be >= 1");
    CentralDivergenceResult out;
    if (u.empty()) return out;
    const detail::CentralNormalOperator op(u.bbox());
    const size_t n = u.size();
    std::vector<double> v(n * 3);
    for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) v[3 * i + size_t(a)] = double(u.data()[i][a]);
    Eigen::VectorXd b(Eigen::Index(n), 1);
    op.transposed(v.data(), b.data()); // G^T u = -div u (index units, twice the central difference)
    const double h = u.lattice().voxelSize;
    out.divRmsBefore = b.norm() / std::sqrt(double(n)) / (2.0 * h);
    if (b.squaredNorm() == 0.0) {
        out.converged = true;
        return out;
    }
    Eigen::ConjugateGradient<detail::CentralNormalOperator, Eigen::Lower | Eigen::Upper, Eigen::IdentityPreconditioner>
        cg;
    cg.setTolerance(tolerance);
    cg.setMaxIterations(maxIterations);
    cg.compute(op);
    const Eigen::VectorXd psi = cg.solve(b);
    const std::vector<double>& g = op.gradientOf(psi.data());
    parallelFor(n, 1 << 14, [&](size_t b0, size_t b1) {
        for (size_t i = b0; i < b1; ++i)
            for (int a = 0; a < 3; ++a) {
                u.data()[i][a] = float(v[3 * i + size_t(a)] - g[3 * i + size_t(a)]);
                v[3 * i + size_t(a)] = double(u.data()[i][a]); // what is left, as stored
            }
    });
    Eigen::VectorXd after(Eigen::Index(n), 1);
    op.transposed(v.data(), after.data());
    out.iterations = int(cg.iterations());
    out.converged = cg.info() == Eigen::Success;
    out.divRmsAfter = after.norm() / std::sqrt(double(n)) / (2.0 * h);
    return out;
}

} // namespace turb
