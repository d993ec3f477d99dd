#pragma once
// A small test-double camera facing a flat wall, written independently of the calibration code:
// a known per-pixel offset pattern, exponential warm-up drift, wiggling with period L/4, Gaussian
// distance noise from the shot-noise model, intensity proportional to integration time / d^2,
// and registers that wrap at L like a real phase measurement.

#include <cmath>
#include <cstdint>
#include <functional>
#include <optional>
#include <random>

#include "tofcam/core/camera.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::testing {

struct FakeWallOptions {
  int width = 40;
  int height = 31;
  double fx_px = 51.02, fy_px = 36.5;         // the SR-2 field of view at a quarter of the pixels
  double wall_distance_m = 1.5;               // perpendicular, wall normal (0, 0, 1)
  double signal_per_register_at_1m = 3000.0;  // intensity units
  double contrast = 0.4;                      // amplitude / signal
  double background = 0.0;                    // intensity units
  double noise_scale = 2.0 / kPi;  // σ = noise_scale * ΔL (ideal 4-tap sampling, gain 1)
  double drift_amplitude_m = 0.0;  // warm-up drift at open
  double drift_time_constant_s = 20.0;
  double drift_linear_m_per_s = 0.0;      // a camera that never settles
  double wiggle_amplitude_m = 0.0;        // sin(2π 4 t / L)
  double constant_offset_m = 0.0;         // added to every pixel's pattern
  double exposure_offset_m_per_ms = 0.0;  // distance shift per ms of integration time
  bool pattern = true;                    // bowl + pixel-to-pixel pattern
  int blocked_columns = 0;                // leftmost columns return nothing (amplitude 0)
  bool collapse_clipped = false;  // a pixel whose intensity clips reads amplitude 0 (taps full)
  std::uint64_t seed = 1;
};

class FakeWallCamera final : public Camera {
 public:
  explicit FakeWallCamera(FakeWallOptions o) : o_(o), rng_(o.seed) {
    info_.model = "FAKE";
    info_.intrinsics.width = o.width;
    info_.intrinsics.height = o.height;
    info_.intrinsics.fx_px = o.fx_px;
    info_.intrinsics.fy_px = o.fy_px;
    info_.intrinsics.cx_px = (o.width - 1) / 2.0;
    info_.intrinsics.cy_px = (o.height - 1) / 2.0;
  }

  // The offset the camera adds to pixel (row, col), metres.
  [[nodiscard]] double TrueOffset(int row, int col) const {
    if (!o_.pattern) return o_.constant_offset_m;
    const double u = (col - info_.intrinsics.cx_px) / info_.intrinsics.cx_px;
    const double v = (row - info_.intrinsics.cy_px) / info_.intrinsics.cy_px;
    return o_.constant_offset_m + 0.02 * (u * u + v * v) + 0.01 * std::sin(7.0 * row + 3.0 * col);
  }
  // True radial distance of pixel (row, col) to the wall.
  [[nodiscard]] double TrueDistance(int row, int col) const {
    const double x = (col - info_.intrinsics.cx_px) / o_.fx_px;
    const double y = (row - info_.intrinsics.cy_px) / o_.fy_px;
    return o_.wall_distance_m * std::sqrt(x * x + y * y + 1.0);
  }
  [[nodiscard]] double Wiggle(double d) const {
    return o_.wiggle_amplitude_m * std::sin(2.0 * kPi * 4.0 * d / info_.unambiguous_range_m());
  }
  void MoveWall(double distance_m) { o_.wall_distance_m = distance_m; }
  [[nodiscard]] double TimeS() const { return static_cast<double>(sequence_) / 30.0; }
  [[nodiscard]] double Drift() const {
    return o_.drift_amplitude_m * std::exp(-TimeS() / o_.drift_time_constant_s) +
           o_.drift_linear_m_per_s * TimeS();
  }

  std::optional<Frame> Grab() override {
    const int w = o_.width, h = o_.height;
    const double range = info_.unambiguous_range_m();
    Frame f;
    f.distance = Image<std::uint16_t>(w, h);
    f.amplitude = Image<std::uint16_t>(w, h);
    f.intensity = Image<std::uint16_t>(w, h);
    f.info.sequence = sequence_;
    f.info.timestamp_ns = static_cast<std::int64_t>(TimeS() * 1e9);
    f.info.integration_time_register = register_;
    f.info.integration_time_us = info_.IntegrationTimeUs(register_);
    f.info.modulation_frequency_hz = info_.modulation_frequency_hz;
    f.info.camera_model = info_.model;
    f.info.distance_offset_register = offset_register_;
    const double drift = Drift();
    const double exposure_shift =
        o_.exposure_offset_m_per_ms * info_.IntegrationTimeUs(register_) * 1e-3;
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        if (c < o_.blocked_columns) continue;  // all registers 0: no return
        const double t = TrueDistance(r, c);
        const double signal = o_.signal_per_register_at_1m * register_ / (t * t);
        const double intensity = std::min(signal + o_.background, 65532.0);
        const double amplitude = o_.collapse_clipped && intensity >= 65532.0
                                     ? 0.0
                                     : std::min(o_.contrast * signal, 65532.0);
        const double delta_l = range / std::sqrt(8.0) * std::sqrt(intensity) / (2.0 * amplitude);
        double d = t + TrueOffset(r, c) + Wiggle(t) + drift + exposure_shift +
                   o_.noise_scale * delta_l * normal_(rng_);
        d = std::fmod(d, range);
        if (d < 0) d += range;
        const auto reg = static_cast<long>(std::lround(d / range * 65536.0)) + offset_register_;
        f.distance(r, c) = static_cast<std::uint16_t>(reg % 65536);
        f.amplitude(r, c) = static_cast<std::uint16_t>(std::lround(amplitude));
        f.intensity(r, c) = static_cast<std::uint16_t>(std::lround(intensity));
      }
    }
    ++sequence_;
    return f;
  }
  const CameraInfo& Info() const override { return info_; }
  void SetIntegrationTimeRegister(int reg) override {
    if (reg < 1 || reg > 255) throw Error(ErrorCode::kInvalidArgument, "register");
    register_ = reg;
  }
  int IntegrationTimeRegister() const override { return register_; }
  void SetModulationFrequencyHz(double) override {
    throw Error(ErrorCode::kUnsupported, "fixed frequency");
  }
  void SetDistanceOffsetRegister(int reg) override { offset_register_ = reg; }
  int DistanceOffsetRegister() const override { return offset_register_; }
  void SetPanAngleRad(double) override { throw Error(ErrorCode::kUnsupported, "no pan unit"); }
  double PanAngleRad() const override { return 0.0; }

 private:
  FakeWallOptions o_;
  CameraInfo info_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::uint64_t sequence_ = 0;
  int register_ = 20;
  int offset_register_ = 0;
};

}  // namespace tofcam::testing
