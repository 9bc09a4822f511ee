#include <turb/SynthSequence.h>

#include "../core/Timing.h"

#include <turb/Error.h>
#include <turb/Operators.h>
#include <turb/Resample.h>

#include <algorithm>
#include <cmath>

namespace turb {

namespace {

LookbackSettings lookbackOf(const SynthSequenceSettings& s)
{
    LookbackSettings l;
    l.frames = s.lookback;
    return l;
}

// Section 3.5's projection of F, with the walls and the obstacle closed; a 2D field stays 2D.
ProjectionResult projectMotion(
    VectorField& F, const SynthSequenceSettings& s, const ScalarField* obstacle, bool volume, Progress* progress)
{
    ProjectionSettings ps;
    ps.maxIterations = s.projectIterations;
    for (int k = 0; k < 6; ++k)
        if (s.synth.boundary.walls & (1u << k)) ps.faces[size_t(k)] = Boundary::Closed;
    if (!volume) ps.faces[kFaceZMin] = ps.faces[kFaceZMax] = Boundary::Closed;
    std::optional<MaskField> solid;
    if (obstacle) {
        solid = MaskField(F.bbox(), F.lattice());
        for (size_t n = 0; n < solid->size(); ++n) {
            const Vec3d w = F.lattice().indexToWorld(solid->coordOf(n).asVec3d());
            solid->data()[n] = sampleWorld(*obstacle, w) < 0.0f ? 1 : 0;
        }
    }
    return project(F, ps, solid ? &*solid : nullptr, progress);
}

} // namespace

SynthSequence::SynthSequence(const SynthExemplars& exemplars, const SynthSequenceSettings& settings)
    : mExemplars(exemplars), mSettings(settings), mLookback(lookbackOf(settings))
{}

SynthFrameResult SynthSequence::next(const SynthFrameInput& in, Progress* progress)
{
    if (!in.coarse || in.coarse->empty()) throw ValueError("synth: a frame needs its coarse velocity L");
    if (!(in.dt > 0.0)) throw ValueError("synth: the time per frame must be > 0");
    const SynthSequenceSettings& s = mSettings;
    const bool volume = in.coarse->bbox().dim().z() > 1;
    SynthFrameResult r;
    detail::Clock::time_point t0 = detail::Clock::now();

    // Continue from the previous *processed* frame over the real time between the two: frames two apart
    // (--frames 1-30x2, a cache written every second frame) advect by two frames' time.
    const bool continuing = bool(mPrevious);
    const double elapsed = continuing ? in.dt * double(in.frame - mPreviousFrame) : in.dt;
    SynthInput si;
    si.coarse = in.coarse;
    si.coarseDensity = in.coarseDensity;
    si.obstacle = in.obstacle;
    si.factor = s.factor;
    si.previous = continuing ? &*mPrevious : nullptr;
    si.dt = elapsed;
    DetailField H = synthesizeDetail(mExemplars, si, s.synth, progress);
    r.seconds.synthesis = detail::lap(t0);

    if (progress) progress->begin("combine");
    // Detail near the smoke only: the smoke on L's box, zero where the density grid stops short.
    CombineSettings combine = s.combine;
    ScalarField smoke;
    if (s.detailNearSmoke && in.coarseDensity) {
        smoke = cropped(*in.coarseDensity, in.coarse->bbox());
        combine.smoke = &smoke;
        r.smokeless = std::none_of(
            smoke.values().begin(), smoke.values().end(), [&](float v) { return v > combine.smokeThreshold; });
    }
    CentralDivergenceResult divergence;
    r.motion = combineMotion(*in.coarse, H.world, combine, &divergence);
    if (combine.solenoidalDetail) r.detailDivergence = divergence;
    if (s.project) {
        if (progress) progress->begin("projection");
        r.projection = projectMotion(r.motion, s, in.obstacle, volume, progress);
    }
    r.seconds.combine = detail::lap(t0);

    r.frame.number = in.frame;
    r.frame.dt = in.dt;
    r.frame.timeUnit = in.timeUnit;
    r.frame.velocity = r.motion;
    if (s.detailOnly) {
        const VectorField up = upsampleCoarse(*in.coarse, s.factor);
        for (size_t n = 0; n < r.motion.size(); ++n) r.frame.velocity.data()[n] -= up.data()[n];
    }
    if (in.coarseDensity && s.density) {
        if (progress) progress->begin("density");
        if (!continuing) mLookback = LookbackDensity(lookbackOf(s)); // the first frame starts a new history
        const ScalarField sources =
            estimateSources(mPreviousDensity.empty() || !continuing ? nullptr : &mPreviousDensity, *in.coarseDensity,
                *in.coarse, elapsed, AdvectSettings{}, in.emitters);
        const ScalarField fineSources = upsampleCoarse(sources, s.factor);
        const ScalarField coarseOnly = s.lookback > 0 ? upsampleCoarse(*in.coarseDensity, s.factor) : ScalarField();
        r.frame.density = mLookback.step(r.motion, fineSources, coarseOnly, elapsed, progress);
        mPreviousDensity = *in.coarseDensity;
        double mass = 0.0;
        for (float v : r.frame.density.values()) mass += v;
        r.densityMass = mass * std::pow(r.frame.density.lattice().voxelSize, 3);
    }
    r.seconds.density = detail::lap(t0);

    mPrevious = std::move(H);
    mPreviousFrame = in.frame;
    return r;
}

const DetailField& SynthSequence::lastDetail() const
{
    if (!mPrevious) throw ValueError("synth: no frame has been synthesised yet");
    return *mPrevious;
}

} // namespace turb
