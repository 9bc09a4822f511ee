// The OpenImageIO half of turbio/ImageIO.h, built as its own module (libturb_oiio.so) and loaded on the first
// image read or write. Debian's OpenImageIO brings about 240 shared libraries (codecs, DICOM, camera raw,
// colour management) whose dynamic linking took 0.5 s of every vdbturb start; commands that never touch an
// image (transfer, sim, info, resample, measure without figures) no longer pay it.
#pragma once

#include <turbio/ImageIO.h>

namespace turbio::detail {

/// The module's entry points: the functions of turbio/ImageIO.h that need OpenImageIO.
struct ImageBackend
{
    ImageFileInfo (*inspectImage)(const std::string& path);
    turb::RgbaImage (*readImage)(const std::string& path, ImageFileInfo* info);
    void (*writeRgba)(const std::string& path, const turb::RgbaImage& image, const ImageWriteOptions& options);
    void (*writePicture)(const std::string& path, const turb::Image& picture, const ImageWriteOptions& options);
    turb::Image (*withTextDrawn)(const turb::Image& picture);
};

} // namespace turbio::detail

/// Exported by libturb_oiio.so: its table, the same object on every call.
extern "C" const turbio::detail::ImageBackend* vdbturb_oiio_backend();
