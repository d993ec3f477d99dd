#pragma once
// The per-pixel pass shared by PaperChain and Pipeline: stage 1 (metric conversion), stage 2
// (eq. 1 + the dense distance table), stage 3 (ΔL), the per-pixel filters and, optionally,
// stage 6 (the point cloud), straight into the caller's reused buffers (no allocation once
// their sizes are stable). The stages run one after the other over chunks of the frame
// (CacheChunkPixels(), or kernels::kChunkPixels when the pass makes a streamed cloud);
// the results are those of the stage functions called one after the other on the whole
// frame, bit for bit, since each chunk runs the very same loops (src/pipeline/stage_kernels.h).
// fused_pass.cc explains the chunk sizes.
// Not installed.

#include <cstddef>
#include <optional>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam::pipeline_internal {

// What the pass runs; pointers are owned by the caller (PaperChain, Pipeline).
struct FusedStages {
  MetricConversionOptions metric;
  const OffsetCalibration* calibration = nullptr;  // nullptr: no eq. 1
  // calibration->distance_correction resampled for range `table_range_m` (nullptr: none).
  const DenseDistanceCorrection* table = nullptr;
  double table_range_m = 0.0;
  const AccuracyOptions* accuracy = nullptr;  // nullptr: no ΔL
  FilterSetOptions filters;                   // only its per-pixel filters run in the pass
  const RayTable* rays = nullptr;
  const PointCloudOptions* cloud = nullptr;  // nullptr: no cloud in this pass
};

struct FusedOutputs {
  MetricFrame* frame = nullptr;
  Image<PixelFlags>* input_flags = nullptr;   // flags before the filters; nullptr: not kept
  Image<PixelFlags>* filter_flags = nullptr;  // bits the per-pixel filters raised; nullptr: not
  PointCloud* cloud = nullptr;                // needed when stages.cloud is set
};

// Runs the pass. Throws like the stage functions (checks happen before any pixel is written).
void RunFusedPass(const Frame& frame, const FusedStages& stages, const FusedOutputs& out);

// Pixels per chunk of a pass without a streamed cloud: kernels::kCacheChunkPixels on Intel CPUs,
// SIZE_MAX (the whole frame) on others, decided once (fused_pass.cc gives the measurements).
[[nodiscard]] std::size_t CacheChunkPixels();

// Tests only: CacheChunkPixels() returns `pixels` (> 0; SIZE_MAX: whole frames) until called
// with 0. Any chunking gives the same results; this lets one machine run every form.
void ForceCacheChunkForTesting(std::size_t pixels);

// Error(kMismatch) naming the field unless the calibration was made for this camera.
void CheckCalibrationFits(const OffsetCalibration& c, const CameraInfo& camera);

// The calibration's distance correction resampled for the camera's L (DenseDistanceCorrection
// at its default step, as ApplyCalibrationInPlace uses); empty without one.
[[nodiscard]] std::optional<DenseDistanceCorrection> PrepareTable(
    const std::optional<OffsetCalibration>& calibration, const CameraInfo& camera);

}  // namespace tofcam::pipeline_internal
