/// @file ImageIO.h
/// @brief Every image file vdbturb reads or writes, through OpenImageIO: exemplars, alpha masks and
///        motion fields in; stylized frames, previews, contact sheets and plots out.
///
/// Reading accepts any format OpenImageIO reads (PNG, EXR, TIFF, JPEG, ...; 8/16-bit, half, float;
/// gray, gray+alpha, RGB, RGBA) and returns a turb::RgbaImage with **straight** alpha:
/// - channels are taken by name (R, G, B, A, Y) where the file names them, else by position: 1 channel
///   is gray (copied to R, G, B), 2 are gray+alpha when the second is alpha else R, G; 3 are RGB;
/// - integer formats are scaled to [0, 1]; float formats keep their values (motion in pixels, HDR);
/// - associated (premultiplied) files, EXR's convention, are divided by alpha where alpha > 0;
/// - no colour conversion: RgbaImage::colorSpace records what the file declared.
///
/// Writing picks the format from the extension (.png, .exr, .tif/.tiff, .jpg/.jpeg) and is atomic
/// (temporary file + rename), so a failed or interrupted write leaves nothing at the path.
/// - RgbaImage: PNG and TIFF store straight alpha (8-bit PNG, 16-bit TIFF by default), EXR stores
///   half-float premultiplied RGBA, JPEG stores RGB only. Values are written as they are (no conversion);
///   the colour space is recorded in the file's metadata when known.
/// - turb::Image pictures (display-referred, sRGB-encoded) with their captions drawn by OpenImageIO's
///   render_text in DejaVu Sans Mono (Debian fonts-dejavu-core). EXR pictures are decoded to linear,
///   EXR's convention, so a viewer shows the same picture as the PNG.
///
/// Every failure throws turb::IoError naming the file; an unknown output extension throws
/// turb::ValueError naming the path.
///
/// @code
/// turbio::ImageFileInfo info;
/// turb::RgbaImage ex = turbio::readImage("fire.png", &info);   // info.hasAlpha tells if alpha came from the file
/// turbio::writeImage("styl/fire.0001.exr", ex);                 // half RGBA, premultiplied on disk
/// turbio::writeImage("sheet.png", turb::contactSheet(rows, labels, "title"));
/// @endcode
#pragma once

#include <turb/Image.h>
#include <turb/RgbaImage.h>

#include <string>
#include <utility>
#include <vector>

namespace turbio {

/// What an image file holds, from its header.
struct ImageFileInfo
{
    std::string path;
    std::string format; ///< OpenImageIO's format name: "png", "openexr", "tiff", "jpeg", ...
    int width = 0, height = 0;
    int channels = 0;                      ///< channels in the file
    std::vector<std::string> channelNames; ///< as the file names them (or OpenImageIO's defaults)
    bool hasAlpha = false;                 ///< the file has an alpha channel
    bool associatedAlpha = false;          ///< its colours are premultiplied by alpha (EXR; some TIFFs)
    std::string pixelType;                 ///< "uint8", "uint16", "half", "float", ...
    std::string colorSpace;                ///< as declared ("sRGB", "Linear", ...); empty = undeclared
    /// The header's text attributes by name (EXR string attributes, PNG text chunks, TIFF tags), e.g.
    /// vdbturb_command and vdbturb_settings in vdbturb's own frames.
    std::vector<std::pair<std::string, std::string>> metadata;
    /// The text attribute `name`, or "" when the header has none.
    std::string attribute(const std::string& name) const;
};

/// Reads the header only. Throws turb::IoError naming the file.
ImageFileInfo inspectImage(const std::string& path);

/// Reads the first subimage at full resolution (see the file comment for the channel rules).
/// `info`, when given, receives the header. Throws turb::IoError naming the file.
turb::RgbaImage readImage(const std::string& path, ImageFileInfo* info = nullptr);

/// Bits per channel on disk.
enum class PixelBits {
    Auto,   ///< PNG/JPEG 8-bit, TIFF 16-bit, EXR half
    Uint8,  ///< PNG, TIFF, JPEG
    Uint16, ///< PNG, TIFF
    Half,   ///< EXR, TIFF
    Float   ///< EXR, TIFF
};

struct ImageWriteOptions
{
    bool noClobber = false;           ///< refuse to replace an existing file
    PixelBits bits = PixelBits::Auto; ///< storage per channel; a format that cannot hold it is an error
    bool alpha = true;                ///< RgbaImage: write the alpha channel (JPEG never has one)
    /// Text attributes for the header (name, value), read back by inspectImage: what made the frame, for
    /// --skip-existing. JPEG keeps them as comments only where OpenImageIO can; EXR, PNG and TIFF keep them.
    std::vector<std::pair<std::string, std::string>> metadata;
};

/// OpenImageIO's format name for an output path: "png", "openexr", "tiff" or "jpeg". Throws
/// turb::ValueError naming the path for any other extension.
std::string outputFormatOf(const std::string& path);

/// Writes data pixels atomically (see the file comment). Throws turb::IoError naming the file.
void writeImage(const std::string& path, const turb::RgbaImage& image, const ImageWriteOptions& options = {});

/// Writes a display picture with its captions drawn, atomically. Throws turb::IoError naming the file.
void writeImage(const std::string& path, const turb::Image& picture, const ImageWriteOptions& options = {});

/// The picture with its captions rasterised into the pixels (and none left as labels): what
/// writeImage stores. Throws turb::IoError when the caption font cannot be found.
turb::Image withTextDrawn(const turb::Image& picture);

} // namespace turbio
