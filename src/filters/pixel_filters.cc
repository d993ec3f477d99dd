#include "tofcam/filters/pixel_filters.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "../pipeline/stage_kernels.h"
#include "filter_internal.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace filters_internal {
namespace {

constexpr std::uint16_t Bit(Flag f) { return static_cast<std::uint16_t>(f); }

void CheckChannel(int w, int h, int cw, int ch, bool allow_empty, const char* filter,
                  const char* channel) {
  if (allow_empty && cw == 0 && ch == 0) return;
  if (cw != w || ch != h) {
    throw Error(ErrorCode::kInvalidArgument, std::string(filter) + ": " + channel + " is " +
                                                 std::to_string(cw) + "x" + std::to_string(ch) +
                                                 ", the distance image " + std::to_string(w) + "x" +
                                                 std::to_string(h));
  }
}

}  // namespace

void CheckFrame(const MetricFrame& f, const char* filter) {
  const int w = f.radial_distance_m.width(), h = f.radial_distance_m.height();
  if (f.radial_distance_m.empty()) {
    throw Error(ErrorCode::kInvalidArgument, std::string(filter) + ": empty distance image");
  }
  CheckChannel(w, h, f.amplitude.width(), f.amplitude.height(), true, filter, "amplitude");
  CheckChannel(w, h, f.intensity.width(), f.intensity.height(), true, filter, "intensity");
  CheckChannel(w, h, f.flags.width(), f.flags.height(), true, filter, "flags");
  CheckChannel(w, h, f.delta_l_m.width(), f.delta_l_m.height(), true, filter, "delta_l_m");
}

void CheckRays(const MetricFrame& f, const RayTable& rays, const char* filter) {
  const int w = f.width(), h = f.height();
  if (!rays.x.SameSize(w, h) || !rays.y.SameSize(w, h) || !rays.z.SameSize(w, h)) {
    throw Error(ErrorCode::kMismatch, std::string(filter) + ": ray table is " +
                                          std::to_string(rays.x.width()) + "x" +
                                          std::to_string(rays.x.height()) + ", the frame " +
                                          std::to_string(w) + "x" + std::to_string(h));
  }
}

const PixelFlags* PriorOrZeros(const Image<PixelFlags>& prior, std::size_t n) {
  if (!prior.empty()) return prior.data();
  thread_local std::vector<PixelFlags> zeros;
  if (zeros.size() < n) zeros.resize(n);
  return zeros.data();
}

// The loops below write whole PixelFlags values computed without branches so that they
// vectorise; `!(x <= t)` is true for NaN as well as for x > t.

void AccuracyInto(const MetricFrame& frame, const AccuracyThresholdOptions& o,
                  Image<PixelFlags>& out) {
  if (frame.delta_l_m.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "accuracy threshold filter: delta_l_m is empty (run the accuracy stage first)");
  }
  const float t = static_cast<float>(o.max_delta_l_m);
  const float* dl = frame.delta_l_m.data();
  PixelFlags* f = out.data();
  const std::size_t n = out.size();
  for (std::size_t i = 0; i < n; ++i) {
    const bool ok = (dl[i] >= 0.0f) & (dl[i] <= t);
    f[i] |= PixelFlags(static_cast<std::uint16_t>(ok ? 0 : Bit(Flag::kHighDeltaL)));
  }
}

void AmplitudeInto(const MetricFrame& frame, const AmplitudeThresholdOptions& o,
                   Image<PixelFlags>& out) {
  if (frame.amplitude.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "amplitude threshold filter: amplitude is empty");
  }
  const float t = static_cast<float>(o.min_amplitude);
  const float* a = frame.amplitude.data();
  PixelFlags* f = out.data();
  const std::size_t n = out.size();
  for (std::size_t i = 0; i < n; ++i) {
    f[i] |= PixelFlags(static_cast<std::uint16_t>(a[i] >= t ? 0 : Bit(Flag::kLowAmplitude)));
  }
}

