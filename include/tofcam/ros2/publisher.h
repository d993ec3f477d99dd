#pragma once
/// \file
/// Publishes the pipeline's output as ROS 2 topics over Cyclone DDS (docs/ros2.md): ROS 2's
/// topic names (rt/<namespace>/<name>), type names (sensor_msgs::msg::dds_::PointCloud2_) and
/// CDR encoding, so `ros2 topic echo`, RViz2 and rosbag2 on the same DDS domain see them. No ROS
/// installation is needed. Also listens for remote set-point commands.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "tofcam/core/camera.h"
#include "tofcam/core/image.h"
#include "tofcam/core/rgb.h"
#include "tofcam/pipeline/pipeline.h"

namespace tofcam::ros2 {

/// Where and how to publish.
struct Ros2Options {
  int domain_id = 0;  ///< DDS domain (ROS_DOMAIN_ID), [0, 232].
  /// ROS namespace of the topics: "/" or "/name[/name...]" (letters, digits, '_'), no trailing
  /// '/'. Topic `points` becomes ROS topic <namespace>/points, DDS topic rt<namespace>/points.
  std::string name_space = "/tofcam";
  /// header.frame_id of every message: the camera's optical frame (REP 103: x right, y down, z
  /// forward), non-empty.
  std::string frame_id = "tofcam_optical_frame";
  /// False: best effort, as ROS 2 sensor drivers (rclcpp::SensorDataQoS). True: reliable (the
  /// ROS 2 default profile); a reliable writer waits for slow readers within its history.
  bool reliable = false;
  int history_depth = 5;  ///< KEEP_LAST depth, [1, 1000] (SensorDataQoS: 5).

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// The DDS topic name of a ROS topic `name` in `name_space` ("rt/tofcam/points").
[[nodiscard]] std::string DdsTopicName(std::string_view name_space, std::string_view name);

/// Remote commands received since the last TakeCommands (the latest of each).
struct Ros2Commands {
  /// <namespace>/controller/target_intensity (std_msgs/Float64): the controller's I_A.
  std::optional<double> target_intensity;
  /// <namespace>/controller/integration_register (std_msgs/Int32): the register to continue
  /// from (the held register of the fixed controller, or the camera's when not controlling).
  std::optional<int> integration_register;
};

/// Controller state for the diagnostics topic.
struct Ros2ControllerState {
  std::string name;  ///< Controller name, "" when not controlling.
  double target_intensity = 0.0;
  int next_integration_register = 0;
};

/// One DDS participant with a writer per topic: points (PointCloud2), depth (Image 32FC1),
/// depth/mm (Image 16UC1), amplitude and intensity (Image 16UC1; intensity only when the camera
/// has it), false_color (Image rgb8), camera_info (CameraInfo), diagnostics (DiagnosticArray);
/// and reliable readers for the two command topics of Ros2Commands. Not thread-safe.
class Ros2Publisher {
 public:
  /// Throws Error(kInvalidArgument) for bad options, Error(kIo) when DDS cannot start (naming
  /// the DDS error; e.g. a CYCLONEDDS_URI that does not parse).
  Ros2Publisher(const Ros2Options& options, const tofcam::CameraInfo& camera);
  ~Ros2Publisher();
  Ros2Publisher(const Ros2Publisher&) = delete;
  Ros2Publisher& operator=(const Ros2Publisher&) = delete;

  /// Publishes one processed frame. Stamps: the wall-clock time at the first Publish, plus the
  /// frame's timestamp minus the first frame's (so they advance exactly as the camera's
  /// timestamps); re-anchored to the wall clock when a timestamp does not advance (a looping
  /// playback), so stamps always increase. `false_color` is published as is (any size). Throws
  /// Error(kIo) when DDS refuses a sample.
  void Publish(const PipelineResult& result, const Image<Rgb8>& false_color,
               const Ros2ControllerState& controller);

  /// Readers matched on the topic with the most of them.
  [[nodiscard]] int MatchedSubscribers() const;
  /// Waits until at least `count` readers match one of the topics (MatchedSubscribers) or
  /// `timeout_s` passes; returns whether they did.
  bool WaitForSubscribers(int count, double timeout_s);
  /// Reliable writers: waits up to `timeout_s` until matched readers acknowledged every sample
  /// (call before exiting). Best effort: returns at once.
  void Flush(double timeout_s);
  /// Takes the commands received so far (non-blocking). Commands with a non-finite value are
  /// dropped and counted in rejected_commands().
  [[nodiscard]] Ros2Commands TakeCommands();
  [[nodiscard]] std::uint64_t rejected_commands() const noexcept;
  [[nodiscard]] std::uint64_t published_frames() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tofcam::ros2
