#include "tofcam/filters/uncertainty.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

}  // namespace

void UncertaintyOptions::Validate() const {
  if (!(max_uncertainty_m > 0.0 && max_uncertainty_m <= 100.0)) {
    Bad("uncertainty.max_uncertainty_m = " + std::to_string(max_uncertainty_m) +
        " must be in (0, 100]");
  }
  if (!(edge_fraction >= 0.0 && edge_fraction <= 1.0)) {
    Bad("uncertainty.edge_fraction = " + std::to_string(edge_fraction) + " must be in [0, 1]");
  }
  if (!(min_jump_sigma > 0.0 && min_jump_sigma <= 100.0)) {
    Bad("uncertainty.min_jump_sigma = " + std::to_string(min_jump_sigma) + " must be in (0, 100]");
  }
}

Image<float> ComputeUncertainty(const MetricFrame& frame, const UncertaintyOptions& options) {
  options.Validate();
  const int w = frame.width(), h = frame.height();
  if (w <= 0 || h <= 0) Bad("uncertainty: empty frame");
  if (!frame.delta_l_m.SameSize(w, h) || !frame.flags.SameSize(w, h)) {
    Bad("uncertainty: the frame needs ΔL and flags of its size (enable the accuracy stage)");
  }
  constexpr float kInf = std::numeric_limits<float>::infinity();
  auto usable = [&](std::size_t i) {
    return !frame.flags[i].Any(kRejectMask) && std::isfinite(frame.radial_distance_m[i]) &&
           std::isfinite(frame.delta_l_m[i]);
  };
  Image<float> out(w, h, kInf);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      if (!usable(i)) continue;
      const double d = frame.radial_distance_m[i], s = frame.delta_l_m[i];
      double jump = 0.0;
      const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
      for (int k = 0; k < 4; ++k) {
        const int rr = r + dr[k], cc = c + dc[k];
        if (rr < 0 || rr >= h || cc < 0 || cc >= w) continue;
        const std::size_t j = static_cast<std::size_t>(rr) * w + cc;
        if (frame.flags[j].Any(options.unknown_neighbour_flags)) {
          jump = std::numeric_limits<double>::infinity();
          break;
        }
        if (!usable(j)) continue;
        const double step = std::abs(frame.radial_distance_m[j] - d);
        const double sj = frame.delta_l_m[j];
        if (step > options.min_jump_sigma * std::sqrt(s * s + sj * sj)) jump = std::max(jump, step);
      }
      if (std::isinf(jump)) continue;  // next to a clipped pixel: unbounded
      const double e = options.edge_fraction * jump;
      out[i] = static_cast<float>(std::sqrt(s * s + e * e));
    }
  }
  return out;
}

Image<PixelFlags> UncertaintyFilter(const MetricFrame& frame, const UncertaintyOptions& options) {
  const Image<float> u = ComputeUncertainty(frame, options);
  Image<PixelFlags> out(frame.width(), frame.height());
  const float max = static_cast<float>(options.max_uncertainty_m);
  for (std::size_t i = 0; i < u.size(); ++i) {
    // Rejected pixels (u = inf) already carry their reason; the others are judged (u = inf
    // there: next to a clipped pixel, or no ΔL).
    if (!frame.flags[i].Any(kRejectMask) && !(u[i] <= max)) {
      out[i] = PixelFlags(Flag::kLowConfidence);
    }
  }
  return out;
}

}  // namespace tofcam
