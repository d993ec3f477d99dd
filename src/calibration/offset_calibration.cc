#include "tofcam/calibration/offset_calibration.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <string>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& message) {
  throw Error(ErrorCode::kInvalidArgument, "calibration: " + message);
}

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

}  // namespace

double DistanceCorrection::Evaluate(double distance_m) const noexcept {
  const std::size_t n = correction_m.size();
  if (n == 0) return 0.0;
  if (n == 1) return correction_m[0];
  const double x = (distance_m - start_m) / step_m;
  if (!(x > 0.0)) return correction_m.front();  // also NaN
  const double last = static_cast<double>(n - 1);
  if (x >= last) return correction_m.back();
  const auto k = static_cast<std::size_t>(x);
  const double t = x - static_cast<double>(k);
  // Catmull-Rom through knots k-1..k+2, end knots repeated.
  const double p0 = correction_m[k == 0 ? 0 : k - 1];
  const double p1 = correction_m[k];
  const double p2 = correction_m[k + 1];
  const double p3 = correction_m[std::min(k + 2, n - 1)];
  return p1 + 0.5 * t *
                  ((p2 - p0) +
                   t * ((2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) + t * (3.0 * (p1 - p2) + p3 - p0)));
}

void DistanceCorrection::Validate() const {
  if (!std::isfinite(start_m) || start_m < 0.0) {
    Bad("distance_correction.start_m = " + Num(start_m) + " must be >= 0");
  }
  if (!std::isfinite(step_m) || step_m <= 0.0) {
    Bad("distance_correction.step_m = " + Num(step_m) + " must be > 0");
  }
  if (correction_m.size() < 2 || correction_m.size() > (1u << 20)) {
    Bad("distance_correction.correction_m has " + std::to_string(correction_m.size()) +
        " knots, need 2..2^20");
  }
  for (std::size_t i = 0; i < correction_m.size(); ++i) {
    if (!std::isfinite(correction_m[i])) {
      Bad("distance_correction.correction_m[" + std::to_string(i) + "] is not finite");
    }
  }
}

void NoiseCalibration::Validate() const {
  if (!std::isfinite(delta_l_scale) || delta_l_scale <= 0.0 || delta_l_scale > 1e6) {
    Bad("noise.delta_l_scale = " + Num(delta_l_scale) + " must be in (0, 1e6]");
  }
  if (!std::isfinite(r_squared) || r_squared > 1.0 || r_squared < -1e9) {
    Bad("noise.r_squared = " + Num(r_squared) + " must be finite and <= 1");
  }
  if (frames < 0 || pixels_used < 0) Bad("noise.frames and noise.pixels_used must be >= 0");
}

void OffsetCalibration::Validate() const {
  if (version != kVersion) Bad("version " + std::to_string(version) + " is not supported");
  if (width <= 0 || height <= 0) {
    Bad("size " + std::to_string(width) + "x" + std::to_string(height) + " must be positive");
  }
  if (!std::isfinite(modulation_frequency_hz) || modulation_frequency_hz <= 0.0) {
    Bad("modulation_frequency_hz = " + Num(modulation_frequency_hz) + " must be > 0");
  }
  if (!std::isfinite(integration_time_us) || integration_time_us < 0.0) {
    Bad("integration_time_us = " + Num(integration_time_us) + " must be >= 0");
  }
  if (!std::isfinite(wall_distance_m) || wall_distance_m < 0.0) {
    Bad("wall_distance_m = " + Num(wall_distance_m) + " must be >= 0");
  }
  for (double v : wall_normal) {
    if (!std::isfinite(v)) Bad("wall_normal is not finite");
  }
  if (frames_averaged < 0) Bad("frames_averaged must be >= 0");
  if (!offset_m.SameSize(width, height)) {
    Bad("offset matrix is " + std::to_string(offset_m.width()) + "x" +
        std::to_string(offset_m.height()) + ", header says " + std::to_string(width) + "x" +
        std::to_string(height));
  }
  const double half_range = UnambiguousRangeM(modulation_frequency_hz) / 2.0;
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      const float o = offset_m(r, c);
      if (!std::isfinite(o) || std::abs(o) > half_range) {
        Bad("offset at row " + std::to_string(r) + ", col " + std::to_string(c) + " = " + Num(o) +
            " m is not finite or beyond ±L/2 = " + Num(half_range) + " m");
      }
    }
  }
  if (!pixel_flags.empty() && !pixel_flags.SameSize(width, height)) {
    Bad("pixel_flags size differs from the offset matrix");
  }
  if (distance_correction) distance_correction->Validate();
  if (!std::isfinite(exposure_offset_m_per_ms) || std::abs(exposure_offset_m_per_ms) > 0.1) {
    Bad("exposure_offset_m_per_ms = " + Num(exposure_offset_m_per_ms) +
        " must be finite and within ±0.1 m/ms");
  }
  // The exposure term is s (t - t_cal): without t_cal it would shift every frame by s t.
  if (exposure_offset_m_per_ms != 0.0 && !(integration_time_us > 0.0)) {
    Bad("exposure_offset_m_per_ms = " + Num(exposure_offset_m_per_ms) +
        " needs the calibration's integration_time_us (t_cal), which is " +
        Num(integration_time_us));
  }
  if (noise) noise->Validate();
  if (controller_setpoint) controller_setpoint->Validate();
}

