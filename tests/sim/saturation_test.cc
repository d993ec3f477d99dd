// The per-pixel saturation step of the simulator (src/sim/saturation.h) on hand-computed charges.
#include "saturation.h"

#include <gtest/gtest.h>

#include <random>

namespace tofcam::sim::internal {
namespace {

constexpr float kFullWell = 1000.0f;

TEST(OverflowPixelTest, BelowTheFullWellNothingMoves) {
  float n[4] = {999.0f, 500.0f, 1.0f, 500.0f};
  EXPECT_EQ(OverflowPixel(n, kFullWell, 0.5f), 0.0f);
  EXPECT_EQ(n[0], 999.0f);
  EXPECT_EQ(n[2], 1.0f);
}

TEST(OverflowPixelTest, HalfTheExcessFillsTheOtherSitesEvenly) {
  // Taps (1.4, 0.6, 0.2, 0.6) x FW: excess 0.4 FW; half of it (0.2 FW) is shared by the three
  // sites with room, 0.0667 FW each; the other half leaves the pixel.
  float n[4] = {1400.0f, 600.0f, 200.0f, 600.0f};
  const float out = OverflowPixel(n, kFullWell, 0.5f);
  EXPECT_FLOAT_EQ(out, 200.0f);
  EXPECT_FLOAT_EQ(n[0], 1000.0f);
  EXPECT_NEAR(n[1], 666.667f, 1e-3f);
  EXPECT_NEAR(n[2], 266.667f, 1e-3f);
  EXPECT_NEAR(n[3], 666.667f, 1e-3f);
}

TEST(OverflowPixelTest, WaterFillingFillsSitesThatRunOutOfRoomFirst) {
  // Taps (1.9, 0.95, 0.1, 0.95) x FW, everything stays (share 1): excess 0.9 FW. Round 1: 0.3 FW
  // each, but sites 1 and 3 take only 0.05 FW; site 2 takes 0.3 FW (-> 0.4 FW), 0.5 FW is left.
  // Round 2: only site 2 has room and takes it all (-> 0.9 FW). Nothing leaves.
  float n[4] = {1900.0f, 950.0f, 100.0f, 950.0f};
  EXPECT_NEAR(OverflowPixel(n, kFullWell, 1.0f), 0.0f, 1e-3f);
  EXPECT_FLOAT_EQ(n[1], 1000.0f);
  EXPECT_FLOAT_EQ(n[3], 1000.0f);
  EXPECT_NEAR(n[2], 900.0f, 1e-3f);
  // More than the pixel can hold: all sites full, the rest leaves.
  float full[4] = {3000.0f, 1500.0f, 600.0f, 1500.0f};  // 6600 in, 4000 fit
  EXPECT_NEAR(OverflowPixel(full, kFullWell, 1.0f), 2600.0f, 1e-2f);
  for (float v : full) EXPECT_FLOAT_EQ(v, 1000.0f);
}

TEST(OverflowPixelTest, ConservesChargeAndNeverExceedsTheFullWell) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> tap(0.0f, 3000.0f), share(0.0f, 1.0f);
  for (int t = 0; t < 10000; ++t) {
    float n[4];
    double before = 0.0;
    for (float& v : n) before += v = tap(rng);
    const float keep_share = share(rng);
    const float out = OverflowPixel(n, kFullWell, keep_share);
    double after = out;
    for (float v : n) {
      EXPECT_LE(v, kFullWell);
      after += v;
    }
    EXPECT_GE(out, 0.0f);
    EXPECT_NEAR(after, before, 1e-5 * before);  // float rounding of a few additions
  }
}

}  // namespace
}  // namespace tofcam::sim::internal
