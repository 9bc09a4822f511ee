// Header scans of frames and sequences: what a read will give, without reading voxels.
#include <turbio/Scan.h>

#include "ReadChecks.h"

#include <turb/Error.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>

namespace turbio {

namespace {

bool isFloatType(const std::string& t) { return t == "float" || t == "double"; }
bool isVectorType(const std::string& t) { return t == "vec3s" || t == "vec3d"; }

const GridInfo* findSelector(const std::vector<GridInfo>& grids, const std::string& selector)
{
    for (const auto& g : grids)
        if (g.selector == selector) return &g;
    return nullptr;
}

turb::Lattice latticeOf(const GridInfo& g) { return turb::Lattice{g.voxelSize, g.origin}; }

// The grids a read would use: density `d` and velocity `v` (or null), then any velocity components and extras.
struct UsedGrids
{
    std::vector<const GridInfo*> used;
    const GridInfo* d = nullptr;
    const GridInfo* v = nullptr;
};

// The grids the read picks by the options (recorded in fs as they are checked), with the read's own messages for
// missing or unusable ones.
UsedGrids chooseGrids(FrameScan& fs, const FileInfo& info, const ReadOptions& options)
{
    std::vector<std::string> names, types;
    for (const auto& g : info.grids) {
        names.push_back(g.selector);
        types.push_back(g.valueType);
    }
    const std::string listing = describeGrids(info.grids);
    if (const std::string problem = detail::noVolumeProblem(fs.path, types, listing); !problem.empty())
        throw turb::IoError(problem);
    const auto dens = resolveGrid(names, GridRole::Density, options.densityGrid);
    const auto vel = resolveGrid(names, GridRole::Velocity, options.velocityGrid);
    if (dens.empty() && (options.requireDensity || !options.densityGrid.empty()))
        throw detail::missingGrid(fs.path, GridRole::Density, options, listing, names);
    if (vel.empty() && (options.requireVelocity || !options.velocityGrid.empty()))
        throw detail::missingGrid(fs.path, GridRole::Velocity, options, listing, names);

    UsedGrids u;
    u.d = dens.empty() ? nullptr : findSelector(info.grids, dens[0]);
    u.v = vel.empty() ? nullptr : findSelector(info.grids, vel[0]);
    if (const GridInfo* d = u.d) {
        if (!isFloatType(d->valueType))
            throw turb::IoError(fs.path + ": grid '" + d->name + "' has type " + d->valueType +
                                "; a density grid must be float or double");
        if (d->gridClass == "level set") throw turb::IoError(detail::levelSetDensityMessage(fs.path, d->name));
        u.used.push_back(d);
        fs.densityGrid = d->selector;
        fs.densityActive = d->activeVoxels;
    }
    if (const GridInfo* v = u.v) {
        const bool ok = vel.size() == 3 ? isFloatType(v->valueType) : isVectorType(v->valueType);
        if (!ok)
            throw turb::IoError(fs.path + ": grid '" + v->name + "' has type " + v->valueType +
                                "; a velocity grid must be vec3s or vec3d (or three float grids name.x/.y/.z)");
        u.used.push_back(v);
        for (size_t k = 1; k < vel.size(); ++k)
            if (const GridInfo* c = findSelector(info.grids, vel[k])) u.used.push_back(c);
        fs.velocityGrid = v->selector;
        fs.velocityActive = v->activeVoxels;
    }
    if (options.readExtras)
        for (GridRole role : {GridRole::Temperature, GridRole::Flame})
            if (auto n = resolveGrid(names, role); !n.empty())
                if (const GridInfo* e = findSelector(info.grids, n[0])) u.used.push_back(e);
    if (u.used.empty()) throw detail::noRequestedGrid(fs.path, listing);
    for (const GridInfo* g : u.used)
        if (!g->supportedTransform)
            throw turb::IoError(detail::unsupportedTransformMessage(fs.path, g->name, g->mapType));
    return u;
}

// Each used grid's active box on the frame's lattice (from the header), and the bytes a dense voxel of them takes.
struct GridSpans
{
    std::vector<std::pair<std::string, turb::CoordBBox>> spans;
    double bytesPerVoxel = 0.0;
    bool densityOutside = false; // its header box says nothing of where the smoke is inside the box then
};

// The spans of the used grids, expanding fs.domain; a grid without header statistics leaves the domain unknown.
// Voxels outside Blender's simulation box are strays, which readFrame leaves out too.
GridSpans spanGrids(FrameScan& fs, const FileInfo& info, const ReadOptions& options, const UsedGrids& u,
    const std::optional<turb::CoordBBox>& simulationBox)
{
    GridSpans s;
    for (const GridInfo* g : u.used) {
        s.bytesPerVoxel += isVectorType(g->valueType) ? 12.0 : 4.0;
        if (!g->hasBBox) {
            if (g->activeVoxels != 0) fs.domainKnown = false; // no header statistics
            s.spans.emplace_back(g->name, turb::CoordBBox());
            continue;
        }
        turb::CoordBBox b = detail::boxOnLattice(g->activeBBox, latticeOf(*g), fs.lattice);
        // A staggered grid's faces on the domain's upper boundary are not voxels of the domain.
        if (info.baseResolution && g->gridClass == "staggered")
            b.intersect(turb::CoordBBox(turb::Coord(0), *info.baseResolution - turb::Coord(1)));
        if (simulationBox && !simulationBox->isInside(b)) {
            if (g == u.d) {
                s.densityOutside = true;
                const turb::Coord r = *info.baseResolution;
                if (options.strayNote)
                    options.strayNote(fs.path + ": grid '" + g->name + "' has active voxels outside Blender's simulation box " +
                                std::to_string(r.x()) + "x" + std::to_string(r.y()) + "x" + std::to_string(r.z()) +
                                " (its active box reaches " + std::to_string(b.max().x()) + "," +
                                std::to_string(b.max().y()) + "," + std::to_string(b.max().z()) +
                                "): strays, ignored: see --keep-isolated");
            }
            b.intersect(*simulationBox);
        }
        s.spans.emplace_back(g->name, b);
        fs.domain.expand(b);
    }
    return s;
}

// Cropped to the smoke, as readFrame holds it. The density's header box bounds the smoke; a box far larger than its
// voxels (stray voxels) is worth one read of the density alone, which is what readFrame will hold.
void holdSmoke(FrameScan& fs, const FileInfo& info, const ReadOptions& options, const UsedGrids& u, const GridSpans& s,
    const std::optional<turb::CoordBBox>& simulationBox)
{
    const GridInfo* d = u.d;
    fs.region.hasDensity = true;
    if (d->hasBBox && d->activeVoxels != 0) fs.region.smoke = d->activeBBox;
    if (simulationBox) fs.region.smoke.intersect(*simulationBox);
    // As readFrame: the margin reaches as far as the other grids (or Blender's domain), not the strays.
    turb::CoordBBox& others = fs.others;
    if (info.baseResolution) others = turb::CoordBBox(turb::Coord(0), *info.baseResolution - turb::Coord(1));
    for (size_t i = 0; i < u.used.size(); ++i)
        if (u.used[i] != d) others.expand(s.spans[i].second);
    const auto reach = [&] {
        turb::CoordBBox r = others;
        r.expand(fs.region.smoke);
        return r.empty() ? fs.span : r;
    };
    fs.domain = heldRegion(fs.region, reach(), options);
    const double held = double(fs.domain.volume());
    const bool tooBig = !detail::denseSizeProblem(fs.path, fs.domain, s.spans, s.bytesPerVoxel, options).empty();
    if (tooBig || s.densityOutside || (held > 1.0e6 && d->activeVoxels >= 0 && held > 64.0 * double(d->activeVoxels))) {
        fs.region = smokeRegion(fs.path, options);
        fs.regionFromVoxels = true;
        fs.domain = heldRegion(fs.region, reach(), options);
        // Outside Blender's box the note above already says it; these are strays inside it, or any cache's.
        if (!s.densityOutside && !fs.region.strays.empty() && options.strayNote)
            options.strayNote(fs.path + ": " + fs.region.describeStrays(d->name));
    }
}

// Houdini writes two grids of one name when two primitives share it: say which one is read, and how to pick
// another (readFrame reads the same one: the selector resolveGrid chose). And say when the velocity is resampled.
void noteChoices(FrameScan& fs, const FileInfo& info, const ReadOptions& options, const UsedGrids& u)
{
    const GridInfo *d = u.d, *v = u.v;
    for (const GridInfo* chosen : {d, v}) {
        if (!chosen) continue;
        const bool chosenByName = (chosen == d ? options.densityGrid : options.velocityGrid).empty();
        std::string twins;
        for (const GridInfo& g : info.grids)
            if (g.name == chosen->name && g.index != chosen->index) twins += (twins.empty() ? "" : ", ") + g.selector;
        if (!twins.empty())
            fs.timing.notes.push_back("the file has more than one grid named '" + chosen->name + "': reading #" +
                                      std::to_string(chosen->index) + " (" + chosen->selector + ")" +
                                      (chosenByName ? ", the first, as OpenVDB's readGrid does" : "") +
                                      "; the grid selector " + twins + " reads another");
    }
    if (fs.velocityVoxel > 0.0) {
        std::ostringstream note;
        note << "grid '" << v->name << "' (voxel " << v->voxelSize << ") will be resampled trilinearly onto the "
             << (d ? "density's" : "frame's") << " lattice (voxel " << fs.lattice.voxelSize << ")";
        fs.timing.notes.push_back(note.str());
    }
}

// Everything the header says about the grids a read would use; throws the read's own messages.
void resolveFrame(FrameScan& fs, const FileInfo& info, const ReadOptions& options)
{
    const UsedGrids u = chooseGrids(fs, info, options);
    const GridInfo *d = u.d, *v = u.v;
    fs.lattice = latticeOf(*u.used.front());
    if (v && !sameLattice(latticeOf(*v), fs.lattice)) fs.velocityVoxel = v->voxelSize;
    fs.domain = turb::CoordBBox();
    if (info.baseResolution) fs.domain = turb::CoordBBox(turb::Coord(0), *info.baseResolution - turb::Coord(1));
    fs.domainKnown = true;
    const std::optional<turb::CoordBBox> simulationBox =
        options.keepIsolated ? std::nullopt : detail::blenderSimulationBox(info.baseResolution, info.creator);
    std::vector<std::string> notes;
    const GridSpans s = spanGrids(fs, info, options, u, simulationBox);
    if (info.recordedDomain) fs.domain.expand(*info.recordedDomain);
    fs.sequenceDomain = info.sequenceDomain;
    if (fs.domain.empty()) fs.domain = turb::CoordBBox(turb::Coord(0), turb::Coord(0));
    fs.span = fs.domain;
    if (fs.domainKnown && d && options.cropToSmoke) holdSmoke(fs, info, options, u, s, simulationBox);
    if (fs.domainKnown) {
        detail::checkDenseSize(fs.path, fs.domain, s.spans, s.bytesPerVoxel, options);
    }
    if (detail::blenderSimulationBox(info.baseResolution, info.creator)) fs.blenderResolution = info.baseResolution;
    const bool blenderVel = v && info.baseResolution && v->name == "velocity" && v->gridClass == "staggered";
    fs.timing =
        resolveTiming(blenderVel, info.baseResolution.has_value(), info.recordedDt, options, info.recordedTimeUnit);
    fs.timing.notes = std::move(notes);
    noteChoices(fs, info, options, u);
}

} // namespace

bool sameLattice(const turb::Lattice& a, const turb::Lattice& b) { return a.approxEqual(b); }

FrameScan scanFrame(const std::string& path, int frame, const ReadOptions& options, bool readVoxelsIfNeeded)
{
    FrameScan fs;
    fs.frame = frame;
    fs.path = path;
    try {
        FileInfo info = inspectFile(path, false);
        fs.grids = info.grids;
        resolveFrame(fs, info, options);
        if (!fs.domainKnown && readVoxelsIfNeeded) {
            info = inspectFile(path, true);
            fs.grids = info.grids;
            resolveFrame(fs, info, options);
        }
    } catch (const turb::Error& e) {
        fs.error = e.what();
        fs.errorSettings = e.settings();
    }
    return fs;
}

const FrameScan* SequenceScan::firstFailure() const
{
    for (const auto& f : frames)
        if (!f.error.empty()) return &f;
    return nullptr;
}

std::string SequenceScan::describeChanges(size_t most) const
{
    std::ostringstream os;
    for (size_t i = 0; i < changes.size() && i < most; ++i) {
        const LatticeChange& c = changes[i];
        if (i) os << "; ";
        if (c.voxelSizeChanged)
            os << "voxel size changes from " << c.from.voxelSize << " at frame " << c.fromFrame << " (" << c.fromPath
               << ") to " << c.to.voxelSize << " at frame " << c.toFrame << " (" << c.toPath << ")";
        else
            os << "the lattice moves from origin " << c.from.origin << " at frame " << c.fromFrame << " (" << c.fromPath
               << ") to " << c.to.origin << " at frame " << c.toFrame << " (" << c.toPath << ")";
    }
    if (changes.size() > most) os << "; and " << (changes.size() - most) << " more changes";
    return os.str();
}

const FrameScan* SequenceScan::largestDomain() const
{
    const FrameScan* best = nullptr;
    for (const auto& f : frames)
        if (f.error.empty() && f.domainKnown && (!best || f.domain.volume() > best->domain.volume())) best = &f;
    return best;
}

SequenceScan scanSequence(
    const Sequence& seq, const std::vector<int>& frames, const ReadOptions& options, bool readVoxelsIfNeeded)
{
    SequenceScan scan;
    for (int f : frames) {
        if (!std::binary_search(seq.frames.begin(), seq.frames.end(), f)) continue;
        scan.frames.push_back(scanFrame(seq.path(f), f, options, readVoxelsIfNeeded && scan.frames.empty()));
    }
    const FrameScan* prev = nullptr;
    for (const auto& f : scan.frames) {
        if (!f.error.empty()) continue;
        if (prev && !sameLattice(prev->lattice, f.lattice)) {
            LatticeChange c;
            c.fromFrame = prev->frame;
            c.toFrame = f.frame;
            c.fromPath = prev->path;
            c.toPath = f.path;
            c.from = prev->lattice;
            c.to = f.lattice;
            c.voxelSizeChanged =
                std::abs(prev->lattice.voxelSize - f.lattice.voxelSize) > 1e-6 * prev->lattice.voxelSize;
            scan.changes.push_back(c);
        }
        // Blender's Adaptive Domain: the simulation box changes, and the domain it is written over (box x voxel) with
        // it: Blender scales each frame's box to the domain's full size. A re-bake at another resolution keeps the
        // domain (32 x 0.125 = 16 x 0.25).
        if (prev && scan.blenderAdaptive.empty() && prev->blenderResolution && f.blenderResolution &&
            *prev->blenderResolution != *f.blenderResolution) {
            bool domainChanged = false;
            for (int k = 0; k < 3; ++k) {
                const double a = (*prev->blenderResolution)[k] * prev->lattice.voxelSize;
                const double b = (*f.blenderResolution)[k] * f.lattice.voxelSize;
                domainChanged = domainChanged || std::abs(a - b) > 1e-4 * std::max(a, b);
            }
            if (domainChanged) {
                const auto res = [](const turb::Coord& r) {
                    return std::to_string(r.x()) + "x" + std::to_string(r.y()) + "x" + std::to_string(r.z());
                };
                std::ostringstream os;
                os << "Blender's Adaptive Domain: the simulation box changes from " << res(*prev->blenderResolution)
                   << " voxels of " << prev->lattice.voxelSize << " at frame " << prev->frame << " (" << prev->path
                   << ") to " << res(*f.blenderResolution) << " voxels of " << f.lattice.voxelSize << " at frame "
                   << f.frame << " (" << f.path
                   << "), and Blender writes each frame's box scaled to the whole domain, so the voxel sizes, "
                      "positions and velocities in these files are not the simulation's (its voxel is smaller, and "
                      "the same in every frame). Bake the cache without Adaptive Domain";
                scan.blenderAdaptive = os.str();
            }
        }
        prev = &f;
    }
    return scan;
}

} // namespace turbio
