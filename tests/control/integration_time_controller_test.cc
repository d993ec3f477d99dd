#include "tofcam/control/integration_time_controller.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

MetricFrame Uniform(float intensity, int w = 4, int h = 4) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(w, h, 1.0f);
  m.amplitude = Image<float>(w, h, 100.0f);
  m.intensity = Image<float>(w, h, intensity);
  m.flags = Image<PixelFlags>(w, h);
  return m;
}

ControllerOptions Opts(ControllerKind kind, double vp, int c0) {
  ControllerOptions o;
  o.kind = kind;
  o.target_intensity = 16000.0;
  o.gain_register_per_intensity = vp;
  o.bias_register = c0;
  return o;
}

TEST(ControllerKindTest, NamesRoundTrip) {
  for (ControllerKind k :
       {ControllerKind::kMayProportional, ControllerKind::kMayIncremental,
        ControllerKind::kVendorHistogram, ControllerKind::kFixed, ControllerKind::kModelBased}) {
    EXPECT_EQ(ParseControllerKind(ControllerKindName(k)), k);
    EXPECT_EQ(MakeController(Opts(k, 0.01, 50))->Name(), ControllerKindName(k));
  }
  EXPECT_THROW((void)ParseControllerKind("pid"), Error);
}

TEST(MayProportionalTest, PrintedLawOnHandComputedSequence) {
  MayProportional p(Opts(ControllerKind::kMayProportional, 0.01, 50));
  // c = -V_p (Ī - I_A) + c_0 with V_p = 0.01, I_A = 16000, c_0 = 50.
  EXPECT_EQ(p.Update(Uniform(18000)), 30);   // -20 + 50
  EXPECT_EQ(p.Update(Uniform(10000)), 110);  // +60 + 50
  EXPECT_EQ(p.Update(Uniform(16000)), 50);   // on target: the bias itself
  EXPECT_EQ(p.Update(Uniform(16000)), 50);   // position form: no memory of the past
  EXPECT_EQ(p.Update(Uniform(40000)), 1);    // -240 + 50 clamped to the minimum
  EXPECT_EQ(p.Update(Uniform(0)), 210);      // +160 + 50
  ControllerOptions capped = Opts(ControllerKind::kMayProportional, 0.01, 50);
  capped.max_register = 200;
  capped.min_register = 10;
  MayProportional q(capped);
  EXPECT_EQ(q.Update(Uniform(0)), 200);
  EXPECT_EQ(q.Update(Uniform(40000)), 10);
  // Rounds to the nearest register: -0.001 * 2400 + 50 = 47.6.
  MayProportional r(Opts(ControllerKind::kMayProportional, 0.001, 50));
  EXPECT_EQ(r.Update(Uniform(18400)), 48);
}

TEST(MayIncrementalTest, AccumulatesClampsAndResets) {
  MayIncremental c(Opts(ControllerKind::kMayIncremental, 0.01, 50));
  EXPECT_EQ(c.Update(Uniform(18000)), 30);   // 50 - 20
  EXPECT_EQ(c.Update(Uniform(17000)), 20);   // 30 - 10
  EXPECT_EQ(c.Update(Uniform(16000)), 20);   // on target: holds (no steady-state offset)
  EXPECT_EQ(c.Update(Uniform(10000)), 80);   // 20 + 60
  EXPECT_EQ(c.Update(Uniform(0)), 240);      // 80 + 160
  EXPECT_EQ(c.Update(Uniform(0)), 255);      // 400 clamped; the state is clamped too
  EXPECT_EQ(c.Update(Uniform(30000)), 115);  // 255 - 140 (no wind-up beyond 255)
  c.Reset(7);
  EXPECT_EQ(c.Update(Uniform(16500)), 2);  // 7 - 5
  EXPECT_EQ(c.Update(Uniform(17000)), 1);  // -8 clamped to 1
  // Small corrections accumulate instead of rounding away: 50 - 0.2 per frame.
  MayIncremental slow(Opts(ControllerKind::kMayIncremental, 0.0001, 50));
  EXPECT_EQ(slow.Update(Uniform(18000)), 50);  // 49.8
  EXPECT_EQ(slow.Update(Uniform(18000)), 50);  // 49.6
  EXPECT_EQ(slow.Update(Uniform(18000)), 49);  // 49.4
}

