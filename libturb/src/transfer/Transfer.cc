// The transfer pipeline (seed 002, section 3) and its state between frames.
#include <turb/Transfer.h>

#include "Align.h"
#include "PatchSearch.h"

#include <turb/Advect.h>
#include <turb/Error.h>
#include <turb/Parallel.h>
#include <turb/Resample.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <chrono>
#include <cmath>
#include <deque>
#include <map>
#include <sstream>

namespace turb {

const char* TransferStats::stepName(int i)
{
    static const char* names[9] = {"split", "global", "local", "paste", "seams", "output", "density", "total", "advect_detail"};
    return (i >= 0 && i < 9) ? names[i] : "?";
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

void requireFrame(const Frame& f, const char* role)
{
    if (!f.hasVelocity()) throw ValueError(std::string("the ") + role + " frame has no velocity");
    if (!f.hasDensity()) throw ValueError(std::string("the ") + role + " frame has no density");
    if (f.velocity.bbox() != f.density.bbox())
        throw ValueError(std::string("the ") + role + " frame's velocity and density cover different boxes");
    if (!(f.dt > 0.0))
        throw ValueError(std::string("the ") + role + " frame has no time per frame (dt); give it explicitly");
}

// Energy of the detail (minus `less`, same box, when given) inside the smoke, where the turbulence is
// seen (and measured).
double smokeEnergy(const VectorField& u, const ScalarField& density, float threshold, const VectorField* less = nullptr)
{
    return parallelSum(u.size(), 1 << 16, [&](size_t b, size_t e) {
        double acc = 0.0;
        for (size_t n = b; n < e; ++n)
            if (density.data()[n] > threshold)
                acc += double((less ? u.data()[n] - less->data()[n] : u.data()[n]).lengthSqr());
        return acc;
    });
}

// The factor that brings detail of mean energy `now` to `reference`. Bounded: a large factor would mean
// the pipeline lost the detail, not something to amplify.
double energyFactor(double reference, double now)
{
    return now > 0.0 ? std::clamp(std::sqrt(reference / now), 1.0 / 3.0, 3.0) : 1.0;
}

// The fraction of a coarse part measuring `lf` (lf_err's ratio) that stays within `tolerance`; an
// infinite lf (a target at rest under the detail) keeps none.
double keptFraction(double lf, double tolerance)
{
    if (!std::isfinite(lf)) return 0.0;
    return lf > tolerance ? tolerance / lf : 1.0;
}

size_t smokeCount(const ScalarField& density, float threshold)
{
    size_t n = 0;
    for (float v : density.values()) n += v > threshold;
    return n;
}

bool anySmoke(const ScalarField& d, float threshold)
{
    for (float v : d.values())
        if (v > threshold) return true;
    return false;
}

// Adds the target's emission (fine, same box as `d`) where it emits, but never beyond the target's own density
// there (`targetFine`) unless `d` already holds more. Inflow emitters in Blender and Houdini set (or take the
// maximum of) density inside the emitter rather than adding without limit; the estimate max(0, d_t - advect(d_t))
// cannot tell the two apart, and summed onto a high-resolution density that keeps more smoke at the emitter than
// the coarse advection predicts, it piles up there frame after frame.
void addBoundedEmission(ScalarField& d, const ScalarField& emissionFine, const ScalarField& targetFine)
{
    for (size_t n = 0; n < d.size(); ++n) {
        const float e = emissionFine.data()[n];
        if (!(e > 0.0f)) continue;
        float& v = d.data()[n];
        v = std::min(v + e, std::max(v, targetFine.data()[n]));
    }
}

// The time between two processed frames: their frame-number gap times the time per frame (the mean of the two
// frames' when they differ), so frames processed two apart (a cache written every second frame, --frames x2)
// are advanced by two frames' time. Throws on frames out of order.
double elapsedTime(int previousNumber, double previousDt, int number, double dt)
{
    const int gap = number - previousNumber;
    if (gap <= 0)
        throw ValueError("frames must be processed in increasing order: frame " + std::to_string(number) + " after frame " +
                         std::to_string(previousNumber));
    return 0.5 * (previousDt + dt) * double(gap);
}

} // namespace

struct TurbulenceTransfer::Impl
{
    TransferSettings s;
    detail::MatchWeights w;

    // Fixed once the first frame arrives.
    bool started = false;
    int ratio = 0;
    Lattice targetLattice;
    CoordBBox targetBox, fineBox;
    PatchLayout layout;
    int globalPatch = 3;
    bool rotationChosen = false;
    detail::AxisRotation rotation;

    // Carried between frames. Patches are keyed by their position on the absolute patch lattice (fine
    // index / B), so a target whose active box grows or moves from frame to frame (Houdini's resizing
    // containers) keeps its tracks.
    std::map<Coord, Coord> tracks;  // patch -> source corner of its best local patch last frame
    std::vector<uint8_t> tracked;   // this frame's layout: the patch has a track
    std::vector<Coord> match;       // this frame's layout: that track's source corner
    bool havePrevious = false;
    VectorField prevDetail;         // U_h(i-1), output lattice
    VectorField prevTargetVelocity; // u_t(i-1), target lattice
    ScalarField prevTargetDensity;  // d_t(i-1)
    ScalarField prevDensity;        // D(i-1), output lattice
    VectorField prevVelocity;       // U(i-1), output lattice
    double prevDt = 0.0;            // time per frame at frame i-1
    int prevNumber = 0;             // frame number of i-1 (the previous *processed* frame)
    struct History
    {
        VectorField velocity;       // U(j)
        ScalarField emission;       // coarse emission estimate injected at step j
        ScalarField targetDensity;  // up-sampled later when a look-back starts here, and bounds the emission
        double elapsed = 0.0;       // time from frame j to the next processed frame (set when it arrives)
    };
    std::deque<History> history;    // LookBack mode: the last m frames

