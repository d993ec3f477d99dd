#pragma once
/// \file
/// Stage 2: per-pixel distance calibration (paper section II-B) and its application.
///
/// The offset matrix o holds, per pixel, measured minus true radial ("polar") distance in metres
/// at the calibration wall. Eq. 1 corrects a measurement m exactly as printed:
///     l = (m - o + r_e) mod r_e,   r_e = L = c / (2 f_mod) of the frame,
/// which keeps l in [0, r_e) where a plain subtraction could go negative. An optional
/// distance-dependent correction (a lookup table over the eq.-1-corrected distance, fitted on a
/// wall sweep) then removes the periodic "wiggling" error:
///     l' = (l - g(l) + r_e) mod r_e.
///
/// Exposure offset (format version 2): the distance a camera reports shifts slightly with the
/// integration time t, while the offsets are measured at one integration time t_cal. With the
/// measured slope s (m/ms) eq. 1 becomes, per frame,
///     l = (m - o - s (t - t_cal) + r_e) mod r_e,
/// i.e. a per-frame scalar folded into the per-pixel offset.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/control/integration_time_controller.h"
#include "tofcam/core/frame.h"
#include "tofcam/optics/scattering.h"

namespace tofcam {

/// Distance-dependent correction g(l): error (measured minus true, metres) as a function of the
/// eq.-1-corrected distance l, sampled at uniform knots start_m + k * step_m. Between knots a
/// Catmull-Rom cubic interpolates (exact for quadratics, smooth for the sinusoidal wiggling);
/// outside [first knot, last knot] the end value holds.
struct DistanceCorrection {
  double start_m = 0.0;             ///< Distance of knot 0, m, >= 0.
  double step_m = 0.05;             ///< Knot spacing, m, > 0.
  std::vector<float> correction_m;  ///< g at each knot, m; at least 2 knots, all finite.

  /// g(l) in metres; `distance_m` any finite value.
  [[nodiscard]] double Evaluate(double distance_m) const noexcept;
  /// Throws Error(kInvalidArgument) naming the field for a malformed table.
  void Validate() const;
};

/// g resampled once onto a dense uniform grid and interpolated linearly: the form the per-pixel
/// loop of ApplyCalibration evaluates (two table reads and one multiply-add, branch-free, so it
/// vectorises; the Catmull-Rom segment search and cubic of DistanceCorrection::Evaluate do not).
///
/// Grid: x_j = origin_m + j * step_m, step_m = knot step / k for the smallest integer k with
/// step_m <= `max_step_m` (so every knot is a grid point and each grid interval lies inside one
/// Catmull-Rom segment, where g is a cubic), covering the knots within [0, range_m]. Outside the
/// grid the end values hold, exactly as DistanceCorrection::Evaluate holds its end knots.
/// Interpolation error on an interval: |g - linear| <= step_m^2 / 8 * max |g''|, recorded as
/// `max_interpolation_error_m` (max |g''| from the knots in closed form). For 5 cm knots of a
/// 2 cm wiggle of period L/4 at 1 mm steps this is < 4e-7 m, below a float ulp at L (4.8e-7 m);
/// it is largest on the first segment, where the spline repeats the end knot
/// (tests/calibration/offset_calibration_test.cc checks it against the spline).
struct DenseDistanceCorrection {
  static constexpr double kDefaultMaxStepM = 0.001;  ///< 1 mm.
  static constexpr std::size_t kMaxSamples = std::size_t{1} << 22;

  double origin_m = 0.0;             ///< Distance of sample 0, m.
  double step_m = kDefaultMaxStepM;  ///< Sample spacing, m.
  std::vector<float> values_m;       ///< g at each sample, m; at least 2.
  /// Per interval j: values_m[j] and values_m[j + 1] - values_m[j] (m, in float), interleaved,
  /// so the per-pixel loop reads both with one 64-bit load: 2 (values_m.size() - 1) entries, or
  /// empty (then values_m alone is used, same result). Filled by Resample and derived from
  /// values_m: code that changes values_m afterwards must refill or clear it.
  std::vector<float> intervals_m;
  /// Bound on |g(x) - linear interpolation| from step_m and the knots (see above), m.
  double max_interpolation_error_m = 0.0;

  /// Resamples `g` over [0, range_m] (range_m > 0: the unambiguous range L the distances lie
  /// in). `max_step_m` in (0, 1]; the sample count is capped at kMaxSamples by coarsening k.
  /// Throws Error(kInvalidArgument) for a malformed `g` (DistanceCorrection::Validate) or
  /// arguments out of range.
  [[nodiscard]] static DenseDistanceCorrection Resample(const DistanceCorrection& g, double range_m,
                                                        double max_step_m = kDefaultMaxStepM);

