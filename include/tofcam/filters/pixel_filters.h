#pragma once
/// \file
/// Per-pixel filters: each looks at one pixel at a time and raises one PixelFlags bit.
///
/// Every filter returns ONLY the flags it raises (an image of the frame's size, other bits 0);
/// the caller ORs them into the frame with MergeFlags(). Per-pixel filters judge every pixel,
/// including pixels another stage already rejected, so a pixel can carry several reasons.
/// Inputs are checked at the boundary: an empty distance image or channels of different sizes
/// throw Error(kInvalidArgument); options are validated (Validate() throws kInvalidArgument
/// naming the field).

#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam {

/// ORs `flags` into `frame.flags` (which is created, all clear, when empty). Throws
/// Error(kInvalidArgument) when `flags` is not the frame's size.
void MergeFlags(MetricFrame& frame, const Image<PixelFlags>& flags);

/// The paper's accuracy filter (section III-B): reject pixels whose predicted inaccuracy ΔL
/// (eq. 2, filled by the accuracy stage) exceeds a fixed threshold.
struct AccuracyThresholdOptions {
  /// Largest accepted ΔL, m; (0, 100]. The paper gives no number; 0.07 m is the default noise
  /// threshold of a current pmd camera (tof-notes §5), a free parameter.
  double max_delta_l_m = 0.07;
  void Validate() const;
};

/// kHighDeltaL where `delta_l_m > max_delta_l_m`; NaN, ±inf and negative ΔL count as above.
/// Throws Error(kInvalidArgument) when `frame.delta_l_m` is empty (accuracy stage not run).
[[nodiscard]] Image<PixelFlags> AccuracyThresholdFilter(const MetricFrame& frame,
                                                        const AccuracyThresholdOptions& options);

/// The vendor driver's amplitude threshold.
struct AmplitudeThresholdOptions {
  /// Smallest accepted amplitude, register units (0..65532 scale); [0, 65532]. Free parameter.
  double min_amplitude = 100.0;
  void Validate() const;
};

/// kLowAmplitude where `amplitude < min_amplitude` or the amplitude is NaN.
[[nodiscard]] Image<PixelFlags> AmplitudeThresholdFilter(const MetricFrame& frame,
                                                         const AmplitudeThresholdOptions& options);

/// Saturation from the registers. The SR-2 has no saturation bit: its amplitude and intensity
/// registers clip at 65532, and when taps clip at full well the measured amplitude collapses
/// while the offset stays high. With 4-tap demodulation the brightest tap is about
/// intensity + amplitude (offset B plus modulation A), so the rule is: a pixel is saturated when
///   intensity >= max_intensity  or  amplitude >= max_amplitude  or
///   intensity + amplitude >= max_peak.
/// The third clause catches clipped pixels whose amplitude has collapsed (the clipped tap
/// keeps B + A near full scale while A alone looks harmless); it is the "sum of both values is
/// limited by a maximum value" the paper quotes from Oggier et al. Frames without an intensity
/// channel use the amplitude clause only.
struct SaturationOptions {
  double max_intensity = 65532.0;  ///< Intensity register at which a pixel is saturated; > 0.
  double max_amplitude = 65532.0;  ///< Amplitude register at which a pixel is saturated; > 0.
  /// Brightest-tap estimate (intensity + amplitude) at which a pixel is saturated; > 0.
  /// Default 98 % of 65532: a tap within 2 % of full scale is treated as clipped.
  double max_peak = 64221.0;
  void Validate() const;
};

/// kSaturated by the rule above. NaN registers compare false and are not flagged here (the
/// amplitude filter flags a NaN amplitude).
[[nodiscard]] Image<PixelFlags> SaturationFilter(const MetricFrame& frame,
                                                 const SaturationOptions& options);

/// Range limits on the radial distance.
struct RangeOptions {
  double min_distance_m = 0.05;  ///< Smallest accepted radial distance, m; >= 0.
  double max_distance_m = 7.5;   ///< Largest accepted radial distance, m; > min_distance_m.
  void Validate() const;
};

/// kOutOfRange where the radial distance is outside [min_distance_m, max_distance_m] or NaN.
[[nodiscard]] Image<PixelFlags> RangeFilter(const MetricFrame& frame, const RangeOptions& options);

/// The camera's own confidence channel (Frame::confidence: MESA confidence map, ADI confidence
/// byte, ...) as a filter.
struct ConfidenceThresholdOptions {
  /// Pixels whose vendor confidence is below this value (camera units, oriented so that higher
  /// is better) are rejected; [0, 1e9].
  double min_confidence = 0.0;
  void Validate() const;
};

/// kLowConfidence where `frame.confidence` < min_confidence or is NaN. A frame without a
/// confidence channel (empty image) gets no flag: the filter has nothing to judge by.
[[nodiscard]] Image<PixelFlags> ConfidenceThresholdFilter(
    const MetricFrame& frame, const ConfidenceThresholdOptions& options);

/// Same, OR-ing kLowConfidence into `out` (which must have the frame's size; untouched when the
/// frame has no confidence channel).
void ConfidenceThresholdInto(const MetricFrame& frame, const ConfidenceThresholdOptions& options,
                             Image<PixelFlags>& out);

}  // namespace tofcam