    void start(const Frame& target, int f)
    {
        ratio = f;
        targetLattice = target.velocity.lattice();
        setBox(target.velocity.bbox());
        globalPatch = s.globalPatch > 0 ? s.globalPatch : 2 * ((s.localPatch + f - 1) / f) + 1;
        if (globalPatch % 2 == 0) ++globalPatch;
        if (double(globalPatch) * f <= double(s.localPatch))
            throw ValueError("global patch b = " + std::to_string(globalPatch) + " coarse voxels does not exceed the local patch (b must be > B*dX/dx = " +
                             std::to_string(double(s.localPatch) / f) + ")");
        started = true;
    }

    // The frame's boxes and patch layout; patches sit on the absolute lattice of multiples of B.
    void setBox(const CoordBBox& box)
    {
        const int B = s.localPatch;
        targetBox = box;
        fineBox = refineBox(targetBox, ratio);
        const Coord lo(floorDiv(fineBox.min().x(), B) * B, floorDiv(fineBox.min().y(), B) * B,
            floorDiv(fineBox.min().z(), B) * B);
        layout = PatchLayout::covering(CoordBBox(lo, fineBox.max()), B);
        tracked.assign(layout.patchCount(), 0);
        match.assign(layout.patchCount(), Coord(0));
        for (const auto& [P, m] : tracks) {
            const Coord rel = P - Coord(lo.x() / B, lo.y() / B, lo.z() / B);
            if (rel.x() < 0 || rel.y() < 0 || rel.z() < 0 || rel.x() >= layout.count.x() || rel.y() >= layout.count.y() ||
                rel.z() >= layout.count.z())
                continue;
            tracked[layout.patchIndex(rel)] = 1;
            match[layout.patchIndex(rel)] = m;
        }
    }

    Coord absolutePatch(size_t p) const
    {
        const Coord P(int(p / (size_t(layout.count.y()) * size_t(layout.count.z()))),
            int((p / size_t(layout.count.z())) % size_t(layout.count.y())), int(p % size_t(layout.count.z())));
        return P + Coord(layout.origin.x() / s.localPatch, layout.origin.y() / s.localPatch, layout.origin.z() / s.localPatch);
    }

