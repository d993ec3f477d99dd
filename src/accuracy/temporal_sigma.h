#pragma once
// Private helper of the noise fits (delta_l.cc, noise_model.cc): a pixel's temporal σ.

#include <cmath>
#include <span>

#include "tofcam/core/frame.h"
#include "tofcam/core/units.h"

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

}  // namespace tofcam::accuracy_internal
