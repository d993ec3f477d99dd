#include "tofcam/sim/simulated_camera.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "rng.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::sim {

namespace internal {
const NormalTable& GetNormalTable() {
  static const NormalTable table;
  return table;
}
}  // namespace internal

namespace {

using internal::Rng;
constexpr double kPlanckJs = 6.62607015e-34;
constexpr float kInf = std::numeric_limits<float>::infinity();

void Require(bool ok, const std::string& what) {
  if (!ok) throw Error(ErrorCode::kInvalidArgument, "simulator options: " + what);
}

// Runs body(row_begin, row_end, thread_index) over [0, rows) on `threads` threads (the caller's
// included).
template <typename F>
void ParallelRows(int rows, int threads, const F& body) {
  if (threads <= 1 || rows < 2 * threads) {
    body(0, rows, 0);
    return;
  }
  std::vector<std::thread> pool;
  pool.reserve(static_cast<std::size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) {
    pool.emplace_back([&, t] { body(rows * t / threads, rows * (t + 1) / threads, t); });
  }
  body(0, rows / threads, 0);
  for (auto& th : pool) th.join();
}

// Separable Gaussian blur with zero padding (light leaving the sensor is lost).
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h, double sigma) {
  const int radius = std::max(1, static_cast<int>(std::ceil(3 * sigma)));
  std::vector<float> k(2 * radius + 1);
  double sum = 0;
  for (int i = -radius; i <= radius; ++i)
    sum += k[i + radius] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
  for (auto& v : k) v = static_cast<float>(v / sum);
  tmp.assign(img.size(), 0.f);
  for (int r = 0; r < h; ++r) {
    const float* in = &img[static_cast<std::size_t>(r) * w];
    float* out = &tmp[static_cast<std::size_t>(r) * w];
    for (int c = 0; c < w; ++c) {
      const int lo = std::max(-radius, -c), hi = std::min(radius, w - 1 - c);
      float acc = 0;
      for (int i = lo; i <= hi; ++i) acc += k[i + radius] * in[c + i];
      out[c] = acc;
    }
  }
  for (int r = 0; r < h; ++r) {
    const int lo = std::max(-radius, -r), hi = std::min(radius, h - 1 - r);
    float* out = &img[static_cast<std::size_t>(r) * w];
    for (int c = 0; c < w; ++c) out[c] = 0;
    for (int i = lo; i <= hi; ++i) {
      const float kv = k[i + radius];
      const float* in = &tmp[static_cast<std::size_t>(r + i) * w];
      for (int c = 0; c < w; ++c) out[c] += kv * in[c];
    }
  }
}

}  // namespace

SimulatorOptions SimulatorOptions::Ideal() {
  SimulatorOptions o;
  o.shot_noise = o.read_noise = o.dark_current = o.saturation = o.blooming = false;
  o.background_light = o.glossy = o.multipath = o.scattering = false;
  o.wiggling = o.fixed_pattern = o.warmup_drift = o.exposure_offset = o.motion = false;
  return o;
}

void SimulatorOptions::Validate() const {
  Require(supersampling >= 1 && supersampling <= 8, "supersampling must be in 1..8");
  Require(threads >= 1 && threads <= 64, "threads must be in 1..64");
  Require(std::isfinite(power_on_time_s) && power_on_time_s >= 0, "power_on_time_s must be >= 0");
  Require(integration_time_register >= 0, "integration_time_register must be >= 0");
  Require(max_bounces >= 0 && max_bounces <= 8, "max_bounces must be in 0..8");
  Require(std::isfinite(motion_threshold_m) && motion_threshold_m >= 0,
          "motion_threshold_m must be >= 0");
  Require(std::isfinite(truth_mixed_span_m) && truth_mixed_span_m > 0,
          "truth_mixed_span_m must be > 0");
  Require(std::isfinite(truth_bias_m) && truth_bias_m > 0, "truth_bias_m must be > 0");
}

// Per-pixel rates (electrons per second of integration time, per tap) of one rendering.
struct Render {
  std::vector<float> re, im;                     // modulated phasor, all paths
  std::vector<float> direct_re, direct_im;       // first-surface paths only
  std::vector<float> dc;                         // optical DC: active + background
  std::vector<float> scat_re, scat_im, scat_dc;  // scattered additions
  std::vector<float> span_m;                     // subsample distance span (inf when some miss)
  void Resize(std::size_t n) {
    for (auto* v : {&re, &im, &direct_re, &direct_im, &dc, &scat_re, &scat_im, &scat_dc, &span_m}) {
      v->assign(n, 0.f);
    }
  }
};

struct RenderKey {
  Eigen::Matrix<double, 3, 4> camera;
  std::vector<double> objects;  // flattened dynamic object poses
  std::vector<char> lamps;
  bool valid = false;
  bool operator==(const RenderKey& o) const {
    return valid && o.valid && camera == o.camera && objects == o.objects && lamps == o.lamps;
  }
};

struct SimulatedCamera::Impl {
  Scene scene;
  CameraModel model;
  SimulatorOptions options;
  int width = 0, height = 0, ss = 1;
  double modulation_hz = 20e6;
  double range_m = 7.5;

  RTCDevice device = nullptr;
  RTCScene rtc_scene = nullptr;
  std::vector<unsigned> geometry_ids;          // per object
  std::vector<char> dynamic_object;            // per object
  std::vector<Eigen::Isometry3d> object_pose;  // last committed
  bool committed = false;