    TransferResult process(const Frame& target, const Frame& sourceIn, Progress* progress);
};

int transferRatio(double targetVoxel, double sourceVoxel, bool resampleSource)
{
    // A non-integer ratio (e.g. 2.5) is met by resampling the source trilinearly to the nearest integer
    // ratio: the source is an exemplar library, so a slightly rescaled exemplar is still a valid one.
    const int f = resampleSource ? nearestRatio(targetVoxel, sourceVoxel) : integerRatio(targetVoxel, sourceVoxel);
    // At f = 1 there is no band above the target's Nyquist to transfer (and a ratio of 1.2 would round
    // to it): refuse rather than run the search on empty detail.
    if (f < 2) {
        std::ostringstream os;
        os << "resolution ratio " << targetVoxel << " / " << sourceVoxel << " = " << targetVoxel / sourceVoxel
           << " leaves no detail to transfer: the source needs voxels at most half the target's";
        throw ValueError(os.str());
    }
    return f;
}

TurbulenceTransfer::TurbulenceTransfer(const TransferSettings& settings) : mImpl(std::make_unique<Impl>())
{
    const TransferSettings& s = settings;
    if (s.localPatch < 2) throw ValueError("local patch size must be >= 2");
    if (s.alpha < 0 || s.beta < 0 || s.seams.gamma < 0) throw ValueError("alpha, beta and gamma must be >= 0");
    if (s.localStride < 1 || s.refineCandidates < 1 || s.pcaComponents < 1)
        throw ValueError("stride, candidates and PCA components must be >= 1");
    if (s.densityMode == DensityMode::LookBack && s.lookBackFrames < 1)
        throw ValueError("look-back needs at least one frame");
    if (!(s.temporalBlend >= 0.0f && s.temporalBlend <= 0.999f)) throw ValueError("temporal blend must lie in [0, 0.999]");
    if (!(s.coarseTolerance >= 0.0f)) throw ValueError("coarse tolerance must be >= 0");
    if (!(s.seams.boxKeep >= 0.0f && s.seams.boxKeep <= 1.0f)) throw ValueError("box keep must lie in [0, 1]");
    mImpl->s = settings;
    mImpl->w = detail::MatchWeights{s.alpha, s.beta, s.densityThreshold};
}

TurbulenceTransfer::~TurbulenceTransfer() = default;
TurbulenceTransfer::TurbulenceTransfer(TurbulenceTransfer&&) noexcept = default;
TurbulenceTransfer& TurbulenceTransfer::operator=(TurbulenceTransfer&&) noexcept = default;

const TransferSettings& TurbulenceTransfer::settings() const { return mImpl->s; }

TransferResult TurbulenceTransfer::process(const Frame& target, const Frame& source, Progress* progress)
{
    TransferResult r;
    withThreads(mImpl->s.threads, [&] { r = mImpl->process(target, source, progress); });
    return r;
}

TransferResult TurbulenceTransfer::Impl::process(const Frame& target, const Frame& sourceArg, Progress* progress)
{
    const auto tTotal = Clock::now();
    requireFrame(target, "target");
    requireFrame(sourceArg, "source");
    const double tv = target.velocity.lattice().voxelSize, sv = sourceArg.velocity.lattice().voxelSize;
    const int f = transferRatio(tv, sv, s.resampleSource);
    const bool resampleSource = !isIntegerRatio(tv, sv);
    Frame resampledSource;
    if (resampleSource) resampledSource = resampledToVoxel(sourceArg, tv / f);
    const Frame& sourceIn = resampleSource ? resampledSource : sourceArg;
    if (!started) start(target, f);
    if (f != ratio || !target.velocity.lattice().approxEqual(targetLattice))
        throw ValueError("target frame " + std::to_string(target.number) +
                         " changed voxel size or transform within the sequence");
    setBox(target.velocity.bbox()); // also loads this frame's view of the patch tracks
    // Every temporal step below (density and detail advection, the emission estimate, the temporal blend) spans
    // the real time since the previous processed frame, not one frame's.
    const double elapsed = havePrevious ? elapsedTime(prevNumber, prevDt, target.number, target.dt) : 0.0;
    const int frameGap = havePrevious ? target.number - prevNumber : 1;
    if (!history.empty()) history.back().elapsed = elapsed;

    TransferResult result;
    TransferStats& st = result.stats;
    st.ratio = f;
    st.sourceRatio = tv / sv;
    st.sourceResampled = resampleSource;
    const int B = s.localPatch;
    const Lattice fineLattice = targetLattice.refined(f);

    // --- Target at output resolution -----------------------------------------------------------
    if (progress) progress->begin("split");
    auto t0 = Clock::now();
    const VectorField Ut = upsample(target.velocity, f);
    const ScalarField Dt = upsample(target.density, f);

    // Emission estimate for density: what the target gained that advection does not explain.
    ScalarField emission(target.density.bbox(), targetLattice);
    if (havePrevious) {
        const ScalarField previous = cropped(prevTargetDensity, target.density.bbox());
        emission = estimateSources(&previous, target.density, prevTargetVelocity, elapsed);
    }
    st.seconds[0] = since(t0);

    // --- Output density. It needs only past velocities, so it is known before this frame's detail, and
    // the detail can cover all the smoke the output will show (high-res advection carries smoke
    // beyond the target's own).
    if (progress) progress->begin("density");
    t0 = Clock::now();
    ScalarField outDensity;
    if (s.densityMode == DensityMode::Advect) {
        if (!havePrevious) {
            outDensity = Dt;
        } else {
            outDensity = cropped(advect(prevDensity, prevVelocity, elapsed), fineBox);
            addBoundedEmission(outDensity, upsample(emission, f), Dt);
        }
    } else {
        // Seed 003, pseudocode 4: start from the target's density m frames back and advect it through
        // the output velocities since, injecting the target's emission on the way.
        if (history.empty()) {
            outDensity = Dt;
        } else {
            outDensity = cropped(upsample(history.front().targetDensity, f), fineBox);
            for (size_t j = 0; j < history.size(); ++j) {
                outDensity = advect(outDensity, history[j].velocity, history[j].elapsed);
                const bool last = j + 1 == history.size();
                const ScalarField& em = last ? emission : history[j + 1].emission;
                addBoundedEmission(outDensity, cropped(upsample(em, f), fineBox),
                    last ? Dt : cropped(upsample(history[j + 1].targetDensity, f), fineBox));
            }
        }
    }
    {
        DensityGuideSettings g = s.densityGuide;
        g.threshold = s.densityThreshold;
        const DensityGuideStats gs = guideDensity(outDensity, target.density, f, g);
        st.densityErrBefore = gs.errorBefore;
        st.densityErr = gs.errorAfter;
    }
    st.seconds[6] = since(t0);
    t0 = Clock::now();

    const size_t smokeVoxels = smokeCount(outDensity, s.densityThreshold);
    const auto meanSmokeEnergy = [&](const VectorField& u, const VectorField* less = nullptr) {
        return smokeVoxels ? smokeEnergy(u, outDensity, s.densityThreshold, less) / double(smokeVoxels) : 0.0;
    };

    // Per-patch smoke test: the patches eq. 2 runs for.
    std::vector<uint8_t> active(layout.patchCount(), 0);
    for (size_t n = 0; n < Dt.size(); ++n)
        if (Dt.data()[n] > s.densityThreshold || outDensity.data()[n] > s.densityThreshold)
            active[layout.patchIndex(layout.patchOf(Dt.coordOf(n)))] = 1;
    st.localPatches = int(std::count(active.begin(), active.end(), uint8_t(1)));

    VectorField detail(fineBox, fineLattice);
    VectorField advectedDetail; // U_h(i-1) advected through u_t(i-1); empty on a first frame
    double referenceEnergy = 0.0; // mean |U_h|^2 per smoke voxel the detail is calibrated to
    detail::MatchWeights w = this->w;
    if (st.localPatches == 0) {
        // Defined no-op: no smoke in the target, nothing to match. Tracks restart when smoke appears.
        result.empty = true;
        std::fill(tracked.begin(), tracked.end(), 0);
        tracks.clear();
    } else {
        // --- Source: alignment, frequency split, masks --------------------------------------------
        VectorField Us = sourceIn.velocity;
        ScalarField Ds = sourceIn.density;
        if (!anySmoke(Ds, s.densityThreshold))
            throw ValueError("the source frame " + std::to_string(sourceIn.number) + " holds no smoke above the density threshold");
        const bool rotate = s.alignment == FlowAlignment::Rotate || s.alignment == FlowAlignment::Both;
        const bool normalize = s.alignment == FlowAlignment::Normalize || s.alignment == FlowAlignment::Both;
        Vec3d meanT, meanS;
        double rmsT = 0, rmsS = 0;
        detail::smokeFlowStats(target.velocity, target.density, s.densityThreshold, meanT, rmsT);
        if (rotate && !rotationChosen) {
            detail::smokeFlowStats(Us, Ds, s.densityThreshold, meanS, rmsS);
            // Chosen once per sequence, so the source does not flip between frames.
            rotation = detail::bestRotation(meanS, meanT);
            rotationChosen = true;
        }
        if (rotate && !rotation.isIdentity()) {
            Us = rotated(Us, rotation);
            Ds = rotated(Ds, rotation);
        }
        const detail::MatchWeights wm = w;
        FrequencySplit split = splitFrequencies(Us, f);
        // The source's high-frequency energy per smoke voxel, as quality.md's hf_ratio defines it (before
        // the coarse part below is taken out): the level --detail-energy source calibrates U_h to.
        double sourceReference = 0.0;
        {
            size_t n = 0;
            for (size_t i = 0; i < split.high.size(); ++i)
                if (Ds.data()[i] > s.densityThreshold) {
                    sourceReference += double(split.high.data()[i].lengthSqr());
                    ++n;
                }
            sourceReference = n ? sourceReference / double(n) : 0.0;
        }
        if (s.removeCoarseDetail) {
            // U_sh still has box means where the coarse flow is sharp (trilinear up-sampling is not the
            // inverse of box averaging). Those belong to the coarse motion, which is the target's to give:
            // transfer only the part of the source's detail that is invisible at the target's resolution.
            const VectorField c = detail::coarsePart(split.high, f);
            const VectorField cu = cropped(upsample(c, f), split.high.bbox());
            for (size_t n = 0; n < split.high.size(); ++n) {
                split.high.data()[n] -= cu.data()[n];
                split.low.data()[n] += cu.data()[n];
            }
        }
        const ScalarField ds = boxDownsample(Ds, f);
        // Velocity scale into matching units. Grid units (coarse cells per frame) by default; with
        // normalisation, units of each sequence's RMS speed.
        const double dxS = sourceIn.velocity.lattice().voxelSize * f;
        float kt = float(target.dt / targetLattice.voxelSize);
        float ks = float(sourceIn.dt / dxS);
        if (normalize) {
            detail::smokeFlowStats(split.coarse, ds, s.densityThreshold, meanS, rmsS);
            if (rmsT > 0 && rmsS > 0) {
                kt = float(1.0 / rmsT);
                ks = float(1.0 / rmsS);
            }
        }
        const float detailScale = ks / kt; // U_sh (source world units) -> output world units
        sourceReference *= double(detailScale) * double(detailScale);
        st.seconds[0] += since(t0);

        // --- Previous detail advected through the target velocity (the beta term) ---------------
        t0 = Clock::now();
        if (havePrevious && (s.beta > 0.0f || s.temporalBlend > 0.0f)) {
            AdvectSettings a;
            // BFECC: with temporal blending this detail is most of the next frame's, and first-order
            // advection would blur it a little more every frame.
            a.scheme = s.temporalBlend > 0.0f ? AdvectSettings::Scheme::BFECC : AdvectSettings::Scheme::SemiLagrangian;
            advectedDetail = cropped(advect(prevDetail, prevTargetVelocity, elapsed, a), fineBox);
        }
        st.seconds[8] = since(t0);

        // --- Global search (eq. 1), only where smoke newly entered a patch -------------------------
        if (progress) progress->begin("global search");
        t0 = Clock::now();
        std::vector<Coord> regionCentre(layout.patchCount(), Coord(0)); // fine source voxel
        std::vector<size_t> needGlobal;
        for (size_t p = 0; p < active.size(); ++p) {
            if (!active[p]) continue;
            if (s.trackGlobalPatches && tracked[p]) {
                regionCentre[p] = match[p] + Coord(B / 2);
                ++st.trackedPatches;
            } else {
                needGlobal.push_back(p);
            }
        }
        st.globalSearches = int(needGlobal.size());
        if (!needGlobal.empty()) {
            detail::GlobalIndex gindex;
            gindex.build(split.coarse, ds, globalPatch, ks, wm, s.pcaComponents);
            if (gindex.empty()) throw ValueError("the source has no smoke to match against");
            const size_t dim = detail::globalDescriptorSize(globalPatch);
            parallelFor(needGlobal.size(), 16, [&](size_t b, size_t e) {
                std::vector<float> desc(dim);
                for (size_t i = b; i < e; ++i) {
                    const size_t p = needGlobal[i];
                    const Coord P = Coord(int(p / (size_t(layout.count.y()) * size_t(layout.count.z()))),
                        int((p / size_t(layout.count.z())) % size_t(layout.count.y())), int(p % size_t(layout.count.z())));
                    const Coord centreFine = layout.patchBox(P).min() + Coord(B / 2);
                    const Coord c(floorDiv(centreFine.x(), f), floorDiv(centreFine.y(), f), floorDiv(centreFine.z(), f));
                    detail::globalDescriptor(target.velocity, target.density, c, globalPatch, kt, wm, desc.data());
                    const Coord q = gindex.nearest(desc.data());
                    regionCentre[p] = Coord(q.x() * f + f / 2, q.y() * f + f / 2, q.z() * f + f / 2);
                }
            });
        }
        st.seconds[1] = since(t0);

        // --- Local search (eq. 2) inside the global region -----------------------------------------
        if (progress) progress->begin("local search");
        t0 = Clock::now();
        detail::LocalCandidates cands;
        cands.build(split.low, Ds, B, s.localStride, ks, wm, s.pcaComponents);
        if (cands.count() == 0) throw ValueError("the source has no local patch holding smoke");
        const int radius = std::max(0, (globalPatch * f - B) / 2);
        const size_t rk = cands.pca().outputDim();
        const size_t ldim = detail::localDescriptorSize(B);
        const CoordBBox corners = cands.cornerBox();
        const int stride = cands.stride();
        std::vector<Coord> chosen(layout.patchCount(), Coord(0));
        std::vector<double> chosenEnergy(layout.patchCount(), 0.0);
        std::vector<size_t> activeList;
        for (size_t p = 0; p < active.size(); ++p)
            if (active[p]) activeList.push_back(p);

        // Full-resolution E_h of a target patch against a source corner (eq. 2).
        const auto energy = [&](const Coord& tCorner, const Coord& sCorner, bool temporal) {
            double e = 0.0;
            for (int x = 0; x < B; ++x)
                for (int y = 0; y < B; ++y)
                    for (int z = 0; z < B; ++z) {
                        const Coord tv = tCorner + Coord(x, y, z);
                        if (!fineBox.isInside(tv)) continue;
                        const Coord sv = sCorner + Coord(x, y, z);
                        const Vec3f du = Ut[tv] * kt - split.low[sv] * ks;
                        const float dm = float(Dt[tv] > s.densityThreshold) - float(Ds[sv] > s.densityThreshold);
                        e += double(du.lengthSqr()) + double(s.alpha) * double(dm * dm);
                        if (temporal) {
                            const Vec3f dh = advectedDetail[tv] * kt - split.high[sv] * ks;
                            e += double(s.beta) * double(dh.lengthSqr());
                        }
                    }
            return e;
        };

        parallelFor(activeList.size(), 8, [&](size_t b, size_t e) {
            std::vector<float> desc(ldim), red(rk);
            std::vector<std::pair<float, Coord>> best;
            for (size_t i = b; i < e; ++i) {
                const size_t p = activeList[i];
                const Coord P = Coord(int(p / (size_t(layout.count.y()) * size_t(layout.count.z()))),
                    int((p / size_t(layout.count.z())) % size_t(layout.count.y())), int(p % size_t(layout.count.z())));
                const Coord tCorner = layout.patchBox(P).min();
                detail::localDescriptor(Ut, Dt, tCorner, B, kt, wm, desc.data());
                cands.pca().project(desc.data(), red.data());
                best.clear();
                // Candidate corners on the stride lattice within the global region; widen the region
                // if it holds no smoke-bearing candidate (e.g. at the edge of the source's smoke).
                for (int grow = 0; grow < 4 && best.empty(); ++grow) {
                    const int rad = radius + grow * (globalPatch * f);
                    const Coord lo = regionCentre[p] - Coord(B / 2) - Coord(rad);
                    const Coord hi = regionCentre[p] - Coord(B / 2) + Coord(rad);
                    Coord c0, c1;
                    for (int a = 0; a < 3; ++a) {
                        const int base = corners.min()[a];
                        const int l = std::max(lo[a], base), h = std::min(hi[a], corners.max()[a]);
                        c0[a] = base + ((l - base + stride - 1) / stride) * stride;
                        c1[a] = h;
                    }
                    for (int x = c0.x(); x <= c1.x(); x += stride)
                        for (int y = c0.y(); y <= c1.y(); y += stride)
                            for (int z = c0.z(); z <= c1.z(); z += stride) {
                                const float* r = cands.reduced(Coord(x, y, z));
                                if (!r) continue;
                                float d2 = 0.0f;
                                for (size_t k = 0; k < rk; ++k) {
                                    const float t = r[k] - red[k];
                                    d2 += t * t;
                                }
                                best.emplace_back(d2, Coord(x, y, z));
                            }
                }
                if (best.empty()) {
                    // The whole source lattice as a last resort (tiny sources).
                    for (int x = corners.min().x(); x <= corners.max().x(); x += stride)
                        for (int y = corners.min().y(); y <= corners.max().y(); y += stride)
                            for (int z = corners.min().z(); z <= corners.max().z(); z += stride)
                                if (const float* r = cands.reduced(Coord(x, y, z))) {
                                    float d2 = 0.0f;
                                    for (size_t k = 0; k < rk; ++k) d2 += (r[k] - red[k]) * (r[k] - red[k]);
                                    best.emplace_back(d2, Coord(x, y, z));
                                }
                }
                const size_t m = std::min(best.size(), size_t(s.refineCandidates));
                std::partial_sort(best.begin(), best.begin() + long(m), best.end(), [](const auto& a, const auto& c) {
                    if (a.first != c.first) return a.first < c.first;
                    return a.second < c.second;
                });
                best.resize(m);
                // Keep last frame's match in the running: the cheapest way to stay coherent.
                if (tracked[p] && corners.isInside(match[p])) best.emplace_back(0.0f, match[p]);
                const bool temporal = !advectedDetail.empty() && tracked[p];
                double bestE = -1.0;
                Coord bestC = best.empty() ? corners.min() : best.front().second;
                for (const auto& cand : best) {
                    const double en = energy(tCorner, cand.second, temporal);
                    if (bestE < 0.0 || en < bestE || (en == bestE && cand.second < bestC)) {
                        bestE = en;
                        bestC = cand.second;
                    }
                }
                chosen[p] = bestC;
                chosenEnergy[p] = std::max(0.0, bestE);
            }
        });
        // Coherence (beyond the paper, as in Ashikhmin's and k-coherence texture synthesis): a patch
        // takes a neighbour's continuation when it matches almost as well, so neighbouring patches come
        // from neighbouring source positions and many borders have no seam at all. Red-black sweeps keep
        // the result independent of the thread count.
        if (s.coherence > 0.0f) {
            const auto patchCoord = [&](size_t p) {
                return Coord(int(p / (size_t(layout.count.y()) * size_t(layout.count.z()))),
                    int((p / size_t(layout.count.z())) % size_t(layout.count.y())), int(p % size_t(layout.count.z())));
            };
            const bool temporalAll = !advectedDetail.empty();
            for (int sweep = 0; sweep < 2 * s.coherenceSweeps; ++sweep) {
                const int colour = sweep % 2;
                parallelFor(activeList.size(), 8, [&](size_t b, size_t e) {
                    for (size_t i = b; i < e; ++i) {
                        const size_t p = activeList[i];
                        const Coord P = patchCoord(p);
                        if (((P.x() + P.y() + P.z()) & 1) != colour) continue;
                        const Coord tCorner = layout.patchBox(P).min();
                        const bool temporal = temporalAll && tracked[p];
                        double bestE = chosenEnergy[p];
                        Coord bestC = chosen[p];
                        for (int nb = 0; nb < 6; ++nb) {
                            Coord Q = P;
                            Q[nb / 2] += (nb % 2) ? 1 : -1;
                            if (Q[nb / 2] < 0 || Q[nb / 2] >= layout.count[nb / 2]) continue;
                            const size_t q = layout.patchIndex(Q);
                            if (!active[q]) continue;
                            // The neighbour's source patch, continued across the border.
                            const Coord c = chosen[q] + (tCorner - layout.patchBox(Q).min());
                            if (!corners.isInside(c) || c == bestC) continue;
                            const double en = energy(tCorner, c, temporal);
                            if (en <= (1.0 + s.coherence) * chosenEnergy[p] && en < bestE) {
                                bestE = en;
                                bestC = c;
                            }
                        }
                        chosen[p] = bestC;
                        chosenEnergy[p] = bestE;
                    }
                });
            }
        }
        double esum = 0.0;
        for (size_t p : activeList) esum += chosenEnergy[p];
        st.meanLocalEnergy = activeList.empty() ? 0.0 : esum / double(activeList.size());
        st.seconds[2] = since(t0);

        // --- Paste U_h ---------------------------------------------------------------------------
        t0 = Clock::now();
        std::vector<Coord> offsets(layout.patchCount(), Coord(0));
        parallelFor(activeList.size(), 16, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) {
                const size_t p = activeList[i];
                const Coord P = Coord(int(p / (size_t(layout.count.y()) * size_t(layout.count.z()))),
                    int((p / size_t(layout.count.z())) % size_t(layout.count.y())), int(p % size_t(layout.count.z())));
                CoordBBox pb = layout.patchBox(P);
                pb.intersect(fineBox);
                const Coord off = chosen[p] - layout.patchBox(P).min();
                offsets[p] = off;
                for (int x = pb.min().x(); x <= pb.max().x(); ++x)
                    for (int y = pb.min().y(); y <= pb.max().y(); ++y)
                        for (int z = pb.min().z(); z <= pb.max().z(); ++z)
                            detail(x, y, z) = split.high(x + off.x(), y + off.y(), z + off.z()) * detailScale;
            }
        });
        st.seconds[3] = since(t0);
        if (s.detailEnergy == DetailEnergy::Source) {
            referenceEnergy = sourceReference;
        } else if (s.detailEnergy == DetailEnergy::Pasted) {
            referenceEnergy = meanSmokeEnergy(detail);
        }

