#pragma once
/// \file
/// Stage 3: the predicted inaccuracy ΔL of every pixel (paper section III-B) and the noise
/// calibration that ties it to the measured temporal standard deviation.
///
/// Eq. 2 and 3:  ΔL = scale * L / sqrt(8) * sqrt(I) / (2 A),  L = c / (2 f_mod),
/// with A and I in register units (0..65532) and ΔL in metres.
///
/// Eq. 2 holds up to a constant that depends on how A and I are scaled. For ideal 4-tap sampling
/// with shot noise, σ_d = L sqrt(B) / (2 sqrt(2) π A) with B and A in electrons (tof-notes §1).
/// With registers = g * electrons (I = g B, A_reg = g A) this is σ_d = (2 sqrt(g) / π) ΔL, so the
/// scale a noise calibration finds is 2 sqrt(g) / π for a camera whose registers count g units
/// per electron (0.637 for g = 1). FitDeltaLScale measures it; see docs/calibration.md.

#include <optional>
#include <span>

#include "tofcam/core/frame.h"
#include "tofcam/filters/pixel_filters.h"

namespace tofcam {

/// A fitted per-camera noise model (tofcam/accuracy/noise_model.h, docs/noise_model.md):
///   ln σ = c0 + c_A ln A + c_I ln I + c_r ln r + c_sat A / A_ref + c_C ln(1 + C). Coefficients are
///   dimensionless except c0
/// (ln of metres).
struct NoiseModel {
  double intercept = 0.0;           ///< c0.
  double log_amplitude = 0.0;       ///< c_A, slope in ln A.
  double log_intensity = 0.0;       ///< c_I, slope in ln I; non-zero needs an intensity channel.
  double log_distance = 0.0;        ///< c_r, slope in ln r (r in m, floored at 0.05 m).
  double amplitude_fraction = 0.0;  ///< c_sat, slope in A / amplitude_ref (saturation proximity).
  double amplitude_ref = 1.0;       ///< A_ref, register units, > 0 (the fit's 99th percentile).
  double log_confidence = 0.0;  ///< c_C, slope in ln(1 + C); non-zero needs a confidence channel.
  /// c_E, slope in ln(1 + E / edge_ref_m), E = the pixel's local depth variation (m,
  /// LocalDepthVariation): pixels at depth edges (flying pixels) can be noisier than their
  /// channels say. Non-zero makes ΔL a neighbourhood quantity.
  double log_edge = 0.0;
  double edge_ref_m = 0.01;  ///< E_ref, m, > 0 (the fit's median E).

  [[nodiscard]] bool uses_intensity() const noexcept { return log_intensity != 0.0; }
  [[nodiscard]] bool uses_confidence() const noexcept { return log_confidence != 0.0; }
  [[nodiscard]] bool uses_edges() const noexcept { return log_edge != 0.0; }
  /// Throws Error(kInvalidArgument) naming the field unless every value is finite, every
  /// coefficient within ±1e3 and amplitude_ref, edge_ref_m > 0.
  void Validate() const;
};

/// Predicted σ (m) of one pixel. Amplitude <= 0 or NaN gives +inf (as eq. 2); intensity is
/// floored at 1, distance at 0.05 m, confidence and local depth variation `edge_m` at 0.
[[nodiscard]] double PredictSigmaM(const NoiseModel& model, double amplitude, double intensity,
                                   double distance_m, double confidence, double edge_m = 0.0);

/// Local depth variation E per pixel, m: the largest |d - d_n| over its 4-neighbours n whose
/// distance is finite and that carry no reject flag (kRejectMask; `flags` may be empty). 0 where
/// no such neighbour exists or the pixel's own distance is not finite. The noise model's edge
/// channel.
void LocalDepthVariation(const Image<float>& distance_m, const Image<PixelFlags>& flags,
                         Image<float>& out);

/// Multiplies `delta_l` (the model's σ without its edge term) by (1 + E / E_ref)^c_E, E from
/// `distance_m` and `flags` (LocalDepthVariation); nothing when the model has no edge term.
/// ComputeDeltaL and the Pipeline call it after the per-pixel terms. Throws
/// Error(kInvalidArgument) for images of different sizes.
void ApplyNoiseModelEdgeTerm(const NoiseModel& model, const Image<float>& distance_m,
                             const Image<PixelFlags>& flags, Image<float>& delta_l);

struct AccuracyOptions {
  /// Multiplies eq. 2; 1 is the paper's formula, FitDeltaLScale() measures the camera's value.
  /// Valid range (0, 1e6].
  double scale = 1.0;
  /// Amplitude-only form for sources without an intensity channel: I is replaced by
  /// intensity_per_amplitude * A, i.e. ΔL = scale L / sqrt(8) sqrt(k A) / (2 A). The default 2.5
  /// is 1 / 0.4, the offset-to-amplitude ratio of a demodulation contrast of 0.4 without
  /// background light; background raises the true ratio, so the form is optimistic under lamps
  /// or sunlight. Valid range (0, 1e6].
  double intensity_per_amplitude = 2.5;
  /// When set, ΔL is this model's predicted σ (m) instead of eq. 2 (scale and
  /// intensity_per_amplitude are then unused). From `tofcam calibrate --noise`.
  std::optional<NoiseModel> model;

