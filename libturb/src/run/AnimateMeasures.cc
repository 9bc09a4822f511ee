// runAnimate's --measure (AnimateParts.h): the output's motion against the design, its temporal statistics against
// the example's.
#include "AnimateParts.h"

#include <turb/run/Reporter.h>

#include <turb/Parallel.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>

#include <cmath>

namespace turb::run::detail {

namespace {

// Medians over a handful of frame pairs swing widely (2 frames gave speed ratios of 10-27).
constexpr size_t kMinMeasuredFrames = 8;

std::string said(const turb::FlowAgreement& f)
{
    return std::isnan(f.medianAngleDeg)
               ? std::string("not measured (nothing tracked)")
               : fmt("%.1f deg", f.medianAngleDeg) + ", speed ratio " + fmt("%.2f", f.medianSpeedRatio);
}

// The calibration: the same tracking on the example against the cache's own flow.
void sayExampleAgreement(const Measures& m, nlohmann::json& quality)
{
    if (!m.exampleAgreement) return;
    quality["example_track_median_angle_deg"] = m.exampleTracks->medianAngleDeg;
    quality["example_track_median_speed_ratio"] = m.exampleTracks->medianSpeedRatio;
    quality["example_flow_median_angle_deg"] = m.exampleAgreement->medianAngleDeg;
    quality["example_flow_median_speed_ratio"] = m.exampleAgreement->medianSpeedRatio;
    logInfo("animate: the same tracking on the example against the cache's flow: tracks " + said(*m.exampleTracks) +
            "; interpolated field " + said(*m.exampleAgreement));
}

} // namespace

Measures startMeasures(const AnimateJob& a, const Example& example, const Target& target)
{
    Measures m;
    if (!a.measure) return m;
    const turb::AnimateSettings& s = a.settings;
    m.exTemporal.emplace(s.tau);
    for (size_t i = size_t(s.tau); i < example.frames.size(); ++i) m.exTemporal->add(example.frames[i]);
    m.outTemporal.emplace(s.tau, target.matte ? &*target.matte : nullptr);
    // Calibration of the measurement: the same tracking on the example against the cache's own flow.
    if (example.flow)
        turb::withThreads(a.threads, [&] {
            std::vector<turb::FlowTrack> tracks; // one tracking pass gives both measures
            const turb::ChannelImage v = turb::estimateMeanFlow(example.frames, s.analysis, nullptr, nullptr, &tracks);
            m.exampleAgreement = turb::compareFlows(v, *example.flow, nullptr, 0.25);
            m.exampleTracks = turb::compareTracks(tracks, *example.flow, nullptr, 0.25);
        });
    return m;
}

void finishMeasures(const AnimateJob& a, const Measures& m, const turb::ChannelImage& designed, const Target& target,
    nlohmann::json& summary)
{
    turb::AnalysisSettings as = a.settings.analysis;
    turb::AnalysisStats tracked;
    std::vector<turb::FlowTrack> tracks; // one tracking pass gives both measures
    const turb::ChannelImage measured = turb::estimateMeanFlow(m.outLuma, as, &tracked, nullptr, &tracks);
    const turb::ChannelImage* matte = target.matte ? &*target.matte : nullptr;
    // No pair tracked: the interpolated field is zero by default, not a measurement.
    const turb::FlowAgreement fa = tracked.pairsUsed > 0 ? turb::compareFlows(measured, designed, matte)
                                                         : turb::FlowAgreement{std::nan(""), std::nan(""), 0.0};
    const turb::FlowAgreement ft = turb::compareTracks(tracks, designed, matte);
    const turb::TemporalSummary te = m.exTemporal->summary(), to = m.outTemporal->summary();
    summary["quality"] = {{"track_median_angle_deg", ft.medianAngleDeg},
        {"track_median_speed_ratio", ft.medianSpeedRatio}, {"track_fraction", ft.pixels},
        {"flow_median_angle_deg", fa.medianAngleDeg}, {"flow_median_speed_ratio", fa.medianSpeedRatio},
        {"flow_pixels", fa.pixels}, {"temporal_std", to.temporalStd}, {"temporal_std_example", te.temporalStd},
        {"autocorrelation", to.autocorrelation}, {"autocorrelation_example", te.autocorrelation}};
    sayExampleAgreement(m, summary["quality"]);
    logInfo("animate: motion vs design: tracks " + said(ft) + "; interpolated field " + said(fa) + "; temporal std " +
            fmt("%.4f", to.temporalStd) + " (example " + fmt("%.4f", te.temporalStd) + "); autocorrelation lag 1 " +
            fmt("%.2f", to.autocorrelation[0]) + " (example " + fmt("%.2f", te.autocorrelation[0]) + ")");
    if (m.outLuma.size() < kMinMeasuredFrames)
        logWarning("--measure: " + std::to_string(m.outLuma.size()) +
                   " output frames; the motion and temporal "
                   "figures need at least " +
                   std::to_string(kMinMeasuredFrames) + " to mean much");
    if (std::isnan(ft.medianAngleDeg))
        logWarning("--measure: nothing moving was tracked in the output inside the matte; no motion figures");
    if (!a.dump.empty()) turbio::writeImage(a.dump + "/measured_flow.png", flowPicture(measured));
}

} // namespace turb::run::detail
