#include "tofcam/control/integration_time_controller.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "../filters/hot_loop.h"
#include "../filters/simd.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& field, const std::string& value, const std::string& rule) {
  throw Error(ErrorCode::kInvalidArgument,
              "controller option " + field + " = " + value + " " + rule);
}

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// The ROI clipped to the frame, as [row0, row1) x [col0, col1).
struct Rect {
  int row0, row1, col0, col1;
};

Rect Clip(const RegionOfInterest& roi, int width, int height) {
  const bool whole = roi.rows <= 0 || roi.cols <= 0;
  Rect r{whole ? 0 : roi.row, whole ? height : roi.row + roi.rows, whole ? 0 : roi.col,
         whole ? width : roi.col + roi.cols};
  r.row0 = std::clamp(r.row0, 0, height);
  r.row1 = std::clamp(r.row1, r.row0, height);
  r.col0 = std::clamp(r.col0, 0, width);
  r.col1 = std::clamp(r.col1, r.col0, width);
  return r;
}

const Image<float>& ControlChannel(const MetricFrame& frame) {
  return frame.has_intensity() ? frame.intensity : frame.amplitude;
}

// Largest change of the scheduled laws per frame, as a factor on the register: a dark or empty
// frame (Ī near 0) would otherwise ask for an unbounded step.
constexpr double kMaxScheduledFactor = 4.0;

// The register the frame was taken with (the info's, else the controller's last output).
double FrameRegister(const MetricFrame& frame, double fallback) {
  return frame.info.integration_time_register > 0 ? frame.info.integration_time_register : fallback;
}

// V_p,t * D_t of the scheduled gain: loop_gain * c_t * (1 - I_A / Ī_t), limited so that the
// incremental step c_t - V_p D_t stays within [c_t / 4, 4 c_t].
double ScheduledCorrection(const ControllerOptions& o, double mean, double c) {
  const double wanted = o.loop_gain * c * (1.0 - o.target_intensity / std::max(mean, 1e-9));
  return std::clamp(wanted, c * (1.0 - kMaxScheduledFactor), c * (1.0 - 1.0 / kMaxScheduledFactor));
}

int RoundClamp(double c, int lo, int hi) {
  if (!std::isfinite(c)) return c > 0 ? hi : lo;
  return static_cast<int>(
      std::lround(std::clamp(c, static_cast<double>(lo), static_cast<double>(hi))));
}

}  // namespace

std::string_view ControllerKindName(ControllerKind kind) noexcept {
  switch (kind) {
    case ControllerKind::kMayProportional:
      return "may-proportional";
    case ControllerKind::kMayIncremental:
      return "may-incremental";
    case ControllerKind::kVendorHistogram:
      return "vendor-histogram";
    case ControllerKind::kFixed:
      return "fixed";
    case ControllerKind::kModelBased:
      return "model-based";
  }
  return "unknown";
}

ControllerKind ParseControllerKind(std::string_view name) {
  for (ControllerKind k :
       {ControllerKind::kMayProportional, ControllerKind::kMayIncremental,
        ControllerKind::kVendorHistogram, ControllerKind::kFixed, ControllerKind::kModelBased}) {
    if (ControllerKindName(k) == name) return k;
  }
  throw Error(ErrorCode::kInvalidArgument,
              "unknown controller kind '" + std::string(name) +
                  "' (known: may-proportional, may-incremental, vendor-histogram, fixed, "
                  "model-based)");
}

