#include "tofcam/calibration/offset_calibration.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "../core/avx512_forms.h"
#include "../filters/hot_loop.h"
#include "../pipeline/stage_kernels.h"
#include "calibration_kernel.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

// The hand-written table kernels (Eq1IntervalsAvx2, Eq1Intervals16): x86-64 GCC or clang, and
// not under AddressSanitizer (hot_loop.h sets TOFCAM_NO_CLONES there), so that the sanitizer
// build checks the portable loop the kernels are tested against; the same condition as
// TOFCAM_AVX512_FORMS (src/core/avx512_forms.h), which guards the AVX-512 one.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(TOFCAM_NO_CLONES)
#include <immintrin.h>
#define TOFCAM_EQ1_AVX2 1
#else
#define TOFCAM_EQ1_AVX2 0
#endif

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& message) {
  throw Error(ErrorCode::kInvalidArgument, "calibration: " + message);
}

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

// Catmull-Rom through knots k-1..k+2 (end knots repeated) at t in [0, 1] of segment k.
double CatmullRom(const std::vector<float>& p, std::size_t k, double t) {
  const std::size_t n = p.size();
  const double p0 = p[k == 0 ? 0 : k - 1];
  const double p1 = p[k];
  const double p2 = p[k + 1];
  const double p3 = p[std::min(k + 2, n - 1)];
  return p1 + 0.5 * t *
                  ((p2 - p0) +
                   t * ((2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) + t * (3.0 * (p1 - p2) + p3 - p0)));
}

// max |g''| over segment k in units of 1/step^2: g''(t) = A2 + 3 A3 t is linear in t, so its
// extremes are at t = 0 and t = 1.
double MaxSecondDerivative(const std::vector<float>& p, std::size_t k) {
  const std::size_t n = p.size();
  const double p0 = p[k == 0 ? 0 : k - 1];
  const double p1 = p[k];
  const double p2 = p[k + 1];
  const double p3 = p[std::min(k + 2, n - 1)];
  const double a2 = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
  const double a3 = 3.0 * (p1 - p2) + p3 - p0;
  return std::max(std::abs(a2), std::abs(a2 + 3.0 * a3));
}

}  // namespace

double DistanceCorrection::Evaluate(double distance_m) const noexcept {
  const std::size_t n = correction_m.size();
  if (n == 0) return 0.0;
  if (n == 1) return correction_m[0];
  const double x = (distance_m - start_m) / step_m;
  if (!(x > 0.0)) return correction_m.front();  // also NaN
  const double last = static_cast<double>(n - 1);
  if (x >= last) return correction_m.back();
  const auto k = static_cast<std::size_t>(x);
  return CatmullRom(correction_m, k, x - static_cast<double>(k));
}

void DistanceCorrection::Validate() const {
  if (!std::isfinite(start_m) || start_m < 0.0) {
    Bad("distance_correction.start_m = " + Num(start_m) + " must be >= 0");
  }
  if (!std::isfinite(step_m) || step_m <= 0.0) {
    Bad("distance_correction.step_m = " + Num(step_m) + " must be > 0");
  }
  if (correction_m.size() < 2 || correction_m.size() > (1u << 20)) {
    Bad("distance_correction.correction_m has " + std::to_string(correction_m.size()) +
        " knots, need 2..2^20");
  }
  for (std::size_t i = 0; i < correction_m.size(); ++i) {
    if (!std::isfinite(correction_m[i])) {
      Bad("distance_correction.correction_m[" + std::to_string(i) + "] is not finite");
    }
  }
}

namespace {

void FillIntervals(DenseDistanceCorrection& d) {
  const std::vector<float>& v = d.values_m;
  d.intervals_m.resize(2 * (v.size() - 1));
  for (std::size_t j = 0; j + 1 < v.size(); ++j) {
    d.intervals_m[2 * j] = v[j];
    d.intervals_m[2 * j + 1] = v[j + 1] - v[j];  // the loop's own difference, in float
  }
}

}  // namespace

