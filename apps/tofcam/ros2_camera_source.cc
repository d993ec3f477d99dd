// Camera source `ros2:<namespace>[?key=value&...]`: depth + amplitude (+ intensity) Images and
// CameraInfo from a ROS 2 ToF driver over DDS (docs/ros2.md).
#include <memory>
#include <string>

#include "camera_source.h"
#include "tofcam/ros2/ros2_camera.h"

namespace tofcam::cli {
namespace {

std::unique_ptr<Camera> OpenRos2Camera(const std::string& rest, const CameraSourceOptions& o) {
  return std::make_unique<ros2::Ros2Camera>(ros2::ParseRos2CameraSpec(rest, o.ros2_domain));
}

TOFCAM_REGISTER_CAMERA_SOURCE(
    "ros2",
    "ros2:<namespace>[?driver=tofcam|azure-kinect|ifm3d|royale&depth=..&amplitude=..&...]  "
    "ROS 2 ToF driver topics over DDS (domain: --ros2-domain)",
    OpenRos2Camera);

}  // namespace
}  // namespace tofcam::cli
