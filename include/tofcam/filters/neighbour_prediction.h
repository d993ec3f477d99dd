#pragma once
/// \file
/// What a pixel's neighbours say its distance should be, and how far its own reading then
/// probably is from the truth (not in the paper; issue 18, docs/beyond.md, "The neighbours'
/// prediction").
///
/// ΔL (eq. 2) gives a reading's σ but not its error: a pixel with σ = 6 cm is good or bad by its
/// noise draw, and no rule that sees only σ can tell which (the per-pixel ceiling of docs/
/// beyond.md). Its neighbours can, where they lie on its surface: their readings predict its
/// distance with a σ_p much smaller than σ, so the residual r = d - p of the reading against the
/// prediction shows most of the draw. With the reading's error e = d - truth ~ N(0, σ²) and the
/// prediction's p - truth ~ N(0, σ_p²) independent, e given r is Gaussian with
///   mean  m = r σ² / (σ² + σ_p²),   variance  v = σ² σ_p² / (σ² + σ_p²),
/// so the reading's expected squared error is m² + v, and d - m (the inverse-variance combination
/// of reading and prediction) is the best estimate of the truth, with σ = sqrt(v).
///
/// **The prediction.** Every pair of pixels placed symmetrically about the centre, (r + i, c + j)
/// and (r - i, c - j), predicts it by its midpoint. Midpoints are taken of q = 1/d: on a plane,
/// 1/z is affine in the normalised image coordinates, and 1/d = (1/z) r_z, whose factor r_z
/// changes only to second order across a small window, so a midpoint of 1/d is exact on a plane
/// up to that factor's curvature and the lens's distortion, where a midpoint of d is biased by
/// the distance's curvature on slanted planes (the SR-2's lens, a plane at 60°, 7x7 windows:
/// at most 1.6e-4 of the distance against 2.7e-3, neighbour_prediction_test). Pairs with a pixel
/// outside the image are not usable, so a pixel near the border uses the pairs of its window
/// that fit. Each pair's midpoint has variance (σ_a² + σ_b²) / 4 in q (σ_q = ΔL / d²), and
/// the prediction is their inverse-variance weighted mean over the window's usable pairs, with
/// σ_p = (Σ w)^-1/2. The window is the (2 R + 1)² one of `radius_px` R when every usable pair's
/// midpoint lies within `max_disagreement_sigma` of its own σ of the prediction and the window
/// has at least `min_pairs` usable pairs; else the next smaller window is tried, down to 3x3;
/// else the pixel has no prediction. A window that holds a depth step, a wrap or a strongly
/// curved surface fails that test: a step between the pixel and one side makes every pair
/// across it disagree with the pairs along it. The pixel's own reading takes no part, so the
/// prediction and the choice of window are independent of its noise draw.
///
/// A pixel is usable as support when it carries no reject bit (kRejectMask), its distance lies
/// in [0.01, 1e4] m and its ΔL in [1e-5, 100] m (within those every sum stays finite in single
/// precision). Sums are in single precision, pairs in a fixed order, so every CPU gives the same
/// bits.
///
/// **What it does not see.** An error that the pixel shares with its neighbours (a scattering
/// halo's smooth bias, multipath across a surface, a calibration error common to the region)
/// cancels in r and is invisible here, as it is to ΔL; so is anything on a pixel whose window
/// fails the test (depth edges: the uncertainty's edge terms judge those). ΔL itself is taken
/// as the readings' σ: where it underestimates the noise, σ_p does too.

#include <algorithm>
#include <cmath>
#include <limits>

#include "tofcam/core/frame.h"

