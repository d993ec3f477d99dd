#include "tofcam/core/camera_intrinsics.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

constexpr double kDeg = 180.0 / kPi;

CameraIntrinsics Distorted() {
  // Azure-Kinect-like rational lens, strong enough that undistortion needs iteration.
  CameraIntrinsics k;
  k.width = 640;
  k.height = 576;
  k.fx_px = 504.0;
  k.fy_px = 504.2;
  k.cx_px = 321.3;
  k.cy_px = 329.6;
  k.k1 = 0.57;
  k.k2 = -0.01;
  k.k3 = -0.004;
  k.k4 = 0.9;
  k.k5 = 0.11;
  k.k6 = -0.02;
  k.p1 = 5e-5;
  k.p2 = -2e-5;
  return k;
}

TEST(CameraIntrinsicsTest, Sr2FieldOfViewMatchesDatasheet) {
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  EXPECT_NO_THROW(k.Validate());
  // tof-notes §3: SR-2 field of view ≈ 42.8° x 46.0°.
  EXPECT_NEAR(k.HorizontalFovRad() * kDeg, 42.8, 0.5);
  EXPECT_NEAR(k.VerticalFovRad() * kDeg, 46.0, 0.5);
  // Focal lengths from 8 mm over the pixel pitch.
  EXPECT_NEAR(k.fx_px, 204.08, 0.01);
  EXPECT_NEAR(k.fy_px, 145.99, 0.01);
}

TEST(CameraIntrinsicsTest, ProjectHandComputedPinhole) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  // (1, 0.5, 2) m: normalised (0.5, 0.25).
  const Eigen::Vector2d px = k.Project({1.0, 0.5, 2.0});
  EXPECT_NEAR(px.x(), 0.5 * (8e-3 / 39.2e-6) + 79.5, 1e-9);
  EXPECT_NEAR(px.y(), 0.25 * (8e-3 / 54.8e-6) + 61.5, 1e-9);
  EXPECT_TRUE(std::isnan(k.Project({1.0, 0.0, -1.0}).x()));  // behind the camera
}

TEST(CameraIntrinsicsTest, DistortHandComputed) {
  CameraIntrinsics k;
  k.k1 = 0.1;
  // r² = 0.04: radial factor 1 + 0.1 * 0.04 = 1.004.
  const Eigen::Vector2d d = k.Distort({0.2, 0.0});
  EXPECT_NEAR(d.x(), 0.2008, 1e-12);
  EXPECT_NEAR(d.y(), 0.0, 1e-12);
  k = CameraIntrinsics{};
  k.p1 = 0.01;
  // Tangential only, at (0.1, 0.2): dx = 2 p1 x y = 0.0004, dy = p1 (r² + 2y²) = 0.0013.
  const Eigen::Vector2d t = k.Distort({0.1, 0.2});
  EXPECT_NEAR(t.x(), 0.1004, 1e-12);
  EXPECT_NEAR(t.y(), 0.2013, 1e-12);
}

TEST(CameraIntrinsicsTest, ProjectUnprojectRoundTripBelowMicroPixel) {
  for (const CameraIntrinsics& k : {CameraIntrinsics::SwissRangerSr2(), Distorted()}) {
    double worst = 0.0;
    for (double v = -0.5; v <= k.height - 0.5; v += k.height / 13.0) {
      for (double u = -0.5; u <= k.width - 0.5; u += k.width / 17.0) {
        const Eigen::Vector3d ray = k.Unproject({u, v});
        ASSERT_TRUE(ray.allFinite());
        EXPECT_NEAR(ray.norm(), 1.0, 1e-12);
        EXPECT_GT(ray.z(), 0.0);
        const Eigen::Vector2d back = k.Project(3.7 * ray);  // any range along the ray
        worst = std::max(worst, (back - Eigen::Vector2d(u, v)).norm());
      }
    }
    EXPECT_LT(worst, 1e-6);
  }
}

TEST(CameraIntrinsicsTest, RayTableHoldsUnitRaysOfPixelCentres) {
  const CameraIntrinsics k = Distorted();
  const RayTable t = MakeRayTable(k);
  ASSERT_EQ(t.x.width(), k.width);
  ASSERT_EQ(t.z.height(), k.height);
  for (int r = 0; r < k.height; r += 7) {
    for (int c = 0; c < k.width; c += 11) {
      const Eigen::Vector3d ray(t.x(r, c), t.y(r, c), t.z(r, c));
      EXPECT_NEAR(ray.norm(), 1.0, 1e-6);
      const Eigen::Vector2d px = k.Project(ray);
      EXPECT_NEAR(px.x(), c, 1e-3);  // float storage: ~1e-7 relative
      EXPECT_NEAR(px.y(), r, 1e-3);
    }
  }
  // The optical axis: the principal point of the SR-2 sits between four pixels, so the four
  // central rays are symmetric.
  const RayTable s = MakeRayTable(CameraIntrinsics::SwissRangerSr2());
  EXPECT_NEAR(s.x(61, 79), -s.x(62, 80), 1e-7);
  EXPECT_NEAR(s.y(61, 79), -s.y(62, 80), 1e-7);
}

TEST(CameraIntrinsicsTest, ValidateNamesTheBadField) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.fx_px = -1;
  EXPECT_THROW(k.Validate(), Error);
  k = CameraIntrinsics::SwissRangerSr2();
  k.k2 = std::nan("");
  try {
    k.Validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("k2"), std::string::npos);
  }
  k = CameraIntrinsics::SwissRangerSr2();
  k.width = 0;
  EXPECT_THROW(MakeRayTable(k), Error);
}

// Barrel distortion k1 = -0.3, k2 = 0.02: the distorted radius f(r) = r (1 - 0.3 r^2 + 0.02 r^4)
// grows until f'(r) = 1 - 0.9 r^2 + 0.1 r^4 = 0 at r^2 = (0.9 - sqrt(0.41)) / 0.2 = 1.298 (r =
// 1.139), where f = 0.734 (closed form). A 160 x 124 image at f = 80 px reaches a distorted
// radius of hypot(80, 62) / 80 = 1.26 at its corners, beyond the fold: pixels there have no ray
// on the first branch (the simulator used to hand NaN rays to Embree, which aborted; its camera
// models now require an unfolded lens). At f = 200 px the corners reach 0.51 < 0.734: the same
// lens is fine for the smaller field of view.
TEST(CameraIntrinsicsTest, ALensThatFoldsOverInsideTheImageIsFound) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.k1 = -0.3;
  k.k2 = 0.02;
  k.fx_px = k.fy_px = 80.0;
  try {
    RequireUnfoldedDistortion(k);
    FAIL() << "a folding lens passed";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("folds over"), std::string::npos) << e.what();
  }
  // A real camera's fitted model may fold where nothing is imaged: valid, with NaN rays there
  // (a root on the far branch, at r = 3.55, used to come back as a ray 74 degrees off the axis).
  EXPECT_NO_THROW(k.Validate());
  EXPECT_TRUE(k.Unproject({79.5, 61.5}).allFinite());
  EXPECT_FALSE(k.Unproject({-0.5, -0.5}).allFinite());
  k.fx_px = k.fy_px = 200.0;
  EXPECT_NO_THROW(RequireUnfoldedDistortion(k));
  const RayTable t = MakeRayTable(k);
  for (std::size_t i = 0; i < t.x.size(); ++i) {
    ASSERT_TRUE(std::isfinite(t.x[i]) && std::isfinite(t.y[i]) && std::isfinite(t.z[i])) << i;
  }
}

}  // namespace
}  // namespace tofcam
