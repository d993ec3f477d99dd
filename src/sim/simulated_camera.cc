#include "tofcam/sim/simulated_camera.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "geometry.h"
#include "noise.h"
#include "optics.h"
#include "parallel.h"
#include "radiometry.h"
#include "rng.h"
#include "sensor.h"
#include "subsample_shortcut.h"
#include "timing.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::sim {

using namespace internal;  // NOLINT: the stages of this simulator

namespace {

void Require(bool ok, const std::string& what) {
  if (!ok) throw Error(ErrorCode::kInvalidArgument, "simulator options: " + what);
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
  Require(interreflection_samples >= 1 && interreflection_samples <= 256,
          "interreflection_samples must be in 1..256");
  Require(std::isfinite(motion_threshold_m) && motion_threshold_m >= 0,
          "motion_threshold_m must be >= 0");
  Require(std::isfinite(truth_mixed_span_m) && truth_mixed_span_m > 0,
          "truth_mixed_span_m must be > 0");
  Require(std::isfinite(truth_bias_m) && truth_bias_m > 0, "truth_bias_m must be > 0");
}

// The simulator as a composition of its stages (docs/simulator.md): geometry and ray casting
// (geometry.h), radiometry (radiometry.h), optics (optics.h), the sensor (sensor.h), noise
// (noise.h) and timing (timing.h). Impl owns the stages' state and per-thread scratch; Grab() runs
// them in order.
struct SimulatedCamera::Impl {
  Scene scene;
  CameraModel model;
  SimulatorOptions options;
  int width = 0, height = 0, ss = 1;
  double modulation_hz = 20e6;
  double range_m = 7.5;

  std::unique_ptr<SceneGeometry> geometry;      // stage 1: Embree scene of `scene`
  std::unique_ptr<SubsampleShortcut> shortcut;  // stage 1: the planar shortcut, when on
  std::vector<char> dynamic_object;             // per object: does it move
  PixelRays rays;                               // stage 1: subsample and central rays
  SubsampleRadiometry rad;                      // stage 2: camera factors per subsample
  MaterialTable mats;                           // stage 2: shading constants per object
  ScatterPlan scatter;                          // stage 3: scattering PSF
  InterreflectionBuffers ir;                    // stage 3: inter-reflection per pixel
  Image<float> fpn_m;                           // stage 5: fixed-pattern offsets, m

  std::vector<Render> renders;  // 1 or 4 (one per tap time)
  std::vector<RenderKey> keys;
  RenderKey truth_key;
  std::vector<float> truth_distance;
  std::vector<float> taps[4];
  std::vector<float> tmp2;  // scratch of the blooming blur
  // Per pixel of the current frame: noiseless offset plus read-noise variance (electrons), the
  // denominator of the truth sigma, so blooming can add its charge to it.
  std::vector<float> truth_noise_e2;
  std::vector<float> bloom_mean;  // mean spilled charge per tap, electrons (blooming)
  // Per thread: one row of rays and the shading terms of each ray.
  struct Scratch {
    RayBatch rays;
    RayBatch rest;                  // the planar shortcut: subsample rays Embree casts
    std::vector<unsigned> rest_at;  // their positions in `rays`
    std::vector<std::uint8_t> ok;   // per subsample: the closed form holds
    std::vector<float> cos_i;       // cosine of incidence
    std::vector<float> weight;  // active electrons / s before the 1/d^2 and phase: I cos4 brdf cos
    std::vector<float> dist;    // hit distance, 1 on a miss (weight 0) so the phase stays finite
    std::vector<float> bg;      // background radiance times sub_bg
    std::vector<float> re, im;  // phasor of each subsample
    std::vector<float> scatter_tmp[4];  // reduced images of one scattering channel
    std::vector<unsigned> glossy_at;    // subsamples on glossy materials
    GlossyScratch glossy;               // their lobes
    std::vector<int> mirrored;          // subsamples whose first hit is a mirror (bounces follow)
    SensorRow sensor;
    std::vector<std::uint8_t> saturated;  // one row of DemodulateRow
  };
  std::vector<Scratch> scratch;  // per thread
  std::unique_ptr<RowPool> pool;

