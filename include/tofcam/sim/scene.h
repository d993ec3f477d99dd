#pragma once
/// \file
/// Simulator scenes: triangle-mesh objects with materials and keyframed motion, lamps, ambient
/// light, a camera trajectory and a pan unit. Loaded from YAML (docs/scene-format.md); the
/// built-in scenes in scenes/*.yaml are embedded in the library at build time.
///
/// World frame: the camera convention (x right, y down, z forward) of the pan-unit base at its
/// rest pose; metres, seconds.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/core/pan_unit.h"

namespace tofcam::sim {

/// Surface reflectance at the camera's wavelength.
struct Material {
  std::string name;
  double albedo = 0.5;            ///< Lambertian NIR albedo, [0, 1].
  double specular = 0.0;          ///< Glossy (Blinn-Phong) lobe weight, [0, 1].
  double shininess = 50.0;        ///< Lobe exponent (> 0); larger is sharper.
  double mirror = 0.0;            ///< Specular mirror reflectance, [0, 1).
  double emission_w_m2_sr = 0.0;  ///< In-band radiance of a glowing surface (lamp bulbs).
};

/// A pose at a time: position, and rotation as Euler angles (deg) applied X, then Y, then Z
/// (R = Rz * Ry * Rx) about the fixed world axes.
struct Keyframe {
  double time_s = 0.0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();
};

/// Piecewise-linear motion through keyframes sorted by time, held constant outside them.
struct Trajectory {
  std::vector<Keyframe> keys;  ///< At least one.
  /// Object-to-world transform at `time_s`.
  [[nodiscard]] Eigen::Isometry3d At(double time_s) const;
  [[nodiscard]] bool IsStatic() const;
};

/// A rigid object: a triangle mesh in its own frame plus a material and motion.
struct SceneObject {
  std::string name;
  std::vector<Eigen::Vector3f> vertices;   ///< Object frame, m.
  std::vector<Eigen::Vector3i> triangles;  ///< Vertex indices.
  int material = 0;                        ///< Index into Scene::materials.
  Trajectory motion;
};

/// An on/off switch at a time; the state holds until the next entry.
struct LampSwitch {
  double time_s = 0.0;
  bool on = true;
};

/// A point light with in-band infrared power; its bulb is a glowing sphere object.
struct Lamp {
  std::string name;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  double ir_power_w = 1.0;           ///< In-band radiant power, W (isotropic).
  double bulb_radius_m = 0.03;       ///< Radius of the visible bulb.
  std::vector<LampSwitch> schedule;  ///< Empty: always on.
  [[nodiscard]] bool OnAt(double time_s) const;
};

/// Angle of the pan unit over time (deg), linear between entries.
struct PanKey {
  double time_s = 0.0;
  double angle_deg = 0.0;
};

struct Scene {
  std::string name;
  std::vector<Material> materials;
  std::vector<SceneObject> objects;
  std::vector<Lamp> lamps;
  double ambient_irradiance_w_m2 = 0.0;  ///< In-band sunlight / room light on every surface.
  Trajectory camera;                     ///< Pan-unit base to world.
  PanUnit pan_unit;
  std::vector<PanKey> pan_schedule;          ///< Empty: the pan angle is whatever the user sets.
  double duration_s = 0.0;                   ///< Length of a dynamic scene; 0 for static scenes.
  std::map<std::string, double> parameters;  ///< Parameter values the scene was built with.

  /// Index of the first lamp-bulb object; objects [bulb_begin, end) are bulbs of lamps.
  int lamp_bulb_begin = 0;
};

/// Parameter overrides at load time, e.g. {{"distance_m", "2.5"}}.
using SceneOverrides = std::map<std::string, std::string>;

/// Parses scene YAML. `source` names the text in messages; relative mesh paths resolve against
/// `base_dir`. Throws Error(kFormat) naming source, line and problem (a key repeated within one
/// mapping too); Error(kInvalidArgument) for
/// an override that is not a declared parameter or not a number.
[[nodiscard]] Scene ParseScene(std::string_view yaml_text, const std::string& source,
                               const std::filesystem::path& base_dir,
                               const SceneOverrides& overrides = {});
/// Loads a scene file.
[[nodiscard]] Scene LoadScene(const std::filesystem::path& path,
                              const SceneOverrides& overrides = {});
/// Names of the built-in scenes.
[[nodiscard]] std::vector<std::string> BuiltinSceneNames();
/// A built-in scene by name; Error(kNotFound) listing the names when unknown.
[[nodiscard]] Scene LoadBuiltinScene(const std::string& name, const SceneOverrides& overrides = {});
/// The scene as it is at t = 0, held still: every trajectory (objects, camera) keeps its first
/// key (trajectories are held constant before it), the pan schedule its first entry, every lamp
/// its state at t = 0; duration 0. For static sequences of dynamic scenes (noise statistics, set
/// points). Throws Error(kInvalidArgument) when a trajectory's first key is before t = 0.
[[nodiscard]] Scene StaticView(Scene scene);

/// A built-in scene name, an embedded scene in a folder (e.g. "calibration/scattering-card",
/// not part of BuiltinSceneNames()) or a path to a YAML file.
[[nodiscard]] Scene ResolveScene(const std::string& name_or_path,
                                 const SceneOverrides& overrides = {});
/// Parses "name?key=value&key=value" into the name and overrides (kInvalidArgument when
/// malformed).
[[nodiscard]] std::pair<std::string, SceneOverrides> ParseSceneSpec(const std::string& spec);

/// Reads a triangle mesh from OBJ (tinyobjloader) or PLY (ASCII or binary little-endian; vertex
/// x, y, z and face vertex_indices). Throws Error(kNotFound) / Error(kFormat) naming the file
/// (and for OBJ the line): also for a coordinate that is not a finite float and, in OBJ, for a
/// vertex without 3 coordinates or a face index that is not a whole number naming one of the
/// file's vertices (a negative, relative index: one defined before the face).
void LoadMesh(const std::filesystem::path& path, std::vector<Eigen::Vector3f>& vertices,
              std::vector<Eigen::Vector3i>& triangles);

}  // namespace tofcam::sim