void SaturationInto(const MetricFrame& frame, const SaturationOptions& o, Image<PixelFlags>& out) {
  if (frame.amplitude.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "saturation filter: amplitude is empty");
  }
  const float max_a = static_cast<float>(o.max_amplitude);
  const float* a = frame.amplitude.data();
  PixelFlags* f = out.data();
  const std::size_t n = out.size();
  if (frame.intensity.empty()) {
    for (std::size_t i = 0; i < n; ++i) {
      f[i] |= PixelFlags(static_cast<std::uint16_t>(a[i] >= max_a ? Bit(Flag::kSaturated) : 0));
    }
    return;
  }
  const float max_i = static_cast<float>(o.max_intensity);
  const float max_p = static_cast<float>(o.max_peak);
  const float* in = frame.intensity.data();
  for (std::size_t i = 0; i < n; ++i) {
    const bool sat = (in[i] >= max_i) | (a[i] >= max_a) | (in[i] + a[i] >= max_p);
    f[i] |= PixelFlags(static_cast<std::uint16_t>(sat ? Bit(Flag::kSaturated) : 0));
  }
}

void RangeInto(const MetricFrame& frame, const RangeOptions& o, Image<PixelFlags>& out) {
  const float lo = static_cast<float>(o.min_distance_m);
  const float hi = static_cast<float>(o.max_distance_m);
  const float* d = frame.radial_distance_m.data();
  PixelFlags* f = out.data();
  const std::size_t n = out.size();
  for (std::size_t i = 0; i < n; ++i) {
    const bool ok = (d[i] >= lo) & (d[i] <= hi);
    f[i] |= PixelFlags(static_cast<std::uint16_t>(ok ? 0 : Bit(Flag::kOutOfRange)));
  }
}

