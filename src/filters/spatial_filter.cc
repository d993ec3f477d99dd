#include "tofcam/filters/spatial_filter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

void Bad(const std::string& field, const std::string& rule) {
  throw Error(ErrorCode::kInvalidArgument, "spatial filter " + field + " " + rule);
}

bool Usable(const MetricFrame& f, std::size_t i) {
  return std::isfinite(f.radial_distance_m[i]) && (f.flags.empty() || f.flags[i].Valid());
}

inline void Sort2(float& a, float& b) {
  const float lo = a < b ? a : b;
  b = a < b ? b : a;
  a = lo;
}

// Median of nine by the 19-exchange network (Paeth / Devillard's opt_med9): no branches on the
// data, so it stays fast when the support is complete, which it is for most pixels.
float Median9(float p[9]) {
  Sort2(p[1], p[2]);
  Sort2(p[4], p[5]);
  Sort2(p[7], p[8]);
  Sort2(p[0], p[1]);
  Sort2(p[3], p[4]);
  Sort2(p[6], p[7]);
  Sort2(p[1], p[2]);
  Sort2(p[4], p[5]);
  Sort2(p[7], p[8]);
  Sort2(p[0], p[3]);
  Sort2(p[5], p[8]);
  Sort2(p[4], p[7]);
  Sort2(p[3], p[6]);
  Sort2(p[1], p[4]);
  Sort2(p[2], p[5]);
  Sort2(p[4], p[7]);
  Sort2(p[4], p[2]);
  Sort2(p[6], p[4]);
  Sort2(p[4], p[2]);
  return p[4];
}

}  // namespace

std::string_view SpatialFilterKindName(SpatialFilterKind kind) noexcept {
  return kind == SpatialFilterKind::kMedian ? "median" : "bilateral";
}

SpatialFilterKind ParseSpatialFilterKind(std::string_view name) {
  if (name == "median") return SpatialFilterKind::kMedian;
  if (name == "bilateral") return SpatialFilterKind::kBilateral;
  throw Error(ErrorCode::kInvalidArgument,
              "unknown spatial filter kind '" + std::string(name) + "' (known: median, bilateral)");
}

void SpatialFilterOptions::Validate() const {
  if (radius_px < 1 || radius_px > 3) Bad("radius_px", "must be in [1, 3]");
  if (!(max_jump_m >= 0.0) || !std::isfinite(max_jump_m)) Bad("max_jump_m", "must be >= 0");
  if (min_support < 1 || min_support > 49) Bad("min_support", "must be in [1, 49]");
  if (!(range_sigma_factor > 0.0 && range_sigma_factor <= 100.0)) {
    Bad("range_sigma_factor", "must be in (0, 100]");
  }
  if (!(fallback_sigma_m > 0.0) || !std::isfinite(fallback_sigma_m)) {
    Bad("fallback_sigma_m", "must be > 0");
  }
}

MetricFrame SpatialFilter(const MetricFrame& frame, const SpatialFilterOptions& options) {
  MetricFrame out = frame;
  SpatialFilterInto(frame, options, out.radial_distance_m);
  return out;
}

void SpatialFilterInto(const MetricFrame& frame, const SpatialFilterOptions& options,
                       Image<float>& distance_out) {
  options.Validate();
  const Image<float>& d = frame.radial_distance_m;
  const int w = d.width(), h = d.height();
  const auto same = [&](const auto& image, const char* name) {
    if (!image.empty() && !image.SameSize(d)) {
      throw Error(ErrorCode::kInvalidArgument,
                  std::string("spatial filter: ") + name + " differs in size from the distances");
    }
  };
  same(frame.flags, "flags");
  same(frame.delta_l_m, "delta_l_m");
  if (&distance_out == &frame.radial_distance_m) {
    throw Error(ErrorCode::kInvalidArgument, "spatial filter: output aliases the input");
  }
  if (!distance_out.SameSize(d)) distance_out = Image<float>(w, h);
  std::copy(d.data(), d.data() + d.size(), distance_out.data());
  const int r = options.radius_px;
  const double limit =
      options.max_jump_m > 0.0 ? options.max_jump_m : std::numeric_limits<double>::infinity();
  const bool has_sigma = !frame.delta_l_m.empty();
  const auto sigma_at = [&](std::size_t i) {
    const double s = has_sigma ? frame.delta_l_m[i] : 0.0;
    return std::isfinite(s) && s > 0.0 ? s : options.fallback_sigma_m;
  };
  // Usable distances, NaN elsewhere: one test per neighbour in the loops below.
  thread_local std::vector<float> usable;
  usable.resize(d.size());
  for (std::size_t i = 0; i < d.size(); ++i) {
    usable[i] = Usable(frame, i) ? d[i] : std::numeric_limits<float>::quiet_NaN();
  }
  std::array<float, 49> support{};
  const float flimit = static_cast<float>(limit);
  for (int row = 0; row < h; ++row) {
    for (int col = 0; col < w; ++col) {
      const std::size_t c = static_cast<std::size_t>(row) * w + col;
      const float fc = usable[c];
      if (!(fc == fc)) continue;  // NaN: not usable
      if (options.kind == SpatialFilterKind::kMedian && r == 1 && row > 0 && row + 1 < h &&
          col > 0 && col + 1 < w) {
        // Interior 3x3: when all nine are usable and within the limit, the network.
        float p[9];
        bool all = true;
        for (int y = -1; y <= 1; ++y) {
          const float* q = usable.data() + (c + static_cast<std::ptrdiff_t>(y) * w) - 1;
          for (int x = 0; x < 3; ++x) {
            const float v = q[x];
            all &= std::abs(v - fc) <= flimit;  // false for NaN
            p[(y + 1) * 3 + x] = v;
          }
        }
        if (all) {
          distance_out[c] = Median9(p);
          continue;
        }
      }
      const double dc = fc;
      const double sc = sigma_at(c);
      const double inv_two_range2 = 1.0 / (2.0 * std::pow(options.range_sigma_factor * sc, 2));
      int n = 0;
      double weight_sum = 0.0, weighted = 0.0;
      for (int y = std::max(0, row - r); y <= std::min(h - 1, row + r); ++y) {
        for (int x = std::max(0, col - r); x <= std::min(w - 1, col + r); ++x) {
          const std::size_t i = static_cast<std::size_t>(y) * w + x;
          const float un = usable[i];
          if (!(un == un)) continue;
          const double dn = un;
          if (std::abs(dn - dc) > limit) continue;
          support[static_cast<std::size_t>(n++)] = static_cast<float>(dn);
          if (options.kind == SpatialFilterKind::kBilateral) {
            const double sn = sigma_at(i);
            const double wgt = std::exp(-(dn - dc) * (dn - dc) * inv_two_range2) / (sn * sn);
            weight_sum += wgt;
            weighted += wgt * dn;
          }
        }
      }
      if (n < options.min_support) continue;
      if (options.kind == SpatialFilterKind::kMedian) {
        auto* mid = support.begin() + (n - 1) / 2;
        std::nth_element(support.begin(), mid, support.begin() + n);
        distance_out[c] = *mid;
      } else {
        distance_out[c] = static_cast<float>(weighted / weight_sum);
      }
    }
  }
}

}  // namespace tofcam
