#include "tofcam/calibration/calibration_procedure.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <ctime>
#include <deque>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {
namespace {

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

[[noreturn]] void Bad(const std::string& field, double value, const std::string& rule) {
  throw Error(ErrorCode::kInvalidArgument,
              "calibration option " + field + " = " + Num(value) + " " + rule);
}

// Wraps x into [-range/2, range/2).
double WrapSigned(double x, double range) { return x - range * std::floor(x / range + 0.5); }

void Report(const ProgressCallback& progress, std::string_view phase, int frame, int total,
            std::string message) {
  if (progress) progress(CalibrationProgress{phase, frame, total, std::move(message)});
}

MetricFrame GrabMetric(Camera& camera) {
  std::optional<Frame> frame = camera.Grab();
  if (!frame) throw Error(ErrorCode::kIo, "calibration: the camera stopped delivering frames");
  return ConvertToMetric(*frame);
}

// Per-pixel circular mean of the distance over several frames.
class PhasorAverage {
 public:
  PhasorAverage(int width, int height, double range_m)
      : width_(width),
        height_(height),
        range_m_(range_m),
        cos_(static_cast<std::size_t>(width) * height, 0.0),
        sin_(cos_.size(), 0.0),
        count_(cos_.size(), 0) {}

  void Add(const MetricFrame& frame) {
    const double to_rad = 2.0 * kPi / range_m_;
    for (std::size_t i = 0; i < cos_.size(); ++i) {
      if (!frame.flags[i].Valid()) continue;
      const double phi = frame.radial_distance_m[i] * to_rad;
      cos_[i] += std::cos(phi);
      sin_[i] += std::sin(phi);
      ++count_[i];
    }
    ++frames_;
  }

  [[nodiscard]] int frames() const { return frames_; }
  [[nodiscard]] int count(std::size_t i) const { return count_[i]; }
  /// Circular mean distance in [0, L).
  [[nodiscard]] double Mean(std::size_t i) const {
    double d = std::atan2(sin_[i], cos_[i]) * range_m_ / (2.0 * kPi);
    if (d < 0.0) d += range_m_;
    return d;
  }
  /// Circular standard deviation of one sample, m.
  [[nodiscard]] double Sigma(std::size_t i) const {
    if (count_[i] < 2) return 0.0;
    const double r = std::hypot(cos_[i], sin_[i]) / count_[i];
    return range_m_ / (2.0 * kPi) * std::sqrt(std::max(0.0, -2.0 * std::log(std::min(r, 1.0))));
  }
  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }

 private:
  int width_, height_;
  double range_m_;
  std::vector<double> cos_, sin_;
  std::vector<int> count_;
  int frames_ = 0;
};

void CheckCameraSize(const MetricFrame& frame, const CameraInfo& info) {
  if (frame.width() != info.width() || frame.height() != info.height()) {
    throw Error(ErrorCode::kMismatch,
                "calibration: camera delivers " + std::to_string(frame.width()) + "x" +
                    std::to_string(frame.height()) + " frames, its info says " +
                    std::to_string(info.width()) + "x" + std::to_string(info.height()));
  }
}

// Runs the controller until the register is stable; returns the frames used.
int SettleExposure(Camera& camera, const WallCalibrationOptions& o,
                   const ProgressCallback& progress) {
  std::unique_ptr<IntegrationTimeController> controller = MakeController(o.controller);
  controller->Reset(camera.IntegrationTimeRegister());
  int stable = 0;
  for (int n = 1; n <= o.controller_max_frames; ++n) {
    const MetricFrame frame = GrabMetric(camera);
    CheckCameraSize(frame, camera.Info());
    const int used = frame.info.integration_time_register > 0 ? frame.info.integration_time_register
                                                              : camera.IntegrationTimeRegister();
    const int next = controller->Update(frame);
    stable = std::abs(next - used) <= 1 ? stable + 1 : 0;
    camera.SetIntegrationTimeRegister(next);
    if (n % 10 == 0 || stable >= o.controller_settle_frames) {
      Report(progress, "exposure", n, o.controller_max_frames,
             "integration-time register " + std::to_string(next));
    }
    if (stable >= o.controller_settle_frames) return n;
  }
  throw Error(ErrorCode::kInvalidArgument,
              "calibration: the integration-time controller (" + std::string(controller->Name()) +
                  ") did not settle within " + std::to_string(o.controller_max_frames) +
                  " frames; lower its gain (V_p) or raise controller_max_frames");
}

// Least-squares slope of y over t.
double Slope(const std::deque<std::pair<double, double>>& samples) {
  double mt = 0.0, my = 0.0;
  for (const auto& [t, y] : samples) {
    mt += t;
    my += y;
  }
  mt /= static_cast<double>(samples.size());
  my /= static_cast<double>(samples.size());
  double num = 0.0, den = 0.0;
  for (const auto& [t, y] : samples) {
    num += (t - mt) * (y - my);
    den += (t - mt) * (t - mt);
  }
  return den > 0.0 ? num / den : 0.0;
}

