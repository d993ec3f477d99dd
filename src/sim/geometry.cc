#include "geometry.h"

#include <algorithm>
#include <string>
#include <type_traits>

#include "tofcam/core/error.h"

namespace tofcam::sim::internal {

namespace {

// Embree ray packets of K rays (4, 8, 16): the widest the CPU runs natively is chosen at run
// time, so the library stays built for the x86-64 baseline while Embree uses AVX2 or AVX-512.
template <int K>
struct Packet;
template <>
struct Packet<4> {
  using RayHit = RTCRayHit4;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect4(valid, s, c, r);
  }
};
template <>
struct Packet<8> {
  using RayHit = RTCRayHit8;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect8(valid, s, c, r);
  }
};
template <>
struct Packet<16> {
  using RayHit = RTCRayHit16;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect16(valid, s, c, r);
  }
};

// The first m hits of a packet into rays [q, q + m) of b (inlined, so a constant m is a
// fixed-size copy).
// Copies m values (Count: std::size_t, or std::integral_constant for a whole packet). A plain
// loop: std::copy_n of a packet compiles to a call of memmove even at a constant 64 bytes (GCC
// 12, baseline ISA), nine calls a packet and about 2.5 % of a moving SR-2 frame in perf.
template <typename T, typename Count>
inline void CopyLanes(const T* __restrict from, Count m, T* __restrict to) {
  for (std::size_t l = 0; l < m; ++l) to[l] = from[l];
}

// The first m hits of a packet into rays q.. of b.
template <typename RayHit, typename Count>
inline void StoreHits(const RayHit& rh, Count m, std::size_t q, RayBatch& b) {
  CopyLanes(rh.ray.tfar, m, &b.t[q]);
  CopyLanes(rh.hit.geomID, m, &b.geom[q]);
  CopyLanes(rh.hit.primID, m, &b.prim[q]);
  CopyLanes(rh.hit.Ng_x, m, &b.nx[q]);
  CopyLanes(rh.hit.Ng_y, m, &b.ny[q]);
  CopyLanes(rh.hit.Ng_z, m, &b.nz[q]);
}

// Intersects rays [first, first + n) of `b`, all from `org`, in packets of K consecutive rays.
template <int K>
void TraceK(RTCScene scene, RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n,
            RayBatch& b, std::size_t first) {
  typename Packet<K>::RayHit rh{};
  alignas(64) int valid[K];
  for (int l = 0; l < K; ++l) {
    rh.ray.org_x[l] = org.x();
    rh.ray.org_y[l] = org.y();
    rh.ray.org_z[l] = org.z();
    rh.ray.mask[l] = 0xFFFFFFFFu;
    rh.ray.id[l] = static_cast<unsigned>(l);
  }
  const std::size_t end = first + n, full = first + (n - n % K);
  for (int l = 0; l < K; ++l) valid[l] = -1;
  // Full packets: fixed-size copies.
  for (std::size_t q = first; q < full; q += K) {
    const std::integral_constant<std::size_t, K> lanes;
    CopyLanes(&b.dx[q], lanes, rh.ray.dir_x);
    CopyLanes(&b.dy[q], lanes, rh.ray.dir_y);
    CopyLanes(&b.dz[q], lanes, rh.ray.dir_z);
    std::fill_n(rh.ray.tfar, K, kInf);  // stays inf on a miss
    std::fill_n(rh.hit.geomID, K, RTC_INVALID_GEOMETRY_ID);
    std::fill_n(rh.hit.instID[0], K, RTC_INVALID_GEOMETRY_ID);
    Packet<K>::Intersect(valid, scene, ctx, &rh);
    StoreHits(rh, lanes, q, b);
  }
  if (full == end) return;
  // The partial packet: inactive lanes repeat a valid ray.
  const std::size_t q = full, m = end - full;
  for (int l = 0; l < K; ++l) {
    const bool on = static_cast<std::size_t>(l) < m;
    const std::size_t i = on ? q + l : q;
    valid[l] = on ? -1 : 0;
    rh.ray.dir_x[l] = b.dx[i];
    rh.ray.dir_y[l] = b.dy[i];
    rh.ray.dir_z[l] = b.dz[i];
    rh.ray.tfar[l] = kInf;
    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
  }
  Packet<K>::Intersect(valid, scene, ctx, &rh);
  StoreHits(rh, m, q, b);
}

