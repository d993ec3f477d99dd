// The planar shortcut (SimulatorOptions::planar_shortcut, src/sim/subsample_shortcut.h) against
// the exact simulator, which casts every subsample ray with Embree. With the noise off, the two
// must give the same frames up to float rounding: the closed-form distance of a subsample differs
// from Embree's in the last bits, which moves a register by at most one count where the value
// lies at a rounding boundary. A value that sits on a threshold (full well, a truth cause's
// 5 cm / 1 cm limits) can flip instead; none does in these scenes on this machine, but Embree's
// last bits differ between instruction sets, so up to kTieFraction of the pixels may (a count
// of 1 at 160x124, 30 at 640x480). The truth distance (central rays, cast by Embree in both)
// must be bit for bit the same. Four scenes are built to defeat a shortcut that looked only at
// the four pixel centres around a subsample: a pole thinner than a pixel, a cube smaller than a
// pixel, the sharp corner of a large triangle and the sliver where a plate pokes out of a wall,
// each seen by a subsample ray but by no pixel centre; there the frames must agree to one count
// everywhere.
#include <gtest/gtest.h>

#include <algorithm>
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

// Fraction of pixels allowed to differ by more than rounding (threshold ties, see above).
constexpr double kTieFraction = 1e-4;

struct Difference {
  int max_counts = 0;               // largest |exact - shortcut| over the three registers
  std::int64_t pixels = 0;          // pixels where they differ at all
  std::int64_t beyond_one = 0;      // pixels where they differ by more than one count
  std::int64_t truth_distance = 0;  // pixels whose truth distance differs (bitwise)
  std::int64_t truth_causes = 0;    // pixels whose truth causes differ
};

Difference Compare(const Frame& a, const Frame& b) {
  Difference d;
  for (std::size_t i = 0; i < a.distance.size(); ++i) {
    // The distance register wraps at the unambiguous range: 0 and 65535 are one count apart.
    const int dd = std::abs(a.distance[i] - b.distance[i]);
    const int m = std::max({std::min(dd, 65536 - dd), std::abs(a.amplitude[i] - b.amplitude[i]),
                            std::abs(a.intensity[i] - b.intensity[i])});
    d.max_counts = std::max(d.max_counts, m);
    d.pixels += m > 0 ? 1 : 0;
    d.beyond_one += m > 1 ? 1 : 0;
    const float ta = a.truth->radial_distance_m[i], tb = b.truth->radial_distance_m[i];
    d.truth_distance += (ta == tb || (std::isinf(ta) && std::isinf(tb))) ? 0 : 1;
    d.truth_causes += a.truth->causes[i].bits() == b.truth->causes[i].bits() ? 0 : 1;
  }
  return d;
}

// Frames of the exact and the shortcut simulator, side by side, must agree to one count (up to
// `ties` pixels a frame beyond that); returns how many pixels differed at all.
std::int64_t ExpectSameFrames(const Scene& scene, const CameraModel& model, SimulatorOptions exact,
                              int frames, const std::string& what, bool allow_ties = true) {
  SimulatorOptions fast = exact;
  fast.planar_shortcut = true;
  SimulatedCamera a(scene, model, exact);
  SimulatedCamera b(scene, model, fast);
  std::int64_t differing = 0;
  for (int f = 0; f < frames; ++f) {
    const Frame fa = *a.Grab();
    const Frame fb = *b.Grab();
    const Difference d = Compare(fa, fb);
    const auto ties =
        allow_ties
            ? static_cast<std::int64_t>(kTieFraction * static_cast<double>(fa.distance.size()))
            : 0;
    EXPECT_LE(d.beyond_one, ties) << what << ", frame " << f << ": " << d.pixels
                                  << " pixels differ, by up to " << d.max_counts << " counts";
    EXPECT_EQ(d.truth_distance, 0) << what << ", frame " << f;
    EXPECT_LE(d.truth_causes, ties) << what << ", frame " << f;
    differing += d.pixels;
  }
  return differing;
}

TEST(SubsampleShortcutTest, EveryBuiltinSceneGivesTheExactFramesUpToRounding) {
  std::int64_t differing = 0;
  for (const std::string& name : BuiltinSceneNames()) {
    differing += ExpectSameFrames(LoadBuiltinScene(name), ResolveCameraModel("sr2"),
                                  Noiseless(false), 2, name);
  }
  // The shortcut is in use: Embree and the closed form round differently, so some register
  // somewhere differs by a count (with every subsample cast by Embree, none would).
  EXPECT_GT(differing, 0) << "the closed form was never used";
}