  // Per subsample (pixel-major, ss*ss per pixel), camera frame.
  std::vector<Eigen::Vector3f> sub_dir;
  std::vector<float> sub_active;  // K * cos^4 * LED intensity / S^2
  std::vector<float> sub_bg;      // K * cos^4 / S^2
  std::vector<Eigen::Vector3f> center_dir;

  Image<float> fpn_m;
  std::vector<Render> renders;  // 1 or 4 (one per tap time)
  std::vector<RenderKey> keys;
  RenderKey truth_key;
  std::vector<float> truth_distance;
  std::vector<float> taps[4];
  std::vector<float> tmp1, tmp2, tmp3;
  // Per pixel of the current frame: noiseless offset plus read-noise variance (electrons), the
  // denominator of the truth sigma, so blooming can add its charge to it.
  std::vector<float> truth_noise_e2;
  std::vector<float> bloom_mean;  // mean spilled charge per tap, electrons (blooming)
  std::vector<std::vector<RTCRayHit>> ray_buffers;  // per thread
  // Per object: its material's shading constants in float.
  struct ShadeMaterial {
    float diffuse = 0, glossy = 0, shininess = 1, mirror = 0, emission = 0;
  };
  std::vector<ShadeMaterial> shade;

  ~Impl() {
    if (rtc_scene) rtcReleaseScene(rtc_scene);
    if (device) rtcReleaseDevice(device);
  }

