#include "tofcam/filters/uncertainty.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

MetricFrame Row(std::initializer_list<float> d, float sigma) {
  MetricFrame m;
  const int w = static_cast<int>(d.size());
  m.radial_distance_m = Image<float>(w, 1);
  m.amplitude = Image<float>(w, 1, 1000.0f);
  m.flags = Image<PixelFlags>(w, 1);
  m.delta_l_m = Image<float>(w, 1, sigma);
  int i = 0;
  for (float v : d) m.radial_distance_m[i++] = v;
  return m;
}

TEST(Uncertainty, EdgesAddHalfTheirJump) {
  // 1.0, 1.0 | 2.0: the pixels next to the 1 m step get sqrt(0.01² + 0.5²); the first one only
  // its noise. A 2 cm step is below 3 sqrt(2) σ = 4.2 cm: noise, not an edge.
  MetricFrame m = Row({1.0f, 1.0f, 2.0f, 2.02f}, 0.01f);
  const Image<float> u = ComputeUncertainty(m);
  EXPECT_NEAR(u[0], 0.01, 1e-7);
  EXPECT_NEAR(u[1], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[2], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[3], 0.01, 1e-7);
  const Image<PixelFlags> f = UncertaintyFilter(m);
  EXPECT_FALSE(f[0].Has(Flag::kLowConfidence));
  EXPECT_TRUE(f[1].Has(Flag::kLowConfidence));
  EXPECT_TRUE(f[2].Has(Flag::kLowConfidence));
  // A noisy pixel alone: ΔL 6 cm > 5 cm.
  EXPECT_TRUE(UncertaintyFilter(Row({3.0f}, 0.06f))[0].Has(Flag::kLowConfidence));
}

TEST(Uncertainty, RejectedPixelsAreInfiniteAndNotNeighbours) {
  MetricFrame m = Row({1.0f, 5.0f, 1.0f, 1.0f}, 0.01f);
  m.flags[1] = PixelFlags(Flag::kLowAmplitude);
  const Image<float> u = ComputeUncertainty(m);
  EXPECT_TRUE(std::isinf(u[1]));
  EXPECT_NEAR(u[0], 0.01, 1e-7);  // a rejected neighbour is no edge evidence
  EXPECT_FALSE(UncertaintyFilter(m)[1].Any(kRejectMask));  // its own flag already says why
}

TEST(Uncertainty, NextToAClippedPixelTheJumpIsUnbounded) {
  // Pixel 1 clipped: its distance is unknown, pixels 0 and 2 may mix with it (u = inf, flagged);
  // pixel 3 is two away and keeps its noise. Without the flag in unknown_neighbour_flags, a
  // clipped neighbour is merely unusable, as any rejected one. The same for kInconsistent.
  MetricFrame m = Row({1.0f, 5.0f, 1.0f, 1.0f}, 0.01f);
  m.flags[1] = PixelFlags(Flag::kSaturated);
  UncertaintyOptions on;
  on.unknown_neighbour_flags =
      PixelFlags(Flag::kSaturated).bits() | PixelFlags(Flag::kInconsistent).bits();
  const Image<float> u = ComputeUncertainty(m, on);
  EXPECT_TRUE(std::isinf(u[0]));
  EXPECT_TRUE(std::isinf(u[2]));
  EXPECT_NEAR(u[3], 0.01, 1e-7);
  const Image<PixelFlags> f = UncertaintyFilter(m, on);
  EXPECT_TRUE(f[0].Has(Flag::kLowConfidence));
  EXPECT_TRUE(f[2].Has(Flag::kLowConfidence));
  EXPECT_FALSE(f[1].Any(kRejectMask));  // its own kSaturated says why
  EXPECT_FALSE(f[3].Any(kRejectMask));
  UncertaintyOptions off;
  off.unknown_neighbour_flags = 0;
  EXPECT_NEAR(ComputeUncertainty(m, off)[0], 0.01, 1e-7);
  m.flags[1] = PixelFlags(Flag::kInconsistent);
  EXPECT_TRUE(std::isinf(ComputeUncertainty(m, on)[0]));
}

TEST(Uncertainty, BadInputIsAClearError) {
  MetricFrame m = Row({1.0f}, 0.01f);
  m.delta_l_m = Image<float>();
  EXPECT_THROW((void)ComputeUncertainty(m), Error);
  UncertaintyOptions o;
  o.max_uncertainty_m = 0;
  EXPECT_THROW((void)ComputeUncertainty(Row({1.0f}, 0.01f), o), Error);
}

}  // namespace
}  // namespace tofcam
