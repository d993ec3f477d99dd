#pragma once
/// \file
/// Frames as cameras deliver them (Frame: 16-bit registers) and in metric units (MetricFrame).
/// Both are value types; organised images stay organised (one element per sensor pixel).

#include <cstdint>
#include <optional>
#include <string>

#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam {

/// Acquisition metadata of one frame.
struct FrameInfo {
  std::uint64_t sequence = 0;             ///< Frame counter since the camera was opened, from 0.
  std::int64_t timestamp_ns = 0;          ///< Mid-exposure time in ns since the camera was opened.
  int integration_time_register = 0;      ///< Raw register (SR-2: 1..255); 0 when unknown.
  double integration_time_us = 0.0;       ///< Integration time in µs (SR-2: register x 255 µs).
  double modulation_frequency_hz = 20e6;  ///< Modulation frequency, Hz (> 0).
  double pan_angle_rad = 0.0;             ///< Pan-unit angle, rad, positive = counter-clockwise.
  int distance_offset_register = 0;  ///< Camera distance-offset register (0 during calibration).
  std::string camera_model;          ///< Model name, e.g. "SR-2".
  /// False when the source has no intensity (offset) channel; `Frame::intensity` then holds
  /// zeros and the accuracy model uses its amplitude-only form.
  bool has_intensity = true;
  /// What `Frame::confidence` holds when it is not empty, one line (e.g. "MESA confidence map");
  /// empty otherwise.
  std::string confidence_source;
};

/// Ground truth a simulator attaches to each frame.
struct GroundTruth {
  /// True radial distance (m) along each pixel's central ray to the first surface; +inf where the
  /// ray hits nothing (then `causes` has kNoReturn).
  Image<float> radial_distance_m;
  /// Physical causes of error per pixel: kSaturated, kMixed, kMultipath, kScattering,
  /// kBeyondUnambiguous, kNoReturn, kMotion (see kTruthMask).
  Image<PixelFlags> causes;
  /// True per-pixel distance standard deviation (m) from the shot-noise model, 0 where unknown.
  Image<float> sigma_m;
  /// Nearest and farthest radial distance (m) at which the rays through the pixel's area (its
  /// footprint: the simulator's subsamples, over every rendering of the exposure) hit a
  /// surface; both +inf where none hits. A pixel whose footprint straddles a depth edge
  /// (kMixed) that reads one of the two surfaces measures a real surface point within half a
  /// pixel of its ray, though metres from `radial_distance_m`. Empty when the source does not
  /// give them (recordings made before they existed).
  Image<float> footprint_near_m;
  Image<float> footprint_far_m;
};

/// One frame exactly as a SwissRanger delivers it: three 16-bit register channels.
///  - distance: phase, 0..65535 mapped linearly onto [0, L) (see kDistanceRegisterSpan);
///  - amplitude: modulation amplitude, 0..65532;
///  - intensity: offset (DC level: signal plus background), 0..65532.
struct Frame {
  Image<std::uint16_t> distance;
  Image<std::uint16_t> amplitude;
  Image<std::uint16_t> intensity;
  /// Per-pixel problems the camera itself reports (e.g. a real camera's confidence bits mapped to
  /// kInvalid / kSaturated); empty when the source reports none.
  Image<PixelFlags> source_flags;
  /// The camera's own per-pixel confidence (MESA confidence map, ADI 255 - confidence byte, ...),
  /// in the camera's units but oriented so that higher means more trustworthy; >= 0, finite.
  /// Empty when the source gives none (simulator, most importers). FrameInfo::confidence_source
  /// says what it is. The noise model (tofcam/accuracy/noise_model.h) and the confidence filter
  /// (FilterSetOptions::min_confidence) read it.
  Image<float> confidence;
  FrameInfo info;
  std::optional<GroundTruth> truth;  ///< Present only when the source is a simulator.

  [[nodiscard]] int width() const noexcept { return distance.width(); }
  [[nodiscard]] int height() const noexcept { return distance.height(); }
};

/// A frame in metric units with per-pixel flags; what every pipeline stage consumes.
struct MetricFrame {
  Image<float> radial_distance_m;  ///< Radial distance along the pixel ray, m, in [0, L).
  Image<float> amplitude;          ///< Amplitude in register units (>= 0).
  /// Intensity (offset) in register units; empty when the source has no intensity channel
  /// (then the accuracy model uses its amplitude-only form).
  Image<float> intensity;
  Image<PixelFlags> flags;  ///< Problems found so far; see Flag.
  /// Predicted inaccuracy ΔL (m) per pixel (paper eq. 2); empty until the accuracy stage ran.
  Image<float> delta_l_m;
  /// The camera's own confidence (Frame::confidence), copied; empty when the source has none.
  Image<float> confidence;
  FrameInfo info;
  std::optional<GroundTruth> truth;

  [[nodiscard]] int width() const noexcept { return radial_distance_m.width(); }
  [[nodiscard]] int height() const noexcept { return radial_distance_m.height(); }
  [[nodiscard]] bool has_intensity() const noexcept { return !intensity.empty(); }
};

/// Throws Error(kInvalidArgument) unless the three channels (and truth, if any) share one size
/// and the modulation frequency is positive and finite. The truth's sigma_m and footprint may be
/// empty; the footprint's two images are both empty or both of the frame's size. `what` names the
/// frame in the message.
void ValidateFrame(const Frame& frame, const std::string& what = "frame");

}  // namespace tofcam
