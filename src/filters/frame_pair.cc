#include "tofcam/filters/frame_pair.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "hot_loop.h"
#include "kth_smallest.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

constexpr std::size_t kMinPixelsForMedian = 64;

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

bool Good(const MetricFrame& f, std::size_t i) {
  return !f.flags[i].Any(kRejectMask) && std::isfinite(f.radial_distance_m[i]);
}

// Weight 1/σ², with a usable fallback where ΔL is missing or not positive.
double Weight(float delta_l) {
  return std::isfinite(delta_l) && delta_l > 0.0f ? 1.0 / (static_cast<double>(delta_l) * delta_l)
                                                  : 0.0;
}

// The wrap-count search of two frequencies for pixels [0, n): for each count n1 = 0..max_n1 of
// the first frame's wrap, the second's nearest count n2 >= 0, and of these pairs the one whose
// unwrapped distances disagree least (a, b) and the second-least disagreement. Pixel by pixel the
// same operations in the same order as a loop over n1 per pixel; the loops are turned so that
// each pass over n1 runs across pixels (vectorised, rounding inline in the AVX2 clone). `best`:
// scratch of n values.
TOFCAM_HOT_LOOP void WrapSearch(std::size_t n, const float* __restrict d1s,
                                const float* __restrict d2s, double l1, double l2, int max_n1,
                                double* __restrict a, double* __restrict b, double* __restrict best,
                                double* __restrict second) {
  for (std::size_t i = 0; i < n; ++i) {
    a[i] = d1s[i];
    b[i] = d2s[i];
    best[i] = 1e300;
    second[i] = 1e300;
  }
  for (int n1 = 0; n1 <= max_n1; ++n1) {
    for (std::size_t i = 0; i < n; ++i) {
      const double d1 = d1s[i], d2 = d2s[i];
      const double e1 = d1 + n1 * l1;
      const double n2 = std::max(0.0, std::round((e1 - d2) / l2));
      const double e2 = d2 + n2 * l2;
      const double disagreement = std::abs(e1 - e2);
      const bool better = disagreement < best[i];
      const bool second_better = !better && disagreement < second[i];
      second[i] = better ? best[i] : (second_better ? disagreement : second[i]);
      best[i] = better ? disagreement : best[i];
      a[i] = better ? e1 : a[i];
      b[i] = better ? e2 : b[i];
    }
  }
}

// ln(b / a) for positive a, b: as 2 atanh(u), u = (b - a) / (b + a), by its series to u^5 where
// b and a differ by less than about 20 % (|u| < 0.1: the omitted terms sum to less than 3e-8;
// the distances of a pair differ by motion or noise, a few %), by std::log elsewhere.
double LogRatio(double b, double a) {
  const double u = (b - a) / (b + a);
  if (!(std::abs(u) < 0.1)) return std::log(b / a);
  const double u2 = u * u;
  return 2.0 * u * (1.0 + u2 * (1.0 / 3.0 + u2 * (1.0 / 5.0)));
}

// Per-pixel inputs of the pooled two-returns check (FramePairOptions::two_returns_radius_px),
// recorded by the combination for the pixels that contribute, on a grid padded by the radius so
// that every window reads within it. A NaN distance marks a pixel that does not contribute
// (padding too); its weights are 0. The weighted values are premultiplied: the pooled ratio's
// mean less the median m is (Σ w r - m Σ w) / Σ w, so the median need not be known first.
struct PooledInputs {
  int width = 0, radius = 0;
  std::ptrdiff_t stride = 0;    // the padded row
  std::vector<float> distance;  // b, m: the same-surface test
  std::vector<float> sigma2;    // ΔL² of b, m²
  std::vector<float> ratio_w;   // 1 / the variance of r = ln(A2 / A1) + 2 ln(b / a)
  std::vector<float> ratio_wr;  // ratio_w x r: the amplitude ratio corrected for motion
  std::vector<float> gap_w;     // 1 / the variance of a - b, 1/m²
  std::vector<float> gap_wg;    // gap_w x (a - b)
  std::vector<double> ratios;   // every contributor's r, for the median

