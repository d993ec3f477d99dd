#include "fused_pass.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "../calibration/calibration_kernel.h"
#include "stage_kernels.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::pipeline_internal {

void CheckCalibrationFits(const OffsetCalibration& c, const CameraInfo& camera) {
  if (c.camera_model != camera.model) {
    throw Error(ErrorCode::kMismatch, "calibration is for camera model '" + c.camera_model +
                                          "', the camera is '" + camera.model + "'");
  }
  if (c.width != camera.width() || c.height != camera.height()) {
    throw Error(ErrorCode::kMismatch, "calibration is " + std::to_string(c.width) + "x" +
                                          std::to_string(c.height) + ", the camera is " +
                                          std::to_string(camera.width()) + "x" +
                                          std::to_string(camera.height()));
  }
  if (!(std::abs(c.modulation_frequency_hz - camera.modulation_frequency_hz) <=
        1e-9 * camera.modulation_frequency_hz)) {
    throw Error(ErrorCode::kMismatch, "calibration was made at " +
                                          std::to_string(c.modulation_frequency_hz) +
                                          " Hz, the camera runs at " +
                                          std::to_string(camera.modulation_frequency_hz) + " Hz");
  }
}

std::optional<DenseDistanceCorrection> PrepareTable(
    const std::optional<OffsetCalibration>& calibration, const CameraInfo& camera) {
  if (!calibration || !calibration->distance_correction) return std::nullopt;
  return DenseDistanceCorrection::Resample(*calibration->distance_correction,
                                           UnambiguousRangeM(camera.modulation_frequency_hz));
}

void RunFusedPass(const Frame& frame, const FusedStages& s, const FusedOutputs& out) {
  MetricFrame& m = *out.frame;
  // Every check and buffer sizing first, in the order the stage functions do them.
  const kernels::MetricPlan metric =
      kernels::PrepareMetric(frame, s.metric, m, /*keep_delta_l=*/s.accuracy != nullptr);
  calibration_internal::CalibrationPlan calibration;
  if (s.calibration != nullptr) {
    calibration = calibration_internal::MakePlan(m, *s.calibration, nullptr);  // checks first
    if (s.calibration->distance_correction) {
      // The prepared table is for the camera's L, which eq. 1 has just checked against the
      // frame's; the per-thread cache covers a caller without one.
      const double range_m = UnambiguousRangeM(m.info.modulation_frequency_hz);
      const DenseDistanceCorrection* table =
          s.table != nullptr && s.table_range_m == range_m
              ? s.table
              : calibration_internal::CachedTable(*s.calibration, range_m);
      calibration = calibration_internal::MakePlan(m, *s.calibration, table);
    }
  }
  kernels::DeltaLPlan delta_l;
  if (s.accuracy != nullptr) delta_l = kernels::PrepareDeltaL(m, *s.accuracy, m.delta_l_m);
  const kernels::PixelFilterPlan filters = kernels::PreparePixelFilters(m, s.filters);
  const int w = m.width(), h = m.height();
  for (Image<PixelFlags>* image : {out.input_flags, out.filter_flags}) {
    if (image != nullptr && !image->SameSize(w, h)) *image = Image<PixelFlags>(w, h);
  }
  if (s.cloud != nullptr) kernels::PrepareCloud(m, *s.rays, *out.cloud);

  const std::size_t n = m.radial_distance_m.size();
  thread_local std::vector<PixelFlags> raised_block;
  raised_block.resize(kernels::kBlockPixels);
  float* d = m.radial_distance_m.data();
  PixelFlags* f = m.flags.data();
  for (std::size_t begin = 0; begin < n; begin += kernels::kBlockPixels) {
    const std::size_t end = std::min(n, begin + kernels::kBlockPixels);
    const std::size_t len = end - begin;
    kernels::ConvertSpan(metric, begin, end, m);
    if (s.calibration != nullptr)
      calibration_internal::CalibrateSpan(calibration, begin, end, d, f);
    if (s.accuracy != nullptr) kernels::DeltaLSpan(delta_l, m, begin, end, m.delta_l_m.data());
    if (out.input_flags != nullptr) std::copy(f + begin, f + end, out.input_flags->data() + begin);
    PixelFlags* raised =
        out.filter_flags != nullptr ? out.filter_flags->data() + begin : raised_block.data();
    if (filters.any) {
      kernels::PixelFiltersSpan(filters, m, begin, end, raised);
      kernels::OrFlags(len, f + begin, raised);
    } else if (out.filter_flags != nullptr) {
      std::fill(raised, raised + len, PixelFlags());
    }
    if (s.cloud != nullptr) kernels::CloudSpan(m, *s.rays, *s.cloud, begin, end, *out.cloud);
  }
}

}  // namespace tofcam::pipeline_internal
