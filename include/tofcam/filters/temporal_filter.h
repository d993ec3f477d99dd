#pragma once
/// \file
/// Per-pixel temporal filter: a running average weighted by each measurement's predicted σ (ΔL),
/// reset where the scene changed. What camera SDKs call a temporal filter, done as the
/// minimum-variance (Kalman) update of a constant per pixel:
///   innovation  e = d_t - μ,  its σ² = v + σ_t²  (v: variance of the running mean μ)
///   z = e / sqrt(v + σ_t²)
///   |z| > reset_sigma in two frames in a row, or z beyond ±drift_sigma with one sign in
///   drift_frames frames in a row  ->  motion: μ = d_t, v = σ_t² (start again; the second
///   test catches a surface that moves slowly, e.g. a wall the robot drives towards, which a
///   lagging average would otherwise follow late);
///   |z| > reset_sigma in one frame only  ->  an outlier of the noise (0.3 % of frames at 3 σ):
///   the output is the measurement itself and the state is left alone (restarting from a 3 σ
///   outlier would pull it into the next frames' average);
///   otherwise   g = v / (v + σ_t²),  μ += g e,  v = (1 - g) v,
/// with v kept >= σ_t² / max_frames so that the average never spans more than about
/// max_frames frames (it keeps following slow drift). σ_t is the pixel's ΔL (m) in that frame
/// (fallback_sigma_m where ΔL is missing or not finite). A pixel rejected in a frame (any
/// kRejectMask bit, or a non-finite distance) is passed through unchanged and does not touch
/// its state; after more than max_gap_frames such frames in a row its state is forgotten.
/// Wrapping needs no special case: a jump by the unambiguous range is far beyond reset_sigma σ.

#include <vector>

#include "tofcam/core/frame.h"

namespace tofcam {

struct TemporalFilterOptions {
  double reset_sigma = 3.0;        ///< Motion test, in σ of the innovation; (0, 100].
  double drift_sigma = 1.5;        ///< Drift test, in σ of the innovation; (0, reset_sigma].
  int drift_frames = 3;            ///< Frames of one-signed drift that mean motion; [2, 100].
  int max_frames = 8;              ///< Longest effective average, frames; [1, 10000].
  int max_gap_frames = 2;          ///< Rejected frames before a pixel's state is forgotten; >= 0.
  double fallback_sigma_m = 0.02;  ///< σ where ΔL is missing, m; > 0.
  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// The filter for one camera; its state is one mean and variance per pixel.
class TemporalFilter {
 public:
  /// Throws Error(kInvalidArgument) for invalid options.
  explicit TemporalFilter(const TemporalFilterOptions& options = {});

  /// Filters `frame` in place: the distances of usable pixels become the running means. The
  /// first frame, and any frame of another size, starts every pixel afresh.
  void Process(MetricFrame& frame);
  /// Forgets every pixel's history (e.g. after the pan unit moved).
  void Reset();
  /// Frames averaged per pixel so far (1 after a reset), for tests and displays.
  [[nodiscard]] const std::vector<std::uint16_t>& frames_averaged() const noexcept {
    return count_;
  }
  [[nodiscard]] const TemporalFilterOptions& options() const noexcept { return options_; }

 private:
  TemporalFilterOptions options_;
  int width_ = 0, height_ = 0;
  std::vector<float> mean_m_;       // μ
  std::vector<float> variance_m2_;  // v; 0 = no state
  std::vector<std::uint16_t> count_;
  std::vector<std::uint8_t> gap_;
  std::vector<std::uint8_t> deviant_;  // 1 after a frame beyond reset_sigma
  std::vector<std::int8_t> drift_;     // signed run of frames beyond drift_sigma
};

}  // namespace tofcam
