#include "tofcam/calibration/calibration_procedure.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "fake_wall_camera.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {
namespace {

using testing::FakeWallCamera;
using testing::FakeWallOptions;

constexpr double kL20 = 7.49481145;

WallCalibrationOptions FastOptions(double distance_m) {
  WallCalibrationOptions o;
  o.wall_distance_m = distance_m;
  o.frames = 40;
  o.warmup_window_frames = 60;
  o.warmup_max_frames = 3000;
  // 2 mm/s: the fake's 20 s time constant gets there in under a minute of camera time.
  o.warmup_max_drift_m_per_s = 2e-3;
  // The exposure-offset measurement has its own tests below; here it would add frames (and
  // drift) after the averaging that the drift checks do not expect.
  o.exposure_offset_fractions = {};
  return o;
}

TEST(WallRadialDistanceTest, RayPlaneIntersection) {
  CameraIntrinsics k;
  k.width = 3;
  k.height = 3;
  k.fx_px = 2.0;
  k.fy_px = 4.0;
  k.cx_px = 1.0;
  k.cy_px = 1.0;
  const Image<float> t = WallRadialDistance(k, 2.0, {0.0, 0.0, 1.0});
  EXPECT_NEAR(t(1, 1), 2.0, 1e-6);                                   // optical axis
  EXPECT_NEAR(t(1, 2), 2.0 * std::sqrt(1.0 + 0.25), 1e-6);           // x = 1/2
  EXPECT_NEAR(t(0, 0), 2.0 * std::sqrt(1.0 + 0.25 + 0.0625), 1e-6);  // x = -1/2, y = -1/4
  // Wall turned 45° about y: n = (1, 0, 1)/sqrt(2), plane n.x = 2. Axis ray: t = 2 sqrt(2).
  const Image<float> tilted = WallRadialDistance(k, 2.0, {1.0, 0.0, 1.0});
  EXPECT_NEAR(tilted(1, 1), 2.0 * std::sqrt(2.0), 1e-5);
  // Pixel (1, 2): ray (0.5, 0, 1)/|.|; n.r = 1.5 / (sqrt(2) sqrt(1.25)); t = 2 / n.r.
  EXPECT_NEAR(tilted(1, 2), 2.0 * std::sqrt(2.0) * std::sqrt(1.25) / 1.5, 1e-5);
  EXPECT_THROW((void)WallRadialDistance(k, 2.0, {0.0, 0.0, -1.0}), Error);
}

TEST(CalibrateOffsetsTest, RecoversTheOffsetPatternAfterWarmup) {
  FakeWallOptions fo;
  fo.drift_amplitude_m = 0.2;
  fo.drift_time_constant_s = 20.0;
  FakeWallCamera camera(fo);
  std::set<std::string> phases;
  WallCalibrationReport report;
  const OffsetCalibration c = CalibrateOffsets(
      camera, FastOptions(1.5),
      [&](const CalibrationProgress& p) { phases.insert(std::string(p.phase)); }, &report);
  EXPECT_EQ(phases, (std::set<std::string>{"exposure", "warm-up", "averaging"}));
  EXPECT_EQ(c.width, 40);
  EXPECT_EQ(c.camera_model, "FAKE");
  EXPECT_EQ(c.frames_averaged, 40);
  EXPECT_TRUE(c.pixel_flags.empty());
  EXPECT_NO_THROW(c.Validate());
  // Exposure: median intensity at 62 * 256 = 15872 (± the deadband of 2 * 256). I = 3000 reg /
  // t^2 with t = 1.5 m on the axis and up to 1.14 x 1.5 m at the corners: register 12 or 13.
  EXPECT_GE(report.integration_register, 12);
  EXPECT_LE(report.integration_register, 13);
  EXPECT_EQ(c.integration_time_register, report.integration_register);
  // Warm-up: drift 200 mm e^(-t/20 s), rate 10 e^(-t/20) mm/s, 2 mm/s at t = 20 ln 5 = 32.2 s
  // = frame 966 from power-on (exposure frames included). The 60-frame regression lags by 1 s
  // and has a noise of ~0.08 mm/s (per-frame mean good to 12 mm / sqrt(1240) = 0.34 mm):
  // it ends within frames 900..1100.
  const int settled_at = report.exposure_frames + report.warmup_frames;
  EXPECT_GT(settled_at, 900);
  EXPECT_LT(settled_at, 1100);
  EXPECT_LE(std::abs(report.drift_m_per_s), 2e-3);
  // Offsets = the pattern plus the drift left at averaging time; the drift is common to all
  // pixels, so compare after removing the mean difference.
  const double drift_now = camera.Drift();
  double sum = 0.0, sum2 = 0.0, max_err = 0.0;
  const int n = 40 * 31;
  for (int r = 0; r < 31; ++r) {
    for (int col = 0; col < 40; ++col) {
      const double err = c.offset_m(r, col) - camera.TrueOffset(r, col);
      sum += err;
      sum2 += err * err;
    }
  }
  const double mean = sum / n;
  for (int r = 0; r < 31; ++r) {
    for (int col = 0; col < 40; ++col) {
      max_err = std::max(max_err, std::abs(c.offset_m(r, col) - camera.TrueOffset(r, col) - mean));
    }
  }
  const double rms = std::sqrt(sum2 / n - mean * mean);
  // The mean error is the drift at mid-averaging: 2 mm/s x 0.67 s above the drift now.
  EXPECT_NEAR(mean, drift_now, 3e-3);
  // Noise: σ = (2/π) ΔL ≈ 12 mm per frame at I ≈ 16000 (up to 14 mm in the dimmer corners);
  // averaged over 40 frames σ/sqrt(40) ≈ 2 mm; the RMS must be at that level and no pixel
  // beyond 5 σ of the corners (11 mm).
  EXPECT_LT(rms, 3e-3);
  EXPECT_LT(max_err, 0.011);
  EXPECT_NEAR(report.noise_sigma_m, 0.012, 0.006);
}

TEST(CalibrateOffsetsTest, WrapAtTheSeamIsAveragedAsPhasors) {
  // Narrow field of view; wall at L - 0.3 m and every pixel 0.3 m long: the measurements
  // straddle the 0 / L seam (half near 0, half near L). A naive mean would be off by ~L/2.
  FakeWallOptions fo;
  fo.width = 8;
  fo.height = 6;
  fo.fx_px = 400.0;
  fo.fy_px = 400.0;
  fo.pattern = false;
  fo.constant_offset_m = 0.3;
  fo.wall_distance_m = kL20 - 0.3;
  fo.signal_per_register_at_1m = 3000.0 * 56.0 / 2.25;  // same exposure as 1.5 m
  FakeWallCamera camera(fo);
  WallCalibrationOptions o = FastOptions(kL20 - 0.3);
  o.warmup_window_frames = 10;
  const OffsetCalibration c = CalibrateOffsets(camera, o);
  for (int r = 0; r < 6; ++r) {
    for (int col = 0; col < 8; ++col) {
      // Noise per frame ≈ 12 mm, 40 frames: 2 mm; 10 mm is 5 σ.
      EXPECT_NEAR(c.offset_m(r, col), 0.3, 0.01) << r << "," << col;
    }
  }
  // Applying it brings the wrapped measurements back to the wall: e.g. m = 0.05 (wrapped)
  // -> (0.05 - 0.3 + L) mod L = L - 0.25, the wall at L - 0.3 plus 5 cm of noise.
  MetricFrame m;
  m.radial_distance_m = Image<float>(8, 6, 0.05f);
  m.amplitude = Image<float>(8, 6, 1.0f);
  m.flags = Image<PixelFlags>(8, 6);
  EXPECT_NEAR(ApplyCalibration(m, c).radial_distance_m(0, 0), kL20 - 0.25, 0.011);
}

TEST(CalibrateOffsetsTest, NeverSettlingDriftIsAClearError) {
  FakeWallOptions fo;
  fo.drift_linear_m_per_s = 0.01;  // 10 mm/s forever
  FakeWallCamera camera(fo);
  WallCalibrationOptions o = FastOptions(1.5);
  o.warmup_max_frames = 200;
  try {
    (void)CalibrateOffsets(camera, o);
    FAIL() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("still drifts by 9."), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("200 warm-up frames"), std::string::npos) << e.what();
  }
}