  void Reset(int w, int h, int r) {
    width = w;
    radius = r;
    stride = w + 2 * r;
    const std::size_t padded = static_cast<std::size_t>(stride) * (h + 2 * r);
    distance.assign(padded, std::numeric_limits<float>::quiet_NaN());
    sigma2.assign(padded, 0.0f);
    ratio_w.assign(padded, 0.0f);
    ratio_wr.assign(padded, 0.0f);
    gap_w.assign(padded, 0.0f);
    gap_wg.assign(padded, 0.0f);
    ratios.clear();
  }
  // Pixel i of the frame (row-major, `width` columns) at its place in the grid.
  [[nodiscard]] std::size_t At(std::size_t i) const {
    const std::size_t r = i / static_cast<std::size_t>(width), c = i % width;
    return (r + radius) * static_cast<std::size_t>(stride) + c + radius;
  }
  // Records a contributing pixel unless a value or weight is too large for the float sums of a
  // window of up to 11x11 (a ΔL below about 1e-18 m in both frames): such a pixel neither
  // contributes nor is judged.
  void Record(std::size_t i, double b, double sigma_b, double r, double r_variance, double gap,
              double gap_variance) {
    constexpr int kSide = 2 * FramePairOptions::kMaxTwoReturnsRadiusPx + 1;
    constexpr double kMax = std::numeric_limits<float>::max() / (kSide * kSide);
    const double s2 = sigma_b * sigma_b, rw = 1.0 / r_variance, gw = 1.0 / gap_variance;
    for (const double v : {b, s2, rw, r * rw, gw, gap * gw}) {
      if (!(std::abs(v) <= kMax)) return;
    }
    const std::size_t p = At(i);
    distance[p] = static_cast<float>(b);
    sigma2[p] = static_cast<float>(s2);
    ratio_w[p] = static_cast<float>(rw);
    ratio_wr[p] = static_cast<float>(r * rw);
    gap_w[p] = static_cast<float>(gw);
    gap_wg[p] = static_cast<float>(gap * gw);
    ratios.push_back(r);
  }
};

// Sixteen floats, and sixteen lanes of a comparison's result (all bits set where true);
// `Floats16Unaligned` reads and writes them anywhere a float may be.
using Floats16 = float __attribute__((vector_size(64)));
using Floats16Unaligned = float __attribute__((vector_size(64), aligned(4), may_alias));
using Mask16 = std::int32_t __attribute__((vector_size(64)));

// The pooled sums of a row of `n` pixels over their (2 radius + 1)² windows: sum_rw, sum_rs,
// sum_gw, sum_gs and the count of readings, each `n` floats in `out`. Neighbour j counts where it
// lies on the centre's surface (a NaN distance, padding or no contribution, never does). The
// pointers are the padded arrays at the row's first pixel, `pw` their row stride. Sixteen pixels
// at a time with their sums in registers (GCC's vector type: one AVX-512 register, two AVX2 or
// four SSE ones); the compiler's own vectoriser left the window's loops scalar, 45 ns a pixel at
// 640x480. No sum depends on a fused multiply-add, so every clone gives the same bits.
TOFCAM_HOT_LOOP_WIDE void PooledRowSums(int n, int radius, std::ptrdiff_t pw, const float* d,
                                        const float* s2, const float* rw, const float* rs,
                                        const float* gw, const float* gs, float k2, float floor2,
                                        float* out) {
  float* const sum_rw = out;
  float* const sum_rs = out + n;
  float* const sum_gw = out + 2 * static_cast<std::ptrdiff_t>(n);
  float* const sum_gs = out + 3 * static_cast<std::ptrdiff_t>(n);
  float* const count = out + 4 * static_cast<std::ptrdiff_t>(n);
  const Floats16 k2v = Floats16{} + k2, floor2v = Floats16{} + floor2, one = Floats16{} + 1.0f;
  // Unaligned loads and stores; `same & value` keeps a value where the mask is set (0 elsewhere).
  const auto at = [](const float* p) { return reinterpret_cast<const Floats16Unaligned*>(p); };
  const auto to = [](float* p) { return reinterpret_cast<Floats16Unaligned*>(p); };
  int c = 0;
  for (; c + 16 <= n; c += 16) {
    const Floats16 d_c = *at(d + c), s2_c = *at(s2 + c);
    Floats16 a_rw{}, a_rs{}, a_gw{}, a_gs{}, a_n{};
    for (int dr = -radius; dr <= radius; ++dr) {
      for (int dc = -radius; dc <= radius; ++dc) {
        const std::ptrdiff_t j = c + dr * pw + dc;
        const Floats16 step = *at(d + j) - d_c;
        Floats16 limit = k2v * (s2_c + *at(s2 + j));
        limit = limit > floor2v ? limit : floor2v;
        const Mask16 same = step * step <= limit;
        a_rw += reinterpret_cast<Floats16>(same & reinterpret_cast<Mask16>(Floats16(*at(rw + j))));
        a_rs += reinterpret_cast<Floats16>(same & reinterpret_cast<Mask16>(Floats16(*at(rs + j))));
        a_gw += reinterpret_cast<Floats16>(same & reinterpret_cast<Mask16>(Floats16(*at(gw + j))));
        a_gs += reinterpret_cast<Floats16>(same & reinterpret_cast<Mask16>(Floats16(*at(gs + j))));
        a_n += reinterpret_cast<Floats16>(same & reinterpret_cast<Mask16>(one));
      }
    }
    *to(sum_rw + c) = a_rw;
    *to(sum_rs + c) = a_rs;
    *to(sum_gw + c) = a_gw;
    *to(sum_gs + c) = a_gs;
    *to(count + c) = a_n;
  }
  for (; c < n; ++c) {  // the row's last pixels, one at a time in the same order
    float a_rw = 0.0f, a_rs = 0.0f, a_gw = 0.0f, a_gs = 0.0f, a_n = 0.0f;
    for (int dr = -radius; dr <= radius; ++dr) {
      for (int dc = -radius; dc <= radius; ++dc) {
        const std::ptrdiff_t j = c + dr * pw + dc;
        const float step = d[j] - d[c];
        const bool same = step * step <= std::max(k2 * (s2[c] + s2[j]), floor2);
        a_rw += same ? rw[j] : 0.0f;
        a_rs += same ? rs[j] : 0.0f;
        a_gw += same ? gw[j] : 0.0f;
        a_gs += same ? gs[j] : 0.0f;
        a_n += same ? 1.0f : 0.0f;
      }
    }
    sum_rw[c] = a_rw;
    sum_rs[c] = a_rs;
    sum_gw[c] = a_gw;
    sum_gs[c] = a_gs;
    count[c] = a_n;
  }
}