void ControllerOptions::Validate() const {
  if (!std::isfinite(target_intensity) || target_intensity <= 0.0 || target_intensity > 65532.0) {
    Bad("target_intensity (I_A)", Num(target_intensity), "must be in (0, 65532]");
  }
  if (!std::isfinite(gain_register_per_intensity) || gain_register_per_intensity < 0.0 ||
      gain_register_per_intensity > 1.0) {
    Bad("gain_register_per_intensity (V_p)", Num(gain_register_per_intensity),
        "must be in [0, 1] (0 = scheduled)");
  }
  if (!std::isfinite(loop_gain) || loop_gain <= 0.0 || loop_gain > 1.0) {
    Bad("loop_gain", Num(loop_gain), "must be in (0, 1]");
  }
  if (!std::isfinite(frame_rate_hz) || frame_rate_hz < 0.0) {
    Bad("frame_rate_hz", Num(frame_rate_hz), "must be >= 0 (0 = the camera's maximum)");
  }
  if (min_register < 1 || min_register > max_register) {
    Bad("min_register", std::to_string(min_register), "must be in [1, max_register]");
  }
  if (max_register > 65535) Bad("max_register", std::to_string(max_register), "must be <= 65535");
  if (bias_register < min_register || bias_register > max_register) {
    Bad("bias_register (c_0)", std::to_string(bias_register),
        "must be in [min_register, max_register] = [" + std::to_string(min_register) + ", " +
            std::to_string(max_register) + "]");
  }
  if (roi.row < 0 || roi.col < 0 || roi.rows < 0 || roi.cols < 0) {
    Bad("roi",
        std::to_string(roi.row) + "," + std::to_string(roi.col) + "," + std::to_string(roi.rows) +
            "," + std::to_string(roi.cols),
        "must not be negative");
  }
  if (!std::isfinite(percent_over_pos) || percent_over_pos < 0.0 || percent_over_pos >= 100.0) {
    Bad("percent_over_pos", Num(percent_over_pos), "must be in [0, 100)");
  }
  if (desired_pos < 1 || desired_pos > 255) {
    Bad("desired_pos", std::to_string(desired_pos), "must be in [1, 255]");
  }
  if (!std::isfinite(vendor_gain) || vendor_gain <= 0.0 || vendor_gain > 1.0) {
    Bad("vendor_gain", Num(vendor_gain), "must be in (0, 1]");
  }
  auto range = [](double v, double lo, double hi, const char* name, const char* rule) {
    if (!std::isfinite(v) || v < lo || v > hi) Bad(name, Num(v), rule);
  };
  range(max_clipped_fraction, 0.0, 0.5, "max_clipped_fraction", "must be in [0, 0.5]");
  range(model_max_increase, 1.0, 1000.0, "model_max_increase", "must be in [1, 1000]");
  range(model_deadband, 0.0, 0.5, "model_deadband", "must be in [0, 0.5]");
  if (!(model_headroom > 0.0 && model_headroom <= 1.0)) {
    Bad("model_headroom", Num(model_headroom), "must be in (0, 1]");
  }
  if (!(model_backoff > 1.0 && model_backoff <= 1000.0)) {
    Bad("model_backoff", Num(model_backoff), "must be in (1, 1000]");
  }
  if (vendor_max_step_register < 1) {
    Bad("vendor_max_step_register", std::to_string(vendor_max_step_register), "must be >= 1");
  }
  if (vendor_deadband < 0 || vendor_deadband > 254) {
    Bad("vendor_deadband", std::to_string(vendor_deadband), "must be in [0, 254]");
  }
  if (!std::isfinite(clipped_intensity) || clipped_intensity < 0.0 || clipped_intensity > 65532.0) {
    Bad("clipped_intensity", Num(clipped_intensity), "must be in [0, 65532]");
  }
}

// A clipped pixel counts whatever its flags: the SR-2 reports a pixel whose taps all clipped with
// amplitude 0 (no phase, so kInvalid) and intensity at full scale, and those are exactly the
// pixels that must make a controller back off and that make the amplitude maximum of a sweep.
bool CountsForExposure(const MetricFrame& frame, std::size_t i, std::uint16_t exclude_flags,
                       double clipped_intensity) noexcept {
  return frame.flags.empty() || !frame.flags[i].Any(exclude_flags) ||
         (clipped_intensity > 0.0 && frame.has_intensity() &&
          frame.intensity[i] >= clipped_intensity);
}

