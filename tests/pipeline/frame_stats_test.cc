#include "tofcam/pipeline/frame_stats.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// A 3 x 2 frame, every number chosen so the statistics can be worked out by hand:
//   pixel  measured  truth  error   flags         intensity  ΔL
//   0      1.00      1.00    0.00   -             100        0.01
//   1      2.00      2.10   -0.10   -             200        0.03
//   2      3.00      3.02   -0.02   high-ΔL       300        0.50
//   3      4.00      4.50   -0.50   high-ΔL       400        0.90
//   4      5.00      inf     -inf   -             500        0.05
//   5      0.00      1.00   -1.00   invalid       0          inf
MetricFrame HandFrame() {
  MetricFrame f;
  f.radial_distance_m = Image<float>(3, 2);
  f.amplitude = Image<float>(3, 2, 1000.0f);
  f.intensity = Image<float>(3, 2);
  f.delta_l_m = Image<float>(3, 2);
  f.flags = Image<PixelFlags>(3, 2);
  GroundTruth truth;
  truth.radial_distance_m = Image<float>(3, 2);
  truth.causes = Image<PixelFlags>(3, 2);
  truth.sigma_m = Image<float>(3, 2);
  const float measured[] = {1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 0.0f};
  const float true_m[] = {1.0f, 2.1f, 3.02f, 4.5f, kInf, 1.0f};
  const float intensity[] = {100, 200, 300, 400, 500, 0};
  const float delta_l[] = {0.01f, 0.03f, 0.5f, 0.9f, 0.05f, kInf};
  for (int i = 0; i < 6; ++i) {
    f.radial_distance_m[i] = measured[i];
    truth.radial_distance_m[i] = true_m[i];
    f.intensity[i] = intensity[i];
    f.delta_l_m[i] = delta_l[i];
  }
  f.flags[2] = Flag::kHighDeltaL;
  f.flags[3] = Flag::kHighDeltaL;
  f.flags[5] = Flag::kInvalid;
  f.truth = truth;
  f.info.sequence = 17;
  f.info.timestamp_ns = 2'500'000'000;
  f.info.integration_time_register = 40;
  f.info.integration_time_us = 40 * 255.0;
  return f;
}

TEST(FrameStatsTest, HandComputedFrame) {
  const FrameStats s = ComputeFrameStats(HandFrame());
  EXPECT_EQ(s.sequence, 17u);
  EXPECT_DOUBLE_EQ(s.timestamp_s, 2.5);
  EXPECT_EQ(s.integration_time_register, 40);
  EXPECT_DOUBLE_EQ(s.integration_time_us, 10200.0);
  // Intensity excludes only kInvalid (the controller's default): (100+...+500) / 5.
  EXPECT_DOUBLE_EQ(s.mean_intensity, 300.0);
  EXPECT_EQ(s.pixels, 6);
  EXPECT_EQ(s.kept_pixels, 3);  // pixels 0, 1, 4
  EXPECT_DOUBLE_EQ(s.valid_fraction, 0.5);
  EXPECT_NEAR(s.mean_delta_l_m, (0.01 + 0.03 + 0.05) / 3.0, 1e-7);

  EXPECT_TRUE(s.has_truth);
  // RMSE over kept pixels with a finite error: pixels 0 (0) and 1 (-0.1).
  EXPECT_EQ(s.truth_error_pixels, 2);
  EXPECT_NEAR(s.rmse_m, std::sqrt(0.01 / 2.0), 1e-6);
  // Bad (|error| > 5 cm or not finite): 1, 3, 4, 5; removed: 3, 5.
  EXPECT_EQ(s.bad_pixels, 4);
  EXPECT_EQ(s.bad_removed, 2);
  EXPECT_DOUBLE_EQ(s.bad_removed_fraction, 0.5);
  // Good: 0 (kept), 2 (removed, 2 cm error is good).
  EXPECT_EQ(s.good_pixels, 2);
  EXPECT_EQ(s.good_kept, 1);
  EXPECT_DOUBLE_EQ(s.good_kept_fraction, 0.5);
}