// The pooled two-returns check over a frame whose inputs the combination recorded; raises
// kInconsistent in `flags`. Each judged pixel pools the contributing pixels of its window on its
// own surface; the ratio is taken less the contributors' median (the camera's contrast ratio of
// the two frequencies, as in the per-pixel check).
void PooledTwoReturnsCheck(int w, int h, const FramePairOptions& options, double log_floor,
                           double fallback_median, PooledInputs& in, MetricFrame& current) {
  if (w <= 0 || h <= 0) return;
  // Too few contributors to tell the camera's contrast ratio: the per-pixel check's reference.
  const double median = in.ratios.size() >= kMinPixelsForMedian
                            ? filters_internal::KthSmallest(in.ratios, in.ratios.size() / 2)
                            : fallback_median;
  Image<PixelFlags>& flags = current.flags;
  const int radius = in.radius;
  const auto k2 =
      static_cast<float>(options.max_disagreement_sigma * options.max_disagreement_sigma);
  const auto floor2 = static_cast<float>(options.min_tolerance_m * options.min_tolerance_m);
  const double k = options.max_amplitude_disagreement_sigma;
  const float min_readings = static_cast<float>(2 * radius + 1);
  thread_local std::vector<float> sums;
  sums.resize(5 * static_cast<std::size_t>(w));
  const float* const sum_rw = sums.data();
  const float* const sum_rs = sum_rw + w;
  const float* const sum_gw = sum_rs + w;
  const float* const sum_gs = sum_gw + w;
  const float* const count = sum_gs + w;
  for (int r = 0; r < h; ++r) {
    const std::size_t centre = in.At(static_cast<std::size_t>(r) * w);
    PooledRowSums(w, radius, in.stride, &in.distance[centre], &in.sigma2[centre],
                  &in.ratio_w[centre], &in.ratio_wr[centre], &in.gap_w[centre], &in.gap_wg[centre],
                  k2, floor2, sums.data());
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      // Fewer readings than the window's side are no region: the per-pixel check's case.
      if (std::isnan(in.distance[centre + c]) || flags[i].Has(Flag::kInconsistent) ||
          count[c] < min_readings || !(sum_rw[c] > 0.0f) || !(sum_gw[c] > 0.0f)) {
        continue;
      }
      // Both must depart: motion moves the distances alone (its amplitude change is corrected),
      // and a region's amplitude ratio alone also moves with in-camera scattering's residue and
      // the contrast's small variations, which leave the distances within a few mm.
      const double ratio_w = sum_rw[c], gap_w = sum_gw[c];
      const double ratio_mean = sum_rs[c] / ratio_w - median;
      const bool ratio_departs = std::abs(ratio_mean) > std::max(k / std::sqrt(ratio_w), log_floor);
      const bool gap_departs =
          std::abs(sum_gs[c] / gap_w) > std::max(k / std::sqrt(gap_w), options.min_tolerance_m);
      if (ratio_departs && gap_departs) {
        // As every pixel the pair flags with two frequencies: its own reading, unwrapped, with
        // its own ΔL, not the average of two readings that sum two returns.
        flags[i] |= Flag::kInconsistent;
        current.radial_distance_m[i] = in.distance[centre + c];
        current.delta_l_m[i] = std::sqrt(in.sigma2[centre + c]);
      }
    }
  }
}

}  // namespace