  void Build() {
    width = model.intrinsics.width;
    height = model.intrinsics.height;
    ss = options.supersampling;
    device = rtcNewDevice("threads=1,set_affinity=0");
    if (!device) throw Error(ErrorCode::kInternal, "Embree: cannot create device");
    rtc_scene = rtcNewScene(device);
    // Few objects move (and only in dynamic scenes): a full-quality static BVH pays off, and the
    // re-commit after moving a small object stays cheap.
    rtcSetSceneBuildQuality(rtc_scene, RTC_BUILD_QUALITY_MEDIUM);
    const int n = static_cast<int>(scene.objects.size());
    geometry_ids.resize(n);
    dynamic_object.resize(n);
    object_pose.assign(n, Eigen::Isometry3d::Identity());
    for (int i = 0; i < n; ++i) {
      const SceneObject& o = scene.objects[i];
      dynamic_object[i] = !o.motion.IsStatic();
      RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
      rtcSetGeometryBuildQuality(
          g, dynamic_object[i] ? RTC_BUILD_QUALITY_REFIT : RTC_BUILD_QUALITY_HIGH);
      rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                              o.vertices.size());
      auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
          g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), o.triangles.size()));
      for (std::size_t t = 0; t < o.triangles.size(); ++t) {
        for (int k = 0; k < 3; ++k) {
          const int v = o.triangles[t][k];
          if (v < 0 || v >= static_cast<int>(o.vertices.size())) {
            rtcReleaseGeometry(g);
            throw Error(ErrorCode::kInvalidArgument,
                        "scene object '" + o.name + "' has a vertex index out of range");
          }
          idx[3 * t + k] = static_cast<unsigned>(v);
        }
      }
      object_pose[i] = o.motion.At(0.0);
      WriteVertices(g, o, object_pose[i]);
      rtcCommitGeometry(g);
      geometry_ids[i] = rtcAttachGeometry(rtc_scene, g);
      rtcReleaseGeometry(g);
    }
    rtcCommitScene(rtc_scene);
    committed = true;

    // Radiometric constant K: e-/s per tap per (W m^-2 sr^-1) of scene radiance (camera equation).
    const double pixel_area = model.pixel_pitch_x_um * model.pixel_pitch_y_um * 1e-12;
    const double photons_per_j = model.wavelength_nm * 1e-9 / (kPlanckJs * kSpeedOfLightMPerS);
    const double k = kPi / (4 * model.f_number * model.f_number) * pixel_area * model.fill_factor *
                     model.quantum_efficiency * photons_per_j * model.tap_duty;
    const double m_exp = -std::log(2.0) / std::log(std::cos(model.led_half_angle_deg * kPi / 180));
    const double led_on_axis = model.led_power_w * (m_exp + 1) / (2 * kPi);  // W/sr
    const int s2 = ss * ss;
    const std::size_t np = static_cast<std::size_t>(width) * height;
    sub_dir.resize(np * s2);
    sub_active.resize(np * s2);
    sub_bg.resize(np * s2);
    center_dir.resize(np);
    for (int r = 0; r < height; ++r) {
      for (int c = 0; c < width; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * width + c;
        center_dir[p] = model.intrinsics.Unproject({c, r}).cast<float>();
        for (int i = 0; i < ss; ++i) {
          for (int j = 0; j < ss; ++j) {
            const Eigen::Vector2d px(c + (j + 0.5) / ss - 0.5, r + (i + 0.5) / ss - 0.5);
            const Eigen::Vector3d d = model.intrinsics.Unproject(px);
            const double cos_a = d.z();
            const double c4 = cos_a * cos_a * cos_a * cos_a;
            const std::size_t s = p * s2 + i * ss + j;
            sub_dir[s] = d.cast<float>();
            sub_bg[s] = static_cast<float>(k * c4 / s2);
            sub_active[s] = static_cast<float>(k * c4 * led_on_axis * std::pow(cos_a, m_exp) / s2);
          }
        }
      }
    }
    // Fixed-pattern map: a bowl reaching fpn_bowl_m at the corners plus seeded pixel spread.
    fpn_m = Image<float>(width, height, 0.f);
    if (options.fixed_pattern) {
      Rng rng(model.unit_seed ^ 0xF1F0'0000'0000'0001ull);
      const double cx = model.intrinsics.cx_px, cy = model.intrinsics.cy_px;
      const double hx = std::max(cx, width - 1 - cx), hy = std::max(cy, height - 1 - cy);
      for (int r = 0; r < height; ++r) {
        for (int c = 0; c < width; ++c) {
          const double u = (c - cx) / std::max(hx, 1.0), v = (r - cy) / std::max(hy, 1.0);
          fpn_m(r, c) = static_cast<float>(model.fpn_bowl_m * 0.5 * (u * u + v * v) +
                                           model.fpn_spread_m * rng.Normal());
        }
      }
    }
    truth_distance.assign(np, kInf);
    ray_buffers.resize(static_cast<std::size_t>(options.threads));
    shade.resize(scene.objects.size());
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      const Material& m = scene.materials.at(static_cast<std::size_t>(scene.objects[i].material));
      ShadeMaterial& sm = shade[i];
      sm.diffuse = static_cast<float>(m.albedo / kPi);
      // Normalised Blinn-Phong lobe; emitter and camera coincide, so the half vector is the
      // viewing direction and the lobe is cos^n of the incidence angle.
      sm.glossy =
          options.glossy ? static_cast<float>(m.specular * (m.shininess + 8) / (8 * kPi)) : 0.f;
      sm.shininess = static_cast<float>(m.shininess);
      sm.mirror = static_cast<float>(m.mirror);
      sm.emission = static_cast<float>(m.emission_w_m2_sr);
    }
    for (auto& t : taps) t.assign(np, 0.f);
    truth_noise_e2.assign(np, 0.f);
  }

  static void WriteVertices(RTCGeometry g, const SceneObject& o, const Eigen::Isometry3d& pose) {
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

  // Moves dynamic objects to their pose at `time_s`; recommits only when something moved.
  void PlaceObjects(double time_s) {
    bool changed = false;
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      if (!dynamic_object[i]) continue;
      const Eigen::Isometry3d pose = scene.objects[i].motion.At(time_s);
      if (pose.matrix() == object_pose[i].matrix()) continue;
      object_pose[i] = pose;
      RTCGeometry g = rtcGetGeometry(rtc_scene, geometry_ids[i]);
      WriteVertices(g, scene.objects[i], pose);
      rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
      rtcCommitGeometry(g);
      changed = true;
    }
    if (changed) rtcCommitScene(rtc_scene);
  }

  // The scene's camera pose is the optical centre at pan angle 0; the pan unit's rotation centre
  // sits camera_offset_m behind it, so pan 0 leaves the camera where the scene put it.
  Eigen::Isometry3d CameraPose(double time_s, double pan_rad) const {
    return scene.camera.At(time_s) * Eigen::Translation3d(-scene.pan_unit.camera_offset_m) *
           scene.pan_unit.CameraToBase(pan_rad);
  }

  RenderKey MakeKey(double time_s, double pan_rad) const {
    RenderKey key;
    key.camera = CameraPose(time_s, pan_rad).matrix().topRows<3>();
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      if (!dynamic_object[i]) continue;
      const Eigen::Matrix<double, 3, 4> m =
          scene.objects[i].motion.At(time_s).matrix().topRows<3>();
      key.objects.insert(key.objects.end(), m.data(), m.data() + 12);
    }
    for (const Lamp& l : scene.lamps) key.lamps.push_back(l.OnAt(time_s) ? 1 : 0);
    key.valid = true;
    return key;
  }

  static void SetRay(RTCRayHit& rh, const Eigen::Vector3f& org, const Eigen::Vector3f& dir,
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

  // Casts one ray; returns the hit distance (inf on miss), geometric normal and object.
  float Cast(const Eigen::Vector3f& org, const Eigen::Vector3f& dir, float tnear,
             RTCIntersectContext& ctx, Eigen::Vector3f& normal, int& object) const {
    RTCRayHit rh;
    SetRay(rh, org, dir, tnear);
    rtcIntersect1(rtc_scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return kInf;
    normal = Eigen::Vector3f(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z).normalized();
    object = static_cast<int>(rh.hit.geomID);  // attached in object order, ids 0..n-1
    return rh.ray.tfar;
  }

  // Renders rates at one time into `out` (no scattering yet).
  void RenderAt(double time_s, double pan_rad, Render& out) {
    PlaceObjects(time_s);
    const Eigen::Isometry3d pose = CameraPose(time_s, pan_rad);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    std::vector<char> lamp_on(scene.lamps.size());
    for (std::size_t l = 0; l < scene.lamps.size(); ++l) lamp_on[l] = scene.lamps[l].OnAt(time_s);
    const float two_pi_over_l = static_cast<float>(2 * kPi / range_m);
    const float contrast = static_cast<float>(model.demodulation_contrast);
    const float ambient =
        options.background_light ? static_cast<float>(scene.ambient_irradiance_w_m2) : 0.f;
    const int s2 = ss * ss;
    const std::size_t np = static_cast<std::size_t>(width) * height;
    if (out.re.size() != np) out.Resize(np);
    ParallelRows(height, options.threads, [&](int r0, int r1, int thread) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      std::vector<RTCRayHit>& rays = ray_buffers[thread];
      rays.resize(static_cast<std::size_t>(width) * s2);
      for (int r = r0; r < r1; ++r) {
        // Primary rays of a whole row as one coherent stream; mirror bounces go one by one.
        for (int c = 0; c < width; ++c) {
          for (int s = 0; s < s2; ++s) {
            const std::size_t si = (static_cast<std::size_t>(r) * width + c) * s2 + s;
            SetRay(rays[static_cast<std::size_t>(c) * s2 + s], org, rot * sub_dir[si], 0.f);
          }
        }
        rtcIntersect1M(rtc_scene, &ctx, rays.data(), static_cast<unsigned>(rays.size()),
                       sizeof(RTCRayHit));
        for (int c = 0; c < width; ++c) {
          const std::size_t p = static_cast<std::size_t>(r) * width + c;
          float re = 0, im = 0, dre = 0, dim = 0, dc = 0;
          float dmin = kInf, dmax = 0;
          bool miss = false;
          for (int s = 0; s < s2; ++s) {
            const std::size_t si = p * s2 + s;
            Eigen::Vector3f dir = rot * sub_dir[si];
            Eigen::Vector3f o = org;
            float path = 0, att = 1;
            for (int bounce = 0;; ++bounce) {
              Eigen::Vector3f n;
              int obj = -1;
              float t = kInf;
              if (bounce > 0) {
                t = Cast(o, dir, 1e-4f, ctx, n, obj);
              } else if (const RTCRayHit& h = rays[static_cast<std::size_t>(c) * s2 + s];
                         h.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
                t = h.ray.tfar;
                n = Eigen::Vector3f(h.hit.Ng_x, h.hit.Ng_y, h.hit.Ng_z).normalized();
                obj = static_cast<int>(h.hit.geomID);
              }
              if (!(t < kInf)) {
                if (bounce == 0) miss = true;
                break;
              }
              path += t;
              if (bounce == 0) {
                dmin = std::min(dmin, t);
                dmax = std::max(dmax, t);
              }
              const ShadeMaterial& m = shade[obj];
              const float cos_i = std::min(1.f, std::abs(n.dot(dir)));
              float brdf = m.diffuse;
              if (m.glossy > 0 && cos_i > 0) {
                brdf += m.glossy * std::exp2(m.shininess * std::log2(cos_i));
              }
              const float active = sub_active[si] * att * brdf * cos_i / (path * path);
              const float a = contrast * active;
              const float phase = two_pi_over_l * path;
              const float pre = a * std::cos(phase), pim = a * std::sin(phase);
              re += pre;
              im += pim;
              if (bounce == 0) {
                dre += pre;
                dim += pim;
              }
              float radiance = 0;
              if (options.background_light) {
                const Eigen::Vector3f hit = o + t * dir;
                float irradiance = ambient;
                const int bulb = obj - scene.lamp_bulb_begin;
                for (std::size_t l = 0; l < scene.lamps.size(); ++l) {
                  if (!lamp_on[l] || static_cast<int>(l) == bulb) continue;
                  const Eigen::Vector3f to = scene.lamps[l].position_m.cast<float>() - hit;
                  const float d2 = std::max(to.squaredNorm(), 1e-6f);
                  irradiance += static_cast<float>(scene.lamps[l].ir_power_w / (4 * kPi)) *
                                std::abs(n.dot(to)) / (d2 * std::sqrt(d2));
                }
                radiance = m.diffuse * irradiance;
                if (bulb >= 0 && lamp_on[bulb]) radiance += m.emission;
              }
              dc += active + sub_bg[si] * att * radiance;
              if (!options.multipath || m.mirror <= 0 || bounce >= options.max_bounces) break;
              // Mirror: the LED light reaches the mirrored scene and returns the same way.
              att *= m.mirror * m.mirror;
              o = o + t * dir;
              dir = dir - 2 * n.dot(dir) * n;
            }
          }
          out.re[p] = re;
          out.im[p] = im;
          out.direct_re[p] = dre;
          out.direct_im[p] = dim;
          out.dc[p] = dc;
          out.span_m[p] = miss ? (dmax > 0 ? kInf : 0.f) : dmax - dmin;
        }
      }
    });
    if (options.scattering) Scatter(out);
  }

  void TruthAt(double time_s, double pan_rad) {
    const Eigen::Isometry3d pose = CameraPose(time_s, pan_rad);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    ParallelRows(height, options.threads, [&](int r0, int r1, int thread) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      std::vector<RTCRayHit>& rays = ray_buffers[thread];
      rays.resize(static_cast<std::size_t>(width));
      for (int r = r0; r < r1; ++r) {
        for (int c = 0; c < width; ++c) {
          SetRay(rays[c], org, rot * center_dir[static_cast<std::size_t>(r) * width + c], 0.f);
        }
        rtcIntersect1M(rtc_scene, &ctx, rays.data(), static_cast<unsigned>(width),
                       sizeof(RTCRayHit));
        for (int c = 0; c < width; ++c) {
          truth_distance[static_cast<std::size_t>(r) * width + c] =
              rays[c].hit.geomID == RTC_INVALID_GEOMETRY_ID ? kInf : rays[c].ray.tfar;
        }
      }
    });
  }

  void Scatter(Render& out) {
    double total = 0, min_sigma = 1e9;
    for (const ScatterLobe& l : model.scattering) {
      total += l.weight;
      min_sigma = std::min(min_sigma, l.sigma_px);
    }
    if (total <= 0) {
      std::fill(out.scat_re.begin(), out.scat_re.end(), 0.f);
      std::fill(out.scat_im.begin(), out.scat_im.end(), 0.f);
      std::fill(out.scat_dc.begin(), out.scat_dc.end(), 0.f);
      return;
    }
    // Wide lobes are smooth: blur at 1/f resolution (f <= sigma/2) and interpolate back.
    const int f = std::clamp(static_cast<int>(min_sigma / 2), 1, 8);
    const int rw = (width + f - 1) / f, rh = (height + f - 1) / f;
    const std::vector<float>* src[3] = {&out.re, &out.im, &out.dc};
    std::vector<float>* dst[3] = {&out.scat_re, &out.scat_im, &out.scat_dc};
    for (int ch = 0; ch < 3; ++ch) {
      tmp1.assign(static_cast<std::size_t>(rw) * rh, 0.f);
      for (int r = 0; r < height; ++r) {
        float* dst_row = &tmp1[static_cast<std::size_t>(r / f) * rw];
        const float* src_row = &(*src[ch])[static_cast<std::size_t>(r) * width];
        for (int c0 = 0, j = 0; c0 < width; c0 += f, ++j) {
          float acc = 0;
          for (int c = c0; c < std::min(c0 + f, width); ++c) acc += src_row[c];
          dst_row[j] += acc;
        }
      }
      std::vector<float> acc(tmp1.size(), 0.f);
      for (const ScatterLobe& l : model.scattering) {
        if (l.weight <= 0) continue;
        tmp2 = tmp1;
        BlurInPlace(tmp2, tmp3, rw, rh, l.sigma_px / f);
        for (std::size_t i = 0; i < acc.size(); ++i)
          acc[i] += static_cast<float>(l.weight) * tmp2[i];
      }
      // Bilinear upsampling; reduced pixel (i, j) covers full pixels [f*i, f*i + f).
      std::vector<float>& d = *dst[ch];
      for (int r = 0; r < height; ++r) {
        const double y = (r + 0.5) / f - 0.5;
        const int y0 = std::clamp(static_cast<int>(std::floor(y)), 0, rh - 1),
                  y1 = std::min(y0 + 1, rh - 1);
        const float wy = static_cast<float>(std::clamp(y - y0, 0.0, 1.0));
        for (int c = 0; c < width; ++c) {
          const double x = (c + 0.5) / f - 0.5;
          const int x0 = std::clamp(static_cast<int>(std::floor(x)), 0, rw - 1),
                    x1 = std::min(x0 + 1, rw - 1);
          const float wx = static_cast<float>(std::clamp(x - x0, 0.0, 1.0));
          const auto at = [&](int yy, int xx) {
            return acc[static_cast<std::size_t>(yy) * rw + xx];
          };
          const float v = (1 - wy) * ((1 - wx) * at(y0, x0) + wx * at(y0, x1)) +
                          wy * ((1 - wx) * at(y1, x0) + wx * at(y1, x1));
          // Each reduced pixel summed f*f full pixels: spread the sum back over f*f pixels.
          d[static_cast<std::size_t>(r) * width + c] = v / static_cast<float>(f * f);
        }
      }
    }
  }

  // Saturation physics on the noisy tap charges (electrons). A storage site holds at most the
  // full well. Of a full site's excess, `overflow` spills over the barrier into the pixel's other
  // sites, which share its photo-gate (filled evenly into the sites with room left): the taps of a
  // saturating pixel equalise, so its offset keeps rising while its amplitude collapses. Of the
  // charge that cannot stay in the pixel, `bloom` leaves it for the neighbours (Gaussian of
  // blooming_sigma_px); the rest goes to the drain.
  // Bloomed charge is charge, not light: it reaches a neighbour's photo-gate at times unrelated to
  // the 20 MHz gate clock, so the neighbour's demodulation sorts it into its four taps equally on
  // average. It raises the neighbour's offset (intensity) but not its amplitude, and each electron
  // lands independently, so every tap receives a Poisson count of it (when shot noise is on):
  // the extra noise eq. 2 predicts from the raised intensity.
  // Returns true when charge bloomed; bloom_mean then holds the mean spill per tap of every pixel.
  bool Saturate(double full_well, double overflow, double bloom, std::uint64_t frame_seed,
                bool shot_noise) {
    const std::size_t np = taps[0].size();
    const float fw = static_cast<float>(full_well);
    const float keep_share = static_cast<float>(overflow);
    const float out_share = static_cast<float>(bloom);
    bool any = false;
    bloom_mean.assign(np, 0.f);
    for (std::size_t i = 0; i < np; ++i) {
      float n[4], excess = 0;
      for (int k = 0; k < 4; ++k) {
        n[k] = taps[k][i];
        if (n[k] > fw) {
          excess += n[k] - fw;
          n[k] = fw;
        }
      }
      if (!(excess > 0)) continue;
      float keep = keep_share * excess;
      // Water-filling: at most three rounds, since each round fills at least one more site.
      for (int round = 0; round < 4 && keep > 0; ++round) {
        int room = 0;
        for (int k = 0; k < 4; ++k) room += n[k] < fw;
        if (room == 0) break;
        const float share = keep / static_cast<float>(room);
        for (int k = 0; k < 4; ++k) {
          if (!(n[k] < fw)) continue;
          const float add = std::min(share, fw - n[k]);
          n[k] += add;
          keep -= add;
        }
      }
      for (int k = 0; k < 4; ++k) taps[k][i] = n[k];
      const float spill = out_share * ((1 - keep_share) * excess + std::max(keep, 0.f));
      if (spill > 0) {
        bloom_mean[i] = spill / 4;  // per tap of the receiving pixel
        any = true;
      }
    }
    if (!any) return false;
    BlurInPlace(bloom_mean, tmp2, width, height, model.blooming_sigma_px);
    for (int r = 0; r < height; ++r) {
      Rng rng(frame_seed ^ 0xB10060000000000Dull ^
              (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull));
      for (int c = 0; c < width; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * width + c;
        const float mean = bloom_mean[i];
        if (!(mean > 0)) continue;
        for (auto& tap : taps) {
          tap[i] += shot_noise ? static_cast<float>(rng.Poisson(mean)) : mean;
        }
      }
    }
    return true;
  }
};

