#pragma once
/// \file
/// Two frames of one scene taken back to back, combined per pixel (not in the paper; issue 18,
/// docs/beyond.md):
///  - at two modulation frequencies (e.g. 20 and 17 MHz): **dual-frequency unwrapping**. Each
///    frame knows its distance only modulo its L; the pair of wrap counts (n1, n2) that makes
///    d1 + n1 L1 and d2 + n2 L2 agree best gives the distance up to the pair's much longer
///    unambiguous range (c / (2 gcd(f1, f2)): 150 m for 20/17 MHz, capped at `max_range_m`);
///  - at one frequency and two integration times: **HDR**. Where one exposure clipped the other
///    is used; where both are good they are averaged with weights 1/σ² (σ = each frame's ΔL).
/// Either way, a pixel whose two distances disagree by more than `max_disagreement_sigma`
/// combined standard deviations (motion between the frames, multipath that differs between
/// frequencies, a wrong wrap count) is flagged kInconsistent; where they agree the pixel's ΔL
/// becomes the combined σ. With two frequencies, a disagreement of at most `max_motion_m` that
/// leaves the wrap count certain is taken as motion instead: the current frame's own reading,
/// unwrapped, is delivered with its own ΔL. A pixel is also flagged kInconsistent when its
/// amplitude per µs changed by more than `max_amplitude_ratio` (it saw two surfaces) and, with
/// two frequencies, when a second pair of wrap counts also agrees within the tolerance (noise too
/// large to tell the pairs apart: ambiguous) or its two amplitudes disagree beyond their noise
/// (`max_amplitude_disagreement_sigma`: it sums two returns, a mixed pixel or two-path
/// multipath), or when that evidence and the distances' difference, pooled over a window of its
/// own surface, both depart from one return's (`two_returns_radius_px`: multipath over a
/// region).
///
/// Single-frequency wrap detection (WrapCheckFilter) is the fallback where only one frequency
/// exists.

#include <optional>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"

namespace tofcam {

struct FramePairOptions {
  /// Largest distance the unwrapping considers, m, (0, 1000]. Capped at the pair's own
  /// unambiguous range.
  double max_range_m = 30.0;
  /// Disagreement, in combined σ (sqrt(ΔL1² + ΔL2²)), beyond which a pixel is kInconsistent,
  /// (0, 1000].
  double max_disagreement_sigma = 4.0;
  /// Absolute floor of that tolerance, m, [0, 10]: registers quantise and ΔL can be tiny on
  /// bright pixels.
  double min_tolerance_m = 0.01;
  /// Largest ratio of the two frames' amplitudes per µs of integration time, [1, 1e6]; 0 = no
  /// check. One surface returns the same amplitude per µs in both frames (at either frequency,
  /// within the demodulation contrast's few %); a larger ratio means the pixel saw two surfaces
  /// (something moved between the frames), whose distances no wrap count or average can
  /// reconcile: kInconsistent. Frames of different exposure without a known
  /// FrameInfo::integration_time_us are not checked.
  double max_amplitude_ratio = 2.0;
  /// Two frequencies only: largest disagreement of the two amplitudes per µs, in combined σ of
  /// the log amplitude (σ_lnA = 2π ΔL / L per frame, as phasor noise is isotropic), after the
  /// pair's median ratio is divided out (the demodulation contrast differs by frequency), [0,
  /// 1000]; 0 = no check. One surface returns the same amplitude at both frequencies; a pixel
  /// that sums two returns (a mixed pixel at a depth edge, two-path multipath) does not, since
  /// the phase difference of its returns differs by frequency, and its distance is then wrong
  /// at both: kInconsistent. A floor of `min_amplitude_tolerance` (relative) applies. With
  /// fewer than 64 pixels good in both frames the median is not estimated (ratio 1 assumed).
  double max_amplitude_disagreement_sigma = 3.0;
  /// Floor of that tolerance as a relative amplitude difference, [0, 1].
  double min_amplitude_tolerance = 0.02;
  /// Two frequencies only: largest motion between the two frames, m, [0, 10]; 0 = off. Where
  /// the two unwrapped distances disagree beyond their tolerance by at most this much and no
  /// other pair of wrap counts comes within it, the wrap count is certain and the disagreement
  /// is motion (a robot's 2.5 cm per frame at 0.75 m/s and 30 frames/s is tens of σ for a bright
  /// pixel): the current frame's reading, unwrapped, is delivered with its own ΔL instead of the
  /// pixel being flagged kInconsistent. The amplitude checks (moved, two returns) still flag.
  /// For a motion m, wrong pairs lie |L1 - L2| - m or more away, so every motion up to the bound
  /// (capped at |L1 - L2| / 2) finds its own pair. A jump m beyond it (a pixel that switched
  /// surfaces) stays kInconsistent unless |m - k |L1 - L2|| falls within the bound for some
  /// k >= 1 (1.07-1.57 m for 20/17 MHz at the default 0.25 m, 7.5 m/s at 30 frames/s): then it
  /// takes a wrong wrap count unless its amplitude change flags it. Measured in `tofcam
  /// experiment beyond` (docs/beyond.md).
  double max_motion_m = 0.25;
  /// Two frequencies only: radius, px, of the window over which the two-returns check also
  /// pools its evidence, [0, kMaxTwoReturnsRadiusPx]; 0 = per pixel only. Multipath sums the
  /// same two paths over whole regions, so a region's amplitude ratio and the difference of its
  /// two unwrapped distances are off by about the same in every pixel: within one pixel's noise,
  /// but many σ of a window's inverse-variance mean. A pixel is then also kInconsistent when,
  /// over the window's pixels on its own surface (unwrapped distances within
  /// `max_disagreement_sigma` combined ΔL, floor `min_tolerance_m`), **both** means depart beyond
  /// `max_amplitude_disagreement_sigma` of their σ:
  ///  - the log amplitude ratio, corrected for each pixel's change of distance between the
  ///    frames (amplitude ∝ 1/d²) and less the median of that over the frame (floor
  ///    `min_amplitude_tolerance`);
  ///  - the two distances' difference (floor `min_tolerance_m`).
  /// Motion moves the distances alone; in-camera scattering's residue and a contrast that varies
  /// over the image move the ratio alone. Pixels whose distances disagree beyond motion, whose
  /// wrap count is ambiguous or whose amplitude moved do not contribute; a pixel whose window
  /// holds fewer than 2 x radius + 1 contributing readings (no region) is left to the per-pixel
  /// check. The means assume
  /// independent readings: denoised ones (PipelineOptions::denoise) share their neighbours',
  /// and the pipeline refuses the two together. Measured in `tofcam experiment beyond`
  /// (docs/beyond.md, "Multipath found over regions"). With fewer than 64 contributors the
  /// ratio's reference is the per-pixel check's median; a pixel whose weights would overflow
  /// the float sums (ΔL below about 1e-18 m) neither contributes nor is judged.
  int two_returns_radius_px = 3;
  /// Largest `two_returns_radius_px`, px: an 11x11 window.
  static constexpr int kMaxTwoReturnsRadiusPx = 5;

