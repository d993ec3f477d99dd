#pragma once
// The per-pixel loops of stages 1, 3, 5 (per-pixel filters) and 6 over a span of pixels, shared
// by the public whole-image functions and the pass of PaperChain and Pipeline
// (src/pipeline/fused_pass.cc). Each stage's "Prepare" does the checks and buffer sizing of its
// public function, once per frame; its "Span" is the loop. Eq. 1 and the distance table are in
// src/calibration/calibration_kernel.h. Not installed.

#include <cstddef>
#include <cstdint>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam::kernels {

// Pixels per chunk of the fused pass when it makes a streamed cloud (kStreamCloudBytes).
inline constexpr std::size_t kChunkPixels = std::size_t{1} << 14;
// Pixels per chunk of the fused pass otherwise, on CPUs where chunks pay
// (pipeline_internal::CacheChunkPixels): the channels one stage hands to the next (distance,
// amplitude, intensity, ΔL, flags: about 18 KiB) stay in L1; the chunk's whole working set
// (about 66 bytes a pixel with the inputs, rays and cloud) in L2. src/pipeline/fused_pass.cc
// gives the measurements.
inline constexpr std::size_t kCacheChunkPixels = std::size_t{1} << 10;

// dst[i] |= src[i] for i in [0, n); dst and src do not overlap.
void OrFlags(std::size_t n, PixelFlags* dst, const PixelFlags* src);

// --- Stage 1: metric conversion (src/pipeline/metric_conversion.cc) ---------------------------

struct MetricPlan {
  const std::uint16_t* distance = nullptr;
  const std::uint16_t* amplitude = nullptr;
  const std::uint16_t* intensity = nullptr;  // nullptr without an intensity channel
  const PixelFlags* source_flags = nullptr;  // nullptr = none
  std::uint16_t offset_register = 0;
  float scale = 0.0f;  // L / 65536
};

// Validates the frame, sizes `out` (no allocation when it already has the frame's size), copies
// info and truth, clears ΔL unless `keep_delta_l` (the fused pass keeps the buffer it is about to
// overwrite). Throws like ConvertToMetricInto.
[[nodiscard]] MetricPlan PrepareMetric(const Frame& frame, const MetricConversionOptions& options,
                                       MetricFrame& out, bool keep_delta_l = false);
// Pixels [begin, begin + n) of the frame into d, a, i (nullptr without intensity) and f, which
// point at the span's first pixel (the frame's own buffers + begin, or a block scratch).
void ConvertSpan(const MetricPlan& plan, std::size_t begin, std::size_t n, float* d, float* a,
                 float* i, PixelFlags* f);

// --- Stage 3: ΔL (src/accuracy/delta_l.cc) ----------------------------------------------------

struct DeltaLPlan {
  float k = 0.0f;   // scale L / (2 sqrt 8)
  float ka = 0.0f;  // amplitude-only form: k sqrt(intensity_per_amplitude)
  bool has_intensity = true;
  const NoiseModel* model = nullptr;  // set: the fitted model instead of eq. 2
};

// Validates options and frame, sizes `out`. Throws like ComputeDeltaLInto.
[[nodiscard]] DeltaLPlan PrepareDeltaL(const MetricFrame& frame, const AccuracyOptions& options,
                                       Image<float>& out);
// ΔL of n pixels from amplitude a and intensity i (unused in the amplitude-only form) into out;
// the fitted model also reads distance d and confidence c (nullptr when the frame has none).
void DeltaLSpan(const DeltaLPlan& plan, std::size_t n, const float* d, const float* a,
                const float* i, const float* c, float* out);

// --- Stage 5: the per-pixel filters (src/filters/pixel_filters.cc) ----------------------------

struct PixelFilterPlan {
  bool any = false;  // false: no per-pixel filter enabled, nothing to do
  float range_lo = 0, range_hi = 0, min_amplitude = 0, max_intensity = 0, max_amplitude = 0;
  float max_peak = 0, max_delta_l = 0;
  std::uint16_t range_bit = 0, amplitude_bit = 0, saturation_bit = 0, accuracy_bit = 0;
};

// The range, amplitude, saturation and accuracy filters of `options` (the others are ignored).
// Validates their options. Needs the frame's channels only for the checks of
// PixelFiltersSpan's inputs (amplitude, ΔL present when needed); throws like ApplyFilters.
[[nodiscard]] PixelFilterPlan PreparePixelFilters(const MetricFrame& frame,
                                                  const FilterSetOptions& options);
// Writes (not ORs) the raised bits of n pixels to raised. Channels may be nullptr when absent
// (they read as zeros, which the plan makes pass).
void PixelFiltersSpan(const PixelFilterPlan& plan, std::size_t n, const float* d, const float* a,
                      const float* i, const float* dl, PixelFlags* raised);
// The same, ORed into `flags`.
void PixelFiltersOrSpan(const PixelFilterPlan& plan, std::size_t n, const float* d, const float* a,
                        const float* i, const float* dl, PixelFlags* flags);

// --- Stage 6: the organised point cloud (src/cloud/point_cloud.cc) ----------------------------

// Checks that the frame has a distance image, that its other channels have that size and that
// `rays` does; throws like MakePointCloudInto.
void CheckCloudInputs(const MetricFrame& frame, const RayTable& rays);
// CheckCloudInputs, then sizes the cloud.
void PrepareCloud(const MetricFrame& frame, const RayTable& rays, PointCloud& cloud);
// Bytes of one point of a PointCloud (x, y, z, amplitude, intensity, ΔL, flags).
inline constexpr std::size_t kCloudBytesPerPoint = 6 * sizeof(float) + sizeof(PixelFlags);
// From this size of cloud on (about 650k points, e.g. 1024x1024), CloudSpan writes it with
// non-temporal stores: a cloud this large does not stay in a small robot computer's last-level
// cache for its reader, so an ordinary store's read of each output line first is wasted traffic.
inline constexpr std::size_t kStreamCloudBytes = std::size_t{16} << 20;

// Points [begin, begin + n) of the cloud from the span's channels (pointers at the span's first
// pixel; a, i, dl, f may be nullptr when the frame has none: NaN / clear flags). Clouds of
// kStreamCloudBytes or more are written with non-temporal stores (the same values).
void CloudSpan(const RayTable& rays, const PointCloudOptions& options, std::size_t begin,
               std::size_t n, const float* d, const PixelFlags* f, const float* a, const float* i,
               const float* dl, PointCloud& cloud);

}  // namespace tofcam::kernels
