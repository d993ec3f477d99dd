#include "tofcam/filters/spatial_filter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "hot_loop.h"
#include "simd.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

void Bad(const std::string& field, const std::string& rule) {
  throw Error(ErrorCode::kInvalidArgument, "spatial filter " + field + " " + rule);
}

bool Usable(const MetricFrame& f, std::size_t i) {
  return std::isfinite(f.radial_distance_m[i]) && (f.flags.empty() || f.flags[i].Valid());
}

// One exchange of a sorting network, lane-wise: the smaller value to `a`.
[[gnu::always_inline]] inline void Sort2(simd::F8& a, simd::F8& b) {
  const simd::I8 lt = a < b;
  const simd::F8 lo = lt ? a : b;
  b = lt ? b : a;
  a = lo;
}

// 3x3 medians of one interior row for columns 1 .. 8k (the rest is left to the per-pixel path;
// returns the first column not done). `u`: the usable distances at the row's column 0, NaN where
// not usable, rows above and below at -+w. Per pixel, as the per-pixel path: nothing when the
// centre is not usable; the support is the usable neighbours within `limit` of the centre; with
// n >= min_support of them the result is their (n - 1) / 2-th smallest value. Branch-free:
// values outside the support become +inf, all nine are sorted by a 25-exchange network (0-1
// principle: checked on all 512 binary inputs), and the sorted value at (n - 1) / 2 is taken.
TOFCAM_HOT_LOOP int MedianRow(int w, float limit, int min_support, const float* __restrict u,
                              float* __restrict out) {
  using namespace simd;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  int col = 1;
  for (; col + 8 <= w - 1; col += 8) {
    F8 p[9];
    for (int y = -1; y <= 1; ++y) {
      for (int x = -1; x <= 1; ++x) p[(y + 1) * 3 + x + 1] = LoadF8(u + y * w + col + x);
    }
    const F8 centre = p[4];
    I8 n = I8{};
    for (F8& v : p) {
      const F8 diff = v - centre;
      const I8 in = (diff < 0.0f ? -diff : diff) <= limit;  // false for NaN
      v = in ? v : F8{} + kInf;
      n -= in;
    }
    // Written out so that p stays in registers (a loop over a table of pairs kept it in memory).
    Sort2(p[0], p[3]);
    Sort2(p[1], p[7]);
    Sort2(p[2], p[5]);
    Sort2(p[4], p[8]);
    Sort2(p[0], p[7]);
    Sort2(p[2], p[4]);
    Sort2(p[3], p[8]);
    Sort2(p[5], p[6]);
    Sort2(p[0], p[2]);
    Sort2(p[1], p[3]);
    Sort2(p[4], p[5]);
    Sort2(p[7], p[8]);
    Sort2(p[1], p[4]);
    Sort2(p[3], p[6]);
    Sort2(p[5], p[7]);
    Sort2(p[0], p[1]);
    Sort2(p[2], p[4]);
    Sort2(p[3], p[5]);
    Sort2(p[6], p[8]);
    Sort2(p[2], p[3]);
    Sort2(p[4], p[5]);
    Sort2(p[6], p[7]);
    Sort2(p[1], p[2]);
    Sort2(p[3], p[4]);
    Sort2(p[5], p[6]);
    const I8 k = (n - 1) >> 1;  // 0..4
    F8 median = p[0];
    for (int j = 1; j <= 4; ++j) median = k == j ? p[j] : median;
    // A usable centre is in its own support (n >= 1).
    const I8 apply = (centre == centre) & (n >= min_support);
    const F8 old = LoadF8(out + col);
    const F8 result = apply ? median : old;
    std::memcpy(out + col, &result, sizeof result);
  }
  return col;
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
  // The support test in single precision, |d_n - d| <= limit, in both paths.
  const float flimit = static_cast<float>(limit);
  for (int row = 0; row < h; ++row) {
    // Columns [1, vector_end) of an interior row are done by MedianRow (3x3 median only).
    int vector_end = 1;
    if (options.kind == SpatialFilterKind::kMedian && r == 1 && row > 0 && row + 1 < h) {
      const std::size_t c0 = static_cast<std::size_t>(row) * w;
      vector_end =
          MedianRow(w, flimit, options.min_support, usable.data() + c0, distance_out.data() + c0);
    }
    for (int col = 0; col < w; ++col) {
      if (col == 1 && vector_end > 1) col = vector_end;
      if (col >= w) break;
      const std::size_t c = static_cast<std::size_t>(row) * w + col;
      const float fc = usable[c];
      if (!(fc == fc)) continue;  // NaN: not usable
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
          if (!(std::abs(un - fc) <= flimit)) continue;
          const double dn = un;
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
