/// @file Rbf.h
/// @brief Scattered-data interpolation with the radial basis phi(r) = r (Okabe et al. sections 4.2 and
///        5.1, after Praun et al. 2000), shared by the example's sparse flow and the flow strokes.
///
/// f(x) = sum_i w_i |x - c_i| + p(x), with p linear (1, x, y) when the centres span the plane, constant
/// when they are collinear, and the side conditions sum_i w_i q(c_i) = 0 for every q in p's space.
/// phi = r is conditionally positive definite of order 1, so the system is uniquely solvable for
/// distinct centres; a linear (constant) function is reproduced exactly. Centres closer than
/// `mergeDistance` are merged (values averaged) so the system stays regular.
#pragma once

#include <turb/ChannelImage.h>

#include <vector>

namespace turb::rbf {

struct Sample
{
    double x = 0.0, y = 0.0;
    std::vector<double> values; ///< one per output channel
};

class Interpolant
{
public:
    /// Fits the samples (all with the same number of values, >= 1 sample). Throws ValueError on an
    /// empty set or mismatched value counts.
    void fit(std::vector<Sample> samples, double mergeDistance = 0.5);

    int channels() const { return mChannels; }
    size_t centres() const { return mCx.size(); }
    /// Writes channels() values at (x, y).
    void evaluate(double x, double y, double* out) const;

    /// The interpolant on a width x height image: evaluated on a lattice of `step` pixels (and on the
    /// last row and column), bilinear in between; step 1 evaluates every pixel. Parallel, deterministic.
    ChannelImage render(int width, int height, int step) const;

private:
    int mChannels = 0, mPoly = 0; // polynomial terms: 1 (constant) or 3 (linear)
    std::vector<double> mCx, mCy; // centres
    std::vector<double> mW;       // (centres + poly) x channels, row-major
};

} // namespace turb::rbf
