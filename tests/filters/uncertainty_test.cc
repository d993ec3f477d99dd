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

TEST(Uncertainty, ExtrapolatedEdgesChargeOnlyWhatLeavesTheOwnSurface) {
  // 1, 1, 1 | 1.5 (a mixed pixel) | 2, 2, 2 with σ 1 cm. Pixel 2 continues its line (1, 1): 0
  // off it, so its noise alone although it is next to a 0.5 m step. Pixel 3 is 0.5 m off the
  // line of 1, 1 and 0.5 m off that of 2, 2: u = sqrt(0.01² + 0.5²). A slope (steps of 10 cm, a
  // straight line) has no edge term at all, where the step rule charges half of each step.
  UncertaintyOptions on;
  on.extrapolate_edges = true;
  MetricFrame m = Row({1.0f, 1.0f, 1.0f, 1.5f, 2.0f, 2.0f, 2.0f}, 0.01f);
  Image<float> u = ComputeUncertainty(m, on);
  EXPECT_NEAR(u[2], 0.01, 1e-6);
  EXPECT_NEAR(u[3], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[4], 0.01, 1e-6);
  EXPECT_NEAR(u[1], 0.01, 1e-6);
  const Image<float> step_rule = ComputeUncertainty(m);
  EXPECT_NEAR(step_rule[2], std::sqrt(0.0001 + 0.0625), 1e-6);
  // Pixel 2 of a 5-pixel slope has a line on both sides: no edge term. Pixels 0, 1, 3 and 4
  // have a 10 cm step towards a side where their own line runs out of the image: the step rule.
  m = Row({1.0f, 1.1f, 1.2f, 1.3f, 1.4f}, 0.01f);
  u = ComputeUncertainty(m, on);
  for (int i = 0; i < 5; ++i) {
    const double expected = i == 2 ? 0.01 : std::sqrt(0.0001 + 0.0025);
    EXPECT_NEAR(u[i], expected, 1e-6) << i;
  }
  EXPECT_NEAR(ComputeUncertainty(m)[2], std::sqrt(0.0001 + 0.0025), 1e-6);
  // Off the line by less than 3 sqrt(6) σ = 7.3 cm is noise: 1, 1, 1.03 | 2 charges pixel 2
  // nothing (its 3 cm step back is no edge either); by 10 cm (1, 1, 1.1 | 2) it charges the
  // 10 cm (more than the step rule's 5 cm for the step back, whose own line is outside).
  m = Row({1.0f, 1.0f, 1.03f, 2.0f}, 0.01f);
  EXPECT_NEAR(ComputeUncertainty(m, on)[2], 0.01, 1e-6);
  m = Row({1.0f, 1.0f, 1.1f, 2.0f}, 0.01f);
  EXPECT_NEAR(ComputeUncertainty(m, on)[2], std::sqrt(0.0001 + 0.01), 1e-6);
}

TEST(Uncertainty, ExtrapolatedEdgesWorkDownColumnsAndFallBackNextToRejectedPixels) {
  // The mixed-pixel row of the test above as a column (1 x 7): the same terms.
  UncertaintyOptions on;
  on.extrapolate_edges = true;
  MetricFrame m = Row({1.0f, 1.0f, 1.0f, 1.5f, 2.0f, 2.0f, 2.0f}, 0.01f);
  MetricFrame column;
  column.radial_distance_m = Image<float>(1, 7);
  column.flags = Image<PixelFlags>(1, 7);
  column.delta_l_m = Image<float>(1, 7, 0.01f);
  for (int i = 0; i < 7; ++i) column.radial_distance_m[i] = m.radial_distance_m[i];
  const Image<float> u = ComputeUncertainty(column, on);
  EXPECT_NEAR(u[2], 0.01, 1e-6);
  EXPECT_NEAR(u[3], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[4], 0.01, 1e-6);
  // Pixel 1 rejected: pixel 2's own line (1, 2) is not measurable, so its step to pixel 3 (0.5 m)
  // is charged by the step rule, half of it.
  column.flags[1] = PixelFlags(Flag::kLowAmplitude);
  EXPECT_NEAR(ComputeUncertainty(column, on)[2], std::sqrt(0.0001 + 0.0625), 1e-6);
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
