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
  // How far pixel i lies off the straight line through its two neighbours in direction
  // (dr, dc), m: 0 when that deviation is within min_jump_sigma of its σ (sqrt(σ_i² + 4 σ_a² +
  // σ_b²)); NaN when either neighbour is outside the image or unusable.
  const auto off_line = [&](int r, int c, int dr, int dc, std::size_t i) -> double {
    const int r1 = r + dr, c1 = c + dc, r2 = r + 2 * dr, c2 = c + 2 * dc;
    if (r2 < 0 || r2 >= h || c2 < 0 || c2 >= w) return std::numeric_limits<double>::quiet_NaN();
    const std::size_t a = static_cast<std::size_t>(r1) * w + c1;
    const std::size_t b = static_cast<std::size_t>(r2) * w + c2;
    if (!usable(a) || !usable(b)) return std::numeric_limits<double>::quiet_NaN();
    const double dev = std::abs(static_cast<double>(frame.radial_distance_m[i]) -
                                2.0 * frame.radial_distance_m[a] + frame.radial_distance_m[b]);
    const double si = frame.delta_l_m[i], sa = frame.delta_l_m[a], sb = frame.delta_l_m[b];
    return dev > options.min_jump_sigma * std::sqrt(si * si + 4 * sa * sa + sb * sb) ? dev : 0.0;
  };
  Image<float> out(w, h, kInf);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      if (!usable(i)) continue;
      const double d = frame.radial_distance_m[i], s = frame.delta_l_m[i];
      double edge = 0.0;  // m
      const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
      for (int k = 0; k < 4; ++k) {
        const int rr = r + dr[k], cc = c + dc[k];
        if (rr < 0 || rr >= h || cc < 0 || cc >= w) continue;
        const std::size_t j = static_cast<std::size_t>(rr) * w + cc;
        if (frame.flags[j].Any(options.unknown_neighbour_flags)) {
          edge = std::numeric_limits<double>::infinity();
          break;
        }
        if (!usable(j)) continue;
        const double dj = frame.radial_distance_m[j];
        const double step = std::abs(dj - d);
        const double sj = frame.delta_l_m[j];
        if (!(step > options.min_jump_sigma * std::sqrt(s * s + sj * sj))) continue;
        double e = options.edge_fraction * step;
        if (options.extrapolate_edges) {
          // The step's other side is the neighbour's business; this pixel is wrong only as far
          // as it leaves its own side's surface (a mixed pixel) or that is unknown.
          const double dev = off_line(r, c, -dr[k], -dc[k], i);
          if (!std::isnan(dev)) e = dev;
        }
        edge = std::max(edge, e);
      }
      if (std::isinf(edge)) continue;  // next to a clipped pixel: unbounded
      out[i] = static_cast<float>(std::sqrt(s * s + edge * edge));
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
