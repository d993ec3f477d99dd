// The branch-free atan2 forms of src/core/fast_atan2.h against libm's atan2 in long double.
#include "fast_atan2.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

namespace tofcam::internal {
namespace {

// Inputs over every octant and many magnitudes, the axes, the diagonals, near-equal |x|, |y|
// (the reduction's switch at tan(pi/8)) and tiny and huge values.
std::vector<std::pair<double, double>> Inputs() {
  std::vector<std::pair<double, double>> in;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> angle(-kPi, kPi);
  std::uniform_real_distribution<double> exponent(-30.0, 30.0);
  for (int i = 0; i < 200000; ++i) {
    const double a = angle(rng), r = std::pow(2.0, exponent(rng));
    in.emplace_back(r * std::sin(a), r * std::cos(a));
  }
  const double t8 = std::tan(kPi / 8);
  for (double s : {1.0, -1.0}) {
    for (double c : {1.0, -1.0}) {
      for (double k : {0.0, 1e-9, t8 * (1 - 1e-7), t8, t8 * (1 + 1e-7), 1.0 - 1e-9, 1.0}) {
        // y = -0 is left out: these forms give +0 or pi for it (libm -0 or -pi), as documented.
        if (k != 0.0) in.emplace_back(s * k, c * 1.0);
        in.emplace_back(s * 1.0, c * k);
      }
    }
  }
  in.emplace_back(1e-30, -1.0);
  in.emplace_back(1e30, 1e-30);
  return in;
}

TEST(FastAtan2Test, DoubleFormWithin1e10RadOfLibm) {
  double worst = 0.0;
  for (const auto& [y, x] : Inputs()) {
    const long double ref = std::atan2(static_cast<long double>(y), static_cast<long double>(x));
    worst = std::max(worst, static_cast<double>(std::abs(FastAtan2(y, x) - ref)));
  }
  EXPECT_LT(worst, 1e-10);  // documented: series truncation < 7e-11 plus a few ulps of pi
  EXPECT_EQ(FastAtan2(0.0, 0.0), 0.0);
}

TEST(FastAtan2Test, FloatFormWithin1e6RadOfLibmOnItsInputs) {
  // Measured on the float inputs themselves (the rounding of y and x to float is the caller's).
  double worst = 0.0;
  for (const auto& [y, x] : Inputs()) {
    const float yf = static_cast<float>(y), xf = static_cast<float>(x);
    const long double ref = std::atan2(static_cast<long double>(yf), static_cast<long double>(xf));
    worst = std::max(worst, static_cast<double>(std::abs(FastAtan2F(yf, xf) - ref)));
  }
  // Documented bound 1e-6 rad (PanCells' error bound relies on it); the series' truncation is
  // 2e-8, the rest float rounding (a few ulps of pi, 2.4e-7 each).
  EXPECT_LT(worst, 1e-6);
  EXPECT_EQ(FastAtan2F(0.0f, 0.0f), 0.0f);
  EXPECT_NEAR(FastAtan2F(0.0f, -1.0f), kPi, 1e-6);
  EXPECT_NEAR(FastAtan2F(-1e-30f, -1.0f), -kPi, 1e-6);
}

#if defined(TOFCAM_AVX512_FORMS)
TOFCAM_AVX512_TARGET float MaxErrorOf16LaneForm(const std::vector<std::pair<double, double>>& in) {
  double worst = 0.0;
  for (std::size_t i = 0; i < in.size(); i += 16) {
    float y[16] = {}, x[16] = {1.0f}, a[16];
    const std::size_t n = std::min<std::size_t>(16, in.size() - i);
    for (std::size_t j = 0; j < n; ++j) {
      y[j] = static_cast<float>(in[i + j].first);
      x[j] = static_cast<float>(in[i + j].second);
    }
    _mm512_storeu_ps(a, FastAtan2F16(_mm512_loadu_ps(y), _mm512_loadu_ps(x)));
    for (std::size_t j = 0; j < n; ++j) {
      const long double ref =
          std::atan2(static_cast<long double>(y[j]), static_cast<long double>(x[j]));
      worst = std::max(worst, static_cast<double>(std::abs(a[j] - ref)));
    }
  }
  return static_cast<float>(worst);
}

TEST(FastAtan2Test, SixteenLaneFormWithin1e6RadOfLibm) {
  if (!CpuHasAvx512()) GTEST_SKIP() << "no AVX-512 on this CPU";
  // The pan view's cell pass uses this form (fused multiply-adds); its error bound relies on the
  // same 1e-6 rad as FastAtan2F's.
  EXPECT_LT(MaxErrorOf16LaneForm(Inputs()), 1e-6f);
  EXPECT_LT(MaxErrorOf16LaneForm({{0.0, -1.0}, {-1e-30, -1.0}, {1.0, 0.0}}), 1e-6f);  // pi, -pi
}
#endif

}  // namespace
}  // namespace tofcam::internal
