#include "radiometry.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "fast_math.h"
#include "hot_loop.h"
#include "tofcam/core/units.h"

namespace tofcam::sim::internal {

namespace {

constexpr double kPlanckJs = 6.62607015e-34;

// Per pixel of a row: the sums of its S^2 subsamples (phasor, DC = active + background), in
// subsample order, the span of the subsample distances (inf when some but not all miss, 0
// when all miss) and the nearest and farthest hit (inf and 0 when all miss). Blocks of G pixels as
// in PixelRays::Index(); G is a compile-time constant so the inner loops become vector operations.
template <int G>
void SumBlocks(int width, int s2, const float* __restrict re, const float* __restrict im,
               const float* __restrict active, const float* __restrict bg,
               const float* __restrict t, float* __restrict out_re, float* __restrict out_im,
               float* __restrict out_dc, float* __restrict span, float* __restrict near,
               float* __restrict far) {
  for (int c0 = 0; c0 < width; c0 += G) {
    const std::size_t base = static_cast<std::size_t>(c0) * s2;
    float sr[G], si[G], sd[G], dmin[G], dmax[G], tmax[G];
    for (int g = 0; g < G; ++g) {
      const std::size_t i = base + g;
      sr[g] = re[i];
      si[g] = im[i];
      sd[g] = active[i] + bg[i];
      dmin[g] = t[i];                      // over the hits: a miss (inf) never lowers it
      dmax[g] = t[i] < kInf ? t[i] : 0.f;  // over the hits
      tmax[g] = t[i];                      // inf when some subsample missed
    }
    for (int s = 1; s < s2; ++s) {
      for (int g = 0; g < G; ++g) {
        const std::size_t i = base + static_cast<std::size_t>(s) * G + g;
        sr[g] += re[i];
        si[g] += im[i];
        sd[g] += active[i] + bg[i];
        const float ts = t[i];
        dmin[g] = std::min(dmin[g], ts);
        dmax[g] = std::max(dmax[g], ts < kInf ? ts : 0.f);
        tmax[g] = std::max(tmax[g], ts);
      }
    }
    for (int g = 0; g < G; ++g) {
      out_re[c0 + g] = sr[g];
      out_im[c0 + g] = si[g];
      out_dc[c0 + g] = sd[g];
      // Selected with bit masks: GCC keeps a ternary over a subtraction scalar.
      const std::uint32_t hit_all = 0u - static_cast<std::uint32_t>(tmax[g] < kInf);
      const float missed = dmax[g] > 0 ? kInf : 0.f;
      span[c0 + g] =
          std::bit_cast<float>((std::bit_cast<std::uint32_t>(dmax[g] - dmin[g]) & hit_all) |
                               (std::bit_cast<std::uint32_t>(missed) & ~hit_all));
      near[c0 + g] = dmin[g];
      far[c0 + g] = dmax[g];
    }
  }
}

// SumBlocks<4> (the S = 2 case with 16-ray packets) written with GCC/Clang vector extensions:
// GCC's auto-vectoriser keeps the generic version scalar here.
void SumBlocks4(int width, int s2, const float* __restrict re, const float* __restrict im,
                const float* __restrict active, const float* __restrict bg,
                const float* __restrict t, float* __restrict out_re, float* __restrict out_im,
                float* __restrict out_dc, float* __restrict span, float* __restrict near,
                float* __restrict far) {
  using V = float __attribute__((vector_size(16)));
  const auto load = [](const float* p) {
    V v;
    std::memcpy(&v, p, sizeof v);
    return v;
  };
  const auto store = [](float* p, V v) { std::memcpy(p, &v, sizeof v); };
  const V inf = {kInf, kInf, kInf, kInf}, zero = {0, 0, 0, 0};
  for (int c0 = 0; c0 < width; c0 += 4) {
    std::size_t i = static_cast<std::size_t>(c0) * s2;
    V sr = load(re + i), si = load(im + i), sd = load(active + i) + load(bg + i);
    V ts = load(t + i);
    V dmin = ts, dmax = ts < inf ? ts : zero, tmax = ts;
    for (int s = 1; s < s2; ++s) {
      i += 4;
      sr += load(re + i);
      si += load(im + i);
      sd += load(active + i) + load(bg + i);
      ts = load(t + i);
      dmin = ts < dmin ? ts : dmin;
      const V hit = ts < inf ? ts : zero;
      dmax = dmax < hit ? hit : dmax;
      tmax = tmax < ts ? ts : tmax;
    }
    store(out_re + c0, sr);
    store(out_im + c0, si);
    store(out_dc + c0, sd);
    const V missed = dmax > zero ? inf : zero;
    store(span + c0, tmax < inf ? dmax - dmin : missed);
    store(near + c0, dmin);
    store(far + c0, dmax);
  }
}

}  // namespace

// The loops below take __restrict pointers and are kept out of line (see hot_loop.h).

// Cosine of incidence |n . d| / |n| (at most 1) for n rays; garbage where the ray missed.
TOFCAM_SIM_LOOP void CosIncidence(std::size_t n, const float* __restrict nx,
                                  const float* __restrict ny, const float* __restrict nz,
                                  const float* __restrict dx, const float* __restrict dy,
                                  const float* __restrict dz, float* __restrict cos_i) {
  for (std::size_t i = 0; i < n; ++i) {
    const float len = std::sqrt(nx[i] * nx[i] + ny[i] * ny[i] + nz[i] * nz[i]);
    cos_i[i] = std::min(1.f, std::abs(nx[i] * dx[i] + ny[i] * dy[i] + nz[i] * dz[i]) / len);
  }
}

// Per subsample: active electrons/s = weight / d^2 (written back into weight) and the modulated
// phasor contrast * active * exp(i 2 pi d / L).
TOFCAM_SIM_LOOP void Phasors(std::size_t n, float inv_range, float contrast,
                             const float* __restrict dist, float* __restrict weight,
                             float* __restrict re, float* __restrict im) {
  for (std::size_t i = 0; i < n; ++i) {
    const float d = dist[i];
    const float active = weight[i] / (d * d);
    float sn, cs;
    internal::SinCos2Pi(d * inv_range, sn, cs);
    weight[i] = active;
    re[i] = contrast * active * cs;
    im[i] = contrast * active * sn;
  }
}

// cos^n for the glossy subsamples of a row, n[k] >= 0 whole numbers below 2^bits: binary
// exponentiation in double precision (the float nearest cos^n, see internal::PowInt) with the
// same `bits` squarings for every lane and a bit-mask select of the factor, so it vectorises.
TOFCAM_SIM_LOOP void PowIntRow(std::size_t m, int bits, const float* __restrict x,
                               const int* __restrict n, double* __restrict base,
                               double* __restrict result) {
  for (std::size_t k = 0; k < m; ++k) {
    base[k] = x[k];
    result[k] = 1.0;
  }
  for (int bit = 0; bit < bits; ++bit) {
    for (std::size_t k = 0; k < m; ++k) {
      const std::uint64_t take = 0 - static_cast<std::uint64_t>((n[k] >> bit) & 1);
      const std::uint64_t factor = (std::bit_cast<std::uint64_t>(base[k]) & take) |
                                   (std::bit_cast<std::uint64_t>(1.0) & ~take);
      result[k] *= std::bit_cast<double>(factor);
      base[k] *= base[k];
    }
  }
}

// Per subsample of a row (g = object hit or RTC_INVALID_GEOMETRY_ID): the active electrons/s
// before the 1/d^2 falloff, weight = I(alpha) K cos^4 / S^2 * brdf * cos(incidence) with
// brdf = albedo / pi + glossy cos^n; the distance (1 on a miss, where the weight is 0); the
// background electrons/s. Misses read the zero entry n_obj of the material arrays. The gathers
// are scalar but branch-free; the rest vectorises. The subsamples on glossy materials are listed
// in `glossy_at` (n_glossy of them) and their cosines in `glossy_x`; the caller adds the lobe.
TOFCAM_SIM_LOOP std::size_t ShadeSurfaces(
    std::size_t n, unsigned n_obj, const unsigned* __restrict geom, const float* __restrict t,
    const float* __restrict cos_in, const float* __restrict bg_k, const float* __restrict diffuse,
    const float* __restrict glossy, const float* __restrict radiance, float* __restrict brdf,
    float* __restrict cos_out, float* __restrict dist, float* __restrict bg,
    unsigned* __restrict glossy_at) {
  std::size_t n_glossy = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool hit = geom[i] != RTC_INVALID_GEOMETRY_ID;
    const unsigned g = hit ? geom[i] : n_obj;
    cos_out[i] = hit ? cos_in[i] : 0.f;  // the normal of a miss is garbage
    brdf[i] = diffuse[g];
    dist[i] = hit ? t[i] : 1.f;
    bg[i] = bg_k[i] * radiance[g];
    glossy_at[n_glossy] = static_cast<unsigned>(i);
    n_glossy += glossy[g] > 0 ? 1 : 0;
  }
  return n_glossy;
}

