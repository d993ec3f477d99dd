#pragma once
// Internal to tofcam's false colour (src/color): one row of the colour law, for the tests that
// check that a form writes exactly its row's bytes and nothing past them.

#include <cstdint>

#include "tofcam/color/false_color.h"

namespace tofcam::color_internal {

/// Tests only: one row of w >= 1 pixels through the law FalseColorImageInto uses (far_m the
/// resolved far limit, m), in the form this process runs (AVX-512 or portable:
/// src/core/avx512_forms.h), into `rgb` (3 w bytes). `flags` and `amplitude` hold w elements.
/// Throws like FalseColorImageInto for bad options or limits.
void ColorRowForTesting(int w, const FalseColorOptions& o, double far_m, const float* d,
                        const PixelFlags* flags, const float* amplitude, std::uint8_t* rgb);

}  // namespace tofcam::color_internal