void FramePairOptions::Validate() const {
  if (!(max_range_m > 0.0 && max_range_m <= 1000.0)) {
    Bad("frame pair max_range_m = " + std::to_string(max_range_m) + " must be in (0, 1000]");
  }
  if (!(max_disagreement_sigma > 0.0 && max_disagreement_sigma <= 1000.0)) {
    Bad("frame pair max_disagreement_sigma = " + std::to_string(max_disagreement_sigma) +
        " must be in (0, 1000]");
  }
  if (!(min_tolerance_m >= 0.0 && min_tolerance_m <= 10.0)) {
    Bad("frame pair min_tolerance_m = " + std::to_string(min_tolerance_m) + " must be in [0, 10]");
  }
  if (!(max_amplitude_ratio == 0.0 || (max_amplitude_ratio >= 1.0 && max_amplitude_ratio <= 1e6))) {
    Bad("frame pair max_amplitude_ratio = " + std::to_string(max_amplitude_ratio) +
        " must be 0 (no check) or in [1, 1e6]");
  }
  if (!(max_amplitude_disagreement_sigma >= 0.0 && max_amplitude_disagreement_sigma <= 1000.0)) {
    Bad("frame pair max_amplitude_disagreement_sigma = " +
        std::to_string(max_amplitude_disagreement_sigma) + " must be in [0, 1000] (0: no check)");
  }
  if (!(max_motion_m >= 0.0 && max_motion_m <= 10.0)) {
    Bad("frame pair max_motion_m = " + std::to_string(max_motion_m) +
        " must be in [0, 10] (0: no motion allowed)");
  }
  if (!(min_amplitude_tolerance >= 0.0 && min_amplitude_tolerance <= 1.0)) {
    Bad("frame pair min_amplitude_tolerance = " + std::to_string(min_amplitude_tolerance) +
        " must be in [0, 1]");
  }
  if (!(two_returns_radius_px >= 0 && two_returns_radius_px <= kMaxTwoReturnsRadiusPx)) {
    Bad("frame pair two_returns_radius_px = " + std::to_string(two_returns_radius_px) +
        " must be in [0, " + std::to_string(kMaxTwoReturnsRadiusPx) + "] (0: per pixel only)");
  }
}

