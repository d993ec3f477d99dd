#include "tofcam/filters/spatial_filter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "exp_non_positive.h"
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

// One neighbour offset of the bilateral for n pixels of a row: `u` the usable distances (NaN
// elsewhere) of the centres, `un` of their neighbours at the offset, `g` the centres'
// 1 / (2 (k σ)²), `inv_s2n` the neighbours' 1 / σ². A neighbour within `limit` of its centre
// (single precision, false for NaN) adds its weight e^(-Δ² g) / σ_n² to `weight_sum`, weight x
// distance to `weighted`, and 1 to `count`. Passes over the offsets in the window's row-major
// order sum in the per-pixel definition's order.
TOFCAM_HOT_LOOP_WIDE void BilateralOffset(int n, float limit, const float* __restrict u,
                                          const float* __restrict un, const double* __restrict g,
                                          const double* __restrict inv_s2n,
                                          double* __restrict weight_sum,
                                          double* __restrict weighted,
                                          std::int32_t* __restrict count) {
  for (int c = 0; c < n; ++c) {
    const float fc = u[c], fn = un[c];
    const bool in = std::abs(fn - fc) <= limit;
    const double dc = fc, dn = fn;
    const double wgt = filters_internal::ExpNonPositive(-(dn - dc) * (dn - dc) * g[c]) * inv_s2n[c];
    weight_sum[c] += in ? wgt : 0.0;
    weighted[c] += in ? wgt * dn : 0.0;
    count[c] += in ? 1 : 0;
  }
}

// The bilateral's per-pixel factors: 1 / σ² and 1 / (2 (k σ)²), σ = ΔL where finite and
// positive, else `fallback` (`s` null: no ΔL).
TOFCAM_HOT_LOOP void BilateralFactors(std::size_t n, const float* __restrict s, double k,
                                      double fallback, double* __restrict inv_s2,
                                      double* __restrict g) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const float si = s == nullptr ? 0.0f : s[i];
    const double sigma = (std::abs(si) < kInf) & (si > 0.0f) ? static_cast<double>(si) : fallback;
    inv_s2[i] = 1.0 / (sigma * sigma);
    const double ks = k * sigma;
    g[i] = 1.0 / (2.0 * (ks * ks));
  }
}

// The bilateral's result for one row: the weighted mean where the centre is usable and its
// support has at least min_support pixels; `out` kept elsewhere.
TOFCAM_HOT_LOOP void BilateralFinish(int w, int min_support, const float* __restrict u,
                                     const double* __restrict weight_sum,
                                     const double* __restrict weighted,
                                     const std::int32_t* __restrict count, float* __restrict out) {
  for (int c = 0; c < w; ++c) {
    // A usable centre is in its own support, so its weight sum is positive.
    const bool apply = (u[c] == u[c]) & (count[c] >= min_support);
    const float mean = static_cast<float>(weighted[c] / weight_sum[c]);
    out[c] = apply ? mean : out[c];
  }
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
  // Usable distances, NaN elsewhere: one test per neighbour in the loops below.
  thread_local std::vector<float> usable;
  usable.resize(d.size());
  for (std::size_t i = 0; i < d.size(); ++i) {
    usable[i] = Usable(frame, i) ? d[i] : std::numeric_limits<float>::quiet_NaN();
  }
  // The support test in single precision, |d_n - d| <= limit, in both kinds.
  const float flimit = static_cast<float>(limit);
  if (options.kind == SpatialFilterKind::kBilateral) {
    // Per pixel 1 / σ² and 1 / (2 (k σ)²), then one vectorised pass per offset of the window
    // over each row's columns (BilateralOffset), in the window's order.
    thread_local std::vector<double> inv_s2, g, weight_sum, weighted;
    thread_local std::vector<std::int32_t> count;
    inv_s2.resize(d.size());
    g.resize(d.size());
    BilateralFactors(d.size(), has_sigma ? frame.delta_l_m.data() : nullptr,
                     options.range_sigma_factor, options.fallback_sigma_m, inv_s2.data(), g.data());
    weight_sum.resize(static_cast<std::size_t>(w));
    weighted.resize(static_cast<std::size_t>(w));
    count.resize(static_cast<std::size_t>(w));
    for (int row = 0; row < h; ++row) {
      std::fill(weight_sum.begin(), weight_sum.end(), 0.0);
      std::fill(weighted.begin(), weighted.end(), 0.0);
      std::fill(count.begin(), count.end(), 0);
      const std::size_t c0 = static_cast<std::size_t>(row) * w;
      for (int y = std::max(0, row - r); y <= std::min(h - 1, row + r); ++y) {
        for (int dx = -r; dx <= r; ++dx) {
          // Columns [first, last) have their neighbour at dx in the image.
          const int first = std::max(0, -dx), last = std::min(w, w - dx);
          if (first >= last) continue;
          const std::size_t at = c0 + static_cast<std::size_t>(first);
          const std::size_t n_at = static_cast<std::size_t>(y) * w +
                                   static_cast<std::size_t>(first + dx);  // first >= -dx
          BilateralOffset(last - first, flimit, usable.data() + at, usable.data() + n_at,
                          g.data() + at, inv_s2.data() + n_at, weight_sum.data() + first,
                          weighted.data() + first, count.data() + first);
        }
      }
      BilateralFinish(w, options.min_support, usable.data() + c0, weight_sum.data(),
                      weighted.data(), count.data(), distance_out.data() + c0);
    }
    return;
  }
  std::array<float, 49> support{};
  for (int row = 0; row < h; ++row) {
    // Columns [1, vector_end) of an interior row are done by MedianRow (3x3 median only).
    int vector_end = 1;
    if (r == 1 && row > 0 && row + 1 < h) {
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
      int n = 0;
      for (int y = std::max(0, row - r); y <= std::min(h - 1, row + r); ++y) {
        for (int x = std::max(0, col - r); x <= std::min(w - 1, col + r); ++x) {
          const float un = usable[static_cast<std::size_t>(y) * w + x];
          if (!(std::abs(un - fc) <= flimit)) continue;  // also NaN: not usable
          support[static_cast<std::size_t>(n++)] = un;
        }
      }
      if (n < options.min_support) continue;
      auto* mid = support.begin() + (n - 1) / 2;
      std::nth_element(support.begin(), mid, support.begin() + n);
      distance_out[c] = *mid;
    }
  }
}

}  // namespace tofcam
