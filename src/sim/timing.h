#pragma once
// Simulator stage 6, timing (internal to tofcam::sim, docs/simulator.md): when a frame's taps are
// exposed (one rendering at mid-exposure, or one per tap when something moves), what invalidates
// a cached rendering, the pan schedule, the frame period, the per-frame noise seed and the
// time-dependent distance offsets (warm-up drift, exposure offset).

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {

/// What a rendering depends on at one time: the camera pose, the dynamic objects' poses and the
/// lamps' switch states. Two valid keys that compare equal give the same rendering.
struct RenderKey {
  Eigen::Matrix<double, 3, 4> camera;
  std::vector<double> objects;  ///< flattened dynamic object poses, 12 per object
  std::vector<char> lamps;
  bool valid = false;
  bool operator==(const RenderKey& o) const {
    return valid && o.valid && camera == o.camera && objects == o.objects && lamps == o.lamps;
  }
};
/// The key of the scene at `time_s` and pan angle `pan_rad`; `dynamic[i]` tells whether object i
/// moves.
[[nodiscard]] RenderKey MakeRenderKey(const Scene& scene, const std::vector<char>& dynamic,
                                      double time_s, double pan_rad);

/// Whether a rigid pose (3 x 4 [R | t]) moved by more than threshold_m between a and b: the
/// translation plus the rotation measured at a 5 m lever arm (||R_a - R_b||_F / sqrt 2, about
/// the angle for small angles).
[[nodiscard]] bool PoseMoved(const Eigen::Matrix<double, 3, 4>& a,
                             const Eigen::Matrix<double, 3, 4>& b, double threshold_m);
/// Whether the camera or any dynamic object moves by more than threshold_m between the keys of
/// an exposure's start and end: then each tap is rendered at its own time.
[[nodiscard]] bool MovesDuringExposure(const RenderKey& start, const RenderKey& end,
                                       double threshold_m);
/// Render time of tap slot s (0..3) of an exposure [start_s, start_s + t_int_s]: the middle of
/// its quarter when split, else mid-exposure.
[[nodiscard]] inline double TapTimeS(double start_s, double t_int_s, bool split, int s) {
  return split ? start_s + (s + 0.5) * t_int_s / 4 : start_s + t_int_s / 2;
}

/// Pan angle (rad) of a schedule at time_s: linear between keys, held before the first and after
/// the last; 0 for an empty schedule.
[[nodiscard]] double PanAngleAtRad(const std::vector<PanKey>& schedule, double time_s);

/// Time from one exposure start to the next, s: max(1 / max frame rate, t_int + readout).
[[nodiscard]] double FramePeriodS(const CameraModel& model, double t_int_s);

/// Seed of frame `sequence`'s random streams for the camera seed.
[[nodiscard]] inline std::uint64_t FrameSeed(std::uint64_t seed, std::uint64_t sequence) {
  return seed * 0x9E3779B97F4A7C15ull + sequence * 0xD1B54A32D192ED03ull;
}

/// Warm-up drift (m) at time_s after opening a camera that had been on for power_on_time_s:
/// warmup_amplitude_m exp(-(power_on + t) / warmup_time_constant_s).
[[nodiscard]] double WarmupOffsetM(const CameraModel& model, double power_on_time_s, double time_s);
/// Distance shift (m) with integration time: exposure_offset_m_per_ms * t_int.
[[nodiscard]] inline double ExposureOffsetM(const CameraModel& model, double t_int_us) {
  return model.exposure_offset_m_per_ms * t_int_us * 1e-3;
}

}  // namespace tofcam::sim::internal
