#pragma once
/// \file
/// Scattering compensation (not in the paper; issue 18, docs/beyond.md). Light from a bright,
/// near object scatters inside the lens and housing and lands on every other pixel. Because a
/// ToF pixel measures a phasor Z = A e^{i 2π d / L} (amplitude and phase), the stray light adds
/// phasors: Z_measured = Z + h ⊛ Z, with h the camera's scattering point-spread (a sum of
/// Gaussian lobes whose weights are the fraction of a pixel's light each spreads). A dim far
/// wall next to a bright hand is pulled towards the hand's distance by centimetres. Subtracting
/// h ⊛ Z in the complex domain (Mure-Dubois & Hügli 2007; Kavli et al. 2008) removes the bias;
/// since h is small (a few %), the fixed-point iteration Z_{k+1} = Z_measured - h ⊛ Z_k converges
/// in a few steps. The intensity (offset) channel is scattered and compensated the same way.

#include <span>
#include <vector>

#include "tofcam/core/frame.h"

namespace tofcam {

/// One Gaussian lobe of the scattering point-spread.
struct ScatteringLobe {
  double weight = 0.0;    ///< Fraction of a pixel's light spread into the lobe, [0, 0.5).
  double sigma_px = 0.0;  ///< Standard deviation, pixels, (0, 1000].
};

struct ScatteringOptions {
  /// The point-spread h; empty = nothing to compensate. Sum of weights < 0.5 (the iteration
  /// converges for any sum below 1; more than half the light scattered is no camera).
  std::vector<ScatteringLobe> lobes;
  /// Fixed-point iterations, [1, 20]: the error after k falls like (Σ weights)^(k + 1).
  int iterations = 3;

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// `frame` with the scattered light removed from its distance, amplitude and intensity
/// registers. Pixels flagged kInvalid or kSaturated by the camera (source_flags), or with
/// amplitude 0, are left as they are and do not take part (their phasor is unknown). Light from
/// outside the image is unknown and taken as 0. Ground truth, flags, info and the confidence
/// channel are copied unchanged. Throws Error(kInvalidArgument) for bad options or a malformed
/// frame (ValidateFrame).
[[nodiscard]] Frame CompensateScattering(const Frame& frame, const ScatteringOptions& options);

/// Same into `out` (its buffers reused when they have the frame's size).
void CompensateScatteringInto(const Frame& frame, const ScatteringOptions& options, Frame& out);

/// h ⊛ image for one real channel, zero outside the image, each lobe a Gaussian approximated by
/// three box passes (exact in mean and variance; O(1) per pixel whatever sigma). Exposed for the
/// estimator and the tests.
[[nodiscard]] std::vector<float> ApplyScatteringPsf(std::span<const float> image, int width,
                                                    int height,
                                                    std::span<const ScatteringLobe> lobes);

struct ScatteringFitOptions {
  /// Candidate lobe widths, pixels (each in (0, 1000]); every pair (or single) is tried. The
  /// default: third octaves from 2 to 64 px (2^(1 + k/3), steps of 26 %).
  std::vector<double> sigma_grid_px = {2,    2.52, 3.17, 4,    5.04, 6.35, 8,    10.1,
                                       12.7, 16,   20.2, 25.4, 32,   40.3, 50.8, 64};
  /// A pixel belongs to the bright target when its amplitude with the target is at least this
  /// many times its amplitude without, (1, 1e6].
  double target_amplitude_ratio = 4.0;
  /// Pixels within this distance of the target are left out of the fit (mixed edges), [0, 64].
  int guard_px = 2;

  void Validate() const;
};

struct ScatteringFit {
  ScatteringOptions psf;  ///< The fitted lobes (one or two).
  int target_pixels = 0;  ///< Pixels of the bright target.
  int fit_pixels = 0;     ///< Background pixels the fit used.
  /// Fraction of Σ |Z_with - Z_without|² over the fit pixels that the fitted point-spread
  /// explains, [0, 1]. The sum includes the frames' noise: with few frames of a dim background
  /// it is small even when the weights are right (they are fitted over all pixels at once).
  double explained_fraction = 0.0;
};

/// Estimates the point-spread from a calibration scene shot twice at one integration time: a
/// background (e.g. a wall) `without` a bright near target, and `with` it (a white card close
/// to the lens). Outside the target, the difference of the mean phasors is the target's stray
/// light, h ⊛ (Z_target - Z_background behind it); for every pair of widths from the grid the
/// weights follow from a least squares (non-negative), and the best pair is kept. Throws
/// Error(kInvalidArgument) for bad options, frames that differ in size or integration time, no
/// target pixels or fewer than 100 usable background pixels.
[[nodiscard]] ScatteringFit EstimateScatteringPsf(std::span<const Frame> without,
                                                  std::span<const Frame> with,
                                                  const ScatteringFitOptions& options = {});

}  // namespace tofcam