  void Build() {
    width = model.intrinsics.width;
    height = model.intrinsics.height;
    ss = options.supersampling;
    geometry = std::make_unique<SceneGeometry>(scene);
    dynamic_object.resize(scene.objects.size());
    for (std::size_t i = 0; i < scene.objects.size(); ++i) dynamic_object[i] = geometry->Dynamic(i);
    const std::size_t np = static_cast<std::size_t>(width) * height;
    rays.group = BlockGroup(ss, geometry->PacketWidth(), width);
    BuildPixelRays(model, ss, rays, rad);
    // With one ray per pixel every subsample is a central ray: nothing to save.
    if (options.planar_shortcut && ss > 1) {
      shortcut = std::make_unique<SubsampleShortcut>(scene, model, rays);
    }
    scatter = PlanScatter(model.scattering, width, height);
    fpn_m = options.fixed_pattern ? FixedPatternMap(model) : Image<float>(width, height, 0.f);
    truth_distance.assign(np, kInf);
    scratch.resize(static_cast<std::size_t>(options.threads));
    pool = std::make_unique<RowPool>(options.threads);
    mats = BuildMaterials(scene, options.glossy);
    for (auto& t : taps) t.assign(np, 0.f);
    truth_noise_e2.assign(np, 0.f);
  }

  RenderKey MakeKey(double time_s, double pan_rad) const {
    return MakeRenderKey(scene, dynamic_object, time_s, pan_rad);
  }

  // World directions of n camera-frame directions (x, y, z) into b.dx.. starting at `at`.
  static void Rotate(const Eigen::Matrix3f& rot, const float* x, const float* y, const float* z,
                     std::size_t n, RayBatch& b, std::size_t at) {
    RotateArrays(rot, x, y, z, n, b.dx.data() + at, b.dy.data() + at, b.dz.data() + at);
  }