SimulatedCamera::SimulatedCamera(Scene scene, CameraModel model, SimulatorOptions options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  model.Validate();
  if (scene.objects.empty()) throw Error(ErrorCode::kInvalidArgument, "scene has no objects");
  impl_->scene = std::move(scene);
  impl_->model = std::move(model);
  impl_->options = options;
  impl_->modulation_hz = impl_->model.modulation_frequencies_hz.front();
  impl_->range_m = UnambiguousRangeM(impl_->modulation_hz);
  info_ = impl_->model.Info(impl_->modulation_hz);
  integration_register_ = options.integration_time_register == 0
                              ? impl_->model.default_integration_register
                              : options.integration_time_register;
  if (integration_register_ < impl_->model.min_integration_register ||
      integration_register_ > impl_->model.max_integration_register) {
    throw Error(ErrorCode::kInvalidArgument,
                "simulator options: integration_time_register " +
                    std::to_string(integration_register_) + " outside [" +
                    std::to_string(impl_->model.min_integration_register) + ", " +
                    std::to_string(impl_->model.max_integration_register) + "]");
  }
  impl_->Build();
}

SimulatedCamera::~SimulatedCamera() = default;

const Scene& SimulatedCamera::scene() const noexcept { return impl_->scene; }
const CameraModel& SimulatedCamera::model() const noexcept { return impl_->model; }
const SimulatorOptions& SimulatedCamera::options() const noexcept { return impl_->options; }
const Image<float>& SimulatedCamera::FixedPatternOffsetM() const noexcept { return impl_->fpn_m; }

