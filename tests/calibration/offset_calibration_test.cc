#include "tofcam/calibration/offset_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

constexpr double kL20 = 7.49481145;  // c / (2 * 20 MHz)

OffsetCalibration MakeCalibration(int w, int h, float offset) {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = w;
  c.height = h;
  c.offset_m = Image<float>(w, h, offset);
  return c;
}

MetricFrame MakeFrame(int w, int h, float distance) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(w, h, distance);
  m.amplitude = Image<float>(w, h, 1000.0f);
  m.intensity = Image<float>(w, h, 5000.0f);
  m.flags = Image<PixelFlags>(w, h);
  return m;
}

ErrorCode CodeOf(auto&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.code();
  }
  return ErrorCode::kInternal;  // "no error" never matches an expected code below
}

TEST(ApplyCalibrationTest, EquationOneHandValuesIncludingWrap) {
  OffsetCalibration c = MakeCalibration(4, 1, 0.0f);
  MetricFrame m = MakeFrame(4, 1, 0.0f);
  // (m, o) -> l = (m - o + r_e) mod r_e, r_e = 7.49481145 m.
  m.radial_distance_m(0, 0) = 0.1f;  // minus 0.3: plain subtraction would be -0.2
  c.offset_m(0, 0) = 0.3f;           // -> 7.29481145
  m.radial_distance_m(0, 1) = 2.0f;
  c.offset_m(0, 1) = 0.05f;  // -> 1.95
  m.radial_distance_m(0, 2) = 7.4f;
  c.offset_m(0, 2) = -0.2f;  // 7.6 wraps -> 0.10518855
  m.radial_distance_m(0, 3) = 3.0f;
  c.offset_m(0, 3) = 0.0f;  // unchanged
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_NEAR(l.radial_distance_m(0, 0), 7.29481145, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 1), 1.95, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 2), 0.10518855, 2e-6);
  EXPECT_FLOAT_EQ(l.radial_distance_m(0, 3), 3.0f);
  for (int col = 0; col < 4; ++col) {
    EXPECT_GE(l.radial_distance_m(0, col), 0.0f);
    EXPECT_LT(l.radial_distance_m(0, col), static_cast<float>(kL20));
  }
  // The input frame is not modified.
  EXPECT_FLOAT_EQ(m.radial_distance_m(0, 0), 0.1f);
}

TEST(ApplyCalibrationTest, InvalidPixelsPassThroughAndCalibrationFlagsAreAdded) {
  OffsetCalibration c = MakeCalibration(3, 1, 0.5f);
  c.pixel_flags = Image<PixelFlags>(3, 1);
  c.pixel_flags(0, 2) = PixelFlags(Flag::kInvalid);
  MetricFrame m = MakeFrame(3, 1, 2.0f);
  m.flags(0, 0) = PixelFlags(Flag::kInvalid);
  m.flags(0, 1) = PixelFlags(Flag::kSaturated);
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_FLOAT_EQ(l.radial_distance_m(0, 0), 2.0f);  // untouched
  EXPECT_EQ(l.flags(0, 0), PixelFlags(Flag::kInvalid));
  EXPECT_NEAR(l.radial_distance_m(0, 1), 1.5, 1e-6);  // saturated: corrected, flag kept
  EXPECT_EQ(l.flags(0, 1), PixelFlags(Flag::kSaturated));
  EXPECT_EQ(l.flags(0, 2), PixelFlags(Flag::kInvalid));  // uncalibrated pixel
}

TEST(ApplyCalibrationTest, RejectsMismatchedFrames) {
  const OffsetCalibration c = MakeCalibration(3, 2, 0.0f);
  EXPECT_EQ(CodeOf([&] { (void)ApplyCalibration(MakeFrame(2, 3, 1.0f), c); }),
            ErrorCode::kMismatch);
  MetricFrame m = MakeFrame(3, 2, 1.0f);
  m.info.modulation_frequency_hz = 30e6;
  EXPECT_EQ(CodeOf([&] { (void)ApplyCalibration(m, c); }), ErrorCode::kMismatch);
}

TEST(DistanceCorrectionTest, InterpolatesKnotsAndHoldsEnds) {
  DistanceCorrection g;
  g.start_m = 1.0;
  g.step_m = 0.5;
  // Samples of q(x) = 0.01 x^2 - 0.02 x at x = 1.0 .. 3.5.
  const auto q = [](double x) { return 0.01 * x * x - 0.02 * x; };
  for (int k = 0; k < 6; ++k) g.correction_m.push_back(static_cast<float>(q(1.0 + 0.5 * k)));
  EXPECT_NO_THROW(g.Validate());
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(g.Evaluate(1.0 + 0.5 * k), q(1.0 + 0.5 * k), 1e-7);
  // Catmull-Rom reproduces quadratics on interior intervals (knots k-1..k+2 all present).
  for (double x : {1.6, 2.0 + 1.0 / 3.0, 2.9}) EXPECT_NEAR(g.Evaluate(x), q(x), 1e-7) << x;
  EXPECT_NEAR(g.Evaluate(0.2), q(1.0), 1e-7);  // before the first knot: first value
  EXPECT_NEAR(g.Evaluate(9.0), q(3.5), 1e-7);  // after the last: last value
  EXPECT_NEAR(g.Evaluate(std::nan("")), q(1.0), 1e-7);
}

