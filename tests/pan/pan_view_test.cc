#include "tofcam/pan/pan_view.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "pan/pan_cells.h"      // internal: the cell definition (src/pan)
#include "tofcam/core/error.h"
#include "tofcam/core/pixel_flags.h"
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

// The view by its definition, point by point: the whole-cloud transform, libm atan2 and hypot
// for the cell, and in each cell the point with the smallest squared distance from the rotation
// centre (in double; the first of equals). The fast version must give the same cloud bit for
// bit and the same panorama cells (its double-precision azimuth is within 1e-10 rad of libm's, so
// a point would have to lie within that of a cell border to land elsewhere).
struct Reference {
  PointCloud cloud;
  Image<float> distance, amplitude;
};
Reference ReferenceView(const std::vector<MetricFrame>& frames, const RayTable& rays,
                        const PanViewOptions& o, int cols, int rows) {
  Reference ref;
  ref.distance = Image<float>(cols, rows, std::nanf(""));
  ref.amplitude = Image<float>(cols, rows, std::nanf(""));
  Image<double> zbuffer(cols, rows, std::numeric_limits<double>::infinity());
  const double res = o.resolution_deg * kDeg, max_az = o.max_azimuth_deg * kDeg;
  const double max_tan = std::tan(o.max_elevation_deg * kDeg);
  const Eigen::Vector3d up = o.pan_unit.axis.normalized(), z(0, 0, 1);
  const Eigen::Vector3d forward = (z - z.dot(up) * up).normalized(), left = up.cross(forward);
  for (const MetricFrame& frame : frames) {
    const PointCloud base = TransformPointCloud(MakePointCloud(frame, rays, o.cloud),
                                                o.pan_unit.CameraToBase(frame.info.pan_angle_rad));
    for (std::size_t i = 0; i < base.size(); ++i) {
      const bool valid = base.IsValid(i);
      if (valid || !o.only_valid) {
        ref.cloud.x.push_back(base.x[i]);
        ref.cloud.y.push_back(base.y[i]);
        ref.cloud.z.push_back(base.z[i]);
        ref.cloud.amplitude.push_back(base.amplitude[i]);
        ref.cloud.intensity.push_back(base.intensity[i]);
        ref.cloud.delta_l_m.push_back(base.delta_l_m[i]);
        ref.cloud.flags.push_back(base.flags[i]);
      }
      if (!valid) continue;
      const Eigen::Vector3d p(base.x[i], base.y[i], base.z[i]);
      const double pf = p.dot(forward), pl = p.dot(left), pu = p.dot(up);
      const double rho = std::hypot(pf, pl);
      if (rho < 1e-6) continue;
      const double col = (max_az - std::atan2(pl, pf)) / res;
      const double row = (max_tan - pu / rho) / res;
      if (!(col >= 0.0 && col < cols && row >= 0.0 && row < rows)) continue;
      const int c = static_cast<int>(col), r = static_cast<int>(row);
      const double range2 = p.x() * p.x() + p.y() * p.y() + p.z() * p.z();
      if (range2 < zbuffer(r, c)) {
        zbuffer(r, c) = range2;
        ref.distance(r, c) = frame.radial_distance_m.data()[i];
        ref.amplitude(r, c) = base.amplitude[i];
      }
    }
  }
  return ref;
}

// Same values bit for bit (so NaN equals NaN).
bool SameBits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// Every channel of two clouds bit for bit (so NaN equals NaN).
void ExpectSameChannels(const PointCloud& a, const PointCloud& b) {
  EXPECT_TRUE(SameBits(a.x, b.x));
  EXPECT_TRUE(SameBits(a.y, b.y));
  EXPECT_TRUE(SameBits(a.z, b.z));
  EXPECT_TRUE(SameBits(a.amplitude, b.amplitude));
  EXPECT_TRUE(SameBits(a.intensity, b.intensity));
  EXPECT_TRUE(SameBits(a.delta_l_m, b.delta_l_m));
  EXPECT_EQ(a.flags, b.flags);
}

