// Masked, tiled, deterministic PatchMatch (Barnes et al. 2009, 2010).
#include <turb/PatchMatch.h>

#include <turb/Error.h>
#include <turb/Parallel.h>

#include "Search.h"

#include <algorithm>
#include <limits>
#include <string>

namespace turb {

void validatePatchSpace(const PatchSpace& s)
{
    if (!s.source || !s.target || !s.weights) throw ValueError("patch space: source, target and weights must be set");
    if (s.source->empty() || s.target->empty()) throw ValueError("patch space: empty image");
    if (s.source->channels() != s.target->channels() || s.weights->channels() != s.target->channels())
        throw ValueError("patch space: source, target and weights must have the same channels (" +
                         std::to_string(s.source->channels()) + ", " + std::to_string(s.target->channels()) + ", " +
                         std::to_string(s.weights->channels()) + ")");
    if (!s.weights->sameSize(*s.target)) throw ValueError("patch space: weights must have the target's size");
    if (s.radius < 1) throw ValueError("patch space: radius must be >= 1");
}

Labels centreLabels(const std::vector<std::int8_t>& segment, int width, int height, int radius)
{
    if (segment.size() != size_t(width) * size_t(height)) throw ValueError("centreLabels: segment size mismatch");
    Labels out(segment.size(), -1);
    for (int y = radius; y < height - radius; ++y)
        for (int x = radius; x < width - radius; ++x)
            out[size_t(y) * size_t(width) + size_t(x)] = segment[size_t(y) * size_t(width) + size_t(x)];
    return out;
}

Nnf emptyNnf(int width, int height)
{
    Nnf n;
    n.width = width;
    n.height = height;
    n.source.assign(size_t(width) * size_t(height), -1);
    n.distance.assign(n.source.size(), std::numeric_limits<float>::infinity());
    return n;
}

namespace {

void checkLabels(const PatchSpace& s, const Labels& src, const Labels& tgt)
{
    validatePatchSpace(s);
    if (src.size() != s.source->pixelCount() || tgt.size() != s.target->pixelCount())
        throw ValueError("patch match: labels must have one entry per pixel");
    // Labels are trusted to mark whole-patch centres only: check the borders once.
    const auto borderOk = [&](const Labels& l, const ChannelImage& img) {
        for (int y = 0; y < img.height(); ++y)
            for (int x = 0; x < img.width(); ++x)
                if (l[img.index(x, y)] >= 0 &&
                    (x < s.radius || y < s.radius || x >= img.width() - s.radius || y >= img.height() - s.radius))
                    return false;
        return true;
    };
    if (!borderOk(src, *s.source) || !borderOk(tgt, *s.target))
        throw ValueError(
            "patch match: a labelled centre lies closer than the patch radius to the border (use centreLabels)");
}

std::vector<std::vector<std::int32_t>> centresByLabel(const Labels& labels)
{
    std::vector<std::vector<std::int32_t>> lists;
    for (size_t i = 0; i < labels.size(); ++i) {
        const int L = labels[i];
        if (L < 0) continue;
        if (size_t(L) >= lists.size()) lists.resize(size_t(L) + 1);
        lists[size_t(L)].push_back(std::int32_t(i));
    }
    return lists;
}

} // namespace

void patchMatch(const PatchSpace& space, const Labels& sourceLabels, const Labels& targetLabels,
    const PatchMatchSettings& settings, Nnf& nnf, Progress* progress)
{
    checkLabels(space, sourceLabels, targetLabels);
    if (settings.iterations < 1 || settings.randomCentres < 0) throw ValueError("patch match: iterations must be >= 1");
    const ChannelImage& T = *space.target;
    if (nnf.width != T.width() || nnf.height != T.height() || nnf.source.size() != T.pixelCount())
        nnf = emptyNnf(T.width(), T.height());
    const auto lists = centresByLabel(sourceLabels);
    std::vector<char> active(T.pixelCount());
    for (size_t q = 0; q < active.size(); ++q) {
        active[q] = targetLabels[q] >= 0;
        if (!active[q]) {
            nnf.source[q] = -1;
            nnf.distance[q] = std::numeric_limits<float>::infinity();
        }
    }
    detail::SearchConfig cfg;
    cfg.qW = T.width();
    cfg.qH = T.height();
    cfg.dW = space.source->width();
    cfg.dH = space.source->height();
    cfg.iterations = settings.iterations;
    cfg.tileSize = settings.tileSize;
    cfg.randomCentres = settings.randomCentres;
    cfg.seed = settings.seed;
    const auto ok = [&](std::int32_t d, int L) { return sourceLabels[size_t(d)] == L; };
    const auto dist = [&](std::int32_t q, std::int32_t p, float cutoff) { return space.distance(p, q, cutoff); };
    detail::sweepSearch(cfg, active, targetLabels, lists, ok, dist, nnf.source, nnf.distance, progress);
}

Nnf bruteForceNnf(const PatchSpace& space, const Labels& sourceLabels, const Labels& targetLabels)
{
    checkLabels(space, sourceLabels, targetLabels);
    const ChannelImage& T = *space.target;
    Nnf nnf = emptyNnf(T.width(), T.height());
    const auto lists = centresByLabel(sourceLabels);
    parallelFor(T.pixelCount(), 64, [&](size_t b, size_t e) {
        for (size_t q = b; q < e; ++q) {
            const int L = targetLabels[q];
            if (L < 0 || size_t(L) >= lists.size()) continue;
            for (std::int32_t p : lists[size_t(L)]) {
                const float d = space.distance(p, std::int32_t(q), nnf.distance[q]);
                if (d < nnf.distance[q]) {
                    nnf.distance[q] = d;
                    nnf.source[q] = p;
                }
            }
        }
    });
    return nnf;
}

} // namespace turb
