#pragma once
/// \file
/// A Camera fed by ROS 2 topics (docs/ros2.md): depth + amplitude (+ intensity) Images and a
/// CameraInfo of any ROS 2 ToF driver, over Cyclone DDS. Images of one instant are paired by
/// their header stamps; malformed samples are skipped and counted (skipped(), last_skip()).

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "tofcam/core/camera.h"
#include "tofcam/ros2/messages.h"

namespace tofcam::ros2 {

struct Ros2CameraOptions {
  int domain_id = 0;                              ///< DDS domain, [0, 232].
  std::string name_space = "/";                   ///< Namespace of the relative topic names below.
  std::string depth_topic = "depth";              ///< Image 16UC1 (mm) or 32FC1 (m).
  std::string amplitude_topic = "amplitude";      ///< Image 16UC1 / mono16 / 32FC1.
  std::string intensity_topic;                    ///< Image like amplitude; "" = none.
  std::string camera_info_topic = "camera_info";  ///< CameraInfo.
  RosFrameOptions frame;                          ///< Register conversion, model name.
  /// Seconds to wait for the first camera_info (constructor) and for each frame (Grab), (0,
  /// 3600]. Before any frame a timeout is an error; after one it ends the stream.
  double timeout_s = 5.0;
  bool reliable = false;   ///< Reader QoS: false = best effort (matches every writer).
  int history_depth = 10;  ///< KEEP_LAST depth per topic, [1, 1000].

  void Validate() const;
};

/// Options from the CLI spec `<namespace>[?key=value&...]` (the part after `ros2:`; see
/// docs/ros2.md). Keys: driver (tofcam, azure-kinect, ifm3d, royale: that driver's topic names,
/// depth axis, range and model; applied first), depth, amplitude, intensity, camera_info (topic
/// names, relative to the namespace unless they start with '/'; intensity=none for none),
/// depth_axis (z or radial), range_m, model, timeout_s, reliable (0 or 1), history (KEEP_LAST),
/// domain. `domain_id` is the domain unless the spec has one. Throws Error(kInvalidArgument)
/// naming the key for an unknown key, driver or a bad value.
[[nodiscard]] Ros2CameraOptions ParseRos2CameraSpec(const std::string& spec, int domain_id);

/// Resolves a topic against a namespace: "/abs" stays, "rel" becomes <name_space>/rel.
[[nodiscard]] std::string ResolveTopic(const std::string& name_space, const std::string& topic);

class Ros2Camera final : public Camera {
 public:
  /// Subscribes and waits for the first valid camera_info. Throws Error(kNotFound) naming the
  /// topic and domain when none arrives within timeout_s, Error(kFormat) when it is malformed
  /// (e.g. NaN intrinsics), Error(kIo) when DDS cannot start.
  explicit Ros2Camera(const Ros2CameraOptions& options);
  ~Ros2Camera() override;

  /// The next complete frame (depth, amplitude and, if configured, intensity with one stamp).
  /// Timestamps are the stamps relative to the first frame's. Throws Error(kNotFound) when no
  /// frame arrives within timeout_s before the first frame (naming what was and was not seen
  /// and the last skip reason); returns nullopt when the stream stays idle that long later.
  [[nodiscard]] std::optional<Frame> Grab() override;
  [[nodiscard]] const tofcam::CameraInfo& Info() const override;
  /// The integration time belongs to the driver: only 0 (unknown) is accepted.
  void SetIntegrationTimeRegister(int reg) override;
  [[nodiscard]] int IntegrationTimeRegister() const override { return 0; }
  void SetModulationFrequencyHz(double hz) override;
  void SetDistanceOffsetRegister(int reg) override;
  [[nodiscard]] int DistanceOffsetRegister() const override { return 0; }
  void SetPanAngleRad(double angle_rad) override;
  [[nodiscard]] double PanAngleRad() const override { return 0.0; }
  /// Makes a waiting Grab() return nullopt within half a second (and every Grab() after).
  void Interrupt() noexcept override;

  /// Samples skipped as malformed or unpaired so far, and the reason of the last one.
  [[nodiscard]] std::uint64_t skipped() const noexcept;
  [[nodiscard]] const std::string& last_skip() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tofcam::ros2