void CombineFramePair(const MetricFrame& previous, MetricFrame& current,
                      const FramePairOptions& options) {
  options.Validate();
  const int w = current.width(), h = current.height();
  if (previous.width() != w || previous.height() != h || !previous.flags.SameSize(w, h) ||
      !current.flags.SameSize(w, h)) {
    Bad("frame pair: the two frames differ in size");
  }
  if (!previous.delta_l_m.SameSize(w, h) || !current.delta_l_m.SameSize(w, h)) {
    Bad("frame pair: both frames need ΔL (enable the accuracy stage)");
  }
  const double f1 = previous.info.modulation_frequency_hz;
  const double f2 = current.info.modulation_frequency_hz;
  // Up to 1 GHz (CW ToF cameras modulate at tens to a few hundred MHz): the wrap search tries
  // every count up to max_range_m / L, which a far higher frequency would make endless.
  constexpr double kMaxFrequencyHz = 1e9;
  if (!(f1 > 0.0 && f1 <= kMaxFrequencyHz) || !(f2 > 0.0 && f2 <= kMaxFrequencyHz)) {
    Bad("frame pair: modulation frequencies must be in (0, 1 GHz]");
  }
  const double l1 = UnambiguousRangeM(f1), l2 = UnambiguousRangeM(f2);
  const bool dual = f1 != f2;
  double range = options.max_range_m;
  if (dual) {
    const long long g = std::gcd(std::llround(f1), std::llround(f2));
    if (g > 0) range = std::min(range, UnambiguousRangeM(static_cast<double>(g)));
  }
  const int max_n1 = dual ? static_cast<int>(std::floor(range / l1)) : 0;
  // Amplitudes compare per µs of exposure; without known times only equal exposures compare.
  const double t1 = previous.info.integration_time_us, t2 = current.info.integration_time_us;
  double amplitude_scale = 0.0;  // A1 x scale is comparable with A2; 0 = no check
  if (options.max_amplitude_ratio > 0.0) {
    if (t1 > 0.0 && t2 > 0.0) {
      amplitude_scale = t2 / t1;
    } else if (previous.info.integration_time_register == current.info.integration_time_register) {
      amplitude_scale = 1.0;
    }
  }
  const double max_log_ratio = amplitude_scale > 0.0 ? std::log(options.max_amplitude_ratio) : 0.0;
  const bool amplitudes = amplitude_scale > 0.0 && previous.amplitude.SameSize(w, h) &&
                          current.amplitude.SameSize(w, h);
  const std::size_t n = current.radial_distance_m.size();
  // ln(A2 / A1) of each pixel good in both frames with both amplitudes positive (0 elsewhere:
  // no check reads it), computed once for the median and the per-pixel checks below. std::log is
  // a library call per value; twice per pixel it was a fifth of the combination's time.
  thread_local std::vector<double> log_ratios;
  // Two frequencies: the pair's median log amplitude ratio (per µs) over the pixels good in
  // both (at least kMinPixelsForMedian of them), the reference the per-pixel amplitude check
  // compares with (the demodulation contrast, and so the amplitude per µs, differs by frequency on
  // a real camera).
  const bool two_returns_check =
      dual && amplitudes && options.max_amplitude_disagreement_sigma > 0.0;
  double median_log_ratio = 0.0;
  if (amplitudes) {
    thread_local std::vector<double> logs;
    logs.clear();
    log_ratios.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double a1 = previous.amplitude[i] * amplitude_scale, a2 = current.amplitude[i];
      const bool both = Good(previous, i) && Good(current, i) && a1 > 0.0 && a2 > 0.0;
      log_ratios[i] = both ? std::log(a2 / a1) : 0.0;
      // NaN (two infinite amplitudes) left out: nth_element needs an order.
      if (two_returns_check && both && !std::isnan(log_ratios[i])) logs.push_back(log_ratios[i]);
    }
    // Too few pixels to tell the camera's ratio from the scene's: equal contrast assumed.
    if (logs.size() >= kMinPixelsForMedian) {
      median_log_ratio = filters_internal::KthSmallest(logs, logs.size() / 2);
    }
  }
  const double log_floor = std::log1p(options.min_amplitude_tolerance);
  // Within half the wrap separation a motion's own pair is the only one that close.
  const double motion_bound = std::min(options.max_motion_m, 0.5 * std::abs(l1 - l2));
  // Two frequencies: the wrap search for blocks of pixels at a time (its scratch stays in cache).
  constexpr std::size_t kBlock = 1024;
  thread_local std::vector<double> search;
  search.resize(4 * kBlock);
  double* const search_a = search.data();
  double* const search_b = search_a + kBlock;
  double* const search_best = search_b + kBlock;
  double* const search_second = search_best + kBlock;
  // The pooled two-returns check's inputs.
  const bool pooled = two_returns_check && options.two_returns_radius_px > 0;
  thread_local PooledInputs pooled_inputs;
  if (pooled) pooled_inputs.Reset(w, h, options.two_returns_radius_px);
  std::size_t block_start = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (dual && i % kBlock == 0) {
      block_start = i;
      WrapSearch(std::min(kBlock, n - i), previous.radial_distance_m.data() + i,
                 current.radial_distance_m.data() + i, l1, l2, max_n1, search_a, search_b,
                 search_best, search_second);
    }
    const bool ok1 = Good(previous, i), ok2 = Good(current, i);
    if (!ok1 && !ok2) continue;
    if (!ok1 || !ok2) {
      if (dual) {
        current.flags[i] |= Flag::kInconsistent;  // one phase alone cannot be unwrapped
      } else if (ok1) {
        // HDR: the other exposure clipped or failed here; this one did not.
        current.radial_distance_m[i] = previous.radial_distance_m[i];
        current.amplitude[i] = previous.amplitude[i];
        if (current.has_intensity() && previous.has_intensity()) {
          current.intensity[i] = previous.intensity[i];
        }
        current.delta_l_m[i] = previous.delta_l_m[i];
        current.flags[i] = previous.flags[i];
      }
      continue;
    }
    const double d1 = previous.radial_distance_m[i], d2 = current.radial_distance_m[i];
    const double s1 = previous.delta_l_m[i], s2 = current.delta_l_m[i];
    const double tolerance = std::max(options.max_disagreement_sigma * std::sqrt(s1 * s1 + s2 * s2),
                                      options.min_tolerance_m);
    double a = d1, b = d2;
    bool ambiguous = false;
    double second = 1e300;  // the second-best pair's disagreement (two frequencies)
    if (dual) {
      const std::size_t k = i - block_start;
      a = search_a[k];
      b = search_b[k];
      second = search_second[k];
      ambiguous = second <= tolerance;
    } else {
      a = d1 - l1 * std::round((d1 - d2) / l1);  // the same surface near the 0 / L seam
    }
    bool moved = false, two_returns = false;
    const bool disagree = !(std::abs(a - b) <= tolerance);
    if (amplitudes) {
      const double a1 = previous.amplitude[i] * amplitude_scale, a2 = current.amplitude[i];
      // Both positive or the check cannot tell (a zero amplitude has no phase anyway).
      const bool both = a1 > 0.0 && a2 > 0.0;
      const double log_ratio = both ? log_ratios[i] : 0.0;
      moved = both && std::abs(log_ratio) > max_log_ratio;
      if (two_returns_check && both) {
        const double p1 = 2 * kPi * s1 / l1, p2 = 2 * kPi * s2 / l2;  // σ of ln A per frame
        const double variance = p1 * p1 + p2 * p2;
        const double allowed =
            std::max(options.max_amplitude_disagreement_sigma * std::sqrt(variance), log_floor);
        two_returns = std::abs(log_ratio - median_log_ratio) > allowed;
        const bool within_motion =
            !disagree || (std::abs(a - b) <= motion_bound && !(second <= motion_bound));
        if (pooled && within_motion && !ambiguous && !moved && a > 0.0 && b > 0.0) {
          const double gap_variance = s1 * s1 + s2 * s2;
          const double corrected = log_ratio + 2.0 * LogRatio(b, a);
          // Infinite amplitudes have no ratio (inf / inf): out of the median and the sums.
          if (variance > 0.0 && gap_variance > 0.0 && std::isfinite(corrected)) {
            pooled_inputs.Record(i, b, s2, corrected, variance, a - b, gap_variance);
          }
        }
      }
    }
    if (dual && disagree && std::abs(a - b) <= motion_bound && !(second <= motion_bound) &&
        !moved && !two_returns) {
      // Motion: one wrap count explains it; the average would be neither reading.
      current.radial_distance_m[i] = static_cast<float>(b);
      continue;
    }
    if (disagree || ambiguous || moved || two_returns) {
      current.flags[i] |= Flag::kInconsistent;
      if (dual) current.radial_distance_m[i] = static_cast<float>(b);
      continue;
    }
    const double w1 = Weight(previous.delta_l_m[i]), w2 = Weight(current.delta_l_m[i]);
    const double sum = w1 + w2;
    current.radial_distance_m[i] =
        static_cast<float>(sum > 0.0 ? (w1 * a + w2 * b) / sum : 0.5 * (a + b));
    if (sum > 0.0) current.delta_l_m[i] = static_cast<float>(1.0 / std::sqrt(sum));
  }
  if (pooled) {
    PooledTwoReturnsCheck(w, h, options, log_floor, median_log_ratio, pooled_inputs, current);
  }
}