namespace {

// The enabled filters' bits of each pixel: written into f (kWrite: f may hold anything, every
// pixel of the span is overwritten) or ORed into it. The filters a set leaves out are compiled
// out (kRange ... kAccuracy), since the frequent sets (the paper's threshold alone, the
// pipeline's default threshold + saturation, one filter alone) would otherwise pay for every
// comparison and read every channel; their bits would be 0 anyway, so every instance gives the
// generic one's result.
template <bool kRange, bool kAmplitude, bool kSaturation, bool kAccuracy, bool kWrite>
[[gnu::always_inline]] inline void FusedBody(std::size_t n, const kernels::PixelFilterPlan& l,
                                             const float* __restrict d, const float* __restrict a,
                                             const float* __restrict in, const float* __restrict dl,
                                             PixelFlags* __restrict f) {
  const float lo = l.range_lo, hi = l.range_hi, min_a = l.min_amplitude;
  const float max_i = l.max_intensity, max_a = l.max_amplitude, max_p = l.max_peak;
  const float max_dl = l.max_delta_l;
  const unsigned rb = l.range_bit, ab = l.amplitude_bit, sb = l.saturation_bit, db = l.accuracy_bit;
  for (std::size_t i = 0; i < n; ++i) {
    unsigned bits = 0;
    if constexpr (kRange) {
      bits |= static_cast<unsigned>(!((d[i] >= lo) & (d[i] <= hi))) * rb;
    }
    if constexpr (kAmplitude) bits |= static_cast<unsigned>(!(a[i] >= min_a)) * ab;
    if constexpr (kSaturation) {
      bits |=
          static_cast<unsigned>((in[i] >= max_i) | (a[i] >= max_a) | (in[i] + a[i] >= max_p)) * sb;
    }
    if constexpr (kAccuracy) {
      bits |= static_cast<unsigned>(!((dl[i] >= 0.0f) & (dl[i] <= max_dl))) * db;
    }
    if constexpr (kWrite) {
      f[i] = PixelFlags(static_cast<std::uint16_t>(bits));
    } else {
      f[i] |= PixelFlags(static_cast<std::uint16_t>(bits));
    }
  }
}

// x86-64-v4 clones too: on a Zen 5 the single-filter rows (amplitude, range) at SR-2 went from
// 9.2 to 6.3 times their memcpy floor (`tofcam bench`, two alternated pairs), measured when they
// still ran the form for all four filters; the forms of one filter were not measured against
// their AVX2 clone. Compares and one add, built without contraction: the same flags in every
// clone. The write forms serve FilterSet and ApplyFilters; the OR forms the fused pass, which
// ORs only the paper's threshold (PaperChain) or, generically, any set.
#define TOFCAM_FUSED_FILTERS(name, r, a, s, c, write)                                    \
  TOFCAM_HOT_LOOP_WIDE void name(std::size_t n, const kernels::PixelFilterPlan& l,       \
                                 const float* __restrict d, const float* __restrict am,  \
                                 const float* __restrict in, const float* __restrict dl, \
                                 PixelFlags* __restrict f) {                             \
    FusedBody<r, a, s, c, write>(n, l, d, am, in, dl, f);                                \
  }
TOFCAM_FUSED_FILTERS(FusedAllOr, true, true, true, true, false)
TOFCAM_FUSED_FILTERS(FusedAccuracyOr, false, false, false, true, false)
TOFCAM_FUSED_FILTERS(FusedAllWrite, true, true, true, true, true)
TOFCAM_FUSED_FILTERS(FusedAccuracyWrite, false, false, false, true, true)
TOFCAM_FUSED_FILTERS(FusedSaturationAccuracyWrite, false, false, true, true, true)
TOFCAM_FUSED_FILTERS(FusedRangeWrite, true, false, false, false, true)
TOFCAM_FUSED_FILTERS(FusedAmplitudeWrite, false, true, false, false, true)
TOFCAM_FUSED_FILTERS(FusedSaturationWrite, false, false, true, false, true)
#undef TOFCAM_FUSED_FILTERS

const float* ZeroFloats(std::size_t n) {
  thread_local std::vector<float> zeros;
  if (zeros.size() < n) zeros.resize(n, 0.0f);
  return zeros.data();
}

// n pixels; channels at the span's first pixel, nullptr when absent (read as zeros). `write`:
// overwrite f with the bits (it need not be cleared) rather than OR them in.
void RunFused(const kernels::PixelFilterPlan& l, std::size_t n, const float* d, const float* a,
              const float* in, const float* dl, PixelFlags* f, bool write) {
  // Missing channels read zeros; the plan makes their filters pass (or they are disabled).
  if (a == nullptr || in == nullptr || dl == nullptr) {
    const float* zeros = ZeroFloats(n);
    a = a != nullptr ? a : zeros;
    in = in != nullptr ? in : zeros;
    dl = dl != nullptr ? dl : zeros;
  }
  using Kernel = void (*)(std::size_t, const kernels::PixelFilterPlan&, const float*, const float*,
                          const float*, const float*, PixelFlags*);
  const unsigned set = (l.range_bit != 0 ? 1u : 0u) | (l.amplitude_bit != 0 ? 2u : 0u) |
                       (l.saturation_bit != 0 ? 4u : 0u) | (l.accuracy_bit != 0 ? 8u : 0u);
  Kernel k = write ? FusedAllWrite : FusedAllOr;
  if (!write) {
    if (set == 8) k = FusedAccuracyOr;
  } else if (set == 8) {
    k = FusedAccuracyWrite;
  } else if (set == (4 | 8)) {
    k = FusedSaturationAccuracyWrite;
  } else if (set == 1) {
    k = FusedRangeWrite;
  } else if (set == 2) {
    k = FusedAmplitudeWrite;
  } else if (set == 4) {
    k = FusedSaturationWrite;
  }
  k(n, l, d, a, in, dl, f);
}

}  // namespace

}  // namespace filters_internal

