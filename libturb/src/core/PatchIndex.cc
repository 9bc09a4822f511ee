#include <turb/PatchIndex.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include <Eigen/Dense>
#include <flann/flann.hpp>

#include <algorithm>
#include <numeric>
#include <random>

namespace turb {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

namespace {

// X * M and X^T * M for a tall sample X (n x dim) in fixed chunks of rows: the same GEMM shapes, hence the same
// rounding, at any thread count, with X^T M's partial sums added in chunk order. Eigen alone runs one thread.
constexpr Eigen::Index kRowChunk = 1024;

Eigen::MatrixXf tallTimes(const RowMatrix& X, const Eigen::MatrixXf& M)
{
    Eigen::MatrixXf out(X.rows(), M.cols());
    const size_t chunks = size_t((X.rows() + kRowChunk - 1) / kRowChunk);
    parallelFor(chunks, 1, [&](size_t c0, size_t c1) {
        for (size_t c = c0; c < c1; ++c) {
            const Eigen::Index r0 = Eigen::Index(c) * kRowChunk, rn = std::min(kRowChunk, X.rows() - r0);
            out.middleRows(r0, rn).noalias() = X.middleRows(r0, rn) * M;
        }
    });
    return out;
}

Eigen::MatrixXf tallTransposeTimes(const RowMatrix& X, const Eigen::MatrixXf& M)
{
    const size_t chunks = size_t((X.rows() + kRowChunk - 1) / kRowChunk);
    std::vector<Eigen::MatrixXf> partial(chunks);
    parallelFor(chunks, 1, [&](size_t c0, size_t c1) {
        for (size_t c = c0; c < c1; ++c) {
            const Eigen::Index r0 = Eigen::Index(c) * kRowChunk, rn = std::min(kRowChunk, X.rows() - r0);
            partial[c].noalias() = X.middleRows(r0, rn).transpose() * M.middleRows(r0, rn);
        }
    });
    Eigen::MatrixXf out = Eigen::MatrixXf::Zero(X.cols(), M.cols());
    for (const Eigen::MatrixXf& p : partial) out += p;
    return out;
}

// The top k principal axes of the centred sample X (n x dim) by randomized subspace iteration (Halko, Martinsson
// and Tropp 2011, "Finding structure with randomness", algorithm 4.4): O(n dim (k + p)) per pass instead of the
// O(n dim^2 + dim^3) of the covariance and its full eigendecomposition, which took tens of seconds for the 2916
// dimensions of a 9^3 global patch at ratio 2. The passes over X run in float on all threads (they were 3 s of
// every ratio-2 frame that searched globally in double on one); the small factorisations stay in double. A fixed
// seed keeps it deterministic. Returns the axes as columns (dim x k) and their variances (descending).
void randomizedAxes(const RowMatrix& X, size_t k, Eigen::MatrixXd& axes, Eigen::VectorXd& variances)
{
    const Eigen::Index dim = X.cols(), l = Eigen::Index(std::min<size_t>(size_t(dim), k + 10));
    std::mt19937_64 rng(0x5eed);
    std::normal_distribution<double> normal;
    Eigen::MatrixXf omega(dim, l);
    for (Eigen::Index c = 0; c < l; ++c)
        for (Eigen::Index r = 0; r < dim; ++r) omega(r, c) = float(normal(rng));
    const auto orthonormal = [](const Eigen::MatrixXf& m) {
        Eigen::HouseholderQR<Eigen::MatrixXd> qr(m.cast<double>());
        return Eigen::MatrixXf((qr.householderQ() * Eigen::MatrixXd::Identity(m.rows(), m.cols())).cast<float>());
    };
    Eigen::MatrixXf Q = orthonormal(tallTimes(X, omega));
    // Power iterations sharpen the spectrum's decay; re-orthonormalising each half-step keeps them stable.
    for (int it = 0; it < 3; ++it) Q = orthonormal(tallTimes(X, orthonormal(tallTransposeTimes(X, Q))));
    const Eigen::MatrixXd B = tallTransposeTimes(X, Q).transpose().cast<double>(); // l x dim
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(B, Eigen::ComputeThinV);
    axes = svd.matrixV().leftCols(Eigen::Index(k));
    const double norm = double(std::max<Eigen::Index>(X.rows() - 1, 1));
    variances = svd.singularValues().head(Eigen::Index(k)).array().square() / norm;
}

} // namespace

void Pca::fit(const float* rows, size_t count, size_t dim, const PcaSettings& settings)
{
    if (count == 0 || dim == 0) throw ValueError("PCA: no descriptors to fit");
    mDim = dim;
    mK = std::min(dim, size_t(std::max(1, settings.components)));
    // An even stride keeps the sample spread over the whole set and independent of threading.
    const size_t n = std::min(count, std::max<size_t>(settings.maxSamples, 1));
    const double stride = double(count) / double(n);
    Eigen::Map<const RowMatrix> all(rows, Eigen::Index(count), Eigen::Index(dim));
    mMean.assign(dim, 0.0f);
    mBasis.assign(dim * mK, 0.0f);
    double total = 0.0;     // the sample's total variance
    Eigen::MatrixXd axes;   // dim x mK, strongest first
    Eigen::VectorXd values; // their variances
    const auto sampleRow = [&](size_t i) { return all.row(Eigen::Index(size_t(double(i) * stride))); };
    if (dim <= settings.exactMaxDim) {
        Eigen::MatrixXd sample(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(dim));
        for (size_t i = 0; i < n; ++i) sample.row(Eigen::Index(i)) = sampleRow(i).cast<double>();
        const Eigen::VectorXd mean = sample.colwise().mean();
        sample.rowwise() -= mean.transpose();
        for (size_t d = 0; d < dim; ++d) mMean[d] = float(mean(Eigen::Index(d)));
        total = sample.squaredNorm() / double(std::max<size_t>(n - 1, 1));
        const Eigen::MatrixXd cov = (sample.transpose() * sample) / double(std::max<size_t>(n - 1, 1));
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov); // ascending
        axes = eig.eigenvectors().rightCols(Eigen::Index(mK)).rowwise().reverse();
        values = eig.eigenvalues().tail(Eigen::Index(mK)).reverse();
    } else {
        // Thousands of dimensions: a float sample (half the memory) for the randomized passes, the mean and the
        // total variance summed in double.
        Eigen::VectorXd mean = Eigen::VectorXd::Zero(Eigen::Index(dim));
        for (size_t i = 0; i < n; ++i) mean += sampleRow(i).cast<double>().transpose();
        mean /= double(n);
        const Eigen::RowVectorXf meanF = mean.transpose().cast<float>();
        RowMatrix sample(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(dim));
        for (size_t i = 0; i < n; ++i) {
            sample.row(Eigen::Index(i)) = sampleRow(i) - meanF;
            total += sample.row(Eigen::Index(i)).cast<double>().squaredNorm();
        }
        for (size_t d = 0; d < dim; ++d) mMean[d] = meanF(Eigen::Index(d));
        total /= double(std::max<size_t>(n - 1, 1));
        randomizedAxes(sample, mK, axes, values);
    }
    double kept = 0.0;
    for (size_t j = 0; j < mK; ++j) {
        const Eigen::Index col = Eigen::Index(j);
        kept += std::max(0.0, values(col));
        // Fix each axis's sign (largest component positive) so results do not depend on the solver.
        Eigen::Index arg = 0;
        axes.col(col).cwiseAbs().maxCoeff(&arg);
        const double sign = axes(arg, col) < 0 ? -1.0 : 1.0;
        for (size_t d = 0; d < dim; ++d) mBasis[d * mK + j] = float(sign * axes(Eigen::Index(d), col));
    }
    mExplained = total > 0 ? std::min(1.0, kept / total) : 1.0;
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
    const size_t count = rows.size() / dim;
    std::vector<float> reduced(count * pca.outputDim(), 0.0f);
    pca.projectRows(rows.data(), count, reduced.data());
    rows = std::vector<float>(); // free the full descriptors early
    buildReduced(std::move(reduced), pca);
}

void PatchIndex::buildReduced(std::vector<float> reduced, const Pca& pca)
{
    const size_t k = pca.outputDim();
    if (k == 0 || reduced.size() % k != 0) throw ValueError("PatchIndex: reduced array is not count x outputDim");
    mImpl->pca = pca;
    mImpl->count = reduced.size() / k;
    mImpl->reduced = std::move(reduced);
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

void PatchIndex::queryMany(
    const float* descriptors, size_t count, int k, std::vector<int>& indices, std::vector<float>& dist2) const
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