// Discards frames until the drift of the mean distance settles; returns frames used and rate.
std::pair<int, double> WaitForWarmup(Camera& camera, const WallCalibrationOptions& o,
                                     const ProgressCallback& progress) {
  const double range_m = camera.Info().unambiguous_range_m();
  const double frame_period_s =
      camera.Info().max_frame_rate_hz > 0.0 ? 1.0 / camera.Info().max_frame_rate_hz : 1.0 / 30;
  std::deque<std::pair<double, double>> window;
  MetricFrame reference;
  double last_time = -std::numeric_limits<double>::infinity();
  double slope = 0.0;
  for (int n = 1; n <= o.warmup_max_frames; ++n) {
    MetricFrame frame = GrabMetric(camera);
    CheckCameraSize(frame, camera.Info());
    if (n == 1) reference = frame;
    // Mean change against the first frame, wrapped per pixel: immune to the 0 / L seam.
    double sum = 0.0;
    std::size_t count = 0;
    const std::size_t pixels = frame.radial_distance_m.size();
    for (std::size_t i = 0; i < pixels; ++i) {
      if (!frame.flags[i].Valid() || !reference.flags[i].Valid()) continue;
      sum += WrapSigned(
          static_cast<double>(frame.radial_distance_m[i]) - reference.radial_distance_m[i],
          range_m);
      ++count;
    }
    // Frame times from the timestamps; a source without them gets its nominal frame rate.
    double t = static_cast<double>(frame.info.timestamp_ns) * 1e-9;
    if (!(t > last_time)) t = std::max(last_time, 0.0) + frame_period_s;
    last_time = t;
    if (count > 0) window.emplace_back(t, sum / static_cast<double>(count));
    while (static_cast<int>(window.size()) > o.warmup_window_frames) window.pop_front();
    if (static_cast<int>(window.size()) == o.warmup_window_frames) {
      slope = Slope(window);
      if (std::abs(slope) <= o.warmup_max_drift_m_per_s) {
        Report(progress, "warm-up", n, o.warmup_max_frames,
               "drift " + Num(slope * 1e3) + " mm/s: settled");
        return {n, slope};
      }
    }
    if (n % 50 == 0) {
      const bool full = static_cast<int>(window.size()) == o.warmup_window_frames;
      Report(
          progress, "warm-up", n, o.warmup_max_frames,
          full ? "drift " + Num(slope * 1e3) +
                     " mm/s (need <= " + Num(o.warmup_max_drift_m_per_s * 1e3) + ")"
               : "measuring the drift over " + std::to_string(o.warmup_window_frames) + " frames");
    }
  }
  throw Error(ErrorCode::kInvalidArgument,
              "calibration: the distance still drifts by " + Num(slope * 1e3) + " mm/s after " +
                  std::to_string(o.warmup_max_frames) +
                  " warm-up frames (limit warmup_max_drift_m_per_s = " +
                  Num(o.warmup_max_drift_m_per_s * 1e3) + " mm/s)");
}

PhasorAverage AverageFrames(Camera& camera, int frames, std::string_view phase,
                            const ProgressCallback& progress) {
  const CameraInfo& info = camera.Info();
  PhasorAverage average(info.width(), info.height(), info.unambiguous_range_m());
  for (int n = 1; n <= frames; ++n) {
    const MetricFrame frame = GrabMetric(camera);
    CheckCameraSize(frame, info);
    average.Add(frame);
    if (n % 10 == 0 || n == frames) {
      Report(progress, phase, n, frames, "averaged " + std::to_string(n) + " frames");
    }
  }
  return average;
}

Eigen::Vector3d UnitNormal(const std::array<double, 3>& n) {
  return Eigen::Vector3d(n[0], n[1], n[2]).normalized();
}

void ValidateNormal(const std::array<double, 3>& n) {
  const double norm = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (!std::isfinite(norm) || norm <= 0.0 || !(n[2] / norm > 0.05)) {
    throw Error(ErrorCode::kInvalidArgument, "calibration option wall_normal = (" + Num(n[0]) +
                                                 ", " + Num(n[1]) + ", " + Num(n[2]) +
                                                 ") must be finite and point forward (z > 0)");
  }
}