TEST(PanViewTest, SameViewAsTheStraightforwardAssembly) {
  // The SR-2's optics on 161 x 123 pixels: 19803 points a frame, four chunks of 4096 and one of
  // 3419 (not a multiple of 8): the append's vector blocks and its scalar tail both run.
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.width = 161;
  k.height = 123;
  k.cx_px = 80.0;
  k.cy_px = 61.0;
  const RayTable rays = MakeRayTable(k);
  std::vector<MetricFrame> frames;
  std::uint32_t h = 12345;
  auto next = [&h] {  // a small LCG: reproducible distances and flags
    h = h * 1664525u + 1013904223u;
    return static_cast<double>(h >> 8) / 16777216.0;
  };
  for (double deg : {-60.0, -30.0, 0.0, 30.0, 60.0}) {
    MetricFrame f;
    f.radial_distance_m = Image<float>(k.width, k.height);
    f.amplitude = Image<float>(k.width, k.height);
    f.flags = Image<PixelFlags>(k.width, k.height);
    f.delta_l_m = Image<float>(k.width, k.height);
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      f.radial_distance_m.data()[i] = static_cast<float>(0.3 + 6.0 * next());
      f.amplitude.data()[i] = static_cast<float>(100 + 1000 * next());
      f.delta_l_m.data()[i] = static_cast<float>(0.1 * next());
      // Runs of kept and rejected pixels of every length, so the append meets every mask.
      if (next() < (i / 512 % 2 == 0 ? 0.1 : 0.6)) f.flags.data()[i].Set(Flag::kLowAmplitude);
      if (i % 997 == 0) f.radial_distance_m.data()[i] = std::nanf("");
    }
    f.info.pan_angle_rad = deg * kDeg;
    frames.push_back(std::move(f));
  }
  // The last frame without flags (all its points count; missing channels become NaN / clear).
  frames.back().flags = Image<PixelFlags>();
  // The default 0.5° strip has more cells than a frame has points, the 2° strip 6.5 points of a
  // frame per cell (both the branch-free splat), the 5° strip 39 (the splat with a branch: more
  // than 12). All points kept, too.
  // Both forms: the fused AVX-512 pass where the CPU has it, and the portable loops.
  for (const bool portable : {false, true}) {
    for (const double resolution_deg : {0.5, 2.0, 5.0}) {
      for (const bool only_valid : {true, false}) {
        SCOPED_TRACE(testing::Message() << resolution_deg << " deg, only_valid " << only_valid
                                        << (portable ? ", portable" : ", AVX-512 if available"));
        const internal::PortableFormsForTesting forms(portable);
        PanViewOptions o;
        o.resolution_deg = resolution_deg;
        o.only_valid = only_valid;
        const PanView view = MakePanView(frames, rays, o);
        const Reference ref = ReferenceView(frames, rays, o, view.panorama_distance_m.width(),
                                            view.panorama_distance_m.height());
        ASSERT_EQ(view.cloud.size(), ref.cloud.x.size());
        ExpectSameChannels(view.cloud, ref.cloud);
        int filled = 0;
        for (std::size_t i = 0; i < ref.distance.size(); ++i) {
          const float a = view.panorama_distance_m.data()[i], b = ref.distance.data()[i];
          if (std::isnan(b)) {
            EXPECT_TRUE(std::isnan(a)) << i;
            continue;
          }
          ++filled;
          EXPECT_EQ(a, b) << i;
          EXPECT_EQ(view.panorama_amplitude.data()[i], ref.amplitude.data()[i]) << i;
        }
        // Most of the strip the five frames cover is filled.
        EXPECT_GT(filled, static_cast<int>(view.panorama_distance_m.size() / 3));
      }
    }
  }
}

