/// @file SteerablePyramid.h
/// @brief The real steerable pyramid (Simoncelli and Freeman 1995) that Heeger-Bergen histogram matching
///        works on (Okabe et al. 2009 section 5.6, after Heeger and Bergen 1995), and the Laplacian
///        pyramid of its fast preview mode.
///
/// The steerable pyramid is built in the Fourier domain (FFTW), as Portilla and Simoncelli's
/// construction but with real bands:
/// - a high-pass residual H0 (radial mask 1 beyond Nyquist, raised-cosine in log radius from 1/2 to 1);
/// - per level, K oriented bands B_k = L * hi(2 rho) * alpha cos^{K-1}(theta - pi k / K) * (-i)^{K-1}
///   (the factor makes each band real), and the low-pass L * lo(2 rho), cropped to half size in each axis;
/// - the final low-pass residual.
/// hi^2 + lo^2 = 1 and sum_k (alpha cos^{K-1})^2 = 1, so the transform is a tight frame: collapse() of
/// build() returns the image to float rounding. Level l bands are (padded size) / 2^l.
/// Images are first extended by reflection at the right and bottom to a size that factors into 2, 3, 5
/// and 7, is divisible by 2^levels and leaves >= 8 pixels of margin (fewer wrap-around artefacts, fast FFTs).
///
/// @code
/// turb::SteerablePyramid pyr = turb::buildSteerablePyramid(gray, 4, 4);  // 4 levels, 4 orientations
/// pyr.bands[1][2] ...                                                     // level 1, orientation 2
/// turb::ChannelImage back = turb::collapse(pyr);                          // == gray
/// @endcode
#pragma once

#include <turb/ChannelImage.h>

#include <vector>

namespace turb {

struct SteerablePyramid
{
    int width = 0, height = 0;                    ///< the image's size (bands cover the padded size)
    int paddedWidth = 0, paddedHeight = 0;        ///< level 0 band size
    ChannelImage highpass;                        ///< H0, 1 channel, padded size
    std::vector<std::vector<ChannelImage>> bands; ///< [level][orientation], 1 channel, padded size / 2^level
    ChannelImage lowpass;                         ///< the residual low-pass, padded size / 2^levels
    int levels() const { return int(bands.size()); }
};

/// Levels that keep the coarsest band at >= 8 pixels on the short side (at least 1).
int maxSteerableLevels(int width, int height);

/// Builds the pyramid of a 1-channel image. Throws ValueError on an empty or multi-channel image,
/// levels outside 1..maxSteerableLevels, or orientations outside 1..8.
SteerablePyramid buildSteerablePyramid(const ChannelImage& image, int levels, int orientations);

/// Rebuilds the image (width x height, 1 channel) from the pyramid.
ChannelImage collapse(const SteerablePyramid& pyramid);

/// A Laplacian pyramid (Burt and Adelson): bands[l] = G_l - expand(G_{l+1}) with G_0 the image and
/// G_{l+1} = reduce(G_l) (OpenCV pyrDown/pyrUp), and the low-pass G_levels. Sizes ceil(W / 2^l).
struct LaplacianPyramid
{
    std::vector<ChannelImage> bands;
    ChannelImage lowpass;
    int levels() const { return int(bands.size()); }
};

/// Throws ValueError on an empty or multi-channel image or levels outside 1..maxSteerableLevels.
LaplacianPyramid buildLaplacianPyramid(const ChannelImage& image, int levels);
/// Exact inverse of buildLaplacianPyramid (to float rounding).
ChannelImage collapse(const LaplacianPyramid& pyramid);

} // namespace turb