double SimulatedCamera::WarmupOffsetM(double time_s) const noexcept {
  if (!impl_->options.warmup_drift) return 0.0;
  return impl_->model.warmup_amplitude_m *
         std::exp(-(impl_->options.power_on_time_s + time_s) / impl_->model.warmup_time_constant_s);
}

void SimulatedCamera::SetIntegrationTimeRegister(int reg) {
  if (reg < info_.min_integration_register || reg > info_.max_integration_register) {
    throw Error(ErrorCode::kInvalidArgument,
                "integration-time register " + std::to_string(reg) + " outside [" +
                    std::to_string(info_.min_integration_register) + ", " +
                    std::to_string(info_.max_integration_register) + "]");
  }
  integration_register_ = reg;
}

void SimulatedCamera::SetModulationFrequencyHz(double hz) {
  for (double f : impl_->model.modulation_frequencies_hz) {
    if (std::isfinite(hz) && std::abs(f - hz) <= 1.0) {
      if (f != impl_->modulation_hz) {
        impl_->modulation_hz = f;
        impl_->range_m = UnambiguousRangeM(f);
        info_.modulation_frequency_hz = f;
        for (auto& k : impl_->keys) k.valid = false;  // phases change
        impl_->truth_key.valid = false;
      }
      return;
    }
  }
  std::string known;
  for (double f : impl_->model.modulation_frequencies_hz) {
    known += (known.empty() ? "" : ", ") + std::to_string(static_cast<long long>(f)) + " Hz";
  }
  throw Error(ErrorCode::kInvalidArgument, "modulation frequency " + std::to_string(hz) +
                                               " Hz not supported by " + info_.model + " (" +
                                               known + ")");
}