TEST(FrameStatsTest, BadThresholdIsAnOption) {
  FrameStatsOptions options;
  options.bad_error_m = 0.2;  // pixel 1 (10 cm) becomes good
  const FrameStats s = ComputeFrameStats(HandFrame(), options);
  EXPECT_EQ(s.bad_pixels, 3);
  EXPECT_EQ(s.good_pixels, 3);
  EXPECT_EQ(s.good_kept, 2);
}

TEST(FrameStatsTest, WithoutTruthOrDeltaLTheStatisticsAreNaN) {
  MetricFrame f = HandFrame();
  f.truth.reset();
  f.delta_l_m = Image<float>();
  const FrameStats s = ComputeFrameStats(f);
  EXPECT_FALSE(s.has_truth);
  EXPECT_TRUE(std::isnan(s.rmse_m));
  EXPECT_TRUE(std::isnan(s.bad_removed_fraction));
  EXPECT_TRUE(std::isnan(s.good_kept_fraction));
  EXPECT_TRUE(std::isnan(s.mean_delta_l_m));
  EXPECT_EQ(s.kept_pixels, 3);
}

TEST(FrameStatsTest, NothingKeptGivesNaNNotZero) {
  MetricFrame f = HandFrame();
  f.flags.Fill(PixelFlags(Flag::kInvalid));
  const FrameStats s = ComputeFrameStats(f);
  EXPECT_EQ(s.kept_pixels, 0);
  EXPECT_DOUBLE_EQ(s.valid_fraction, 0.0);
  EXPECT_TRUE(std::isnan(s.mean_delta_l_m));
  EXPECT_TRUE(std::isnan(s.rmse_m));
  EXPECT_TRUE(std::isnan(s.mean_intensity));
  EXPECT_DOUBLE_EQ(s.bad_removed_fraction, 1.0);
}

TEST(FrameStatsTest, RejectsBadInput) {
  FrameStatsOptions bad;
  bad.bad_error_m = 0.0;
  try {
    (void)ComputeFrameStats(HandFrame(), bad);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("bad_error_m"), std::string::npos);
  }
  MetricFrame f = HandFrame();
  f.truth->radial_distance_m = Image<float>(2, 2);
  EXPECT_THROW((void)ComputeFrameStats(f), Error);
  EXPECT_THROW((void)ComputeFrameStats(MetricFrame{}), Error);
}

TEST(FrameStatsTest, CsvRowMatchesHeader) {
  FrameStats s = ComputeFrameStats(HandFrame());
  s.next_integration_register = 41;
  const std::string header = FrameStatsCsvHeader();
  const std::string row = FrameStatsCsvRow(s);
  EXPECT_EQ(std::count(header.begin(), header.end(), ','), std::count(row.begin(), row.end(), ','));
  EXPECT_EQ(header.rfind("sequence,timestamp_s,integration_register,", 0), 0u);
  // sequence 17, 2.5 s, register 40, 10200 µs, next 41, intensity 300, 3 kept, 0.5 valid.
  EXPECT_EQ(row.rfind("17,2.5,40,10200,41,300,3,0.5,", 0), 0u) << row;
  MetricFrame f = HandFrame();
  f.truth.reset();
  const std::string no_truth = FrameStatsCsvRow(ComputeFrameStats(f));
  EXPECT_NE(no_truth.find(",nan,"), std::string::npos) << no_truth;
}