namespace tofcam {

struct NeighbourPredictionOptions {
  /// R: the largest window is (2 R + 1)^2 (3 = 7x7, 24 pairs); [1, 5].
  int radius_px = 3;
  /// A window is used only when each usable pair's midpoint lies within this many of its own σ
  /// of the window's prediction; (0, 100]. At 4, a 7x7 window of pure noise with the right σ
  /// passes with probability 0.9985 (24 pairs, 6.3e-5 each beyond 4σ), and still 0.83 when ΔL
  /// underestimates the noise by 1.5x (as eq. 2 with the SR-2's noise calibration does on a
  /// dim wall: docs/beyond.md), while a depth step of many σ fails it. Measured in `tofcam
  /// experiment beyond`: F1 0.903 at 3, 0.910 at 4 and 5 (docs/beyond.md; before the frame
  /// pair's pooled two-returns check, with which it is 0.907 at 4).
  double max_disagreement_sigma = 4.0;
  /// Fewest usable pairs a window needs, the fallback windows' too; [1, 2 R (R + 1)] (the
  /// largest window's pairs). A 3x3 window has 4 pairs and a 5x5 12: above those, that window
  /// never serves as a fallback.
  int min_pairs = 2;
  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// Per pixel, the prediction and its σ; NaN where the pixel has none (no window passed the
/// test). Every pixel gets one if its window allows, usable or not.
struct NeighbourPrediction {
  Image<float> distance_m;  ///< p, m.
  Image<float> sigma_m;     ///< σ_p, m: σ_q(p) p².
};

/// The prediction for every pixel (see the file comment). Throws Error(kInvalidArgument) for bad
/// options, an empty frame, or a frame without ΔL or flags of its size.
[[nodiscard]] NeighbourPrediction PredictFromNeighbours(
    const MetricFrame& frame, const NeighbourPredictionOptions& options = {});

/// The same into `out` (resized when needed; a per-frame loop allocates nothing once sizes are
/// stable). Throws like PredictFromNeighbours, before `out` is touched.
void PredictFromNeighboursInto(const MetricFrame& frame, const NeighbourPredictionOptions& options,
                               NeighbourPrediction& out);

/// The reading's error given its residual against a prediction (see the file comment).
struct ReadingPosterior {
  double mean_error_m = 0.0;  ///< m = E[e | r], m; d - m is the combination.
  double variance_m2 = 0.0;   ///< v, m²: the combination's variance.
  /// sqrt(E[e² | r]) = sqrt(m² + v), m: how far the reading itself is expected to be off.
  [[nodiscard]] double ReadingRmsErrorM() const;
};

/// For a reading d with σ = delta_l_m and a prediction p with σ_p = sigma_p_m: e given r =
/// d - p. All arguments finite, delta_l_m and sigma_p_m > 0 (else the result is NaN). Inline:
/// the uncertainty calls it for every pixel.
[[nodiscard]] inline ReadingPosterior PosteriorOfReading(double distance_m, double delta_l_m,
                                                         double predicted_m, double sigma_p_m) {
  ReadingPosterior post;
  if (!(delta_l_m > 0.0) || !(sigma_p_m > 0.0) || !std::isfinite(distance_m) ||
      !std::isfinite(predicted_m) || !std::isfinite(delta_l_m) || !std::isfinite(sigma_p_m)) {
    post.mean_error_m = std::numeric_limits<double>::quiet_NaN();
    post.variance_m2 = std::numeric_limits<double>::quiet_NaN();
    return post;
  }
  // gain = σ² / (σ² + σ_p²) = 1 / (1 + (σ_p / σ)²) and v = σ² σ_p² / (σ² + σ_p²) = a² / (1 +
  // (a / b)²) with a = min(σ, σ_p), b = max: no square of the larger σ is formed, so finite
  // inputs give a finite v unless the smaller σ itself squares past 1e308.
  const double ratio = sigma_p_m / delta_l_m;
  const double gain = 1.0 / (1.0 + ratio * ratio);
  const double a = std::min(delta_l_m, sigma_p_m), b = std::max(delta_l_m, sigma_p_m);
  post.mean_error_m = (distance_m - predicted_m) * gain;
  post.variance_m2 = a * a / (1.0 + (a / b) * (a / b));
  return post;
}

/// The distances with every pixel that carries no reject bit and has a prediction replaced by
/// the combination of its reading and the prediction, d - m; the other pixels unchanged. ΔL is
/// not changed (the combination's σ is sqrt(v) <= ΔL; the reading's σ stays an upper bound).
/// Throws Error(kMismatch) when the prediction's size is not the frame's, Error(kInvalidArgument)
/// for a frame without ΔL or flags of its size.
[[nodiscard]] Image<float> CombineWithPrediction(const MetricFrame& frame,
                                                 const NeighbourPrediction& prediction);

/// The same into `out` (resized when needed). `out` may be the frame's own distance image;
/// Error(kInvalidArgument) when it is the frame's ΔL or one of the prediction's images.
void CombineWithPredictionInto(const MetricFrame& frame, const NeighbourPrediction& prediction,
                               Image<float>& out);

}  // namespace tofcam
