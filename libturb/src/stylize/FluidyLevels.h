// Fluidymation's pyramid levels (exemplar and target) and the patch distance D over them. Internal.
#pragma once

#include <turb/ChannelImage.h>
#include <turb/Fluidymation.h>
#include <turb/RotatedNnf.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace turb::fluidy {

// Source voxel channels: R, G, B, shape, ext+, ext- (in extent units), flow direction x, y (unit vector
// times the confidence min(1, |flow| / eps)).
constexpr int kS = 8;
// Target pixel channels: the same 8 (R, G, B being the current synthesis), then T^temp R, G, B and the
// per-pixel temporal weight w^temp m(q).
constexpr int kT = 12;
constexpr std::int8_t kBoundary = 0, kInterior = 1;
constexpr std::uint8_t kNoDirection = 255;

/// True when direction steps a (turned by `rotation`) and b point more than 90 degrees apart.
inline bool oppositeSteps(std::uint8_t a, int rotation, std::uint8_t b)
{
    if (a == kNoDirection || b == kNoDirection) return false;
    const int d = ((int(a) + rotation - int(b)) % kRotations + kRotations) % kRotations;
    return d > kRotations / 4 && d < 3 * kRotations / 4;
}

/// One pyramid level of the exemplar: every frame, voxel v = (i H + y) W + x.
struct ExemplarLevel
{
    int W = 0, H = 0, F = 0;
    std::vector<float> feat; // F H W kS
    std::vector<std::uint8_t>
        dirStep;                    // patch-mean flow direction as a rotation step, kNoDirection where slower than eps
    std::vector<std::int8_t> label; // -1: not a patch centre; else its segment
    std::vector<std::int8_t> segment;  // every voxel's segment (Omega's normalisation)
    std::vector<std::int32_t> centres; // the voxels with label >= 0
    long long segCount[2] = {0, 0};    // |S_seg|: centres per segment
    std::vector<ChannelImage> vote;    // per frame: R, G, B, mask (voting)
    std::vector<std::int32_t> counts;  // Omega's 2D footprints per voxel
    std::vector<float> omega;          // Omega(p') = Omega*(p') / (n^2 omega*), per voxel
    std::vector<float> omegaPatch;     // sum of Omega over the n x n window centred on each voxel
    std::vector<float> scratch;        // per-voxel work space of the Omega rebuild

    size_t voxel(int i, int x, int y) const { return (size_t(i) * size_t(H) + size_t(y)) * size_t(W) + size_t(x); }
    bool isCentre(int i, int x, int y) const
    {
        return i >= 0 && i < F && x >= 0 && y >= 0 && x < W && y < H && label[voxel(i, x, y)] >= 0;
    }
    bool isCentre(const PatchRef& p) const { return isCentre(p.frame, p.x, p.y); }
    PatchRef refOf(size_t v, std::uint8_t rotation) const
    {
        PatchRef p;
        p.frame = std::int16_t(v / (size_t(W) * size_t(H)));
        const size_t r = v % (size_t(W) * size_t(H));
        p.y = std::int16_t(r / size_t(W));
        p.x = std::int16_t(r % size_t(W));
        p.rotation = rotation;
        return p;
    }
};

/// One pyramid level of the current target frame, padded by the patch radius (clamped).
struct TargetLevel
{
    int W = 0, H = 0, pad = 0;
    std::vector<float> feat;           // (W + 2 pad)(H + 2 pad) kT
    std::vector<std::uint8_t> dirStep; // W H: patch-mean flow direction as a rotation step, or kNoDirection
    std::vector<std::int8_t> label;    // W H: -1 not a centre, else its segment
    long long segCount[2] = {0, 0};

    int paddedWidth() const { return W + 2 * pad; }
    float* at(int x, int y) { return feat.data() + (size_t(y + pad) * size_t(paddedWidth()) + size_t(x + pad)) * kT; }
    const float* at(int x, int y) const
    {
        return feat.data() + (size_t(y + pad) * size_t(paddedWidth()) + size_t(x + pad)) * kT;
    }
};

/// The settings-derived constants of D.
struct Weights
{
    float bound = 0, ext = 0, dir = 0, uni = 0, clamp = 10;
};

/// D(p, q) of eq. 2 over the level's channels, nearest-pixel samples of the rotated source patch.
struct Evaluator
{
    const ExemplarLevel* E = nullptr;
    const TargetLevel* T = nullptr;
    const RotationTable* table = nullptr;
    Weights w;
    float cosK[kRotations], sinK[kRotations];

    Evaluator(const ExemplarLevel& e, const TargetLevel& t, const RotationTable& tab, const Weights& weights)
        : E(&e), T(&t), table(&tab), w(weights)
    {
        for (int k = 0; k < kRotations; ++k) {
            cosK[k] = float(std::cos(rotationAngle(k)));
            sinK[k] = float(std::sin(rotationAngle(k)));
        }
    }

    /// True when the rotated source flow and the target flow point opposite ways (patch means).
    bool opposite(size_t q, size_t v, int rotation) const
    {
        return oppositeSteps(E->dirStep[v], rotation, T->dirStep[q]);
    }