// weight = active * brdf * cos.
TOFCAM_SIM_LOOP void Weights(std::size_t n, const float* __restrict active,
                             const float* __restrict brdf, const float* __restrict cos_i,
                             float* __restrict weight) {
  for (std::size_t i = 0; i < n; ++i) weight[i] = active[i] * brdf[i] * cos_i[i];
}

TOFCAM_SIM_LOOP void SumSubsamples(int group, int width, int s2, const float* __restrict re,
                                   const float* __restrict im, const float* __restrict active,
                                   const float* __restrict bg, const float* __restrict t,
                                   float* __restrict out_re, float* __restrict out_im,
                                   float* __restrict out_dc, float* __restrict span,
                                   float* __restrict near, float* __restrict far) {
  switch (group) {
    case 16:
      SumBlocks<16>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span, near, far);
      break;
    case 8:
      SumBlocks<8>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span, near, far);
      break;
    case 4:
      SumBlocks4(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span, near, far);
      break;
    case 2:
      SumBlocks<2>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span, near, far);
      break;
    default:
      SumBlocks<1>(width, s2, re, im, active, bg, t, out_re, out_im, out_dc, span, near, far);
  }
}

double RadiometricConstant(const CameraModel& model) {
  const double pixel_area = model.pixel_pitch_x_um * model.pixel_pitch_y_um * 1e-12;
  const double photons_per_j = model.wavelength_nm * 1e-9 / (kPlanckJs * kSpeedOfLightMPerS);
  return kPi / (4 * model.f_number * model.f_number) * pixel_area * model.fill_factor *
         model.quantum_efficiency * photons_per_j * model.tap_duty;
}

