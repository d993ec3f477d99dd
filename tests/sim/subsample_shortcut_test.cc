// The planar shortcut (SimulatorOptions::planar_shortcut, src/sim/subsample_shortcut.h) against
// the exact simulator, which casts every subsample ray with Embree. With the noise off, the two
// must give the same frames up to float rounding: the closed-form distance of a subsample differs
// from Embree's in the last bits, which moves a register by at most one count where the value
// lies at a rounding boundary. The ground truth (central rays, cast by Embree in both) must be
// bit for bit the same. Three scenes are built to defeat a shortcut that looked only at the four
// pixel centres around a subsample: a pole thinner than a pixel, a cube smaller than a pixel and
// the sharp corner of a large triangle, each seen by a subsample ray but by no pixel centre.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <numbers>
#include <string>

#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"
#include "tofcam/sim/simulated_camera.h"

namespace tofcam::sim {
namespace {

// The noise off (so that both runs draw nothing) and every other effect on.
SimulatorOptions Noiseless(bool shortcut) {
  SimulatorOptions o;
  o.shot_noise = false;
  o.read_noise = false;
  o.planar_shortcut = shortcut;
  return o;
}

struct Difference {
  int max_counts = 0;         // largest |exact - shortcut| over the three registers
  long pixels = 0;            // pixels where they differ at all
  long truth_distance = 0;    // pixels whose truth distance differs (bitwise)
  long truth_causes = 0;      // pixels whose truth causes differ
};

Difference Compare(const Frame& a, const Frame& b) {
  Difference d;
  for (std::size_t i = 0; i < a.distance.size(); ++i) {
    const int m = std::max({std::abs(a.distance[i] - b.distance[i]),
                            std::abs(a.amplitude[i] - b.amplitude[i]),
                            std::abs(a.intensity[i] - b.intensity[i])});
    d.max_counts = std::max(d.max_counts, m);
    d.pixels += m > 0 ? 1 : 0;
    const float ta = a.truth->radial_distance_m[i], tb = b.truth->radial_distance_m[i];
    d.truth_distance += (ta == tb || (std::isinf(ta) && std::isinf(tb))) ? 0 : 1;
    d.truth_causes += a.truth->causes[i].bits() == b.truth->causes[i].bits() ? 0 : 1;
  }
  return d;
}

// Frames of the exact and the shortcut simulator, side by side, must agree to one count.
void ExpectSameFrames(const Scene& scene, const CameraModel& model, SimulatorOptions exact,
                      int frames, const std::string& what) {
  SimulatorOptions fast = exact;
  fast.planar_shortcut = true;
  SimulatedCamera a(scene, model, exact);
  SimulatedCamera b(scene, model, fast);
  for (int f = 0; f < frames; ++f) {
    const Frame fa = *a.Grab();
    const Frame fb = *b.Grab();
    const Difference d = Compare(fa, fb);
    EXPECT_LE(d.max_counts, 1) << what << ", frame " << f << ": " << d.pixels
                               << " pixels differ, by up to " << d.max_counts << " counts";
    EXPECT_EQ(d.truth_distance, 0) << what << ", frame " << f;
    EXPECT_EQ(d.truth_causes, 0) << what << ", frame " << f;
  }
}

TEST(SubsampleShortcutTest, EveryBuiltinSceneGivesTheExactFramesUpToRounding) {
  for (const std::string& name : BuiltinSceneNames()) {
    ExpectSameFrames(LoadBuiltinScene(name), ResolveCameraModel("sr2"), Noiseless(false), 2,
                     name);
  }
}

TEST(SubsampleShortcutTest, OddSupersamplingTwoThreadsAndALargerCameraToo) {
  SimulatorOptions ss3 = Noiseless(false);
  ss3.supersampling = 3;  // the centre subsample is the central ray itself
  ExpectSameFrames(LoadBuiltinScene("pavilion"), ResolveCameraModel("sr2"), ss3, 1, "S = 3");
  SimulatorOptions ss1 = Noiseless(false);
  ss1.supersampling = 1;
  ExpectSameFrames(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), ss1, 1, "S = 1");
  SimulatorOptions two = Noiseless(false);
  two.threads = 2;
  ExpectSameFrames(LoadBuiltinScene("hand"), ResolveCameraModel("sr2"), two, 2, "2 threads");
  ExpectSameFrames(LoadBuiltinScene("pavilion"), ResolveCameraModel("generic640x480"),
                   Noiseless(false), 1, "640x480");
}

TEST(SubsampleShortcutTest, ALensWithDistortionToo) {
  CameraModel model = ResolveCameraModel("sr2");
  model.intrinsics.k1 = -0.25;  // strong barrel distortion
  model.intrinsics.k2 = 0.05;
  model.intrinsics.p1 = 0.002;
  ExpectSameFrames(LoadBuiltinScene("pavilion"), model, Noiseless(false), 1, "distorted lens");
}

// A white wall 3 m in front of the SR-2 and `extra` objects in front of it.
Scene WallWith(const std::string& extra) {
  return ParseScene(
      "materials: {w: {albedo: 0.8}, dark: {albedo: 0.3}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [20, 20], position_m: [0, 0, 3]}\n" +
          extra,
      "inline", {});
}

// Camera-frame x (m) at depth z of image column u on the SR-2 (no distortion).
double XAt(double u, double z) {
  const CameraIntrinsics in = ResolveCameraModel("sr2").intrinsics;
  return (u - in.cx_px) * z / in.fx_px;
}
double YAt(double v, double z) {
  const CameraIntrinsics in = ResolveCameraModel("sr2").intrinsics;
  return (v - in.cy_px) * z / in.fy_px;
}

// The object must matter (the exact frame differs from the bare wall's by far more than a count
// somewhere) and the shortcut must see it as the exact simulator does.
void ExpectSeenLikeTheExactSimulator(const Scene& with, const std::string& what,
                                     const CameraModel& model = ResolveCameraModel("sr2")) {
  SimulatedCamera bare(WallWith(""), model, Noiseless(false));
  SimulatedCamera exact(with, model, Noiseless(false));
  const Difference seen = Compare(*bare.Grab(), *exact.Grab());
  ASSERT_GT(seen.max_counts, 100) << what << " is not seen by any subsample: the case tests nothing";
  ExpectSameFrames(with, model, Noiseless(false), 1, what);
}

TEST(SubsampleShortcutTest, APoleThinnerThanAPixelBetweenPixelCentres) {
  // 0.3 px wide at 1.5 m, centred a quarter pixel right of column 90's centre: it covers the
  // right-hand subsamples of column 90 and no pixel centre.
  const double z = 1.5, w = XAt(90.4, z) - XAt(90.1, z);
  const std::string pole = "  - {type: box, material: dark, size_m: [" + std::to_string(w) +
                           ", 0.5, 0.01], position_m: [" + std::to_string(XAt(90.25, z)) +
                           ", 0, " + std::to_string(z) + "]}\n";
  ExpectSeenLikeTheExactSimulator(WallWith(pole), "a pole 0.3 px wide");
}

TEST(SubsampleShortcutTest, APoleBetweenPixelCentresNearTheEdgeOfADistortingLens) {
  // Barrel distortion moves column 12 of row 62 several pixels from where the pinhole model puts
  // it; the pole, placed through the lens model itself, still covers only the right-hand
  // subsamples of that column.
  CameraModel model = ResolveCameraModel("sr2");
  model.intrinsics.k1 = -0.25;
  model.intrinsics.k2 = 0.05;
  const double z = 1.5;
  const auto x_at = [&](double u) {
    const Eigen::Vector3d d = model.intrinsics.Unproject({u, 62.0});
    return d.x() / d.z() * z;
  };
  const double y = model.intrinsics.Unproject({12.25, 62.0}).y() /
                   model.intrinsics.Unproject({12.25, 62.0}).z() * z;
  const std::string pole = "  - {type: box, material: dark, size_m: [" +
                           std::to_string(x_at(12.4) - x_at(12.1)) + ", 0.05, 0.001], position_m: [" +
                           std::to_string(x_at(12.25)) + ", " + std::to_string(y) + ", " +
                           std::to_string(z) + "]}\n";
  ExpectSeenLikeTheExactSimulator(WallWith(pole), "a pole 0.3 px wide behind a distorting lens",
                                  model);
}

TEST(SubsampleShortcutTest, ACubeSmallerThanAPixelBetweenPixelCentres) {
  // 0.35 px on a side at 1.5 m around the lower-right subsample of pixel (60, 90).
  const double z = 1.5, w = XAt(90.45, z) - XAt(90.1, z);
  const std::string cube =
      "  - {type: box, material: dark, size_m: [" + std::to_string(w) + ", " +
      std::to_string(YAt(60.45, z) - YAt(60.1, z)) + ", " + std::to_string(w) +
      "], position_m: [" + std::to_string(XAt(90.25, z)) + ", " + std::to_string(YAt(60.25, z)) +
      ", " + std::to_string(z) + "]}\n";
  ExpectSeenLikeTheExactSimulator(WallWith(cube), "a cube 0.35 px wide");
}

TEST(SubsampleShortcutTest, TheSharpCornerOfALargeTriangle) {
  // One triangle at 1.5 m: its 4-degree corner at column 84.3, row 60.3 points left, its body
  // runs 40 px to the right. Up to column 92 it is too narrow to cover the centres of rows 60 and
  // 61, yet it covers the subsample at (90.75, 60.25) of pixel (60, 91), 6.5 px from the corner,
  // whose quad's four centres all see the wall.
  Scene scene = WallWith("");
  const double z = 1.5;
  const double half = std::tan(2.0 * std::numbers::pi / 180) * 40;  // rows at 40 px
  SceneObject tri;
  tri.name = "wedge";
  tri.material = 0;
  tri.vertices = {Eigen::Vector3f(XAt(84.3, z), YAt(60.3, z), z),
                  Eigen::Vector3f(XAt(124.3, z), YAt(60.3 - half, z), z),
                  Eigen::Vector3f(XAt(124.3, z), YAt(60.3 + half, z), z)};
  tri.triangles = {Eigen::Vector3i(0, 1, 2)};
  scene.objects.push_back(tri);
  ExpectSeenLikeTheExactSimulator(scene, "a 4-degree corner");
}

}  // namespace
}  // namespace tofcam::sim
