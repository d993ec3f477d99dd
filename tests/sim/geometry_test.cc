// Stage 1 of the simulator (src/sim/geometry.h): ray casting against closed-form plane and box
// distances, packets against single rays, moving objects, the subsample layout.
#include "geometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "tofcam/core/units.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {
namespace {

Scene PlaneAt(double z) {
  return ParseScene(
      "materials: {w: {albedo: 0.5}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [10, 10], position_m: [0, 0, " +
          std::to_string(z) + "]}\n",
      "inline", {});
}

TEST(GeometryTest, CastHitsAPlaneAtItsDistanceAndMissesBehind) {
  const Scene scene = PlaneAt(2.0);
  const SceneGeometry g(scene);
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  Eigen::Vector3f n;
  int obj = -1;
  EXPECT_NEAR(g.Cast({0, 0, 0}, {0, 0, 1}, 0.f, ctx, n, obj), 2.0f, 1e-5f);
  EXPECT_EQ(obj, 0);
  EXPECT_NEAR(std::abs(n.z()), 1.0f, 1e-6f);
  EXPECT_NEAR(n.norm(), 1.0f, 1e-6f);
  // 30 degrees off axis: 2 / cos 30.
  const Eigen::Vector3f d(0.5f, 0.f, std::sqrt(3.f) / 2);
  EXPECT_NEAR(g.Cast({0, 0, 0}, d, 0.f, ctx, n, obj), 2.0f / (std::sqrt(3.f) / 2), 1e-5f);
  EXPECT_FALSE(g.Cast({0, 0, 0}, {0, 0, -1}, 0.f, ctx, n, obj) < kInf);
}

TEST(GeometryTest, PacketsGiveTheSameHitsAsSingleRaysIncludingAPartialPacket) {
  const Scene scene = PlaneAt(3.0);
  const SceneGeometry g(scene);
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  const std::size_t n = 37;  // not a multiple of any packet width
  RayBatch b;
  b.Resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f d =
        Eigen::Vector3f(0.02f * (static_cast<float>(i) - 18), 0.01f, 1.f).normalized();
    b.dx[i] = d.x();
    b.dy[i] = d.y();
    b.dz[i] = d.z();
  }
  b.dz[5] = -b.dz[5];  // one ray away from the plane
  g.Trace(&ctx, {0, 0, 0}, n, b);
  for (std::size_t i = 0; i < n; ++i) {
    if (i == 5) {
      EXPECT_FALSE(b.t[i] < kInf);
      EXPECT_EQ(b.geom[i], RTC_INVALID_GEOMETRY_ID);
      continue;
    }
    EXPECT_NEAR(b.t[i], 3.0f / b.dz[i], 1e-4f) << i;  // closed form: z / cos
    EXPECT_EQ(b.geom[i], 0u);
  }
}

TEST(GeometryTest, TraceFromAnOffsetLeavesTheOtherRaysAndReportsTheTriangle) {
  // A box: rays [first, first + n) fan across its front face (two triangles), the rest of the
  // batch carries sentinels that the trace must not touch.
  const Scene scene = ParseScene(
      "materials: {w: {albedo: 0.5}}\nobjects:\n"
      "  - {type: box, material: w, size_m: [2, 2, 1], position_m: [0, 0, 3]}\n",
      "inline", {});
  const SceneGeometry g(scene);
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  const std::size_t total = 60, first = 5, n = 37;  // a partial packet at any width
  RayBatch b;
  b.Resize(total);
  for (std::size_t i = 0; i < total; ++i) {
    const Eigen::Vector3f d =
        Eigen::Vector3f(0.016f * (static_cast<float>(i) - 23), 0.002f, 1.f).normalized();
    b.dx[i] = d.x();
    b.dy[i] = d.y();
    b.dz[i] = d.z();
    b.t[i] = -1.f;  // sentinels
    b.geom[i] = 77u;
    b.prim[i] = 78u;
    b.nx[i] = b.ny[i] = b.nz[i] = -2.f;
  }
  g.Trace(&ctx, {0, 0, 0}, n, b, first);
  std::set<unsigned> prims;
  for (std::size_t i = 0; i < total; ++i) {
    if (i < first || i >= first + n) {
      EXPECT_EQ(b.t[i], -1.f) << i;
      EXPECT_EQ(b.geom[i], 77u) << i;
      EXPECT_EQ(b.prim[i], 78u) << i;
      EXPECT_EQ(b.nx[i], -2.f) << i;
      EXPECT_EQ(b.nz[i], -2.f) << i;
      continue;
    }
    EXPECT_NEAR(b.t[i], 2.5f / b.dz[i], 1e-4f) << i;  // the front face at z = 2.5
    EXPECT_EQ(b.geom[i], 0u);
    // The same triangle as a single ray reports.
    RTCRayHit rh;
    SetRay(rh, {0, 0, 0}, Eigen::Vector3f(b.dx[i], b.dy[i], b.dz[i]), 0.f);
    rtcIntersect1(g.Handle(), &ctx, &rh);
    EXPECT_EQ(b.prim[i], rh.hit.primID) << i;
    prims.insert(b.prim[i]);
  }
  // The fan crosses the face's centre just off both diagonals, so it crosses either one.
  EXPECT_EQ(prims.size(), 2u) << "the fan should cross the face's diagonal";
}

