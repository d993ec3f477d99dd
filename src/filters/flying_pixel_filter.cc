#include "tofcam/filters/flying_pixel_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "filter_internal.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace filters_internal {
namespace {

// Per-row horizontal 3-sums (weight, amplitude, amplitude², and 3-min / 3-max of the distance)
// kept for three rolling rows, so the working set stays in L1; the vertical pass adds three rows.
// Unusable pixels carry weight 0, amplitude 0 and distances that never win a min (+inf) or max
// (-inf); a neutral row stands in above the first and below the last row. Reused per thread so
// a stable frame size allocates nothing.
struct Scratch {
  std::vector<float> rows;  // 3 rolling rows of 5 sums each, plus one neutral row of each
  std::vector<float> ca, cw, clo, chi;  // one padded input row
};

// The loops live in functions with __restrict parameters: with a dozen pointers GCC otherwise
// gives up on the run-time alias checks and does not vectorise.
TOFCAM_HOT_LOOP void PrepareRow(int w, const float* __restrict d, const float* __restrict a,
                                const PixelFlags* __restrict pf, float* __restrict cw,
                                float* __restrict ca, float* __restrict clo,
                                float* __restrict chi) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int c = 0; c < w; ++c) {
    // |x| < inf is false for NaN and ±inf.
    const bool usable = (static_cast<unsigned>(std::abs(d[c]) < kInf) &
                         static_cast<unsigned>(std::abs(a[c]) < kInf) &
                         static_cast<unsigned>((pf[c].bits() & kRejectMask) == 0)) != 0;
    cw[c + 1] = usable ? 1.0f : 0.0f;
    ca[c + 1] = usable ? a[c] : 0.0f;
    clo[c + 1] = usable ? d[c] : kInf;
    chi[c + 1] = usable ? d[c] : -kInf;
  }
}

TOFCAM_HOT_LOOP void HorizontalSums(int w, const float* __restrict cw, const float* __restrict ca,
                                    const float* __restrict clo, const float* __restrict chi,
                                    float* __restrict n, float* __restrict sum,
                                    float* __restrict sum2, float* __restrict lo,
                                    float* __restrict hi) {
  for (int c = 0; c < w; ++c) {
    n[c] = cw[c] + cw[c + 1] + cw[c + 2];
    sum[c] = ca[c] + ca[c + 1] + ca[c + 2];
    sum2[c] = ca[c] * ca[c] + ca[c + 1] * ca[c + 1] + ca[c + 2] * ca[c + 2];
    lo[c] = std::min(std::min(clo[c], clo[c + 1]), clo[c + 2]);
    hi[c] = std::max(std::max(chi[c], chi[c + 1]), chi[c + 2]);
  }
}

struct Thresholds {
  float contrast, floor_a, close, far, max_delta, avg_delta;
};

// Horizontal sums of one row: count, Σa, Σa², 3-min and 3-max of the distance.
struct RowSums {
  float* n;
  float* sum;
  float* sum2;
  float* lo;
  float* hi;
};

// Rows up (u), mid (m) and down (v) of the horizontal sums; all restrict-qualified so that GCC
// vectorises without run-time alias checks.
TOFCAM_HOT_LOOP void Decide(int w, const Thresholds& t, const float* __restrict nu,
                            const float* __restrict nm, const float* __restrict nv,
                            const float* __restrict su, const float* __restrict sm,
                            const float* __restrict sv, const float* __restrict qu,
                            const float* __restrict qm, const float* __restrict qv,
                            const float* __restrict lu, const float* __restrict lm,
                            const float* __restrict lv, const float* __restrict hu,
                            const float* __restrict hm, const float* __restrict hv,
                            const float* __restrict d, const float* __restrict a,
                            const PixelFlags* __restrict pf, PixelFlags* __restrict f) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kFlyingPixel);
  const float contrast = t.contrast, floor_a = t.floor_a, close = t.close, far = t.far;
  const float max_delta = t.max_delta, avg_delta = t.avg_delta;
  for (int c = 0; c < w; ++c) {
    const float cnt = nu[c] + nm[c] + nv[c];
    const float sum = su[c] + sm[c] + sv[c];
    const float sum2 = qu[c] + qm[c] + qv[c];
    const float dmin = std::min(std::min(lu[c], lm[c]), lv[c]);
    const float dmax = std::max(std::max(hu[c], hm[c]), hv[c]);
    // Population variance n·Σa² - (Σa)² over n², clamped against rounding below zero;
    // std/mean >= contrast  <=>  var·n² >= (contrast·mean·n)²  (both sides >= 0).
    const float nn = std::max(cnt, 1.0f);
    const float var_n2 = std::max(nn * sum2 - sum * sum, 0.0f);
    const float mean = std::max(sum / nn, floor_a);
    const float lim = contrast * mean * nn;
    const float dc = d[c];
    const float to_min = dc - dmin, to_max = dmax - dc;
    // Unusable centres (NaN / inf distance or amplitude, rejected) are cleared via `usable`;
    // integer ANDs instead of && keep the loop free of branches.
    const unsigned usable = static_cast<unsigned>(std::abs(dc) < kInf) &
                            static_cast<unsigned>(std::abs(a[c]) < kInf) &
                            static_cast<unsigned>((pf[c].bits() & kRejectMask) == 0);
    const unsigned flying = usable & static_cast<unsigned>(var_n2 >= lim * lim) &
                            static_cast<unsigned>(to_min > close) &
                            static_cast<unsigned>(to_max > far) &
                            static_cast<unsigned>(std::max(to_min, to_max) > max_delta) &
                            static_cast<unsigned>(0.5f * (to_min + to_max) > avg_delta);
    f[c] |= PixelFlags(static_cast<std::uint16_t>(flying * bit));
  }
}

}  // namespace

