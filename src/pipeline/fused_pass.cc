#include "fused_pass.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>

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

namespace {
// ForceCacheChunkForTesting's value; 0: the CPU's default.
std::atomic<std::size_t> forced_cache_chunk{0};

// Intel CPUs: kernels::kCacheChunkPixels; others: whole frames. On an Intel Xeon (2 MiB L2,
// docs/benchmarks.md, eighth session of 2026-11-27) 1K-pixel chunks, in which the channels handed
// from stage to stage (about 18 bytes a pixel) stay in L1, took the 640x480 chain from 1.44-1.53
// to 1.19-1.20 ms and SR-2 from 48.1-48.6 to 45.5-47.0 us (pipeline_bench, two alternated
// rounds; 512 and 2K pixels 1.19-1.23 ms, 4K 1.25-1.31 ms). On the AMD Zen machines of earlier
// sessions, chunks made it slower: 2^12 and 2^14 pixels 20-35 % at 640x480 and 6-33 % at 1 MP,
// SR-2 no faster (a Zen 4, third session of 2026-11-25); 16K up to 12 % at 640x480 (a Zen 4,
// fourth session of 2026-11-26). 1K chunks were not measured there, so those CPUs keep whole
// frames. The results are the same bit for bit either way.
bool ChunksPay() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_cpu_init();
  return __builtin_cpu_is("intel") != 0;
#else
  return false;
#endif
}

}  // namespace

std::size_t CacheChunkPixels() {
  const std::size_t forced = forced_cache_chunk.load(std::memory_order_relaxed);
  if (forced != 0) return forced;
  static const std::size_t chunk =
      ChunksPay() ? kernels::kCacheChunkPixels : std::numeric_limits<std::size_t>::max();
  return chunk;
}

void ForceCacheChunkForTesting(std::size_t pixels) {
  forced_cache_chunk.store(pixels, std::memory_order_relaxed);
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

  // The stages run one after the other over chunks of the frame, directly on the frame's
  // buffers, so that what one stage writes is still in a cache when the next stage reads it.
  // - Frames whose cloud is large enough to be streamed past the caches (kStreamCloudBytes,
  //   CloudSpan) run in chunks of kChunkPixels (16K): a chunk's channels stay in the core's L2,
  //   and the streamed cloud saves the reads of its output lines. At 1 MP that took the chain
  //   from a median 1.60x its memcpy floor to 1.40x (pipeline_bench, ten interleaved runs each,
  //   on a machine with a busy second core; docs/benchmarks.md). Either alone was measured no
  //   faster: without streaming the cloud's stores read every output line from memory first;
  //   without chunks the streamed channels are read back from memory. Streaming the metric
  //   frame too (computed in an L2 scratch) was slower: median 1.57x. Chunks of 2^15-2^16
  //   pixels measured the same as 2^14 (and, on the Intel Xeon below, 1K-4K too).
  // - Other frames: CacheChunkPixels().
  const std::size_t n = m.radial_distance_m.size();
  const bool streamed_cloud =
      s.cloud != nullptr && n * kernels::kCloudBytesPerPoint >= kernels::kStreamCloudBytes;
  const std::size_t chunk =
      streamed_cloud ? kernels::kChunkPixels : std::min(CacheChunkPixels(), n);
  const bool intensity = m.has_intensity();
  const bool accuracy = s.accuracy != nullptr;
  float* d = m.radial_distance_m.data();
  float* a = m.amplitude.data();
  float* in = intensity ? m.intensity.data() : nullptr;
  float* dl = accuracy ? m.delta_l_m.data() : nullptr;
  PixelFlags* f = m.flags.data();
  for (std::size_t begin = 0; begin < n; begin += chunk) {
    const std::size_t len = std::min(chunk, n - begin);
    float* cd = d + begin;
    float* ca = a + begin;
    float* ci = intensity ? in + begin : nullptr;
    float* cdl = accuracy ? dl + begin : nullptr;
    PixelFlags* cf = f + begin;
    kernels::ConvertSpan(metric, begin, len, cd, ca, ci, cf);
    if (s.calibration != nullptr)
      calibration_internal::CalibrateSpan(calibration, begin, len, cd, cf);
    if (accuracy) {
      const float* cc = m.confidence.empty() ? nullptr : m.confidence.data() + begin;
      kernels::DeltaLSpan(delta_l, len, cd, ca, ci, cc, cdl);
    }
    if (out.input_flags != nullptr) std::copy(cf, cf + len, out.input_flags->data() + begin);
    if (out.filter_flags != nullptr) {
      PixelFlags* raised = out.filter_flags->data() + begin;
      kernels::PixelFiltersSpan(filters, len, cd, ca, ci, cdl, raised);
      if (filters.any) kernels::OrFlags(len, cf, raised);
    } else if (filters.any) {
      kernels::PixelFiltersOrSpan(filters, len, cd, ca, ci, cdl, cf);  // straight into the flags
    }
    if (s.cloud != nullptr) {
      kernels::CloudSpan(*s.rays, *s.cloud, begin, len, cd, cf, ca, ci, cdl, *out.cloud);
    }
  }
}

}  // namespace tofcam::pipeline_internal