        // Temporal coherence beyond eq. 2's beta term: where a patch already carried detail last frame,
        // mix in that detail advected through the target, so the turbulence moves with the flow instead
        // of being re-pasted every frame. Done before the seam solve, whose gradient targets blend the
        // same way, so its divergence term also cleans up what the advection distorted.
        // The energy log is for a progress reporter only: four passes over the field are not free.
        std::ostringstream energyLog;
        if (progress) {
            energyLog << "detail energy per smoke voxel: pasted " << meanSmokeEnergy(detail);
            if (!advectedDetail.empty()) energyLog << ", advected previous " << meanSmokeEnergy(advectedDetail);
        }
        // Per-patch weights: lambda where the patch carried detail last frame; where smoke has just
        // arrived, only as much as the detail advected into it (relative rms against the pasted detail),
        // so detail that flowed in keeps moving instead of being replaced.
        std::vector<float> blendWeight;
        // The blend's memory is in frames: over a gap of k frames the carried detail keeps lambda^k.
        const float lambda = (!advectedDetail.empty()) ? float(std::pow(double(s.temporalBlend), frameGap)) : 0.0f;
        if (lambda > 0.0f) {
            blendWeight.assign(layout.patchCount(), 0.0f);
            parallelFor(activeList.size(), 16, [&](size_t b, size_t e) {
                for (size_t i = b; i < e; ++i) {
                    const size_t p = activeList[i];
                    if (tracked[p]) {
                        blendWeight[p] = lambda;
                        continue;
                    }
                    CoordBBox pb = layout.patchBox(layout.patchCoord(p));
                    pb.intersect(fineBox);
                    double ea = 0.0, ep = 0.0;
                    for (auto it = pb.begin(); it; ++it) {
                        ea += double(advectedDetail[*it].lengthSqr());
                        ep += double(detail[*it].lengthSqr());
                    }
                    blendWeight[p] = ep > 0.0 ? float(lambda * std::min(1.0, std::sqrt(ea / ep))) : lambda;
                }
            });
            parallelFor(detail.size(), 1 << 14, [&](size_t b, size_t e) {
                for (size_t n = b; n < e; ++n) {
                    const float w = blendWeight[layout.patchIndex(layout.patchOf(detail.coordOf(n)))];
                    if (w > 0.0f) detail.data()[n] = detail.data()[n] * (1.0f - w) + advectedDetail.data()[n] * w;
                }
            });
        }