TEST(ControllerTest, MeanOverRoiAndUsablePixels) {
  MetricFrame m = Uniform(10000, 4, 4);
  // ROI rows 1..2, cols 2..3 holds 20000; one of its pixels is invalid with a huge value and
  // one is saturated (saturated pixels must count).
  for (int r = 1; r <= 2; ++r)
    for (int c = 2; c <= 3; ++c) m.intensity(r, c) = 20000;
  m.intensity(1, 2) = 60000;
  m.flags(1, 2) = PixelFlags(Flag::kInvalid);
  m.intensity(2, 3) = 26000;
  m.flags(2, 3) = PixelFlags(Flag::kSaturated);
  const RegionOfInterest roi{1, 2, 2, 2};
  const auto invalid = static_cast<std::uint16_t>(Flag::kInvalid);
  EXPECT_DOUBLE_EQ(MeanControlIntensity(m, roi, invalid), (20000.0 + 20000 + 26000) / 3);
  // Whole image: 12 pixels at 10000, 2 at 20000, 1 at 26000 (the invalid one left out).
  EXPECT_DOUBLE_EQ(MeanControlIntensity(m, {}, invalid), (12 * 10000.0 + 40000 + 26000) / 15);
  // A ROI leaving the frame is clipped.
  EXPECT_DOUBLE_EQ(MeanControlIntensity(m, {3, 3, 10, 10}, invalid), 10000.0);
  // No usable pixel: NaN, and the controllers hold their register.
  m.flags.Fill(PixelFlags(Flag::kInvalid));
  EXPECT_TRUE(std::isnan(MeanControlIntensity(m, {}, invalid)));
  ControllerOptions o = Opts(ControllerKind::kMayProportional, 0.01, 50);
  o.roi = roi;
  MayProportional p(o);
  EXPECT_EQ(p.Update(Uniform(18000)), 30);
  EXPECT_EQ(p.Update(m), 30);
  MayIncremental inc(Opts(ControllerKind::kMayIncremental, 0.01, 50));
  EXPECT_EQ(inc.Update(m), 50);
}

TEST(ControllerTest, AmplitudeWithoutIntensityChannel) {
  MetricFrame m = Uniform(0);
  m.intensity = Image<float>();
  m.amplitude.Fill(17000.0f);
  MayProportional p(Opts(ControllerKind::kMayProportional, 0.01, 50));
  EXPECT_EQ(p.Update(m), 40);  // D = 17000 - 16000 on the amplitude
}

// 100 pixels: 90 in 8-bit bin 20, 10 in bin 100.
MetricFrame TwoLevels() {
  MetricFrame m = Uniform(20 * 256 + 5, 10, 10);
  for (int c = 0; c < 10; ++c) m.intensity(9, c) = 100 * 256 + 7;
  return m;
}

TEST(VendorHistogramTest, PercentilePositionAndDampedStep) {
  ControllerOptions o = Opts(ControllerKind::kVendorHistogram, 0.0, 50);
  o.percent_over_pos = 10.0;
  o.desired_pos = 45;
  o.vendor_gain = 0.5;
  o.vendor_max_step_register = 100;
  VendorHistogram v(o);
  // 10 % may lie above x: x = 20. Step = 50 * 0.5 * (45 / 20 - 1) = 31.25 -> 81.25.
  EXPECT_EQ(v.Update(TwoLevels()), 81);
  EXPECT_EQ(v.last_position(), 20);
  // Only 5 % may lie above: x = 100. From 81: step = 81 * 0.5 * (0.45 - 1) = -22.275 -> 58.7.
  o.percent_over_pos = 5.0;
  VendorHistogram w(o);
  w.Reset(81);
  EXPECT_EQ(w.Update(TwoLevels()), 59);
  EXPECT_EQ(w.last_position(), 100);
}

TEST(VendorHistogramTest, StepLimitDeadbandAndClamp) {
  ControllerOptions o = Opts(ControllerKind::kVendorHistogram, 0.0, 50);
  o.vendor_max_step_register = 20;
  VendorHistogram v(o);
  EXPECT_EQ(v.Update(TwoLevels()), 70);  // the 31.25 step limited to 20
  // x = 44 is inside the deadband (|44 - 45| <= 2): no change.
  EXPECT_EQ(v.Update(Uniform(44 * 256)), 70);
  EXPECT_EQ(v.last_position(), 44);
  // Intensity 0 everywhere: x = 0 counts as 1, the step is the limit each frame, up to 255.
  for (int i = 0; i < 20; ++i) (void)v.Update(Uniform(0));
  EXPECT_EQ(v.Update(Uniform(0)), 255);
  // Saturated intensity (65532 -> bin 255): down by the limit, then clamped at the minimum.
  EXPECT_EQ(v.Update(Uniform(65532)), 235);
  for (int i = 0; i < 20; ++i) (void)v.Update(Uniform(65532));
  EXPECT_EQ(v.Update(Uniform(65532)), 1);
}

// Closed loop on a linear plant I = k * c (intensity proportional to integration time), the
// paper's assumption that successive frames are similar.
int RunLoop(IntegrationTimeController& c, double k, int start, int frames) {
  int reg = start;
  for (int t = 0; t < frames; ++t) reg = c.Update(Uniform(static_cast<float>(k * reg)));
  return reg;
}

TEST(ControllerClosedLoopTest, PositionFormKeepsAnOffsetIncrementalFormDoesNot) {
  // k = 1000 per register, I_A = 16000: the ideal register is 16.
  ControllerOptions o = Opts(ControllerKind::kMayProportional, 2.5e-4, 40);
  MayProportional p(o);
  // Fixed point of c = -V_p (k c - I_A) + c_0: c = (c_0 + V_p I_A) / (1 + V_p k)
  // = (40 + 4) / 1.25 = 35.2 -> the loop settles at 35 (intensity 35000, not 16000).
  EXPECT_EQ(RunLoop(p, 1000.0, 40, 50), 35);
  // c_0 at the ideal register removes the offset, as the notes say.
  o.bias_register = 16;
  MayProportional tuned(o);
  EXPECT_EQ(RunLoop(tuned, 1000.0, 40, 50), 16);
  // The incremental form converges to the ideal register from any start: loop gain
  // V_p k = 0.25, error shrinks by 0.75 per frame.
  MayIncremental inc(Opts(ControllerKind::kMayIncremental, 2.5e-4, 40));
  EXPECT_EQ(RunLoop(inc, 1000.0, 40, 60), 16);
  // A loop gain above 2 oscillates (V_p k = 2.5): the clamp bounds it but it never settles.
  MayIncremental hot(Opts(ControllerKind::kMayIncremental, 2.5e-3, 40));
  const int a = RunLoop(hot, 1000.0, 40, 60);
  const int b = hot.Update(Uniform(static_cast<float>(1000.0 * a)));
  EXPECT_GT(std::abs(a - b), 5);
}