  /// Throws Error(kInvalidArgument) naming the field when a value is out of range or not finite.
  void Validate() const;
};

/// ΔL in metres per pixel (eq. 2, times options.scale), with L of the frame's modulation
/// frequency; or options.model's σ when a model is set (Error(kMismatch) when it needs an
/// intensity or confidence channel the frame lacks). Pixels with A <= 0 (or NaN) get +inf;
/// intensities below 0 count as 0. Flags are not read or changed: invalid pixels get the value of
/// the formula too (the threshold filter reads flags and ΔL together). Uses the amplitude-only form
/// when `!frame.has_intensity()`. Throws Error(kInvalidArgument) for bad options, an empty frame or
/// channels of different sizes.
[[nodiscard]] Image<float> ComputeDeltaL(const MetricFrame& frame,
                                         const AccuracyOptions& options = {});

/// Same as ComputeDeltaL, into `out` (reused when it has the frame's size), e.g.
/// `ComputeDeltaLInto(frame, options, frame.delta_l_m)`.
void ComputeDeltaLInto(const MetricFrame& frame, const AccuracyOptions& options, Image<float>& out);

/// The result of a noise calibration.
struct DeltaLScaleFit {
  /// Fitted factor s in σ = s * ΔL(scale = 1): least squares of σ² on ΔL² through the origin
  /// (sample variance is an unbiased estimate of σ², so this fit has no small-sample bias).
  double scale = 0.0;
  double median_ratio = 0.0;  ///< Median over pixels of σ / ΔL (robust cross-check).
  /// Coefficient of determination of σ against scale * ΔL over the pixels used (1 = perfect).
  double r_squared = 0.0;
  /// Root mean square of (σ - scale * ΔL) / (scale * ΔL): the spread of the model around the fit.
  double relative_rms = 0.0;
  int pixels_used = 0;  ///< Pixels valid in every frame with finite ΔL.
  int frames = 0;       ///< Frames the temporal σ was computed from.
};

struct DeltaLFitOptions {
  /// Pixels whose predicted σ (the median of σ / ΔL over all pixels, times their mean ΔL)
  /// exceeds this fraction of the unambiguous range L are left out of the least squares: near
  /// dark pixels whose phase spreads so far that wrapping (σ saturates near L / sqrt(12)) and read
  /// noise (not in eq. 2) make σ stop following eq. 2. Relative to L, so one value serves every
  /// camera whatever its register convention. (0, inf); +inf = no cut.
  double max_sigma_fraction_of_range = 0.01;
  /// At least this many pixels must remain, [1, 2^28].
  int min_pixels = 10;
  /// Options for ΔL during the fit; `scale` is ignored (the fit is for scale 1).
  AccuracyOptions accuracy;
  /// Pixels this rule flags kSaturated in any frame are left out (as the pipeline's saturation
  /// filter rejects them): a clipped pixel's spread is not noise.
  SaturationOptions saturation;

  void Validate() const;
};

/// Noise calibration: the per-pixel temporal σ of the radial distance over `frames` (a static
/// scene, same integration time) against the mean ΔL of eq. 2 with scale 1. Temporal σ is taken
/// around the circular mean, so pixels near the 0 / L seam are handled. Pixels invalid or
/// clipped (options.saturation) in any frame are skipped. Throws Error(kInvalidArgument) with fewer
/// than 3 frames, frames of different sizes or modulation frequencies, or fewer than min_pixels
/// usable pixels.
[[nodiscard]] DeltaLScaleFit FitDeltaLScale(std::span<const MetricFrame> frames,
                                            const DeltaLFitOptions& options = {});

}  // namespace tofcam