namespace {

// Eight explicit accumulator lanes: pixel i of a row adds to lane i mod 8 of the row's chunk, the
// lanes are summed in a fixed order at the end. The loop vectorises (GCC will not reorder one
// double accumulator) and the result does not depend on the CPU. For integer-valued channels
// (every register-converted frame) each lane sum is an exact integer below 2^53, so the mean is
// the exact one; for other values it differs from a sequential sum by at most n * 2^-53 of the
// sum of magnitudes (tests/control/integration_time_controller_test.cc).
constexpr int kLanes = 8;
struct MeanLanes {
  double sum[kLanes] = {};
  std::int64_t count[kLanes] = {};
};

// A pixel counts when it has no `exclude` bit or its value reaches `clipped` (+inf: never),
// and its value is finite (|x| <= FLT_MAX, as an integer compare of the bits: false for NaN).
TOFCAM_HOT_LOOP void MeanRow(std::size_t n, const float* __restrict v,
                             const PixelFlags* __restrict f, std::uint16_t exclude, float clipped,
                             MeanLanes& lanes) {
  using namespace simd;
  constexpr std::int32_t kMaxBits = 0x7f7fffff;  // FLT_MAX
  D4 sum_lo = {lanes.sum[0], lanes.sum[1], lanes.sum[2], lanes.sum[3]};
  D4 sum_hi = {lanes.sum[4], lanes.sum[5], lanes.sum[6], lanes.sum[7]};
  I8 count = {};
  std::size_t i = 0;
  for (; i + kLanes <= n; i += kLanes) {
    const F8 x = LoadF8(v + i);
    const I8 ok =
        (((LoadFlags8(f + i) & exclude) == 0) | (x >= clipped)) & (AbsBits(x) <= kMaxBits);
    const F8 kept = Select(ok, x);
    sum_lo += Low(kept);
    sum_hi += High(kept);
    count -= ok;  // masks are -1
  }
  for (int j = 0; j < kLanes; ++j) {
    lanes.sum[j] = j < 4 ? sum_lo[j] : sum_hi[j - 4];
    lanes.count[j] += count[j];
  }
  for (int j = 0; i < n; ++i, ++j) {
    const float x = v[i];
    const bool ok = (((f[i].bits() & exclude) == 0) | (x >= clipped)) &
                    (std::abs(x) <= std::numeric_limits<float>::max());
    lanes.sum[j] += ok ? static_cast<double>(x) : 0.0;
    lanes.count[j] += ok ? 1 : 0;
  }
}

}  // namespace

double MeanControlIntensity(const MetricFrame& frame, const RegionOfInterest& roi,
                            std::uint16_t exclude_flags, double clipped_intensity) {
  const Image<float>& channel = ControlChannel(frame);
  const Rect r = Clip(roi, channel.width(), channel.height());
  // Without (usable) flags every pixel counts; the clipped clause reads the intensity, which is
  // the control channel whenever there is one.
  const bool flags_ok = !frame.flags.empty() && frame.flags.SameSize(channel);
  const std::uint16_t exclude = flags_ok ? exclude_flags : 0;
  // The smallest float >= the threshold: for a float x, x >= clipped_intensity (in double) holds
  // exactly when x >= this.
  float clipped = std::numeric_limits<float>::infinity();
  if (clipped_intensity > 0.0 && frame.has_intensity()) {
    clipped = static_cast<float>(clipped_intensity);
    if (static_cast<double>(clipped) < clipped_intensity) {
      clipped = std::nextafter(clipped, std::numeric_limits<float>::infinity());
    }
  }
  thread_local std::vector<PixelFlags> no_flags;
  const std::size_t cols = static_cast<std::size_t>(r.col1 - r.col0);
  if (!flags_ok && no_flags.size() < cols) no_flags.resize(cols);
  MeanLanes lanes;
  for (int row = r.row0; row < r.row1; ++row) {
    const std::size_t base = static_cast<std::size_t>(row) * channel.width() + r.col0;
    MeanRow(cols, channel.data() + base, flags_ok ? frame.flags.data() + base : no_flags.data(),
            exclude, clipped, lanes);
  }
  double sum = 0.0;
  std::int64_t count = 0;
  for (int j = 0; j < kLanes; ++j) {
    sum += lanes.sum[j];
    count += lanes.count[j];
  }
  return count == 0 ? std::numeric_limits<double>::quiet_NaN() : sum / static_cast<double>(count);
}

// --- MayProportional -------------------------------------------------------------------------

MayProportional::MayProportional(const ControllerOptions& options)
    : options_(options), last_register_(options.bias_register) {
  options_.Validate();
}

int MayProportional::Update(const MetricFrame& frame) {
  const double mean = ControlledMeanIntensity(frame, options_);
  if (std::isnan(mean)) return last_register_;
  const double deviation = mean - options_.target_intensity;  // D_t
  const double correction =
      options_.gain_register_per_intensity > 0.0
          ? options_.gain_register_per_intensity * deviation
          : ScheduledCorrection(options_, mean, FrameRegister(frame, last_register_));
  last_register_ =
      RoundClamp(options_.bias_register - correction, options_.min_register, options_.max_register);
  return last_register_;
}