// The exposure offset: the wall at several registers, one frame per register in turn, so that a
// drift left after the warm-up shifts every register's average alike. Returns s in m/ms and
// fills the exposure part of the report. `calibrated` marks the pixels of the offset matrix.
double MeasureExposureOffset(Camera& camera, const WallCalibrationOptions& o,
                             const Image<PixelFlags>& uncalibrated,
                             const ProgressCallback& progress, WallCalibrationReport& r) {
  const CameraInfo& info = camera.Info();
  const int base = camera.IntegrationTimeRegister();
  std::vector<int> registers = {base};
  for (double f : o.exposure_offset_fractions) {
    const int reg = static_cast<int>(std::clamp(std::lround(base * f),
                                                static_cast<long>(info.min_integration_register),
                                                static_cast<long>(info.max_integration_register)));
    if (std::find(registers.begin(), registers.end(), reg) == registers.end()) {
      registers.push_back(reg);
    }
  }
  r.exposure_registers = registers;
  r.exposure_shift_m.assign(registers.size(), 0.0);
  if (registers.size() < 2) return 0.0;
  const double range_m = info.unambiguous_range_m();
  std::vector<PhasorAverage> averages(registers.size(),
                                      PhasorAverage(info.width(), info.height(), range_m));
  std::vector<double> times_ms(registers.size(), 0.0);
  for (int n = 1; n <= o.exposure_offset_frames; ++n) {
    for (std::size_t k = 0; k < registers.size(); ++k) {
      camera.SetIntegrationTimeRegister(registers[k]);
      const MetricFrame frame = GrabMetric(camera);
      CheckCameraSize(frame, info);
      // A camera may deliver one more frame at the old setting: bin the frame by the register
      // it reports it was taken at, by the one just set when it reports none.
      std::size_t bin = k;
      const auto reported =
          std::find(registers.begin(), registers.end(), frame.info.integration_time_register);
      if (frame.info.integration_time_register > 0 && reported != registers.end()) {
        bin = static_cast<std::size_t>(reported - registers.begin());
      }
      // The frame's own integration time where the source reports it (that is what eq. 1 will
      // be given later), the camera's register formula otherwise.
      times_ms[bin] =
          (frame.info.integration_time_us > 0.0 ? frame.info.integration_time_us
                                                : info.IntegrationTimeUs(registers[bin])) *
          1e-3;
      averages[bin].Add(frame);
    }
    if (n % 10 == 0 || n == o.exposure_offset_frames) {
      Report(progress, "exposure-offset", n, o.exposure_offset_frames,
             "averaged " + std::to_string(n) + " frames at each of " +
                 std::to_string(registers.size()) + " integration times");
    }
  }
  camera.SetIntegrationTimeRegister(base);

  // Per pixel: shifts against the calibration register (wrapped, seam-safe) and the pixel's own
  // least-squares slope; globally: the mean shift per register and the slope through them.
  const int min_count =
      std::max(1, static_cast<int>(std::ceil(o.min_valid_fraction * o.exposure_offset_frames)));
  const std::size_t regs = registers.size();
  double mean_t = 0.0;
  for (double t : times_ms) mean_t += t / static_cast<double>(regs);
  double stt = 0.0;
  for (double t : times_ms) stt += (t - mean_t) * (t - mean_t);
  if (!(stt > 0.0)) return 0.0;
  std::vector<double> shift_sum(regs, 0.0);
  double slope_sum = 0.0, slope_sq = 0.0, noise_var = 0.0;
  int used = 0;
  const std::size_t pixels = uncalibrated.size();
  for (std::size_t i = 0; i < pixels; ++i) {
    if (uncalibrated[i].Has(Flag::kInvalid)) continue;
    bool ok = true;
    for (const PhasorAverage& a : averages) ok = ok && a.count(i) >= min_count;
    if (!ok) continue;
    const double ref = averages[0].Mean(i);
    double sty = 0.0, var = 0.0;
    for (std::size_t k = 0; k < regs; ++k) {
      const double y = WrapSigned(averages[k].Mean(i) - ref, range_m);
      shift_sum[k] += y;
      sty += (times_ms[k] - mean_t) * y;
      const double sigma = averages[k].Sigma(i);
      var += (times_ms[k] - mean_t) * (times_ms[k] - mean_t) * sigma * sigma / averages[k].count(i);
    }
    const double slope = sty / stt;
    slope_sum += slope;
    slope_sq += slope * slope;
    noise_var += var / (stt * stt);
    ++used;
  }
  r.exposure_pixels = used;
  if (used < 2) return 0.0;
  double sty = 0.0;
  for (std::size_t k = 0; k < regs; ++k) {
    r.exposure_shift_m[k] = shift_sum[k] / used;
    sty += (times_ms[k] - mean_t) * r.exposure_shift_m[k];
  }
  const double s = sty / stt;  // equals the mean of the per-pixel slopes
  // Fail here, not when the file is saved after the rest of the run: a shift of more than 0.1 m
  // per ms is not an exposure offset but a camera or scene that changed between the registers.
  if (!(std::abs(s) <= 0.1)) {
    throw Error(ErrorCode::kMismatch,
                "calibration: the wall moved by " + Num(s * 1e3) +
                    " mm per ms of integration time between registers; an exposure offset is "
                    "at most 100 mm/ms (did the camera or the wall move?)");
  }
  r.exposure_offset_m_per_ms = s;
  r.exposure_pixel_slope_sd_m_per_ms =
      std::sqrt(std::max(0.0, (slope_sq - slope_sum * slope_sum / used) / (used - 1)));
  r.exposure_pixel_slope_noise_m_per_ms = std::sqrt(noise_var / used);
  Report(progress, "exposure-offset", o.exposure_offset_frames, o.exposure_offset_frames,
         "exposure offset " + Num(s * 1e3) + " mm per ms of integration time (per-pixel spread " +
             Num(r.exposure_pixel_slope_sd_m_per_ms * 1e3) + " mm/ms, noise alone " +
             Num(r.exposure_pixel_slope_noise_m_per_ms * 1e3) + ")");
  return s;
}

}  // namespace

ControllerOptions DefaultCalibrationController() {
  ControllerOptions c;
  // The multiplicative vendor law is scale-free: it converges whatever the intensity per
  // register step is, which varies 200-fold between a wall at 0.5 m and one at 7 m. Its median
  // set point (50 % over position 62, i.e. 62 * 256 = 15872) is the paper's I_A = 16000 for the
  // mean of a uniformly lit wall.
  c.kind = ControllerKind::kVendorHistogram;
  c.percent_over_pos = 50.0;
  c.desired_pos = 62;
  c.vendor_gain = 0.5;
  c.vendor_deadband = 2;
  c.vendor_max_step_register = 50;
  c.target_intensity = 16000.0;
  c.bias_register = 20;
  return c;
}

