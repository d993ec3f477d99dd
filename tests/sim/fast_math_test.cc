// The simulator's replacements for libm calls (src/sim/fast_math.h) against the exact formulas.
// Tolerances are stated against what the sensor resolves: one step of the 16-bit distance
// register is 2 pi / 65536 = 9.6e-5 rad of phase (0.114 mm at 20 MHz); amplitude and intensity
// registers resolve 1 part in 65532 at full scale.
#include "fast_math.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tofcam/core/units.h"

namespace tofcam::sim::internal {
namespace {

constexpr double kRegisterStepRad = 2 * kPi / 65536;

// Per-subsample phasor: cos and sin of 2 pi d / L, with the phase given in cycles (float).
TEST(FastMathTest, SinCos2PiIsWithinFloatRoundingOfTheExactPhasor) {
  std::mt19937 gen(1);
  std::uniform_real_distribution<float> cycles(-6.f, 6.f);  // paths up to 6 L (mirror bounces)
  double worst = 0;
  auto check = [&](float x) {
    float s, c;
    SinCos2Pi(x, s, c);
    const double phase = 2 * kPi * static_cast<double>(x);
    worst = std::max({worst, std::abs(s - std::sin(phase)), std::abs(c - std::cos(phase))});
  };
  for (int i = 0; i < 2000000; ++i) check(cycles(gen));
  // Octant and quadrant boundaries, where the reduction switches.
  for (int k = -48; k <= 48; ++k) {
    const float b = static_cast<float>(k) / 8;
    check(b);
    check(std::nextafter(b, 10.f));
    check(std::nextafter(b, -10.f));
  }
  // A few float ulps (6e-8 each); the old per-ray sinf/cosf of a float phase had a similar error
  // from rounding the phase itself. 3e-7 is over 300 times below one distance register.
  EXPECT_LT(worst, 3e-7);
  EXPECT_LT(300 * 3e-7, kRegisterStepRad);
}

// Per-pixel phase shift of the systematic distance errors (centimetres: hundredths of a radian).
TEST(FastMathTest, SinCosSmallIsExactToDoubleRounding) {
  double worst = 0;
  for (int i = -100000; i <= 100000; ++i) {
    const double x = kSinCosSmallMax * i / 100000.0;
    double s, c;
    SinCosSmall(x, s, c);
    worst = std::max({worst, std::abs(s - std::sin(x)), std::abs(c - std::cos(x))});
  }
  EXPECT_LT(worst, 4e-16);
  // Beyond the polynomial's range it is libm itself.
  for (double x : {0.3, -1.0, 2.5, 100.0}) {
    double s, c;
    SinCosSmall(x, s, c);
    EXPECT_EQ(s, std::sin(x));
    EXPECT_EQ(c, std::cos(x));
  }
}

// Blinn-Phong lobe cos^n for whole-number shininess.
TEST(FastMathTest, PowIntMatchesPowWithinItsBound) {
  std::mt19937 gen(2);
  std::uniform_real_distribution<float> cosine(0.f, 1.f);
  double worst_rel = 0;
  for (unsigned n : {0u, 1u, 2u, 3u, 7u, 30u, 80u, 100u, 255u, 1000u, 1024u}) {
    for (int i = 0; i < 20000; ++i) {
      const float x = i == 0 ? 1.f : cosine(gen);
      const double exact = std::pow(static_cast<double>(x), static_cast<double>(n));
      const double got = PowInt(x, n);
      if (exact < 1e-30) {
        EXPECT_LT(got, 1e-29);  // underflow region: no relative statement
        continue;
      }
      worst_rel = std::max(worst_rel, std::abs(got - exact) / exact);
    }
  }
  // The float nearest x^n (half an ulp, 6e-8) plus n double ulps; the lobe is part of the
  // amplitude, whose register resolves 1.5e-5 of full scale.
  EXPECT_LT(worst_rel, 1.2e-7);
}

// Wiggling evaluated from the measured phasor by the double-angle formulas instead of
// sin(4 atan2(im, re) + phase).
TEST(FastMathTest, WiggleFromDoubleAngleFormulasEqualsTheAtan2Form) {
  std::mt19937 gen(3);
  std::uniform_real_distribution<double> u(-1e6, 1e6);
  double worst = 0;
  for (int i = 0; i < 200000; ++i) {
    const double re = u(gen), im = u(gen), psi = 0.3;
    const double a = std::sqrt(re * re + im * im);
    const double cr = re / a, ci = im / a;
    const double c2 = cr * cr - ci * ci, s2 = 2 * cr * ci;
    const double c4 = c2 * c2 - s2 * s2, s4 = 2 * c2 * s2;
    const double fast = s4 * std::cos(psi) + c4 * std::sin(psi);
    worst = std::max(worst, std::abs(fast - std::sin(4 * std::atan2(im, re) + psi)));
  }
  EXPECT_LT(worst, 1e-14);  // times the 3 cm amplitude: far below a femtometre
}

}  // namespace
}  // namespace tofcam::sim::internal
