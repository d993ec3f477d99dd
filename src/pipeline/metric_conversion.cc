#include "tofcam/pipeline/metric_conversion.h"

#include <cstddef>
#include <cstdint>

#include "tofcam/core/units.h"

namespace tofcam {

static_assert(static_cast<std::uint16_t>(Flag::kInvalid) == 1u);

void MetricConversionOptions::Validate() const {}

namespace {

template <typename T>
void Reshape(Image<T>& image, int w, int h) {
  if (!image.SameSize(w, h)) image = Image<T>(w, h);
}

}  // namespace

MetricFrame ConvertToMetric(const Frame& frame, const MetricConversionOptions& options) {
  MetricFrame out;
  ConvertToMetricInto(frame, options, out);
  return out;
}

void ConvertToMetricInto(const Frame& frame, const MetricConversionOptions& options,
                         MetricFrame& out) {
  options.Validate();
  ValidateFrame(frame);
  const int w = frame.width();
  const int h = frame.height();
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);

  Reshape(out.radial_distance_m, w, h);
  Reshape(out.amplitude, w, h);
  Reshape(out.flags, w, h);
  out.delta_l_m = Image<float>();
  out.info = frame.info;
  out.truth = frame.truth;

  // The offset register is applied by the camera modulo 2^16; uint16 arithmetic undoes it
  // exactly, wrap included.
  const auto offset = static_cast<std::uint16_t>(
      options.remove_distance_offset_register ? frame.info.distance_offset_register : 0);
  const float scale = static_cast<float>(UnambiguousRangeM(frame.info.modulation_frequency_hz) /
                                         kDistanceRegisterSpan);
  const std::uint16_t* d = frame.distance.data();
  const std::uint16_t* a = frame.amplitude.data();
  float* dm = out.radial_distance_m.data();
  float* am = out.amplitude.data();
  PixelFlags* f = out.flags.data();
  // Separate simple loops: each one vectorises (a fused loop with three outputs does not).
  for (std::size_t i = 0; i < n; ++i) {
    dm[i] = static_cast<float>(static_cast<std::uint16_t>(d[i] - offset)) * scale;
  }
  for (std::size_t i = 0; i < n; ++i) am[i] = static_cast<float>(a[i]);
  for (std::size_t i = 0; i < n; ++i) {
    f[i] = PixelFlags(static_cast<std::uint16_t>(a[i] == 0 ? 1u : 0u));  // kInvalid is bit 0
  }
  if (!frame.source_flags.empty()) {
    const PixelFlags* s = frame.source_flags.data();
    for (std::size_t i = 0; i < n; ++i) f[i] |= s[i];
  }
  if (!frame.info.has_intensity) {
    out.intensity = Image<float>();
  } else {
    Reshape(out.intensity, w, h);
    const std::uint16_t* in = frame.intensity.data();
    float* im = out.intensity.data();
    for (std::size_t i = 0; i < n; ++i) im[i] = static_cast<float>(in[i]);
  }
}

}  // namespace tofcam