// A frame of a proportional plant taken at `reg`: Ī = k reg + ambient.
MetricFrame PlantFrame(double k, int reg, double ambient = 0.0) {
  MetricFrame m = Uniform(static_cast<float>(k * reg + ambient));
  m.info.integration_time_register = reg;
  return m;
}

TEST(ScheduledGainTest, HandComputedSteps) {
  // V_p = 0: V_p,t = loop_gain c_t / Ī_t; with Ī = 20000 at c_t = 40, I_A = 16000, gain 0.5:
  // the correction is 0.5 * 40 * (1 - 16000 / 20000) = 4 registers.
  MayIncremental inc(Opts(ControllerKind::kMayIncremental, 0.0, 40));
  EXPECT_EQ(inc.Update(PlantFrame(500.0, 40)), 36);  // 40 - 4
  // Next frame at the real state 36: 36 - 0.5 * 36 * (1 - 16000 / 20000) = 32.4 -> 32.
  EXPECT_EQ(inc.Update(PlantFrame(20000.0 / 36, 36)), 32);
  // The printed position form with the same scheduled V_p: c_0 - V_p,t D_t = 40 - 0.5 * 36 *
  // 0.2 = 36.4 -> 36 (c_t read from the frame's register).
  MayProportional prop(Opts(ControllerKind::kMayProportional, 0.0, 40));
  EXPECT_EQ(prop.Update(PlantFrame(20000.0 / 36, 36)), 36);
  // A dark frame asks for an unbounded step: at most a factor 4 per frame (40 -> 160).
  MayIncremental dark(Opts(ControllerKind::kMayIncremental, 0.0, 40));
  EXPECT_EQ(dark.Update(PlantFrame(2.5, 40)), 160);
  EXPECT_EQ(dark.Update(PlantFrame(2.5, 160)), 255);  // then the bound
  // A fixed V_p is the printed law, untouched by the schedule (loop_gain is ignored).
  ControllerOptions fixed = Opts(ControllerKind::kMayIncremental, 0.001, 40);
  fixed.loop_gain = 1.0;
  MayIncremental f(fixed);
  EXPECT_EQ(f.Update(PlantFrame(500.0, 40)), 36);  // 40 - 0.001 * 4000
}

TEST(ScheduledGainTest, ConvergesGeometricallyInEveryScene) {
  // On Ī = k c the scheduled incremental law is c_{t+1} = c_t - g (c_t - c_A), c_A = I_A / k:
  // the error shrinks by (1 - g) = 0.5 per frame whatever k, from a dim hall (k = 2 per
  // register, c_A = 8000: beyond the bound) to a hand at 20 cm (k = 4000, c_A = 4).
  for (double k : {100.0, 400.0, 1000.0, 4000.0}) {
    MayIncremental inc(Opts(ControllerKind::kMayIncremental, 0.0, 40));
    const double target = 16000.0 / k;
    int reg = 40;
    double previous_error = std::abs(40.0 - target);
    for (int t = 0; t < 12; ++t) {
      reg = inc.Update(Uniform(static_cast<float>(k * reg)));
      // Halved each frame, plus the register rounding of the plant input and of the output (the
      // plant sees the rounded register: up to 0.5 each).
      const double error = std::abs(reg - target);
      EXPECT_LE(error, 0.5 * previous_error + 1.0) << "k " << k << " t " << t;
      previous_error = error;
    }
    EXPECT_NEAR(reg, target, 1.0) << "k " << k;
  }
  MayIncremental dim(Opts(ControllerKind::kMayIncremental, 0.0, 40));
  EXPECT_EQ(RunLoop(dim, 2.0, 40, 10), 255);  // I_A out of reach: pinned at the bound
  // The same gains that make a fixed V_p oscillate on the hand (k V_p = 4000 * 2.5e-3 = 10)
  // settle with the schedule: no change over the last frames.
  MayIncremental hand(Opts(ControllerKind::kMayIncremental, 0.0, 40));
  const int settled = RunLoop(hand, 4000.0, 40, 20);
  EXPECT_EQ(hand.Update(Uniform(static_cast<float>(4000.0 * settled))), settled);
}

