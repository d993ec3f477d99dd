#pragma once
/// \file
/// The paper's per-frame chain for one camera in one call: registers -> metric (stage 1) ->
/// eq. 1 with the distance table (stage 2) -> ΔL (stage 3) -> the ΔL threshold (the paper's
/// filter) -> organised point cloud (stage 6), into reused buffers (no allocation per frame).
///
/// The results are exactly those of calling the stage functions one after the other —
/// ConvertToMetricInto, ApplyCalibrationInPlace, ComputeDeltaLInto,
/// MergeFlags(AccuracyThresholdFilter), MakePointCloudInto — without their per-call checks,
/// allocations and the per-thread table cache: the distance table is resampled once at
/// construction and the threshold ORs straight into the flags. Pipeline::Process runs the same
/// pass (plus the other filters, the controller and the statistics). See docs/benchmarks.md.
///
///     PaperChain chain(options, camera.Info());
///     MetricFrame frame;
///     PointCloud cloud;
///     while (auto f = camera.Grab()) chain.Process(*f, frame, cloud);  // no allocation

#include <optional>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {

struct PaperChainOptions {
  MetricConversionOptions metric;
  /// Per-pixel calibration (eq. 1, plus its distance table if any); none = stage 2 skipped.
  /// Must have been made for the camera (model, size, modulation frequency).
  std::optional<OffsetCalibration> calibration;
  AccuracyOptions accuracy;            ///< ΔL, eq. 2.
  AccuracyThresholdOptions threshold;  ///< kHighDeltaL where ΔL exceeds it.
  PointCloudOptions cloud;             ///< Which flags make a point NaN.

  /// Throws Error(kInvalidArgument) naming the section and field.
  void Validate() const;
};

/// The chain for one camera: owns its options, ray table and the resampled distance table.
/// Not thread-safe; one instance per thread.
class PaperChain {
 public:
  /// Validates the options; Error(kMismatch) when the calibration does not fit the camera.
  PaperChain(PaperChainOptions options, const CameraInfo& camera);

  /// Runs the chain on `frame`: `out` receives the calibrated metric frame (distance,
  /// amplitude, intensity, ΔL, flags incl. kHighDeltaL, info, truth), `cloud` the organised
  /// cloud. Both are reused (no allocation when they already have the frame's size). Throws
  /// like the stage functions (Error(kMismatch) for a frame of another size or frequency).
  void Process(const Frame& frame, MetricFrame& out, PointCloud& cloud);

  [[nodiscard]] const PaperChainOptions& options() const noexcept { return options_; }
  [[nodiscard]] const RayTable& rays() const noexcept { return rays_; }

 private:
  PaperChainOptions options_;
  CameraInfo camera_;
  RayTable rays_;
  std::optional<DenseDistanceCorrection> table_;
};

}  // namespace tofcam
