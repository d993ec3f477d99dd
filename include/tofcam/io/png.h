#pragma once
/// \file
/// PNG images through libpng: 8-bit RGB (false colour) and 16-bit grey (raw register channels).
/// Writes are atomic; reads validate the header and refuse images over 2^28 pixels.

#include <cstdint>
#include <filesystem>

#include "tofcam/core/image.h"
#include "tofcam/core/rgb.h"

namespace tofcam {

/// Writes an 8-bit RGB PNG. Throws Error(kIo) naming the path on failure,
/// Error(kInvalidArgument) for an empty image.
void WritePngRgb8(const std::filesystem::path& path, const Image<Rgb8>& image);
/// Writes a 16-bit greyscale PNG (e.g. a distance register channel).
void WritePngGray16(const std::filesystem::path& path, const Image<std::uint16_t>& image);

/// Reads an 8-bit RGB PNG (palette, grey and alpha are converted to RGB).
[[nodiscard]] Image<Rgb8> ReadPngRgb8(const std::filesystem::path& path);
/// Reads a 16-bit greyscale PNG; Error(kFormat) when the file is not 16-bit grey.
[[nodiscard]] Image<std::uint16_t> ReadPngGray16(const std::filesystem::path& path);

}  // namespace tofcam