TEST(MaxRegisterForFrameRateTest, HandComputed) {
  CameraInfo sr2;  // 255 µs per register, registers 1..255
  sr2.readout_time_us = 4000.0;
  // (1e6 / 30 - 4000) / 255 = 115.03 -> 115.
  EXPECT_EQ(MaxRegisterForFrameRate(sr2, 30.0), 115);
  EXPECT_EQ(MaxRegisterForFrameRate(sr2, 1.0), 255);               // capped by the camera
  EXPECT_EQ(MaxRegisterForFrameRate(sr2, 200.0), 3);               // 1000 µs / 255 = 3.9
  EXPECT_THROW((void)MaxRegisterForFrameRate(sr2, 300.0), Error);  // 3.3 ms < readout
  EXPECT_THROW((void)MaxRegisterForFrameRate(sr2, 0.0), Error);
  EXPECT_THROW((void)MaxRegisterForFrameRate(sr2, std::nan("")), Error);
  // SR-4000 style timing: 300 µs + n x 100 µs, no readout: (1e6 / 50 - 300) / 100 = 197.
  CameraInfo sr4000;
  sr4000.integration_time_base_us = 300.0;
  sr4000.integration_time_step_us = 100.0;
  sr4000.min_integration_register = 0;
  sr4000.max_integration_register = 255;
  EXPECT_EQ(MaxRegisterForFrameRate(sr4000, 50.0), 197);
}

TEST(ControllerClosedLoopTest, VendorHistogramConvergesWhateverTheGain) {
  // The multiplicative step is scale-free: for k = 100 and k = 5000 per register the 8-bit
  // position x = k c / 256 ends within the deadband of desired_pos = 45 (or at a bound).
  for (double k : {100.0, 1000.0, 5000.0}) {
    ControllerOptions o = Opts(ControllerKind::kVendorHistogram, 0.0, 40);
    VendorHistogram v(o);
    const int reg = RunLoop(v, k, 40, 100);
    const double x = k * reg / 256.0;
    // Rounding to whole registers: at k = 5000 one register moves x by 19.5.
    EXPECT_NEAR(x, 45.0, std::max(3.0, k / 256.0)) << "k " << k << " reg " << reg;
  }
}

TEST(FixedTest, AlwaysTheBias) {
  Fixed f(Opts(ControllerKind::kFixed, 0.5, 77));
  EXPECT_EQ(f.Update(Uniform(0)), 77);
  EXPECT_EQ(f.Update(Uniform(65532)), 77);
  f.Reset(3);
  EXPECT_EQ(f.Update(Uniform(100)), 77);
}

