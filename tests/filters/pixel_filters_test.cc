#include "tofcam/filters/pixel_filters.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

// A 1 x n frame; every channel holds the given values (or 1 when not given).
MetricFrame Row(std::vector<float> distance, std::vector<float> amplitude = {},
                std::vector<float> intensity = {}, std::vector<float> delta_l = {}) {
  const int n = static_cast<int>(distance.size());
  MetricFrame f;
  f.radial_distance_m = Image<float>(n, 1);
  f.amplitude = Image<float>(n, 1, 1000.0f);
  f.flags = Image<PixelFlags>(n, 1);
  for (int i = 0; i < n; ++i) f.radial_distance_m[i] = distance[i];
  for (std::size_t i = 0; i < amplitude.size(); ++i) f.amplitude[i] = amplitude[i];
  if (!intensity.empty()) {
    f.intensity = Image<float>(n, 1);
    for (std::size_t i = 0; i < intensity.size(); ++i) f.intensity[i] = intensity[i];
  }
  if (!delta_l.empty()) {
    f.delta_l_m = Image<float>(n, 1);
    for (std::size_t i = 0; i < delta_l.size(); ++i) f.delta_l_m[i] = delta_l[i];
  }
  return f;
}

std::vector<bool> Has(const Image<PixelFlags>& flags, Flag f) {
  std::vector<bool> out;
  for (std::size_t i = 0; i < flags.size(); ++i) out.push_back(flags[i].Has(f));
  return out;
}

// Only the filter's own bit may be set.
void ExpectOnly(const Image<PixelFlags>& flags, Flag f) {
  for (std::size_t i = 0; i < flags.size(); ++i) {
    EXPECT_EQ(flags[i].bits() & ~static_cast<std::uint16_t>(f), 0) << "pixel " << i;
  }
}

TEST(AccuracyThresholdFilterTest, FlagsAboveThresholdAndNonFinite) {
  const MetricFrame f =
      Row({1, 1, 1, 1, 1, 1, 1}, {}, {}, {0.01f, 0.07f, 0.0701f, kNan, kInf, -0.1f, 0.0f});
  AccuracyThresholdOptions o;
  o.max_delta_l_m = 0.07;
  const Image<PixelFlags> out = AccuracyThresholdFilter(f, o);
  // 0.07 equals the threshold (not above); NaN, inf and negative count as above.
  EXPECT_EQ(Has(out, Flag::kHighDeltaL),
            (std::vector<bool>{false, false, true, true, true, true, false}));
  ExpectOnly(out, Flag::kHighDeltaL);
}

TEST(AccuracyThresholdFilterTest, ErrorsAreReported) {
  const MetricFrame no_delta = Row({1, 2});
  try {
    (void)AccuracyThresholdFilter(no_delta, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("delta_l_m"), std::string::npos);
  }
  AccuracyThresholdOptions bad;
  bad.max_delta_l_m = 0.0;
  EXPECT_THROW(bad.Validate(), Error);
  bad.max_delta_l_m = kNan;
  EXPECT_THROW(bad.Validate(), Error);
  MetricFrame wrong = Row({1, 2}, {}, {}, {0.1f, 0.1f});
  wrong.delta_l_m = Image<float>(3, 1);
  try {
    (void)AccuracyThresholdFilter(wrong, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
}

TEST(AmplitudeThresholdFilterTest, FlagsLowAndNan) {
  const MetricFrame f = Row({1, 1, 1, 1}, {99.9f, 100.0f, 5000.0f, kNan});
  AmplitudeThresholdOptions o;
  o.min_amplitude = 100.0;
  const Image<PixelFlags> out = AmplitudeThresholdFilter(f, o);
  EXPECT_EQ(Has(out, Flag::kLowAmplitude), (std::vector<bool>{true, false, false, true}));
  ExpectOnly(out, Flag::kLowAmplitude);
  o.min_amplitude = -1.0;
  EXPECT_THROW(o.Validate(), Error);
  o.min_amplitude = 70000.0;
  EXPECT_THROW(o.Validate(), Error);
}

TEST(SaturationFilterTest, RegisterRuleHandCases) {
  // (intensity, amplitude): clipped intensity; clipped amplitude; brightest tap I + A = 64300 at
  // or above the default max_peak of 64221 (amplitude collapsed, but the tap is at full scale);
  // I + A = 60000 below it; dark pixel.
  const MetricFrame f = Row({1, 1, 1, 1, 1}, {10.0f, 65532.0f, 24300.0f, 20000.0f, 50.0f},
                            {65532.0f, 30000.0f, 40000.0f, 40000.0f, 100.0f});
  const Image<PixelFlags> out = SaturationFilter(f, {});
  EXPECT_EQ(Has(out, Flag::kSaturated), (std::vector<bool>{true, true, true, false, false}));
  ExpectOnly(out, Flag::kSaturated);
}

TEST(SaturationFilterTest, WithoutIntensityUsesAmplitudeOnly) {
  const MetricFrame f = Row({1, 1}, {65532.0f, 64300.0f});
  ASSERT_FALSE(f.has_intensity());
  EXPECT_EQ(Has(SaturationFilter(f, {}), Flag::kSaturated), (std::vector<bool>{true, false}));
  SaturationOptions bad;
  bad.max_peak = 0.0;
  EXPECT_THROW(bad.Validate(), Error);
}

TEST(RangeFilterTest, FlagsOutsideLimitsAndNan) {
  const MetricFrame f = Row({0.04f, 0.05f, 3.0f, 7.5f, 7.6f, kNan, -kInf});
  const Image<PixelFlags> out = RangeFilter(f, {});  // defaults [0.05, 7.5] m
  EXPECT_EQ(Has(out, Flag::kOutOfRange),
            (std::vector<bool>{true, false, false, false, true, true, true}));
  ExpectOnly(out, Flag::kOutOfRange);
  RangeOptions bad;
  bad.min_distance_m = 2.0;
  bad.max_distance_m = 1.0;
  try {
    bad.Validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("max_distance_m"), std::string::npos);
  }
}

TEST(MergeFlagsTest, OrsIntoFrameAndChecksSize) {
  MetricFrame f = Row({1, 1, 1});
  f.flags[0] = PixelFlags(Flag::kMixed);
  Image<PixelFlags> add(3, 1);
  add[0] = Flag::kJumpEdge;
  add[2] = Flag::kLowAmplitude;
  MergeFlags(f, add);
  EXPECT_EQ(f.flags[0], PixelFlags(Flag::kMixed) | Flag::kJumpEdge);
  EXPECT_TRUE(f.flags[1].None());
  EXPECT_EQ(f.flags[2], PixelFlags(Flag::kLowAmplitude));
  f.flags = Image<PixelFlags>();  // empty flags are created
  MergeFlags(f, add);
  EXPECT_EQ(f.flags, add);
  EXPECT_THROW(MergeFlags(f, Image<PixelFlags>(2, 1)), Error);
}

TEST(PixelFiltersTest, RejectEmptyOrInconsistentFrames) {
  MetricFrame empty;
  EXPECT_THROW((void)RangeFilter(empty, {}), Error);
  MetricFrame f = Row({1, 2});
  f.amplitude = Image<float>(1, 1);
  try {
    (void)AmplitudeThresholdFilter(f, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("amplitude"), std::string::npos);
  }
}

}  // namespace
}  // namespace tofcam