void WallCalibrationOptions::Validate() const {
  if (!std::isfinite(wall_distance_m) || wall_distance_m <= 0.0) {
    Bad("wall_distance_m", wall_distance_m, "must be > 0");
  }
  ValidateNormal(wall_normal);
  if (frames < 1 || frames > 100000) Bad("frames", frames, "must be in [1, 100000]");
  controller.Validate();
  if (controller_settle_frames < 1 || controller_settle_frames > 1000) {
    Bad("controller_settle_frames", controller_settle_frames, "must be in [1, 1000]");
  }
  if (controller_max_frames < 1 || controller_max_frames > 100000) {
    Bad("controller_max_frames", controller_max_frames, "must be in [1, 100000]");
  }
  if (warmup_window_frames < 3 || warmup_window_frames > 100000) {
    Bad("warmup_window_frames", warmup_window_frames, "must be in [3, 100000]");
  }
  if (!std::isfinite(warmup_max_drift_m_per_s) || warmup_max_drift_m_per_s <= 0.0 ||
      warmup_max_drift_m_per_s > 1.0) {
    Bad("warmup_max_drift_m_per_s", warmup_max_drift_m_per_s, "must be in (0, 1]");
  }
  if (warmup_max_frames < warmup_window_frames) {
    Bad("warmup_max_frames", warmup_max_frames,
        "must be >= warmup_window_frames (" + std::to_string(warmup_window_frames) + ")");
  }
  if (!(min_valid_fraction > 0.0 && min_valid_fraction <= 1.0)) {
    Bad("min_valid_fraction", min_valid_fraction, "must be in (0, 1]");
  }
  if (!(max_uncalibrated_fraction >= 0.0 && max_uncalibrated_fraction <= 1.0)) {
    Bad("max_uncalibrated_fraction", max_uncalibrated_fraction, "must be in [0, 1]");
  }
  for (double f : exposure_offset_fractions) {
    if (!(f > 0.0 && f <= 4.0)) Bad("exposure_offset_fractions entry", f, "must be in (0, 4]");
  }
  if (exposure_offset_frames < 1 || exposure_offset_frames > 100000) {
    Bad("exposure_offset_frames", exposure_offset_frames, "must be in [1, 100000]");
  }
}

void SweepOptions::Validate() const {
  wall.Validate();
  if (!std::isfinite(from_m) || from_m <= 0.0) Bad("sweep from_m", from_m, "must be > 0");
  if (!std::isfinite(to_m) || to_m < from_m) Bad("sweep to_m", to_m, "must be >= from_m");
  if (!std::isfinite(step_m) || step_m <= 0.0 || (to_m - from_m) / step_m > 1000.0) {
    Bad("sweep step_m", step_m, "must be > 0 and give at most 1000 distances");
  }
  if (frames_per_distance < 1 || frames_per_distance > 100000) {
    Bad("sweep frames_per_distance", frames_per_distance, "must be in [1, 100000]");
  }
  if (!std::isfinite(lut_step_m) || lut_step_m <= 0.0 || lut_step_m > 1.0) {
    Bad("sweep lut_step_m", lut_step_m, "must be in (0, 1]");
  }
  if (lut_min_samples < 1 || lut_min_samples > (1 << 30)) {
    Bad("sweep lut_min_samples", lut_min_samples, "must be in [1, 2^30]");
  }
  if (!std::isfinite(outlier_m) || outlier_m <= 0.0)
    Bad("sweep outlier_m", outlier_m, "must be > 0");
  if (refine_iterations < 0 || refine_iterations > 20) {
    Bad("sweep refine_iterations", refine_iterations, "must be in [0, 20]");
  }
}

Image<float> WallRadialDistance(const CameraIntrinsics& intrinsics, double wall_distance_m,
                                const std::array<double, 3>& wall_normal) {
  ValidateNormal(wall_normal);
  const RayTable rays = MakeRayTable(intrinsics);
  const Eigen::Vector3d n = UnitNormal(wall_normal);
  Image<float> out(intrinsics.width, intrinsics.height);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double cos_incidence = n.x() * rays.x[i] + n.y() * rays.y[i] + n.z() * rays.z[i];
    out[i] = cos_incidence > 0.0 ? static_cast<float>(wall_distance_m / cos_incidence)
                                 : std::numeric_limits<float>::infinity();
  }
  return out;
}

OffsetCalibration CalibrateOffsets(Camera& camera, const WallCalibrationOptions& options,
                                   const ProgressCallback& progress,
                                   WallCalibrationReport* report) {
  options.Validate();
  const CameraInfo& info = camera.Info();
  const double range_m = info.unambiguous_range_m();
  if (options.wall_distance_m >= range_m) {
    Bad("wall_distance_m", options.wall_distance_m,
        "must be below the unambiguous range L = " + Num(range_m) + " m");
  }
  // Paper: the distance-offset register is 0 during calibration.
  if (camera.DistanceOffsetRegister() != 0) camera.SetDistanceOffsetRegister(0);

  WallCalibrationReport r;
  r.exposure_frames = SettleExposure(camera, options, progress);
  r.integration_register = camera.IntegrationTimeRegister();
  if (options.controller.kind != ControllerKind::kFixed) {
    const int hi = std::min(options.controller.max_register, info.max_integration_register);
    const int lo = std::max(options.controller.min_register, info.min_integration_register);
    r.exposure_at_bound =
        r.integration_register >= hi ? 1 : (r.integration_register <= lo ? -1 : 0);
  }
  std::tie(r.warmup_frames, r.drift_m_per_s) = WaitForWarmup(camera, options, progress);
  const PhasorAverage average = AverageFrames(camera, options.frames, "averaging", progress);

  OffsetCalibration c;
  c.camera_model = info.model;
  c.width = info.width();
  c.height = info.height();
  c.modulation_frequency_hz = info.modulation_frequency_hz;
  c.integration_time_register = r.integration_register;
  c.integration_time_us = info.IntegrationTimeUs(r.integration_register);
  c.created_unix_s = static_cast<std::int64_t>(std::time(nullptr));
  c.wall_distance_m = options.wall_distance_m;
  const Eigen::Vector3d n = UnitNormal(options.wall_normal);
  for (int k = 0; k < 3; ++k) c.wall_normal[k] = n[k];
  c.frames_averaged = options.frames;
  c.offset_m = Image<float>(c.width, c.height);
  c.pixel_flags = Image<PixelFlags>(c.width, c.height);

  const Image<float> truth =
      WallRadialDistance(info.intrinsics, options.wall_distance_m, options.wall_normal);
  const int min_count =
      std::max(1, static_cast<int>(std::ceil(options.min_valid_fraction * options.frames)));
  double sum = 0.0, sum2 = 0.0, sigma = 0.0;
  int good = 0;
  for (std::size_t i = 0; i < c.offset_m.size(); ++i) {
    if (average.count(i) < min_count || !(truth[i] < range_m)) {
      c.pixel_flags[i] = PixelFlags(Flag::kInvalid);
      ++r.uncalibrated_pixels;
      continue;
    }
    const double o = WrapSigned(average.Mean(i) - truth[i], range_m);
    c.offset_m[i] = static_cast<float>(o);
    sum += o;
    sum2 += o * o;
    sigma += average.Sigma(i);
    ++good;
  }
  const double bad_fraction =
      static_cast<double>(r.uncalibrated_pixels) / static_cast<double>(c.offset_m.size());
  if (bad_fraction > options.max_uncalibrated_fraction) {
    throw Error(ErrorCode::kMismatch,
                "calibration: " + std::to_string(r.uncalibrated_pixels) + " of " +
                    std::to_string(c.offset_m.size()) +
                    " pixels saw no wall (limit max_uncalibrated_fraction = " +
                    Num(options.max_uncalibrated_fraction) + ")");
  }
  c.exposure_offset_m_per_ms = MeasureExposureOffset(camera, options, c.pixel_flags, progress, r);
  if (r.uncalibrated_pixels == 0) c.pixel_flags = Image<PixelFlags>();
  if (good > 0) {
    r.mean_offset_m = sum / good;
    r.offset_rms_m = std::sqrt(sum2 / good);
    r.noise_sigma_m = sigma / good;
  }
  Report(progress, "averaging", options.frames, options.frames,
         "offsets: mean " + Num(r.mean_offset_m * 1e3) + " mm, rms " + Num(r.offset_rms_m * 1e3) +
             " mm, " + std::to_string(r.uncalibrated_pixels) + " uncalibrated pixels");
  if (report) *report = r;
  return c;
}