double LedExponent(const CameraModel& model) {
  return -std::log(2.0) / std::log(std::cos(model.led_half_angle_deg * kPi / 180));
}

double LedOnAxisWPerSr(const CameraModel& model) {
  return model.led_power_w * (LedExponent(model) + 1) / (2 * kPi);
}

void BuildPixelRays(const CameraModel& model, int ss, PixelRays& rays, SubsampleRadiometry& rad) {
  const int width = model.intrinsics.width, height = model.intrinsics.height;
  rays.width = width;
  rays.height = height;
  rays.ss = ss;
  // Radiometric constant K: e-/s per tap per (W m^-2 sr^-1) of scene radiance (camera equation).
  const double k = RadiometricConstant(model);
  const double m_exp = LedExponent(model);
  const double led_on_axis = LedOnAxisWPerSr(model);  // W/sr
  const int s2 = ss * ss;
  const std::size_t np = static_cast<std::size_t>(width) * height;
  for (auto* v : {&rays.sub_x, &rays.sub_y, &rays.sub_z, &rad.sub_active, &rad.sub_bg}) {
    v->resize(np * s2);
  }
  for (auto* v : {&rays.center_x, &rays.center_y, &rays.center_z}) v->resize(np);
  rad.pixel_bg.assign(np, 0.f);
  rad.led_on_axis_w_sr = static_cast<float>(led_on_axis);
  rad.led_exponent = static_cast<float>(m_exp);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      const std::size_t p = static_cast<std::size_t>(r) * width + c;
      const Eigen::Vector3d center = model.intrinsics.Unproject({c, r});
      if (!center.allFinite()) NoRay(c, r);  // Embree must never see a NaN ray
      const Eigen::Vector3f cd = center.cast<float>();
      rays.center_x[p] = cd.x();
      rays.center_y[p] = cd.y();
      rays.center_z[p] = cd.z();
      for (int i = 0; i < ss; ++i) {
        for (int j = 0; j < ss; ++j) {
          const Eigen::Vector2d px(c + (j + 0.5) / ss - 0.5, r + (i + 0.5) / ss - 0.5);
          const Eigen::Vector3d d = model.intrinsics.Unproject(px);
          if (!d.allFinite()) NoRay(px.x(), px.y());
          const double cos_a = d.z();
          const double c4 = cos_a * cos_a * cos_a * cos_a;
          const std::size_t s =
              static_cast<std::size_t>(r) * width * s2 + rays.Index(i * ss + j, c);
          rays.sub_x[s] = static_cast<float>(d.x());
          rays.sub_y[s] = static_cast<float>(d.y());
          rays.sub_z[s] = static_cast<float>(d.z());
          rad.sub_bg[s] = static_cast<float>(k * c4 / s2);
          rad.pixel_bg[p] += rad.sub_bg[s];
          rad.sub_active[s] =
              static_cast<float>(k * c4 * led_on_axis * std::pow(cos_a, m_exp) / s2);
        }
      }
    }
  }
}

