// CalibrateScattering on the simulated SR-2, whose optics scatter as its camera model says: the
// wall and the card scene shipped with the simulator, the register chosen so the card does not
// clip, and lobes that shrink the hand scene's halo (the estimator never sees the model's lobes).
#include "tofcam/calibration/scattering_calibration.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "../optics/halo_bias.h"
#include "tofcam/core/error.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam {
namespace {

sim::SimulatedCamera Sim(const std::string& scene, std::uint64_t seed) {
  sim::SimulatorOptions o;
  o.seed = seed;
  sim::SceneOverrides at_3m;  // the card scene's wall is at 3 m by default
  if (scene == "wall") at_3m = {{"distance_m", "3"}};
  return sim::SimulatedCamera(sim::ResolveScene(scene, at_3m), sim::ResolveCameraModel("sr2"), o);
}

using testing::MedianHaloBias;

TEST(ScatteringCalibration, ChoosesAnUnclippedRegisterAndShrinksTheHalo) {
  sim::SimulatedCamera wall = Sim("wall", 1);
  sim::SimulatedCamera card = Sim("calibration/scattering-card", 2);
  card.SetIntegrationTimeRegister(200);  // far too long for a white card at 0.4 m
  std::vector<CalibrationProgress> progress;
  const ScatteringCalibration c = CalibrateScattering(
      wall, card, {}, [&](const CalibrationProgress& p) { progress.push_back(p); });
  // The register was halved from 200 until the card stopped clipping: 200 / 2^k.
  int reg = 200;
  while (reg > c.integration_time_register) reg /= 2;
  EXPECT_EQ(reg, c.integration_time_register);
  EXPECT_LT(c.integration_time_register, 200);
  card.SetIntegrationTimeRegister(c.integration_time_register);
  (void)card.Grab();
  const MetricFrame m = ConvertToMetric(*card.Grab());
  const Image<PixelFlags> clipped = SaturationFilter(m, SaturationOptions{});
  long long n = 0;
  for (std::size_t i = 0; i < clipped.size(); ++i) n += clipped[i].Has(Flag::kSaturated);
  EXPECT_EQ(n, 0);
  EXPECT_EQ(c.frames, 8);
  EXPECT_GT(c.target_pixels, 0);
  ASSERT_FALSE(c.lobes.empty());
  EXPECT_FALSE(progress.empty());

  // The lobes undo the halo of a hand 0.25 m from the lens (issue 18: >= 5x).
  sim::SimulatedCamera hand = Sim("hand", 3);
  hand.SetIntegrationTimeRegister(12);  // the hand stays below saturation
  (void)hand.Grab();
  std::vector<Frame> frames, fixed;
  ScatteringOptions psf;
  psf.lobes = c.lobes;
  for (int k = 0; k < 8; ++k) {
    frames.push_back(*hand.Grab());
    fixed.push_back(CompensateScattering(frames.back(), psf));
  }
  const double before = MedianHaloBias(frames), after = MedianHaloBias(fixed);
  std::printf("register %d, lobes", c.integration_time_register);
  for (const ScatteringLobe& l : c.lobes) std::printf(" %.5f at %.3g px", l.weight, l.sigma_px);
  std::printf("; hand halo median bias %.1f mm before, %.1f mm after\n", before * 1e3, after * 1e3);
  EXPECT_GT(std::abs(before), 0.01);
  EXPECT_LE(std::abs(after) * 5.0, std::abs(before));
}

TEST(ScatteringCalibration, BadInputIsAClearError) {
  sim::SimulatedCamera wall = Sim("wall", 1);
  sim::SimulatedCamera card = Sim("calibration/scattering-card", 2);
  const auto code = [&](const ScatteringCalibrationOptions& o, tofcam::Camera& a,
                        tofcam::Camera& b) {
    try {
      (void)CalibrateScattering(a, b, o);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kInternal;
  };
  ScatteringCalibrationOptions o;
  o.frames = 0;
  EXPECT_EQ(code(o, wall, card), ErrorCode::kInvalidArgument);
  o = {};
  o.integration_time_register = 100000;
  EXPECT_EQ(code(o, wall, card), ErrorCode::kInvalidArgument);
  o = {};
  o.max_saturated_fraction = 1.0;
  EXPECT_EQ(code(o, wall, card), ErrorCode::kInvalidArgument);
  // A "card" scene without a card: nothing brighter to fit.
  sim::SimulatedCamera same = Sim("wall", 4);
  o = {};
  o.frames = 2;
  o.integration_time_register = 12;
  EXPECT_EQ(code(o, wall, same), ErrorCode::kInvalidArgument);
  // Cameras of different sizes.
  sim::SimulatedCamera big(sim::ResolveScene("wall"), sim::ResolveCameraModel("sr4000"), {});
  EXPECT_EQ(code(o, wall, big), ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace tofcam