std::string_view MayProportional::Name() const {
  return ControllerKindName(ControllerKind::kMayProportional);
}

void MayProportional::Reset(int current_register) {
  last_register_ = std::clamp(current_register, options_.min_register, options_.max_register);
}

double ControlledMeanIntensity(const MetricFrame& frame, const ControllerOptions& options) {
  return MeanControlIntensity(frame, options.roi, options.exclude_flags, options.clipped_intensity);
}

int MaxRegisterForFrameRate(const CameraInfo& camera, double frame_rate_hz) {
  if (!std::isfinite(frame_rate_hz) || frame_rate_hz <= 0.0) {
    throw Error(ErrorCode::kInvalidArgument,
                "frame rate " + Num(frame_rate_hz) + " Hz must be positive and finite");
  }
  const double budget_us = 1e6 / frame_rate_hz - camera.readout_time_us;
  const auto fits = [&](int reg) { return camera.IntegrationTimeUs(reg) <= budget_us + 1e-9; };
  if (!fits(camera.min_integration_register)) {
    throw Error(ErrorCode::kInvalidArgument,
                "frame rate " + Num(frame_rate_hz) + " Hz is out of reach for " + camera.model +
                    ": its shortest frame takes " +
                    Num((camera.IntegrationTimeUs(camera.min_integration_register) +
                         camera.readout_time_us) *
                        1e-3) +
                    " ms");
  }
  if (camera.integration_time_step_us <= 0.0) return camera.max_integration_register;
  const double reg = std::floor(
      (budget_us - camera.integration_time_base_us) / camera.integration_time_step_us + 1e-9);
  return static_cast<int>(std::clamp(reg, static_cast<double>(camera.min_integration_register),
                                     static_cast<double>(camera.max_integration_register)));
}

// --- MayIncremental --------------------------------------------------------------------------

MayIncremental::MayIncremental(const ControllerOptions& options)
    : options_(options), state_(options.bias_register) {
  options_.Validate();
}

int MayIncremental::Update(const MetricFrame& frame) {
  const double mean = ControlledMeanIntensity(frame, options_);
  if (!std::isnan(mean)) {
    // The scheduled gain uses the real-valued state as c_t: the frame's register is its rounding.
    state_ -= options_.gain_register_per_intensity > 0.0
                  ? options_.gain_register_per_intensity * (mean - options_.target_intensity)
                  : ScheduledCorrection(options_, mean, state_);
    state_ = std::clamp(state_, static_cast<double>(options_.min_register),
                        static_cast<double>(options_.max_register));
  }
  return RoundClamp(state_, options_.min_register, options_.max_register);
}

std::string_view MayIncremental::Name() const {
  return ControllerKindName(ControllerKind::kMayIncremental);
}

void MayIncremental::Reset(int current_register) {
  state_ = std::clamp(current_register, options_.min_register, options_.max_register);
}

// --- ModelBased ------------------------------------------------------------------------------

ModelBased::ModelBased(const ControllerOptions& options)
    : options_(options), state_(options.bias_register) {
  options_.Validate();
}