TEST(RunStatsAccumulatorTest, PoolsPixelCountsAcrossFrames) {
  FrameStats a;
  a.valid_fraction = 0.5;
  a.mean_delta_l_m = 0.02;
  a.mean_intensity = 100;
  a.has_truth = true;
  a.truth_error_pixels = 1;
  a.sum_squared_error_m2 = 0.04;
  a.bad_pixels = 1;
  a.bad_removed = 1;
  a.good_pixels = 9;
  a.good_kept = 9;
  FrameStats b = a;
  b.valid_fraction = 1.0;
  b.mean_delta_l_m = std::numeric_limits<double>::quiet_NaN();  // skipped in the mean
  b.truth_error_pixels = 3;
  b.sum_squared_error_m2 = 0.0;
  b.bad_pixels = 3;
  b.bad_removed = 0;
  b.good_pixels = 1;
  b.good_kept = 0;
  RunStatsAccumulator acc;
  acc.Add(a);
  acc.Add(b);
  const RunSummary r = acc.Summary();
  EXPECT_EQ(r.frames, 2u);
  EXPECT_DOUBLE_EQ(r.mean_valid_fraction, 0.75);
  EXPECT_DOUBLE_EQ(r.mean_delta_l_m, 0.02);
  EXPECT_DOUBLE_EQ(r.mean_intensity, 100.0);
  EXPECT_TRUE(r.has_truth);
  EXPECT_NEAR(r.rmse_m, std::sqrt(0.04 / 4.0), 1e-12);  // pooled, not the mean of 0.2 and 0
  EXPECT_DOUBLE_EQ(r.bad_removed_fraction, 0.25);       // 1 of 4
  EXPECT_DOUBLE_EQ(r.good_kept_fraction, 0.9);          // 9 of 10
  EXPECT_EQ(r.bad_pixels, 4);
  EXPECT_EQ(r.good_pixels, 10);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

// ComputeFrameStats' per-pixel loop as it was before the lane-wise loops (tofcam 0.1).
FrameStats SequentialStats(const MetricFrame& frame, float bad_error) {
  FrameStats s;
  double delta_l_sum = 0.0;
  int delta_l_count = 0;
  for (std::size_t i = 0; i < frame.radial_distance_m.size(); ++i) {
    const bool kept = frame.flags[i].Valid();
    if (kept) {
      ++s.kept_pixels;
      if (std::isfinite(frame.delta_l_m[i])) {
        delta_l_sum += frame.delta_l_m[i];
        ++delta_l_count;
      }
    }
    const float error = frame.radial_distance_m[i] - frame.truth->radial_distance_m[i];
    const bool finite = std::isfinite(error);
    const bool bad = !finite || std::abs(error) > bad_error;
    if (bad) {
      ++s.bad_pixels;
      if (!kept) ++s.bad_removed;
    } else {
      ++s.good_pixels;
      if (kept) ++s.good_kept;
    }
    if (kept && finite) {
      ++s.truth_error_pixels;
      s.sum_squared_error_m2 += static_cast<double>(error) * error;
    }
  }
  s.mean_delta_l_m = delta_l_sum / delta_l_count;
  return s;
}

TEST(FrameStatsTest, LaneWiseLoopsAgreeWithTheSequentialLoop) {
  // Counts exactly; the double sums (ΔL, squared error) within the reassociation bound
  // 2 n 2^-53 sum|x| (lane order versus sequential order, see frame_stats.cc).
  const int w = 157, h = 123;
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h);
  f.delta_l_m = Image<float>(w, h);
  f.flags = Image<PixelFlags>(w, h);
  f.amplitude = Image<float>(w, h, 1000.0f);
  GroundTruth truth;
  truth.radial_distance_m = Image<float>(w, h);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    truth.radial_distance_m[i] = 0.5f + 6.0f * u(rng);
    f.radial_distance_m[i] = truth.radial_distance_m[i] + 0.2f * (u(rng) - 0.5f);
    f.delta_l_m[i] = 0.1f * u(rng);
    if (u(rng) < 0.2f) f.flags[i] = Flag::kHighDeltaL;
    if (u(rng) < 0.02f) truth.radial_distance_m[i] = kInf;
    if (u(rng) < 0.02f) f.delta_l_m[i] = kInf;
    if (u(rng) < 0.01f) f.radial_distance_m[i] = std::nanf("");
  }
  f.truth = truth;
  const FrameStats got = ComputeFrameStats(f, {});
  const FrameStats want = SequentialStats(f, 0.05f);
  EXPECT_EQ(got.kept_pixels, want.kept_pixels);
  EXPECT_EQ(got.bad_pixels, want.bad_pixels);
  EXPECT_EQ(got.bad_removed, want.bad_removed);
  EXPECT_EQ(got.good_pixels, want.good_pixels);
  EXPECT_EQ(got.good_kept, want.good_kept);
  EXPECT_EQ(got.truth_error_pixels, want.truth_error_pixels);
  EXPECT_GT(want.bad_removed, 0);
  EXPECT_GT(want.good_kept, 0);
  const double n = static_cast<double>(f.radial_distance_m.size());
  const double u53 = std::ldexp(1.0, -53);
  // All summands are non-negative, so sum|x| is the sum itself.
  EXPECT_NEAR(got.sum_squared_error_m2, want.sum_squared_error_m2,
              2.0 * n * u53 * want.sum_squared_error_m2);
  EXPECT_NEAR(got.mean_delta_l_m, want.mean_delta_l_m, 2.0 * n * u53 * want.mean_delta_l_m);
  EXPECT_GT(want.sum_squared_error_m2, 0.0);
}

