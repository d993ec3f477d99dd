#include "tofcam/pan/pan_view.h"

#include <cmath>
#include <limits>
#include <string>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr double kDeg = kPi / 180.0;

void Append(const PointCloud& src, bool only_valid, PointCloud& dst) {
  for (std::size_t i = 0; i < src.size(); ++i) {
    if (only_valid && !src.IsValid(i)) continue;
    dst.x.push_back(src.x[i]);
    dst.y.push_back(src.y[i]);
    dst.z.push_back(src.z[i]);
    dst.amplitude.push_back(src.amplitude[i]);
    dst.intensity.push_back(src.intensity[i]);
    dst.delta_l_m.push_back(src.delta_l_m[i]);
    dst.flags.push_back(src.flags[i]);
  }
}

}  // namespace

void PanViewOptions::Validate() const {
  const Eigen::Vector3d a = pan_unit.axis;
  if (!a.allFinite() || a.norm() < 1e-9 || !pan_unit.camera_offset_m.allFinite()) {
    throw Error(ErrorCode::kInvalidArgument, "pan view: pan_unit axis must be finite and non-zero");
  }
  // The azimuth origin is the base z axis projected perpendicular to the axis.
  if (std::abs(a.normalized().z()) > 0.999) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: pan_unit axis must not be (nearly) the optical axis z");
  }
  if (!(resolution_deg >= 0.01 && resolution_deg <= 10.0)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "pan view: resolution_deg = " + std::to_string(resolution_deg) + " is outside [0.01, 10]");
  }
  if (!(min_azimuth_deg >= -180.0 && max_azimuth_deg <= 180.0 &&
        max_azimuth_deg > min_azimuth_deg)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: azimuth range [" + std::to_string(min_azimuth_deg) + ", " +
                    std::to_string(max_azimuth_deg) + "] deg must be non-empty within ±180");
  }
  if (!(max_elevation_deg > 0.0 && max_elevation_deg <= 80.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: max_elevation_deg = " + std::to_string(max_elevation_deg) +
                    " is outside (0, 80]");
  }
  color.Validate();
}

double PanView::RowElevationRad(int row) const noexcept {
  return std::atan(max_tan_elevation - (row + 0.5) * resolution_rad);
}

PointCloud TransformPointCloud(const PointCloud& cloud, const Eigen::Isometry3d& t) {
  cloud.Validate();
  PointCloud out = cloud;
  const Eigen::Matrix3f r = t.linear().cast<float>();
  const Eigen::Vector3f o = t.translation().cast<float>();
  for (std::size_t i = 0; i < out.size(); ++i) {
    const Eigen::Vector3f p = r * Eigen::Vector3f(cloud.x[i], cloud.y[i], cloud.z[i]) + o;
    out.x[i] = p.x();
    out.y[i] = p.y();
    out.z[i] = p.z();
  }
  return out;
}

PanView MakePanView(std::span<const MetricFrame> frames, const RayTable& rays,
                    const PanViewOptions& o) {
  o.Validate();
  if (frames.empty()) throw Error(ErrorCode::kInvalidArgument, "pan view: no frames");
  PanView view;
  view.resolution_rad = o.resolution_deg * kDeg;
  view.max_azimuth_rad = o.max_azimuth_deg * kDeg;
  view.max_tan_elevation = std::tan(o.max_elevation_deg * kDeg);
  const int cols = static_cast<int>(
      std::ceil((o.max_azimuth_deg - o.min_azimuth_deg) / o.resolution_deg - 1e-9));
  const int rows =
      static_cast<int>(std::ceil(2.0 * view.max_tan_elevation / view.resolution_rad - 1e-9));
  view.panorama_distance_m = Image<float>(cols, rows, kNan);
  view.panorama_amplitude = Image<float>(cols, rows, kNan);
  Image<float> zbuffer(cols, rows, std::numeric_limits<float>::infinity());

  const Eigen::Vector3d up = o.pan_unit.axis.normalized();
  const Eigen::Vector3d z(0.0, 0.0, 1.0);
  const Eigen::Vector3d forward = (z - z.dot(up) * up).normalized();
  const Eigen::Vector3d left = up.cross(forward);
  view.cloud.height = 1;
  view.frame_offsets.push_back(0);

  for (std::size_t k = 0; k < frames.size(); ++k) {
    const MetricFrame& frame = frames[k];
    const PointCloud camera_cloud = MakePointCloud(frame, rays, o.cloud);
    const Eigen::Isometry3d pose = o.pan_unit.CameraToBase(frame.info.pan_angle_rad);
    if (!std::isfinite(frame.info.pan_angle_rad)) {
      throw Error(ErrorCode::kInvalidArgument,
                  "pan view: frame " + std::to_string(k) + " has a non-finite pan angle");
    }
    view.camera_to_base.push_back(pose);
    const PointCloud base_cloud = TransformPointCloud(camera_cloud, pose);
    Append(base_cloud, o.only_valid, view.cloud);
    view.frame_offsets.push_back(view.cloud.x.size());

    const float* d = frame.radial_distance_m.data();
    for (std::size_t i = 0; i < base_cloud.size(); ++i) {
      if (!base_cloud.IsValid(i)) continue;
      const Eigen::Vector3d p(base_cloud.x[i], base_cloud.y[i], base_cloud.z[i]);
      const double pf = p.dot(forward), pl = p.dot(left), pu = p.dot(up);
      const double rho = std::hypot(pf, pl);
      if (rho < 1e-6) continue;  // on the axis: no azimuth
      const double col = (view.max_azimuth_rad - std::atan2(pl, pf)) / view.resolution_rad;
      const double row = (view.max_tan_elevation - pu / rho) / view.resolution_rad;
      if (!(col >= 0.0 && col < cols && row >= 0.0 && row < rows)) continue;
      const int c = static_cast<int>(col), r = static_cast<int>(row);
      const float range = static_cast<float>(p.norm());
      if (range < zbuffer(r, c)) {
        zbuffer(r, c) = range;
        view.panorama_distance_m(r, c) = d[i];
        view.panorama_amplitude(r, c) = base_cloud.amplitude[i];
      }
    }
  }
  view.cloud.width = static_cast<int>(view.cloud.x.size());
  if (view.cloud.width == 0) view.cloud.height = 0;

  const double f_hz = frames[0].info.modulation_frequency_hz;
  const double far_default = (std::isfinite(f_hz) && f_hz > 0.0) ? UnambiguousRangeM(f_hz) : 0.0;
  view.panorama = FalseColorImage(view.panorama_distance_m, Image<PixelFlags>(),
                                  view.panorama_amplitude, far_default, o.color);
  return view;
}

}  // namespace tofcam
