/// @file AnimateQuality.h
/// @brief The numbers that say whether an `animate` result is right (docs/animate.md):
///        does the motion follow the design, and does the output flicker like the example?
///
/// - **Flow agreement**: the output's mean flow, measured by the same analysis as the example's
///   (VideoAnalysis.h: Lucas-Kanade on the differences from the output's own average), against the
///   designed flow, over the matte where the design moves at least `minSpeed`: the median angle between
///   them and the median speed ratio |measured| / |designed|.
/// - **Temporal statistics** of a sequence's luminance, streamed frame by frame: the per-pixel temporal
///   standard deviation (averaged over the region) and the per-pixel temporal autocorrelation at lags
///   1..maxLag, rho(L) = mean_x cov_t(Y(x, t), Y(x, t + L)) / var_t(Y(x, t)) (pixels with var > 0).
///
/// @code
/// turb::ChannelImage measured = turb::estimateMeanFlow(outputFrames, turb::AnalysisSettings{});
/// turb::FlowAgreement a = turb::compareFlows(measured, designed, &matte);   // a.medianAngleDeg, a.medianSpeedRatio
/// turb::TemporalStats ts(16);  for (auto& f : frames) ts.add(f);  turb::TemporalSummary s = ts.summary();
/// @endcode
#pragma once

#include <turb/ChannelImage.h>
#include <turb/VideoAnalysis.h>

#include <vector>

namespace turb {

struct FlowAgreement
{
    double medianAngleDeg = 0.0;   ///< median angle between measured and designed flow, degrees; NaN: none compared
    double medianSpeedRatio = 0.0; ///< median |measured| / |designed|; NaN when nothing was compared
    double pixels = 0.0;           ///< fraction of the image compared
};

/// Compares two 2-channel flows of one size where matte >= 0.5 (everywhere without one) and the designed
/// speed >= minSpeed (pixels per frame), ignoring a border of `border` pixels (where tracking sees
/// texture enter). Throws ValueError on mismatched shapes.
FlowAgreement compareFlows(const ChannelImage& measured, const ChannelImage& designed,
    const ChannelImage* matte = nullptr, double minSpeed = 0.25, int border = 8);

/// The same comparison track by track, before any interpolation: each FlowTrack's displacement against the design
/// at the step's mid-point, where that lies inside the matte (>= 0.5), off the border and where the design moves
/// at least `minSpeed`. `pixels` is then the fraction of the tracks compared. The interpolated field of
/// compareFlows spreads each track over the pixels around it, and a design that varies faster than the tracks are
/// spaced then compares with a smoothed field; the tracks compare only where there is texture to see moving.
/// Throws ValueError on a design that is not 2-channel or a matte of another size.
FlowAgreement compareTracks(const std::vector<FlowTrack>& tracks, const ChannelImage& designed,
    const ChannelImage* matte = nullptr, double minSpeed = 0.25, int border = 8);

struct TemporalSummary
{
    int frames = 0;
    double temporalStd = 0.0;            ///< mean over pixels of the temporal std of the luminance
    std::vector<double> autocorrelation; ///< [L - 1] for lags L = 1..maxLag; NaN for lags >= the frame count
};

/// Streaming per-pixel temporal statistics of a sequence's luminance (Rec. 709 on 3+ channels).
class TemporalStats
{
public:
    /// `matte` (1 channel) restricts the pixels averaged (matte >= 0.5); it must outlive this object.
    explicit TemporalStats(int maxLag, const ChannelImage* matte = nullptr);
    /// Adds the next frame; all frames share one size (ValueError otherwise).
    void add(const ChannelImage& frame);
    TemporalSummary summary() const;

private:
    int mLag;
    const ChannelImage* mMatte;
    int mW = 0, mH = 0, mFrames = 0;
    std::vector<double> mSum, mSum2;
    std::vector<std::vector<double>> mLagSum;         // [L - 1][pixel]: sum_t Y(t) Y(t + L)
    std::vector<std::vector<double>> mHead, mTailSum; // sums of the first / last L frames, to centre each lag exactly
    std::vector<std::vector<float>> mRing;            // the last maxLag luminance frames
};

} // namespace turb
