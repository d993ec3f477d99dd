#pragma once
/// \file
/// Per-frame statistics of the pipeline's output (what `tofcam run` prints and writes to
/// frames.csv) and their accumulation over a run (summary.json).
///
/// Kept pixels are pixels without any kRejectMask bit. With ground truth (simulated frames) each
/// pixel is judged against the true radial distance of its ray:
///  - bad:  |measured - true| > bad_error_m, or the truth is not finite (the ray hits nothing, so
///          any distance is wrong), or the measured distance is not finite;
///  - good: every other pixel.
/// The error is the plain difference, not wrapped modulo L: a surface beyond L measured near 0 is
/// a wrong point for a robot, whatever its phase.

#include <cstdint>
#include <string>

#include "tofcam/control/integration_time_controller.h"
#include "tofcam/core/frame.h"

namespace tofcam {

struct FrameStatsOptions {
  /// A pixel is bad when its error against the truth exceeds this, m; (0, 100]. The issue's
  /// 5 cm: above the SR-2's shot noise at a good exposure (~1-2 cm), below the scattering and
  /// multipath errors the accuracy filter is meant to remove (decimetres).
  double bad_error_m = 0.05;
  /// Region, excluded flags and clipped rule of the mean intensity: the controller's
  /// (ControllerOptions roi, exclude_flags, clipped_intensity; the Pipeline copies them), so the
  /// reported Ī is the one the controller acts on (ControlledMeanIntensity).
  RegionOfInterest intensity_roi;
  std::uint16_t intensity_exclude_flags = static_cast<std::uint16_t>(Flag::kInvalid);
  double intensity_clipped = kDefaultClippedIntensity;  ///< [0, 65532]; 0 = no clipped rule.

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// Statistics of one processed frame. Fractions are in [0, 1]; NaN where the denominator is 0
/// (e.g. no kept pixel, no bad pixel) or the input is missing (no truth, no ΔL).
struct FrameStats {
  std::uint64_t sequence = 0;         ///< FrameInfo::sequence.
  double timestamp_s = 0.0;           ///< FrameInfo::timestamp_ns in seconds.
  int integration_time_register = 0;  ///< Register the frame was taken with.
  double integration_time_us = 0.0;   ///< Its integration time, µs.
  double mean_intensity = 0.0;        ///< Mean intensity (register units) the controller sees.
  int pixels = 0;                     ///< All pixels of the frame.
  int kept_pixels = 0;                ///< Pixels without a reject bit.
  double valid_fraction = 0.0;        ///< kept_pixels / pixels.
  double mean_delta_l_m = 0.0;        ///< Mean ΔL of kept pixels with finite ΔL, m.
  /// Register chosen for the next frame (set by Pipeline::Process; 0 from ComputeFrameStats).
  int next_integration_register = 0;