int ModelBased::Update(const MetricFrame& frame) {
  const int w = frame.width(), h = frame.height();
  const Rect r = Clip(options_.roi, w, h);
  const bool intensity = frame.has_intensity();
  const double clip =
      options_.clipped_intensity > 0.0 ? options_.clipped_intensity : kDefaultClippedIntensity;
  constexpr std::uint16_t kSaturatedBit = static_cast<std::uint16_t>(Flag::kSaturated);
  peaks_.clear();
  std::size_t clipped = 0;
  for (int row = r.row0; row < r.row1; ++row) {
    for (int col = r.col0; col < r.col1; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * static_cast<std::size_t>(w) +
                            static_cast<std::size_t>(col);
      if (!CountsForExposure(frame, i, options_.exclude_flags, options_.clipped_intensity)) {
        continue;
      }
      const float a = frame.amplitude[i];
      const float peak = intensity ? frame.intensity[i] + a : a;
      // A pixel at full scale now has no measured brightness, only a lower bound.
      const bool at_scale = peak >= clip || (intensity && frame.intensity[i] >= clip) ||
                            (!frame.flags.empty() && frame.flags[i].Any(kSaturatedBit));
      if (at_scale) {
        ++clipped;
      } else if (std::isfinite(peak)) {
        peaks_.push_back(std::max(peak, 0.0f));
      }
    }
  }
  const std::size_t n = peaks_.size() + clipped;
  if (n == 0) return RoundClamp(state_, options_.min_register, options_.max_register);
  const double c = FrameRegister(frame, state_);
  last_clipped_fraction_ = static_cast<double>(clipped) / static_cast<double>(n);
  double next = c;
  if (last_clipped_fraction_ > options_.max_clipped_fraction) {
    // Few clipped pixels (at most 5x the allowed fraction) are mostly a scene that brightened a
    // little since the frame the register was chosen on: halve. Many: back off hard.
    const bool few = last_clipped_fraction_ <= 5.0 * options_.max_clipped_fraction;
    next = c / (few ? std::min(2.0, options_.model_backoff) : options_.model_backoff);
  } else {
    // The q-quantile over all n pixels, the clipped ones counting as the brightest: the pixel of
    // rank ceil(q n) among the unclipped ones, which all lie below the clipped.
    const double q = 1.0 - options_.max_clipped_fraction;
    std::size_t k = static_cast<std::size_t>(std::ceil(q * static_cast<double>(n)));
    k = std::clamp<std::size_t>(k, 1, n) - 1;
    double peak_q;
    if (k >= peaks_.size()) {
      peak_q = clip;  // the quantile is a clipped pixel: hold
    } else {
      std::nth_element(peaks_.begin(), peaks_.begin() + static_cast<std::ptrdiff_t>(k),
                       peaks_.end());
      peak_q = peaks_[k];
    }
    const double wanted = peak_q > 0.0 ? c * options_.model_headroom * clip / peak_q
                                       : c * options_.model_max_increase;
    next = std::min(wanted, c * options_.model_max_increase);
    if (std::abs(next - c) <= options_.model_deadband * c) next = c;
  }
  state_ = std::clamp(next, static_cast<double>(options_.min_register),
                      static_cast<double>(options_.max_register));
  return RoundClamp(state_, options_.min_register, options_.max_register);
}

std::string_view ModelBased::Name() const {
  return ControllerKindName(ControllerKind::kModelBased);
}

void ModelBased::Reset(int current_register) {
  state_ = std::clamp(current_register, options_.min_register, options_.max_register);
  last_clipped_fraction_ = 0.0;
}

// --- VendorHistogram -------------------------------------------------------------------------

VendorHistogram::VendorHistogram(const ControllerOptions& options)
    : options_(options), state_(options.bias_register) {
  options_.Validate();
}

int VendorHistogram::Update(const MetricFrame& frame) {
  const Image<float>& channel = ControlChannel(frame);
  const Rect r = Clip(options_.roi, channel.width(), channel.height());
  const bool flags_ok = frame.flags.empty() || frame.flags.SameSize(channel);
  std::array<std::size_t, 256> histogram{};
  std::size_t count = 0;
  for (int row = r.row0; row < r.row1; ++row) {
    const std::size_t base = static_cast<std::size_t>(row) * channel.width();
    for (int col = r.col0; col < r.col1; ++col) {
      const std::size_t i = base + col;
      if (flags_ok &&
          !CountsForExposure(frame, i, options_.exclude_flags, options_.clipped_intensity)) {
        continue;
      }
      const float v = channel[i];
      if (!(v >= 0.0f)) continue;  // NaN and negatives carry no exposure information
      const auto bin = static_cast<std::size_t>(std::min(v, 65535.0f)) >> 8;
      ++histogram[bin];
      ++count;
    }
  }
  const int current = RoundClamp(state_, options_.min_register, options_.max_register);
  if (count == 0) {
    last_position_ = -1;
    return current;
  }
  // x: smallest value with at most percent_over_pos % of the pixels strictly above it.
  const double allowed_above = options_.percent_over_pos / 100.0 * static_cast<double>(count);
  std::size_t above = count;
  int x = 0;
  for (; x < 256; ++x) {
    above -= histogram[static_cast<std::size_t>(x)];
    if (static_cast<double>(above) <= allowed_above) break;
  }
  last_position_ = x;
  if (std::abs(x - options_.desired_pos) <= options_.vendor_deadband) return current;
  const double ratio = static_cast<double>(options_.desired_pos) / std::max(x, 1);
  double step = state_ * options_.vendor_gain * (ratio - 1.0);
  step = std::clamp(step, -static_cast<double>(options_.vendor_max_step_register),
                    static_cast<double>(options_.vendor_max_step_register));
  state_ = std::clamp(state_ + step, static_cast<double>(options_.min_register),
                      static_cast<double>(options_.max_register));
  return RoundClamp(state_, options_.min_register, options_.max_register);
}