// --- Sweep -----------------------------------------------------------------------------------

namespace {

// One sweep distance after averaging.
struct SweepSample {
  double wall_distance_m = 0.0;
  bool held_out = false;
  int integration_register = 0;
  double exposure_shift_m = 0.0;  // exposure term of eq. 1 at this register
  std::vector<float> measured_m;  // circular mean, [0, L)
  std::vector<float> truth_m;
  std::vector<unsigned char> usable;
  double noise_floor_m = 0.0;
};

// Eq. 1 in double precision.
double EquationOne(double m, double o, double range_m) {
  const double l = std::fmod(m - o + range_m, range_m);
  return l < 0.0 ? l + range_m : l;
}

// Bin averages of (l, r) pairs at knots start + k * step, gaps interpolated, ends held.
DistanceCorrection FitCorrection(const std::vector<std::pair<double, double>>& samples,
                                 double step_m, int min_samples) {
  double lo = std::numeric_limits<double>::infinity(), hi = 0.0;
  for (const auto& s : samples) {
    lo = std::min(lo, s.first);
    hi = std::max(hi, s.first);
  }
  DistanceCorrection g;
  g.step_m = step_m;
  g.start_m = std::max(0.0, std::floor(lo / step_m) * step_m);
  const auto knots = static_cast<std::size_t>(std::ceil((hi - g.start_m) / step_m)) + 1;
  std::vector<double> sum(std::max<std::size_t>(knots, 2), 0.0);
  std::vector<int> count(sum.size(), 0);
  for (const auto& [l, r] : samples) {
    const auto k = static_cast<std::size_t>(
        std::clamp(std::lround((l - g.start_m) / step_m), 0L, static_cast<long>(sum.size() - 1)));
    sum[k] += r;
    ++count[k];
  }
  std::vector<int> filled;
  g.correction_m.assign(sum.size(), 0.0f);
  for (std::size_t k = 0; k < sum.size(); ++k) {
    if (count[k] >= min_samples) {
      g.correction_m[k] = static_cast<float>(sum[k] / count[k]);
      filled.push_back(static_cast<int>(k));
    }
  }
  if (filled.empty()) {
    throw Error(ErrorCode::kMismatch,
                "calibration sweep: no distance bin has enough samples for the correction");
  }
  for (std::size_t k = 0; k < sum.size(); ++k) {
    if (count[k] >= min_samples) continue;
    const auto next = std::lower_bound(filled.begin(), filled.end(), static_cast<int>(k));
    if (next == filled.begin()) {
      g.correction_m[k] = g.correction_m[static_cast<std::size_t>(filled.front())];
    } else if (next == filled.end()) {
      g.correction_m[k] = g.correction_m[static_cast<std::size_t>(filled.back())];
    } else {
      const int a = *(next - 1), b = *next;
      const double t = (static_cast<double>(k) - a) / (b - a);
      g.correction_m[k] = static_cast<float>((1.0 - t) * g.correction_m[a] + t * g.correction_m[b]);
    }
  }
  return g;
}

}  // namespace