MaterialTable BuildMaterials(const Scene& scene, bool glossy) {
  MaterialTable t;
  std::vector<ShadeMaterial>& shade = t.shade;
  shade.resize(scene.objects.size());
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    const Material& m = scene.materials.at(static_cast<std::size_t>(scene.objects[i].material));
    ShadeMaterial& sm = shade[i];
    sm.diffuse = static_cast<float>(m.albedo / kPi);
    // Normalised Blinn-Phong lobe; emitter and camera coincide, so the half vector is the
    // viewing direction and the lobe is cos^n of the incidence angle.
    sm.glossy = glossy ? static_cast<float>(m.specular * (m.shininess + 8) / (8 * kPi)) : 0.f;
    sm.shininess = static_cast<float>(m.shininess);
    if (m.shininess >= 0 && m.shininess <= 1024 && m.shininess == std::floor(m.shininess)) {
      sm.int_shininess = static_cast<int>(m.shininess);
    }
    sm.mirror = static_cast<float>(m.mirror);
    sm.emission = static_cast<float>(m.emission_w_m2_sr);
  }
  const std::size_t n_obj = scene.objects.size();
  t.mat_diffuse.assign(n_obj + 1, 0.f);
  t.mat_glossy.assign(n_obj + 1, 0.f);
  t.mat_shine.assign(n_obj + 1, 0.f);
  t.mat_mirror.assign(n_obj + 1, 0.f);
  t.mat_power.assign(n_obj + 1, -1);
  for (std::size_t i = 0; i < n_obj; ++i) {
    const ShadeMaterial& sm = shade[i];
    t.mat_diffuse[i] = sm.diffuse;
    t.mat_glossy[i] = sm.glossy;
    t.mat_shine[i] = sm.shininess;
    t.mat_power[i] = sm.int_shininess;
    if (sm.glossy > 0) {
      while ((std::max(0, t.mat_power[i]) >> t.power_bits) != 0) ++t.power_bits;
    }
    t.mat_mirror[i] = sm.mirror;
    t.any_mirror = t.any_mirror || sm.mirror > 0;
  }
  return t;
}

