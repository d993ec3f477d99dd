#pragma once
/// \file
/// A per-camera model of the per-pixel distance noise σ beyond eq. 2 (docs/noise_model.md).
///
/// Eq. 2 says σ = s L / sqrt(8) sqrt(I) / (2 A): in logarithms a straight line in ln A and ln I
/// with fixed slopes -1 and 1/2 (amplitude-only form: -1/2 in ln A). Real cameras depart from
/// it: read noise and the camera's own processing flatten the slope at low amplitude, and near
/// saturation the noise rises again (measured on an SR-4000, issue 14). The fitted model keeps
/// eq. 2's form but lets the data set the slopes and adds the channels a camera has:
///
///   ln σ = c0 + c_A ln A + c_I ln I + c_r ln r + c_sat A / A_ref + c_C ln(1 + C)
///
/// with A amplitude and I intensity (register units), r radial distance (m), C the camera's own
/// confidence (Frame::confidence). A coefficient of 0 leaves a channel out. Six numbers, each
/// with a physical reading (c_A = -1, c_I = 1/2, others 0 is eq. 2 itself), fitted by least
/// squares of ln σ on a static recording and validated on held-out pixels (FitNoiseModel).
/// NoiseModel itself lives in delta_l.h: with AccuracyOptions::model set, the ΔL stage outputs
/// the model's σ.

#include <array>
#include <span>
#include <string>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/core/frame.h"

namespace tofcam {

struct NoiseModelFitOptions {
  /// Static frames needed, [3, 1e6]: σ from 3 frames has ~50 % relative error per pixel, so the
  /// default asks for 4 (the minimum).
  int min_frames = 4;
  /// Pixels needed in each half (training and held out), [10, 2^28].
  int min_pixels = 200;
  /// Side (pixels) of the checkerboard blocks that split training from held-out pixels, [1, 4096].
  /// Blocks rather than single pixels: neighbours share optics and scene, so pixel-level splits
  /// leak.
  int block_px = 8;
  /// Channels the model may use (each only where the frames have it).
  bool use_intensity = true;
  bool use_distance = true;
  bool use_saturation = true;
  bool use_confidence = true;
  /// The local depth variation (LocalDepthVariation, each frame's, averaged): pixels at depth
  /// edges may jitter beyond what their amplitude says (flying pixels).
  bool use_edges = true;
  /// Pixels whose eq. 2 σ (at the median σ / ΔL) exceeds this fraction of L are left out, as in
  /// FitDeltaLScale: near-dark pixels whose phase wraps. The cut is on the predictor, not on the
  /// measured σ, so it does not bias the fit. (0, inf].
  double max_sigma_fraction_of_range = 0.01;
  /// Eq. 2's options for the baseline (scale ignored: it is fitted).
  AccuracyOptions accuracy;
  /// Pixels this rule flags kSaturated in any frame are left out, as the pipeline's saturation
  /// filter rejects them: the model predicts the noise of pixels that are measurements. (Near
  /// saturation, still unclipped, is the model's A / A_ref channel.)
  SaturationOptions saturation;

  void Validate() const;
};

/// How well one predictor ranks and predicts the measured temporal σ on held-out pixels.
struct PredictorValidation {
  std::string name;        ///< "eq. 2", "fitted model", "vendor confidence".
  bool available = false;  ///< False when the recording lacks what the predictor needs.
  /// Spearman rank correlation between predicted σ and measured σ (vendor: -C against σ).
  double spearman = 0.0;
  /// True when the predictor gives σ in metres (eq. 2 with its fitted scale, the model); the
  /// vendor's confidence is unitless and only ranks.
  bool calibrated = false;
  /// Per decile of predicted σ (10 equal-count bins, lowest first): RMS predicted σ and RMS
  /// measured σ (m). The sample variance is unbiased, so the RMS of σ's estimates is too.
  std::array<double, 10> predicted_m{};
  std::array<double, 10> measured_m{};
  /// Largest |predicted / measured - 1| over the deciles.
  double max_decile_error = 0.0;
};

/// The result of FitNoiseModel.
struct NoiseModelFit {
  NoiseModel model;            ///< Fitted on every usable pixel (after validation).
  double eq2_scale = 1.0;      ///< Eq. 2's scale on every usable pixel (as FitDeltaLScale).
  PredictorValidation eq2;     ///< Eq. 2, its scale fitted on the training half.
  PredictorValidation fitted;  ///< The model fitted on the training half.
  PredictorValidation vendor;  ///< The camera's confidence channel, where present.
  int frames = 0;
  int training_pixels = 0;
  int held_out_pixels = 0;
  /// The model's channels, e.g. "ln A, ln I, ln r, A/A_ref".
  std::string features;
};

/// Fits NoiseModel on a static recording (same integration time, nothing moving): per-pixel
/// temporal σ around the circular mean of pixels valid in every frame; the least squares of
/// ln σ on the features of the
/// per-pixel mean channels, lightly ridge-regularised so that a channel that barely varies
/// cannot take a wild slope; the intercept is then set so that the mean predicted σ² equals the
/// mean measured σ² (a least squares in logs predicts the geometric mean, which falls short).
/// Validates eq. 2, the model and the vendor channel on held-out checkerboard blocks, then refits
/// on all pixels. Throws Error(kInvalidArgument) for bad options, fewer than min_frames frames,
/// frames that differ in size or frequency, or too few usable pixels.
[[nodiscard]] NoiseModelFit FitNoiseModel(std::span<const MetricFrame> frames,
                                          const NoiseModelFitOptions& options = {});

/// Spearman rank correlation (ties get their mean rank); 0 for fewer than 2 values or a
/// constant input.
[[nodiscard]] double SpearmanCorrelation(std::span<const double> a, std::span<const double> b);

}  // namespace tofcam