FramePairCombiner::FramePairCombiner(const FramePairOptions& options, bool pair_exposures)
    : options_(options), pair_exposures_(pair_exposures) {
  options_.Validate();
}

bool FramePairCombiner::Process(MetricFrame& frame) {
  const bool differs =
      previous_.has_value() &&
      (previous_->info.modulation_frequency_hz != frame.info.modulation_frequency_hz ||
       (pair_exposures_ &&
        previous_->info.integration_time_register != frame.info.integration_time_register)) &&
      previous_->width() == frame.width() && previous_->height() == frame.height();
  if (!differs) {
    previous_ = frame;
    return false;
  }
  // The frame as it came in becomes the next previous one. Copied into buffers kept from frame
  // to frame (copy assignment reuses their capacity) instead of a fresh frame each time.
  spare_ = frame;
  CombineFramePair(*previous_, frame, options_);
  std::swap(*previous_, spare_);
  return true;
}

void WrapCheckOptions::Validate() const {
  if (!(envelope_quantile > 0.0 && envelope_quantile <= 1.0)) {
    Bad("wrap check envelope_quantile = " + std::to_string(envelope_quantile) +
        " must be in (0, 1]");
  }
  if (!(margin > 0.0 && margin <= 10.0)) {
    Bad("wrap check margin = " + std::to_string(margin) + " must be in (0, 10]");
  }
}

