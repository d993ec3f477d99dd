#pragma once
/// \file
/// Camera models of the simulator: geometry, timing, radiometry, sensor and systematic errors of
/// one ToF camera type, loaded from YAML (scenes/cameras/*.yaml, embedded in the library at build
/// time). See docs/simulator.md for every field, its default and why it was chosen.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"

namespace tofcam::sim {

/// One Gaussian lobe of the in-camera scattering PSF.
struct ScatterLobe {
  double weight = 0.0;    ///< Fraction of a pixel's light spread into this lobe (>= 0).
  double sigma_px = 0.0;  ///< Standard deviation in pixels (> 0).
};

/// A ToF camera type. All lengths in metres unless named otherwise.
struct CameraModel {
  /// Longest name, bytes.
  static constexpr std::size_t kMaxNameBytes = 256;
  /// Most pixels a simulated camera may have (2048 x 2048, what a recording holds).
  static constexpr long long kMaxPixels = 1LL << 22;

  std::string name = "SR-2";  ///< Model name reported in CameraInfo::model (1-256 bytes).
  CameraIntrinsics intrinsics = CameraIntrinsics::SwissRangerSr2();
  /// Selectable modulation frequencies, Hz; the first is the default.
  std::vector<double> modulation_frequencies_hz = {20e6};
  double integration_time_step_us = 255.0;  ///< µs per register step (> 0).
  double integration_time_base_us = 0.0;    ///< µs at register 0 (>= 0).
  int min_integration_register = 1;         ///< Smallest valid register (>= 0).
  int max_integration_register = 255;       ///< Largest valid register (>= min).
  int default_integration_register = 32;    ///< Register when the camera is opened.
  double max_frame_rate_hz = 30.0;          ///< Frame-rate cap (> 0).
  double readout_time_us = 4000.0;          ///< Dead time per frame besides integration (>= 0).

  // Radiometry (the emitter sits at the optical centre).
  double led_power_w = 1.0;            ///< Modulated optical power in the filter band, W (> 0).
  double led_half_angle_deg = 30.0;    ///< Half-intensity half angle of the emitter, deg (0, 90).
  double wavelength_nm = 870.0;        ///< Emitter wavelength (> 0).
  double f_number = 1.4;               ///< Lens f-number (> 0).
  double pixel_pitch_x_um = 39.2;      ///< Pixel pitch, horizontal, µm (> 0).
  double pixel_pitch_y_um = 54.8;      ///< Pixel pitch, vertical, µm (> 0).
  double fill_factor = 0.3;            ///< Light-sensitive fraction of a pixel, (0, 1].
  double quantum_efficiency = 0.8;     ///< Electrons per photon, (0, 1].
  double tap_duty = 0.25;              ///< Fraction of the integration time each tap collects.
  double demodulation_contrast = 0.5;  ///< Modulated / DC part of the active signal, (0, 1].

  // Sensor.
  double full_well_e = 100000.0;        ///< Per-tap full-well capacity, electrons (> 0).
  double read_noise_e = 30.0;           ///< Per-tap read noise, electrons RMS (>= 0).
  double dark_current_e_per_s = 2.0e5;  ///< Per-tap dark current, electrons / s (>= 0).
  double gain_reg_per_e = 0.65532;      ///< Register units per electron for amplitude/intensity.
  /// Share of a full tap's excess charge that spills over into the same pixel's other taps (they
  /// share one photo-gate), [0, 1]: the taps of a saturating pixel equalise, so its offset keeps
  /// rising while its amplitude collapses. 0 = clip each tap on its own.
  double overflow_fraction = 0.0;
  /// Share of the excess that does not stay in the pixel and spills into neighbouring pixels (as
  /// offset charge), [0, 1]; the rest goes to the drain.
  double blooming_fraction = 0.5;
  double blooming_sigma_px = 2.0;  ///< Spread of spilled charge, px (> 0).
  std::vector<ScatterLobe> scattering = {{0.01, 8.0}, {0.01, 40.0}};  ///< Scattering PSF lobes.

  // Systematic distance errors.
  double wiggle_amplitude_m = 0.03;         ///< Odd-harmonic error amplitude (period L/4).
  double wiggle_phase_rad = 0.0;            ///< Phase of the wiggling error.
  double fpn_bowl_m = 0.04;                 ///< Fixed-pattern offset at the image corners (bowl).
  double fpn_spread_m = 0.01;               ///< Pixel-to-pixel fixed-pattern spread, σ.
  double warmup_amplitude_m = 0.05;         ///< Drift at power-on, decays exponentially.
  double warmup_time_constant_s = 300.0;    ///< Drift time constant (> 0).
  double exposure_offset_m_per_ms = 0.001;  ///< Distance shift per ms of integration time.
  std::uint64_t unit_seed = 1;  ///< Seed of this unit's fixed-pattern map (a "serial number").

  /// Throws Error(kInvalidArgument) naming the first field out of range.
  void Validate() const;
  /// The CameraInfo a camera of this model reports at `modulation_frequency_hz`.
  [[nodiscard]] CameraInfo Info(double modulation_frequency_hz) const;
};

/// Parses a camera model; `source` names the text in error messages. Missing fields keep the
/// CameraModel defaults. Throws Error(kFormat) naming the source, line and problem.
[[nodiscard]] CameraModel ParseCameraModel(std::string_view yaml_text, const std::string& source);
/// Loads a camera model YAML file (kNotFound if missing, kFormat if malformed).
[[nodiscard]] CameraModel LoadCameraModel(const std::filesystem::path& path);
/// Names of the built-in models: "sr2", "sr3000", "sr4000", "generic640x480".
[[nodiscard]] std::vector<std::string> BuiltinCameraModelNames();
/// A built-in model by name ("" = "sr2") or, when `name_or_path` ends in .yaml/.yml or names an
/// existing file, that file. Throws Error(kNotFound) listing the known names.
[[nodiscard]] CameraModel ResolveCameraModel(const std::string& name_or_path);

/// The same camera with another pixel count: the field of view, the principal point at the image
/// centre, the pixel pitch and the radiometry stay, so each pixel collects the signal of one of
/// the original's pixels (for scaling studies and benchmarks). Throws Error(kInvalidArgument)
/// unless 1 <= width, height <= 16384.
[[nodiscard]] CameraModel WithResolution(CameraModel model, int width, int height);

}  // namespace tofcam::sim