  // Renders rates at one time into `out` (no scattering yet). With `truth`, the central ray of
  // every pixel is cast in the same batches and truth_distance is filled too (same time and pose).
  void RenderAt(double time_s, double pan_rad, Render& out, bool truth) {
    geometry->PlaceObjects(time_s);
    const Eigen::Isometry3d pose = CameraPose(scene, time_s, pan_rad);
    const std::vector<float>&sub_x = rays.sub_x, &sub_y = rays.sub_y, &sub_z = rays.sub_z;
    const std::vector<float>&center_x = rays.center_x, &center_y = rays.center_y,
          &center_z = rays.center_z;
    const std::vector<float>&sub_active = rad.sub_active, &sub_bg = rad.sub_bg;
    const std::vector<ShadeMaterial>& shade = mats.shade;
    const int group = rays.group;
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    std::vector<char> lamp_on(scene.lamps.size());
    bool any_lamp = false;
    for (std::size_t l = 0; l < scene.lamps.size(); ++l) {
      lamp_on[l] = scene.lamps[l].OnAt(time_s);
      any_lamp = any_lamp || lamp_on[l];
    }
    const bool background = options.background_light;
    const bool lamps = background && any_lamp;
    // Background radiance of each object apart from the lamps' light: ambient, glowing bulbs.
    std::vector<float> object_radiance(scene.objects.size(), 0.f);
    if (background) {
      const float ambient = static_cast<float>(scene.ambient_irradiance_w_m2);
      for (std::size_t g = 0; g < object_radiance.size(); ++g) {
        object_radiance[g] = shade[g].diffuse * ambient;
        // A lamp's bulb glows while its lamp is on; any other glowing material always.
        const int bulb = static_cast<int>(g) - scene.lamp_bulb_begin;
        const bool is_bulb = bulb >= 0 && bulb < static_cast<int>(lamp_on.size());
        if (!is_bulb || lamp_on[bulb]) object_radiance[g] += shade[g].emission;
      }
    }
    const float inv_range = static_cast<float>(1.0 / range_m);
    const float contrast = static_cast<float>(model.demodulation_contrast);
    const bool bounces = options.multipath && options.max_bounces > 0;
    const int s2 = ss * ss;
    const std::size_t np = static_cast<std::size_t>(width) * height;
    if (out.re.size() != np) out.Resize(np);
    // Odd S: the centre subsample is the pixel's central ray (same direction bit for bit).
    const bool truth_from_center = truth && ss % 2 == 1;
    const int center_sub = (ss / 2) * ss + ss / 2;
    const std::size_t ns = static_cast<std::size_t>(width) * s2;  // subsample rays of a row
    // The planar shortcut casts every central ray first (they are the truth rays too).
    const std::size_t nr = ns + (truth && !truth_from_center && !shortcut ? width : 0);
    if (shortcut) CastCentersForShortcut(rot, org, pose, truth);
    const auto n_obj = static_cast<unsigned>(scene.objects.size());
    object_radiance.push_back(0.f);  // rays that hit nothing
    MirrorContext mirror;
    mirror.scene = &scene;
    mirror.geometry = geometry.get();
    mirror.materials = &mats;
    mirror.sub_active = sub_active.data();
    mirror.sub_bg = sub_bg.data();
    mirror.range_m = range_m;
    mirror.contrast = model.demodulation_contrast;
    mirror.background_light = options.background_light;
    mirror.max_bounces = options.max_bounces;
    pool->Run(height, [&](int r0, int r1, int thread) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      Scratch& sc = scratch[thread];
      RayBatch& b = sc.rays;
      b.Resize(nr);
      for (auto* v : {&sc.cos_i, &sc.weight, &sc.dist, &sc.bg, &sc.re, &sc.im}) v->resize(ns);
      sc.glossy_at.resize(ns);
      for (int r = r0; r < r1; ++r) {
        const std::size_t row_sub = static_cast<std::size_t>(r) * width * s2;
        const std::size_t row_px = static_cast<std::size_t>(r) * width;
        Rotate(rot, &sub_x[row_sub], &sub_y[row_sub], &sub_z[row_sub], ns, b, 0);
        if (nr > ns) {
          Rotate(rot, &center_x[row_px], &center_y[row_px], &center_z[row_px], width, b, ns);
        }
        // Primary rays of the row (and the truth rays) in coherent packets.
        if (shortcut) {
          const std::size_t m = shortcut->Fill(r, b, sc.rest_at, sc.ok);
          RayBatch& rest = sc.rest;
          rest.Resize(m);
          for (std::size_t j = 0; j < m; ++j) {
            const std::size_t i = sc.rest_at[j];
            rest.dx[j] = b.dx[i];
            rest.dy[j] = b.dy[i];
            rest.dz[j] = b.dz[i];
          }
          geometry->Trace(&ctx, org, m, rest);
          for (std::size_t j = 0; j < m; ++j) {
            const std::size_t i = sc.rest_at[j];
            b.t[i] = rest.t[j];
            b.geom[i] = rest.geom[j];
            b.prim[i] = rest.prim[j];
            b.nx[i] = rest.nx[j];
            b.ny[i] = rest.ny[j];
            b.nz[i] = rest.nz[j];
          }
        } else {
          geometry->Trace(&ctx, org, nr, b);
        }
        if (truth && !shortcut) {
          for (int c = 0; c < width; ++c) {
            truth_distance[row_px + c] =
                truth_from_center ? b.t[rays.Index(center_sub, c)] : b.t[ns + c];
          }
        }
        // Per subsample: cosine of incidence, BRDF, background (vectorised, no branches).
        CosIncidence(ns, b.nx.data(), b.ny.data(), b.nz.data(), b.dx.data(), b.dy.data(),
                     b.dz.data(), sc.cos_i.data());
        const std::size_t n_glossy = ShadeSurfaces(
            ns, n_obj, b.geom.data(), b.t.data(), sc.cos_i.data(), &sub_bg[row_sub],
            mats.mat_diffuse.data(), mats.mat_glossy.data(), object_radiance.data(), sc.re.data(),
            sc.im.data(), sc.dist.data(), sc.bg.data(), sc.glossy_at.data());
        AddGlossyLobes(mats, n_glossy, b.geom.data(), sc.glossy_at.data(), sc.im.data(),
                       sc.re.data(), sc.glossy);
        Weights(ns, &sub_active[row_sub], sc.re.data(), sc.im.data(), sc.weight.data());
        if (lamps) {
          for (std::size_t i = 0; i < ns; ++i) {
            const unsigned g = b.geom[i];
            if (g == RTC_INVALID_GEOMETRY_ID) continue;
            const Eigen::Vector3f n = Eigen::Vector3f(b.nx[i], b.ny[i], b.nz[i]).normalized();
            const Eigen::Vector3f hit = org + b.t[i] * Eigen::Vector3f(b.dx[i], b.dy[i], b.dz[i]);
            sc.bg[i] += sub_bg[row_sub + i] * shade[g].diffuse *
                        LampIrradiance(scene, hit, n, static_cast<int>(g), lamp_on);
          }
        }
        sc.mirrored.clear();
        if (bounces && mats.any_mirror) {
          for (std::size_t i = 0; i < ns; ++i) {
            const unsigned g = b.geom[i];
            if (g != RTC_INVALID_GEOMETRY_ID && shade[g].mirror > 0) {
              sc.mirrored.push_back(static_cast<int>(i));
            }
          }
        }
        // Phasors: amplitude falls with d^2, phase 2 pi d / L (vectorised, no libm).
        Phasors(ns, inv_range, contrast, sc.dist.data(), sc.weight.data(), sc.re.data(),
                sc.im.data());
        SumSubsamples(group, width, s2, sc.re.data(), sc.im.data(), sc.weight.data(), sc.bg.data(),
                      b.t.data(), &out.re[row_px], &out.im[row_px], &out.dc[row_px],
                      &out.span_m[row_px], &out.near_m[row_px], &out.far_m[row_px]);
        std::copy_n(&out.re[row_px], width, &out.direct_re[row_px]);
        std::copy_n(&out.im[row_px], width, &out.direct_im[row_px]);
        for (int i : sc.mirrored) {
          const std::size_t block = static_cast<std::size_t>(i) / (group * s2);
          const std::size_t p = row_px + block * group + static_cast<std::size_t>(i) % group;
          Bounce(mirror, b, static_cast<std::size_t>(i), row_sub + i, org, ctx, lamp_on, out.re[p],
                 out.im[p], out.dc[p]);
        }
      }
    });
    if (options.interreflection) {
      InterreflectionContext ic;
      ic.geometry = geometry.get();
      ic.rays = &rays;
      ic.radiometry = &rad;
      ic.materials = &mats;
      ic.pool = pool.get();
      ic.samples = options.interreflection_samples;
      ic.range_m = range_m;
      ic.contrast = model.demodulation_contrast;
      Interreflect(ic, pose, ir, out);
    }
    if (options.scattering) Scatter(out);
  }

