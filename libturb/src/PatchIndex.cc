#include <turb/PatchIndex.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <Eigen/Dense>
#include <flann/flann.hpp>

#include <algorithm>
#include <numeric>

namespace turb {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

void Pca::fit(const float* rows, size_t count, size_t dim, const PcaSettings& settings)
{
    if (count == 0 || dim == 0) throw ValueError("PCA: no descriptors to fit");
    mDim = dim;
    mK = std::min(dim, size_t(std::max(1, settings.components)));
    // An even stride keeps the sample spread over the whole set and independent of threading.
    const size_t n = std::min(count, std::max<size_t>(settings.maxSamples, 1));
    const double stride = double(count) / double(n);
    Eigen::Map<const RowMatrix> all(rows, Eigen::Index(count), Eigen::Index(dim));
    Eigen::MatrixXd sample(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(dim));
    for (size_t i = 0; i < n; ++i) sample.row(Eigen::Index(i)) = all.row(Eigen::Index(size_t(i * stride))).cast<double>();
    const Eigen::VectorXd mean = sample.colwise().mean();
    sample.rowwise() -= mean.transpose();
    const Eigen::MatrixXd cov = (sample.transpose() * sample) / double(std::max<size_t>(n - 1, 1));
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov);
    const Eigen::VectorXd values = eig.eigenvalues();   // ascending
    const Eigen::MatrixXd vectors = eig.eigenvectors();
    mMean.assign(dim, 0.0f);
    for (size_t d = 0; d < dim; ++d) mMean[d] = float(mean(Eigen::Index(d)));
    mBasis.assign(dim * mK, 0.0f);
    double total = 0.0, kept = 0.0;
    for (Eigen::Index i = 0; i < values.size(); ++i) total += std::max(0.0, values(i));
    for (size_t j = 0; j < mK; ++j) {
        const Eigen::Index col = Eigen::Index(dim - 1 - j);
        kept += std::max(0.0, values(col));
        // Fix each axis's sign (largest component positive) so results do not depend on the solver.
        Eigen::Index arg = 0;
        vectors.col(col).cwiseAbs().maxCoeff(&arg);
        const double sign = vectors(arg, col) < 0 ? -1.0 : 1.0;
        for (size_t d = 0; d < dim; ++d) mBasis[d * mK + j] = float(sign * vectors(Eigen::Index(d), col));
    }
    mExplained = total > 0 ? kept / total : 1.0;
}

void Pca::project(const float* row, float* out) const
{
    for (size_t j = 0; j < mK; ++j) out[j] = 0.0f;
    for (size_t d = 0; d < mDim; ++d) {
        const float v = row[d] - mMean[d];
        const float* b = &mBasis[d * mK];
        for (size_t j = 0; j < mK; ++j) out[j] += v * b[j];
    }
}

void Pca::projectRows(const float* rows, size_t count, float* out) const
{
    Eigen::Map<const RowMatrix> basis(mBasis.data(), Eigen::Index(mDim), Eigen::Index(mK));
    Eigen::Map<const Eigen::RowVectorXf> mean(mMean.data(), Eigen::Index(mDim));
    // Fixed-size chunks: the same GEMM shapes, hence the same rounding, at any thread count.
    const size_t chunk = 1024;
    parallelFor(count, chunk, [&](size_t b, size_t e) {
        Eigen::Map<const RowMatrix> x(rows + b * mDim, Eigen::Index(e - b), Eigen::Index(mDim));
        Eigen::Map<RowMatrix> y(out + b * mK, Eigen::Index(e - b), Eigen::Index(mK));
        y.noalias() = (x.rowwise() - mean) * basis;
    });
}

void Pca::reconstruct(const float* coeffs, float* row) const
{
    for (size_t d = 0; d < mDim; ++d) {
        float v = mMean[d];
        const float* b = &mBasis[d * mK];
        for (size_t j = 0; j < mK; ++j) v += coeffs[j] * b[j];
        row[d] = v;
    }
}

struct PatchIndex::Impl
{
    Pca pca;
    std::vector<float> reduced; // size x k, owned: FLANN matrices do not own memory
    size_t count = 0;
    std::unique_ptr<flann::Index<flann::L2<float>>> index;
};

PatchIndex::PatchIndex() : mImpl(std::make_unique<Impl>()) {}
PatchIndex::~PatchIndex() = default;
PatchIndex::PatchIndex(PatchIndex&&) noexcept = default;
PatchIndex& PatchIndex::operator=(PatchIndex&&) noexcept = default;

void PatchIndex::build(std::vector<float> rows, size_t dim, const PcaSettings& settings)
{
    if (dim == 0 || rows.size() % dim != 0) throw ValueError("PatchIndex: descriptor array is not count x dim");
    Pca pca;
    pca.fit(rows.data(), rows.size() / dim, dim, settings);
    build(std::move(rows), dim, pca);
}

void PatchIndex::build(std::vector<float> rows, size_t dim, const Pca& pca)
{
    if (dim != pca.inputDim()) throw ValueError("PatchIndex: PCA was fitted for another descriptor size");
    if (rows.size() % dim != 0) throw ValueError("PatchIndex: descriptor array is not count x dim");
    mImpl->pca = pca;
    mImpl->count = rows.size() / dim;
    const size_t k = pca.outputDim();
    mImpl->reduced.assign(mImpl->count * k, 0.0f);
    pca.projectRows(rows.data(), mImpl->count, mImpl->reduced.data());
    rows = std::vector<float>(); // free the full descriptors early
    mImpl->index.reset();
    if (mImpl->count == 0) return;
    flann::Matrix<float> data(mImpl->reduced.data(), mImpl->count, k);
    mImpl->index = std::make_unique<flann::Index<flann::L2<float>>>(data, flann::KDTreeSingleIndexParams(12, false));
    mImpl->index->buildIndex();
}

size_t PatchIndex::size() const { return mImpl->count; }
const Pca& PatchIndex::pca() const { return mImpl->pca; }

int PatchIndex::queryReduced(const float* reduced, int k, int* indices, float* dist2) const
{
    if (!mImpl->index || k <= 0) return 0;
    const int kk = int(std::min<size_t>(size_t(k), mImpl->count));
    const size_t dim = mImpl->pca.outputDim();
    flann::Matrix<float> q(const_cast<float*>(reduced), 1, dim);
    flann::Matrix<int> idx(indices, 1, size_t(kk));
    flann::Matrix<float> dst(dist2, 1, size_t(kk));
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED);
    params.cores = 1;
    mImpl->index->knnSearch(q, idx, dst, size_t(kk), params);
    return kk;
}

int PatchIndex::query(const float* descriptor, int k, int* indices, float* dist2) const
{
    std::vector<float> r(mImpl->pca.outputDim());
    mImpl->pca.project(descriptor, r.data());
    return queryReduced(r.data(), k, indices, dist2);
}

void PatchIndex::queryMany(const float* descriptors, size_t count, int k, std::vector<int>& indices,
    std::vector<float>& dist2) const
{
    const size_t rk = mImpl->pca.outputDim();
    indices.assign(count * size_t(std::max(k, 0)), -1);
    dist2.assign(count * size_t(std::max(k, 0)), 0.0f);
    if (k <= 0 || count == 0) return;
    std::vector<float> reduced(count * rk);
    mImpl->pca.projectRows(descriptors, count, reduced.data());
    parallelFor(count, 64, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i)
            queryReduced(&reduced[i * rk], k, &indices[i * size_t(k)], &dist2[i * size_t(k)]);
    });
}

} // namespace turb
