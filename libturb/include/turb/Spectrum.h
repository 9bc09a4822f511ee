/// @file Spectrum.h
/// @brief The shell-averaged kinetic-energy spectrum E(k) of a velocity field over a box.
///
/// How it is computed (docs/measure.md repeats this for users):
/// - the velocity inside `box` is taken as is (no mask inside the box), minus its window-weighted mean,
///   so E(k) describes the fluctuations about the box's mean flow;
/// - each axis is tapered by a Hann window over the box's extent (the box is not periodic: without a
///   taper the jumps at its faces leak a k^-2 tail over the whole spectrum);
/// - the windowed box is zero-padded to a cube whose side is the smallest 2^a 3^b 5^c 7^d >= the longest
///   box side, so the wavenumber grid is isotropic, dk = 2 pi / (side * voxelSize);
/// - FFTW (single precision, FFTW_ESTIMATE plans, so the same plan at any thread count) transforms each
///   component; shell n collects the modes with n - 1/2 <= |k| / dk < n + 1/2, for n = 1 .. side/2
///   (the mean, n = 0, and the corners beyond the Nyquist sphere are left out);
/// - normalisation: sum_n E(k_n) dk equals 1/2 mean |u - mean|^2 over the box (the window's mean square
///   is divided out), so spectra of boxes of different sizes and resolutions compare directly.
/// Wavenumbers are angular, in radians per world unit: a lattice's Nyquist wavenumber is pi / voxelSize.
///
/// @code
/// turb::Spectrum e = turb::energySpectrum(frame.velocity, turb::smokeBBox(frame.density, 0.01f));
/// for (size_t n = 0; n < e.k.size(); ++n) std::cout << e.k[n] << " " << e.energy[n] << "\n";
/// @endcode
#pragma once

#include <turb/Field.h>

#include <vector>

namespace turb {

struct SpectrumSettings
{
    enum class Window { Hann, None };
    Window window = Window::Hann; ///< taper per axis before the FFT; None only for periodic test fields
    bool subtractMean = true;     ///< remove the (window-weighted) mean velocity before the transform
};

struct Spectrum
{
    std::vector<double> k;      ///< shell centres n * dk, n = 1..side/2, radians per world unit
    std::vector<double> energy; ///< E(k) per shell: (world units / time)^2 * world units
    double dk = 0.0;            ///< shell width, radians per world unit
    double meanEnergy = 0.0;    ///< 1/2 mean |u - mean|^2 over the box (sum of all modes, window divided out)
    int fftSide = 0;            ///< side of the padded FFT cube, voxels
    CoordBBox box;              ///< the analysed index box
    bool empty() const { return k.empty(); }
};

/// E(k) of `u` over `box` (clipped to u's box). An empty box gives an empty spectrum.
Spectrum energySpectrum(const VectorField& u, const CoordBBox& box, const SpectrumSettings& s = {});

/// The smallest n >= m whose only prime factors are 2, 3, 5 and 7 (fast FFT sizes).
int fftFriendlySize(int m);

} // namespace turb
