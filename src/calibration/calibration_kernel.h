#pragma once
// Eq. 1 and the dense distance-correction table over a span of pixels: the per-pixel loop of
// ApplyCalibrationInPlace, shared with the pass of PaperChain and Pipeline
// (src/pipeline/fused_pass.cc). Not installed.

#include <cstddef>

#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam::calibration_internal {

// Everything the per-pixel loop needs, checked and converted to single precision once per
// frame by MakePlan.
struct CalibrationPlan {
  const float* offset_m = nullptr;                 // o, frame size
  const PixelFlags* pixel_flags = nullptr;         // OR-ed in; nullptr = none
  float range_m = 0.0f;                            // L
  float bias_m = 0.0f;                             // L - exposure shift
  const DenseDistanceCorrection* table = nullptr;  // nullptr = offset-only eq. 1
  float table_origin_m = 0.0f;
  float table_inv_step = 0.0f;
  float table_last = 0.0f;  // index of the last sample, as float
  int table_last_segment = 0;
  const float* table_intervals = nullptr;  // table->intervals_m when filled, else nullptr
};

// Checks the frame against the calibration (size, modulation frequency, exposure shift, size of
// the correction) and fills the plan; throws like ApplyCalibrationInPlace. `table` must be
// `calibration.distance_correction` resampled for this L (nullptr when there is none).
[[nodiscard]] CalibrationPlan MakePlan(const MetricFrame& frame,
                                       const OffsetCalibration& calibration,
                                       const DenseDistanceCorrection* table);

// Applies the plan to pixels [begin, begin + n): `d` (distances, in place) and `f` (flags) point
// at the span's first pixel.
void CalibrateSpan(const CalibrationPlan& plan, std::size_t begin, std::size_t n, float* d,
                   PixelFlags* f);

// The calibration's correction resampled for range L, cached per thread (rebuilt when the knots
// or L change); nullptr when the calibration has no distance correction.
[[nodiscard]] const DenseDistanceCorrection* CachedTable(const OffsetCalibration& calibration,
                                                         double range_m);

}  // namespace tofcam::calibration_internal