std::string_view VendorHistogram::Name() const {
  return ControllerKindName(ControllerKind::kVendorHistogram);
}

void VendorHistogram::Reset(int current_register) {
  state_ = std::clamp(current_register, options_.min_register, options_.max_register);
  last_position_ = -1;
}

// --- Fixed -----------------------------------------------------------------------------------

Fixed::Fixed(const ControllerOptions& options) : register_(options.bias_register) {
  options.Validate();
}

int Fixed::Update(const MetricFrame& /*frame*/) { return register_; }

std::string_view Fixed::Name() const { return ControllerKindName(ControllerKind::kFixed); }

void Fixed::Reset(int /*current_register*/) {}

// --- Set point from an integration-time sweep ------------------------------------------------

void SetpointOptions::Validate() const {
  if (!(target_fraction > 0.0 && target_fraction <= 1.0)) {
    Bad("setpoint target_fraction", Num(target_fraction), "must be in (0, 1]");
  }
  if (!(plateau_tolerance >= 0.0 && plateau_tolerance <= 0.5)) {
    Bad("setpoint plateau_tolerance", Num(plateau_tolerance), "must be in [0, 0.5]");
  }
  if (!(max_loop_gain > 0.0 && max_loop_gain < 1.0)) {
    Bad("setpoint max_loop_gain", Num(max_loop_gain), "must be in (0, 1)");
  }
  if (!(saturated_intensity > 0.0 && saturated_intensity <= 65532.0)) {
    Bad("setpoint saturated_intensity", Num(saturated_intensity), "must be in (0, 65532]");
  }
  if (min_register < 1 || min_register > max_register || max_register > 65535) {
    Bad("setpoint registers", std::to_string(min_register) + ".." + std::to_string(max_register),
        "must satisfy 1 <= min <= max <= 65535");
  }
}

void ControllerSetpoint::Validate() const {
  if (!(target_intensity > 0.0 && target_intensity <= 65532.0)) {
    Bad("setpoint target_intensity", Num(target_intensity), "must be in (0, 65532]");
  }
  if (bias_register < 1 || bias_register > 65535) {
    Bad("setpoint bias_register", std::to_string(bias_register), "must be in [1, 65535]");
  }
  if (!(gain_register_per_intensity >= 0.0 && gain_register_per_intensity <= 1.0)) {
    Bad("setpoint gain_register_per_intensity", Num(gain_register_per_intensity),
        "must be in [0, 1]");
  }
  if (amplitude_max_register < 0 || amplitude_max_register > 65535) {
    Bad("setpoint amplitude_max_register", std::to_string(amplitude_max_register),
        "must be in [0, 65535]");
  }
  if (!std::isfinite(amplitude_max_intensity) || amplitude_max_intensity < 0.0) {
    Bad("setpoint amplitude_max_intensity", Num(amplitude_max_intensity), "must be >= 0");
  }
  if (!std::isfinite(intensity_per_register)) {
    Bad("setpoint intensity_per_register", Num(intensity_per_register), "must be finite");
  }
}

ControllerOptions ControllerSetpoint::Apply(ControllerOptions base) const {
  base.kind = ControllerKind::kMayProportional;
  base.target_intensity = target_intensity;
  base.gain_register_per_intensity = gain_register_per_intensity;
  base.bias_register = std::clamp(bias_register, base.min_register, base.max_register);
  return base;
}