void AddGlossyLobes(const MaterialTable& mats, std::size_t n_glossy, const unsigned* geom,
                    const unsigned* glossy_at, const float* cos_i_row, float* brdf,
                    GlossyScratch& sc) {
  if (n_glossy == 0) return;
  sc.x.resize(n_glossy);
  sc.n.resize(n_glossy);
  sc.base.resize(n_glossy);
  sc.result.resize(n_glossy);
  for (std::size_t k = 0; k < n_glossy; ++k) {
    const std::size_t i = glossy_at[k];
    sc.x[k] = cos_i_row[i];
    sc.n[k] = std::max(0, mats.mat_power[geom[i]]);
  }
  PowIntRow(n_glossy, mats.power_bits, sc.x.data(), sc.n.data(), sc.base.data(), sc.result.data());
  for (std::size_t k = 0; k < n_glossy; ++k) {
    const std::size_t i = glossy_at[k];
    const unsigned g = geom[i];
    const float cos_i = sc.x[k];
    if (!(cos_i > 0)) continue;  // grazing: the weight is 0 anyway (times cos)
    const float lobe = mats.mat_power[g] >= 0 ? static_cast<float>(sc.result[k])
                                              : std::exp2(mats.mat_shine[g] * std::log2(cos_i));
    brdf[i] += mats.mat_glossy[g] * lobe;
  }
}

float LampIrradiance(const Scene& scene, const Eigen::Vector3f& hit, const Eigen::Vector3f& n,
                     int obj, const std::vector<char>& lamp_on) {
  float irradiance = 0;
  const int bulb = obj - scene.lamp_bulb_begin;
  for (std::size_t l = 0; l < scene.lamps.size(); ++l) {
    if (!lamp_on[l] || static_cast<int>(l) == bulb) continue;
    const Eigen::Vector3f to = scene.lamps[l].position_m.cast<float>() - hit;
    const float d2 = std::max(to.squaredNorm(), 1e-6f);
    irradiance += static_cast<float>(scene.lamps[l].ir_power_w / (4 * kPi)) * std::abs(n.dot(to)) /
                  (d2 * std::sqrt(d2));
  }
  return irradiance;
}

void Bounce(const MirrorContext& mc, const RayBatch& b, std::size_t i, std::size_t si,
            const Eigen::Vector3f& org, RTCIntersectContext& ctx, const std::vector<char>& lamp_on,
            float& re, float& im, float& dc) {
  const Scene& scene = *mc.scene;
  const std::vector<ShadeMaterial>& shade = mc.materials->shade;
  const float two_pi_over_l = static_cast<float>(2 * kPi / mc.range_m);
  const float contrast = static_cast<float>(mc.contrast);
  const float ambient =
      mc.background_light ? static_cast<float>(scene.ambient_irradiance_w_m2) : 0.f;
  Eigen::Vector3f dir(b.dx[i], b.dy[i], b.dz[i]);
  Eigen::Vector3f n = Eigen::Vector3f(b.nx[i], b.ny[i], b.nz[i]).normalized();
  float t = b.t[i];
  int obj = static_cast<int>(b.geom[i]);
  Eigen::Vector3f o = org;
  float path = t, att = 1;
  for (int bounce = 1;; ++bounce) {
    const ShadeMaterial& prev = shade[obj];
    if (prev.mirror <= 0 || bounce > mc.max_bounces) break;
    att *= prev.mirror * prev.mirror;
    o = o + t * dir;
    dir = dir - 2 * n.dot(dir) * n;
    t = mc.geometry->Cast(o, dir, 1e-4f, ctx, n, obj);
    if (!(t < kInf)) break;
    path += t;
    const ShadeMaterial& m = shade[obj];
    const float cos_i = std::min(1.f, std::abs(n.dot(dir)));
    float brdf = m.diffuse;
    if (m.glossy > 0 && cos_i > 0) {
      brdf += m.glossy * std::exp2(m.shininess * std::log2(cos_i));
    }
    const float active = mc.sub_active[si] * att * brdf * cos_i / (path * path);
    const float a = contrast * active;
    const float phase = two_pi_over_l * path;
    re += a * std::cos(phase);
    im += a * std::sin(phase);
    float radiance = 0;
    if (mc.background_light) {
      const Eigen::Vector3f hit = o + t * dir;
      radiance = m.diffuse * (ambient + LampIrradiance(scene, hit, n, obj, lamp_on));
      const int bulb = obj - scene.lamp_bulb_begin;
      const bool is_bulb = bulb >= 0 && bulb < static_cast<int>(lamp_on.size());
      if (!is_bulb || lamp_on[bulb]) radiance += m.emission;  // as in RenderAt
    }
    dc += active + mc.sub_bg[si] * att * radiance;
  }
}

}  // namespace tofcam::sim::internal
