// Section 3.1: the target at output resolution, and the source's frequency split.
#include "Stages.h"

#include <turb/Advect.h>
#include <turb/Error.h>
#include <turb/Measure.h>

namespace turb::detail {

TargetAtOutput splitTarget(const Frame& target, const CarriedState& c, const FrameSetup& fs)
{
    TargetAtOutput t;
    t.Ut = upsample(target.velocity, fs.f);
    t.Dt = upsample(target.density, fs.f);
    // Emission estimate for density: what the target gained that advection does not explain.
    t.emission = ScalarField(target.density.bbox(), fs.targetLattice);
    if (c.havePrevious) {
        const ScalarField previous = cropped(c.prevTargetDensity, target.density.bbox());
        t.emission = estimateSources(&previous, target.density, c.prevTargetVelocity, fs.elapsed, inPlane());
    }
    return t;
}

SourceBands splitSource(const Frame& source, const Frame& target, const FrameSetup& fs, AlignmentState& align)
{
    const TransferSettings& s = *fs.s;
    const int f = fs.f;
    SourceBands out;
    VectorField Us = source.velocity;
    out.Ds = source.density;
    bool smoke = false;
    for (float v : out.Ds.values()) smoke |= v > s.densityThreshold;
    if (!smoke)
        throw ValueError(
            "the source frame " + std::to_string(source.number) + " holds no smoke above the density threshold");
    const bool rotate = s.alignment == FlowAlignment::Rotate || s.alignment == FlowAlignment::Both;
    const bool normalize = s.alignment == FlowAlignment::Normalize || s.alignment == FlowAlignment::Both;
    Vec3d meanT, meanS;
    double rmsT = 0, rmsS = 0;
    smokeFlowStats(target.velocity, target.density, s.densityThreshold, meanT, rmsT);
    if (rotate && !align.chosen) {
        smokeFlowStats(Us, out.Ds, s.densityThreshold, meanS, rmsS);
        align.rotation = bestRotation(meanS, meanT);
        align.chosen = true;
    }
    if (rotate && !align.rotation.isIdentity()) {
        Us = rotated(Us, align.rotation);
        out.Ds = rotated(out.Ds, align.rotation);
    }
    out.split = splitFrequencies(Us, f);
    FrequencySplit& split = out.split;
    // The source's high-frequency energy per smoke voxel, as hf_ratio defines it (before the coarse part below is
    // taken out): the level DetailEnergy::Source calibrates U_h to.
    {
        size_t n = 0;
        for (size_t i = 0; i < split.high.size(); ++i)
            if (out.Ds.data()[i] > s.densityThreshold) {
                out.reference += double(split.high.data()[i].lengthSqr());
                ++n;
            }
        out.reference = n ? out.reference / double(n) : 0.0;
    }
    if (s.removeCoarseDetail) {
        // U_sh still has box means where the coarse flow is sharp (trilinear up-sampling is not the inverse of box
        // averaging). Those belong to the coarse motion, which is the target's to give: transfer only the part of
        // the source's detail that is invisible at the target's resolution.
        const VectorField c = coarsePart(split.high, f);
        const VectorField cu = cropped(upsample(c, f), split.high.bbox());
        for (size_t n = 0; n < split.high.size(); ++n) {
            split.high.data()[n] -= cu.data()[n];
            split.low.data()[n] += cu.data()[n];
        }
    }
    if (s.vorticityLimit > 0.0f && !fs.flat) {
        // The source's hottest vorticity, the cap of TransferSettings::vorticityLimit (in output units below; the
        // cap applies to 3D caches only).
        std::vector<unsigned char> mask(out.Ds.size());
        for (size_t n = 0; n < mask.size(); ++n) mask[n] = out.Ds.data()[n] > s.densityThreshold;
        out.vortPeak = vorticityPeak(Us, mask, kVortPeakQuantile).value_or(0.0);
    }
    out.ds = boxDownsample(out.Ds, f);
    // Velocity scale into matching units: grid units (coarse cells per frame) by default; with normalisation,
    // units of each sequence's RMS speed.
    const double dxS = source.velocity.lattice().voxelSize * f;
    out.kt = float(target.dt / fs.targetLattice.voxelSize);
    out.ks = float(source.dt / dxS);
    if (normalize) {
        smokeFlowStats(split.coarse, out.ds, s.densityThreshold, meanS, rmsS);
        if (rmsT > 0 && rmsS > 0) {
            out.kt = float(1.0 / rmsT);
            out.ks = float(1.0 / rmsS);
        }
    }
    out.detailScale = out.ks / out.kt;
    out.vortPeak *= double(out.detailScale);
    out.reference *= double(out.detailScale) * double(out.detailScale);
    if (fs.detailEnergy() == DetailEnergy::Distribution) {
        std::vector<float> m;
        for (size_t i = 0; i < split.high.size(); ++i)
            if (out.Ds.data()[i] > s.densityThreshold) m.push_back(split.high.data()[i].length() * out.detailScale);
        out.magnitudes = rankTable(std::move(m), kMagnitudeRanks);
    }
    return out;
}

} // namespace turb::detail
