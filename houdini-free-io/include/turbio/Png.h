/// @file Png.h
/// @brief PNG pictures in and out (previews, contact sheets, plots; grayscale and vector exemplars).
#pragma once

#include <turb/Image.h>

#include <string>

namespace turbio {

/// Writes an 8-bit RGB PNG atomically (temporary file + rename). Values are clamped to [0, 1].
void writePng(const std::string& path, const turb::Image& image, bool noClobber = false);

/// Reads any PNG (gray, RGB, palette, with or without alpha; 8 or 16 bit) as RGB in [0, 1].
/// Values are the file's stored code values divided by the maximum, with no colour-space conversion.
turb::Image readPng(const std::string& path);

} // namespace turbio
