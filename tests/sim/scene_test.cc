#include "tofcam/sim/scene.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <tuple>
#include <vector>

#include "../scratch_dir.h"
#include "tofcam/core/error.h"

namespace tofcam::sim {
namespace {

// Per-process names: ctest may run several of these tests (or several build trees) at once.
std::string Prefix() { return "tofcam_scene_test_"; }

std::filesystem::path TempFile(const std::string& name, const std::string& content) {
  const auto path = testing::ScratchDir("tofcam_scene_test_") / (Prefix() + name);
  std::ofstream out(path, std::ios::binary);
  out << content;
  return path;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(SceneTest, AllBuiltinScenesLoad) {
  const auto names = BuiltinSceneNames();
  for (const char* required : {"wall", "hand", "pavilion", "mirror", "lamps", "corridor",
                               "beyond-range", "demo", "approach"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), required), names.end()) << required;
  }
  for (const auto& n : names) {
    const Scene s = LoadBuiltinScene(n);
    EXPECT_FALSE(s.objects.empty()) << n;
    for (const auto& o : s.objects) {
      EXPECT_FALSE(o.triangles.empty()) << n << " " << o.name;
    }
  }
  EXPECT_EQ(LoadBuiltinScene("lamps").lamps.size(), 2u);
  EXPECT_FALSE(LoadBuiltinScene("corridor").camera.IsStatic());
  EXPECT_GT(LoadBuiltinScene("demo").duration_s, 9.0);
}

TEST(SceneTest, ParametersOverrideAtLoad) {
  const Scene a = LoadBuiltinScene("wall");
  const Scene b = LoadBuiltinScene("wall", {{"distance_m", "3.5"}});
  EXPECT_DOUBLE_EQ(a.parameters.at("distance_m"), 2.0);
  EXPECT_DOUBLE_EQ(b.parameters.at("distance_m"), 3.5);
  EXPECT_DOUBLE_EQ(b.objects[0].motion.At(0).translation().z(), 3.5);
  const auto [name, ov] = ParseSceneSpec("wall?distance_m=2.5&tilt_deg=10");
  EXPECT_EQ(name, "wall");
  EXPECT_EQ(ov.at("distance_m"), "2.5");
  const Scene c = ResolveScene(name, ov);
  // A plane tilted 10 deg about y: its normal (0, 0, -1) rotates to (-sin 10, 0, -cos 10).
  const Eigen::Vector3d n = c.objects[0].motion.At(0).linear() * Eigen::Vector3d(0, 0, -1);
  EXPECT_NEAR(n.x(), -std::sin(10 * M_PI / 180), 1e-12);
  try {
    (void)LoadBuiltinScene("wall", {{"distanse_m", "1"}});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("distanse_m"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("distance_m"), std::string::npos);  // lists the known ones
  }
  EXPECT_THROW((void)LoadBuiltinScene("wall", {{"distance_m", "far"}}), Error);
  EXPECT_THROW((void)ParseSceneSpec("wall?distance_m"), Error);
  EXPECT_THROW((void)LoadBuiltinScene("nowhere"), Error);
}

TEST(SceneTest, TrajectoryInterpolatesAndHolds) {
  Trajectory t;
  t.keys = {{0.0, {0, 0, 0}, {0, 0, 0}}, {2.0, {0, 0, 4}, {0, 90, 0}}};
  EXPECT_NEAR(t.At(1.0).translation().z(), 2.0, 1e-12);
  EXPECT_NEAR(t.At(-1.0).translation().z(), 0.0, 1e-12);
  EXPECT_NEAR(t.At(5.0).translation().z(), 4.0, 1e-12);
  // 45 deg about y at t = 1: x axis maps to (cos 45, 0, -sin 45).
  const Eigen::Vector3d x = t.At(1.0).linear() * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(x.x(), std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(x.z(), -std::sqrt(0.5), 1e-12);
  Lamp l;
  l.schedule = {{0, false}, {1, true}, {3, false}};
  EXPECT_FALSE(l.OnAt(0.5));
  EXPECT_TRUE(l.OnAt(2.0));
  EXPECT_FALSE(l.OnAt(3.5));
}

TEST(SceneTest, ErrorsNameFileLineAndProblem) {
  const std::string base = "name: t\nmaterials:\n  white: {albedo: 0.5}\nobjects:\n";
  struct Case {
    std::string body;
    std::string line;
    std::string words;
  } cases[] = {
      {"  - {type: plane, material: white, size_m: [1, 1]}\n  - {type: cone, material: white}\n",
       ":6:", "cone"},
      {"  - {type: plane, material: black, size_m: [1, 1]}\n", ":5:", "black"},
      {"  - {type: plane, material: white, size_m: [1]}\n", ":5:", "size_m"},
      {"  - {type: box, material: white, size_m: [1, 1, -1]}\n", ":5:", "size_m"},
      {"  - {type: sphere, material: white, radius_m: nan}\n", ":5:", "radius_m"},
      {"  - {type: plane, material: white, size_m: [1, 1], colour: red}\n", ":5:", "colour"},
      {"  - {type: plane, material: white, size_m: [1, 1], position_m: [0, 0, $far]}\n",
       ":5:", "far"},
      {"  - {type: mesh, material: white, file: missing.ply}\n", ":5:", "missing.ply"},
      {"  - {type: plane, material: white, size_m: [1, 1], size_m: [2, 2]}\n",
       ":5:", "'size_m' appears twice"},
      // A plane of 1e19 m vanished (every truth distance inf); one of 1e-30 m too.
      {"  - {type: plane, material: white, size_m: [1e19, 1e19]}\n", ":5:", "size_m"},
      {"  - {type: box, material: white, size_m: [1e-30, 1, 1]}\n", ":5:", "size_m"},
      // A key that is a sequence was an internal yaml-cpp error without the file.
      {"  - {type: plane, material: white, size_m: [1, 1], ? [a, b] : 1}\n", ":5:", "plain names"},
  };
  for (const auto& c : cases) {
    const auto path = TempFile("bad.yaml", base + c.body);
    const std::string msg = ErrorOf([&] { (void)LoadScene(path); });
    EXPECT_NE(msg.find(path.string() + c.line), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.words), std::string::npos) << msg;
    std::filesystem::remove(path);
  }
  const auto syntax = TempFile("syntax.yaml", "name: t\nobjects: [\n");
  EXPECT_NE(ErrorOf([&] { (void)LoadScene(syntax); }).find("syntax"), std::string::npos);
  std::filesystem::remove(syntax);
  EXPECT_NE(
      ErrorOf([] { (void)LoadScene("/nonexistent/scene.yaml"); }).find("/nonexistent/scene.yaml"),
      std::string::npos);
}

// YAML aliases let a small file repeat an object: 9000 spheres of 16 x 32 cells (about a
// thousand triangles each) exceed the 2^23 triangles a scene may hold, and the load says so
// instead of allocating gigabytes for Embree.
TEST(SceneTest, AliasedObjectsAreBounded) {
  std::string yaml =
      "name: t\nmaterials: {white: {albedo: 0.5}}\nobjects:\n"
      "  - &s {type: sphere, material: white, radius_m: 0.1, position_m: [0, 0, 2]}\n";
  for (int i = 0; i < 9000; ++i) yaml += "  - *s\n";
  const std::string msg = ErrorOf([&] { (void)ParseScene(yaml, "aliases.yaml", {}); });
  EXPECT_NE(msg.find("triangles"), std::string::npos) << msg;
  std::string few =
      "name: t\nmaterials: {white: {albedo: 0.5}}\nobjects:\n"
      "  - &s {type: sphere, material: white, radius_m: 0.1, position_m: [0, 0, 2]}\n";
  for (int i = 0; i < 10; ++i) few += "  - *s\n";
  EXPECT_EQ(ParseScene(few, "few.yaml", {}).objects.size(), 11u);
}

TEST(SceneTest, LoadsPlyAndObjMeshes) {
  const auto ply = TempFile("quad.ply",
                            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty "
                            "float y\nproperty float z\nelement face 1\nproperty list uchar int "
                            "vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n");
  std::vector<Eigen::Vector3f> v;
  std::vector<Eigen::Vector3i> t;
  LoadMesh(ply, v, t);
  EXPECT_EQ(v.size(), 4u);
  ASSERT_EQ(t.size(), 2u);  // the quad is fanned into two triangles
  EXPECT_EQ(t[1], Eigen::Vector3i(0, 2, 3));

  // Binary little-endian: one triangle.
  std::string bin =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\nproperty list uchar int "
      "vertex_indices\nend_header\n";
  const float verts[9] = {0, 0, 1, 1, 0, 1, 0, 1, 1};
  bin.append(reinterpret_cast<const char*>(verts), sizeof verts);
  bin.push_back(3);
  const int idx[3] = {0, 1, 2};
  bin.append(reinterpret_cast<const char*>(idx), sizeof idx);
  const auto bply = TempFile("tri.ply", bin);
  v.clear();
  t.clear();
  LoadMesh(bply, v, t);
  ASSERT_EQ(v.size(), 3u);
  EXPECT_FLOAT_EQ(v[1].x(), 1.0f);
  EXPECT_EQ(t.size(), 1u);

  const auto obj = TempFile("tri.obj", "v 0 0 2\nv 1 0 2\nv 0 1 2\nf 1 2 3\n");
  v.clear();
  t.clear();
  LoadMesh(obj, v, t);
  EXPECT_EQ(v.size(), 3u);
  EXPECT_EQ(t.size(), 1u);

  // Hostile files: index out of range, truncated data, wrong magic.
  const auto bad_index =
      TempFile("badidx.ply",
               "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty "
               "float y\nproperty float z\nelement face 1\nproperty list uchar int "
               "vertex_indices\nend_header\n0 0 0\n3 0 5 9\n");
  EXPECT_NE(ErrorOf([&] { LoadMesh(bad_index, v, t); }).find("out of range"), std::string::npos);
  const auto truncated =
      TempFile("trunc.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty "
               "float y\nproperty float z\nend_header\n0 0 0\n1 1\n");
  EXPECT_NE(ErrorOf([&] { LoadMesh(truncated, v, t); }).find("truncated"), std::string::npos);
  const auto magic = TempFile("magic.ply", "plx\n");
  EXPECT_NE(ErrorOf([&] { LoadMesh(magic, v, t); }).find("magic"), std::string::npos);
  EXPECT_THROW(LoadMesh(TempFile("x.stl", "solid"), v, t), Error);
  // A coordinate beyond the float range is no finite vertex (PLY reads doubles).
  const auto huge = TempFile("huge.ply",
                             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty "
                             "float y\nproperty float z\nend_header\n1e39 0 0\n");
  EXPECT_NE(ErrorOf([&] { LoadMesh(huge, v, t); }).find("not a finite float"), std::string::npos);
  // OBJ text tinyobjloader would read as another mesh: numbers it cannot parse become 0, a
  // two-coordinate vertex passes, an index beyond int wraps into range.
  const std::string tri = "v 0 0 2\nv 1 0 2\nv 0 1 2\n";
  for (const auto& [text, line, words] :
       std::vector<std::tuple<std::string, std::string, std::string>>{
           {"v 0 0 2\nv abc 0 2\nv 0 1 2\nf 1 2 3\n", ":2:", "'abc'"},
           {"v 0 0 2\nv nan 0 2\nv 0 1 2\nf 1 2 3\n", ":2:", "'nan'"},
           {"v 0 0 2\nv 1e39 0 2\nv 0 1 2\nf 1 2 3\n", ":2:", "'1e39'"},
           {"v 0 0 2\nv 1 0\nv 0 1 2\nf 1 2 3\n", ":2:", "3 coordinates"},
           {tri + "f 1 2 99999999999999999999\n", ":4:", "99999999999999999999"},
           {tri + "f 1 2 4\n", ":4:", "'4'"},
           {tri + "f 1 2 -4\n", ":4:", "'-4'"},
           {"v 0 0 2\nv 0x1p3 0 2\nv 0 1 2\nf 1 2 3\n", ":2:", "'0x1p3'"},
           {"v 0 0 2\rv abc 0 2\rv 0 1 2\rf 1 2 3\r", ":2:", "'abc'"},  // old Mac line ends
           {tri + "f 1 2 0\n", ":4:", "'0'"},
           {tri + "f 1 2\n", ":4:", "at least 3"},
           {tri + "f 1 2 x\n", ":4:", "'x'"},
       }) {
    const auto bad = TempFile("bad.obj", text);
    const std::string msg = ErrorOf([&] { LoadMesh(bad, v, t); });
    EXPECT_NE(msg.find(bad.string() + line), std::string::npos) << msg;
    EXPECT_NE(msg.find(words), std::string::npos) << msg;
    std::filesystem::remove(bad);
  }
  // What OBJ allows: relative (negative) indices, texture/normal references, comments, CRLF,
  // a face before the vertices it names, '+' signs, exponents (a tiny one rounds to 0).
  for (const std::string& text :
       {std::string("# a triangle\r\nv 0 0 2\r\nv 1 0 2 1\r\nv 0 1 2 # third\r\n"
                    "f -3/1 2//1 3/1/1\r\n"),
        std::string("f 1 2 3\nv 0 0 2\nv +1 0 2e0\nv 0 1.0e-320 2\n")}) {
    const auto fine = TempFile("fine.obj", text);
    v.clear();
    t.clear();
    LoadMesh(fine, v, t);
    EXPECT_EQ(v.size(), 3u) << text;
    ASSERT_EQ(t.size(), 1u) << text;
    EXPECT_EQ(t[0], Eigen::Vector3i(0, 1, 2));
    EXPECT_EQ(v[1], Eigen::Vector3f(1, 0, 2));
    std::filesystem::remove(fine);
  }
  std::filesystem::remove(huge);

  // A scene referencing a mesh relative to its own folder.
  const auto scene =
      TempFile("mesh_scene.yaml",
               "materials: {m: {albedo: 0.5}}\nobjects:\n  - {type: mesh, material: m, "
               "file: " +
                   Prefix() + "quad.ply, scale: 2}\n");
  const Scene s = LoadScene(scene);
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_FLOAT_EQ(s.objects[0].vertices[2].x(), 2.0f);
  for (const auto& p : {ply, bply, obj, bad_index, truncated, magic, scene})
    std::filesystem::remove(p);
}

}  // namespace
}  // namespace tofcam::sim