ControllerSetpoint ChooseSetpoint(std::span<const IntegrationSweepPoint> sweep,
                                  const SetpointOptions& options) {
  options.Validate();
  if (sweep.size() < 3) {
    Bad("setpoint sweep", std::to_string(sweep.size()) + " points", "needs at least 3");
  }
  for (std::size_t k = 0; k < sweep.size(); ++k) {
    const IntegrationSweepPoint& p = sweep[k];
    if (p.integration_register < 1 ||
        (k > 0 && p.integration_register <= sweep[k - 1].integration_register)) {
      Bad("setpoint sweep register", std::to_string(p.integration_register),
          "must be >= 1 and strictly increasing");
    }
    for (const auto& [name, value] : {std::pair<const char*, double>{"intensity", p.mean_intensity},
                                      {"amplitude", p.mean_amplitude}}) {
      if (!(value >= 0.0) || !std::isfinite(value)) {
        Bad(std::string("setpoint sweep mean ") + name + " at register " +
                std::to_string(p.integration_register),
            Num(value), "must be finite and >= 0");
      }
    }
  }
  std::size_t best = 0;
  for (std::size_t k = 1; k < sweep.size(); ++k) {
    if (sweep[k].mean_amplitude > sweep[best].mean_amplitude) best = k;
  }
  const double plateau = (1.0 - options.plateau_tolerance) * sweep[best].mean_amplitude;
  for (std::size_t k = 0; k < best; ++k) {
    if (sweep[k].mean_amplitude >= plateau) {
      best = k;
      break;
    }
  }
  ControllerSetpoint s;
  s.amplitude_max_register = sweep[best].integration_register;
  s.amplitude_max_intensity = sweep[best].mean_intensity;
  s.target_intensity = std::clamp(options.target_fraction * s.amplitude_max_intensity, 1.0,
                                  static_cast<double>(kMaxSignalRegister));
  // c_0: where the (rising) intensity curve crosses I_A at or below the amplitude maximum.
  // No crossing happens only when even the lowest register gives more than I_A (I_A lies below
  // the intensity at the maximum, which the curve reaches): c_0 stays at the lowest register.
  double c0 = sweep.front().integration_register;
  std::size_t seg = 0;  // segment [seg, seg + 1] used for the slope
  for (std::size_t k = 1; k <= best; ++k) {
    const IntegrationSweepPoint& a = sweep[k - 1];
    const IntegrationSweepPoint& b = sweep[k];
    if (a.mean_intensity <= s.target_intensity && b.mean_intensity >= s.target_intensity) {
      const double span = b.mean_intensity - a.mean_intensity;
      const double t = span > 0.0 ? (s.target_intensity - a.mean_intensity) / span : 0.0;
      c0 = a.integration_register + t * (b.integration_register - a.integration_register);
      seg = k - 1;
      break;
    }
  }
  s.bias_register =
      std::clamp(static_cast<int>(std::lround(c0)), options.min_register, options.max_register);
  const IntegrationSweepPoint& a = sweep[seg];
  const IntegrationSweepPoint& b = sweep[std::min(seg + 1, sweep.size() - 1)];
  s.intensity_per_register = b.integration_register > a.integration_register
                                 ? (b.mean_intensity - a.mean_intensity) /
                                       (b.integration_register - a.integration_register)
                                 : 0.0;
  // V_p spans the register range below c_0 over the intensities above I_A (a saturated image
  // drives the register to its minimum), unless that makes the loop gain at c_0 too high.
  double vp = options.saturated_intensity > s.target_intensity
                  ? (s.bias_register - options.min_register) /
                        (options.saturated_intensity - s.target_intensity)
                  : 0.0;
  if (s.intensity_per_register > 0.0) {
    vp = std::min(vp, options.max_loop_gain / s.intensity_per_register);
  }
  s.gain_register_per_intensity = std::clamp(vp, 0.0, 1.0);
  return s;
}

std::unique_ptr<IntegrationTimeController> MakeController(const ControllerOptions& options) {
  options.Validate();
  switch (options.kind) {
    case ControllerKind::kMayProportional:
      return std::make_unique<MayProportional>(options);
    case ControllerKind::kMayIncremental:
      return std::make_unique<MayIncremental>(options);
    case ControllerKind::kVendorHistogram:
      return std::make_unique<VendorHistogram>(options);
    case ControllerKind::kFixed:
      return std::make_unique<Fixed>(options);
    case ControllerKind::kModelBased:
      return std::make_unique<ModelBased>(options);
  }
  throw Error(ErrorCode::kInvalidArgument, "controller option kind is not a known kind");
}

}  // namespace tofcam