TEST(CalibrateOffsetsTest, OscillatingControllerIsAClearError) {
  FakeWallCamera camera(FakeWallOptions{});
  WallCalibrationOptions o = FastOptions(1.5);
  // 1333 intensity per register on the axis: V_p = 0.01 overshoots by a factor of ~13.
  o.controller.kind = ControllerKind::kMayIncremental;
  o.controller.gain_register_per_intensity = 0.01;
  o.controller_max_frames = 50;
  try {
    (void)CalibrateOffsets(camera, o);
    FAIL() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("did not settle within 50 frames"), std::string::npos)
        << e.what();
  }
}

TEST(CalibrateOffsetsTest, BlockedPixelsAreFlaggedOrRejected) {
  FakeWallOptions fo;
  fo.blocked_columns = 2;  // 2 of 40 columns: 5 % of the pixels
  FakeWallCamera camera(fo);
  WallCalibrationReport report;
  const OffsetCalibration c = CalibrateOffsets(camera, FastOptions(1.5), {}, &report);
  EXPECT_EQ(report.uncalibrated_pixels, 2 * 31);
  ASSERT_FALSE(c.pixel_flags.empty());
  EXPECT_TRUE(c.pixel_flags(5, 1).Has(Flag::kInvalid));
  EXPECT_TRUE(c.pixel_flags(5, 2).None());

  fo.blocked_columns = 10;  // 25 %
  FakeWallCamera blocked(fo);
  try {
    (void)CalibrateOffsets(blocked, FastOptions(1.5));
    FAIL() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
    EXPECT_NE(std::string(e.what()).find("310 of 1240 pixels"), std::string::npos) << e.what();
  }
}

