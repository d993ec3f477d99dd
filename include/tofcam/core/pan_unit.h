#pragma once
/// \file
/// Geometry of a pan unit (the servo of the paper's fig. 1) shared by the simulator and the
/// pan-view assembly, so both agree on what "pan angle θ" means.
///
/// The base frame is the camera frame at θ = 0 moved to the rotation centre: x right, y down,
/// z forward. The camera's optical centre sits at `camera_offset_m` from the rotation centre,
/// expressed in the rotating (camera-aligned) frame. A camera-frame point p at angle θ is, in
/// the base frame, p_base = R(axis, θ) (p + camera_offset_m). With the default axis (0, -1, 0)
/// ("up", since y points down) a positive θ turns the camera to the left.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tofcam {

struct PanUnit {
  Eigen::Vector3d axis = {0.0, -1.0, 0.0};             ///< Rotation axis in the base frame (unit).
  Eigen::Vector3d camera_offset_m = {0.0, 0.0, 0.05};  ///< Optical centre from rotation centre, m.

  /// Transform taking camera-frame points at pan angle `angle_rad` into the base frame.
  [[nodiscard]] Eigen::Isometry3d CameraToBase(double angle_rad) const {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
    t.translation() = t.linear() * camera_offset_m;
    return t;
  }
};

}  // namespace tofcam