  // The planar shortcut's first pass: every pixel's central ray (and so the truth distances),
  // then the map of quads whose subsamples take the closed form.
  void CastCentersForShortcut(const Eigen::Matrix3f& rot, const Eigen::Vector3f& org,
                              const Eigen::Isometry3d& pose, bool truth) {
    RayBatch& centers = shortcut->Centers();
    pool->Run(height, [&](int r0, int r1, int) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      for (int r = r0; r < r1; ++r) {
        const std::size_t row_px = static_cast<std::size_t>(r) * width;
        Rotate(rot, &rays.center_x[row_px], &rays.center_y[row_px], &rays.center_z[row_px], width,
               centers, row_px);
        geometry->Trace(&ctx, org, width, centers, row_px);
        shortcut->FinishRow(r);
        if (truth) std::copy_n(&centers.t[row_px], width, &truth_distance[row_px]);
      }
    });
    pool->Run(height, [&](int r0, int r1, int) { shortcut->MarkQuads(r0, r1); });
    shortcut->ClearZones(scene, *geometry, pose);
  }

  // Ground truth alone (when the taps were rendered at other times).
  void TruthAt(double time_s, double pan_rad) {
    const Eigen::Isometry3d pose = CameraPose(scene, time_s, pan_rad);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();
    const Eigen::Vector3f org = pose.translation().cast<float>();
    pool->Run(height, [&](int r0, int r1, int thread) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      RayBatch& b = scratch[thread].rays;
      b.Resize(static_cast<std::size_t>(width));
      for (int r = r0; r < r1; ++r) {
        const std::size_t row_px = static_cast<std::size_t>(r) * width;
        Rotate(rot, &rays.center_x[row_px], &rays.center_y[row_px], &rays.center_z[row_px], width,
               b, 0);
        geometry->Trace(&ctx, org, width, b);
        std::copy(b.t.begin(), b.t.begin() + width, truth_distance.begin() + row_px);
      }
    });
  }
  // Stage 3: the scattered light of a rendering. The three channels (re, im, DC) are
  // independent: one per task on the row pool.
  void Scatter(Render& out) {
    if (scatter.weight.empty()) {
      std::fill(out.scat_re.begin(), out.scat_re.end(), 0.f);
      std::fill(out.scat_im.begin(), out.scat_im.end(), 0.f);
      std::fill(out.scat_dc.begin(), out.scat_dc.end(), 0.f);
      return;
    }
    const std::vector<float>* src[3] = {&out.re, &out.im, &out.dc};
    std::vector<float>* dst[3] = {&out.scat_re, &out.scat_im, &out.scat_dc};
    pool->Run(
        3,
        [&](int ch0, int ch1, int thread) {
          for (int ch = ch0; ch < ch1; ++ch) {
            ScatterChannel(scatter, width, height, *src[ch], *dst[ch],
                           scratch[static_cast<std::size_t>(thread)].scatter_tmp);
          }
        },
        1);
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
  return internal::WarmupOffsetM(impl_->model, impl_->options.power_on_time_s, time_s);
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
  return PanAngleAtRad(impl_->scene.pan_schedule, next_start_s_);
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
    split = MovesDuringExposure(im.MakeKey(start, pan), im.MakeKey(start + t_int_s, pan),
                                opt.motion_threshold_m);
  }
  const int slots = split ? 4 : 1;
  im.renders.resize(4);
  im.keys.resize(4);
  const RenderKey truth_key = im.MakeKey(mid, pan);
  for (int s = 0; s < slots; ++s) {
    const double t = TapTimeS(start, t_int_s, split, s);
    const RenderKey key = im.MakeKey(t, pan);
    if (!(key == im.keys[s])) {
      // One rendering at mid-exposure also casts the ground-truth rays (same time and pose).
      const bool with_truth = !split && !(truth_key == im.truth_key);
      im.RenderAt(t, pan, im.renders[s], with_truth);
      im.keys[s] = key;
      if (with_truth) im.truth_key = truth_key;
    }
  }
  if (!(truth_key == im.truth_key)) {
    im.geometry->PlaceObjects(mid);
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
  truth.footprint_near_m = Image<float>(w, h);
  truth.footprint_far_m = Image<float>(w, h);

  const double range = im.range_m;
  const double two_pi = 2 * kPi;
  const double dark =
      opt.dark_current ? model.dark_current_e_per_s * model.tap_duty * t_int_s : 0.0;
  double global_offset_m = 0;
  if (opt.warmup_drift) global_offset_m += WarmupOffsetM(mid);
  if (opt.exposure_offset) global_offset_m += ExposureOffsetM(model, t_int_us);
  const double read_sigma = opt.read_noise ? model.read_noise_e : 0.0;
  const double full_well = model.full_well_e;
  const double bias_rad = opt.truth_bias_m * two_pi / range;
  const std::uint64_t frame_seed = FrameSeed(opt.seed, sequence_);

  // Row loops run on the camera's persistent workers (the demodulation loop below too).
  const auto ParallelRows = [&im](int rows, int /*threads*/, const auto& body,
                                  int granularity = 1) {
    im.pool->Run(rows, body, 2, granularity);
  };
  // Taps: noiseless means, then shot and read noise per tap.
  const double cos_bias = std::cos(std::min(bias_rad, kPi));
  // True when the angle between phasors (ar, ai) and (br, bi) exceeds the truth bias, i.e.
  // dot < cos_bias |a| |b|; squared (no square root) where both sides are known to be >= 0.
  auto differ = [cos_bias](double ar, double ai, double br, double bi) {
    const double dot = ar * br + ai * bi;
    const double norms2 = (ar * ar + ai * ai) * (br * br + bi * bi);
    if (cos_bias >= 0) return dot < 0 || dot * dot < cos_bias * cos_bias * norms2;
    return dot < cos_bias * std::sqrt(norms2);
  };
  SensorConstants sk;
  sk.t_int_s = t_int_s;
  sk.dark_e = dark;
  sk.global_offset_m = global_offset_m;
  sk.wiggle_m = opt.wiggling ? model.wiggle_amplitude_m : 0.0;
  sk.wiggle_cos = std::cos(model.wiggle_phase_rad);
  sk.wiggle_sin = std::sin(model.wiggle_phase_rad);
  sk.m_to_rad = two_pi / range;
  const double read_var = read_sigma * read_sigma;
  const double sigma_scale = range / (2 * std::sqrt(2.0) * kPi);
  ParallelRows(
      h, opt.threads,
      [&](int r0, int r1, int thread) {
        SensorRow& sr = im.scratch[thread].sensor;
        sr.Resize(w);
        for (int r = r0; r < r1; ++r) {
          const std::size_t row = static_cast<std::size_t>(r) * w;
          const float* fpn = &im.fpn_m[row];  // zeros when the fixed pattern is off
          // Noiseless means of the four taps (each from its own rendering when the scene moves).
          for (int slot = 0; slot < slots; ++slot) {
            const Render& rd = im.renders[slot];
            PixelMeans(sk, w, &rd.re[row], &rd.im[row], &rd.dc[row], &rd.scat_re[row],
                       &rd.scat_im[row], &rd.scat_dc[row], fpn, sr.a[slot].data(),
                       sr.b[slot].data(), sr.cos_p[slot].data(), sr.sin_p[slot].data(),
                       sr.shift.data());
          }
          TapMeans(w, slots, sr);
          const std::size_t at = sr.RowOffset();
          NoiseScales(w, read_var, sigma_scale, sr.mu[0].data() + at, sr.mu[1].data() + at,
                      sr.mu[2].data() + at, sr.mu[3].data() + at, sr.a_mean.data(),
                      sr.b_mean.data(), sr.sd[0].data() + at, sr.sd[1].data() + at,
                      sr.sd[2].data() + at, sr.sd[3].data() + at, sr.sigma.data(), sr.noise.data());
          // Shot and read noise, one random stream per row. Draws in the order of Rng::Poisson then
          // the read noise, per tap: drawing shot plus read noise as one N(mu, mu + s^2) would be
          // the same distribution with half the draws, but a different realisation, and statistics
          // evaluated on single frames (experiments fig. 6-7) depend on the realisation. The rows
          // wait in blocks of eight (the AVX-512 form draws eight streams at once); nothing below
          // reads the taps.
          sr.block_seed[sr.block_rows] = RowSeed(frame_seed, r);
          sr.block_row[sr.block_rows] = r;
          ++sr.block_rows;
          if (sr.block_rows == SensorRow::kNoiseBlockRows || r + 1 == r1) {
            const double* const mu[4] = {sr.mu[0].data(), sr.mu[1].data(), sr.mu[2].data(),
                                         sr.mu[3].data()};
            const float* const sd[4] = {sr.sd[0].data(), sr.sd[1].data(), sr.sd[2].data(),
                                        sr.sd[3].data()};
            float* tap_rows[SensorRow::kNoiseBlockRows][4];
            for (int j = 0; j < sr.block_rows; ++j) {
              const std::size_t row_at = static_cast<std::size_t>(sr.block_row[j]) * w;
              for (int k = 0; k < 4; ++k) tap_rows[j][k] = &im.taps[k][row_at];
            }
            NoisyTapsRows(sr.block_rows, w, static_cast<std::size_t>(w), sr.block_seed,
                          opt.shot_noise, read_sigma, mu, sd, tap_rows);
            sr.block_rows = 0;
          }
          // Ground truth.
          const Render& rd = im.renders[0];
          if (cos_bias >= 0) {
            TruthCauses(w, cos_bias * cos_bias, t_int_s, opt.truth_mixed_span_m, range, &rd.re[row],
                        &rd.im[row], &rd.direct_re[row], &rd.direct_im[row], &rd.scat_re[row],
                        &rd.scat_im[row], &rd.span_m[row], &im.truth_distance[row],
                        sr.causes.data());
          }
          for (int c = 0; c < w; ++c) {
            const std::size_t p = row + c;
            PixelFlags causes(sr.causes[c]);
            const float td = im.truth_distance[p];
            if (cos_bias < 0) {
              // Truth causes from the noiseless components.
              const double ind_re = rd.re[p] - rd.direct_re[p], ind_im = rd.im[p] - rd.direct_im[p];
              const double ind2 = ind_re * ind_re + ind_im * ind_im;
              const double dir2 = static_cast<double>(rd.direct_re[p]) * rd.direct_re[p] +
                                  static_cast<double>(rd.direct_im[p]) * rd.direct_im[p];
              // Multipath: the indirect paths shift the phase noticeably, or outweigh the direct
              // one.
              if (ind2 > 0 &&
                  (ind2 >= dir2 || differ(rd.re[p], rd.im[p], rd.direct_re[p], rd.direct_im[p]))) {
                causes.Set(Flag::kMultipath);
              }
              if (rd.scat_re[p] != 0 || rd.scat_im[p] != 0) {
                const double re = (rd.re[p] + rd.scat_re[p]) * t_int_s;
                const double imag = (rd.im[p] + rd.scat_im[p]) * t_int_s;
                if (differ(re, imag, rd.re[p], rd.im[p])) causes.Set(Flag::kScattering);
              }
              if (rd.span_m[p] > opt.truth_mixed_span_m) causes.Set(Flag::kMixed);
              if (!(td < kInf)) causes.Set(Flag::kNoReturn);
              if (td >= range && td < kInf) causes.Set(Flag::kBeyondUnambiguous);
            }
            float near = rd.near_m[p], far = rd.far_m[p];
            bool moved = false;
            for (int k = 1; k < slots; ++k) {
              const Render& rk = im.renders[k];
              moved = moved || differ(rk.re[p], rk.im[p], rd.re[p], rd.im[p]);
              near = std::min(near, rk.near_m[p]);
              far = std::max(far, rk.far_m[p]);
            }
            if (moved) causes.Set(Flag::kMotion);
            truth.footprint_near_m[p] = near;
            truth.footprint_far_m[p] = far > 0 ? far : kInf;
            truth.radial_distance_m[p] = td;
            truth.sigma_m[p] = sr.sigma[c];
            im.truth_noise_e2[p] = sr.noise[c];
            truth.causes[p] = causes;
          }
        }
      },
      SensorRow::kNoiseBlockRows);  // chunks of whole noise blocks (NoisyTapsRows)
  const bool bloomed =
      opt.saturation &&
      Saturate(im.taps, im.bloom_mean, im.tmp2, w, h, model.blooming_sigma_px, full_well,
               model.overflow_fraction, opt.blooming ? model.blooming_fraction : 0.0, frame_seed,
               opt.shot_noise, im.pool.get());
  // Clip, demodulate and quantise.
  const double gain = model.gain_reg_per_e;
  ParallelRows(h, opt.threads, [&](int r0, int r1, int thread) {
    std::vector<std::uint8_t>& saturated = im.scratch[thread].saturated;
    saturated.resize(static_cast<std::size_t>(w));
    for (int r = r0; r < r1; ++r) {
      const std::size_t row = static_cast<std::size_t>(r) * w;
      const float* const taps[4] = {&im.taps[0][row], &im.taps[1][row], &im.taps[2][row],
                                    &im.taps[3][row]};
      DemodulateRow(w, taps, opt.saturation, full_well, gain, offset_register_,
                    frame.distance.Row(r).data(), frame.amplitude.Row(r).data(),
                    frame.intensity.Row(r).data(), saturated.data());
      if (bloomed) {
        // The spilled charge is offset without amplitude: it raises the true shot-noise sigma by
        // sqrt((B + spill) / B) (B including the read-noise variance).
        for (int c = 0; c < w; ++c) {
          const std::size_t p = row + static_cast<std::size_t>(c);
          if (im.bloom_mean[p] > 0 && im.truth_noise_e2[p] > 0) {
            truth.sigma_m[p] *=
                std::sqrt((im.truth_noise_e2[p] + im.bloom_mean[p]) / im.truth_noise_e2[p]);
          }
        }
      }
      for (int c = 0; c < w; ++c) {
        if (saturated[static_cast<std::size_t>(c)] != 0)
          truth.causes[row + c].Set(Flag::kSaturated);
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

  const double period = FramePeriodS(model, t_int_s);
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