  void Validate() const;
};

/// Combines `current` with `previous` in place (see the file comment). Needs ΔL in both frames
/// (the pipeline's accuracy stage). Pixels with a reject flag in one frame take the other's
/// value and flags minus that frame's reject bits (HDR: a clipped pixel is replaced) — except
/// with two frequencies, where one frame alone cannot be unwrapped: such pixels keep their
/// flags and get kInconsistent. With two frequencies a kInconsistent pixel good in both frames
/// delivers its current reading unwrapped, with its own ΔL. Throws Error(kInvalidArgument) for bad
/// options, empty ΔL, frames of different sizes, or a modulation frequency outside (0, 1 GHz].
void CombineFramePair(const MetricFrame& previous, MetricFrame& current,
                      const FramePairOptions& options = {});

/// A stateful wrapper for a stream that alternates frequencies or exposures: Process(frame)
/// combines each frame with the one before when the two differ in modulation frequency or (with
/// `pair_exposures`) in integration time and returns true; the first frame of a stream, frames
/// of another size than the one before and frames whose settings repeat the previous are passed
/// through (false).
class FramePairCombiner {
 public:
  /// `pair_exposures` false: only frames at different modulation frequencies are combined (a
  /// stream whose exposure changes for other reasons, e.g. a controller's step, is not HDR).
  /// Throws Error(kInvalidArgument) for bad options.
  explicit FramePairCombiner(const FramePairOptions& options = {}, bool pair_exposures = true);
  bool Process(MetricFrame& frame);
  void Reset() { previous_.reset(); }

 private:
  FramePairOptions options_;
  bool pair_exposures_ = true;
  std::optional<MetricFrame> previous_;  // the last frame as it came in (before combining)
  MetricFrame spare_;  // the incoming frame's copy; swapped with previous_, so no allocation
};

struct WrapCheckOptions {
  /// Quantile of A d² over the valid pixels taken as the brightest surface's value, (0, 1].
  double envelope_quantile = 0.99;
  /// A pixel is flagged when its A d² is below margin x envelope x (d / (d + L))², (0, 10].
  /// Above 1 so that a wrapped surface as bright as the brightest one is caught (at 1 it sits
  /// exactly on the line); the price: near surfaces darker than margin x (d / (d + L))² of the
  /// brightest (at 2 m: 7 % with 1.5) are flagged too.
  double margin = 1.5;
  void Validate() const;
};

/// Single-frequency wrap detection: a Lambertian surface's amplitude falls like cos θ / d², so
/// A d² / cos θ measures its albedo (times one gain for the whole frame); θ, the angle between the
/// pixel's ray and the surface normal, comes from the neighbours' points (the neighbourhood cue;
/// floored at cos θ = 0.2). A surface whose true distance is d + L but which reads d is darker by
/// (d / (d + L))² than the same surface unwrapped; pixels darker than the frame's brightest
/// surface (its `envelope_quantile`) by that factor are either wrapped or very dark, and are
/// flagged kInconsistent. Returns only the flags it raises (as every filter). Pixels with a
/// reject flag are not judged. `rays` must have the frame's size (kMismatch otherwise).
[[nodiscard]] Image<PixelFlags> WrapCheckFilter(const MetricFrame& frame, const RayTable& rays,
                                                const WrapCheckOptions& options = {});

}  // namespace tofcam