    /// The extent part of D at the patch centres alone, unswapped or swapped: which of the two
    /// D^dir-minimising rotations (aligned, opposite) fits the motion extent better.
    float centreExtent(size_t q, int qx, int qy, size_t v, bool swap) const
    {
        const float* sp = E->feat.data() + v * kS;
        const float* tp = T->at(qx, qy);
        const float a = sp[4] - tp[swap ? 5 : 4], b = sp[5] - tp[swap ? 4 : 5];
        (void)q;
        return a * a + b * b;
    }

    /// D for target centre (qx, qy) and source patch p; stops once the sum exceeds `cutoff`.
    /// When `terms` is given, also splits the sum into its terms (no early stop).
    float operator()(int qx, int qy, const PatchRef& p, float cutoff, FluidyTerms* terms = nullptr) const
    {
        const int r = table->radius();
        const int* off = table->offsets(p.rotation);
        const float c = cosK[p.rotation], s = sinK[p.rotation];
        const size_t q = size_t(qy) * size_t(T->W) + size_t(qx);
        const size_t centre = E->voxel(p.frame, p.x, p.y);
        const bool swap = opposite(q, centre, p.rotation);
        const int plus = swap ? 5 : 4, minus = swap ? 4 : 5;
        const size_t frameBase = size_t(p.frame) * size_t(E->H) * size_t(E->W);
        const float* sf = E->feat.data();
        // Omega summed over the patch: the axis-aligned n x n window of the centre (exact at theta = 0;
        // rotated windows differ at the corners), one lookup instead of n^2.
        const float uni = w.uni * E->omegaPatch[centre];
        float acc = uni;
        double t0 = 0, t1 = 0, t2 = 0, t3 = 0, t4 = 0;
        int t = 0;
        for (int dy = -r; dy <= r; ++dy) {
            const float* tp = T->at(qx - r, qy + dy);
            float row = 0.0f;
            for (int dx = -r; dx <= r; ++dx, ++t, tp += kT) {
                const size_t v = frameBase + size_t(p.y + off[2 * t + 1]) * size_t(E->W) + size_t(p.x + off[2 * t]);
                const float* sp = sf + v * kS;
                const float d0 = sp[0] - tp[0], d1 = sp[1] - tp[1], d2 = sp[2] - tp[2];
                const float tex = d0 * d0 + d1 * d1 + d2 * d2;
                const float e0 = sp[0] - tp[8], e1 = sp[1] - tp[9], e2 = sp[2] - tp[10];
                const float temp = tp[11] * (e0 * e0 + e1 * e1 + e2 * e2);
                const float db = sp[3] - tp[3];
                const float ep = sp[4] - tp[plus], em = sp[5] - tp[minus];
                // D^dir: the source direction turned by theta against the target's; |tan| = |cross| / |dot|,
                // weighted by both confidences (h = |cross, dot|), clamped.
                const float rx = c * sp[6] - s * sp[7], ry = s * sp[6] + c * sp[7];
                const float cr = std::abs(rx * tp[7] - ry * tp[6]), dt = std::abs(rx * tp[6] + ry * tp[7]);
                const float h = std::sqrt(cr * cr + dt * dt);
                const float dir = cr >= w.clamp * dt ? w.clamp * h : h * cr / dt;
                row += tex + temp + w.bound * db * db + w.ext * (ep * ep + em * em) + w.dir * dir;
                if (terms) {
                    t0 += tex;
                    t1 += w.bound * db * db;
                    t2 += w.dir * dir;
                    t3 += w.ext * (ep * ep + em * em);
                    t4 += temp;
                }
            }
            acc += row;
            if (acc > cutoff && !terms) return acc;
        }
        if (terms) *terms = FluidyTerms{t0, t1, t2, t3, t4, uni, swap};
        return acc;
    }
};

/// The full-resolution images a level is reduced from.
struct FrameImages
{
    ChannelImage rgb;   // 3 channels (target: empty)
    ChannelImage mask;  // 1 channel, 0/1
    ChannelImage shape; // 1 channel, the blurred mask
    ChannelImage ext;   // 2 channels, in extent units
    ChannelImage flow;  // 2 channels, pixels per frame
    ChannelImage temp;  // target only: T^temp RGB (3) and w^temp m (1)
};

struct LevelRules
{
    int radius = 2;        // patch radius n / 2
    int boundaryWidth = 5; // pixels inside the mask that count as boundary
    float eps = 0.05f;     // direction confidence scale, pixels per frame
    int reach = 3;         // rotated offsets' reach: the margin a source centre needs
};

/// Fills level `level` of an exemplar from frame i's full-resolution images reduced `level` times
/// (fixed layout: feat, angle, label, segment, vote for that frame).
void fillExemplarFrame(ExemplarLevel& E, int i, const FrameImages& reduced, const LevelRules& rules);

/// A target level from the frame's images reduced `level` times; RGB starts at 0.
TargetLevel makeTargetLevel(const FrameImages& reduced, const LevelRules& rules);

/// The images reduced once more (2x2 means).
FrameImages reduced(const FrameImages& f);

/// Box mean of a 2-channel flow over the patch, as the nearest rotation step of its direction;
/// kNoDirection where its length is below eps.
std::vector<std::uint8_t> patchMeanSteps(const ChannelImage& flow, int radius, float eps);

} // namespace turb::fluidy