  bool has_truth = false;             ///< The frame carried ground truth.
  int truth_error_pixels = 0;         ///< Kept pixels with a finite error (used for the RMSE).
  double sum_squared_error_m2 = 0.0;  ///< Σ error² over those pixels, m² (for pooling).
  double rmse_m = 0.0;                ///< sqrt(sum_squared_error_m2 / truth_error_pixels), m.
  /// Σ FootprintErrorM² over the same pixels, m², when the truth has a footprint
  /// (GroundTruth::footprint_near_m / _far_m); 0 otherwise.
  double footprint_sum_squared_error_m2 = 0.0;
  /// sqrt(footprint_sum_squared_error_m2 / truth_error_pixels), m: the RMSE with a pixel that
  /// reads a surface inside its own area counted right; NaN without a footprint. <= rmse_m.
  double footprint_rmse_m = 0.0;
  int bad_pixels = 0;                 ///< Bad pixels (see the file comment).
  int bad_removed = 0;                ///< Bad pixels with a reject bit.
  int good_pixels = 0;                ///< Good pixels.
  int good_kept = 0;                  ///< Good pixels without a reject bit.
  double bad_removed_fraction = 0.0;  ///< bad_removed / bad_pixels.
  double good_kept_fraction = 0.0;    ///< good_kept / good_pixels.
};

/// A pixel's error against its footprint (GroundTruth::footprint_near_m / _far_m), m: the
/// smallest |measured - x| over the central ray's distance `truth_m` and the nearest and
/// farthest surface hit within the pixel's area; non-finite candidates are skipped. +inf when
/// no candidate is finite (nothing in the footprint is hit) or `measured_m` is NaN. A pixel at a
/// depth edge that reads one of its two surfaces measures a real surface point within half a
/// pixel of its ray, though metres from its central ray's surface: the central truth calls it
/// wrong, this one right. A reading between the two surfaces (a flying pixel) is wrong under
/// both. For a measurement that is not NaN, always <= |measured - truth|.
[[nodiscard]] double FootprintErrorM(double measured_m, double truth_m, double near_m,
                                     double far_m) noexcept;

/// Statistics of `frame` (after filtering: its flags decide what is kept). Uses `delta_l_m` when
/// present and `truth` when present. One pass over the pixels, no allocation. Throws
/// Error(kInvalidArgument) for bad options or an inconsistent frame (channels, flags or truth of
/// other sizes).
[[nodiscard]] FrameStats ComputeFrameStats(const MetricFrame& frame,
                                           const FrameStatsOptions& options = {});

/// Column names of FrameStatsCsvRow, comma separated, no newline: sequence, timestamp_s,
/// integration_register, integration_time_us, next_register, mean_intensity, kept_pixels,
/// valid_fraction, mean_delta_l_m, rmse_m, bad_pixels, bad_removed, bad_removed_fraction,
/// good_pixels, good_kept, good_kept_fraction.
[[nodiscard]] std::string FrameStatsCsvHeader();
/// One CSV row of `stats` (no newline); reals with 9 significant digits, NaN as "nan".
[[nodiscard]] std::string FrameStatsCsvRow(const FrameStats& stats);

/// Pooled statistics of a run: pixel counts are summed over frames before dividing, so a frame
/// with many pixels weighs more than a nearly empty one.
struct RunSummary {
  std::uint64_t frames = 0;
  double mean_valid_fraction = 0.0;  ///< Mean over frames of valid_fraction.
  double mean_delta_l_m = 0.0;       ///< Mean over frames of mean_delta_l_m (finite ones), m.
  double mean_intensity = 0.0;       ///< Mean over frames of mean_intensity (finite ones).
  bool has_truth = false;            ///< Every frame had ground truth.
  double rmse_m = 0.0;               ///< RMSE of kept pixels vs truth over all frames, m.
  /// The same against the footprint truth (FrameStats::footprint_rmse_m), m; NaN unless every
  /// frame with truth had a footprint.
  double footprint_rmse_m = 0.0;
  double bad_removed_fraction = 0.0;  ///< Σ bad_removed / Σ bad_pixels.
  double good_kept_fraction = 0.0;    ///< Σ good_kept / Σ good_pixels.
  std::int64_t bad_pixels = 0;
  std::int64_t good_pixels = 0;
};

/// Sums FrameStats over a run.
class RunStatsAccumulator {
 public:
  void Add(const FrameStats& stats) noexcept;
  /// The pooled summary so far (NaN fractions while a denominator is 0).
  [[nodiscard]] RunSummary Summary() const noexcept;

 private:
  std::uint64_t frames_ = 0;
  std::uint64_t truth_frames_ = 0;
  double valid_fraction_sum_ = 0.0;
  double delta_l_sum_ = 0.0;
  std::uint64_t delta_l_frames_ = 0;
  double intensity_sum_ = 0.0;
  std::uint64_t intensity_frames_ = 0;
  double squared_error_sum_ = 0.0;
  double footprint_squared_error_sum_ = 0.0;
  std::uint64_t footprint_frames_ = 0;
  std::int64_t error_pixels_ = 0;
  std::int64_t bad_pixels_ = 0;
  std::int64_t bad_removed_ = 0;
  std::int64_t good_pixels_ = 0;
  std::int64_t good_kept_ = 0;
};

}  // namespace tofcam
