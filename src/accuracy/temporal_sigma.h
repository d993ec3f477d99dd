#pragma once
// Private helper of the noise fits (delta_l.cc, noise_model.cc): a pixel's temporal σ.

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "tofcam/core/frame.h"
#include "tofcam/core/units.h"
#include "tofcam/filters/pixel_filters.h"

namespace tofcam::accuracy_internal {

// Temporal standard deviation (m, N - 1 in the denominator) of pixel i's radial distance over
// `frames`, taken around the circular mean so that a pixel near the 0 / L seam is not torn
// apart. False when the pixel is flagged or not finite in any frame.
inline bool TemporalSigma(std::span<const MetricFrame> frames, std::size_t i, double range_m,
                          double& sigma_m) {
  const double to_rad = 2.0 * kPi / range_m;
  double c = 0.0, s = 0.0;
  for (const MetricFrame& f : frames) {
    const double d = f.radial_distance_m[i];
    if (!(f.flags.empty() || f.flags[i].Valid()) || !std::isfinite(d)) return false;
    c += std::cos(d * to_rad);
    s += std::sin(d * to_rad);
  }
  // Deviations from the circular mean, wrapped into [-L/2, L/2).
  const double centre_m = std::atan2(s, c) / to_rad;
  const double n = static_cast<double>(frames.size());
  double sum = 0.0, sum2 = 0.0;
  for (const MetricFrame& f : frames) {
    double dev = f.radial_distance_m[i] - centre_m;
    dev -= range_m * std::floor(dev / range_m + 0.5);
    sum += dev;
    sum2 += dev * dev;
  }
  sigma_m = std::sqrt(std::max((sum2 - sum * sum / n) / (n - 1.0), 0.0));
  return true;
}

// 1 for every pixel the saturation filter's rule (registers, or the source's flags) flags in at
// least one of `frames`. A clipped pixel's distance is not a measurement (the pipeline rejects
// it), and one clipped in some frames only jumps between a reading and a clipped value: neither
// spread is the noise the fits model. The SR-2 reports no saturation bit, so the flags alone
// would let every clipped pixel in.
inline std::vector<std::uint8_t> ClippedInAnyFrame(std::span<const MetricFrame> frames,
                                                   const SaturationOptions& options) {
  std::vector<std::uint8_t> clipped(frames.empty() ? 0 : frames.front().radial_distance_m.size(),
                                    0);
  for (const MetricFrame& f : frames) {
    const Image<PixelFlags> raised = SaturationFilter(f, options);
    for (std::size_t i = 0; i < clipped.size() && i < raised.size(); ++i) {
      clipped[i] |= raised[i].Has(Flag::kSaturated) ? 1 : 0;
    }
  }
  return clipped;
}

}  // namespace tofcam::accuracy_internal
