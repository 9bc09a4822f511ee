/// @file Exemplar.h
/// @brief Vector-field texture exemplars for `synth` (Ma et al. 2009): the small 2D or 3D
///        motion fields whose local patterns are spread over a coarse flow.
///
/// An exemplar is a dense array of vectors: planar (two channels, the x and y components, nz == 1) or
/// volumetric (three channels). Sources, as in the paper's section 4:
/// - built-in procedurals (circles, swirls, squares, hearts, stripes, sinusoids), all derived from a
///   stream function, so they are divergence-free and tile seamlessly;
/// - an RGB picture whose red/green channels hold the x/y components at a stated scale;
/// - a grayscale bitmap turned into motion by the 2D curl of its intensity (v = (dI/dy, -dI/dx));
/// - a slice of a VDB velocity (2D) or a whole VDB velocity (3D).
/// Files are read by houdini-free-io; these functions take images and fields already in memory.
///
/// Conventions: exemplar +y is up. Pictures are stored top row first, so row 0 of an image becomes
/// the exemplar's top row (y = height - 1). Planar slices of a volume use the view convention of
/// Synth.h: looking along x the plane is (y, z), along y it is (x, z), along z it is (x, y).
///
/// @code
/// turb::ProceduralExemplarSettings p;
/// p.pattern = turb::ProceduralPattern::Hearts;
/// p.size = 64; p.period = 32;
/// turb::Exemplar hearts = turb::proceduralExemplar(p); // 64^2, periodic, unit rms
/// @endcode
#pragma once

#include <turb/Field.h>
#include <turb/Image.h>

#include <string>
#include <vector>

namespace turb {

/// A planar (2 channels) or volumetric (3 channels) vector-field exemplar.
struct Exemplar
{
    int nx = 0, ny = 0, nz = 1; ///< size in pixels/voxels; nz == 1 for planar exemplars
    int channels = 2;           ///< 2: planar (x, y components); 3: volumetric (x, y, z)
    bool periodic = false;      ///< tiles seamlessly: neighbourhoods may wrap around the edges
    std::vector<float> values;  ///< ((x * ny + y) * nz + z) * channels + c
    std::string name;           ///< for messages and reports ("hearts:32", "smoke.png", ...)

    bool planar() const { return channels == 2; }
    size_t count() const { return size_t(nx) * size_t(ny) * size_t(nz); }
    size_t linear(int x, int y, int z = 0) const
    {
        return (size_t(x) * size_t(ny) + size_t(y)) * size_t(nz) + size_t(z);
    }
    float* at(int x, int y, int z = 0) { return &values[linear(x, y, z) * size_t(channels)]; }
    const float* at(int x, int y, int z = 0) const { return &values[linear(x, y, z) * size_t(channels)]; }
};

/// A zero exemplar of the given size (nz == 1 gives a planar one).
Exemplar makeExemplar(int nx, int ny, int nz, bool periodic, const std::string& name = "");

enum class ProceduralPattern {
    Circles,  ///< ring vortices, all turning the same way, one per cell
    Swirls,   ///< Taylor-Green cells: counter-rotating vortices in a checkerboard
    Squares,  ///< vortices whose streamlines are squares
    Hearts,   ///< vortices whose streamlines are hearts (the paper's figure 1)
    Stripes,  ///< straight bands moving along +x and -x in turn (shear layers)
    Sinusoids ///< flow along sinuous channels (the paper's seaweed exemplar, figure 9)
};

/// Parses "circles", "swirls", "squares", "hearts", "stripes", "sinusoids"; throws ValueError.
ProceduralPattern parseProceduralPattern(const std::string& name);
const char* proceduralPatternName(ProceduralPattern p);

struct ProceduralExemplarSettings
{
    ProceduralPattern pattern = ProceduralPattern::Circles; ///< which motion pattern
    int size = 64;   ///< exemplar edge in pixels, >= 8 and a multiple of `period` (paper: 64)
    int period = 16; ///< feature size: the pattern repeats every `period` pixels, >= 4
};

/// A periodic planar exemplar normalised to unit rms speed. Divergence-free up to discretisation.
Exemplar proceduralExemplar(const ProceduralExemplarSettings& settings);

/// Vectors from a picture's red (x) and green (y) channels: v = (2 * value - 1) * scale, so mid-grey
/// 0.5 is still. Row 0 of the picture is the top of the exemplar.
Exemplar exemplarFromVectorImage(const Image& image, double scale = 1.0);

/// Motion from a grayscale bitmap as in the paper: the 2D curl of the intensity I (the mean of R, G, B),
/// v = (dI/dy, -dI/dx) in intensity units per pixel, times `scale`. One-sided differences at the edges
/// unless `periodic`.
Exemplar exemplarFromGrayImage(const Image& image, double scale = 1.0, bool periodic = false);

/// The in-plane components of the slice of `field` perpendicular to `axis` at index `index` (in the
/// field's index space), in the view convention above. Throws ValueError when the slice is outside.
Exemplar exemplarFromSlice(const VectorField& field, int axis, int index);

/// A volumetric exemplar holding the whole field.
Exemplar exemplarFromVolume(const VectorField& field);

/// Resampled so that features become `factor` times larger (bilinear / trilinear; wraps when periodic).
/// The size becomes round(n * factor) per axis (at least 1). factor > 0.
Exemplar rescaledExemplar(const Exemplar& ex, double factor);

/// Root-mean-square speed over all pixels.
double exemplarRms(const Exemplar& ex);

/// Scales the exemplar to unit rms speed; returns the factor applied (1 when it is all zero).
double normalizeExemplar(Exemplar& ex);

/// The exemplar as a field on a unit lattice: planar ones one voxel thick in z (components x, y, 0),
/// for rendering (LIC) and measurement with the field tools.
VectorField exemplarAsField(const Exemplar& ex);

/// The paper's colour visualisation: red and green encode the x and y components (mid-grey is still),
/// clipped at +-`range` (0 = the largest component). Volumetric exemplars show their middle z slice.
Image exemplarColorImage(const Exemplar& ex, double range = 0.0);

} // namespace turb
