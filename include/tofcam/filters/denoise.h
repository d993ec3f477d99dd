#pragma once
/// \file
/// Noise reduction before anything judges a pixel by its noise (not in the paper): each usable
/// pixel's distance and amplitude become the inverse-variance weighted mean over the pixels of
/// its window that lie on its own surface, and its ΔL the σ of that mean. Run before the
/// dual-frequency unwrapping it lets a pixel whose single reading is too noisy to choose its wrap
/// count choose it from the mean, as Kinect-class pipelines filter their phasors before
/// unwrapping (docs/beyond.md, "Denoising before the pair").
///
/// A pixel is usable when its distance is finite, its ΔL lies in [1e-9, 1e9] m, its amplitude
/// (if the frame has one) lies in [-1e15, 1e15] (so that no weighted sum overflows a float; a
/// camera's amplitudes are below 1e6), and it carries no reject bit (kRejectMask) other than
/// kHighDeltaL: a pixel rejected only for its noise is what this stage is for, and the caller
/// judges ΔL again afterwards (the Pipeline does). Unusable pixels are copied unchanged and are
/// nobody's support.
///
/// The support of a usable pixel with distance d and σ = ΔL is every usable pixel n of its
/// (2 r + 1)^2 window (the pixel itself included) with (d_n - d)^2 <= min(k^2 (σ^2 + σ_n^2), s^2)
/// in single precision, k = support_sigma, s = max_step_m (no limit when 0): a neighbour whose
/// reading differs from the centre's by more than k combined σ, or by more than s, lies on
/// another surface (a depth step, a wrap) and is left out. Without s, a step smaller than k
/// combined σ between two noisy surfaces would be averaged across. This is a hard cut-off, not a
/// range weight: inside it every neighbour counts by its 1 / σ² alone. With weights
/// w_n = 1 / σ_n^2:
///   distance  d + Σ w_n (d_n - d) / Σ w_n   (the weighted mean, summed as deviations from d),
///   amplitude Σ w_n A_n / Σ w_n,
///   ΔL        (Σ w_n)^(-1/2), the σ of the weighted mean of independent readings.
/// Sums are in single precision in the window's row-major order. Flags and intensity are copied.
///
/// With `fit_plane`, the distance is instead the centre's value of a plane fitted to the same
/// support with the same weights: 1/z (z = d r_z, r the pixel's unit ray) is affine in the
/// normalised image coordinates (u, v) = (r_x / r_z, r_y / r_z) on any plane, so the weighted
/// least squares of 1/z_n on (1, u_n - u, v_n - v) gives the plane's 1/z at the centre, b_0, and
///   distance  1 / (b_0 r_z),
///   ΔL        sqrt(1 / Σ w_n + m^T C^-1 m), to first order the σ of that distance,
/// with m the support's weighted mean offset (u, v) from the centre and C the offsets' weighted
/// centred sums of squares and products. On a plane, tilted or not, the fit is exact, where the
/// mean is biased by the distance's curvature across the window and, where the support is
/// lopsided, by its slope. Where the support spans two surfaces the fit is not exact either,
/// but a dim pixel beside bright neighbours of another surface is pulled less towards them: the
/// plane is fixed where they are, and the other readings set how it continues to the centre
/// (typically: measured per scene in docs/beyond.md).
/// ΔL grows where the fit extrapolates. The weights are 1 / σ_n² as for the mean: the exact
/// weights of 1/z differ by the factor (d_n^2 r_z)^2, so ΔL is off by about twice the support's
/// relative depth spread. The fit in 1/z biases a noisy plane by about σ²/d (2 mm at σ = 10 cm,
/// d = 5 m). The pixel gets the weighted mean instead where the support's pixels all lie on one
/// line of the pixel grid (fewer than three, or any lattice line); where the offsets' weighted
/// spread is too lopsided to trust the double sums' centring (det C below 1e-10 of Σ w x² Σ w y²,
/// the offsets x, y measured from the centre pixel: heavy pixels nearly on one line away from the
/// centre, the others weighing about 1e-10 of them or less; a margin of about 1e5 over where the
/// sums' rounding would show); where b_0, the distance or ΔL is not
/// positive and finite; and in every window that holds a usable pixel without a useful 1/z (a
/// distance that is not positive, or a ray 89.4° or more from the optical axis, r_z < 0.01).
/// The fit's sums are in double precision (they cancel when a few heavy neighbours dominate).
/// The amplitude stays the weighted mean. Measured in docs/beyond.md.
///
/// Neighbouring outputs share readings, so their noise is correlated, and the lowered ΔL is
/// smaller than a real step or slope between two neighbours: tests that compare such a step
/// with the neighbours' ΔL (jump edges, the uncertainty's edge term) flag more real geometry
/// after this stage than before it. On a plane facing the camera the mean over a symmetric
/// support is unbiased to within the distance's small curvature across the window (under 0.1 mm
/// at 3 m on the SR-2); on a slanted or curved surface the distance is curved across the window
/// and the mean is biased by that curvature, and at a step smaller than both limits it blends
/// within the noise.

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"

namespace tofcam {

struct DenoiseOptions {
  int radius_px = 1;           ///< Window half-size: 1 = 3x3, 2 = 5x5; [1, 3].
  double support_sigma = 3.0;  ///< k: support within k combined σ of the centre; (0, 100].
  /// s: support also within this of the centre, m; [0, 1e6], 0 = no limit (the default). A
  /// limit keeps depth steps between noisy surfaces apart, but it also leaves out a noisy
  /// pixel's own-surface neighbours that differ from its reading by more, so its mean leans
  /// towards its own reading: measured in docs/beyond.md ("Denoising before the pair").
  double max_step_m = 0.0;
  /// Fit a plane to the support instead of averaging it (see the file comment); needs the
  /// camera's rays (the overloads that take a RayTable).
  bool fit_plane = false;
  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// The three channels DenoiseInto writes, each the frame's size (amplitude empty when the frame
/// has none).
struct DenoisedChannels {
  Image<float> radial_distance_m;  ///< m; unusable pixels: the frame's value.
  Image<float> amplitude;          ///< The frame's amplitude unit; empty without one.
  Image<float> delta_l_m;          ///< m, σ of the mean; unusable pixels: the frame's ΔL.
};

/// The frame with denoised distance, amplitude and ΔL (see the file comment). Throws
/// Error(kInvalidArgument) for invalid options, options.fit_plane (it needs the rays: use the
/// overload below), an empty distance or ΔL image, or channels of different sizes.
[[nodiscard]] MetricFrame Denoise(const MetricFrame& frame, const DenoiseOptions& options);

/// The same with the camera's unit rays (each channel the frame's size; MakeRayTable), which
/// options.fit_plane needs; an empty table counts as none. Throws like the overload above, and
/// Error(kMismatch) naming the channel when the rays do not fit the frame.
[[nodiscard]] MetricFrame Denoise(const MetricFrame& frame, const RayTable& rays,
                                  const DenoiseOptions& options);

/// The denoised channels alone into `out` (resized when needed; a per-frame loop allocates nothing
/// once sizes are stable). Throws like Denoise.
void DenoiseInto(const MetricFrame& frame, const DenoiseOptions& options, DenoisedChannels& out);

/// The same with the rays: what the Pipeline uses. Throws like Denoise with rays.
void DenoiseInto(const MetricFrame& frame, const RayTable& rays, const DenoiseOptions& options,
                 DenoisedChannels& out);

}  // namespace tofcam
