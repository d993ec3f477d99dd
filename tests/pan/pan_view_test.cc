#include "tofcam/pan/pan_view.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

constexpr double kDeg = kPi / 180.0;

TEST(PanViewTest, PointSeenAtTwoAnglesLandsAtOnePlace) {
  const PanUnit unit;  // default: axis up, camera 5 cm in front of the rotation centre
  const Eigen::Vector3d target(0.7, -0.2, 2.0);  // base frame
  const double angles[2] = {10.0 * kDeg, 35.0 * kDeg};
  // A 2 x 1 toy camera: pixel k's ray points at the target from pose k; the other pixel of each
  // frame is rejected.
  RayTable rays{Image<float>(2, 1), Image<float>(2, 1), Image<float>(2, 1)};
  std::vector<MetricFrame> frames(2);
  for (int k = 0; k < 2; ++k) {
    const Eigen::Vector3d in_cam = unit.CameraToBase(angles[k]).inverse() * target;
    const Eigen::Vector3d ray = in_cam.normalized();
    rays.x[k] = static_cast<float>(ray.x());
    rays.y[k] = static_cast<float>(ray.y());
    rays.z[k] = static_cast<float>(ray.z());
    MetricFrame& f = frames[k];
    f.radial_distance_m = Image<float>(2, 1, static_cast<float>(in_cam.norm()));
    f.amplitude = Image<float>(2, 1, 1000.0f);
    f.flags = Image<PixelFlags>(2, 1);
    f.flags[1 - k] = Flag::kInvalid;
    f.info.pan_angle_rad = angles[k];
  }
  // The two views see the target in different directions (the camera moved).
  EXPECT_GT(std::abs(rays.x[0] - rays.x[1]), 0.3f);
  const PanView view = MakePanView(frames, rays, {});
  ASSERT_EQ(view.cloud.size(), 2u);
  ASSERT_EQ(view.frame_offsets, (std::vector<std::size_t>{0, 1, 2}));
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_NEAR(view.cloud.x[i], target.x(), 1e-5);
    EXPECT_NEAR(view.cloud.y[i], target.y(), 1e-5);
    EXPECT_NEAR(view.cloud.z[i], target.z(), 1e-5);
  }
  // Both land in the panorama cell of the target's azimuth atan2(-x, z) (left is -x).
  const double az = std::atan2(-target.x(), target.z());
  const int col = static_cast<int>((view.max_azimuth_rad - az) / view.resolution_rad);
  int filled = 0;
  for (int r = 0; r < view.panorama.height(); ++r) {
    for (int c = 0; c < view.panorama.width(); ++c) {
      if (std::isfinite(view.panorama_distance_m(r, c))) {
        ++filled;
        EXPECT_EQ(c, col);
      }
    }
  }
  EXPECT_EQ(filled, 1);
}

// A room of two coaxial vertical cylinders around the pan axis: radius 2 m where the azimuth is
// in a "band" [20k°, 20k° + 8°), radius 3 m elsewhere. Ray casting in closed form.
bool InBand(double az) {
  const double deg = az / kDeg;
  const double m = std::fmod(std::fmod(deg, 20.0) + 20.0, 20.0);
  return m < 8.0;
}

double HitCylinder(const Eigen::Vector3d& c, const Eigen::Vector3d& d, double radius) {
  // |c_xz + s d_xz| = radius, the far root (the camera is inside).
  const double a = d.x() * d.x() + d.z() * d.z();
  const double b = 2 * (c.x() * d.x() + c.z() * d.z());
  const double cc = c.x() * c.x() + c.z() * c.z() - radius * radius;
  return (-b + std::sqrt(b * b - 4 * a * cc)) / (2 * a);
}

TEST(PanViewTest, SyntheticRoomPanoramaColumnsMapToAzimuths) {
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  const RayTable rays = MakeRayTable(k);
  const PanUnit unit;
  std::vector<MetricFrame> frames;
  for (double deg : {-66.0, -22.0, 22.0, 66.0}) {  // 4 x 42.8° covers about ±87°
    MetricFrame f;
    f.radial_distance_m = Image<float>(k.width, k.height);
    f.amplitude = Image<float>(k.width, k.height, 2000.0f);
    f.flags = Image<PixelFlags>(k.width, k.height);
    f.info.pan_angle_rad = deg * kDeg;
    const Eigen::Isometry3d pose = unit.CameraToBase(f.info.pan_angle_rad);
    const Eigen::Vector3d centre = pose.translation();
    for (int r = 0; r < k.height; ++r) {
      for (int c = 0; c < k.width; ++c) {
        const Eigen::Vector3d dir =
            pose.linear() * Eigen::Vector3d(rays.x(r, c), rays.y(r, c), rays.z(r, c));
        const double s2 = HitCylinder(centre, dir, 2.0);
        const Eigen::Vector3d p2 = centre + s2 * dir;
        const double s = InBand(std::atan2(-p2.x(), p2.z())) ? s2 : HitCylinder(centre, dir, 3.0);
        f.radial_distance_m(r, c) = static_cast<float>(s);
      }
    }
    frames.push_back(std::move(f));
  }
  PanViewOptions o;
  o.resolution_deg = 0.5;
  const PanView view = MakePanView(frames, rays, o);
  EXPECT_EQ(view.panorama.width(), 360);  // 180° / 0.5°
  EXPECT_EQ(view.cloud.size(), 4u * k.width * k.height);
  const int horizon = view.panorama.height() / 2;
  EXPECT_NEAR(view.RowElevationRad(horizon), 0.0, 0.5 * kDeg);
  int checked = 0, filled = 0, covered = 0;
  for (int c = 0; c < view.panorama.width(); ++c) {
    const double az = view.ColumnAzimuthRad(c);
    if (std::abs(az) > 86.0 * kDeg) continue;
    ++covered;
    const float d = view.panorama_distance_m(horizon, c);
    if (!std::isfinite(d)) continue;
    ++filled;
    // Skip columns whose cell straddles a band edge.
    if (InBand(az - 0.3 * kDeg) != InBand(az + 0.3 * kDeg)) continue;
    ++checked;
    // The stored distance is from the camera (5 cm off the centre), so within 6 cm of the radius.
    EXPECT_NEAR(d, InBand(az) ? 2.0 : 3.0, 0.06) << "column " << c << " azimuth " << az / kDeg;
    // And the colour is that distance's false colour over [0, L].
    EXPECT_EQ(view.panorama(horizon, c), FalseColorOfDistance(d, 0.0, UnambiguousRangeM(20e6)));
  }
  EXPECT_GT(checked, 250);
  EXPECT_GE(filled, covered * 95 / 100);  // at most a few holes in the covered part
}

TEST(PanViewTest, ErrorsAreReported) {
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  const RayTable rays = MakeRayTable(k);
  EXPECT_THROW((void)MakePanView({}, rays, {}), Error);
  PanViewOptions o;
  o.resolution_deg = 0.0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.pan_unit.axis = {0, 0, 1};
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.min_azimuth_deg = 10;
  o.max_azimuth_deg = -10;
  EXPECT_THROW(o.Validate(), Error);
  std::vector<MetricFrame> frames(1);
  frames[0].radial_distance_m = Image<float>(4, 4, 1.0f);
  try {
    (void)MakePanView(frames, rays, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
}

}  // namespace
}  // namespace tofcam