  /// Linear interpolation of the samples at `distance_m`, end values held outside the grid;
  /// NaN maps to the first sample. Single precision, as in the per-pixel loop.
  [[nodiscard]] float Evaluate(float distance_m) const noexcept;
};

/// Result of a noise calibration (FitDeltaLScale on static frames): the factor that turns ΔL of
/// eq. 2 (scale 1) into a 1σ prediction in metres for this camera.
struct NoiseCalibration {
  double delta_l_scale = 1.0;  ///< σ = delta_l_scale * ΔL(scale 1); (0, 1e6].
  double r_squared = 0.0;      ///< Fit quality (informative), [-1e9, 1].
  int frames = 0;              ///< Static frames the temporal σ came from, >= 0 (informative).
  int pixels_used = 0;         ///< Pixels in the fit, >= 0 (informative).
  /// The fitted noise model (tofcam/accuracy/noise_model.h) when `tofcam calibrate --noise`
  /// found one that ranks held-out pixels at least as well as eq. 2; the pipeline's ΔL then
  /// outputs its σ unless the configuration sets accuracy.scale.
  std::optional<NoiseModel> model;
  /// Held-out quality of the stored model and of eq. 2 (informative): Spearman ρ against the
  /// measured temporal σ, and the model's largest per-decile |predicted / measured - 1|.
  double model_spearman = 0.0;
  double eq2_spearman = 0.0;
  double model_max_decile_error = 0.0;

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// The camera's scattering point-spread, measured by CalibrateScattering (`tofcam calibrate
/// --scattering-target`, docs/beyond.md) on a wall without and with a bright card near the lens.
struct ScatteringCalibration {
  /// The fitted lobes (one or two; weights [0, 0.5) summing below 0.5, σ in (0, 1000] px).
  std::vector<ScatteringLobe> lobes;
  int frames = 0;                     ///< Frames averaged per scene, >= 1.
  int integration_time_register = 0;  ///< Register both scenes were shot at, >= 0.
  int target_pixels = 0;              ///< Pixels of the card, >= 0.
  int fit_pixels = 0;                 ///< Background pixels the fit used, >= 0.
  double explained_fraction = 0.0;    ///< EstimateScatteringPsf's, [0, 1].

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// A per-pixel calibration of one camera at one modulation frequency.
struct OffsetCalibration {
  /// Current file-format version. 2 added exposure_offset_m_per_ms, noise and
  /// controller_setpoint; version-1 files load with s = 0 (no exposure compensation) and neither.
  /// 3 added the scattering point-spread (optional).
  static constexpr int kVersion = 3;

  int version = kVersion;
  std::string camera_model;               ///< Must match CameraInfo::model.
  int width = 0;                          ///< Pixels per row.
  int height = 0;                         ///< Rows.
  double modulation_frequency_hz = 20e6;  ///< Frequency the offsets were measured at (> 0).
  /// Integration time at the wall (as set by the controller), µs, >= 0: t_cal of the exposure
  /// term in eq. 1; must be > 0 when exposure_offset_m_per_ms is not 0.
  double integration_time_us = 0.0;
  int integration_time_register = 0;  ///< Its register value.
  std::int64_t created_unix_s = 0;    ///< Creation time, seconds since 1970 UTC.
  double wall_distance_m = 0.0;       ///< Perpendicular camera-to-wall distance at calibration, m.
  double wall_normal[3] = {0.0, 0.0, 1.0};  ///< Wall normal in the camera frame (unit, z > 0).
  int frames_averaged = 0;                  ///< Frames averaged per pixel.
  /// Exposure offset s: how much longer every pixel reads per ms of integration time, m/ms,
  /// |s| <= 0.1 (the simulated SR-2: 0.0005). Applied as -s (t - integration_time_us) / 1000
  /// in eq. 1 for frames whose FrameInfo::integration_time_us is known (> 0); 0 = none.
  double exposure_offset_m_per_ms = 0.0;
  /// Noise calibration of eq. 2 for this camera; absent when not measured.
  std::optional<NoiseCalibration> noise;
  /// Integration-time controller set point chosen from an integration-time sweep of the scene
  /// the camera works in (ChooseSetpoint); absent when not measured.
  std::optional<ControllerSetpoint> controller_setpoint;
  /// Scattering point-spread of the camera's optics; absent when not measured.
  std::optional<ScatteringCalibration> scattering;
  /// o[i][j]: measured minus true radial distance, m, in (-L/2, L/2); width x height.
  Image<float> offset_m;
  /// Bits OR-ed into every corrected frame: kInvalid where a pixel could not be calibrated
  /// (no valid measurement at the wall). Empty means every pixel is calibrated.
  Image<PixelFlags> pixel_flags;
  /// Distance-dependent correction from a wall sweep; absent for the paper's offset-only form.
  std::optional<DistanceCorrection> distance_correction;

  /// Throws Error(kInvalidArgument) naming the field for sizes, NaNs or ranges out of order.
  void Validate() const;
};

/// The per-frame exposure term of eq. 1 in metres: s (t - t_cal) / 1000 for a frame taken with
/// `integration_time_us` = t; 0 when t is unknown (<= 0 or not finite) or s = 0.
[[nodiscard]] double ExposureShiftM(const OffsetCalibration& calibration,
                                    double integration_time_us) noexcept;

/// Applies eq. 1 (then g, if present, through its DenseDistanceCorrection) to every pixel. Pixels
/// flagged kInvalid (no measurement) pass through untouched, flags kept; other flagged pixels (e.g.
/// saturated) are corrected too, their flags kept, so displays of raw data stay calibrated. The
/// calibration's pixel_flags are OR-ed in. The exposure term ExposureShiftM(calibration,
/// frame.info.integration_time_us) is subtracted from every pixel. Throws Error(kMismatch) when the
/// frame's size or modulation frequency differs from the calibration's, Error(kInvalidArgument)
/// when the exposure term exceeds L/4 (a slope or integration time far outside anything physical).
[[nodiscard]] MetricFrame ApplyCalibration(const MetricFrame& frame,
                                           const OffsetCalibration& calibration);

/// In-place form of ApplyCalibration for a pipeline that owns its frame (no copy). The
/// distance correction is evaluated through its DenseDistanceCorrection (1 mm), resampled on the
/// first call with a given table and cached per thread (a later call with the same knots and
/// range reuses it; the check compares the knots, not the pixels).
void ApplyCalibrationInPlace(MetricFrame& frame, const OffsetCalibration& calibration);

}  // namespace tofcam