DenseDistanceCorrection DenseDistanceCorrection::Resample(const DistanceCorrection& g,
                                                          double range_m, double max_step_m) {
  g.Validate();
  if (!(range_m > 0.0) || !std::isfinite(range_m)) {
    Bad("dense distance correction: range " + Num(range_m) + " m must be > 0");
  }
  if (!(max_step_m > 0.0 && max_step_m <= 1.0)) {
    Bad("dense distance correction: step " + Num(max_step_m) + " m must be in (0, 1]");
  }
  const std::vector<float>& knots = g.correction_m;
  const std::size_t segments = knots.size() - 1;
  const double end_m = g.start_m + static_cast<double>(segments) * g.step_m;
  DenseDistanceCorrection d;
  const double lo = std::max(0.0, g.start_m);
  const double hi = std::min(range_m, end_m);
  if (!(hi > lo)) {
    // No knot interval overlaps [0, L]: g is one end value there.
    const float v = g.start_m >= range_m ? knots.front() : knots.back();
    d.origin_m = 0.0;
    d.step_m = range_m;
    d.values_m.assign(2, v);
    FillIntervals(d);
    return d;
  }
  // k samples per knot interval, so knots are samples and g is one cubic per sample interval.
  std::size_t k =
      std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(g.step_m / max_step_m - 1e-9)));
  std::size_t j_lo = 0, j_hi = 0;
  for (;;) {
    const double h = g.step_m / static_cast<double>(k);
    j_lo = static_cast<std::size_t>(std::floor((lo - g.start_m) / h));
    j_hi = std::min(static_cast<std::size_t>(std::ceil((hi - g.start_m) / h)), segments * k);
    if (j_hi - j_lo + 1 <= kMaxSamples || k == 1) break;
    k = std::max<std::size_t>(1, k * (kMaxSamples - 2) / (j_hi - j_lo + 1));
  }
  if (j_hi == j_lo) ++j_hi;  // at least two samples (j_hi <= segments * k still holds)
  const double h = g.step_m / static_cast<double>(k);
  d.step_m = h;
  d.origin_m = g.start_m + static_cast<double>(j_lo) * h;
  d.values_m.resize(j_hi - j_lo + 1);
  double max_g2 = 0.0;
  for (std::size_t j = j_lo; j <= j_hi; ++j) {
    const std::size_t seg = std::min(j / k, segments - 1);
    const double t = static_cast<double>(j - seg * k) / static_cast<double>(k);
    d.values_m[j - j_lo] = static_cast<float>(CatmullRom(knots, seg, t));
    if (j < j_hi) max_g2 = std::max(max_g2, MaxSecondDerivative(knots, seg));
  }
  d.max_interpolation_error_m = h * h / 8.0 * max_g2 / (g.step_m * g.step_m);
  FillIntervals(d);
  return d;
}

float DenseDistanceCorrection::Evaluate(float distance_m) const noexcept {
  const float inv_step = static_cast<float>(1.0 / step_m);
  const float last = static_cast<float>(values_m.size() - 1);
  float x = (distance_m - static_cast<float>(origin_m)) * inv_step;
  x = x > 0.0f ? x : 0.0f;  // also NaN
  x = std::min(x, last);
  const int i = std::min(static_cast<int>(x), static_cast<int>(values_m.size()) - 2);
  const float t = x - static_cast<float>(i);
  return values_m[i] + t * (values_m[i + 1] - values_m[i]);
}

void NoiseCalibration::Validate() const {
  if (!std::isfinite(delta_l_scale) || delta_l_scale <= 0.0 || delta_l_scale > 1e6) {
    Bad("noise.delta_l_scale = " + Num(delta_l_scale) + " must be in (0, 1e6]");
  }
  if (!std::isfinite(r_squared) || r_squared > 1.0 || r_squared < -1e9) {
    Bad("noise.r_squared = " + Num(r_squared) + " must be finite and <= 1");
  }
  if (frames < 0 || pixels_used < 0) Bad("noise.frames and noise.pixels_used must be >= 0");
  if (model) model->Validate();
  for (double v : {model_spearman, eq2_spearman}) {
    if (!(v >= -1.0 && v <= 1.0)) Bad("noise.model spearman values must be in [-1, 1]");
  }
  if (!(model_max_decile_error >= 0.0) || !std::isfinite(model_max_decile_error)) {
    Bad("noise.model.held_out_max_decile_error must be finite and >= 0");
  }
}