void SimulatedCamera::SetDistanceOffsetRegister(int reg) {
  if (reg < 0 || reg > 65535) {
    throw Error(ErrorCode::kInvalidArgument,
                "distance-offset register " + std::to_string(reg) + " outside [0, 65535]");
  }
  offset_register_ = reg;
}

void SimulatedCamera::SetPanAngleRad(double angle_rad) {
  if (!std::isfinite(angle_rad)) {
    throw Error(ErrorCode::kInvalidArgument, "pan angle must be finite");
  }
  pan_override_rad_ = angle_rad;
}

double SimulatedCamera::PanAngleRad() const {
  if (pan_override_rad_) return *pan_override_rad_;
  const auto& sched = impl_->scene.pan_schedule;
  if (sched.empty()) return 0.0;
  const double t = next_start_s_;
  if (t <= sched.front().time_s) return sched.front().angle_deg * kPi / 180;
  if (t >= sched.back().time_s) return sched.back().angle_deg * kPi / 180;
  for (std::size_t i = 1; i < sched.size(); ++i) {
    if (t < sched[i].time_s) {
      const double w = (t - sched[i - 1].time_s) / (sched[i].time_s - sched[i - 1].time_s);
      return (sched[i - 1].angle_deg + w * (sched[i].angle_deg - sched[i - 1].angle_deg)) * kPi /
             180;
    }
  }
  return sched.back().angle_deg * kPi / 180;
}