OffsetCalibration CalibrateDistanceCorrection(const OffsetCalibration& base,
                                              const WallCameraSource& source,
                                              const SweepOptions& options,
                                              const ProgressCallback& progress,
                                              SweepReport* report) {
  options.Validate();
  base.Validate();
  if (!source) throw Error(ErrorCode::kInvalidArgument, "calibration sweep: no camera source");
  const double range_m = UnambiguousRangeM(base.modulation_frequency_hz);
  if (options.to_m >= range_m) {
    Bad("sweep to_m", options.to_m, "must be below the unambiguous range L = " + Num(range_m));
  }
  if (options.outlier_m >= range_m / 2) Bad("sweep outlier_m", options.outlier_m, "must be < L/2");

  std::vector<std::pair<double, bool>> plan;
  const int steps =
      static_cast<int>(std::floor((options.to_m - options.from_m) / options.step_m + 1e-9));
  for (int k = 0; k <= steps; ++k) {
    const double d = options.from_m + k * options.step_m;
    plan.emplace_back(d, false);
    if (options.held_out && k < steps) plan.emplace_back(d + options.step_m / 2, true);
  }

  const std::size_t pixels = base.offset_m.size();
  const int min_count = std::max(1, static_cast<int>(std::ceil(options.wall.min_valid_fraction *
                                                               options.frames_per_distance)));
  std::vector<SweepSample> samples;
  int index = 0;
  double previous_distance = 0.0;
  int previous_register = 0;
  for (const auto& [distance, held_out] : plan) {
    ++index;
    Camera& camera = source(distance);
    const CameraInfo& info = camera.Info();
    if (info.width() != base.width || info.height() != base.height ||
        std::abs(info.modulation_frequency_hz - base.modulation_frequency_hz) >
            1e-9 * base.modulation_frequency_hz) {
      throw Error(ErrorCode::kMismatch, "calibration sweep: the camera at " + Num(distance) +
                                            " m does not match the calibration (size or "
                                            "modulation frequency)");
    }
    if (camera.DistanceOffsetRegister() != 0) camera.SetDistanceOffsetRegister(0);
    if (previous_register > 0) {
      // The return falls off as 1 / d^2: start from the previous register scaled by that.
      const double guess =
          previous_register * (distance * distance) / (previous_distance * previous_distance);
      camera.SetIntegrationTimeRegister(static_cast<int>(
          std::clamp(std::lround(guess), static_cast<long>(info.min_integration_register),
                     static_cast<long>(info.max_integration_register))));
    }
    (void)SettleExposure(camera, options.wall, {});
    previous_distance = distance;
    previous_register = camera.IntegrationTimeRegister();
    const PhasorAverage average = AverageFrames(camera, options.frames_per_distance, {}, {});
    const Image<float> truth =
        WallRadialDistance(info.intrinsics, distance, options.wall.wall_normal);
    SweepSample s;
    s.wall_distance_m = distance;
    s.held_out = held_out;
    s.integration_register = camera.IntegrationTimeRegister();
    s.exposure_shift_m = ExposureShiftM(base, info.IntegrationTimeUs(s.integration_register));
    s.measured_m.resize(pixels);
    s.truth_m.resize(pixels);
    s.usable.resize(pixels);
    double noise = 0.0;
    int used = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
      s.measured_m[i] = static_cast<float>(average.Mean(i));
      s.truth_m[i] = truth[i];
      // Near L the wrapped measurement and the LUT's domain disagree; keep 5 cm away.
      s.usable[i] = average.count(i) >= min_count && truth[i] < range_m - 0.05 &&
                    (base.pixel_flags.empty() || base.pixel_flags[i].Valid());
      if (s.usable[i]) {
        // Variance of the mean, so that floors and RMS errors combine in quadrature.
        noise += average.Sigma(i) * average.Sigma(i) / average.count(i);
        ++used;
      }
    }
    s.noise_floor_m = used > 0 ? std::sqrt(noise / used) : 0.0;
    samples.push_back(std::move(s));
    Report(progress, held_out ? "held-out" : "sweep", index, static_cast<int>(plan.size()),
           "wall at " + Num(distance) + " m, register " +
               std::to_string(samples.back().integration_register));
  }

  // Alternate: g from the pooled residuals, then each pixel's mean remaining residual moves
  // its offset. Residuals are r = l - t with l from eq. 1.
  OffsetCalibration out = base;
  out.distance_correction.reset();
  std::vector<double> offset(pixels);
  for (std::size_t i = 0; i < pixels; ++i) offset[i] = base.offset_m[i];
  DistanceCorrection g;
  const auto residuals = [&](bool with_g, std::vector<double>* delta_sum,
                             std::vector<int>* delta_count) {
    std::vector<std::pair<double, double>> pooled;
    for (const SweepSample& s : samples) {
      if (s.held_out) continue;
      for (std::size_t i = 0; i < pixels; ++i) {
        if (!s.usable[i]) continue;
        const double l = EquationOne(s.measured_m[i], offset[i] + s.exposure_shift_m, range_m);
        // Not wrapped: a far pixel whose noisy measurement wrapped past the 0 / L seam would put a
        // far-distance residual at l ~ 0; it is left out with the outliers.
        const double r = l - s.truth_m[i];
        if (std::abs(r) > options.outlier_m) continue;
        if (delta_sum != nullptr) {
          (*delta_sum)[i] += r - (with_g ? g.Evaluate(l) : 0.0);
          ++(*delta_count)[i];
        } else {
          pooled.emplace_back(l, r);
        }
      }
    }
    return pooled;
  };
  for (int it = 0; it <= options.refine_iterations; ++it) {
    g = FitCorrection(residuals(false, nullptr, nullptr), options.lut_step_m,
                      options.lut_min_samples);
    if (it == options.refine_iterations) break;
    std::vector<double> delta_sum(pixels, 0.0);
    std::vector<int> delta_count(pixels, 0);
    (void)residuals(true, &delta_sum, &delta_count);
    for (std::size_t i = 0; i < pixels; ++i) {
      if (delta_count[i] > 0) offset[i] += delta_sum[i] / delta_count[i];
    }
  }
  for (std::size_t i = 0; i < pixels; ++i) {
    out.offset_m[i] = static_cast<float>(WrapSigned(offset[i], range_m));
  }
  out.distance_correction = g;
  out.Validate();

  // Errors before and after, per distance and pooled.
  SweepReport rep;
  double held_before = 0.0, held_after = 0.0, train_before = 0.0, train_after = 0.0;
  double held_noise = 0.0;
  std::size_t held_n = 0, train_n = 0;
  for (const SweepSample& s : samples) {
    SweepDistanceResult d;
    d.wall_distance_m = s.wall_distance_m;
    d.held_out = s.held_out;
    d.integration_register = s.integration_register;
    d.noise_floor_m = s.noise_floor_m;
    double raw = 0.0, before = 0.0, after = 0.0;
    for (std::size_t i = 0; i < pixels; ++i) {
      if (!s.usable[i]) continue;
      const double m = s.measured_m[i];
      const double e_raw = WrapSigned(m - s.truth_m[i], range_m);
      const double e_before = WrapSigned(
          EquationOne(m, base.offset_m[i] + s.exposure_shift_m, range_m) - s.truth_m[i], range_m);
      double l = EquationOne(m, out.offset_m[i] + s.exposure_shift_m, range_m);
      l = EquationOne(l, g.Evaluate(l), range_m);
      const double e_after = WrapSigned(l - s.truth_m[i], range_m);
      raw += e_raw * e_raw;
      before += e_before * e_before;
      after += e_after * e_after;
      ++d.pixels;
    }
    if (d.pixels > 0) {
      d.rms_raw_m = std::sqrt(raw / d.pixels);
      d.rms_before_m = std::sqrt(before / d.pixels);
      d.rms_after_m = std::sqrt(after / d.pixels);
    }
    if (s.held_out) {
      held_before += before;
      held_after += after;
      held_n += static_cast<std::size_t>(d.pixels);
      held_noise += s.noise_floor_m * s.noise_floor_m * d.pixels;
    } else {
      train_before += before;
      train_after += after;
      train_n += static_cast<std::size_t>(d.pixels);
    }
    rep.distances.push_back(d);
  }
  if (held_n > 0) {
    rep.held_out_rms_before_m = std::sqrt(held_before / static_cast<double>(held_n));
    rep.held_out_rms_after_m = std::sqrt(held_after / static_cast<double>(held_n));
    rep.held_out_noise_floor_m = std::sqrt(held_noise / static_cast<double>(held_n));
  }
  if (train_n > 0) {
    rep.training_rms_before_m = std::sqrt(train_before / static_cast<double>(train_n));
    rep.training_rms_after_m = std::sqrt(train_after / static_cast<double>(train_n));
  }
  Report(progress, "sweep", static_cast<int>(plan.size()), static_cast<int>(plan.size()),
         "held-out RMS " + Num(rep.held_out_rms_before_m * 1e3) + " mm before, " +
             Num(rep.held_out_rms_after_m * 1e3) + " mm after the distance correction");
  if (report) *report = std::move(rep);
  return out;
}