TEST(DistanceCorrectionTest, AppliedAfterEquationOneWithWrap) {
  OffsetCalibration c = MakeCalibration(2, 1, 0.1f);
  DistanceCorrection g;
  g.start_m = 0.0;
  g.step_m = 1.0;
  g.correction_m.assign(9, 0.02f);  // constant 20 mm too long
  c.distance_correction = g;
  MetricFrame m = MakeFrame(2, 1, 0.0f);
  m.radial_distance_m(0, 0) = 3.0f;   // eq. 1: 2.9, then 2.88
  m.radial_distance_m(0, 1) = 0.11f;  // eq. 1: 0.01, then -0.01 wraps to L - 0.01
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_NEAR(l.radial_distance_m(0, 0), 2.88, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 1), kL20 - 0.01, 2e-6);
}

TEST(OffsetCalibrationTest, ValidateNamesTheProblem) {
  EXPECT_NO_THROW(MakeCalibration(3, 2, 0.1f).Validate());
  const auto message = [](const OffsetCalibration& c) {
    try {
      c.Validate();
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
      return std::string(e.what());
    }
    return std::string("no error");
  };
  OffsetCalibration c = MakeCalibration(3, 2, 0.1f);
  c.offset_m(1, 2) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(message(c).find("row 1, col 2"), std::string::npos) << message(c);
  c = MakeCalibration(3, 2, 4.0f);  // beyond L / 2
  EXPECT_NE(message(c).find("L/2"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.width = 4;
  EXPECT_NE(message(c).find("header says 4x2"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.version = 3;
  EXPECT_NE(message(c).find("version 3"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.modulation_frequency_hz = 0.0;
  EXPECT_NE(message(c).find("modulation_frequency_hz"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.distance_correction = DistanceCorrection{0.0, 0.0, {0.0f, 0.0f}};
  EXPECT_NE(message(c).find("step_m"), std::string::npos);
  c.distance_correction = DistanceCorrection{0.0, 0.1, {0.0f}};
  EXPECT_NE(message(c).find("knots"), std::string::npos);
  c.distance_correction =
      DistanceCorrection{0.0, 0.1, {0.0f, std::numeric_limits<float>::infinity()}};
  EXPECT_NE(message(c).find("correction_m[1]"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.pixel_flags = Image<PixelFlags>(2, 2);
  EXPECT_NE(message(c).find("pixel_flags"), std::string::npos);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

TEST(ExposureOffsetTest, EquationOneWithTheExposureTermHandValues) {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = 3;
  c.height = 1;
  c.offset_m = Image<float>(3, 1, 0.0f);
  c.integration_time_us = 5100.0;  // register 20 at 255 us
  c.exposure_offset_m_per_ms = 0.0005;
  MetricFrame m;
  m.radial_distance_m = Image<float>(3, 1, 0.0f);
  m.amplitude = Image<float>(3, 1, 1000.0f);
  m.intensity = Image<float>(3, 1, 5000.0f);
  m.flags = Image<PixelFlags>(3, 1);
  m.info.integration_time_us = 25500.0;  // register 100: t - t_cal = 20.4 ms -> 10.2 mm
  m.radial_distance_m(0, 0) = 2.0f;
  c.offset_m(0, 0) = 0.05f;  // 2.0 - 0.05 - 0.0102 = 1.9398
  m.radial_distance_m(0, 1) = 0.005f;
  c.offset_m(0, 1) = 0.0f;  // 0.005 - 0.0102 wraps: 7.49481145 - 0.0052 = 7.48961145
  m.radial_distance_m(0, 2) = 3.0f;
  m.flags(0, 2) = PixelFlags(Flag::kInvalid);  // untouched
  EXPECT_NEAR(ExposureShiftM(c, 25500.0), 0.0102, 1e-12);
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_NEAR(l.radial_distance_m(0, 0), 1.9398, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 1), 7.48961145, 2e-6);
  EXPECT_FLOAT_EQ(l.radial_distance_m(0, 2), 3.0f);

  // At the calibration's own integration time, and when the frame's is unknown (0, e.g. an
  // imported camera), the term vanishes: plain eq. 1.
  for (const double t : {5100.0, 0.0}) {
    m.info.integration_time_us = t;
    EXPECT_EQ(ExposureShiftM(c, t), 0.0);
    const MetricFrame same = ApplyCalibration(m, c);
    EXPECT_NEAR(same.radial_distance_m(0, 0), 1.95, 2e-6) << t;
    EXPECT_NEAR(same.radial_distance_m(0, 1), 0.005, 2e-6) << t;
  }
  // Shorter than at calibration: the camera read short, so the term adds distance.
  m.info.integration_time_us = 1020.0;  // -4.08 ms -> -2.04 mm
  EXPECT_NEAR(ApplyCalibration(m, c).radial_distance_m(0, 0), 1.95204, 2e-6);
}

TEST(ExposureOffsetTest, ValidatesTheSlopeAndAbsurdShifts) {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = 1;
  c.height = 1;
  c.offset_m = Image<float>(1, 1, 0.0f);
  c.exposure_offset_m_per_ms = 0.2;  // beyond ±0.1 m/ms
  EXPECT_THROW(c.Validate(), Error);
  c.exposure_offset_m_per_ms = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(c.Validate(), Error);
  c.exposure_offset_m_per_ms = 0.1;
  // s (t - t_cal) needs t_cal: without it every frame would shift by s t.
  try {
    c.Validate();
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("integration_time_us"), std::string::npos) << e.what();
  }
  c.integration_time_us = 1000.0;
  EXPECT_NO_THROW(c.Validate());
  MetricFrame m;
  m.radial_distance_m = Image<float>(1, 1, 1.0f);
  m.amplitude = Image<float>(1, 1, 1000.0f);
  m.flags = Image<PixelFlags>(1, 1);
  m.info.integration_time_us = 30000.0;  // 0.1 m/ms x (30 - 1) ms = 2.9 m > L/4
  try {
    (void)ApplyCalibration(m, c);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("beyond L/4"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tofcam