TEST(ControllerOptionsTest, RejectsOutOfRangeValues) {
  const auto expect_bad = [](auto mutate) {
    ControllerOptions o;
    mutate(o);
    try {
      (void)MakeController(o);
      ADD_FAILURE() << "expected Error";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    }
  };
  expect_bad([](ControllerOptions& o) { o.target_intensity = 0; });
  expect_bad([](ControllerOptions& o) { o.target_intensity = 70000; });
  expect_bad([](ControllerOptions& o) { o.target_intensity = std::nan(""); });
  expect_bad([](ControllerOptions& o) { o.gain_register_per_intensity = -1e-3; });
  expect_bad([](ControllerOptions& o) {
    o.gain_register_per_intensity = std::numeric_limits<double>::infinity();
  });
  expect_bad([](ControllerOptions& o) { o.min_register = 0; });
  expect_bad([](ControllerOptions& o) { o.min_register = 100, o.max_register = 50; });
  expect_bad([](ControllerOptions& o) { o.max_register = 70000; });
  expect_bad([](ControllerOptions& o) { o.bias_register = 256; });
  expect_bad([](ControllerOptions& o) { o.roi.rows = -1; });
  expect_bad([](ControllerOptions& o) { o.percent_over_pos = 100; });
  expect_bad([](ControllerOptions& o) { o.desired_pos = 0; });
  expect_bad([](ControllerOptions& o) { o.vendor_gain = 0; });
  expect_bad([](ControllerOptions& o) { o.vendor_max_step_register = 0; });
  expect_bad([](ControllerOptions& o) { o.vendor_deadband = -1; });
  expect_bad([](ControllerOptions& o) { o.loop_gain = 0; });
  expect_bad([](ControllerOptions& o) { o.loop_gain = 1.5; });
  expect_bad([](ControllerOptions& o) { o.frame_rate_hz = -1; });
  expect_bad([](ControllerOptions& o) { o.frame_rate_hz = std::nan(""); });
  EXPECT_THROW(MayIncremental(Opts(ControllerKind::kMayIncremental, 2.0, 50)), Error);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

std::vector<IntegrationSweepPoint> Sweep(std::vector<int> regs, std::vector<double> intensity,
                                         std::vector<double> amplitude) {
  std::vector<IntegrationSweepPoint> s;
  for (std::size_t k = 0; k < regs.size(); ++k) {
    s.push_back({regs[k], intensity[k], amplitude[k], 0.0});
  }
  return s;
}

TEST(ChooseSetpointTest, HandComputedFromTheAmplitudeMaximum) {
  // Amplitude peaks at register 30 (intensity 15000): I_A = 0.9 x 15000 = 13500, crossed between
  // registers 20 (10000) and 30 (15000) at 20 + 10 x 3500 / 5000 = 27; k = 5000 / 10 = 500.
  // V_p = min((27 - 1) / (65532 - 13500), 0.5 / 500) = 26 / 52032.
  const auto sweep = Sweep({10, 20, 30, 40, 50}, {5000, 10000, 15000, 20000, 22000},
                           {1000, 2000, 3000, 2500, 2000});
  const ControllerSetpoint s = ChooseSetpoint(sweep);
  EXPECT_EQ(s.amplitude_max_register, 30);
  EXPECT_DOUBLE_EQ(s.amplitude_max_intensity, 15000.0);
  EXPECT_DOUBLE_EQ(s.target_intensity, 13500.0);
  EXPECT_EQ(s.bias_register, 27);
  EXPECT_DOUBLE_EQ(s.intensity_per_register, 500.0);
  EXPECT_DOUBLE_EQ(s.gain_register_per_intensity, 26.0 / 52032.0);
  EXPECT_NO_THROW(s.Validate());

  // A steep scene: the loop-gain bound wins. Peak at register 3 (30000): I_A = 27000 crossed at
  // 2.7 -> c_0 = 3, k = 10000 per register; span rule 2 / 38532 = 5.19e-5 > 0.5 / 10000.
  const ControllerSetpoint steep =
      ChooseSetpoint(Sweep({1, 2, 3, 4}, {10000, 20000, 30000, 35000}, {1, 2, 3, 2}));
  EXPECT_EQ(steep.bias_register, 3);
  EXPECT_DOUBLE_EQ(steep.intensity_per_register, 10000.0);
  EXPECT_DOUBLE_EQ(steep.gain_register_per_intensity, 0.5 / 10000.0);

  // Even the lowest register is brighter than I_A (peak at register 40, intensity 25500, so
  // I_A = 22950 < 24000): c_0 is the lowest register, 10, with the slope of the first segment.
  const ControllerSetpoint bright = ChooseSetpoint(
      Sweep({10, 20, 30, 40, 50}, {24000, 24500, 25000, 25500, 60000}, {1, 2, 3, 4, 1}));
  EXPECT_EQ(bright.amplitude_max_register, 40);
  EXPECT_DOUBLE_EQ(bright.target_intensity, 22950.0);
  EXPECT_EQ(bright.bias_register, 10);
  EXPECT_DOUBLE_EQ(bright.intensity_per_register, 50.0);

  // The peak at the first register: c_0 there.
  const ControllerSetpoint first =
      ChooseSetpoint(Sweep({5, 10, 15}, {20000, 30000, 40000}, {900, 800, 700}));
  EXPECT_EQ(first.bias_register, 5);
  EXPECT_DOUBLE_EQ(first.target_intensity, 18000.0);
}

TEST(ChooseSetpointTest, AFlatTopPicksTheStartOfThePlateau) {
  // Amplitude 1000, 2000, 2980, 2990, 3000, 2995, 2500: the arg-max (register 50) sits on a
  // plateau within 1 % of its value from register 30 on. With the default 2 % tolerance the
  // maximum is register 30 (2980 >= 0.98 x 3000 = 2940), where the intensity is 15000; with
  // tolerance 0 it is the arg-max, intensity 25000.
  const auto sweep =
      Sweep({10, 20, 30, 40, 50, 60, 70}, {5000, 10000, 15000, 20000, 25000, 30000, 35000},
            {1000, 2000, 2980, 2990, 3000, 2995, 2500});
  const ControllerSetpoint plateau = ChooseSetpoint(sweep);
  EXPECT_EQ(plateau.amplitude_max_register, 30);
  EXPECT_DOUBLE_EQ(plateau.amplitude_max_intensity, 15000.0);
  EXPECT_DOUBLE_EQ(plateau.target_intensity, 13500.0);
  SetpointOptions argmax;
  argmax.plateau_tolerance = 0.0;
  const ControllerSetpoint peak = ChooseSetpoint(sweep, argmax);
  EXPECT_EQ(peak.amplitude_max_register, 50);
  EXPECT_DOUBLE_EQ(peak.amplitude_max_intensity, 25000.0);
  argmax.plateau_tolerance = 0.6;
  EXPECT_THROW((void)ChooseSetpoint(sweep, argmax), Error);
}

TEST(ChooseSetpointTest, PrintedLawSettlesAtTheSetpointAndBacksOffFromABrightScene) {
  // Plant: mean intensity I = k c with k = 500 per register (saturating at 65532); the mean
  // amplitude grows until pixels start to saturate at register 60, then falls (paper fig. 3).
  std::vector<IntegrationSweepPoint> sweep;
  for (int c = 10; c <= 250; c += 10) {
    sweep.push_back({c, std::min(500.0 * c, 65532.0), c <= 60 ? 4.0 * c : 240.0 - (c - 60.0), 0.0});
  }
  const ControllerSetpoint s = ChooseSetpoint(sweep);
  EXPECT_EQ(s.amplitude_max_register, 60);
  EXPECT_DOUBLE_EQ(s.target_intensity, 27000.0);  // 0.9 x 30000
  EXPECT_EQ(s.bias_register, 54);                 // 27000 / 500
  // min(53 / 38532, 0.5 / 500): the loop-gain bound.
  EXPECT_DOUBLE_EQ(s.gain_register_per_intensity, 0.001);
  const ControllerOptions o = s.Apply(ControllerOptions{});
  EXPECT_EQ(o.kind, ControllerKind::kMayProportional);
  const auto run = [&](auto plant, int frames) {
    MayProportional p(o);
    int c = o.bias_register;
    for (int t = 0; t < frames; ++t) c = p.Update(Uniform(static_cast<float>(plant(c))));
    return c;
  };
  // On the sweep's scene the printed law has no steady-state offset: c* = c_0.
  EXPECT_EQ(run([](int c) { return 500.0 * c; }, 50), 54);
  // Half the image saturated by something close (a hand): I = 32766 + 250 c. The fixed point of
  // c = c_0 - V_p (I(c) - I_A) is (54 - 0.001 x 5766) / (1 + 0.25) = 38.6; the error shrinks by
  // 0.25 per frame, so 50 frames end on the rounded fixed point.
  EXPECT_NEAR(run([](int c) { return 32766.0 + 250.0 * c; }, 50), 38.6, 0.6);
}

TEST(ChooseSetpointTest, RejectsBadSweepsAndOptions) {
  const auto good = Sweep({10, 20, 30}, {1000, 2000, 3000}, {1, 2, 3});
  EXPECT_NO_THROW((void)ChooseSetpoint(good));
  EXPECT_THROW((void)ChooseSetpoint(Sweep({10, 20}, {1, 2}, {1, 2})), Error);
  EXPECT_THROW((void)ChooseSetpoint(Sweep({10, 10, 30}, {1, 2, 3}, {1, 2, 3})), Error);
  EXPECT_THROW((void)ChooseSetpoint(Sweep({0, 10, 30}, {1, 2, 3}, {1, 2, 3})), Error);
  EXPECT_THROW((void)ChooseSetpoint(
                   Sweep({1, 2, 3}, {1, std::numeric_limits<double>::quiet_NaN(), 3}, {1, 2, 3})),
               Error);
  EXPECT_THROW((void)ChooseSetpoint(Sweep({1, 2, 3}, {1, 2, 3}, {1, -2, 3})), Error);
  SetpointOptions o;
  o.target_fraction = 0.0;
  EXPECT_THROW((void)ChooseSetpoint(good, o), Error);
  o = SetpointOptions{};
  o.max_loop_gain = 1.0;
  EXPECT_THROW((void)ChooseSetpoint(good, o), Error);
  o = SetpointOptions{};
  o.min_register = 0;
  EXPECT_THROW((void)ChooseSetpoint(good, o), Error);
  ControllerSetpoint bad;
  bad.bias_register = 0;
  EXPECT_THROW(bad.Validate(), Error);
  bad = ControllerSetpoint{};
  bad.gain_register_per_intensity = -1.0;
  EXPECT_THROW(bad.Validate(), Error);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

TEST(ControllerTest, ClippedPixelsCountEvenWhenInvalid) {
  // A SwissRanger pixel whose taps all clipped: amplitude 0 (so kInvalid) and full-scale
  // intensity. It must count, or a saturated hand would be invisible to the controller.
  MetricFrame m = Uniform(10000, 2, 2);
  m.intensity(0, 0) = 65532;
  m.flags(0, 0) = PixelFlags(Flag::kInvalid);
  m.intensity(0, 1) = 60000;  // invalid for another reason: left out (below 64221)
  m.flags(0, 1) = PixelFlags(Flag::kInvalid);
  const auto invalid = static_cast<std::uint16_t>(Flag::kInvalid);
  EXPECT_DOUBLE_EQ(MeanControlIntensity(m, {}, invalid, 64221.0), (65532.0 + 20000.0) / 3);
  EXPECT_DOUBLE_EQ(MeanControlIntensity(m, {}, invalid), 10000.0);  // 0 = off: the old rule
  EXPECT_TRUE(CountsForExposure(m, 0, invalid, 64221.0));           // clipped
  EXPECT_FALSE(CountsForExposure(m, 1, invalid, 64221.0));          // invalid, not clipped
  EXPECT_TRUE(CountsForExposure(m, 2, invalid, 64221.0));           // valid
  EXPECT_FALSE(CountsForExposure(m, 0, invalid, 0.0));              // rule off
  // The controllers use ControllerOptions::clipped_intensity (default 64221): P-law with
  // V_p = 0.001, c_0 = 50, I_A = 16000 on Ī = 85532 / 3 gives 50 - 0.001 (28510.7 - 16000).
  MayProportional p(Opts(ControllerKind::kMayProportional, 0.001, 50));
  EXPECT_EQ(p.Update(m), 37);
  ControllerOptions off = Opts(ControllerKind::kMayProportional, 0.001, 50);
  off.clipped_intensity = 0.0;
  MayProportional q(off);
  EXPECT_EQ(q.Update(m), 56);  // 50 - 0.001 (10000 - 16000)
  off.clipped_intensity = 70000.0;
  EXPECT_THROW(off.Validate(), Error);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

// MeanControlIntensity as it was before the lane-wise loop (tofcam 0.1): a sequential double sum.
double SequentialMean(const MetricFrame& frame, int row0, int row1, int col0, int col1,
                      std::uint16_t exclude, double clipped) {
  const Image<float>& channel = frame.has_intensity() ? frame.intensity : frame.amplitude;
  double sum = 0.0;
  long long count = 0;
  for (int row = row0; row < row1; ++row) {
    for (int col = col0; col < col1; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * channel.width() + col;
      const bool usable = frame.flags.empty() || !frame.flags[i].Any(exclude) ||
                          (clipped > 0.0 && frame.has_intensity() && frame.intensity[i] >= clipped);
      if (!usable || !std::isfinite(channel[i])) continue;
      sum += channel[i];
      ++count;
    }
  }
  return count == 0 ? std::nan("") : sum / static_cast<double>(count);
}

MetricFrame RandomFrame(int w, int h, bool integers, std::uint32_t seed) {
  MetricFrame m = Uniform(0.0f, w, h);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> value(0.0f, 65532.0f);
  for (std::size_t i = 0; i < m.intensity.size(); ++i) {
    const float v = value(rng);
    m.intensity[i] = integers ? std::floor(v) : v;
    if (rng() % 7 == 0) m.flags[i] = PixelFlags(Flag::kInvalid);
    if (rng() % 11 == 0) m.flags[i] |= PixelFlags(Flag::kSaturated);
    if (!integers && rng() % 97 == 0) m.intensity[i] = std::nanf("");
    if (!integers && rng() % 89 == 0) m.intensity[i] = std::numeric_limits<float>::infinity();
  }
  return m;
}

TEST(ControllerTest, MeanEqualsTheSequentialSumExactlyOnRegisterValues) {
  // Register-converted intensities are integers: every partial sum is an exact integer below
  // 2^53, so the lane-wise sum must equal the sequential one bit for bit (and so must every
  // register the controllers compute from it).
  for (const auto& [w, h] : {std::pair{160, 124}, std::pair{157, 123}, std::pair{5, 3}}) {
    const MetricFrame m = RandomFrame(w, h, true, 1);
    const std::uint16_t exclude = static_cast<std::uint16_t>(Flag::kInvalid);
    EXPECT_EQ(MeanControlIntensity(m, {}, exclude, 0.0),
              SequentialMean(m, 0, h, 0, w, exclude, 0.0));
    EXPECT_EQ(MeanControlIntensity(m, {}, exclude, 60000.5),
              SequentialMean(m, 0, h, 0, w, exclude, 60000.5));
    const RegionOfInterest roi{1, 2, h - 2, w - 3};
    EXPECT_EQ(MeanControlIntensity(m, roi, exclude | static_cast<std::uint16_t>(Flag::kSaturated)),
              SequentialMean(m, 1, h - 1, 2, w - 1,
                             exclude | static_cast<std::uint16_t>(Flag::kSaturated), 0.0));
  }
}

TEST(ControllerTest, MeanOfArbitraryValuesWithinTheReassociationBound) {
  // Non-integer values: the eight lanes sum in another order than a sequential loop; both are
  // within (n - 1) 2^-53 sum|v| of the exact sum, so they differ by at most 2 n 2^-53 sum|v|.
  const int w = 157, h = 123;
  const MetricFrame m = RandomFrame(w, h, false, 2);
  const std::uint16_t exclude = static_cast<std::uint16_t>(Flag::kInvalid);
  const double expected = SequentialMean(m, 0, h, 0, w, exclude, 0.0);
  double magnitude = 0.0;
  long long count = 0;
  for (std::size_t i = 0; i < m.intensity.size(); ++i) {
    if (!m.flags[i].Any(exclude) && std::isfinite(m.intensity[i])) {
      magnitude += std::abs(m.intensity[i]);
      ++count;
    }
  }
  const double n = static_cast<double>(m.intensity.size());
  const double bound = 2.0 * n * std::ldexp(1.0, -53) * magnitude / static_cast<double>(count);
  EXPECT_NEAR(MeanControlIntensity(m, {}, exclude, 0.0), expected, bound);
  EXPECT_GT(expected, 0.0);
}

// A scene of 100 pixels whose brightest tap (I + A) per register is `per_register[i]`: taken at
// register `reg`, intensity = 0.8 x peak and amplitude = 0.2 x peak, clipped at full scale the
// way a SwissRanger reports it (amplitude 0, intensity at full scale, kInvalid | kSaturated).
MetricFrame PeakFrame(const std::vector<double>& per_register, int reg) {
  const int w = 10, h = static_cast<int>(per_register.size()) / 10;
  MetricFrame m = Uniform(0.0f, w, h);
  m.info.integration_time_register = reg;
  for (std::size_t i = 0; i < per_register.size(); ++i) {
    const double peak = per_register[i] * reg;
    if (peak >= 65532.0) {
      m.intensity[i] = 65532.0f;
      m.amplitude[i] = 0.0f;
      m.flags[i] = PixelFlags(Flag::kInvalid) | Flag::kSaturated;
    } else {
      m.intensity[i] = static_cast<float>(0.8 * peak);
      m.amplitude[i] = static_cast<float>(0.2 * peak);
    }
  }
  return m;
}

TEST(ModelBasedTest, HandComputedStepsFromOneFrame) {
  // 100 pixels, peak per register 100..199 (pixel i: 100 + i). At register 50 nothing clips
  // (largest peak 9950). Allowed clipped fraction 1 %: the 99 % quantile is the pixel of rank
  // ceil(0.99 x 100) = 99, i.e. the 99th smallest: 100 + 98 = 198 per register -> 9900 at 50.
  // Next register = 50 x 0.85 x 64221 / 9900 = 275.7, limited to 2 x 50 = 100 per step
  // (model_max_increase 2 here).
  std::vector<double> scene(100);
  for (int i = 0; i < 100; ++i) scene[i] = 100.0 + i;
  ControllerOptions o = Opts(ControllerKind::kModelBased, 0.0, 50);
  o.max_register = 1000;
  o.model_max_increase = 2.0;
  ModelBased c(o);
  EXPECT_EQ(c.Update(PeakFrame(scene, 50)), 100);
  EXPECT_EQ(c.Update(PeakFrame(scene, 100)), 200);
  // At 200 the quantile peak is 39600: 200 x 0.85 x 64221 / 39600 = 275.70 -> 276.
  EXPECT_EQ(c.Update(PeakFrame(scene, 200)), 276);
  // At 276 the brightest pixel (199 x 276 = 54924) is still below full scale: the law holds
  // (it predicted exactly this frame; the change asked for is 0).
  EXPECT_EQ(c.Update(PeakFrame(scene, 276)), 276);
  EXPECT_EQ(c.last_clipped_fraction(), 0.0);
  // At 400, pixels whose peak reaches the clipped level 64221 (98 % of full scale; 160.6 per
  // register -> pixels 61..99, 39 of them) count as clipped: more than 1 %, so the register is
  // divided by model_backoff = 8 -> 50.
  EXPECT_EQ(c.Update(PeakFrame(scene, 400)), 50);
  EXPECT_NEAR(c.last_clipped_fraction(), 0.39, 1e-12);
}

TEST(ModelBasedTest, AllowsTheConfiguredFractionToClip) {
  // One pixel of 100 is a lamp (peak 10^4 per register, clips at any register >= 7); the rest
  // have 100 per register. With 1 % allowed the lamp may clip and the law exposes the rest:
  // its 99 % quantile is a 100-per-register pixel -> register 0.85 x 64221 / 100 = 545.9.
  std::vector<double> scene(100, 100.0);
  scene[37] = 1e4;
  ControllerOptions o = Opts(ControllerKind::kModelBased, 0.0, 400);
  o.max_register = 1000;
  o.model_max_increase = 10.0;
  ModelBased c(o);
  EXPECT_EQ(c.Update(PeakFrame(scene, 400)), 546);
  EXPECT_NEAR(c.last_clipped_fraction(), 0.01, 1e-12);
  // With none allowed the lamp rules: clipped now (1 % > 0 %) -> back off by 8.
  o.max_clipped_fraction = 0.0;
  ModelBased strict(o);
  EXPECT_EQ(strict.Update(PeakFrame(scene, 400)), 50);
}

TEST(ModelBasedTest, SettlesWithinThreeFramesAfterEveryStepOfAScene) {
  // Closed loop on a proportional plant whose brightness jumps: a dim hall, a hand 40x brighter
  // in a third of the image, back to the hall. After each step the clipped fraction must fall
  // to <= 1 % within 3 frames, and the register must then hold (no hunting).
  std::vector<double> hall(200), hand(200);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.5, 1.5);
  for (int i = 0; i < 200; ++i) {
    hall[i] = 40.0 * u(rng);
    hand[i] = i < 70 ? 1600.0 * u(rng) : hall[i];
  }
  ControllerOptions o = Opts(ControllerKind::kModelBased, 0.0, 40);
  ModelBased c(o);
  int reg = 40;
  for (const auto* scene : {&hall, &hand, &hall, &hand}) {
    int settled_at = -1;
    for (int frame = 0; frame < 12; ++frame) {
      const MetricFrame m = PeakFrame(*scene, reg);
      const int next = c.Update(m);
      if (settled_at < 0 && c.last_clipped_fraction() <= 0.01 && next == reg) settled_at = frame;
      if (settled_at >= 0) {
        EXPECT_EQ(next, reg) << "hunting at frame " << frame;
      }
      reg = next;
    }
    EXPECT_GE(settled_at, 0);
    EXPECT_LE(settled_at, 3);
  }
}

TEST(ModelBasedTest, RejectsBadOptionsAndEmptyFrames) {
  ControllerOptions o = Opts(ControllerKind::kModelBased, 0.0, 40);
  for (auto bad : {+[](ControllerOptions& x) { x.max_clipped_fraction = 0.6; },
                   +[](ControllerOptions& x) { x.model_headroom = 0.0; },
                   +[](ControllerOptions& x) { x.model_backoff = 1.0; },
                   +[](ControllerOptions& x) { x.model_max_increase = 0.5; },
                   +[](ControllerOptions& x) { x.model_deadband = std::nan(""); }}) {
    ControllerOptions b = o;
    bad(b);
    EXPECT_THROW(ModelBased{b}, Error);
  }
  ModelBased c(o);
  MetricFrame all_invalid = Uniform(1000.0f);
  all_invalid.flags.Fill(PixelFlags(Flag::kInvalid));
  EXPECT_EQ(c.Update(all_invalid), 40);  // nothing usable: unchanged
}

}  // namespace
}  // namespace tofcam