void FlyingPixelInto(const MetricFrame& frame, const Image<PixelFlags>& prior,
                     const FlyingPixelOptions& o, Image<PixelFlags>& out) {
  if (frame.amplitude.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "flying pixel filter: amplitude is empty");
  }
  const int w = frame.width(), h = frame.height();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const std::size_t sw = static_cast<std::size_t>(w);
  thread_local Scratch s;
  s.rows.resize(4 * 5 * sw);
  // Slot k in 0..3 holds a row's five sums at [k*5*w, (k+1)*5*w); slot 3 is the neutral row.
  auto slot = [&](int k) {
    float* base = s.rows.data() + static_cast<std::size_t>(k) * 5 * sw;
    return RowSums{base, base + sw, base + 2 * sw, base + 3 * sw, base + 4 * sw};
  };
  const RowSums neutral = slot(3);
  std::fill(neutral.n, neutral.n + sw, 0.0f);
  std::fill(neutral.sum, neutral.sum + sw, 0.0f);
  std::fill(neutral.sum2, neutral.sum2 + sw, 0.0f);
  std::fill(neutral.lo, neutral.lo + sw, kInf);
  std::fill(neutral.hi, neutral.hi + sw, -kInf);
  for (auto* v : {&s.ca, &s.cw, &s.clo, &s.chi}) v->assign(sw + 2, 0.0f);
  float* ca = s.ca.data();
  float* cw = s.cw.data();
  float* clo = s.clo.data();
  float* chi = s.chi.data();
  clo[0] = clo[w + 1] = kInf;
  chi[0] = chi[w + 1] = -kInf;
  const PixelFlags* prior_px = PriorOrZeros(prior, frame.radial_distance_m.size());

  auto sums_of_row = [&](int r) {
    const RowSums out_row = slot(r % 3);
    PrepareRow(w, frame.radial_distance_m.Row(r).data(), frame.amplitude.Row(r).data(),
               prior_px + static_cast<std::size_t>(r) * sw, cw, ca, clo, chi);
    HorizontalSums(w, cw, ca, clo, chi, out_row.n, out_row.sum, out_row.sum2, out_row.lo,
                   out_row.hi);
  };

  const Thresholds t{
      static_cast<float>(o.min_amplitude_contrast), static_cast<float>(o.amplitude_mean_floor),
      static_cast<float>(o.min_close_delta_m),      static_cast<float>(o.min_far_delta_m),
      static_cast<float>(o.min_max_delta_m),        static_cast<float>(o.min_avg_delta_m)};
  sums_of_row(0);
  for (int r = 0; r < h; ++r) {
    if (r + 1 < h) sums_of_row(r + 1);
    const RowSums u = r > 0 ? slot((r - 1) % 3) : neutral;
    const RowSums m = slot(r % 3);
    const RowSums v = r + 1 < h ? slot((r + 1) % 3) : neutral;
    Decide(w, t, u.n, m.n, v.n, u.sum, m.sum, v.sum, u.sum2, m.sum2, v.sum2, u.lo, m.lo, v.lo, u.hi,
           m.hi, v.hi, frame.radial_distance_m.Row(r).data(), frame.amplitude.Row(r).data(),
           prior_px + static_cast<std::size_t>(r) * sw, out.Row(r).data());
  }
}

}  // namespace filters_internal

void FlyingPixelOptions::Validate() const {
  auto nonneg = [](double v, const char* name) {
    if (!(v >= 0.0 && v <= 1e6)) {
      throw Error(ErrorCode::kInvalidArgument, std::string("flying_pixel.") + name + " = " +
                                                   std::to_string(v) + " is outside [0, 1e6]");
    }
  };
  nonneg(min_amplitude_contrast, "min_amplitude_contrast");
  nonneg(min_close_delta_m, "min_close_delta_m");
  nonneg(min_far_delta_m, "min_far_delta_m");
  nonneg(min_max_delta_m, "min_max_delta_m");
  nonneg(min_avg_delta_m, "min_avg_delta_m");
  if (!(amplitude_mean_floor > 0.0 && amplitude_mean_floor <= 1e9)) {
    throw Error(ErrorCode::kInvalidArgument,
                "flying_pixel.amplitude_mean_floor = " + std::to_string(amplitude_mean_floor) +
                    " must be > 0");
  }
}

Image<PixelFlags> FlyingPixelFilter(const MetricFrame& frame, const FlyingPixelOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "flying pixel filter");
  Image<PixelFlags> out(frame.width(), frame.height());
  filters_internal::FlyingPixelInto(frame, frame.flags, options, out);
  return out;
}

}  // namespace tofcam