// --- Integration-time sweep and noise calibration ---------------------------------------------

void IntegrationSweepOptions::Validate() const {
  if (from_register < 0 || to_register < 0 || (to_register != 0 && from_register > to_register)) {
    Bad("integration sweep from_register", from_register,
        "must be >= 0 and below to_register = " + std::to_string(to_register));
  }
  if (steps < 3 || steps > 1000) Bad("integration sweep steps", steps, "must be in [3, 1000]");
  if (frames_per_step < 1 || frames_per_step > 100) {
    Bad("integration sweep frames_per_step", frames_per_step, "must be in [1, 100]");
  }
  if (!(clipped_intensity >= 0.0 && clipped_intensity <= 65532.0)) {
    Bad("integration sweep clipped_intensity", clipped_intensity, "must be in [0, 65532]");
  }
}

std::vector<IntegrationSweepPoint> SweepIntegrationTime(Camera& camera,
                                                        const IntegrationSweepOptions& options,
                                                        const ProgressCallback& progress) {
  options.Validate();
  const CameraInfo& info = camera.Info();
  const int lo = options.from_register > 0 ? options.from_register : info.min_integration_register;
  const int hi = options.to_register > 0 ? options.to_register : info.max_integration_register;
  if (lo < info.min_integration_register || hi > info.max_integration_register || lo >= hi) {
    throw Error(ErrorCode::kInvalidArgument,
                "integration sweep registers " + std::to_string(lo) + ".." + std::to_string(hi) +
                    " must lie within the camera's " +
                    std::to_string(info.min_integration_register) + ".." +
                    std::to_string(info.max_integration_register) + " and be increasing");
  }
  std::vector<int> registers;
  for (int k = 0; k < options.steps; ++k) {
    const int reg = static_cast<int>(
        std::lround(lo + (hi - lo) * static_cast<double>(k) / (options.steps - 1)));
    if (registers.empty() || reg > registers.back()) registers.push_back(reg);
  }
  const int previous = camera.IntegrationTimeRegister();
  std::vector<IntegrationSweepPoint> points;
  for (const int reg : registers) {
    camera.SetIntegrationTimeRegister(reg);
    MetricFrame frame;
    for (int k = 0; k < options.frames_per_step; ++k) frame = GrabMetric(camera);
    CheckCameraSize(frame, info);
    const Image<float>& channel = frame.has_intensity() ? frame.intensity : frame.amplitude;
    // Saturation from the registers (the SR-2 has no saturation bit) or the source's flags.
    const Image<PixelFlags> clipped = SaturationFilter(frame, SaturationOptions{});
    double intensity = 0.0, amplitude = 0.0;
    std::size_t count = 0, saturated = 0;
    // A pixel whose taps all clipped reads amplitude 0 (no phase, hence kInvalid) at full-scale
    // intensity: it is a reading, and its collapsed amplitude is what makes the maximum.
    for (std::size_t i = 0; i < frame.amplitude.size(); ++i) {
      if (!CountsForExposure(frame, i, static_cast<std::uint16_t>(Flag::kInvalid),
                             options.clipped_intensity)) {
        continue;
      }
      intensity += channel[i];
      amplitude += frame.amplitude[i];
      saturated += (frame.flags[i] | clipped[i]).Has(Flag::kSaturated) ? 1 : 0;
      ++count;
    }
    IntegrationSweepPoint p;
    p.integration_register = reg;
    if (count > 0) {
      p.mean_intensity = intensity / static_cast<double>(count);
      p.mean_amplitude = amplitude / static_cast<double>(count);
      p.saturated_fraction = static_cast<double>(saturated) / static_cast<double>(count);
    }
    points.push_back(p);
    Report(progress, "integration-sweep", static_cast<int>(points.size()),
           static_cast<int>(registers.size()),
           "register " + std::to_string(reg) + ": mean intensity " + Num(p.mean_intensity) +
               ", mean amplitude " + Num(p.mean_amplitude));
  }
  camera.SetIntegrationTimeRegister(previous);
  return points;
}