void ScatteringCalibration::Validate() const {
  if (lobes.empty() || lobes.size() > 2) {
    Bad("scattering: " + std::to_string(lobes.size()) + " lobes, expected 1 or 2");
  }
  ScatteringOptions psf;
  psf.lobes = lobes;
  try {
    psf.Validate();
  } catch (const Error& e) {
    Bad(std::string("scattering: ") + e.what());
  }
  if (frames < 1) Bad("scattering.frames = " + std::to_string(frames) + " must be >= 1");
  if (integration_time_register < 0 || target_pixels < 0 || fit_pixels < 0) {
    Bad("scattering: register and pixel counts must be >= 0");
  }
  if (!(explained_fraction >= 0.0 && explained_fraction <= 1.0)) {
    Bad("scattering.explained_fraction = " + Num(explained_fraction) + " must be in [0, 1]");
  }
}

void OffsetCalibration::Validate() const {
  if (version != kVersion) Bad("version " + std::to_string(version) + " is not supported");
  if (width <= 0 || height <= 0) {
    Bad("size " + std::to_string(width) + "x" + std::to_string(height) + " must be positive");
  }
  if (!std::isfinite(modulation_frequency_hz) || modulation_frequency_hz <= 0.0) {
    Bad("modulation_frequency_hz = " + Num(modulation_frequency_hz) + " must be > 0");
  }
  if (!std::isfinite(integration_time_us) || integration_time_us < 0.0) {
    Bad("integration_time_us = " + Num(integration_time_us) + " must be >= 0");
  }
  if (!std::isfinite(wall_distance_m) || wall_distance_m < 0.0) {
    Bad("wall_distance_m = " + Num(wall_distance_m) + " must be >= 0");
  }
  for (double v : wall_normal) {
    if (!std::isfinite(v)) Bad("wall_normal is not finite");
  }
  if (frames_averaged < 0) Bad("frames_averaged must be >= 0");
  if (!offset_m.SameSize(width, height)) {
    Bad("offset matrix is " + std::to_string(offset_m.width()) + "x" +
        std::to_string(offset_m.height()) + ", header says " + std::to_string(width) + "x" +
        std::to_string(height));
  }
  const double half_range = UnambiguousRangeM(modulation_frequency_hz) / 2.0;
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      const float o = offset_m(r, c);
      if (!std::isfinite(o) || std::abs(o) > half_range) {
        Bad("offset at row " + std::to_string(r) + ", col " + std::to_string(c) + " = " + Num(o) +
            " m is not finite or beyond ±L/2 = " + Num(half_range) + " m");
      }
    }
  }
  if (!pixel_flags.empty() && !pixel_flags.SameSize(width, height)) {
    Bad("pixel_flags size differs from the offset matrix");
  }
  if (distance_correction) distance_correction->Validate();
  if (!std::isfinite(exposure_offset_m_per_ms) || std::abs(exposure_offset_m_per_ms) > 0.1) {
    Bad("exposure_offset_m_per_ms = " + Num(exposure_offset_m_per_ms) +
        " must be finite and within ±0.1 m/ms");
  }
  // The exposure term is s (t - t_cal): without t_cal it would shift every frame by s t.
  if (exposure_offset_m_per_ms != 0.0 && !(integration_time_us > 0.0)) {
    Bad("exposure_offset_m_per_ms = " + Num(exposure_offset_m_per_ms) +
        " needs the calibration's integration_time_us (t_cal), which is " +
        Num(integration_time_us));
  }
  if (noise) noise->Validate();
  if (controller_setpoint) controller_setpoint->Validate();
  if (scattering) scattering->Validate();
}

double ExposureShiftM(const OffsetCalibration& calibration, double integration_time_us) noexcept {
  if (!(integration_time_us > 0.0) || !std::isfinite(integration_time_us) ||
      calibration.exposure_offset_m_per_ms == 0.0) {
    return 0.0;
  }
  return calibration.exposure_offset_m_per_ms *
         (integration_time_us - calibration.integration_time_us) * 1e-3;
}

