#pragma once
// Simulated inputs for every bench/*_bench.cc: the SR-2 pavilion with the camera driving back
// and forth (as `tofcam bench`, apps/tofcam/bench_command.cc), seed 7, integration register 40,
// 2x2 supersampling and all effects, at the SR-2 model scaled to the requested size (field of
// view kept). Generated once per process and size; items per second in every benchmark are
// pixels per second.

#include <vector>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"

namespace tofcam::bench {

struct SimulatedInput {
  CameraInfo info;
  RayTable rays;
  /// The simulator's fixed-pattern offsets plus a 150-knot distance table (3 cm wiggle), so the
  /// costlier form of eq. 1 is the one timed; no pixel flags.
  OffsetCalibration calibration;
  /// Frames as the simulator delivers them (registers and ground truth).
  std::vector<Frame> frames;
  /// The same frames without ground truth: what a real camera delivers (the pipeline would
  /// otherwise copy 10 bytes of truth per pixel into every result).
  std::vector<Frame> camera_frames;
  /// ΔL options with the scale of a noise calibration (FitBenchNoiseScale, bench_calibration.h),
  /// as a calibrated pipeline uses them.
  AccuracyOptions accuracy;
  /// Converted, calibrated (eq. 1 + table) and with ΔL (`accuracy`): the input of later stages.
  std::vector<MetricFrame> ready;
};

/// kFrames simulated frames at width x height (SR-2 160x124, 640x480, 1024x1024), cached.
inline constexpr int kFrames = 4;
[[nodiscard]] const SimulatedInput& Simulated(int width, int height);

}  // namespace tofcam::bench