std::optional<Frame> SimulatedCamera::Grab() {
  Impl& im = *impl_;
  const SimulatorOptions& opt = im.options;
  const CameraModel& model = im.model;
  const int w = im.width, h = im.height;
  const double t_int_us = info_.IntegrationTimeUs(integration_register_);
  const double t_int_s = t_int_us * 1e-6;
  const double start = next_start_s_;
  const double mid = start + t_int_s / 2;
  const double pan = PanAngleRad();

  // Does anything move noticeably during this exposure? Compare the poses at its two ends.
  bool split = false;
  if (opt.motion) {
    const RenderKey a = im.MakeKey(start, pan), b = im.MakeKey(start + t_int_s, pan);
    const double lever = 5.0;  // m: rotation error measured at a 5 m lever arm
    auto moved = [&](const auto& x, const auto& y) {
      // ||R1 - R2||_F = 2 sqrt(2) sin(angle / 2), about sqrt(2) * angle for small angles.
      return (x.col(3) - y.col(3)).norm() +
                 lever * (x.template leftCols<3>() - y.template leftCols<3>()).norm() /
                     std::sqrt(2.0) >
             opt.motion_threshold_m;
    };
    split = moved(a.camera, b.camera);
    for (std::size_t i = 0; !split && i + 12 <= a.objects.size(); i += 12) {
      split = moved(Eigen::Map<const Eigen::Matrix<double, 3, 4>>(&a.objects[i]),
                    Eigen::Map<const Eigen::Matrix<double, 3, 4>>(&b.objects[i]));
    }
  }
  const int slots = split ? 4 : 1;
  im.renders.resize(4);
  im.keys.resize(4);
  for (int s = 0; s < slots; ++s) {
    const double t = split ? start + (s + 0.5) * t_int_s / 4 : mid;
    const RenderKey key = im.MakeKey(t, pan);
    if (!(key == im.keys[s])) {
      im.RenderAt(t, pan, im.renders[s]);
      im.keys[s] = key;
    }
  }
  const RenderKey truth_key = im.MakeKey(mid, pan);
  if (!(truth_key == im.truth_key)) {
    im.PlaceObjects(mid);
    im.TruthAt(mid, pan);
    im.truth_key = truth_key;
  }

  Frame frame;
  frame.distance = Image<std::uint16_t>(w, h);
  frame.amplitude = Image<std::uint16_t>(w, h);
  frame.intensity = Image<std::uint16_t>(w, h);
  GroundTruth truth;
  truth.radial_distance_m = Image<float>(w, h);
  truth.causes = Image<PixelFlags>(w, h);
  truth.sigma_m = Image<float>(w, h);

  const double range = im.range_m;
  const double two_pi = 2 * kPi;
  const double dark =
      opt.dark_current ? model.dark_current_e_per_s * model.tap_duty * t_int_s : 0.0;
  double global_offset_m = 0;
  if (opt.warmup_drift) global_offset_m += WarmupOffsetM(mid);
  if (opt.exposure_offset) global_offset_m += model.exposure_offset_m_per_ms * t_int_us * 1e-3;
  const double read_sigma = opt.read_noise ? model.read_noise_e : 0.0;
  const double full_well = model.full_well_e;
  const double bias_rad = opt.truth_bias_m * two_pi / range;
  const std::uint64_t frame_seed =
      opt.seed * 0x9E3779B97F4A7C15ull + sequence_ * 0xD1B54A32D192ED03ull;

  // Taps: noiseless means, then shot and read noise per tap.
  const double cos_bias = std::cos(std::min(bias_rad, kPi));
  // True when the angle between phasors (ar, ai) and (br, bi) exceeds the truth bias.
  auto differ = [cos_bias](double ar, double ai, double br, double bi) {
    const double dot = ar * br + ai * bi;
    const double norms = std::sqrt((ar * ar + ai * ai) * (br * br + bi * bi));
    return dot < cos_bias * norms;
  };
  const double wiggle_a = opt.wiggling ? model.wiggle_amplitude_m : 0.0;
  const double m_to_rad = two_pi / range;
  ParallelRows(h, opt.threads, [&](int r0, int r1, int /*thread*/) {
    for (int r = r0; r < r1; ++r) {
      Rng rng(frame_seed ^ (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull));
      for (int c = 0; c < w; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * w + c;
        PixelFlags causes;
        double a_mean = 0, b_mean = 0;
        const double pixel_offset_m = global_offset_m + (opt.fixed_pattern ? im.fpn_m[p] : 0.0);
        double mu[4];
        for (int slot = 0; slot < slots; ++slot) {
          const Render& rd = im.renders[slot];
          const double re = (rd.re[p] + rd.scat_re[p]) * t_int_s;
          const double imag = (rd.im[p] + rd.scat_im[p]) * t_int_s;
          const double b = (rd.dc[p] + rd.scat_dc[p]) * t_int_s + dark;
          const double a = std::sqrt(re * re + imag * imag);
          double cos_p = 1, sin_p = 0;
          if (a > 0) {
            double offset_m = pixel_offset_m;
            if (wiggle_a != 0) {
              // The odd harmonics make the error periodic in the measured phase with period L/4.
              const double phase = std::atan2(imag, re);
              offset_m += wiggle_a * std::sin(4 * phase + model.wiggle_phase_rad);
            }
            const double cr = re / a, ci = imag / a;
            const double shift = offset_m * m_to_rad;
            const double cs = std::cos(shift), sn = std::sin(shift);
            cos_p = cr * cs - ci * sn;
            sin_p = ci * cs + cr * sn;
          }
          // mu_k = B + A cos(phi - k pi / 2): cos, sin, -cos, -sin.
          const double taps_k[4] = {b + a * cos_p, b + a * sin_p, b - a * cos_p, b - a * sin_p};
          if (slots == 1) {
            for (int k = 0; k < 4; ++k) mu[k] = taps_k[k];
          } else {
            mu[slot] = taps_k[slot];
          }
          a_mean += a / slots;
          b_mean += b / slots;
          if (slot == 0) {
            // Truth causes from the noiseless components.
            const double ind_re = rd.re[p] - rd.direct_re[p], ind_im = rd.im[p] - rd.direct_im[p];
            const double ind2 = ind_re * ind_re + ind_im * ind_im;
            const double dir2 = static_cast<double>(rd.direct_re[p]) * rd.direct_re[p] +
                                static_cast<double>(rd.direct_im[p]) * rd.direct_im[p];
            // Multipath: the indirect paths shift the phase noticeably, or outweigh the direct one.
            if (ind2 > 0 &&
                (ind2 >= dir2 || differ(rd.re[p], rd.im[p], rd.direct_re[p], rd.direct_im[p]))) {
              causes.Set(Flag::kMultipath);
            }
            if ((rd.scat_re[p] != 0 || rd.scat_im[p] != 0) &&
                differ(re, imag, rd.re[p], rd.im[p])) {
              causes.Set(Flag::kScattering);
            }
            if (rd.span_m[p] > opt.truth_mixed_span_m) causes.Set(Flag::kMixed);
          }
        }
        if (slots > 1) {
          const Render& r0d = im.renders[0];
          for (int k = 1; k < 4; ++k) {
            if (differ(im.renders[k].re[p], im.renders[k].im[p], r0d.re[p], r0d.im[p])) {
              causes.Set(Flag::kMotion);
              break;
            }
          }
        }
        for (int k = 0; k < 4; ++k) {
          double v = mu[k];
          if (opt.shot_noise) v = rng.Poisson(v);
          if (read_sigma > 0) v += read_sigma * rng.Normal();
          im.taps[k][p] = static_cast<float>(v);
        }
        const float td = im.truth_distance[p];
        truth.radial_distance_m[p] = td;
        if (!(td < kInf)) causes.Set(Flag::kNoReturn);
        if (td >= range && td < kInf) causes.Set(Flag::kBeyondUnambiguous);
        truth.sigma_m[p] =
            a_mean > 0 ? static_cast<float>(range * std::sqrt(b_mean + read_sigma * read_sigma) /
                                            (2 * std::sqrt(2.0) * kPi * a_mean))
                       : 0.f;
        im.truth_noise_e2[p] = static_cast<float>(b_mean + read_sigma * read_sigma);
        truth.causes[p] = causes;
      }
    }
  });
  if (opt.saturation) {
    if (im.Saturate(full_well, model.overflow_fraction,
                    opt.blooming ? model.blooming_fraction : 0.0, frame_seed, opt.shot_noise)) {
      // The spilled charge is offset without amplitude: it raises the true shot-noise sigma by
      // sqrt((B + spill) / B) (B including the read-noise variance).
      for (std::size_t p = 0; p < im.bloom_mean.size(); ++p) {
        if (im.bloom_mean[p] > 0 && im.truth_noise_e2[p] > 0) {
          truth.sigma_m[p] *=
              std::sqrt((im.truth_noise_e2[p] + im.bloom_mean[p]) / im.truth_noise_e2[p]);
        }
      }
    }
  }
  // Clip, demodulate and quantise.
  const double gain = model.gain_reg_per_e;
  ParallelRows(h, opt.threads, [&](int r0, int r1, int /*thread*/) {
    for (int r = r0; r < r1; ++r) {
      for (int c = 0; c < w; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * w + c;
        double n[4];
        bool saturated = false;
        for (int k = 0; k < 4; ++k) {
          n[k] = std::max(0.0, static_cast<double>(im.taps[k][p]));
          if (opt.saturation && n[k] >= full_well) {
            n[k] = full_well;
            saturated = true;
          }
        }
        const double i_comp = n[0] - n[2], q_comp = n[1] - n[3];
        double phase = std::atan2(q_comp, i_comp);
        if (phase < 0) phase += two_pi;
        const double amp = std::sqrt(i_comp * i_comp + q_comp * q_comp) / 2;
        const double off = (n[0] + n[1] + n[2] + n[3]) / 4;
        long long reg = std::llround(phase / two_pi * kDistanceRegisterSpan) + offset_register_;
        frame.distance[p] = static_cast<std::uint16_t>(reg & 0xFFFF);
        frame.amplitude[p] = static_cast<std::uint16_t>(
            std::min<double>(kMaxSignalRegister, std::round(gain * amp)));
        frame.intensity[p] = static_cast<std::uint16_t>(
            std::min<double>(kMaxSignalRegister, std::round(gain * off)));
        if (saturated || gain * off > kMaxSignalRegister) truth.causes[p].Set(Flag::kSaturated);
      }
    }
  });

  frame.info.sequence = sequence_;
  frame.info.timestamp_ns = static_cast<std::int64_t>(std::llround(mid * 1e9));
  frame.info.integration_time_register = integration_register_;
  frame.info.integration_time_us = t_int_us;
  frame.info.modulation_frequency_hz = im.modulation_hz;
  frame.info.pan_angle_rad = pan;
  frame.info.distance_offset_register = offset_register_;
  frame.info.camera_model = model.name;
  frame.info.has_intensity = true;
  frame.truth = std::move(truth);

  const double period =
      std::max(1.0 / model.max_frame_rate_hz, t_int_s + model.readout_time_us * 1e-6);
  next_start_s_ = start + period;
  ++sequence_;
  if (opt.real_time) {
    // Frame n is due when its successor's exposure would start, on a clock anchored at the first
    // throttled frame.
    using Clock = std::chrono::steady_clock;
    if (!real_time_origin_)
      real_time_origin_ = Clock::now() - std::chrono::duration_cast<Clock::duration>(
                                             std::chrono::duration<double>(start));
    std::this_thread::sleep_until(
        *real_time_origin_ +
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(next_start_s_)));
  }
  return frame;
}

}  // namespace tofcam::sim