namespace calibration_internal {

CalibrationPlan MakePlan(const MetricFrame& frame, const OffsetCalibration& calibration,
                         const DenseDistanceCorrection* table) {
  const int w = frame.width();
  const int h = frame.height();
  if (w != calibration.width || h != calibration.height || !calibration.offset_m.SameSize(w, h)) {
    throw Error(ErrorCode::kMismatch, "calibration is " + std::to_string(calibration.width) + "x" +
                                          std::to_string(calibration.height) + ", frame is " +
                                          std::to_string(w) + "x" + std::to_string(h));
  }
  if (!frame.flags.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument, "ApplyCalibration: frame flags differ in size");
  }
  const double f = frame.info.modulation_frequency_hz;
  if (!(std::abs(f - calibration.modulation_frequency_hz) <=
        1e-9 * calibration.modulation_frequency_hz)) {
    throw Error(ErrorCode::kMismatch, "calibration was made at " +
                                          Num(calibration.modulation_frequency_hz) +
                                          " Hz, frame is at " + Num(f) + " Hz");
  }
  const float range = static_cast<float>(UnambiguousRangeM(f));
  // Exposure offset (format v2): a per-frame scalar folded into the constant of eq. 1,
  // l = (m - o - shift + L) mod L. |shift| <= L/4 keeps m - o - shift + L in [L/4, 11L/4), so
  // the two conditional subtractions in the loop stay exact.
  const double shift_m = ExposureShiftM(calibration, frame.info.integration_time_us);
  if (!(std::abs(shift_m) <= 0.25 * range)) {
    throw Error(ErrorCode::kInvalidArgument,
                "calibration: exposure offset " + Num(calibration.exposure_offset_m_per_ms) +
                    " m/ms at " + Num(frame.info.integration_time_us) + " us gives a shift of " +
                    Num(shift_m) + " m, beyond L/4");
  }
  CalibrationPlan plan;
  plan.offset_m = calibration.offset_m.data();
  plan.pixel_flags = calibration.pixel_flags.empty() ? nullptr : calibration.pixel_flags.data();
  plan.range_m = range;
  plan.bias_m = static_cast<float>(UnambiguousRangeM(f) - shift_m);
  if (calibration.distance_correction && table != nullptr) {
    // Catmull-Rom weights have an absolute sum of at most 1.25, so |g| <= 1.25 max |knot|; the
    // wrap in the loop needs |g| < L/2 (the table's samples are values of g).
    float largest = 0.0f;
    for (float v : calibration.distance_correction->correction_m) {
      largest = std::max(largest, std::abs(v));
    }
    if (!(1.25f * largest < 0.5f * range)) {
      throw Error(ErrorCode::kInvalidArgument, "calibration: distance correction up to " +
                                                   Num(largest) +
                                                   " m is too large for L = " + Num(range) + " m");
    }
    plan.table = table;
    plan.table_origin_m = static_cast<float>(table->origin_m);
    plan.table_inv_step = static_cast<float>(1.0 / table->step_m);
    plan.table_last = static_cast<float>(table->values_m.size() - 1);
    plan.table_last_segment = static_cast<int>(table->values_m.size()) - 2;
    if (table->intervals_m.size() == 2 * (table->values_m.size() - 1)) {
      plan.table_intervals = table->intervals_m.data();
    }
  }
  return plan;
}