Image<PixelFlags> WrapCheckFilter(const MetricFrame& frame, const RayTable& rays,
                                  const WrapCheckOptions& options) {
  options.Validate();
  const int w = frame.width(), h = frame.height();
  if (w <= 0 || h <= 0 || !frame.amplitude.SameSize(w, h) || !frame.flags.SameSize(w, h)) {
    Bad("wrap check: empty frame or channels of different sizes");
  }
  if (!rays.x.SameSize(w, h) || !rays.y.SameSize(w, h) || !rays.z.SameSize(w, h)) {
    throw Error(ErrorCode::kMismatch, "wrap check: the ray table differs in size from the frame");
  }
  Image<PixelFlags> out(w, h);
  const double range = UnambiguousRangeM(frame.info.modulation_frequency_hz);
  auto point = [&](int r, int c, double p[3]) {
    const std::size_t i = static_cast<std::size_t>(r) * w + c;
    const double d = frame.radial_distance_m[i];
    p[0] = d * rays.x[i];
    p[1] = d * rays.y[i];
    p[2] = d * rays.z[i];
  };
  // cos θ from the cross product of the differences to a horizontal and a vertical neighbour
  // (whichever side is good); 1 where no neighbours are good.
  auto cosine = [&](int r, int c) {
    const std::size_t i = static_cast<std::size_t>(r) * w + c;
    const int cn =
        c + 1 < w && Good(frame, i + 1) ? c + 1 : (c > 0 && Good(frame, i - 1) ? c - 1 : -1);
    const int rn = r + 1 < h && Good(frame, i + static_cast<std::size_t>(w))
                       ? r + 1
                       : (r > 0 && Good(frame, i - static_cast<std::size_t>(w)) ? r - 1 : -1);
    if (cn < 0 || rn < 0) return 1.0;
    double p[3], a[3], b[3];
    point(r, c, p);
    point(r, cn, a);
    point(rn, c, b);
    for (int k = 0; k < 3; ++k) {
      a[k] -= p[k];
      b[k] -= p[k];
    }
    const double n[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                         a[0] * b[1] - a[1] * b[0]};
    const double norm = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(norm > 0.0)) return 1.0;
    const double dot = std::abs(n[0] * rays.x[i] + n[1] * rays.y[i] + n[2] * rays.z[i]) / norm;
    return std::max(dot, 0.2);
  };
  Image<float> albedo(w, h, 0.0f);
  std::vector<double> brightness;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      if (!Good(frame, i) || !(frame.amplitude[i] > 0.0f)) continue;
      const double d = frame.radial_distance_m[i];
      albedo[i] = static_cast<float>(frame.amplitude[i] * d * d / cosine(r, c));
      brightness.push_back(albedo[i]);
    }
  }
  if (brightness.empty()) return out;
  const std::size_t k = std::min(
      brightness.size() - 1,
      static_cast<std::size_t>(options.envelope_quantile * static_cast<double>(brightness.size())));
  std::nth_element(brightness.begin(), brightness.begin() + static_cast<std::ptrdiff_t>(k),
                   brightness.end());
  const double envelope = brightness[k];
  for (std::size_t i = 0; i < frame.flags.size(); ++i) {
    if (!Good(frame, i)) continue;
    const double d = frame.radial_distance_m[i];
    const double ratio = d / (d + range);
    if (albedo[i] < options.margin * envelope * ratio * ratio) {
      out[i] = PixelFlags(Flag::kInconsistent);
    }
  }
  return out;
}

}  // namespace tofcam
