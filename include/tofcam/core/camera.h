#pragma once
/// \file
/// The camera interface every frame source implements: the simulator (tofcam::sim), playback of
/// recordings and importers (tofcam::io). Settings that a source cannot change throw
/// Error(kUnsupported); out-of-range settings throw Error(kInvalidArgument) and leave the camera
/// unchanged.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/units.h"

namespace tofcam {

/// Static description of a camera.
struct CameraInfo {
  std::string model = "SR-2";  ///< Model name.
  CameraIntrinsics intrinsics = CameraIntrinsics::SwissRangerSr2();
  double modulation_frequency_hz = 20e6;    ///< Current modulation frequency, Hz.
  double integration_time_step_us = 255.0;  ///< µs per integration-time register step.
  double integration_time_base_us = 0.0;    ///< µs at register 0: time = base + register * step.
  int min_integration_register = 1;
  int max_integration_register = 255;
  double max_frame_rate_hz = 30.0;  ///< Upper bound of the frame rate.
  /// Dead time per frame besides integration, µs (>= 0): a frame takes at least integration +
  /// readout. 0 when the source does not say (recordings, importers).
  double readout_time_us = 0.0;
  bool has_intensity = true;      ///< False for sources without an offset channel.
  bool has_ground_truth = false;  ///< True for simulators.

  [[nodiscard]] int width() const noexcept { return intrinsics.width; }
  [[nodiscard]] int height() const noexcept { return intrinsics.height; }
  /// L = c / (2 f_mod), metres.
  [[nodiscard]] double unambiguous_range_m() const noexcept {
    return UnambiguousRangeM(modulation_frequency_hz);
  }
  /// Integration time in µs of a register value.
  [[nodiscard]] double IntegrationTimeUs(int reg) const noexcept {
    return integration_time_base_us + reg * integration_time_step_us;
  }
};

/// What a looping source (playback, imports) adds to the frames it serves again: each pass
/// continues the timestamps and sequence numbers of the pass before, one mean frame interval
/// after its last frame, so that a looped stream stays ordered in time (and a recording of it
/// can be read back: RecordingReader refuses decreasing timestamps).
struct LoopContinuation {
  std::int64_t timestamp_ns = 0;  ///< Added to every served frame's timestamp, ns.
  std::uint64_t sequence = 0;     ///< Added to every served frame's sequence number.

  /// A pass over `count` (>= 1) frames from `first` to `last` ended; the next one follows it.
  void Wrap(const FrameInfo& first, const FrameInfo& last, std::size_t count) noexcept {
    const std::int64_t span = last.timestamp_ns - first.timestamp_ns;
    const std::int64_t interval =
        count >= 2 && span > 0 ? span / static_cast<std::int64_t>(count - 1) : 0;
    timestamp_ns += (span > 0 ? span : 0) + interval;
    sequence += last.sequence >= first.sequence ? last.sequence - first.sequence + 1 : count;
  }
  /// Shifts a served frame's info into the current pass.
  void Apply(FrameInfo& info) const noexcept {
    info.timestamp_ns += timestamp_ns;
    info.sequence += sequence;
  }
};

/// A continuous-wave ToF camera.
class Camera {
 public:
  virtual ~Camera() = default;
  Camera() = default;
  Camera(const Camera&) = delete;
  Camera& operator=(const Camera&) = delete;

  /// The next frame, or nullopt at the end of a finite stream (a live camera never ends).
  /// Throws Error on device or file failure.
  [[nodiscard]] virtual std::optional<Frame> Grab() = 0;
  [[nodiscard]] virtual const CameraInfo& Info() const = 0;

  /// Integration-time register for the next frame; valid range
  /// [Info().min_integration_register, Info().max_integration_register].
  virtual void SetIntegrationTimeRegister(int reg) = 0;
  [[nodiscard]] virtual int IntegrationTimeRegister() const = 0;
  /// Modulation frequency in Hz; which values are valid depends on the model.
  virtual void SetModulationFrequencyHz(double hz) = 0;
  [[nodiscard]] double ModulationFrequencyHz() const { return Info().modulation_frequency_hz; }
  /// Camera distance-offset register (added to the distance register modulo 2^16).
  virtual void SetDistanceOffsetRegister(int reg) = 0;
  [[nodiscard]] virtual int DistanceOffsetRegister() const = 0;
  /// Pan-unit angle in radians (only for cameras on a pan unit).
  virtual void SetPanAngleRad(double angle_rad) = 0;
  [[nodiscard]] virtual double PanAngleRad() const = 0;
  /// True when SetPanAngleRad can turn the view (a camera on a pan unit, the simulator); false
  /// for sources that only report the angles they recorded.
  [[nodiscard]] virtual bool HasPanUnit() const noexcept { return false; }

  /// Makes a Grab() that is waiting for a live source's next frame return nullopt soon (within
  /// about half a second), and every later Grab() too: how a program stops while the source is
  /// silent. The one member that may be called from another thread during Grab(). Sources whose
  /// Grab() never waits long do nothing.
  virtual void Interrupt() noexcept {}
};

}  // namespace tofcam