        // --- Seam smoothing (section 3.3) ---------------------------------------------------------
        if (progress) progress->begin("seams");
        t0 = Clock::now();
        // The coarse part goes down to the tolerance before the solve: taking out a trilinear field adds
        // divergence, which the solve's gamma term then removes while its box rows hold the means. Both
        // that tolerance and the solve's target-divergence term need the energy factor (step 10) this frame
        // will get: estimated here from the detail without its coarse part.
        VectorField coarse;
        if (s.removeCoarseDetail) coarse = upsample(detail::coarsePart(detail, f), f);
        double scaleEstimate = 1.0;
        if (s.detailEnergy != DetailEnergy::None && referenceEnergy > 0.0)
            scaleEstimate = energyFactor(referenceEnergy, meanSmokeEnergy(detail, coarse.empty() ? nullptr : &coarse));
        if (!coarse.empty()) {
            const double lf = scaleEstimate * detail::coarseRatio(coarse, Ut, target.density, s.densityThreshold, f);
            const float remove = float(1.0 - keptFraction(lf, s.coarseTolerance));
            for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] -= coarse.data()[n] * remove;
        }
        SeamProblem problem;
        problem.sourceHigh = &split.high;
        problem.sourceScale = detailScale;
        problem.layout = layout;
        problem.active = active;
        problem.offset = offsets;
        if (s.compensateTargetDivergence) {
            problem.base = &Ut;
            // The energy factor scales U_h after the solve, and a compensation of the target's divergence
            // scaled with it would overshoot (by 2x at the bound of 3 on first frames).
            problem.baseScale = float(1.0 / scaleEstimate);
        }
        if (s.removeCoarseDetail) problem.boxFactor = f;
        if (lambda > 0.0f) {
            problem.temporal = &advectedDetail;
            problem.temporalWeights = blendWeight;
        }
        if (s.solveFreshPatchesWhole) {
            problem.wholePatches.assign(layout.patchCount(), 0);
            for (size_t p = 0; p < layout.patchCount(); ++p)
                problem.wholePatches[p] = active[p] && (blendWeight.empty() || blendWeight[p] == 0.0f);
        }
        SeamSettings seamSettings = s.seams;
        if (seamSettings.boundaryPatch <= 0) seamSettings.boundaryPatch = B % 2 == 0 ? B : B + 1;
        if (progress) energyLog << ", blended " << meanSmokeEnergy(detail);
        st.seams = smoothSeams(detail, problem, seamSettings, progress);
        if (progress) {
            energyLog << ", after seams " << meanSmokeEnergy(detail);
            progress->note(energyLog.str());
        }
        st.seconds[4] = since(t0);

        // Update tracks.
        tracks.clear();
        for (size_t p = 0; p < active.size(); ++p)
            if (active[p]) tracks[absolutePatch(p)] = chosen[p];
    }

    // --- Output velocity: U = up(u_t) + U_h ---------------------------------------------------------
    t0 = Clock::now();
    VectorField coarseDetail; // the smooth part of U_h with U_h's coarse-cell means
    if (s.removeCoarseDetail && !result.empty) {
        coarseDetail = upsample(detail::coarsePart(detail, f), f);
        for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] -= coarseDetail.data()[n];
    }
    if (s.detailEnergy != DetailEnergy::None && referenceEnergy > 0.0 && !result.empty) {
        st.energyScale = energyFactor(referenceEnergy, meanSmokeEnergy(detail));
        for (auto& v : detail.values()) v *= float(st.energyScale);
    }
    if (!coarseDetail.empty()) {
        // Put back as much of the coarse part as the tolerance allows, measured as lf_err measures it:
        // the coarse part's box means against the up-sampled target's, over the target's smoke cells. A
        // target at rest there leaves no relative budget: the coarse part goes entirely.
        const double lf = st.energyScale * detail::coarseRatio(coarseDetail, Ut, target.density, s.densityThreshold, f);
        st.coarseKept = keptFraction(lf, s.coarseTolerance);
        st.lfErr = st.coarseKept > 0.0 ? lf * st.coarseKept : 0.0;
        const float k = float(st.coarseKept * st.energyScale);
        if (k > 0.0f)
            for (size_t n = 0; n < detail.size(); ++n) detail.data()[n] += coarseDetail.data()[n] * k;
    } else if (!result.empty) {
        st.coarseKept = 1.0;
        const double lf = detail::coarseRatio(detail, Ut, target.density, s.densityThreshold, f);
        st.lfErr = std::isfinite(lf) ? lf : 0.0;
    }
    if (!advectedDetail.empty() && !result.empty) {
        double change = 0.0, now = 0.0, before = 0.0;
        for (size_t n = 0; n < detail.size(); ++n) {
            if (!(outDensity.data()[n] > s.densityThreshold)) continue;
            change += double((detail.data()[n] - advectedDetail.data()[n]).lengthSqr());
            now += double(detail.data()[n].lengthSqr());
            before += double(advectedDetail.data()[n].lengthSqr());
        }
        // Without carried detail (after an empty frame) there is nothing to compare with.
        if (now > 0.0 && before > 0.0) {
            st.detailChange = std::sqrt(change / now);
            st.detailGrowth = std::sqrt(now / before);
        }
    }
    Frame out;
    out.number = target.number;
    out.dt = target.dt;
    out.velocity = VectorField(fineBox, fineLattice);
    for (size_t n = 0; n < out.velocity.size(); ++n) out.velocity.data()[n] = Ut.data()[n] + detail.data()[n];
    if (target.temperature) out.temperature = upsample(*target.temperature, f);
    if (target.flame) out.flame = upsample(*target.flame, f);
    st.seconds[5] = since(t0);

    out.density = std::move(outDensity);
    if (s.densityMode == DensityMode::LookBack) {
        history.push_back(History{out.velocity, emission, target.density, 0.0});
        while (int(history.size()) > s.lookBackFrames) history.pop_front();
    }

    // --- Carry state -------------------------------------------------------------------------------
    // The carried detail is recomputed from the output velocity, exactly as restore() must do from the
    // written file, so a --resume continues bit-identically.
    prevDetail = VectorField(fineBox, fineLattice);
    for (size_t n = 0; n < prevDetail.size(); ++n) prevDetail.data()[n] = out.velocity.data()[n] - Ut.data()[n];
    prevTargetVelocity = target.velocity;
    prevTargetDensity = target.density;
    prevDensity = out.density;
    prevVelocity = out.velocity;
    prevDt = target.dt;
    prevNumber = target.number;
    havePrevious = true;

    std::ostringstream meta;
    out.metadata["vdbturb_patch_size"] = std::to_string(B);
    out.metadata["vdbturb_ratio"] = std::to_string(f);
    out.metadata["vdbturb_global_patch"] = std::to_string(globalPatch);
    out.metadata["vdbturb_patch_origin"] = std::to_string(layout.origin.x()) + "," + std::to_string(layout.origin.y()) + "," +
                                           std::to_string(layout.origin.z());
    meta << s.alpha;
    out.metadata["vdbturb_alpha"] = meta.str();
    meta.str("");
    meta << s.beta;
    out.metadata["vdbturb_beta"] = meta.str();
    meta.str("");
    meta << s.seams.gamma;
    out.metadata["vdbturb_gamma"] = meta.str();
    st.seconds[7] = since(tTotal);
    result.frame = std::move(out);
    return result;
}

