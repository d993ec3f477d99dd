#include "tofcam/pipeline/metric_conversion.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "../filters/hot_loop.h"
#include "stage_kernels.h"
#include "tofcam/core/units.h"

namespace tofcam {

static_assert(static_cast<std::uint16_t>(Flag::kInvalid) == 1u);

void MetricConversionOptions::Validate() const {}

namespace {

template <typename T>
void Reshape(Image<T>& image, int w, int h) {
  if (!image.SameSize(w, h)) image = Image<T>(w, h);
}

// One pass over the registers: restrict pointers and no branches, so the four outputs come
// from one vectorised loop (per block in the fused pass).
TOFCAM_HOT_LOOP void ConvertLoop(std::size_t n, std::uint16_t offset, float scale,
                                 const std::uint16_t* __restrict d,
                                 const std::uint16_t* __restrict a, float* __restrict dm,
                                 float* __restrict am, PixelFlags* __restrict f) {
  for (std::size_t i = 0; i < n; ++i) {
    dm[i] = static_cast<float>(static_cast<std::uint16_t>(d[i] - offset)) * scale;
    am[i] = static_cast<float>(a[i]);
    f[i] = PixelFlags(static_cast<std::uint16_t>(a[i] == 0 ? 1u : 0u));  // kInvalid is bit 0
  }
}

TOFCAM_HOT_LOOP void ToFloat(std::size_t n, const std::uint16_t* __restrict in,
                             float* __restrict out) {
  for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<float>(in[i]);
}

}  // namespace

namespace kernels {

TOFCAM_HOT_LOOP void OrFlags(std::size_t n, PixelFlags* __restrict dst,
                             const PixelFlags* __restrict src) {
  for (std::size_t i = 0; i < n; ++i) dst[i] |= src[i];
}

MetricPlan PrepareMetric(const Frame& frame, const MetricConversionOptions& options,
                         MetricFrame& out, bool keep_delta_l) {
  options.Validate();
  ValidateFrame(frame);
  const int w = frame.width();
  const int h = frame.height();
  Reshape(out.radial_distance_m, w, h);
  Reshape(out.amplitude, w, h);
  Reshape(out.flags, w, h);
  if (!keep_delta_l) out.delta_l_m = Image<float>();
  out.info = frame.info;
  out.truth = frame.truth;
  // A per-frame copy only for sources that have the channel (a few real cameras' importers).
  out.confidence = frame.confidence;
  if (!frame.info.has_intensity) {
    out.intensity = Image<float>();
  } else {
    Reshape(out.intensity, w, h);
  }
  MetricPlan plan;
  plan.distance = frame.distance.data();
  plan.amplitude = frame.amplitude.data();
  plan.intensity = frame.info.has_intensity ? frame.intensity.data() : nullptr;
  plan.source_flags = frame.source_flags.empty() ? nullptr : frame.source_flags.data();
  // The offset register is applied by the camera modulo 2^16; uint16 arithmetic undoes it
  // exactly, wrap included.
  plan.offset_register = static_cast<std::uint16_t>(
      options.remove_distance_offset_register ? frame.info.distance_offset_register : 0);
  plan.scale = static_cast<float>(UnambiguousRangeM(frame.info.modulation_frequency_hz) /
                                  kDistanceRegisterSpan);
  return plan;
}

void ConvertSpan(const MetricPlan& plan, std::size_t begin, std::size_t n, float* d, float* a,
                 float* i, PixelFlags* f) {
  ConvertLoop(n, plan.offset_register, plan.scale, plan.distance + begin, plan.amplitude + begin, d,
              a, f);
  if (plan.source_flags != nullptr) OrFlags(n, f, plan.source_flags + begin);
  if (plan.intensity != nullptr) ToFloat(n, plan.intensity + begin, i);
}

}  // namespace kernels

MetricFrame ConvertToMetric(const Frame& frame, const MetricConversionOptions& options) {
  MetricFrame out;
  ConvertToMetricInto(frame, options, out);
  return out;
}

void ConvertToMetricInto(const Frame& frame, const MetricConversionOptions& options,
                         MetricFrame& out) {
  const kernels::MetricPlan plan = kernels::PrepareMetric(frame, options, out);
  kernels::ConvertSpan(plan, 0, out.radial_distance_m.size(), out.radial_distance_m.data(),
                       out.amplitude.data(), out.has_intensity() ? out.intensity.data() : nullptr,
                       out.flags.data());
}

}  // namespace tofcam