TEST(PanViewTest, PointJustOutsideTheStripTakesNoCell) {
  // A point a hair (5e-7 rad) beyond the strip's left edge, in its top row: the float cell loop
  // cannot tell which side it is on and leaves it to the double definition, which puts it
  // outside. It must land in no cell; in particular not in cell 0 (the top-left one), where the
  // splat parks points without a cell under a key that never wins.
  const PanViewOptions o;  // 0.5°, azimuth ±90°, elevation ±30°
  const Eigen::Vector3d up = o.pan_unit.axis.normalized(), z(0.0, 0.0, 1.0);
  const Eigen::Vector3d forward = (z - z.dot(up) * up).normalized(), left = up.cross(forward);
  internal::PanStrip strip{};
  for (int i = 0; i < 3; ++i) {
    strip.forward[i] = forward[i];
    strip.left[i] = left[i];
    strip.up[i] = up[i];
  }
  strip.max_azimuth_rad = o.max_azimuth_deg * kDeg;
  strip.max_tan_elevation = std::tan(o.max_elevation_deg * kDeg);
  strip.inv_resolution = 1.0 / (o.resolution_deg * kDeg);
  strip.cols = 360;
  strip.rows = 133;
  const double az = strip.max_azimuth_rad + 5e-7;
  const double t = strip.max_tan_elevation - 0.5 * o.resolution_deg * kDeg;
  const Eigen::Vector3d edge = 0.8 * (std::cos(az) * forward + std::sin(az) * left + t * up);
  const Eigen::Vector3d middle = 2.0 * forward + 0.3 * left;  // an ordinary point
  const Eigen::Isometry3d pose = o.pan_unit.CameraToBase(0.0);
  RayTable rays{Image<float>(2, 1), Image<float>(2, 1), Image<float>(2, 1)};
  MetricFrame f;
  f.radial_distance_m = Image<float>(2, 1);
  f.amplitude = Image<float>(2, 1, 500.0f);
  f.flags = Image<PixelFlags>(2, 1);
  f.info.pan_angle_rad = 0.0;
  for (int k = 0; k < 2; ++k) {
    const Eigen::Vector3d in_cam = pose.inverse() * (k == 0 ? edge : middle);
    const Eigen::Vector3d ray = in_cam.normalized();
    rays.x[k] = static_cast<float>(ray.x());
    rays.y[k] = static_cast<float>(ray.y());
    rays.z[k] = static_cast<float>(ray.z());
    f.radial_distance_m[k] = static_cast<float>(in_cam.norm());
  }
  for (const bool portable : {false, true}) {
    SCOPED_TRACE(portable ? "portable" : "AVX-512 if available");
    const internal::PortableFormsForTesting forms(portable);
    const PanView view = MakePanView(std::span<const MetricFrame>(&f, 1), rays, o);
    ASSERT_EQ(view.cloud.size(), 2u);
    ASSERT_EQ(view.panorama_distance_m.width(), strip.cols);
    ASSERT_EQ(view.panorama_distance_m.height(), strip.rows);
    // Premise: the float loop leaves the edge point undecided, and it is outside the strip.
    std::int32_t cell = 0;
    const std::uint8_t valid = 1;
    EXPECT_EQ(internal::PanCells(1, strip, &view.cloud.x[0], &view.cloud.y[0], &view.cloud.z[0],
                                 &valid, &cell),
              1u);
    EXPECT_EQ(cell, internal::kNoCell);
    EXPECT_TRUE(std::isnan(view.panorama_distance_m(0, 0)));
    int filled = 0;
    for (std::size_t i = 0; i < view.panorama_distance_m.size(); ++i) {
      filled += std::isfinite(view.panorama_distance_m.data()[i]) ? 1 : 0;
    }
    EXPECT_EQ(filled, 1);  // the middle point only
  }
}

