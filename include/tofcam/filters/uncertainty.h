#pragma once
/// \file
/// A combined per-pixel uncertainty in metres and one threshold on it (not in the paper; issue
/// 18, docs/beyond.md). ΔL predicts only the noise of a pixel that sees one surface. A pixel on a
/// depth edge mixes two surfaces and may read anywhere between them: its error is bounded by the
/// jump, not by its noise. The uncertainty is
///
///   u = sqrt(ΔL² + (edge_fraction x jump)²)
///
/// with `jump` the largest distance step to a usable 4-neighbour when that step exceeds
/// `min_jump_sigma` of the two pixels' combined ΔL (smaller steps are noise or slope, not an
/// edge); with `extrapolate_edges` the edge term is instead how far the pixel leaves its own
/// side's surface, and with `unmix_edges` a pixel whose area lies mostly across a step is charged
/// the whole step. Pixels with a reject flag (saturated, inconsistent between frequencies, ...) or
/// without ΔL have u = +inf. Optionally (`unknown_neighbour_flags`) so have pixels next to a
/// clipped one or to one whose two combined frames disagree: such a neighbour sees something else
/// (far brighter and usually much nearer, or that moved) at a distance nobody knows, so the jump
/// cannot be bounded (and the camera blooms into exactly the neighbours of clipped pixels); a
/// neighbour rejected for being dark or noisy is merely no evidence. One threshold, in metres,
/// then decides.
///
/// With the neighbours' prediction (tofcam/filters/neighbour_prediction.h; the overloads below
/// that take one), ΔL in the noise term is replaced, where a pixel has a prediction, by the
/// reading's expected error given its residual against the prediction, sqrt(m² + v), or by the
/// combination's σ, sqrt(v) (`judge_combination`); the edge terms are unchanged.

#include <cstdint>

#include "tofcam/core/frame.h"
#include "tofcam/filters/neighbour_prediction.h"

