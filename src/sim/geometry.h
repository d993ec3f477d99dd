#pragma once
// Simulator stage 1, geometry and ray casting (internal to tofcam::sim, docs/simulator.md): the
// scene's triangles in an Embree BVH that follows the moving objects, the camera pose on its pan
// unit, the pixels' subsample rays and batched ray casting in the CPU's native packet width.

#include <embree3/rtcore.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "hot_loop.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {

/// Rays of one batch in structure-of-arrays form: directions in, hits out.
struct RayBatch {
  std::vector<float> dx, dy, dz;  ///< world directions (unit)
  std::vector<float> t;           ///< hit distance, m; inf on a miss
  std::vector<unsigned> geom;     ///< geometry id (= object index) or RTC_INVALID_GEOMETRY_ID
  std::vector<unsigned> prim;     ///< triangle index within the geometry; undefined on a miss
  std::vector<float> nx, ny, nz;  ///< geometric normal, not normalised; undefined on a miss
  void Resize(std::size_t n) {
    for (auto* v : {&dx, &dy, &dz, &t, &nx, &ny, &nz}) v->resize(n);
    geom.resize(n);
    prim.resize(n);
  }
};

/// Fills one Embree ray: origin, direction, near distance (m), infinite far, no hit yet.
inline void SetRay(RTCRayHit& rh, const Eigen::Vector3f& org, const Eigen::Vector3f& dir,
                   float tnear) {
  rh.ray.org_x = org.x();
  rh.ray.org_y = org.y();
  rh.ray.org_z = org.z();
  rh.ray.dir_x = dir.x();
  rh.ray.dir_y = dir.y();
  rh.ray.dir_z = dir.z();
  rh.ray.tnear = tnear;
  rh.ray.tfar = kInf;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.time = 0;
  rh.ray.flags = 0;
  rh.ray.id = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

/// (dx, dy, dz) = rot * (x, y, z) for n directions (vectorised).
void RotateArrays(const Eigen::Matrix3f& rot, const float* __restrict x, const float* __restrict y,
                  const float* __restrict z, std::size_t n, float* __restrict dx,
                  float* __restrict dy, float* __restrict dz);

/// The scene's triangles in an Embree scene: static objects in a high-quality BVH, moving ones
/// refitted when they move. Object i is Embree geometry i. Not copyable.
class SceneGeometry {
 public:
  /// Throws Error(kInternal) when Embree fails, Error(kInvalidArgument) for a vertex index out of
  /// range. Objects start at their pose at time 0.
  explicit SceneGeometry(const Scene& scene);
  ~SceneGeometry();
  SceneGeometry(const SceneGeometry&) = delete;
  SceneGeometry& operator=(const SceneGeometry&) = delete;

  /// Moves the dynamic objects to their pose at `time_s`; recommits only when something moved.
  void PlaceObjects(double time_s);
  /// Grows by one each time PlaceObjects moves something (0 at construction).
  [[nodiscard]] std::uint64_t Version() const noexcept { return version_; }
  /// Whether object i moves (its motion is not static).
  [[nodiscard]] bool Dynamic(std::size_t i) const { return dynamic_object_[i] != 0; }
  /// Rays per packet the CPU runs natively: 16, 8, 4 or 1.
  [[nodiscard]] int PacketWidth() const noexcept { return packet_width_; }
  [[nodiscard]] RTCScene Handle() const noexcept { return rtc_scene_; }
  /// World coordinates (x, y, z per vertex, m) of object i's vertices at its current pose, in the
  /// order of SceneObject::vertices.
  [[nodiscard]] const float* WorldVertices(std::size_t i) const;

  /// Casts one ray from `org` along unit `dir` beyond `tnear` (m); returns the hit distance (inf
  /// on a miss) and sets the unit geometric normal and the object index on a hit.
  float Cast(const Eigen::Vector3f& org, const Eigen::Vector3f& dir, float tnear,
             RTCIntersectContext& ctx, Eigen::Vector3f& normal, int& object) const;
  /// Intersects rays [first, first + n) of `b` (all from org) in the CPU's native packet width.
  void Trace(RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n, RayBatch& b,
             std::size_t first = 0) const;

 private:
  static void WriteVertices(RTCGeometry g, const SceneObject& o, const Eigen::Isometry3d& pose);

  const Scene& scene_;
  RTCDevice device_ = nullptr;
  RTCScene rtc_scene_ = nullptr;
  std::vector<unsigned> geometry_ids_;          // per object
  std::vector<char> dynamic_object_;            // per object
  std::vector<Eigen::Isometry3d> object_pose_;  // last committed
  int packet_width_ = 1;
  std::uint64_t version_ = 0;
};

/// The camera's pose in the world at `time_s` and pan angle `pan_rad`: the scene's camera pose is
/// the optical centre at pan angle 0; the pan unit's rotation centre sits camera_offset_m behind
/// it, so pan 0 leaves the camera where the scene put it.
[[nodiscard]] Eigen::Isometry3d CameraPose(const Scene& scene, double time_s, double pan_rad);

/// Per subsample ray of the camera, in camera coordinates, as arrays in the order the rays go to
/// Embree: a row is split into blocks of `group` neighbouring pixels, and a block holds their
/// subsample s = i S + j (i, j in 0..S-1) for s = 0, 1, .., S^2 - 1 in turn, so one packet of
/// group * S^2 rays covers group x 1 pixels and the per-pixel sums over subsamples are vector adds.
struct PixelRays {
  int width = 0, height = 0, ss = 1;
  int group = 1;  ///< pixels per block (1: pixel-major, when S^2 does not divide a packet)
  std::vector<float> sub_x, sub_y, sub_z;           ///< unit direction per subsample
  std::vector<float> center_x, center_y, center_z;  ///< per pixel: the central ray (truth)
  /// Position of subsample s of column c within a row's arrays.
  [[nodiscard]] std::size_t Index(int s, int c) const {
    const int s2 = ss * ss;
    return static_cast<std::size_t>(c / group) * group * s2 + static_cast<std::size_t>(s) * group +
           c % group;
  }
};

/// Pixels per block for S x S subsamples and a packet width: packet / S^2 when S^2 divides the
/// packet and the block divides the width, else 1.
[[nodiscard]] int BlockGroup(int ss, int packet_width, int width);

}  // namespace tofcam::sim::internal