TEST(CalibrateOffsetsTest, RejectsBadOptions) {
  FakeWallCamera camera(FakeWallOptions{});
  const auto code = [&](auto mutate) {
    WallCalibrationOptions o = FastOptions(1.5);
    mutate(o);
    try {
      (void)CalibrateOffsets(camera, o);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kInternal;
  };
  const auto bad = ErrorCode::kInvalidArgument;
  EXPECT_EQ(code([](auto& o) { o.wall_distance_m = 0; }), bad);
  EXPECT_EQ(code([](auto& o) { o.wall_distance_m = 8.0; }), bad);  // beyond L
  EXPECT_EQ(code([](auto& o) { o.wall_distance_m = std::nan(""); }), bad);
  EXPECT_EQ(code([](auto& o) { o.wall_normal = {0, 0, 0}; }), bad);
  EXPECT_EQ(code([](auto& o) { o.frames = 0; }), bad);
  EXPECT_EQ(code([](auto& o) { o.warmup_window_frames = 2; }), bad);
  EXPECT_EQ(code([](auto& o) { o.warmup_max_frames = 10; }), bad);
  EXPECT_EQ(code([](auto& o) { o.warmup_max_drift_m_per_s = 0; }), bad);
  EXPECT_EQ(code([](auto& o) { o.min_valid_fraction = 0; }), bad);
  EXPECT_EQ(code([](auto& o) { o.max_uncalibrated_fraction = 1.5; }), bad);
  EXPECT_EQ(code([](auto& o) { o.controller.target_intensity = -1; }), bad);
}

TEST(SweepTest, DistanceCorrectionRemovesWiggling) {
  FakeWallOptions fo;
  fo.wiggle_amplitude_m = 0.03;  // ±30 mm with period L/4 = 1.87 m
  FakeWallCamera camera(fo);
  WallCalibrationOptions wall = FastOptions(1.5);
  wall.warmup_window_frames = 10;
  const OffsetCalibration base = CalibrateOffsets(camera, wall);

  SweepOptions s;
  s.from_m = 0.5;
  s.to_m = 7.0;
  s.step_m = 0.25;
  s.frames_per_distance = 10;
  s.wall = wall;
  int calls = 0;
  SweepReport report;
  const OffsetCalibration full = CalibrateDistanceCorrection(
      base,
      [&](double d) -> Camera& {
        ++calls;
        camera.MoveWall(d);
        return camera;
      },
      s, {}, &report);
  EXPECT_EQ(calls, 27 + 26);  // 0.5, 0.75, ..., 7.0 and the 26 midpoints
  ASSERT_TRUE(full.distance_correction.has_value());
  EXPECT_EQ(report.distances.size(), 53u);
  for (const SweepDistanceResult& d : report.distances) {
    EXPECT_GT(d.pixels, 700) << d.wall_distance_m;  // corners beyond L drop out near 7 m
    // Every distance, not only on average: after <= noise floor + 3 mm. Below 1 m the radial
    // distances one wall sees ([d, 1.14 d]) leave gaps between 0.25 m steps that the table
    // bridges linearly; the worst of them (0.875 m) sits ~2.6 mm above the floor.
    EXPECT_LT(d.rms_after_m, d.noise_floor_m + 0.003) << d.wall_distance_m;
  }
  // Before: the paper's offsets leave w(t) - w(t_wall) of a ±30 mm sine: RMS around 25 mm.
  EXPECT_GT(report.held_out_rms_before_m, 0.015);
  // After: at the noise floor of 10-frame averages (a few mm), far below the wiggling.
  EXPECT_LT(report.held_out_rms_after_m, report.held_out_rms_before_m / 4);
  EXPECT_LT(report.held_out_rms_after_m, 2.0 * report.held_out_noise_floor_m + 0.002)
      << "noise floor " << report.held_out_noise_floor_m;
  // The correction carries the whole wiggling: 60 mm peak to peak over one period.
  const DistanceCorrection& g = *full.distance_correction;
  double lo = 1.0, hi = -1.0;
  for (double d = 2.0; d < 2.0 + 1.874; d += 0.01) {
    lo = std::min(lo, g.Evaluate(d));
    hi = std::max(hi, g.Evaluate(d));
  }
  EXPECT_NEAR(hi - lo, 0.06, 0.006);
}

TEST(SweepTest, RejectsBadOptions) {
  FakeWallCamera camera(FakeWallOptions{});
  OffsetCalibration base;
  base.camera_model = "FAKE";
  base.width = 40;
  base.height = 31;
  base.offset_m = Image<float>(40, 31);
  const WallCameraSource source = [&](double) -> Camera& { return camera; };
  const auto code = [&](auto mutate) {
    SweepOptions s;
    mutate(s);
    try {
      (void)CalibrateDistanceCorrection(base, source, s);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kInternal;
  };
  const auto bad = ErrorCode::kInvalidArgument;
  EXPECT_EQ(code([](auto& s) { s.from_m = 0; }), bad);
  EXPECT_EQ(code([](auto& s) { s.to_m = 0.2; }), bad);
  EXPECT_EQ(code([](auto& s) { s.to_m = 7.6; }), bad);  // beyond L
  EXPECT_EQ(code([](auto& s) { s.step_m = 0; }), bad);
  EXPECT_EQ(code([](auto& s) { s.step_m = 1e-5; }), bad);  // too many distances
  EXPECT_EQ(code([](auto& s) { s.lut_step_m = 0; }), bad);
  EXPECT_EQ(code([](auto& s) { s.refine_iterations = -1; }), bad);
  EXPECT_EQ(code([](auto& s) { s.outlier_m = 4.0; }), bad);
  base.width = 41;
  base.offset_m = Image<float>(41, 31);
  EXPECT_EQ(code([](auto&) {}), ErrorCode::kMismatch);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

// A wall whose return needs a long integration time (register ~125), so the exposure
// measurement spans 8..32 ms.
FakeWallOptions DimWall(double exposure_offset_m_per_ms) {
  FakeWallOptions fo;
  fo.signal_per_register_at_1m = 300.0;
  fo.exposure_offset_m_per_ms = exposure_offset_m_per_ms;
  return fo;
}

TEST(ExposureOffsetTest, RecoversTheCamerasSlopeWithOneGlobalValue) {
  FakeWallCamera camera(DimWall(0.0005));  // the simulated SR-2's 0.5 mm per ms
  WallCalibrationOptions o = FastOptions(1.5);
  o.exposure_offset_fractions = {0.25, 0.5};
  o.exposure_offset_frames = 40;
  std::set<std::string> phases;
  WallCalibrationReport report;
  const OffsetCalibration c = CalibrateOffsets(
      camera, o, [&](const CalibrationProgress& p) { phases.insert(std::string(p.phase)); },
      &report);
  EXPECT_TRUE(phases.count("exposure-offset"));
  ASSERT_EQ(report.exposure_registers.size(), 3u);
  const int base = report.exposure_registers[0];
  EXPECT_EQ(base, c.integration_time_register);
  EXPECT_GT(base, 100);  // I = 300 reg / t^2 reaches the median 15872 near register 125
  EXPECT_EQ(report.exposure_registers[1], static_cast<int>(std::lround(base * 0.25)));
  EXPECT_EQ(report.exposure_registers[2], static_cast<int>(std::lround(base * 0.5)));
  EXPECT_EQ(camera.IntegrationTimeRegister(), base);  // left at the calibration's register
  // Slope noise: per-register means over 40 frames x 1240 pixels are good to 0.08-0.15 mm over
  // a span of 24 ms, so s is known to ~0.006 mm/ms (1.3 %); 5 % is about 4 sigma.
  EXPECT_NEAR(c.exposure_offset_m_per_ms, 0.0005, 0.05 * 0.0005);
  EXPECT_DOUBLE_EQ(c.exposure_offset_m_per_ms, report.exposure_offset_m_per_ms);
  // Shift at each register: s (t_k - t_cal), t = 255 us per register.
  for (std::size_t k = 0; k < 3; ++k) {
    const double expected = 0.0005 * (report.exposure_registers[k] - base) * 0.255;
    EXPECT_NEAR(report.exposure_shift_m[k], expected, 4e-4) << k;
  }
  // The fake's shift is the same for every pixel: the per-pixel slopes scatter by exactly what
  // their noise predicts (the sd is estimated from 1240 pixels, ~2 %; the prediction from
  // per-pixel σ of 40 frames; 15 % covers both).
  EXPECT_GT(report.exposure_pixels, 1200);
  EXPECT_NEAR(report.exposure_pixel_slope_sd_m_per_ms / report.exposure_pixel_slope_noise_m_per_ms,
              1.0, 0.15);
}

TEST(ExposureOffsetTest, CompensationRemovesTheShiftAtAnotherIntegrationTime) {
  FakeWallCamera camera(DimWall(0.0005));
  WallCalibrationOptions o = FastOptions(1.5);
  o.exposure_offset_fractions = {0.25, 0.5};
  o.exposure_offset_frames = 40;
  const OffsetCalibration c = CalibrateOffsets(camera, o);
  OffsetCalibration uncompensated = c;
  uncompensated.exposure_offset_m_per_ms = 0.0;
  // Frames at a quarter of the calibration's integration time: the camera reads
  // 0.5 mm/ms x (t - t_cal) shorter, about -24 mm x 0.75 = -12 mm.
  const int reg = c.integration_time_register / 4;
  camera.SetIntegrationTimeRegister(reg);
  const double expected_shift = 0.0005 * (reg - c.integration_time_register) * 0.255;
  double with = 0.0, without = 0.0;
  int n = 0;
  for (int k = 0; k < 20; ++k) {
    const MetricFrame m = ConvertToMetric(*camera.Grab());
    const MetricFrame a = ApplyCalibration(m, c);
    const MetricFrame b = ApplyCalibration(m, uncompensated);
    for (int r = 0; r < 31; ++r) {
      for (int col = 0; col < 40; ++col) {
        with += a.radial_distance_m(r, col) - camera.TrueDistance(r, col);
        without += b.radial_distance_m(r, col) - camera.TrueDistance(r, col);
        ++n;
      }
    }
  }
  // Means over 24800 samples of ~33 mm noise: good to 0.2 mm, plus the offsets' own averaging
  // noise (40 frames, ~0.1 mm in the mean).
  EXPECT_NEAR(without / n, expected_shift, 1e-3);
  EXPECT_LT(expected_shift, -0.008);
  EXPECT_NEAR(with / n, 0.0, 1e-3);
}

TEST(ExposureOffsetTest, NotMeasuredWithoutOtherRegisters) {
  FakeWallCamera camera(DimWall(0.0005));
  WallCalibrationOptions o = FastOptions(1.5);
  o.exposure_offset_fractions = {1.0};  // the calibration register itself: nothing to compare
  WallCalibrationReport report;
  const OffsetCalibration c = CalibrateOffsets(camera, o, {}, &report);
  EXPECT_EQ(c.exposure_offset_m_per_ms, 0.0);
  EXPECT_EQ(report.exposure_registers.size(), 1u);
  o.exposure_offset_fractions = {0.0};
  EXPECT_THROW((void)CalibrateOffsets(camera, o), Error);
  o.exposure_offset_fractions = {0.5};
  o.exposure_offset_frames = 0;
  EXPECT_THROW((void)CalibrateOffsets(camera, o), Error);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

TEST(SweepIntegrationTimeTest, MeansMatchTheFakesRadiometry) {
  FakeWallOptions fo;
  fo.signal_per_register_at_1m = 3000.0;
  FakeWallCamera camera(fo);
  camera.SetIntegrationTimeRegister(7);
  IntegrationSweepOptions o;
  o.from_register = 10;
  o.to_register = 50;
  o.steps = 5;
  const std::vector<IntegrationSweepPoint> points = SweepIntegrationTime(camera, o);
  ASSERT_EQ(points.size(), 5u);
  EXPECT_EQ(camera.IntegrationTimeRegister(), 7);  // left where it was
  for (std::size_t k = 0; k < points.size(); ++k) {
    const int reg = 10 + 10 * static_cast<int>(k);
    EXPECT_EQ(points[k].integration_register, reg);
    // The fake: I = 3000 reg / t^2 clipped at 65532, A = 0.4 x that signal (both rounded).
    double i_sum = 0.0, a_sum = 0.0, sat = 0.0;
    for (int r = 0; r < 31; ++r) {
      for (int c = 0; c < 40; ++c) {
        const double t = camera.TrueDistance(r, c);
        const double signal = 3000.0 * reg / (t * t);
        const double i = std::min(signal, 65532.0);
        const double a = std::min(0.4 * signal, 65532.0);
        i_sum += i;
        a_sum += a;
        sat += (i >= 65532.0 || i + a >= 64221.0) ? 1 : 0;
      }
    }
    EXPECT_NEAR(points[k].mean_intensity, i_sum / 1240, 1.0) << reg;  // register rounding
    EXPECT_NEAR(points[k].mean_amplitude, a_sum / 1240, 1.0) << reg;
    EXPECT_NEAR(points[k].saturated_fraction, sat / 1240, 1e-9) << reg;
  }
  EXPECT_GT(points.back().saturated_fraction, 0.5);  // register 50 at 1.5 m: I ~ 66000
  o.steps = 2;
  EXPECT_THROW((void)SweepIntegrationTime(camera, o), Error);
  o = IntegrationSweepOptions{};
  o.from_register = 100;
  o.to_register = 300;  // beyond the fake's 255
  EXPECT_THROW((void)SweepIntegrationTime(camera, o), Error);
}

TEST(SweepIntegrationTimeTest, ClippedPixelsWithoutPhaseCountBlockedOnesDoNot) {
  // Pixels whose intensity clips read amplitude 0 (kInvalid: no phase) at 65532: they are
  // readings and count with amplitude 0; the 5 blocked columns (all registers 0) do not.
  FakeWallOptions fo;
  fo.collapse_clipped = true;
  fo.blocked_columns = 5;
  FakeWallCamera camera(fo);
  IntegrationSweepOptions o;
  o.from_register = 20;
  o.to_register = 60;
  o.steps = 3;
  const std::vector<IntegrationSweepPoint> points = SweepIntegrationTime(camera, o);
  ASSERT_EQ(points.size(), 3u);
  for (std::size_t k = 0; k < points.size(); ++k) {
    const int reg = 20 + 20 * static_cast<int>(k);
    double i_sum = 0.0, a_sum = 0.0;
    int n = 0;
    for (int r = 0; r < 31; ++r) {
      for (int c = 5; c < 40; ++c) {
        const double t = camera.TrueDistance(r, c);
        const double signal = 3000.0 * reg / (t * t);
        i_sum += std::min(signal, 65532.0);
        a_sum += signal >= 65532.0 ? 0.0 : 0.4 * signal;
        ++n;
      }
    }
    EXPECT_NEAR(points[k].mean_intensity, i_sum / n, 1.0) << reg;
    EXPECT_NEAR(points[k].mean_amplitude, a_sum / n, 1.0) << reg;
  }
  // Register 60 at 1.5-1.9 m: signal 50000-80000, so part of the wall clips and collapses.
  EXPECT_LT(points[2].mean_amplitude, points[1].mean_amplitude * 1.5);
}

// A camera that ends after `frames` frames (a finite recording).
class FiniteCamera final : public Camera {
 public:
  FiniteCamera(FakeWallCamera& inner, int frames) : inner_(inner), left_(frames) {}
  std::optional<Frame> Grab() override {
    if (left_ == 0) return std::nullopt;
    --left_;
    return inner_.Grab();
  }
  const CameraInfo& Info() const override { return inner_.Info(); }
  void SetIntegrationTimeRegister(int reg) override { inner_.SetIntegrationTimeRegister(reg); }
  int IntegrationTimeRegister() const override { return inner_.IntegrationTimeRegister(); }
  void SetModulationFrequencyHz(double hz) override { inner_.SetModulationFrequencyHz(hz); }
  void SetDistanceOffsetRegister(int reg) override { inner_.SetDistanceOffsetRegister(reg); }
  int DistanceOffsetRegister() const override { return inner_.DistanceOffsetRegister(); }
  void SetPanAngleRad(double a) override { inner_.SetPanAngleRad(a); }
  double PanAngleRad() const override { return 0.0; }

 private:
  FakeWallCamera& inner_;
  int left_;
};

TEST(CalibrateNoiseTest, RecoversTheFakesNoiseScale) {
  FakeWallOptions fo;
  fo.noise_scale = 2.0 / kPi;  // σ = 0.637 ΔL, ideal 4-tap sampling with unit gain
  FakeWallCamera camera(fo);
  camera.SetIntegrationTimeRegister(12);  // median intensity ~16000
  DeltaLScaleFit fit;
  std::set<std::string> phases;
  const NoiseCalibration n = CalibrateNoise(
      camera, {}, [&](const CalibrationProgress& p) { phases.insert(std::string(p.phase)); }, &fit);
  EXPECT_EQ(phases, std::set<std::string>{"noise"});
  EXPECT_EQ(n.frames, 30);
  EXPECT_EQ(n.pixels_used, 1240);
  EXPECT_EQ(n.delta_l_scale, fit.scale);
  // 1240 pixels x 30 frames: the least-squares scale is good to ~1 %; 5 % is ~4 sigma.
  EXPECT_NEAR(n.delta_l_scale, 2.0 / kPi, 0.05 * 2.0 / kPi);

  // A finite source is used with the frames it had, but needs 3.
  FiniteCamera five(camera, 5);
  EXPECT_EQ(CalibrateNoise(five).frames, 5);
  FiniteCamera two(camera, 2);
  try {
    (void)CalibrateNoise(two);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kIo);
    EXPECT_NE(std::string(e.what()).find("delivered 2 frames"), std::string::npos) << e.what();
  }
  NoiseCalibrationOptions bad;
  bad.frames = 2;
  EXPECT_THROW((void)CalibrateNoise(camera, bad), Error);
}

TEST(GroundTruthNoiseScaleTest, LeastSquaresOnTheTruthSigma) {
  // 4 x 4 pixels, A = 100 * (1 + k), I = 2.5 A: ΔL(scale 1) from eq. 2 by hand, truth σ = 0.2 ΔL
  // except one pixel flagged kInvalid with a wild σ, which must be ignored.
  MetricFrame m;
  m.radial_distance_m = Image<float>(4, 4, 2.0f);
  m.amplitude = Image<float>(4, 4);
  m.intensity = Image<float>(4, 4);
  m.flags = Image<PixelFlags>(4, 4);
  m.truth = GroundTruth{};
  m.truth->sigma_m = Image<float>(4, 4);
  const double range = UnambiguousRangeM(20e6);
  for (std::size_t k = 0; k < 16; ++k) {
    m.amplitude[k] = static_cast<float>(100.0 * (1 + k));
    m.intensity[k] = 2.5f * m.amplitude[k];
    const double delta_l =
        range / std::sqrt(8.0) * std::sqrt(m.intensity[k]) / (2 * m.amplitude[k]);
    m.truth->sigma_m[k] = static_cast<float>(0.2 * delta_l);
  }
  m.truth->sigma_m[3] = 5.0f;
  m.flags[3] = PixelFlags(Flag::kInvalid);
  const std::optional<double> scale = GroundTruthNoiseScale(m);
  ASSERT_TRUE(scale.has_value());
  EXPECT_NEAR(*scale, 0.2, 1e-6);  // float σ
  DeltaLFitOptions strict;
  strict.min_pixels = 16;  // only 15 usable
  EXPECT_FALSE(GroundTruthNoiseScale(m, strict).has_value());
  m.truth.reset();
  EXPECT_FALSE(GroundTruthNoiseScale(m).has_value());
}

}  // namespace
}  // namespace tofcam