// Everything a view holds, compared field by field.
void ExpectSameView(const PanView& a, const PanView& b) {
  EXPECT_EQ(a.cloud.width, b.cloud.width);
  EXPECT_EQ(a.cloud.height, b.cloud.height);
  ExpectSameChannels(a.cloud, b.cloud);
  EXPECT_EQ(a.frame_offsets, b.frame_offsets);
  ASSERT_EQ(a.camera_to_base.size(), b.camera_to_base.size());
  for (std::size_t k = 0; k < a.camera_to_base.size(); ++k) {
    EXPECT_TRUE(a.camera_to_base[k].isApprox(b.camera_to_base[k], 0.0));
  }
  ASSERT_TRUE(a.panorama_distance_m.SameSize(b.panorama_distance_m));
  for (std::size_t i = 0; i < a.panorama_distance_m.size(); ++i) {
    const float x = a.panorama_distance_m.data()[i], y = b.panorama_distance_m.data()[i];
    EXPECT_TRUE((std::isnan(x) && std::isnan(y)) || x == y) << i;
  }
  ASSERT_TRUE(a.panorama.SameSize(b.panorama));
  for (std::size_t i = 0; i < a.panorama.size(); ++i) {
    EXPECT_EQ(a.panorama.data()[i], b.panorama.data()[i]) << i;
  }
  EXPECT_EQ(a.resolution_rad, b.resolution_rad);
}

TEST(PanViewTest, ReusedViewEqualsAFreshOne) {
  // A view reused for another sweep (fewer frames, other distances, all points kept, then a
  // coarser strip) must hold exactly what a fresh MakePanView gives: nothing of the previous
  // sweep may survive in the cloud, the offsets, the poses or the panorama.
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  const RayTable rays = MakeRayTable(k);
  auto sweep = [&](std::vector<double> degrees, float base_m) {
    std::vector<MetricFrame> frames;
    for (double deg : degrees) {
      MetricFrame f;
      f.radial_distance_m = Image<float>(k.width, k.height, base_m);
      f.amplitude = Image<float>(k.width, k.height, 1000.0f);
      f.flags = Image<PixelFlags>(k.width, k.height);
      for (std::size_t i = 0; i < f.radial_distance_m.size(); i += 7) {
        f.radial_distance_m.data()[i] = base_m + 0.001f * static_cast<float>(i % 1000);
        if (i % 3 == 0) f.flags.data()[i].Set(Flag::kLowAmplitude);
      }
      f.info.pan_angle_rad = deg * kDeg;
      f.info.modulation_frequency_hz = 20e6;
      frames.push_back(std::move(f));
    }
    return frames;
  };
  const std::vector<MetricFrame> first = sweep({-60, -30, 0, 30, 60}, 2.0f);
  const std::vector<MetricFrame> second = sweep({-20, 40}, 4.5f);
  PanViewOptions o;
  PanView reused;
  MakePanViewInto(first, rays, o, reused);
  ExpectSameView(reused, MakePanView(first, rays, o));
  o.only_valid = false;
  MakePanViewInto(second, rays, o, reused);
  ExpectSameView(reused, MakePanView(second, rays, o));
  o.resolution_deg = 1.0;
  MakePanViewInto(first, rays, o, reused);
  ExpectSameView(reused, MakePanView(first, rays, o));
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
  o = {};
  o.resolution_deg = 0.01;  // 36000 x 6616 cells over 360° x ±30°: too many
  o.min_azimuth_deg = -180;
  o.max_azimuth_deg = 180;
  EXPECT_THROW(o.Validate(), Error);
  o.max_azimuth_deg = -170;  // 1000 x 6616: fine
  EXPECT_NO_THROW(o.Validate());
  o = {};
  o.resolution_deg = 10;  // no column: 1e-9° of azimuth at 10° a cell
  o.min_azimuth_deg = 0;
  o.max_azimuth_deg = 1e-9;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.max_elevation_deg = 1e-9;  // no row
  o.resolution_deg = 10;
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
