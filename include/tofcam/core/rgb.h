#pragma once
/// \file
/// 8-bit RGB pixels, shared by the false-colour stage (core) and the PNG writer (tofcam::io), so
/// that the core library does not depend on libpng.

#include <cstdint>

namespace tofcam {

/// One 8-bit RGB pixel.
struct Rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
  friend bool operator==(const Rgb8&, const Rgb8&) = default;
};

static_assert(sizeof(Rgb8) == 3);

}  // namespace tofcam