TEST(SubsampleShortcutTest, OddSupersamplingTwoThreadsAndALargerCameraToo) {
  SimulatorOptions ss3 = Noiseless(false);
  ss3.supersampling = 3;  // the centre subsample is the central ray itself
  ExpectSameFrames(LoadBuiltinScene("pavilion"), ResolveCameraModel("sr2"), ss3, 1, "S = 3");
  SimulatorOptions ss1 = Noiseless(false);
  ss1.supersampling = 1;
  // One ray per pixel: the option has nothing to save and changes nothing.
  EXPECT_EQ(ExpectSameFrames(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), ss1, 1, "S = 1"),
            0);
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

// A subsample of pixel (row, col) sees the object while none of the four pixel centres of its
// quad, rows [row, row + 1] x columns [quad_col, quad_col + 1], does: their truth distance is the
// bare scene's, and the pixel's registers differ from the bare scene's by more than 20 counts (far
// beyond the one count of rounding; a surface seen edge-on returns little light, so a mixed
// subsample may move a register by no more than about a hundred), in frame `premise_frame`. The
// shortcut must then see the object as the exact simulator does, to one count everywhere, in
// every frame up to that one.
struct Premise {
  int row, col, quad_col;
};

void ExpectSeenLikeTheExactSimulator(const Scene& with, const std::string& what, Premise at,
                                     const CameraModel& model = ResolveCameraModel("sr2"),
                                     const Scene& bare_scene = WallWith(""),
                                     int premise_frame = 0) {
  SimulatedCamera bare_camera(bare_scene, model, Noiseless(false));
  SimulatedCamera exact_camera(with, model, Noiseless(false));
  Frame bare, exact;
  for (int f = 0; f <= premise_frame; ++f) {
    bare = *bare_camera.Grab();
    exact = *exact_camera.Grab();
  }
  for (int r = at.row; r <= at.row + 1; ++r) {
    for (int c = at.quad_col; c <= at.quad_col + 1; ++c) {
      ASSERT_EQ(exact.truth->radial_distance_m(r, c), bare.truth->radial_distance_m(r, c))
          << what << ": the pixel centre (" << r << ", " << c
          << ") sees it; the case tests nothing";
    }
  }
  const int moved =
      std::max(std::abs(exact.distance(at.row, at.col) - bare.distance(at.row, at.col)),
               std::abs(exact.amplitude(at.row, at.col) - bare.amplitude(at.row, at.col)));
  ASSERT_GT(moved, 20) << what << ": no subsample of the pixel sees it (" << moved
                       << " counts); the case tests nothing";
  ExpectSameFrames(with, model, Noiseless(false), premise_frame + 1, what, /*allow_ties=*/false);
}

TEST(SubsampleShortcutTest, APoleThinnerThanAPixelBetweenPixelCentres) {
  // 0.3 px wide at 1.5 m, centred a quarter pixel right of column 90's centre: it covers the
  // right-hand subsamples of column 90 and no pixel centre.
  const double z = 1.5, w = XAt(90.4, z) - XAt(90.1, z);
  const std::string pole = "  - {type: box, material: dark, size_m: [" + std::to_string(w) +
                           ", 0.5, 0.01], position_m: [" + std::to_string(XAt(90.25, z)) + ", 0, " +
                           std::to_string(z) + "]}\n";
  ExpectSeenLikeTheExactSimulator(WallWith(pole), "a pole 0.3 px wide", {60, 90, 90});
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
                           std::to_string(x_at(12.4) - x_at(12.1)) +
                           ", 0.05, 0.001], position_m: [" + std::to_string(x_at(12.25)) + ", " +
                           std::to_string(y) + ", " + std::to_string(z) + "]}\n";
  ExpectSeenLikeTheExactSimulator(WallWith(pole), "a pole 0.3 px wide behind a distorting lens",
                                  {62, 12, 12}, model);
}

TEST(SubsampleShortcutTest, ACubeSmallerThanAPixelBetweenPixelCentres) {
  // 0.35 px on a side at 1.5 m around the lower-right subsample of pixel (60, 90).
  const double z = 1.5, w = XAt(90.45, z) - XAt(90.1, z);
  const std::string cube = "  - {type: box, material: dark, size_m: [" + std::to_string(w) + ", " +
                           std::to_string(YAt(60.45, z) - YAt(60.1, z)) + ", " + std::to_string(w) +
                           "], position_m: [" + std::to_string(XAt(90.25, z)) + ", " +
                           std::to_string(YAt(60.25, z)) + ", " + std::to_string(z) + "]}\n";
  ExpectSeenLikeTheExactSimulator(WallWith(cube), "a cube 0.35 px wide", {60, 90, 90});
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
  ExpectSeenLikeTheExactSimulator(scene, "a 4-degree corner", {60, 91, 90});
}

