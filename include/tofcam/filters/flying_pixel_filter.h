#pragma once
/// \file
/// Edge-aware flying-pixel filter in the style of libfreenect2's depth post-filter
/// (tof-notes §4), applied to radial distance instead of depth z.

#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam {

/// In the 3x3 window around a pixel with distance d (m), over the usable pixels of the window
/// (the centre included): the amplitude contrast std/max(mean, amplitude_mean_floor), the
/// window minimum dmin and maximum dmax of the distance. The pixel is a flying pixel when
///   contrast >= min_amplitude_contrast  and  d - dmin > min_close_delta_m  and
///   dmax - d > min_far_delta_m  and  max(d - dmin, dmax - d) > min_max_delta_m  and
///   (d - dmin + dmax - d) / 2 > min_avg_delta_m.
/// Defaults are libfreenect2's (its millimetres converted to metres; its amplitude floor of 50
/// kept in our register units, a free parameter).
struct FlyingPixelOptions {
  double min_amplitude_contrast = 0.05;  ///< std/mean of amplitude, dimensionless; >= 0.
  double amplitude_mean_floor = 50.0;    ///< Floor of the mean amplitude, register units; > 0.
  double min_close_delta_m = 0.05;       ///< d - dmin must exceed this, m; >= 0.
  double min_far_delta_m = 0.03;         ///< dmax - d must exceed this, m; >= 0.
  double min_max_delta_m = 0.10;         ///< The larger of the two must exceed this, m; >= 0.
  double min_avg_delta_m = 0.0;          ///< Their mean must exceed this, m; >= 0.
  void Validate() const;
};

/// kFlyingPixel by the rule above. Pixels already rejected in `frame.flags` (any kRejectMask
/// bit) or with a non-finite distance or amplitude are neither judged nor part of any window.
/// Image borders use the part of the window inside the image. Throws Error(kInvalidArgument)
/// when the amplitude image is missing or of another size.
[[nodiscard]] Image<PixelFlags> FlyingPixelFilter(const MetricFrame& frame,
                                                  const FlyingPixelOptions& options);

}  // namespace tofcam
