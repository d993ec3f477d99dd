#pragma once
// Branch-free replacements for the libm calls of the simulator's per-ray and per-pixel loops.
// They are written so that GCC vectorises loops over arrays of them at the x86-64 baseline (no
// calls, no data-dependent branches). Their errors are far below what the sensor can resolve: one
// step of the 16-bit distance register is 2 pi / 65536 = 9.6e-5 rad of phase (0.114 mm at
// 20 MHz); tests/sim/fast_math_test.cc checks each against the exact libm formula.

#include <cmath>
#include <cstdint>

namespace tofcam::sim::internal {

/// Nearest integer of |x| < 2^22 as a float (ties to even), without SSE4.1 `roundps`: adding and
/// subtracting 1.5 * 2^23 leaves only the integer part in the mantissa. Valid because tofcam is
/// compiled without -ffast-math (the compiler must not fold the two operations).
inline float RoundToIntegralF(float x) {
  constexpr float kMagic = 12582912.0f;  // 1.5 * 2^23
  return (x + kMagic) - kMagic;
}

/// sin(2 pi x) and cos(2 pi x) for a phase x in cycles, |x| < 2^20. The phase is reduced exactly
/// to an octant (x - round(x) and the quarter turn are exact float subtractions), then Taylor
/// polynomials of degree 9 (sin) and 8 (cos) on |theta| <= pi/4 leave a truncation error below
/// 2.5e-8, so the result is within a few float ulps (< 3e-7 absolute), over 300 times below one
/// distance register.
inline void SinCos2Pi(float x, float& s, float& c) {
  const float r = x - RoundToIntegralF(x);      // [-0.5, 0.5], exact
  const float qf = RoundToIntegralF(4.0f * r);  // quadrant -2..2
  const float y = r - 0.25f * qf;               // [-1/8, 1/8], exact
  const int q = static_cast<int>(qf) & 3;       // 0..3 (two's complement)
  const float t = 6.28318530717958647692f * y;  // [-pi/4, pi/4]
  const float t2 = t * t;
  const float sn =
      t + t * t2 * (-1.0f / 6 + t2 * (1.0f / 120 + t2 * (-1.0f / 5040 + t2 * (1.0f / 362880))));
  const float cs =
      1.0f + t2 * (-0.5f + t2 * (1.0f / 24 + t2 * (-1.0f / 720 + t2 * (1.0f / 40320))));
  // Rotate by q quarter turns: (sin, cos) -> q=1: (cos, -sin), q=2: (-sin, -cos), q=3: (-cos, sin).
  const bool swap = (q & 1) != 0;
  const float s0 = swap ? cs : sn;
  const float c0 = swap ? sn : cs;
  s = (q & 2) != 0 ? -s0 : s0;
  c = ((q + 1) & 2) != 0 ? -c0 : c0;
}

/// Largest |x| for which SinCosSmallPoly is exact to double rounding.
inline constexpr double kSinCosSmallMax = 0.25;

/// sin and cos of a small angle |x| <= kSinCosSmallMax in double precision, branch-free: Taylor
/// polynomials to x^11 and x^12 (truncation error < 3e-18, i.e. exact to double rounding).
inline void SinCosSmallPoly(double x, double& s, double& c) {
  const double x2 = x * x;
  s = x + x * x2 *
              (-1.0 / 6 + x2 * (1.0 / 120 +
                                x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 + x2 * (-1.0 / 39916800)))));
  c = 1.0 +
      x2 * (-0.5 + x2 * (1.0 / 24 +
                         x2 * (-1.0 / 720 + x2 * (1.0 / 40320 + x2 * (-1.0 / 3628800 +
                                                                      x2 * (1.0 / 479001600))))));
}

/// sin and cos in double precision: the polynomial below |x| = 0.25 rad, libm beyond. The
/// simulator's per-pixel distance offsets (fixed pattern, wiggling, drift) are centimetres, a few
/// hundredths of a radian, so the polynomial is the case that matters.
inline void SinCosSmall(double x, double& s, double& c) {
  if (std::abs(x) <= kSinCosSmallMax) {
    SinCosSmallPoly(x, s, c);
    return;
  }
  s = std::sin(x);
  c = std::cos(x);
}

/// x^n for 0 <= x <= 1 and an integer exponent n >= 0, by binary exponentiation in double
/// precision: the relative error grows like n double ulps (2e-13 for n = 1024), so the result is
/// the float nearest x^n (within 1.2e-7 relative), where exp2(n log2 x) costs two libm calls.
inline float PowInt(float x, unsigned n) {
  double base = x, result = 1.0;
  while (n != 0) {
    if ((n & 1u) != 0) result *= base;
    base *= base;
    n >>= 1;
  }
  return static_cast<float>(result);
}

}  // namespace tofcam::sim::internal