// A triangle with image corners (80, 60.35), (104, 60.35), (92, 54) whose plane,
// 1/z = 1/3 + 0.04 [(v - 60.35) - slope (u - 94.5)] per metre, meets the wall (z = 3 m) in a
// line that leaves the triangle's lower edge (row 60.35) at column 94.5, `slope` rows per column.
SceneObject Plate(double slope) {
  const CameraIntrinsics in = ResolveCameraModel("sr2").intrinsics;
  const auto point = [&](double u, double v) {
    const double z = 1 / (1.0 / 3 + 0.04 * ((v - 60.35) - slope * (u - 94.5)));
    return Eigen::Vector3f(static_cast<float>((u - in.cx_px) * z / in.fx_px),
                           static_cast<float>((v - in.cy_px) * z / in.fy_px),
                           static_cast<float>(z));
  };
  SceneObject plate;
  plate.name = "plate";
  plate.material = 0;
  plate.vertices = {point(80, 60.35), point(104, 60.35), point(92, 54)};
  plate.triangles = {Eigen::Vector3i(0, 1, 2)};
  return plate;
}

TEST(SubsampleShortcutTest, TheSliverWhereAPlatePokesOutOfAWall) {
  // The plate meets the wall at 4 degrees: it is in front of the wall only in the thin wedge
  // between the meeting line and its lower edge, left of column 94.5. At column 90 and beyond
  // the wedge lies between the centres of rows 60 and 61, yet it covers the subsample at
  // (90.75, 60.25), 6 cm in front of the wall. No vertex is near (the corner zones end at
  // columns 86 and 98): only the band along the segment where the two surfaces meet covers it.
  Scene scene = WallWith("");
  scene.objects.push_back(Plate(0.07));
  ExpectSeenLikeTheExactSimulator(scene, "a plate poking out of the wall", {60, 91, 90});
}

TEST(SubsampleShortcutTest, TheSliverWhereAPlatePokesOutOfAWallThatEndsFirst) {
  // The same at 2 degrees, but the wall (a second one 3 m further back) ends at column 94,
  // before the plate's lower edge reaches the wall's plane: no edge of the plate pierces the
  // wall near the wedge's tip (the wall's border pierces the plate instead). The subsample at
  // (86.75, 60.25) of pixel (60, 87) sees the plate; the centres of columns 86 and 87 do not.
  const double right_m = (94 - 79.5) * 3 / ResolveCameraModel("sr2").intrinsics.fx_px;
  const std::string walls =
      "materials: {w: {albedo: 0.8}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [10, 10], position_m: [" +
      std::to_string(right_m - 5) +
      ", 0, 3]}\n"
      "  - {type: plane, material: w, size_m: [20, 20], position_m: [0, 0, 6]}\n";
  const Scene bare = ParseScene(walls, "inline", {});
  Scene scene = bare;
  scene.objects.push_back(Plate(0.035));
  ExpectSeenLikeTheExactSimulator(scene, "a plate poking out of a wall that ends first",
                                  {60, 87, 86}, ResolveCameraModel("sr2"), bare);
}

TEST(SubsampleShortcutTest, TheSliverOfAMovingPlateFollowsIt) {
  // The first plate as a moving object: 5 m to the right (out of view, through nothing) for the
  // first frame, then moved into place between 40 and 50 ms, so frames 2 and 3 see the wedge.
  // Where surfaces meet is found again whenever objects move; found once, it would be stale.
  Scene scene = WallWith("");
  SceneObject plate = Plate(0.07);
  Keyframe away, still_away, in_place;
  away.position_m = still_away.position_m = Eigen::Vector3d(5, 0, 0);
  still_away.time_s = 0.04;
  in_place.time_s = 0.05;
  plate.motion.keys = {away, still_away, in_place};
  scene.objects.push_back(plate);
  ExpectSeenLikeTheExactSimulator(scene, "a plate that moves into the wall", {60, 91, 90},
                                  ResolveCameraModel("sr2"), WallWith(""), 3);
}

}  // namespace
}  // namespace tofcam::sim