namespace tofcam {

struct UncertaintyOptions {
  /// Pixels with u above this are flagged kLowConfidence, m, (0, 100].
  double max_uncertainty_m = 0.05;
  /// Part of an edge's jump counted as uncertainty, [0, 1]: a mixed pixel's reading lies
  /// between the two surfaces, half the jump away from the nearer one at worst on average.
  double edge_fraction = 0.5;
  /// Steps smaller than this many combined σ are not edges, (0, 100].
  double min_jump_sigma = 3.0;
  /// Edge term from the pixel's own side: for a step to neighbour j, the term is how far the
  /// pixel lies off the straight line through its two neighbours opposite j (0 within
  /// min_jump_sigma of that deviation's σ, sqrt(σ² + 4 σ_1² + σ_2²)), instead of edge_fraction
  /// x the step; edge_fraction x the step where those two are not usable. A pixel that
  /// continues its own surface up to the edge reads right whatever lies beyond; a mixed pixel
  /// leaves both lines. edge_fraction then applies only to the fallback. An edge blurred
  /// linearly over three or more pixels looks like a slope and gets no edge term. Measured:
  /// docs/beyond.md.
  bool extrapolate_edges = false;
  /// Unmix edge pixels: for a step to neighbour j, the pixel's phasor (amplitude, and phase
  /// 4π f d / c at the frame's modulation frequency) is taken as the mix t z_a + (1 - t) z_j of
  /// its own side's neighbour a (opposite j, usable, reading within half the step of the pixel)
  /// and of j, least squares in t: t is the share of the pixel's area (footprint) on its own
  /// side. Its reading is its own side's distance (a bright near surface outweighs a dim far
  /// one's larger area), but its centre lies on its own side only when t > 1/2 (a straight
  /// edge). So unless t is at least 1/2 + min_jump_sigma σ_t (to first order σ_t =
  /// sqrt(var_i + t² var_a + (1 - t)² var_j) / |z_a - z_j|, each phasor's variance (amplitude x
  /// ΔL x 4π f / c)²), its edge term becomes the whole step. Otherwise the term is as the other
  /// options say. j may be a pixel a filter rejected (noisy, inconsistent), not a clipped or
  /// invalid one or one of amplitude 0. A usable j must pass the edge test above, and its step
  /// must leave the line through a and the pixel by as much (min_jump_sigma σ of d_j - 2 d + d_a:
  /// on a slope t ≈ 1/2 means nothing). Nothing is decided where the phasors lie too close:
  /// within min_jump_sigma sqrt(var_i + var_a + var_j) of each other, or within 4 min_jump_sigma
  /// sqrt(var_i + var_a), where a pixel wholly on its own side would be charged by its noise
  /// (between two surfaces of one brightness, steps under 4 sqrt 2 min_jump_sigma ΔL, 17 ΔL at
  /// 3, for small ΔL, and as far from a multiple of L). Needs the frame's amplitude and a finite
  /// positive modulation frequency, else nothing is unmixed; pixels whose own or a's amplitude
  /// is not finite and positive are not unmixed. Per-pixel form only.
  /// Measured: docs/beyond.md ("Mixed pixels unmixed", "The share's noise, and slopes").
  bool unmix_edges = false;
  /// A pixel with a 4-neighbour carrying any of these flags gets u = +inf (see the file
  /// comment); 0 = none (the default). Measured (`tofcam experiment beyond`, two frequencies):
  /// kSaturated | kInconsistent lowers the kept pixels' RMSE within L from 237 to 218 mm but
  /// flags good pixels too (F1 0.804 -> 0.785); kSaturated alone changes neither much.
  std::uint16_t unknown_neighbour_flags = 0;
  /// With a neighbour prediction (tofcam/filters/neighbour_prediction.h, the overloads below
  /// that take one): where a pixel has a prediction, the noise term ΔL is replaced by
  ///  - false (the default): the reading's expected error given its residual against the
  ///    prediction, sqrt(m² + v): a reading the neighbours contradict is judged by how far it
  ///    probably is off, not by its σ;
  ///  - true: the σ of the reading's combination with the prediction, sqrt(v): for a pipeline
  ///    that delivers the combination (PipelineOptions::prediction_combine), which is then what
  ///    is judged.
  bool judge_combination = false;
  void Validate() const;
};

/// u per pixel, m (see the file comment). With `prediction` (PredictFromNeighbours of the same
/// frame; null = none), the noise term of a pixel with a prediction is as
/// `options.judge_combination` says. Throws Error(kInvalidArgument) for bad options, an empty
/// frame or one without ΔL, Error(kMismatch) for a prediction of another size.
[[nodiscard]] Image<float> ComputeUncertainty(const MetricFrame& frame,
                                              const UncertaintyOptions& options = {},
                                              const NeighbourPrediction* prediction = nullptr);

/// kLowConfidence where u > max_uncertainty_m (only the flags it raises, as every filter).
[[nodiscard]] Image<PixelFlags> UncertaintyFilter(const MetricFrame& frame,
                                                  const UncertaintyOptions& options = {},
                                                  const NeighbourPrediction* prediction = nullptr);

/// Same, into `out`: resized to the frame's size when it differs, then every pixel overwritten
/// (kLowConfidence or nothing), so a per-frame loop allocates no output image (with the default
/// options, no prediction and an AVX-512 CPU nothing at all; otherwise the u image of
/// ComputeUncertainty is still made per call, and with a prediction, `extrapolate_edges` or
/// `unmix_edges` it is computed pixel by pixel: about 16 ns a pixel against 0.9 with a
/// prediction, 22-23 ns with all three on frames without rejections, docs/benchmarks.md). `out`
/// must not be one of the frame's channels. Throws as ComputeUncertainty, before `out` is touched.
void UncertaintyFilterInto(const MetricFrame& frame, const UncertaintyOptions& options,
                           Image<PixelFlags>& out, const NeighbourPrediction* prediction = nullptr);

}  // namespace tofcam
