#include "fused_pass.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
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

  // Each block is computed in a scratch that stays in L1 and then copied to the frame. Working
  // on the frame's buffers directly would keep ~20 arrays live per block, and at large sizes
  // every buffer is a separate mmap at the same offset within its pages: all of them then map
  // to the same L1 sets, more than its 12 ways, and evict each other between the stages. The
  // scratch is contiguous (spread over all sets); the copies stream one array at a time.
  constexpr std::size_t kB = kernels::kBlockPixels;
  // Arrays of the block, staggered by a few cache lines so that no two start at the same offset
  // within a 4 KiB page (4K aliasing between the loads and stores of the stage loops).
  struct Scratch {
    float d[kB];
    char pad0[64 * 1];
    float a[kB];
    char pad1[64 * 2];
    float i[kB];
    char pad2[64 * 3];
    float dl[kB];
    char pad3[64 * 4];
    float x[kB];
    char pad4[64 * 5];
    float y[kB];
    char pad5[64 * 6];
    float z[kB];
    char pad6[64 * 7];
    PixelFlags f[kB];
    char pad7[64 * 8];
    PixelFlags raised[kB];
  };
  thread_local Scratch b;
  const bool intensity = m.has_intensity();
  const bool accuracy = s.accuracy != nullptr;
  const std::size_t n = m.radial_distance_m.size();
  float* d = m.radial_distance_m.data();
  float* a = m.amplitude.data();
  float* in = intensity ? m.intensity.data() : nullptr;
  float* dl = accuracy ? m.delta_l_m.data() : nullptr;
  PixelFlags* f = m.flags.data();
  // Outputs beyond this size cannot stay in the caches until anyone reads them: they are written
  // with non-temporal stores (no read-for-ownership, no eviction of the inputs). 24 MiB: 3/4 of
  // a 32 MiB L3, the rule glibc's memcpy uses; the SR-2 frame's outputs (0.9 MB) stay cached.
  constexpr std::size_t kStreamBytes = std::size_t{24} << 20;
  constexpr std::size_t kOutputBytesPerPixel = 18 + 4 + 26;  // metric frame, flag copies, cloud
  const bool stream = n * kOutputBytesPerPixel > kStreamBytes;
  auto put = [stream](auto* dst, const auto* src, std::size_t len) {
    if (stream) {
      kernels::StreamCopy(dst, src, len * sizeof(*src));
    } else {
      std::copy(src, src + len, dst);
    }
  };
  const float kNan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t begin = 0; begin < n; begin += kB) {
    const std::size_t len = std::min(kB, n - begin);
    kernels::ConvertSpan(metric, begin, len, b.d, b.a, intensity ? b.i : nullptr, b.f);
    if (s.calibration != nullptr) {
      calibration_internal::CalibrateSpan(calibration, begin, len, b.d, b.f);
    }
    if (accuracy) kernels::DeltaLSpan(delta_l, len, b.a, b.i, b.dl);
    if (out.input_flags != nullptr) put(out.input_flags->data() + begin, b.f, len);
    if (filters.any) {
      kernels::PixelFiltersSpan(filters, len, b.d, b.a, intensity ? b.i : nullptr,
                                accuracy ? b.dl : nullptr, b.raised);
      kernels::OrFlags(len, b.f, b.raised);
    } else {
      std::fill(b.raised, b.raised + len, PixelFlags());
    }
    if (out.filter_flags != nullptr) put(out.filter_flags->data() + begin, b.raised, len);
    if (s.cloud != nullptr) {
      // As MakePointCloudInto: points from the block, the other fields copied (NaN if absent).
      PointCloud& c = *out.cloud;
      kernels::ProjectSpan(len, b.d, b.f, s.cloud->nan_mask, s.rays->x.data() + begin,
                           s.rays->y.data() + begin, s.rays->z.data() + begin, b.x, b.y, b.z);
      put(c.x.data() + begin, b.x, len);
      put(c.y.data() + begin, b.y, len);
      put(c.z.data() + begin, b.z, len);
      put(c.amplitude.data() + begin, b.a, len);
      if (intensity) {
        put(c.intensity.data() + begin, b.i, len);
      } else {
        std::fill(c.intensity.begin() + begin, c.intensity.begin() + begin + len, kNan);
      }
      if (accuracy) {
        put(c.delta_l_m.data() + begin, b.dl, len);
      } else {
        std::fill(c.delta_l_m.begin() + begin, c.delta_l_m.begin() + begin + len, kNan);
      }
      put(c.flags.data() + begin, b.f, len);
    }
    put(d + begin, b.d, len);
    put(a + begin, b.a, len);
    if (intensity) put(in + begin, b.i, len);
    if (accuracy) put(dl + begin, b.dl, len);
    put(f + begin, b.f, len);
  }
  if (stream) kernels::StreamFence();
}

}  // namespace tofcam::pipeline_internal
