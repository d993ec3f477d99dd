#pragma once
// The calibration every benchmark input gets (shared by bench/bench_inputs.cc and `tofcam bench`,
// apps/tofcam/bench_command.cc): eq. 1 with the simulator's own fixed-pattern offsets, a
// distance-dependent table (so the costlier form of eq. 1 is the one timed) and the ΔL scale of a
// noise calibration.

#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include "sim_scenes.h"
#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/metric_conversion.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::bench {

// The SR-2 model in the pavilion at the moving camera's start pose, held still (seed 7).
inline sim::SimulatedCamera StaticStartCamera(int integration_register) {
  sim::SimulatorOptions so;
  so.seed = 7;
  so.threads = 2;
  so.integration_time_register = integration_register;
  sim::Scene scene = MovingPavilion();
  scene.camera.keys.resize(1);
  return sim::SimulatedCamera(std::move(scene), sim::ResolveCameraModel("sr2"), so);
}

// Eq. 1 with the simulator's own fixed-pattern offsets: what a wall calibration would give.
inline OffsetCalibration SimulatorOffsets(const sim::SimulatedCamera& cam) {
  OffsetCalibration c;
  const CameraInfo info = cam.Info();
  c.camera_model = info.model;
  c.width = info.intrinsics.width;
  c.height = info.intrinsics.height;
  c.modulation_frequency_hz = info.modulation_frequency_hz;
  c.offset_m = cam.FixedPatternOffsetM();
  c.pixel_flags = Image<PixelFlags>(c.width, c.height);
  return c;
}

// A 150-knot table (5 cm knots from 0.3 m, a 3 cm wiggle of period L/4). Its cost is real, its
// values are made up (not the simulator's wiggling), so ground-truth counts use eq. 1 alone.
inline DistanceCorrection MadeUpDistanceTable() {
  DistanceCorrection g;
  g.start_m = 0.3;
  g.step_m = 0.05;
  for (int k = 0; k < 150; ++k) {
    g.correction_m.push_back(static_cast<float>(0.03 * std::sin(k * 0.05 * 4 * kPi / 7.5)));
  }
  return g;
}

// The ΔL scale a user gets from `tofcam calibrate --noise` (FitDeltaLScale on 16 static frames),
// so the accuracy threshold's 7 cm default means 7 cm of predicted σ, as in a calibrated
// pipeline; with scale 1 it would mean ~1.2 cm and reject most good pixels. The scaled models
// keep the SR-2 pixel and its gain, so one fit serves every size.
inline double FitBenchNoiseScale() {
  sim::SimulatedCamera cam = StaticStartCamera(40);
  const OffsetCalibration c = SimulatorOffsets(cam);
  std::vector<MetricFrame> frames;
  for (int i = 0; i < 16; ++i) {
    std::optional<Frame> f = cam.Grab();
    if (!f) throw Error(ErrorCode::kInternal, "simulator returned no frame");
    MetricFrame m = ConvertToMetric(*f);
    ApplyCalibrationInPlace(m, c);
    frames.push_back(std::move(m));
  }
  return FitDeltaLScale(frames).scale;
}

}  // namespace tofcam::bench
