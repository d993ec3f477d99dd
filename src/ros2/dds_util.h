#pragma once
// Private helpers of tofcam::ros2 (not installed): DDS entity ownership, QoS, and copies between
// the plain C++ messages (tofcam/ros2/messages.h) and the idlc-generated C structs.

#include <dds/dds.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "diagnostic_msgs/msg/DiagnosticArray.h"
#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "std_msgs/msg/Float64.h"
#include "std_msgs/msg/Int32.h"
#include "tofcam/ros2/messages.h"

namespace tofcam::ros2::dds_internal {

/// Throws Error(kIo) "<what>: <DDS error>" when `rc` < 0; returns rc.
dds_return_t Check(dds_return_t rc, const std::string& what);

/// Owns a participant (deleting it deletes every entity it created).
class Participant {
 public:
  /// Throws Error(kInvalidArgument) for a domain outside [0, 232], Error(kIo) when DDS fails.
  explicit Participant(int domain_id);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;
  [[nodiscard]] dds_entity_t get() const noexcept { return handle_; }

 private:
  dds_entity_t handle_ = 0;
};

/// QoS: reliable or best effort, volatile, keep last `depth`.
struct QosDeleter {
  void operator()(dds_qos_t* q) const noexcept { dds_delete_qos(q); }
};
[[nodiscard]] std::unique_ptr<dds_qos_t, QosDeleter> MakeQos(bool reliable, int depth);

/// Creates the topic (type from `descriptor`) and a writer / reader on it.
[[nodiscard]] dds_entity_t CreateWriter(dds_entity_t participant,
                                        const dds_topic_descriptor_t* descriptor,
                                        const std::string& topic, const dds_qos_t* qos);
[[nodiscard]] dds_entity_t CreateReader(dds_entity_t participant,
                                        const dds_topic_descriptor_t* descriptor,
                                        const std::string& topic, const dds_qos_t* qos);

/// Nanoseconds since the epoch; throws Error(kInvalidArgument) outside builtin_interfaces/Time.
void ToC(const Header& in, std_msgs_msg_dds__Header_& out);
[[nodiscard]] Header FromC(const std_msgs_msg_dds__Header_& in);

// The C views alias the C++ messages' memory (no copy); they live as long as `in`.
void ToC(const ImageMessage& in, sensor_msgs_msg_dds__Image_& out);
void ToC(const CameraInfoMessage& in, sensor_msgs_msg_dds__CameraInfo_& out);
void ToC(const PointCloud2Message& in, std::vector<sensor_msgs_msg_dds__PointField_>& fields,
         sensor_msgs_msg_dds__PointCloud2_& out);
/// `status` and `values` hold the C arrays the view points into.
void ToC(const DiagnosticArrayMessage& in,
         std::vector<diagnostic_msgs_msg_dds__DiagnosticStatus_>& status,
         std::vector<std::vector<diagnostic_msgs_msg_dds__KeyValue_>>& values,
         diagnostic_msgs_msg_dds__DiagnosticArray_& out);

// Copies out of a received sample.
[[nodiscard]] ImageMessage FromC(const sensor_msgs_msg_dds__Image_& in);
[[nodiscard]] CameraInfoMessage FromC(const sensor_msgs_msg_dds__CameraInfo_& in);
[[nodiscard]] PointCloud2Message FromC(const sensor_msgs_msg_dds__PointCloud2_& in);

/// dds_duration_t of seconds (clamped to [0, 1e6] s).
[[nodiscard]] dds_duration_t Seconds(double s) noexcept;

}  // namespace tofcam::ros2::dds_internal
