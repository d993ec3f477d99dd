#pragma once
/// \file
/// The virtual ToF camera: ray casting (Embree) through supersampled pixels, continuous-wave
/// four-tap demodulation with shot and read noise, saturation, blooming, scattering, multipath,
/// wiggling, fixed-pattern offsets, warm-up drift and motion during exposure. Every effect can be
/// switched off. See docs/simulator.md.

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>

#include "tofcam/core/camera.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim {

/// Which effects run and how; defaults are "everything on".
struct SimulatorOptions {
  std::uint64_t seed = 1;          ///< Noise seed; the same seed gives bit-identical frames.
  int supersampling = 2;           ///< S x S rays per pixel, 1..8.
  int threads = 1;                 ///< Worker threads for ray casting and taps, 1..64.
  bool real_time = false;          ///< Grab() sleeps so frames arrive at the frame rate.
  double power_on_time_s = 600.0;  ///< Time the camera has been on when opened, s (>= 0).
  /// Integration-time register at open; 0 = the camera model's default.
  int integration_time_register = 0;

  bool shot_noise = true;        ///< Poisson noise on each tap.
  bool read_noise = true;        ///< Gaussian read noise on each tap.
  bool dark_current = true;      ///< Dark current in the offset.
  bool saturation = true;        ///< Full-well clipping per tap.
  bool blooming = true;          ///< Over-full-well charge spills into neighbours.
  bool background_light = true;  ///< Lamps and ambient light.
  bool glossy = true;            ///< Specular lobes of glossy materials.
  bool multipath = true;         ///< Mirror bounces.
  bool scattering = true;        ///< In-camera scattering PSF.
  bool wiggling = true;          ///< Odd-harmonic distance error.
  bool fixed_pattern = true;     ///< Per-pixel offset map.
  bool warmup_drift = true;      ///< Exponential drift after power-on.
  bool exposure_offset = true;   ///< Distance shift with integration time.
  bool motion = true;            ///< Taps at their own times when something moves.
  int max_bounces = 2;           ///< Mirror bounces per ray, 0..8.
  /// One-bounce diffuse inter-reflection (LED -> surface -> surface -> camera, e.g. in concave
  /// corners): an extra phasor over a longer path, so distances are biased long. Off by default:
  /// it costs about as much as the primary rendering (docs/simulator.md).
  bool interreflection = false;
  /// Cosine-weighted hemisphere samples per evaluated point (every second pixel in x and y; the
  /// result is smoothed along each surface), 1..256.
  int interreflection_samples = 4;

  /// The planar shortcut: Embree casts each pixel's central ray; a subsample ray whose four
  /// surrounding pixel centres hit one triangle (or two coplanar halves of one convex
  /// quadrilateral) is cast on that plane in closed form, the rest by Embree, and so is every
  /// subsample near a triangle's corner or near where two surfaces pass through each other (where a
  /// surface can hide between pixel centres). Frames equal the exact ones up to float rounding:
  /// with the noise off a register differs by at most one count, except where a value sits on a
  /// threshold (saturation, a truth cause, a mirror bounce grazing an edge); the truth distance
  /// is bit for bit the same, the truth sigma and footprint up to rounding. With noise, a
  /// rounding difference can change how many random numbers a dark pixel's Poisson draw takes,
  /// so the rest of that row draws other (equally distributed) noise. 1.3-1.45x faster frames
  /// for a moving camera among large surfaces with 2x2 supersampling; slower (by 3-8 %) for a
  /// static camera on a moving, finely tessellated object (docs/simulator.md "The planar
  /// shortcut"); no effect at S = 1. Off by default, so that the documented experiments
  /// reproduce bit for bit.
  bool planar_shortcut = false;

  /// Render taps separately when anything moves more than this during one exposure, m.
  double motion_threshold_m = 0.01;
  /// Ground truth: kMixed when the subsample distances of a pixel span more than this, m.
  double truth_mixed_span_m = 0.05;
  /// Ground truth: kMultipath / kScattering when that component shifts the distance by more than
  /// this, m.
  double truth_bias_m = 0.01;

  /// All effects off except the ideal sensor (taps, quantisation): for tests against closed forms.
  [[nodiscard]] static SimulatorOptions Ideal();
  /// Throws Error(kInvalidArgument) naming the option.
  void Validate() const;
};

/// A simulated camera looking at a Scene. Not thread-safe (one grabbing thread).
class SimulatedCamera final : public Camera {
 public:
  /// Throws Error(kInvalidArgument) for invalid options or model, Error(kInternal) when Embree
  /// fails.
  SimulatedCamera(Scene scene, CameraModel model, SimulatorOptions options = {});
  ~SimulatedCamera() override;

  /// Renders the next frame (always a value: the simulator never ends).
  [[nodiscard]] std::optional<Frame> Grab() override;
  [[nodiscard]] const CameraInfo& Info() const override { return info_; }
  void SetIntegrationTimeRegister(int reg) override;
  [[nodiscard]] int IntegrationTimeRegister() const override { return integration_register_; }
  /// Must be one of CameraModel::modulation_frequencies_hz (within 1 Hz).
  void SetModulationFrequencyHz(double hz) override;
  /// 0..65535.
  void SetDistanceOffsetRegister(int reg) override;
  [[nodiscard]] int DistanceOffsetRegister() const override { return offset_register_; }
  /// Any finite angle; overrides the scene's pan schedule from now on.
  void SetPanAngleRad(double angle_rad) override;
  [[nodiscard]] double PanAngleRad() const override;
  [[nodiscard]] bool HasPanUnit() const noexcept override { return true; }

  [[nodiscard]] const Scene& scene() const noexcept;
  [[nodiscard]] const CameraModel& model() const noexcept;
  [[nodiscard]] const SimulatorOptions& options() const noexcept;
  /// Start of the next frame's exposure, s since the camera was opened.
  [[nodiscard]] double NextExposureStartS() const noexcept { return next_start_s_; }
  /// The unit's fixed-pattern offset map, m (zeros when fixed_pattern is off).
  [[nodiscard]] const Image<float>& FixedPatternOffsetM() const noexcept;
  /// Distance offset (m) added by warm-up drift at a time since opening.
  [[nodiscard]] double WarmupOffsetM(double time_s) const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  CameraInfo info_;
  int integration_register_ = 1;
  int offset_register_ = 0;
  std::optional<double> pan_override_rad_;
  double next_start_s_ = 0.0;
  std::uint64_t sequence_ = 0;
  std::optional<std::chrono::steady_clock::time_point> real_time_origin_;
};

}  // namespace tofcam::sim