namespace kernels {

PixelFilterPlan PreparePixelFilters(const MetricFrame& frame, const FilterSetOptions& o) {
  PixelFilterPlan l;
  l.any = o.range_enabled || o.amplitude_enabled || o.saturation_enabled || o.accuracy_enabled;
  if (!l.any) return l;
  if (o.range_enabled) o.range.Validate();
  if (o.amplitude_enabled) o.amplitude.Validate();
  if (o.saturation_enabled) o.saturation.Validate();
  if (o.accuracy_enabled) o.accuracy.Validate();
  if ((o.amplitude_enabled || o.saturation_enabled) && frame.amplitude.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "filters: amplitude is empty");
  }
  if (o.accuracy_enabled && frame.delta_l_m.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "accuracy threshold filter: delta_l_m is empty (run the accuracy stage first)");
  }
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // A disabled filter gets limits nothing can fail (NaN-safe: its bit is 0 anyway).
  l.range_lo = o.range_enabled ? static_cast<float>(o.range.min_distance_m) : -kInf;
  l.range_hi = o.range_enabled ? static_cast<float>(o.range.max_distance_m) : kInf;
  l.range_bit = o.range_enabled ? filters_internal::Bit(Flag::kOutOfRange) : 0;
  l.min_amplitude = o.amplitude_enabled ? static_cast<float>(o.amplitude.min_amplitude) : 0.0f;
  l.amplitude_bit = o.amplitude_enabled ? filters_internal::Bit(Flag::kLowAmplitude) : 0;
  const bool has_i = !frame.intensity.empty();
  l.max_intensity =
      o.saturation_enabled && has_i ? static_cast<float>(o.saturation.max_intensity) : kInf;
  l.max_amplitude = o.saturation_enabled ? static_cast<float>(o.saturation.max_amplitude) : kInf;
  l.max_peak = o.saturation_enabled && has_i ? static_cast<float>(o.saturation.max_peak) : kInf;
  l.saturation_bit = o.saturation_enabled ? filters_internal::Bit(Flag::kSaturated) : 0;
  l.max_delta_l = o.accuracy_enabled ? static_cast<float>(o.accuracy.max_delta_l_m) : kInf;
  l.accuracy_bit = o.accuracy_enabled ? filters_internal::Bit(Flag::kHighDeltaL) : 0;
  return l;
}

void PixelFiltersSpan(const PixelFilterPlan& plan, std::size_t n, const float* d, const float* a,
                      const float* i, const float* dl, PixelFlags* raised) {
  if (plan.any) {
    filters_internal::RunFused(plan, n, d, a, i, dl, raised, /*write=*/true);
  } else {
    std::fill(raised, raised + n, PixelFlags());
  }
}

void PixelFiltersOrSpan(const PixelFilterPlan& plan, std::size_t n, const float* d, const float* a,
                        const float* i, const float* dl, PixelFlags* flags) {
  if (plan.any) filters_internal::RunFused(plan, n, d, a, i, dl, flags, /*write=*/false);
}

}  // namespace kernels

namespace {

void RequireRange(double v, double lo, double hi, const char* name) {
  if (!(v >= lo && v <= hi)) {
    throw Error(ErrorCode::kInvalidArgument, std::string(name) + " = " + std::to_string(v) +
                                                 " is outside [" + std::to_string(lo) + ", " +
                                                 std::to_string(hi) + "]");
  }
}

Image<PixelFlags> Blank(const MetricFrame& frame) {
  return Image<PixelFlags>(frame.width(), frame.height());
}

}  // namespace

void MergeFlags(MetricFrame& frame, const Image<PixelFlags>& flags) {
  if (!flags.SameSize(frame.radial_distance_m)) {
    throw Error(ErrorCode::kInvalidArgument,
                "MergeFlags: flags are " + std::to_string(flags.width()) + "x" +
                    std::to_string(flags.height()) + ", the frame " +
                    std::to_string(frame.width()) + "x" + std::to_string(frame.height()));
  }
  if (frame.flags.empty()) {
    frame.flags = flags;
    return;
  }
  if (!frame.flags.SameSize(flags)) {
    throw Error(ErrorCode::kInvalidArgument, "MergeFlags: frame.flags differ in size from frame");
  }
  PixelFlags* dst = frame.flags.data();
  const PixelFlags* src = flags.data();
  for (std::size_t i = 0; i < flags.size(); ++i) dst[i] |= src[i];
}