// The same one ray at a time (CPUs without native packets).
void Trace1(RTCScene scene, RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n,
            RayBatch& b, std::size_t first) {
  for (std::size_t i = first; i < first + n; ++i) {
    RTCRayHit rh;
    SetRay(rh, org, Eigen::Vector3f(b.dx[i], b.dy[i], b.dz[i]), 0.f);
    rtcIntersect1(scene, ctx, &rh);
    b.t[i] = rh.ray.tfar;
    b.geom[i] = rh.hit.geomID;
    b.prim[i] = rh.hit.primID;
    b.nx[i] = rh.hit.Ng_x;
    b.ny[i] = rh.hit.Ng_y;
    b.nz[i] = rh.hit.Ng_z;
  }
}

}  // namespace

// The loops below take __restrict pointers and are kept out of line (see hot_loop.h).
// (dx, dy, dz) = rot * (x, y, z) for n directions.
TOFCAM_SIM_LOOP void RotateArrays(const Eigen::Matrix3f& rot, const float* __restrict x,
                                  const float* __restrict y, const float* __restrict z,
                                  std::size_t n, float* __restrict dx, float* __restrict dy,
                                  float* __restrict dz) {
  const float r00 = rot(0, 0), r01 = rot(0, 1), r02 = rot(0, 2);
  const float r10 = rot(1, 0), r11 = rot(1, 1), r12 = rot(1, 2);
  const float r20 = rot(2, 0), r21 = rot(2, 1), r22 = rot(2, 2);
  for (std::size_t i = 0; i < n; ++i) {
    dx[i] = r00 * x[i] + r01 * y[i] + r02 * z[i];
    dy[i] = r10 * x[i] + r11 * y[i] + r12 * z[i];
    dz[i] = r20 * x[i] + r21 * y[i] + r22 * z[i];
  }
}

SceneGeometry::SceneGeometry(const Scene& scene) : scene_(scene) {
  device_ = rtcNewDevice("threads=1,set_affinity=0");
  if (!device_) throw Error(ErrorCode::kInternal, "Embree: cannot create device");
  rtc_scene_ = rtcNewScene(device_);
  // Few objects move (and only in dynamic scenes): a full-quality static BVH pays off, and the
  // re-commit after moving a small object stays cheap.
  rtcSetSceneBuildQuality(rtc_scene_, RTC_BUILD_QUALITY_MEDIUM);
  const int n = static_cast<int>(scene.objects.size());
  geometry_ids_.resize(n);
  dynamic_object_.resize(n);
  object_pose_.assign(n, Eigen::Isometry3d::Identity());
  for (int i = 0; i < n; ++i) {
    const SceneObject& o = scene.objects[i];
    dynamic_object_[i] = !o.motion.IsStatic();
    RTCGeometry g = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(
        g, dynamic_object_[i] ? RTC_BUILD_QUALITY_REFIT : RTC_BUILD_QUALITY_HIGH);
    rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                            o.vertices.size());
    auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), o.triangles.size()));
    for (std::size_t t = 0; t < o.triangles.size(); ++t) {
      for (int k = 0; k < 3; ++k) {
        const int v = o.triangles[t][k];
        if (v < 0 || v >= static_cast<int>(o.vertices.size())) {
          rtcReleaseGeometry(g);
          rtcReleaseScene(rtc_scene_);
          rtcReleaseDevice(device_);
          throw Error(ErrorCode::kInvalidArgument,
                      "scene object '" + o.name + "' has a vertex index out of range");
        }
        idx[3 * t + k] = static_cast<unsigned>(v);
      }
    }
    object_pose_[i] = o.motion.At(0.0);
    WriteVertices(g, o, object_pose_[i]);
    rtcCommitGeometry(g);
    geometry_ids_[i] = rtcAttachGeometry(rtc_scene_, g);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(rtc_scene_);
  if (rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED)) {
    packet_width_ = 16;
  } else if (rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED)) {
    packet_width_ = 8;
  } else if (rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED)) {
    packet_width_ = 4;
  }
}