namespace {

// Eq. 1. With m in [0, L) and |o| <= L/2, m - o + bias lies in [L/4, 11L/4): at most two
// subtractions make the mod exact without a division. Branch-free, so it vectorises; kInvalid
// pixels keep their value.
TOFCAM_HOT_LOOP void Eq1(std::size_t n, float range, float bias, const float* __restrict o,
                         const PixelFlags* __restrict f, float* __restrict d) {
  for (std::size_t i = 0; i < n; ++i) {
    float l = d[i] - o[i] + bias;
    l -= l >= range ? range : 0.0f;
    l -= l >= range ? range : 0.0f;
    d[i] = f[i].Has(Flag::kInvalid) ? d[i] : l;
  }
}

// Eq. 1, then l' = (l - g(l) + L) mod L with g interpolated linearly in the dense table: two
// table reads (a gather in the AVX2 clone) instead of the Catmull-Rom segment search.
TOFCAM_HOT_LOOP void Eq1Table(std::size_t n, float range, float bias, const float* __restrict o,
                              const PixelFlags* __restrict f, float* __restrict d,
                              const float* __restrict table, float origin, float inv_step,
                              float last, int last_segment) {
  for (std::size_t i = 0; i < n; ++i) {
    float l = d[i] - o[i] + bias;
    l -= l >= range ? range : 0.0f;
    l -= l >= range ? range : 0.0f;
    float x = (l - origin) * inv_step;
    x = x > 0.0f ? x : 0.0f;  // NaN too: the index stays in the table
    x = std::min(x, last);
    const int k = std::min(static_cast<int>(x), last_segment);  // int32: SSE2 converts it
    const float t = x - static_cast<float>(k);
    const float g0 = table[k];
    const float corr = g0 + t * (table[k + 1] - g0);
    // |corr| < L/2 (MakePlan), so l - corr + L is in (L/2, 3L/2): one subtraction wraps it.
    float v = l - corr + range;
    v -= v >= range ? range : 0.0f;
    d[i] = f[i].Has(Flag::kInvalid) ? d[i] : v;
  }
}

#if TOFCAM_EQ1_AVX2
// Pair j of the interval table, (g_j, g_{j+1} - g_j), as one 64-bit integer; memcpy, not a cast,
// keeps the read well defined. Inlined into both interval kernels (a baseline function inlines
// into a function of a wider target).
[[gnu::always_inline]] inline long long IntervalPair(const float* intervals, std::int32_t j) {
  long long v;
  std::memcpy(&v, intervals + 2 * static_cast<std::ptrdiff_t>(j), sizeof v);
  return v;
}

// Eq1Table with the interval table (g_j, g_{j+1} - g_j): the two values a pixel needs are one
// 64-bit element. Written with intrinsics because GCC does not turn the paired reads into 64-bit
// reads; the same float operations in the same order as Eq1Table, so the same values bit for bit
// (tests/calibration/offset_calibration_test.cc). This file is compiled with -ffp-contract=off so
// that no compiler fuses either form's multiply-add into an FMA where the other is not (clang
// contracts the scalar loop's expression, never the separate intrinsics).
//
// Two passes over blocks of kBlock pixels. Pass 1 computes eq. 1's l, the table index k and the
// fraction t; pass 2 reads the pairs with scalar 64-bit loads and finishes. In one pass each
// group of 8 pixels is one long dependent chain (eq. 1, index, moves to integer registers, an L2
// read of the 60 KB table, shuffles, the rest: by count about 90 cycles), and too few groups fit
// in the reorder buffer to overlap them; one pass with scalar loads took 21 us in
// calibration_bench, two passes 19 us (and 14-16 us in tofcam bench). The pairs are read with
// scalar loads because the machine's vpgatherdq is slower than eight loads (a stand-alone test:
// 11-16 us against 8-9.5 us per SR-2 frame). Eq. 1 + table per SR-2 frame on the 2-core Zen 4
// test machine, three interleaved `tofcam bench` runs each: 22.8-23.8 us with two gathers in one
// pass, 14.0-14.4 us now (docs/benchmarks.md).
// Returns the pixels done (a multiple of 8); the caller finishes the rest with Eq1Table.
__attribute__((target("avx2"))) std::size_t Eq1IntervalsAvx2(
    std::size_t n, float range, float bias, const float* __restrict o, PixelFlags* __restrict f,
    const PixelFlags* __restrict extra_flags, float* __restrict d,
    const float* __restrict intervals, float origin, float inv_step, float last, int last_segment) {
  constexpr std::size_t kBlock = 256;
  alignas(32) float l_block[kBlock];
  alignas(32) float t_block[kBlock];
  alignas(32) std::int32_t k_block[kBlock];
  const __m256 vrange = _mm256_set1_ps(range), vbias = _mm256_set1_ps(bias);
  const __m256 vorigin = _mm256_set1_ps(origin), vinv = _mm256_set1_ps(inv_step);
  const __m256 vlast = _mm256_set1_ps(last), zero = _mm256_setzero_ps();
  const __m256i vseg = _mm256_set1_epi32(last_segment);
  const __m128i invalid = _mm_set1_epi16(static_cast<short>(Flag::kInvalid));
  const std::size_t done = n / 8 * 8;
  for (std::size_t begin = 0; begin < done; begin += kBlock) {
    const std::size_t len = std::min(kBlock, done - begin);
    const float* bo = o + begin;
    PixelFlags* bf = f + begin;
    float* bd = d + begin;
    for (std::size_t i = 0; i < len; i += 8) {
      __m256 l =
          _mm256_add_ps(_mm256_sub_ps(_mm256_loadu_ps(bd + i), _mm256_loadu_ps(bo + i)), vbias);
      // l -= l >= range ? range : 0, twice.
      l = _mm256_sub_ps(l, _mm256_and_ps(_mm256_cmp_ps(l, vrange, _CMP_GE_OQ), vrange));
      l = _mm256_sub_ps(l, _mm256_and_ps(_mm256_cmp_ps(l, vrange, _CMP_GE_OQ), vrange));
      __m256 x = _mm256_mul_ps(_mm256_sub_ps(l, vorigin), vinv);
      x = _mm256_and_ps(_mm256_cmp_ps(x, zero, _CMP_GT_OQ), x);  // x > 0 ? x : 0 (NaN -> 0)
      x = _mm256_min_ps(x, vlast);  // x < last ? x : last, as std::min(x, last)
      const __m256i k = _mm256_min_epi32(_mm256_cvttps_epi32(x), vseg);
      _mm256_store_ps(l_block + i, l);
      _mm256_store_ps(t_block + i, _mm256_sub_ps(x, _mm256_cvtepi32_ps(k)));
      _mm256_store_si256(reinterpret_cast<__m256i*>(k_block + i), k);
    }
    for (std::size_t i = 0; i < len; i += 8) {
      // The (g0, dg) pairs of pixels 0-7, deinterleaved into g0 and dg.
      const std::int32_t* k = k_block + i;
      const __m128i p01 =
          _mm_set_epi64x(IntervalPair(intervals, k[1]), IntervalPair(intervals, k[0]));
      const __m128i p23 =
          _mm_set_epi64x(IntervalPair(intervals, k[3]), IntervalPair(intervals, k[2]));
      const __m128i p45 =
          _mm_set_epi64x(IntervalPair(intervals, k[5]), IntervalPair(intervals, k[4]));
      const __m128i p67 =
          _mm_set_epi64x(IntervalPair(intervals, k[7]), IntervalPair(intervals, k[6]));
      // Pixels 0, 1, 4, 5 and 2, 3, 6, 7, so that the in-lane shuffles give pixel order.
      const __m256 lo = _mm256_castsi256_ps(_mm256_set_m128i(p45, p01));
      const __m256 hi = _mm256_castsi256_ps(_mm256_set_m128i(p67, p23));
      const __m256 g0 = _mm256_shuffle_ps(lo, hi, _MM_SHUFFLE(2, 0, 2, 0));
      const __m256 dg = _mm256_shuffle_ps(lo, hi, _MM_SHUFFLE(3, 1, 3, 1));
      const __m256 corr = _mm256_add_ps(g0, _mm256_mul_ps(_mm256_load_ps(t_block + i), dg));
      __m256 v = _mm256_add_ps(_mm256_sub_ps(_mm256_load_ps(l_block + i), corr), vrange);
      v = _mm256_sub_ps(v, _mm256_and_ps(_mm256_cmp_ps(v, vrange, _CMP_GE_OQ), vrange));
      // kInvalid pixels (before the calibration's flags are OR-ed in) keep their value.
      auto* flags_at = reinterpret_cast<__m128i*>(bf + i);
      const __m128i flags = _mm_loadu_si128(flags_at);
      const __m128i bad16 = _mm_cmpeq_epi16(_mm_and_si128(flags, invalid), invalid);
      const __m256 bad = _mm256_castsi256_ps(_mm256_cvtepi16_epi32(bad16));
      _mm256_storeu_ps(bd + i, _mm256_blendv_ps(v, _mm256_loadu_ps(bd + i), bad));
      if (extra_flags != nullptr) {
        const auto* extra = reinterpret_cast<const __m128i*>(extra_flags + begin + i);
        _mm_storeu_si128(flags_at, _mm_or_si128(flags, _mm_loadu_si128(extra)));
      }
    }
  }
  return done;
}

// Eq1IntervalsAvx2 for AVX-512 CPUs: the same two passes, sixteen pixels a step. The pair reads
// stay scalar 64-bit loads (as many per pixel as in the AVX2 form: the hardware gather was
// measured slower, 19-23 us against 14-15 us per SR-2 frame for qword gathers and 33 us for two
// dword gathers); the arithmetic, the flags and the deinterleave take half the instructions.
// The same float operations in the same order, so the same values bit for bit
// (tests/calibration/offset_calibration_test.cc runs both forms against eq. 1 and the table).
#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
TOFCAM_AVX512_TARGET std::size_t Eq1Intervals16(std::size_t n, float range, float bias,
                                                const float* __restrict o, PixelFlags* __restrict f,
                                                const PixelFlags* __restrict extra_flags,
                                                float* __restrict d,
                                                const float* __restrict intervals, float origin,
                                                float inv_step, float last, int last_segment) {
  constexpr std::size_t kBlock = 256;
  alignas(64) float l_block[kBlock];
  alignas(64) float t_block[kBlock];
  alignas(64) std::int32_t k_block[kBlock];
  const __m512 vrange = _mm512_set1_ps(range), vbias = _mm512_set1_ps(bias);
  const __m512 vorigin = _mm512_set1_ps(origin), vinv = _mm512_set1_ps(inv_step);
  const __m512 vlast = _mm512_set1_ps(last), zero = _mm512_setzero_ps();
  const __m512i vseg = _mm512_set1_epi32(last_segment);
  const __m256i invalid = _mm256_set1_epi16(static_cast<short>(Flag::kInvalid));
  // Lanes 0, 2, .. 30 (g0) and 1, 3, .. 31 (dg) of the 16 pairs in two registers.
  const __m512i evens =
      _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
  const __m512i odds = _mm512_add_epi32(evens, _mm512_set1_epi32(1));
  // Pairs k[0..3] as one 256-bit register, in order (a macro: a lambda would not inherit the
  // function's target).
#define TOFCAM_FOUR_PAIRS(k)                                                          \
  _mm256_set_epi64x(IntervalPair(intervals, (k)[3]), IntervalPair(intervals, (k)[2]), \
                    IntervalPair(intervals, (k)[1]), IntervalPair(intervals, (k)[0]))
  const std::size_t done = n / 16 * 16;
  for (std::size_t begin = 0; begin < done; begin += kBlock) {
    const std::size_t len = std::min(kBlock, done - begin);
    const float* bo = o + begin;
    PixelFlags* bf = f + begin;
    float* bd = d + begin;
    for (std::size_t i = 0; i < len; i += 16) {
      __m512 l =
          _mm512_add_ps(_mm512_sub_ps(_mm512_loadu_ps(bd + i), _mm512_loadu_ps(bo + i)), vbias);
      // l -= l >= range ? range : 0, twice.
      l = _mm512_mask_sub_ps(l, _mm512_cmp_ps_mask(l, vrange, _CMP_GE_OQ), l, vrange);
      l = _mm512_mask_sub_ps(l, _mm512_cmp_ps_mask(l, vrange, _CMP_GE_OQ), l, vrange);
      __m512 x = _mm512_mul_ps(_mm512_sub_ps(l, vorigin), vinv);
      x = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(x, zero, _CMP_GT_OQ), x);  // NaN -> 0
      x = _mm512_min_ps(x, vlast);  // x < last ? x : last, as std::min(x, last)
      const __m512i k = _mm512_min_epi32(_mm512_cvttps_epi32(x), vseg);
      _mm512_store_ps(l_block + i, l);
      _mm512_store_ps(t_block + i, _mm512_sub_ps(x, _mm512_cvtepi32_ps(k)));
      _mm512_store_si512(k_block + i, k);
    }
    for (std::size_t i = 0; i < len; i += 16) {
      const std::int32_t* k = k_block + i;
      const __m512i p0 = _mm512_inserti64x4(_mm512_castsi256_si512(TOFCAM_FOUR_PAIRS(k)),
                                            TOFCAM_FOUR_PAIRS(k + 4), 1);
      const __m512i p1 = _mm512_inserti64x4(_mm512_castsi256_si512(TOFCAM_FOUR_PAIRS(k + 8)),
                                            TOFCAM_FOUR_PAIRS(k + 12), 1);
      const __m512 g0 = _mm512_castsi512_ps(_mm512_permutex2var_epi32(p0, evens, p1));
      const __m512 dg = _mm512_castsi512_ps(_mm512_permutex2var_epi32(p0, odds, p1));
      const __m512 corr = _mm512_add_ps(g0, _mm512_mul_ps(_mm512_load_ps(t_block + i), dg));
      __m512 v = _mm512_add_ps(_mm512_sub_ps(_mm512_load_ps(l_block + i), corr), vrange);
      v = _mm512_mask_sub_ps(v, _mm512_cmp_ps_mask(v, vrange, _CMP_GE_OQ), v, vrange);
      // kInvalid pixels (before the calibration's flags are OR-ed in) keep their value.
      auto* flags_at = reinterpret_cast<__m256i*>(bf + i);
      const __m256i flags = _mm256_loadu_si256(flags_at);
      _mm512_mask_storeu_ps(bd + i, _mm256_testn_epi16_mask(flags, invalid), v);
      if (extra_flags != nullptr) {
        const auto* extra = reinterpret_cast<const __m256i*>(extra_flags + begin + i);
        _mm256_storeu_si256(flags_at, _mm256_or_si256(flags, _mm256_loadu_si256(extra)));
      }
    }
  }
  return done;
}
#undef TOFCAM_FOUR_PAIRS
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

