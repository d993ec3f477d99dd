#pragma once
// A branch-free double-precision atan2 for vectorised loops (pan assembly, the simulator's
// demodulation). Internal to tofcam; not installed.

#include <bit>
#include <cmath>
#include <cstdint>

#include "avx512_forms.h"
#include "tofcam/core/units.h"

#if defined(TOFCAM_AVX512_FORMS)
#include <immintrin.h>
#endif

namespace tofcam::internal {

/// Float form of Sel.
inline float SelF(bool c, float a, float b) {
  const std::uint32_t m = 0 - static_cast<std::uint32_t>(c);
  return std::bit_cast<float>((std::bit_cast<std::uint32_t>(a) & m) |
                              (std::bit_cast<std::uint32_t>(b) & ~m));
}

/// a where c, else b, by bit masks: GCC turns a ternary into a branch in some loops and keeps
/// them scalar (branches on an octant are unpredictable).
inline double Sel(bool c, double a, double b) {
  const std::uint64_t m = 0 - static_cast<std::uint64_t>(c);
  return std::bit_cast<double>((std::bit_cast<std::uint64_t>(a) & m) |
                               (std::bit_cast<std::uint64_t>(b) & ~m));
}

/// atan2(y, x) in [-pi, pi] without libm, branch-free so loops over it vectorise: octant
/// reduction to atan(u), |u| <= tan(pi/8), by its Taylor series to u^21 (truncation error below
/// tan(pi/8)^23 / 23 < 7e-11 rad; the reductions add a few ulps of pi). atan2(0, 0) = 0, and
/// y = -0 gives +0 or pi (libm: -0 or -pi).
inline double FastAtan2(double y, double x) {
  constexpr double kTanPi8 = 0.41421356237309504880;
  const double ax = std::abs(x), ay = std::abs(y);
  const double hi = std::max(ax, ay), lo = std::min(ax, ay);
  const double t = lo / std::max(hi, 1e-300);
  const bool reduce = t > kTanPi8;
  const double u = Sel(reduce, (t - 1.0) / (t + 1.0), t);
  const double u2 = u * u;
  double p = 1.0 / 21;
  p = p * u2 - 1.0 / 19;
  p = p * u2 + 1.0 / 17;
  p = p * u2 - 1.0 / 15;
  p = p * u2 + 1.0 / 13;
  p = p * u2 - 1.0 / 11;
  p = p * u2 + 1.0 / 9;
  p = p * u2 - 1.0 / 7;
  p = p * u2 + 1.0 / 5;
  p = p * u2 - 1.0 / 3;
  p = p * u2 + 1.0;
  double a = Sel(reduce, kPi / 4, 0.0) + u * p;
  a = Sel(ay > ax, kPi / 2 - a, a);
  a = Sel(x < 0.0, kPi - a, a);
  return Sel(y < 0.0, -a, a);
}

/// FastAtan2 in single precision (eight lanes per AVX2 vector): the same reduction, the series
/// to u^15 (truncation below tan(pi/8)^17 / 17 < 2e-8 rad), the rest float rounding; within
/// 1e-6 rad of atan2 (tests/core/fast_atan2_test.cc asserts it; 2.7e-7 measured) where
/// max(|x|, |y|) lies in [1e-30, 1e38]. Outside that, |x| + |y| overflows or the guard against
/// a zero divisor distorts the ratio (errors up to 0.2 rad): callers keep inputs in range.
inline float FastAtan2F(float y, float x) {
  constexpr float kTanPi8 = 0.41421356237309504880f;
  constexpr float kPiF = static_cast<float>(kPi);
  const float ax = std::abs(x), ay = std::abs(y);
  const float hi = std::max(ax, ay), lo = std::min(ax, ay);
  // One division: (t - 1) / (t + 1) with t = lo / hi is (lo - hi) / (lo + hi).
  const bool reduce = lo > kTanPi8 * hi;
  const float u = SelF(reduce, lo - hi, lo) / std::max(SelF(reduce, lo + hi, hi), 1e-30f);
  const float u2 = u * u;
  float p = -1.0f / 15;
  p = p * u2 + 1.0f / 13;
  p = p * u2 - 1.0f / 11;
  p = p * u2 + 1.0f / 9;
  p = p * u2 - 1.0f / 7;
  p = p * u2 + 1.0f / 5;
  p = p * u2 - 1.0f / 3;
  p = p * u2 + 1.0f;
  float a = SelF(reduce, kPiF / 4, 0.0f) + u * p;
  a = SelF(ay > ax, kPiF / 2 - a, a);
  a = SelF(x < 0.0f, kPiF - a, a);
  return SelF(y < 0.0f, -a, a);
}

#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_DIAGNOSTICS_BEGIN
/// FastAtan2F of 16 lanes with AVX-512 (the pan view's cell pass): the same reduction and series,
/// the multiply-adds fused (one rounding where FastAtan2F has two). Within the same 1e-6 rad of
/// atan2 over the same range (tests/core/fast_atan2_test.cc asserts it on AVX-512 CPUs).
TOFCAM_AVX512_INLINE __m512 FastAtan2F16(__m512 y, __m512 x) {
  constexpr float kPiF = static_cast<float>(kPi);
  const __m512 zero = _mm512_setzero_ps();
  const __m512 ax = _mm512_abs_ps(x), ay = _mm512_abs_ps(y);
  const __m512 hi = _mm512_max_ps(ax, ay), lo = _mm512_min_ps(ax, ay);
  const __mmask16 reduce = _mm512_cmp_ps_mask(
      lo, _mm512_mul_ps(_mm512_set1_ps(0.41421356237309504880f), hi), _CMP_GT_OQ);
  const __m512 num = _mm512_mask_sub_ps(lo, reduce, lo, hi);
  const __m512 den = _mm512_max_ps(_mm512_mask_add_ps(hi, reduce, lo, hi), _mm512_set1_ps(1e-30f));
  const __m512 u = _mm512_div_ps(num, den);
  const __m512 uu = _mm512_mul_ps(u, u);
  __m512 p = _mm512_set1_ps(-1.0f / 15);
  for (const float c : {1.0f / 13, -1.0f / 11, 1.0f / 9, -1.0f / 7, 1.0f / 5, -1.0f / 3, 1.0f}) {
    p = _mm512_fmadd_ps(p, uu, _mm512_set1_ps(c));
  }
  __m512 a = _mm512_fmadd_ps(u, p, _mm512_maskz_mov_ps(reduce, _mm512_set1_ps(kPiF / 4)));
  a = _mm512_mask_sub_ps(a, _mm512_cmp_ps_mask(ay, ax, _CMP_GT_OQ), _mm512_set1_ps(kPiF / 2), a);
  a = _mm512_mask_sub_ps(a, _mm512_cmp_ps_mask(x, zero, _CMP_LT_OQ), _mm512_set1_ps(kPiF), a);
  return _mm512_mask_xor_ps(a, _mm512_cmp_ps_mask(y, zero, _CMP_LT_OQ), a,
                            _mm512_castsi512_ps(_mm512_set1_epi32(INT32_MIN)));
}
TOFCAM_AVX512_DIAGNOSTICS_END
#endif

}  // namespace tofcam::internal
