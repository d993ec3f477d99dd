#include "tofcam/pipeline/metric_conversion.h"

#include <gtest/gtest.h>

#include <cstdint>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

Frame MakeFrame(int w, int h) {
  Frame f;
  f.distance = Image<std::uint16_t>(w, h);
  f.amplitude = Image<std::uint16_t>(w, h, 1000);
  f.intensity = Image<std::uint16_t>(w, h, 3000);
  return f;
}

// L = c / (2 f): 299792458 / 4e7 = 7.49481145 m at 20 MHz, 4.99654097 m at 30 MHz.
constexpr double kL20 = 7.49481145;
constexpr double kL30 = 4.99654097;

TEST(MetricConversionTest, KnownRegistersToMetres) {
  Frame f = MakeFrame(4, 1);
  f.distance(0, 0) = 0;
  f.distance(0, 1) = 32768;  // half the span: L / 2
  f.distance(0, 2) = 65535;  // last step: L * 65535 / 65536
  f.distance(0, 3) = 8738;   // 8738 * 7.49481145 / 65536 = 0.999293 m
  f.amplitude(0, 1) = 65532;
  f.intensity(0, 2) = 17;
  const MetricFrame m = ConvertToMetric(f);
  ASSERT_EQ(m.width(), 4);
  EXPECT_FLOAT_EQ(m.radial_distance_m(0, 0), 0.0f);
  EXPECT_NEAR(m.radial_distance_m(0, 1), kL20 / 2, 1e-6);
  EXPECT_NEAR(m.radial_distance_m(0, 2), kL20 * 65535.0 / 65536.0, 1e-6);
  EXPECT_NEAR(m.radial_distance_m(0, 3), 0.9992929, 1e-6);
  EXPECT_FLOAT_EQ(m.amplitude(0, 1), 65532.0f);
  EXPECT_FLOAT_EQ(m.amplitude(0, 0), 1000.0f);
  EXPECT_FLOAT_EQ(m.intensity(0, 2), 17.0f);
  EXPECT_FLOAT_EQ(m.intensity(0, 0), 3000.0f);
  for (int c = 0; c < 4; ++c) EXPECT_TRUE(m.flags(0, c).None());
  EXPECT_TRUE(m.delta_l_m.empty());
}

TEST(MetricConversionTest, RespectsModulationFrequency) {
  Frame f = MakeFrame(1, 1);
  f.info.modulation_frequency_hz = 30e6;
  f.distance(0, 0) = 16384;  // a quarter of the span
  EXPECT_NEAR(ConvertToMetric(f).radial_distance_m(0, 0), kL30 / 4, 1e-6);
}

TEST(MetricConversionTest, RemovesDistanceOffsetRegisterModulo16Bit) {
  Frame f = MakeFrame(2, 1);
  f.info.distance_offset_register = 200;
  f.distance(0, 0) = 1200;  // 1000 steps after removing the offset
  f.distance(0, 1) = 100;   // camera wrapped: (100 - 200) mod 65536 = 65436
  const MetricFrame m = ConvertToMetric(f);
  EXPECT_NEAR(m.radial_distance_m(0, 0), 1000.0 * kL20 / 65536.0, 1e-6);
  EXPECT_NEAR(m.radial_distance_m(0, 1), 65436.0 * kL20 / 65536.0, 1e-6);
  MetricConversionOptions keep;
  keep.remove_distance_offset_register = false;
  EXPECT_NEAR(ConvertToMetric(f, keep).radial_distance_m(0, 0), 1200.0 * kL20 / 65536.0, 1e-6);
}

TEST(MetricConversionTest, ZeroAmplitudeIsInvalidAndSourceFlagsAreKept) {
  Frame f = MakeFrame(3, 1);
  f.amplitude(0, 0) = 0;
  f.source_flags = Image<PixelFlags>(3, 1);
  f.source_flags(0, 1) = PixelFlags(Flag::kSaturated);
  f.source_flags(0, 0) = PixelFlags(Flag::kLowAmplitude);
  const MetricFrame m = ConvertToMetric(f);
  EXPECT_EQ(m.flags(0, 0), PixelFlags(Flag::kInvalid) | Flag::kLowAmplitude);
  EXPECT_EQ(m.flags(0, 1), PixelFlags(Flag::kSaturated));
  EXPECT_TRUE(m.flags(0, 2).None());
}

TEST(MetricConversionTest, NoIntensityChannelLeavesIntensityEmpty) {
  Frame f = MakeFrame(2, 2);
  f.info.has_intensity = false;
  const MetricFrame m = ConvertToMetric(f);
  EXPECT_TRUE(m.intensity.empty());
  EXPECT_FALSE(m.has_intensity());
  EXPECT_EQ(m.amplitude.width(), 2);
}

TEST(MetricConversionTest, CopiesInfoAndTruth) {
  Frame f = MakeFrame(2, 1);
  f.info.sequence = 42;
  f.info.integration_time_register = 17;
  f.info.camera_model = "SR-2";
  f.truth =
      GroundTruth{Image<float>(2, 1, 1.5f), Image<PixelFlags>(2, 1), Image<float>(2, 1), {}, {}};
  f.truth->causes(0, 1) = PixelFlags(Flag::kMixed);
  const MetricFrame m = ConvertToMetric(f);
  EXPECT_EQ(m.info.sequence, 42u);
  EXPECT_EQ(m.info.integration_time_register, 17);
  EXPECT_EQ(m.info.camera_model, "SR-2");
  ASSERT_TRUE(m.truth.has_value());
  EXPECT_FLOAT_EQ(m.truth->radial_distance_m(0, 0), 1.5f);
  EXPECT_TRUE(m.truth->causes(0, 1).Has(Flag::kMixed));
}

TEST(MetricConversionTest, RejectsInconsistentFrames) {
  Frame f = MakeFrame(2, 2);
  f.amplitude = Image<std::uint16_t>(3, 2);
  EXPECT_THROW((void)ConvertToMetric(f), Error);
  f = MakeFrame(2, 2);
  f.info.modulation_frequency_hz = -1;
  try {
    (void)ConvertToMetric(f);
    FAIL() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
  EXPECT_THROW((void)ConvertToMetric(Frame{}), Error);
}

}  // namespace
}  // namespace tofcam
