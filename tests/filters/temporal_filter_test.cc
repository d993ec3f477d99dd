#include "tofcam/filters/temporal_filter.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

MetricFrame One(float d, float sigma) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(1, 1, d);
  f.delta_l_m = Image<float>(1, 1, sigma);
  f.flags = Image<PixelFlags>(1, 1);
  return f;
}

float Step(TemporalFilter& t, float d, float sigma) {
  MetricFrame f = One(d, sigma);
  t.Process(f);
  return f.radial_distance_m[0];
}

TEST(TemporalFilterTest, EqualSigmasGiveTheRunningMean) {
  TemporalFilter t;
  EXPECT_FLOAT_EQ(Step(t, 1.0f, 1.0f), 1.0f);
  EXPECT_FLOAT_EQ(Step(t, 2.0f, 1.0f), 1.5f);  // (1 + 2) / 2
  EXPECT_FLOAT_EQ(Step(t, 3.0f, 1.0f), 2.0f);  // (1 + 2 + 3) / 3
  EXPECT_EQ(t.frames_averaged()[0], 3);
}

TEST(TemporalFilterTest, MeasurementsAreWeightedByTheirVariance) {
  // 0 with σ = 1 and 3 with σ = 2: (0 / 1 + 3 / 4) / (1 / 1 + 1 / 4) = 0.6.
  TemporalFilter t;
  (void)Step(t, 0.0f, 1.0f);
  EXPECT_NEAR(Step(t, 3.0f, 2.0f), 0.6f, 1e-6);
}

TEST(TemporalFilterTest, AJumpBeyondResetSigmaStartsAgain) {
  TemporalFilter t;
  for (int k = 0; k < 5; ++k) (void)Step(t, 2.0f, 0.01f);
  // Innovation 0.5 m against sqrt(v + σ²) ~ 0.011 m. One such frame is taken for an outlier:
  // the output is the measurement and the state stays.
  EXPECT_FLOAT_EQ(Step(t, 2.5f, 0.01f), 2.5f);
  EXPECT_EQ(t.frames_averaged()[0], 5);
  // A second one in a row is motion: the new value, and the average starts again.
  EXPECT_FLOAT_EQ(Step(t, 2.5f, 0.01f), 2.5f);
  EXPECT_EQ(t.frames_averaged()[0], 1);
  // A lone outlier between normal frames leaves the average alone.
  (void)Step(t, 2.5f, 0.01f);
  EXPECT_FLOAT_EQ(Step(t, 3.5f, 0.01f), 3.5f);
  EXPECT_NEAR(Step(t, 2.5f, 0.01f), 2.5f, 1e-6);
  EXPECT_EQ(t.frames_averaged()[0], 3);
}

TEST(TemporalFilterTest, ASlowlyMovingSurfaceIsFollowed) {
  // A wall approaching at 1.5 cm per frame, σ = 1 cm: each step is below the 3 σ reset, but
  // the innovations keep one sign beyond 1.5 σ: after drift_frames (3) of them the average
  // restarts, so the output never lags by more than a few steps (a plain average of 8 frames
  // would lag by ~8 x 1.5 / 2 = 6 cm).
  TemporalFilter t;
  double worst = 0.0;
  for (int k = 0; k < 40; ++k) {
    const float truth = 5.0f - 0.015f * k;
    const double lag = std::abs(Step(t, truth, 0.01f) - truth);
    if (k > 10) worst = std::max(worst, lag);
  }
  EXPECT_LT(worst, 0.045);
}

TEST(TemporalFilterTest, RejectedFramesPassThroughAndLongGapsForget) {
  TemporalFilterOptions o;
  o.max_gap_frames = 1;
  TemporalFilter t(o);
  (void)Step(t, 1.0f, 1.0f);
  (void)Step(t, 2.0f, 1.0f);  // mean 1.5
  MetricFrame rejected = One(7.0f, 1.0f);
  rejected.flags[0].Set(Flag::kHighDeltaL);
  t.Process(rejected);
  EXPECT_FLOAT_EQ(rejected.radial_distance_m[0], 7.0f);  // unchanged
  EXPECT_FLOAT_EQ(Step(t, 1.5f, 1.0f), 1.5f);            // (1 + 2 + 1.5) / 3: state kept
  t.Process(rejected);
  t.Process(rejected);  // two in a row > max_gap_frames: forgotten
  EXPECT_FLOAT_EQ(Step(t, 9.0f, 1.0f), 9.0f);
  EXPECT_EQ(t.frames_averaged()[0], 1);
}

TEST(TemporalFilterTest, SteadyStateNoiseIsThatOfTheCappedAverage) {
  // With v held at σ²/N the gain is 1/(N + 1): an exponential average with α = 1/(N + 1), whose
  // variance is α / (2 - α) σ² = σ² / (2N + 1). N = 8: σ / sqrt(17) = 0.243 σ.
  TemporalFilterOptions o;
  o.max_frames = 8;
  TemporalFilter t(o);
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  const int w = 100, h = 100;
  double s2 = 0.0;
  long n = 0;
  for (int k = 0; k < 60; ++k) {
    MetricFrame f;
    f.radial_distance_m = Image<float>(w, h);
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      f.radial_distance_m[i] = 2.0f + noise(rng);
    }
    f.delta_l_m = Image<float>(w, h, 0.01f);
    t.Process(f);
    if (k < 30) continue;  // settled: the start transient is long gone
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      const double e = f.radial_distance_m[i] - 2.0;
      s2 += e * e;
      ++n;
    }
  }
  // Outliers beyond reset_sigma (0.3 % of pixel-frames) pass through raw (+0.3 % x ~10 σ²), and
  // one-signed runs beyond 1.5 σ (a few per mille) restart the average: both add a little.
  const double measured = std::sqrt(s2 / n) / 0.01;
  EXPECT_GT(measured, 1.0 / std::sqrt(17.0) - 0.01);
  EXPECT_LT(measured, 0.3);
}

TEST(TemporalFilterTest, BadOptionsAndSizes) {
  TemporalFilterOptions o;
  o.max_frames = 0;
  EXPECT_THROW(TemporalFilter{o}, Error);
  o = {};
  o.reset_sigma = -1;
  EXPECT_THROW(TemporalFilter{o}, Error);
  TemporalFilter t;
  MetricFrame f = One(1.0f, 0.1f);
  f.delta_l_m = Image<float>(2, 2);
  EXPECT_THROW(t.Process(f), Error);
}

}  // namespace
}  // namespace tofcam
