#pragma once
// e^x for x <= 0 as an inline function a vectorising compiler can inline into a loop (internal to
// the filters; no public header).

#include <cstdint>
#include <cstring>

namespace tofcam::filters_internal {

// e^x for x <= 0 in double precision, without calls or branches, so that a loop calling it
// vectorises (the bilateral's offset pass, src/filters/spatial_filter.cc; std::exp is a library
// call per value, and it was a third of that filter's time). Cody-Waite reduction
// x = k ln 2 + r, |r| <= ln 2 / 2, with k rounded by adding 1.5 x 2^52; e^r by its Taylor series
// to degree 13 (truncation below r^14 / 14! < 6e-18 relative), evaluated by Estrin's scheme
// (pairs, then r², r⁴, r⁸: a chain of about 8 operations instead of Horner's 26; measured no
// slower); 2^k built in the exponent bits. Within 4 units in the last place of glibc's std::exp
// for -700 <= x <= 0 (tests/filters/exp_non_positive_test.cc); 0 for x < -700, where
// e^x < 1e-304; NaN for NaN.
[[gnu::always_inline]] inline double ExpNonPositive(double x) {
  constexpr double kLog2e = 1.4426950408889634;
  constexpr double kLn2Hi = 6.93147180369123816490e-01;  // ln 2 in two parts (fdlibm's split)
  constexpr double kLn2Lo = 1.90821492927058770002e-10;
  constexpr double kShift = 0x1.8p52;  // t + kShift rounds t to an integer in the low bits
  const double xc = x < -700.0 ? -700.0 : x;
  const double t = xc * kLog2e + kShift;
  const double k = t - kShift;
  const double r = (xc - k * kLn2Hi) - k * kLn2Lo;
  const double r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
  const double q0 = 1.0 + r, q1 = 0.5 + r * (1.0 / 6.0);
  const double q2 = 1.0 / 24.0 + r * (1.0 / 120.0), q3 = 1.0 / 720.0 + r * (1.0 / 5040.0);
  const double q4 = 1.0 / 40320.0 + r * (1.0 / 362880.0);
  const double q5 = 1.0 / 3628800.0 + r * (1.0 / 39916800.0);
  const double q6 = 1.0 / 479001600.0 + r * (1.0 / 6227020800.0);
  const double p = ((q0 + q1 * r2) + (q2 + q3 * r2) * r4) + ((q4 + q5 * r2) + q6 * r4) * r8;
  std::int64_t ti;
  std::memcpy(&ti, &t, sizeof ti);
  std::int64_t shift_bits;
  std::memcpy(&shift_bits, &kShift, sizeof shift_bits);
  const std::int64_t scale_bits = (ti - shift_bits + 1023) << 52;  // k in [-1010, 0]
  double scale;
  std::memcpy(&scale, &scale_bits, sizeof scale);
  return x < -700.0 ? 0.0 : p * scale;
}

}  // namespace tofcam::filters_internal