double ExposureShiftM(const OffsetCalibration& calibration, double integration_time_us) noexcept {
  if (!(integration_time_us > 0.0) || !std::isfinite(integration_time_us) ||
      calibration.exposure_offset_m_per_ms == 0.0) {
    return 0.0;
  }
  return calibration.exposure_offset_m_per_ms *
         (integration_time_us - calibration.integration_time_us) * 1e-3;
}

void ApplyCalibrationInPlace(MetricFrame& frame, const OffsetCalibration& calibration) {
  const int w = frame.width();
  const int h = frame.height();
  if (w != calibration.width || h != calibration.height || !calibration.offset_m.SameSize(w, h)) {
    throw Error(ErrorCode::kMismatch, "calibration is " + std::to_string(calibration.width) + "x" +
                                          std::to_string(calibration.height) + ", frame is " +
                                          std::to_string(w) + "x" + std::to_string(h));
  }
  if (!frame.flags.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument, "ApplyCalibration: frame flags differ in size");
  }
  const double f = frame.info.modulation_frequency_hz;
  if (!(std::abs(f - calibration.modulation_frequency_hz) <=
        1e-9 * calibration.modulation_frequency_hz)) {
    throw Error(ErrorCode::kMismatch, "calibration was made at " +
                                          Num(calibration.modulation_frequency_hz) +
                                          " Hz, frame is at " + Num(f) + " Hz");
  }
  const float range = static_cast<float>(UnambiguousRangeM(f));
  // Exposure offset (format v2): a per-frame scalar folded into the constant of eq. 1,
  // l = (m - o - shift + L) mod L. |shift| <= L/4 keeps m - o - shift + L in [L/4, 11L/4), so
  // the two conditional subtractions below stay exact.
  const double shift_m = ExposureShiftM(calibration, frame.info.integration_time_us);
  if (!(std::abs(shift_m) <= 0.25 * range)) {
    throw Error(ErrorCode::kInvalidArgument,
                "calibration: exposure offset " + Num(calibration.exposure_offset_m_per_ms) +
                    " m/ms at " + Num(frame.info.integration_time_us) + " us gives a shift of " +
                    Num(shift_m) + " m, beyond L/4");
  }
  const float bias = static_cast<float>(UnambiguousRangeM(f) - shift_m);
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  float* d = frame.radial_distance_m.data();
  PixelFlags* flags = frame.flags.data();
  const float* o = calibration.offset_m.data();
  // Eq. 1. With m in [0, L) and |o| <= L/2, m - o + L lies in [L/2, 5L/2): at most two
  // subtractions make the mod exact without a division. Branch-free, so it vectorises; kInvalid
  // pixels keep their value.
  for (std::size_t i = 0; i < n; ++i) {
    float l = d[i] - o[i] + bias;
    l -= l >= range ? range : 0.0f;
    l -= l >= range ? range : 0.0f;
    d[i] = flags[i].Has(Flag::kInvalid) ? d[i] : l;
  }
  if (calibration.distance_correction) {
    const DistanceCorrection& g = *calibration.distance_correction;
    // Knots padded with the end values on both sides so every Catmull-Rom segment reads four
    // entries without index clamping; single precision is ample (knots are floats).
    const std::size_t knots = g.correction_m.size();
    std::vector<float> p(knots + 3);
    p[0] = g.correction_m.front();
    std::copy(g.correction_m.begin(), g.correction_m.end(), p.begin() + 1);
    p[knots + 1] = p[knots + 2] = g.correction_m.back();
    // Catmull-Rom weights have an absolute sum of at most 1.25, so |g| <= 1.25 max |knot|; the
    // wrap below needs |g| < L/2.
    float largest = 0.0f;
    for (float v : g.correction_m) largest = std::max(largest, std::abs(v));
    if (!(1.25f * largest < 0.5f * range)) {
      throw Error(ErrorCode::kInvalidArgument, "calibration: distance correction up to " +
                                                   Num(largest) +
                                                   " m is too large for L = " + Num(range) + " m");
    }
    const float start = static_cast<float>(g.start_m);
    const float inv_step = static_cast<float>(1.0 / g.step_m);
    const float last = static_cast<float>(knots - 1);
    const int last_segment = static_cast<int>(knots) - 2;
    for (std::size_t i = 0; i < n; ++i) {
      const float l = d[i];
      const float x = std::clamp((l - start) * inv_step, 0.0f, last);
      const int k = std::min(static_cast<int>(x), last_segment);  // int32: SSE2 converts it
      const float t = x - static_cast<float>(k);
      const float p0 = p[k], p1 = p[k + 1], p2 = p[k + 2], p3 = p[k + 3];
      const float corr = p1 + 0.5f * t *
                                  ((p2 - p0) + t * ((2.0f * p0 - 5.0f * p1 + 4.0f * p2 - p3) +
                                                    t * (3.0f * (p1 - p2) + p3 - p0)));
      // |corr| < L/2 (Validate), so l - corr + L is in (L/2, 3L/2): one subtraction wraps it.
      float v = l - corr + range;
      v -= v >= range ? range : 0.0f;
      d[i] = flags[i].Has(Flag::kInvalid) ? l : v;
    }
  }
  if (!calibration.pixel_flags.empty()) {
    const PixelFlags* pf = calibration.pixel_flags.data();
    for (std::size_t i = 0; i < n; ++i) flags[i] |= pf[i];
  }
}

MetricFrame ApplyCalibration(const MetricFrame& frame, const OffsetCalibration& calibration) {
  MetricFrame out = frame;
  ApplyCalibrationInPlace(out, calibration);
  return out;
}

}  // namespace tofcam