TEST(GeometryTest, PlaceObjectsMovesADynamicBox) {
  const Scene scene = ParseScene(
      "materials: {w: {albedo: 0.5}}\nobjects:\n"
      "  - type: box\n    material: w\n    size_m: [0.4, 0.4, 0.4]\n"
      "    motion: [{t: 0, position_m: [0, 0, 2]}, {t: 1, position_m: [0, 0, 3]}]\n",
      "inline", {});
  SceneGeometry g(scene);
  EXPECT_TRUE(g.Dynamic(0));
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  Eigen::Vector3f n;
  int obj = -1;
  EXPECT_NEAR(g.Cast({0, 0, 0}, {0, 0, 1}, 0.f, ctx, n, obj), 1.8f, 1e-5f);  // front face
  g.PlaceObjects(0.5);                                                       // centre at 2.5 m
  EXPECT_NEAR(g.Cast({0, 0, 0}, {0, 0, 1}, 0.f, ctx, n, obj), 2.3f, 1e-5f);
}

TEST(GeometryTest, RotateArraysIsTheMatrixProduct) {
  const Eigen::Matrix3f rot =
      Eigen::AngleAxisf(0.3f, Eigen::Vector3f(1, 2, 3).normalized()).toRotationMatrix();
  const float x[3] = {1, 0, 0.3f}, y[3] = {0, 1, -0.2f}, z[3] = {0, 0, 0.9f};
  float dx[3], dy[3], dz[3];
  RotateArrays(rot, x, y, z, 3, dx, dy, dz);
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3f e = rot * Eigen::Vector3f(x[i], y[i], z[i]);
    EXPECT_NEAR(dx[i], e.x(), 1e-6f);
    EXPECT_NEAR(dy[i], e.y(), 1e-6f);
    EXPECT_NEAR(dz[i], e.z(), 1e-6f);
  }
}

TEST(GeometryTest, BlockGroupFillsWholePacketsOnly) {
  EXPECT_EQ(BlockGroup(2, 16, 176), 4);  // 4 pixels x 4 subsamples = one 16-ray packet
  EXPECT_EQ(BlockGroup(2, 8, 176), 2);
  EXPECT_EQ(BlockGroup(1, 16, 176), 16);
  EXPECT_EQ(BlockGroup(3, 16, 176), 1);  // 9 does not divide 16
  EXPECT_EQ(BlockGroup(2, 16, 174), 1);  // 174 is not a multiple of 4
  EXPECT_EQ(BlockGroup(2, 1, 176), 1);
}

TEST(GeometryTest, IndexIsAPermutationWithBlocksOfGroupPixels) {
  PixelRays rays;
  rays.ss = 2;
  rays.group = 4;
  const int width = 8;
  std::set<std::size_t> seen;
  for (int c = 0; c < width; ++c) {
    for (int s = 0; s < 4; ++s) seen.insert(rays.Index(s, c));
  }
  EXPECT_EQ(seen.size(), 32u);
  EXPECT_EQ(*seen.rbegin(), 31u);
  // Pixel 5 is the second pixel of the second block: subsample s at 16 + 4 s + 1.
  for (int s = 0; s < 4; ++s) EXPECT_EQ(rays.Index(s, 5), 16u + 4u * s + 1u);
}

TEST(GeometryTest, CameraPoseAtPanZeroIsTheScenesCamera) {
  const Scene scene = LoadBuiltinScene("pavilion");
  const Eigen::Isometry3d a = CameraPose(scene, 0.0, 0.0);
  EXPECT_TRUE(a.matrix().isApprox(scene.camera.At(0.0).matrix(), 1e-12));
  // A quarter turn of the pan unit turns the optical axis by 90 degrees.
  const Eigen::Isometry3d b = CameraPose(scene, 0.0, kPi / 2);
  EXPECT_NEAR(a.linear().col(2).dot(b.linear().col(2)), 0.0, 1e-12);
}

}  // namespace
}  // namespace tofcam::sim::internal