SceneGeometry::~SceneGeometry() {
  if (rtc_scene_) rtcReleaseScene(rtc_scene_);
  if (device_) rtcReleaseDevice(device_);
}

void SceneGeometry::WriteVertices(RTCGeometry g, const SceneObject& o,
                                  const Eigen::Isometry3d& pose) {
  auto* v = static_cast<float*>(rtcGetGeometryBufferData(g, RTC_BUFFER_TYPE_VERTEX, 0));
  const Eigen::Matrix3f rot = pose.linear().cast<float>();
  const Eigen::Vector3f tr = pose.translation().cast<float>();
  for (std::size_t i = 0; i < o.vertices.size(); ++i) {
    const Eigen::Vector3f w = rot * o.vertices[i] + tr;
    v[3 * i] = w.x();
    v[3 * i + 1] = w.y();
    v[3 * i + 2] = w.z();
  }
}

void SceneGeometry::PlaceObjects(double time_s) {
  bool changed = false;
  for (std::size_t i = 0; i < scene_.objects.size(); ++i) {
    if (!dynamic_object_[i]) continue;
    const Eigen::Isometry3d pose = scene_.objects[i].motion.At(time_s);
    if (pose.matrix() == object_pose_[i].matrix()) continue;
    object_pose_[i] = pose;
    RTCGeometry g = rtcGetGeometry(rtc_scene_, geometry_ids_[i]);
    WriteVertices(g, scene_.objects[i], pose);
    rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
    rtcCommitGeometry(g);
    changed = true;
  }
  if (changed) {
    rtcCommitScene(rtc_scene_);
    ++version_;
  }
}

const float* SceneGeometry::WorldVertices(std::size_t i) const {
  return static_cast<const float*>(rtcGetGeometryBufferData(
      rtcGetGeometry(rtc_scene_, geometry_ids_[i]), RTC_BUFFER_TYPE_VERTEX, 0));
}

float SceneGeometry::Cast(const Eigen::Vector3f& org, const Eigen::Vector3f& dir, float tnear,
                          RTCIntersectContext& ctx, Eigen::Vector3f& normal, int& object) const {
  RTCRayHit rh;
  SetRay(rh, org, dir, tnear);
  rtcIntersect1(rtc_scene_, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return kInf;
  normal = Eigen::Vector3f(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z).normalized();
  object = static_cast<int>(rh.hit.geomID);  // attached in object order, ids 0..n-1
  return rh.ray.tfar;
}

void SceneGeometry::Trace(RTCIntersectContext* ctx, const Eigen::Vector3f& org, std::size_t n,
                          RayBatch& b, std::size_t first) const {
  switch (packet_width_) {
    case 16:
      TraceK<16>(rtc_scene_, ctx, org, n, b, first);
      break;
    case 8:
      TraceK<8>(rtc_scene_, ctx, org, n, b, first);
      break;
    case 4:
      TraceK<4>(rtc_scene_, ctx, org, n, b, first);
      break;
    default:
      Trace1(rtc_scene_, ctx, org, n, b, first);
  }
}

Eigen::Isometry3d CameraPose(const Scene& scene, double time_s, double pan_rad) {
  return scene.camera.At(time_s) * Eigen::Translation3d(-scene.pan_unit.camera_offset_m) *
         scene.pan_unit.CameraToBase(pan_rad);
}

int BlockGroup(int ss, int packet_width, int width) {
  const int s2 = ss * ss;
  if (s2 <= packet_width && packet_width % s2 == 0 && width % (packet_width / s2) == 0) {
    return packet_width / s2;
  }
  return 1;
}

}  // namespace tofcam::sim::internal