bool HasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2") != 0;
  return has;
}
#endif

}  // namespace

void CalibrateSpan(const CalibrationPlan& plan, std::size_t begin, std::size_t n, float* d,
                   PixelFlags* f) {
  std::size_t done = 0;  // pixels whose calibration flags are OR-ed in already
  if (plan.table == nullptr) {
    Eq1(n, plan.range_m, plan.bias_m, plan.offset_m + begin, f, d);
  } else {
#if TOFCAM_EQ1_AVX2
    // The interval kernels also OR the calibration's flags into the pixels they do.
    decltype(&Eq1IntervalsAvx2) intervals = HasAvx2() ? Eq1IntervalsAvx2 : nullptr;
#if defined(TOFCAM_AVX512_FORMS)
    if (internal::UseAvx512Forms()) intervals = Eq1Intervals16;
#endif
    if (plan.table_intervals != nullptr && intervals != nullptr) {
      const PixelFlags* extra = plan.pixel_flags == nullptr ? nullptr : plan.pixel_flags + begin;
      done = intervals(n, plan.range_m, plan.bias_m, plan.offset_m + begin, f, extra, d,
                       plan.table_intervals, plan.table_origin_m, plan.table_inv_step,
                       plan.table_last, plan.table_last_segment);
    }
#endif
    Eq1Table(n - done, plan.range_m, plan.bias_m, plan.offset_m + begin + done, f + done, d + done,
             plan.table->values_m.data(), plan.table_origin_m, plan.table_inv_step, plan.table_last,
             plan.table_last_segment);
  }
  if (plan.pixel_flags != nullptr) {
    kernels::OrFlags(n - done, f + done, plan.pixel_flags + begin + done);
  }
}