void AccuracyThresholdOptions::Validate() const {
  // A zero or negative threshold would reject every pixel; 100 m is far beyond any range.
  if (!(max_delta_l_m > 0.0 && max_delta_l_m <= 100.0)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "accuracy.max_delta_l_m = " + std::to_string(max_delta_l_m) + " is outside (0, 100] m");
  }
}

void AmplitudeThresholdOptions::Validate() const {
  RequireRange(min_amplitude, 0.0, 65532.0, "amplitude.min_amplitude");
}

void ConfidenceThresholdOptions::Validate() const {
  RequireRange(min_confidence, 0.0, 1e9, "confidence.min_confidence");
}

void SaturationOptions::Validate() const {
  RequireRange(max_intensity, 1e-9, 1e9, "saturation.max_intensity");
  RequireRange(max_amplitude, 1e-9, 1e9, "saturation.max_amplitude");
  RequireRange(max_peak, 1e-9, 2e9, "saturation.max_peak");
}

void RangeOptions::Validate() const {
  RequireRange(min_distance_m, 0.0, 1e6, "range.min_distance_m");
  RequireRange(max_distance_m, 0.0, 1e6, "range.max_distance_m");
  if (!(max_distance_m > min_distance_m)) {
    throw Error(ErrorCode::kInvalidArgument,
                "range.max_distance_m = " + std::to_string(max_distance_m) +
                    " must exceed range.min_distance_m = " + std::to_string(min_distance_m));
  }
}

Image<PixelFlags> AccuracyThresholdFilter(const MetricFrame& frame,
                                          const AccuracyThresholdOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "accuracy threshold filter");
  Image<PixelFlags> out = Blank(frame);
  filters_internal::AccuracyInto(frame, options, out);
  return out;
}

Image<PixelFlags> AmplitudeThresholdFilter(const MetricFrame& frame,
                                           const AmplitudeThresholdOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "amplitude threshold filter");
  Image<PixelFlags> out = Blank(frame);
  filters_internal::AmplitudeInto(frame, options, out);
  return out;
}

Image<PixelFlags> SaturationFilter(const MetricFrame& frame, const SaturationOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "saturation filter");
  Image<PixelFlags> out = Blank(frame);
  filters_internal::SaturationInto(frame, options, out);
  return out;
}

Image<PixelFlags> RangeFilter(const MetricFrame& frame, const RangeOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "range filter");
  Image<PixelFlags> out = Blank(frame);
  filters_internal::RangeInto(frame, options, out);
  return out;
}

void ConfidenceThresholdInto(const MetricFrame& frame, const ConfidenceThresholdOptions& options,
                             Image<PixelFlags>& out) {
  options.Validate();
  if (frame.confidence.empty()) return;
  if (!frame.confidence.SameSize(out) || !out.SameSize(frame.radial_distance_m)) {
    throw Error(ErrorCode::kInvalidArgument,
                "confidence filter: confidence, flags and distance differ in size");
  }
  const float min = static_cast<float>(options.min_confidence);
  const float* c = frame.confidence.data();
  PixelFlags* o = out.data();
  for (std::size_t i = 0; i < out.size(); ++i) {
    // !(c >= min) also rejects NaN.
    if (!(c[i] >= min)) o[i] |= Flag::kLowConfidence;
  }
}

Image<PixelFlags> ConfidenceThresholdFilter(const MetricFrame& frame,
                                            const ConfidenceThresholdOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "confidence filter");
  Image<PixelFlags> out = Blank(frame);
  ConfidenceThresholdInto(frame, options, out);
  return out;
}

}  // namespace tofcam
