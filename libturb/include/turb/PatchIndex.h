/// @file PatchIndex.h
/// @brief Nearest-neighbour search over patch descriptors: PCA reduction (Eigen) + a FLANN k-d tree.
///
/// Descriptors live in one contiguous row-major array (count x dim). PCA and the index are one object
/// with build/query, so callers never see FLANN (the nanoflann "adaptor" idea). The k-d tree is FLANN's
/// single exact tree: queries are deterministic and independent, so they run in parallel through
/// turb::parallelFor (FLANN's own OpenMP threading is not used; it fights TBB).
///
/// @code
/// turb::PatchIndex index;
/// index.build(std::move(rows), dim, turb::PcaSettings{16});
/// int nearest; float d2;
/// index.query(queryRow.data(), 1, &nearest, &d2);
/// @endcode
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

namespace turb {

struct PcaSettings
{
    int components = 16;       ///< reduced dimension, >= 1 (clamped to the descriptor dimension)
    size_t maxSamples = 12000; ///< rows used to estimate the covariance (an even stride through the set)
    size_t exactMaxDim = 512;  ///< up to this descriptor dimension the covariance is decomposed exactly; above
                               ///< it, randomized subspace iteration finds the top axes (Halko et al. 2011)
};

/// Rows the transfer's global index fits its PCA on (PcaSettings::maxSamples there): at ratio 2 a global descriptor
/// has 2916 floats and the fit was most of a searching frame's time with 12000 rows. Measured on the Blender plume2
/// pair at ratio 2: the same explained variance (0.86664 against 0.86671) and mean local energies E_h within
/// -0.4..+0.8% of the 12000-row fit's per frame, in half the time (0.45 -> 0.24 s). Tested by
/// `Pca.GlobalPatchSampleFindsTheSameNeighbours`.
inline constexpr size_t kGlobalPatchPcaSamples = 6000;

/// Principal axes of a set of row vectors.
class Pca
{
public:
    /// Fits mean and the top principal axes of `count` rows of `dim` floats.
    void fit(const float* rows, size_t count, size_t dim, const PcaSettings& settings);

    size_t inputDim() const { return mDim; }
    size_t outputDim() const { return mK; }
    /// Fraction of the sample's total variance the kept axes explain, in [0, 1].
    double explainedVariance() const { return mExplained; }

    /// Coefficients of one row (outputDim floats).
    void project(const float* row, float* out) const;
    /// Coefficients of many rows, row-major count x outputDim; parallel and deterministic.
    void projectRows(const float* rows, size_t count, float* out) const;
    /// A row rebuilt from its coefficients (inputDim floats).
    void reconstruct(const float* coeffs, float* row) const;

    const std::vector<float>& mean() const { return mMean; }

private:
    size_t mDim = 0, mK = 0;
    std::vector<float> mMean;  // dim
    std::vector<float> mBasis; // dim x k, column j = j-th axis
    double mExplained = 0.0;
};

class PatchIndex
{
public:
    PatchIndex();
    ~PatchIndex();
    PatchIndex(PatchIndex&&) noexcept;
    PatchIndex& operator=(PatchIndex&&) noexcept;

    /// Fits PCA on the rows and builds the tree over their coefficients. `rows` is consumed.
    void build(std::vector<float> rows, size_t dim, const PcaSettings& pca);
    /// Builds the tree with an already fitted PCA (shared between frames, or fit on another set).
    void build(std::vector<float> rows, size_t dim, const Pca& pca);
    /// Builds the tree over rows already reduced by `pca` (count x pca.outputDim()), so callers can project
    /// large sets in chunks without holding every full descriptor at once.
    void buildReduced(std::vector<float> reduced, const Pca& pca);

    size_t size() const;
    bool empty() const { return size() == 0; }
    const Pca& pca() const;

    /// The k nearest rows to a full-dimension descriptor: row indices and squared distances in the
    /// reduced space, nearest first. Returns how many were found (min(k, size())).
    int query(const float* descriptor, int k, int* indices, float* dist2) const;
    /// The same for an already reduced descriptor.
    int queryReduced(const float* reduced, int k, int* indices, float* dist2) const;
    /// Many descriptors (row-major count x dim) in parallel; results are count x k, padded with -1.
    void queryMany(
        const float* descriptors, size_t count, int k, std::vector<int>& indices, std::vector<float>& dist2) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace turb