std::string TurbulenceTransfer::saveState() const
{
    const Impl& m = *mImpl;
    std::ostringstream os;
    os << "v2 f=" << m.ratio << " B=" << m.s.localPatch << " rot=" << (m.rotationChosen ? m.rotation.id() : -1)
       << " tracks=";
    bool first = true;
    for (const auto& [P, c] : m.tracks) {
        os << (first ? "" : ";") << P.x() << ',' << P.y() << ',' << P.z() << ',' << c.x() << ',' << c.y() << ',' << c.z();
        first = false;
    }
    return os.str();
}

void TurbulenceTransfer::restore(const std::string& state, const Frame& previousOutput, const Frame& previousTarget)
{
    Impl& m = *mImpl;
    requireFrame(previousTarget, "previous target");
    if (!previousOutput.hasVelocity() || !previousOutput.hasDensity())
        throw ValueError("the previous output frame has no velocity or density to resume from");
    std::istringstream is(state);
    std::string version, fField, bField, rotField, tracks;
    is >> version >> fField >> bField >> rotField >> tracks;
    if (version != "v2" || fField.rfind("f=", 0) != 0 || bField.rfind("B=", 0) != 0 || rotField.rfind("rot=", 0) != 0 ||
        tracks.rfind("tracks=", 0) != 0)
        throw ValueError("unrecognised transfer state in the previous output: '" + state.substr(0, 60) + "'");
    // The state comes from a file: a damaged one is refused, never a crash (tests/fuzz/fuzz_resume_state.cc).
    const auto number = [&](const std::string& text, long long lo, long long hi) {
        char* end = nullptr;
        errno = 0;
        const long long v = std::strtoll(text.c_str(), &end, 10);
        if (text.empty() || *end != '\0' || errno == ERANGE || v < lo || v > hi)
            throw ValueError("damaged transfer state in the previous output: '" + text.substr(0, 40) + "' is not a number in [" +
                             std::to_string(lo) + ", " + std::to_string(hi) + "]");
        return int(v);
    };
    const int f = number(fField.substr(2), 1, 256);
    if (!previousOutput.velocity.lattice().approxEqual(previousTarget.velocity.lattice().refined(f)))
        throw ValueError("the previous output's voxel is not the target's / " + std::to_string(f) + " as its state says");
    const int B = number(bField.substr(2), 2, 1024);
    if (B != m.s.localPatch)
        throw ValueError("the previous output used local patch " + std::to_string(B) + ", not " + std::to_string(m.s.localPatch));
    const int rot = number(rotField.substr(4), -1, 1 << 20);
    if (rot >= 0) {
        m.rotation = detail::AxisRotation::fromId(rot);
        m.rotationChosen = true;
    }
    m.tracks.clear();
    std::stringstream ts(tracks.substr(7));
    std::string item;
    while (std::getline(ts, item, ';')) {
        if (item.empty()) continue;
        int v[6];
        char sep;
        std::istringstream one(item);
        bool ok = bool(one >> v[0]);
        for (int k = 1; k < 6 && ok; ++k) ok = bool(one >> sep >> v[k]) && sep == ',';
        // Patch and source coordinates far beyond any lattice would overflow the search arithmetic.
        for (int k = 0; k < 6 && ok; ++k) ok = std::abs(v[k]) < (1 << 24);
        if (!ok) throw ValueError("damaged transfer state entry '" + item.substr(0, 60) + "'");
        m.tracks[Coord(v[0], v[1], v[2])] = Coord(v[3], v[4], v[5]);
    }
    m.start(previousTarget, f);
    const VectorField velocity = cropped(previousOutput.velocity, m.fineBox);
    const VectorField Ut = upsample(previousTarget.velocity, f);
    m.prevDetail = VectorField(m.fineBox, m.targetLattice.refined(f));
    for (size_t i = 0; i < velocity.size(); ++i) m.prevDetail.data()[i] = velocity.data()[i] - Ut.data()[i];
    m.prevTargetVelocity = previousTarget.velocity;
    m.prevTargetDensity = previousTarget.density;
    m.prevVelocity = velocity;
    m.prevDensity = cropped(previousOutput.density, m.fineBox);
    m.prevDt = previousTarget.dt;
    m.prevNumber = previousTarget.number;
    m.havePrevious = true;
    m.history.clear();
}

} // namespace turb
