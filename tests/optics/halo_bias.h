#pragma once
// The measure of issue 18's scattering target, shared by the tests that check it: the median
// over the halo pixels of the per-pixel mean error against the simulator's truth.

#include <algorithm>
#include <cmath>
#include <vector>

#include "tofcam/core/frame.h"
#include "tofcam/core/units.h"

namespace tofcam::testing {

// Median over the halo pixels (truth cause kScattering, nothing else wrong, hand not there) of
// the per-pixel mean error against the truth, m.
inline double MedianHaloBias(const std::vector<Frame>& frames) {
  const Frame& f0 = frames.front();
  const double range = UnambiguousRangeM(f0.info.modulation_frequency_hz);
  std::vector<double> bias;
  for (std::size_t i = 0; i < f0.distance.size(); ++i) {
    const PixelFlags causes = f0.truth->causes[i];
    if (!causes.Has(Flag::kScattering) || causes.Has(Flag::kMixed) ||
        causes.Has(Flag::kSaturated) || causes.Has(Flag::kNoReturn) ||
        f0.truth->radial_distance_m[i] < 1.0f) {
      continue;
    }
    double sum = 0;
    for (const Frame& f : frames) {
      double e = f.distance[i] * range / 65536.0 - f.truth->radial_distance_m[i];
      e -= range * std::round(e / range);
      sum += e;
    }
    bias.push_back(sum / frames.size());
  }
  if (bias.empty()) return 0.0;
  std::nth_element(bias.begin(), bias.begin() + bias.size() / 2, bias.end());
  return bias[bias.size() / 2];
}

}  // namespace tofcam::testing
