// Stage 6 of the simulator (src/sim/timing.h): exposure times, the motion test, the pan
// schedule, frame period and time-dependent offsets against hand-computed values.
#include "timing.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "tofcam/core/units.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {
namespace {

TEST(TimingTest, TapsAreRenderedAtTheMiddlesOfTheirQuartersWhenSplit) {
  EXPECT_DOUBLE_EQ(TapTimeS(1.0, 0.008, false, 3), 1.004);
  EXPECT_DOUBLE_EQ(TapTimeS(1.0, 0.008, true, 0), 1.001);
  EXPECT_DOUBLE_EQ(TapTimeS(1.0, 0.008, true, 3), 1.007);
}

TEST(TimingTest, PoseMovedMeasuresTranslationAndRotationAtAFiveMetreLever) {
  Eigen::Matrix<double, 3, 4> a = Eigen::Matrix<double, 3, 4>::Zero();
  a.leftCols<3>().setIdentity();
  Eigen::Matrix<double, 3, 4> b = a;
  b(0, 3) = 0.02;
  EXPECT_TRUE(PoseMoved(a, b, 0.01));
  b(0, 3) = 0.005;
  EXPECT_FALSE(PoseMoved(a, b, 0.01));
  b(0, 3) = 0;
  // ||R(angle) - I||_F / sqrt 2 = 2 sin(angle / 2): 5 m * ~0.001 = 5 mm, 5 m * 0.003 = 15 mm.
  b.leftCols<3>() = Eigen::AngleAxisd(0.001, Eigen::Vector3d::UnitY()).toRotationMatrix();
  EXPECT_FALSE(PoseMoved(a, b, 0.01));
  b.leftCols<3>() = Eigen::AngleAxisd(0.003, Eigen::Vector3d::UnitY()).toRotationMatrix();
  EXPECT_TRUE(PoseMoved(a, b, 0.01));
}

TEST(TimingTest, RenderKeysChangeWithMovingObjectsAndLampsOnly) {
  const Scene scene = ParseScene(
      "materials: {w: {albedo: 0.5}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [4, 4], position_m: [0, 0, 3]}\n"
      "  - type: box\n    material: w\n    size_m: [0.2, 0.2, 0.2]\n"
      "    motion: [{t: 0, position_m: [0, 0, 2]}, {t: 1, position_m: [1, 0, 2]}]\n",
      "inline", {});
  const std::vector<char> dynamic = {0, 1};
  const RenderKey a = MakeRenderKey(scene, dynamic, 0.0, 0.0);
  const RenderKey b = MakeRenderKey(scene, dynamic, 0.5, 0.0);
  EXPECT_EQ(a.objects.size(), 12u);
  EXPECT_FALSE(a == b);
  EXPECT_TRUE(a == MakeRenderKey(scene, dynamic, 0.0, 0.0));
  EXPECT_FALSE(a == MakeRenderKey(scene, dynamic, 0.0, 0.1));  // panned
  EXPECT_TRUE(MovesDuringExposure(a, b, 0.01));                // the box moved 0.5 m
  const std::vector<char> none = {0, 0};
  EXPECT_TRUE(MakeRenderKey(scene, none, 0.0, 0.0) == MakeRenderKey(scene, none, 0.5, 0.0));
  RenderKey invalid;
  EXPECT_FALSE(invalid == invalid);  // an invalid key never matches
}

TEST(TimingTest, PanScheduleIsLinearBetweenKeysAndHeldOutside) {
  const std::vector<PanKey> s = {{1.0, 0.0}, {3.0, 90.0}};
  EXPECT_DOUBLE_EQ(PanAngleAtRad(s, 0.0), 0.0);
  EXPECT_NEAR(PanAngleAtRad(s, 2.0), kPi / 4, 1e-15);
  EXPECT_NEAR(PanAngleAtRad(s, 5.0), kPi / 2, 1e-15);
  EXPECT_EQ(PanAngleAtRad({}, 2.0), 0.0);
}

TEST(TimingTest, FramePeriodIsTheRateCapOrExposurePlusReadout) {
  CameraModel m;
  m.max_frame_rate_hz = 50;
  m.readout_time_us = 4000;
  EXPECT_DOUBLE_EQ(FramePeriodS(m, 0.010), 0.020);  // 1/50 > 14 ms
  EXPECT_DOUBLE_EQ(FramePeriodS(m, 0.030), 0.034);
}

TEST(TimingTest, DriftAndExposureOffsets) {
  CameraModel m;
  m.warmup_amplitude_m = 0.05;
  m.warmup_time_constant_s = 300;
  m.exposure_offset_m_per_ms = 0.001;
  EXPECT_DOUBLE_EQ(WarmupOffsetM(m, 0.0, 0.0), 0.05);
  EXPECT_NEAR(WarmupOffsetM(m, 200.0, 100.0), 0.05 * std::exp(-1.0), 1e-15);
  EXPECT_DOUBLE_EQ(ExposureOffsetM(m, 8000), 0.008);
}

TEST(TimingTest, FrameSeedsDifferPerFrameAndCamera) {
  EXPECT_NE(FrameSeed(1, 0), FrameSeed(1, 1));
  EXPECT_NE(FrameSeed(1, 0), FrameSeed(2, 0));
  EXPECT_EQ(FrameSeed(0, 0), 0u);
}

}  // namespace
}  // namespace tofcam::sim::internal