TEST(FrameStatsTest, FootprintRmseOverTheSamePixels) {
  // The hand frame's kept pixels with a finite error are 0 (error 0) and 1 (-0.10 m). Give
  // pixel 1 a footprint that holds 2.00 m (an edge pixel reading its nearer surface) and pixel 0
  // one of its own surface: the footprint RMSE is 0; the central one sqrt(0.01 / 2).
  MetricFrame f = HandFrame();
  EXPECT_TRUE(std::isnan(ComputeFrameStats(f).footprint_rmse_m));  // no footprint
  f.truth->footprint_near_m = Image<float>(3, 2, kInf);
  f.truth->footprint_far_m = Image<float>(3, 2, kInf);
  f.truth->footprint_near_m[0] = f.truth->footprint_far_m[0] = 1.0f;
  f.truth->footprint_near_m[1] = 2.0f;
  f.truth->footprint_far_m[1] = 2.1f;
  const FrameStats s = ComputeFrameStats(f);
  EXPECT_NEAR(s.rmse_m, std::sqrt(0.01 / 2), 1e-6);
  EXPECT_NEAR(s.footprint_rmse_m, 0.0, 1e-7);
  // A reading between the two surfaces (a flying pixel) is wrong under both truths.
  f.radial_distance_m[1] = 2.05f;
  f.truth->footprint_near_m[1] = 1.5f;
  f.truth->footprint_far_m[1] = 2.6f;
  EXPECT_NEAR(ComputeFrameStats(f).footprint_rmse_m, std::sqrt(0.05 * 0.05 / 2), 1e-6);
  // Pooled: NaN once a frame with truth has no footprint.
  RunStatsAccumulator run;
  run.Add(s);
  EXPECT_NEAR(run.Summary().footprint_rmse_m, 0.0, 1e-7);
  run.Add(ComputeFrameStats(HandFrame()));
  EXPECT_TRUE(std::isnan(run.Summary().footprint_rmse_m));
  // A footprint of the wrong size is refused.
  f.truth->footprint_far_m = Image<float>(2, 2);
  EXPECT_THROW((void)ComputeFrameStats(f), Error);
}

TEST(FrameStatsTest, FootprintErrorIsTheDistanceToTheNearestSurfaceInTheFootprint) {
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // An edge pixel: the board at 1.0 m, the wall at 3.0 m, its central ray on the wall.
  EXPECT_NEAR(FootprintErrorM(1.02, 3.0, 1.0, 3.0), 0.02, 1e-12);  // reads the board
  EXPECT_NEAR(FootprintErrorM(2.9, 3.0, 1.0, 3.0), 0.1, 1e-12);    // near the wall
  EXPECT_NEAR(FootprintErrorM(2.0, 3.0, 1.0, 3.0), 1.0, 1e-12);    // between: a flying pixel
  // One surface: the central truth decides unless the footprint's span is closer.
  EXPECT_NEAR(FootprintErrorM(2.5, 2.0, 1.99, 2.01), 0.49, 1e-12);
  // The central ray misses (sky) but part of the footprint hits the wall's edge.
  EXPECT_NEAR(FootprintErrorM(4.01, inf, 4.0, 4.0), 0.01, 1e-12);
  // Nothing is hit, or nothing is measured.
  EXPECT_EQ(FootprintErrorM(4.0, inf, inf, inf), inf);
  EXPECT_EQ(FootprintErrorM(nan, 3.0, 1.0, 3.0), inf);
  // No footprint (NaN candidates are skipped): the central error.
  EXPECT_NEAR(FootprintErrorM(3.3, 3.0, nan, nan), 0.3, 1e-12);
}

}  // namespace
}  // namespace tofcam