void NoiseCalibrationOptions::Validate() const {
  if (frames < 3 || frames > 100000) Bad("noise frames", frames, "must be in [3, 100000]");
  fit.Validate();
  if (fit_model) model_fit.Validate();
}

NoiseCalibration CalibrateNoise(Camera& camera, const NoiseCalibrationOptions& options,
                                const ProgressCallback& progress, DeltaLScaleFit* fit,
                                NoiseModelReport* model) {
  options.Validate();
  std::vector<MetricFrame> frames;
  for (int n = 1; n <= options.frames; ++n) {
    std::optional<Frame> frame = camera.Grab();
    if (!frame) break;  // a finite source: use what it had
    frames.push_back(ConvertToMetric(*frame));
    CheckCameraSize(frames.back(), camera.Info());
    if (n % 10 == 0 || n == options.frames) {
      Report(progress, "noise", n, options.frames, "grabbed " + std::to_string(n) + " frames");
    }
  }
  if (frames.size() < 3) {
    throw Error(ErrorCode::kIo, "noise calibration: the camera delivered " +
                                    std::to_string(frames.size()) +
                                    " frames, at least 3 static frames are needed");
  }
  const DeltaLScaleFit f = FitDeltaLScale(frames, options.fit);
  NoiseCalibration n;
  n.delta_l_scale = f.scale;
  n.r_squared = std::isfinite(f.r_squared) ? std::clamp(f.r_squared, -1e9, 1.0) : 0.0;
  n.frames = f.frames;
  n.pixels_used = f.pixels_used;
  NoiseModelReport report;
  if (!options.fit_model) {
    report.note = "not fitted (disabled)";
  } else if (frames.size() < static_cast<std::size_t>(options.model_fit.min_frames)) {
    report.note = "not fitted: " + std::to_string(frames.size()) + " frames, the model needs " +
                  std::to_string(options.model_fit.min_frames);
  } else {
    try {
      report.fit = FitNoiseModel(frames, options.model_fit);
      const NoiseModelFit& m = *report.fit;
      report.stored = m.fitted.spearman >= m.eq2.spearman;
      report.note = report.stored ? "stored: it ranks held-out pixels at least as well as eq. 2"
                                  : "not stored: eq. 2 ranks held-out pixels better";
      if (report.stored) {
        n.model = m.model;
        n.model_spearman = m.fitted.spearman;
        n.eq2_spearman = m.eq2.spearman;
        n.model_max_decile_error = m.fitted.max_decile_error;
      }
    } catch (const Error& e) {
      report.note = std::string("not fitted: ") + e.what();
    }
  }
  if (model) *model = report;
  n.Validate();
  Report(progress, "noise", static_cast<int>(frames.size()), options.frames,
         "sigma = " + Num(f.scale) + " x dL of eq. 2 (R^2 " + Num(f.r_squared) + ", " +
             std::to_string(f.pixels_used) + " pixels)");
  if (fit) *fit = f;
  return n;
}

std::optional<double> GroundTruthNoiseScale(const MetricFrame& frame,
                                            const DeltaLFitOptions& options) {
  options.Validate();
  if (!frame.truth || frame.truth->sigma_m.empty() ||
      !frame.truth->sigma_m.SameSize(frame.width(), frame.height())) {
    return std::nullopt;
  }
  AccuracyOptions accuracy = options.accuracy;
  accuracy.scale = 1.0;
  const Image<float> delta_l = ComputeDeltaL(frame, accuracy);
  // The truth σ is known here, so the cut of FitDeltaLScale applies to it directly.
  const double max_sigma_m =
      options.max_sigma_fraction_of_range * UnambiguousRangeM(frame.info.modulation_frequency_hz);
  double sxy = 0.0, sxx = 0.0;
  int used = 0;
  for (std::size_t i = 0; i < delta_l.size(); ++i) {
    const double sigma = frame.truth->sigma_m[i];
    const double d = delta_l[i];
    if (!frame.flags[i].Valid() || !(sigma > 0.0) || !(sigma <= max_sigma_m) || !(d > 0.0) ||
        !std::isfinite(d)) {
      continue;
    }
    sxy += sigma * sigma * d * d;
    sxx += d * d * d * d;
    ++used;
  }
  if (used < options.min_pixels || !(sxx > 0.0)) return std::nullopt;
  return std::sqrt(sxy / sxx);
}

}  // namespace tofcam