const DenseDistanceCorrection* CachedTable(const OffsetCalibration& calibration, double range_m) {
  if (!calibration.distance_correction) return nullptr;
  struct Cache {
    DistanceCorrection source;
    double range_m = 0.0;
    DenseDistanceCorrection table;
    bool valid = false;
  };
  thread_local Cache cache;
  const DistanceCorrection& g = *calibration.distance_correction;
  if (!cache.valid || cache.range_m != range_m || cache.source.start_m != g.start_m ||
      cache.source.step_m != g.step_m || cache.source.correction_m != g.correction_m) {
    cache.valid = false;
    cache.table = DenseDistanceCorrection::Resample(g, range_m);
    cache.source = g;
    cache.range_m = range_m;
    cache.valid = true;
  }
  return &cache.table;
}

}  // namespace calibration_internal

void ApplyCalibrationInPlace(MetricFrame& frame, const OffsetCalibration& calibration) {
  namespace ci = calibration_internal;
  // The size checks come first (MakePlan), so the table is only built for a frame that fits.
  ci::CalibrationPlan plan = ci::MakePlan(frame, calibration, nullptr);
  if (calibration.distance_correction) {
    const double range_m = UnambiguousRangeM(frame.info.modulation_frequency_hz);
    plan = ci::MakePlan(frame, calibration, ci::CachedTable(calibration, range_m));
  }
  ci::CalibrateSpan(plan, 0, frame.radial_distance_m.size(), frame.radial_distance_m.data(),
                    frame.flags.data());
}

MetricFrame ApplyCalibration(const MetricFrame& frame, const OffsetCalibration& calibration) {
  MetricFrame out = frame;
  ApplyCalibrationInPlace(out, calibration);
  return out;
}

}  // namespace tofcam
