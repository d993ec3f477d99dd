#include "optics.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "tofcam/core/units.h"

namespace tofcam::sim::internal {

// Normalised Gaussian kernel of radius max(1, ceil(3 sigma)).
std::vector<float> GaussianKernel(double sigma) {
  const int radius = std::max(1, static_cast<int>(std::ceil(3 * sigma)));
  std::vector<float> k(2 * radius + 1);
  double sum = 0;
  for (int i = -radius; i <= radius; ++i)
    sum += k[i + radius] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
  for (auto& v : k) v = static_cast<float>(v / sum);
  return k;
}

// Separable blur with a kernel of odd length and zero padding (light leaving the sensor is lost).
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h,
                 const std::vector<float>& k) {
  const int radius = static_cast<int>(k.size() / 2);
  tmp.assign(img.size(), 0.f);
  for (int r = 0; r < h; ++r) {
    const float* in = &img[static_cast<std::size_t>(r) * w];
    float* out = &tmp[static_cast<std::size_t>(r) * w];
    // Tap by tap over the columns it reaches (vectorises); every output still sums its taps in
    // increasing order from 0, so the result is the same as a per-pixel loop.
    for (int i = -radius; i <= radius; ++i) {
      const float kv = k[i + radius];
      for (int c = std::max(0, -i); c < std::min(w, w - i); ++c) out[c] += kv * in[c + i];
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

// Separable Gaussian blur with zero padding (light leaving the sensor is lost).
void BlurInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h, double sigma) {
  BlurInPlace(img, tmp, w, h, GaussianKernel(sigma));
}

void BlurBoxInPlace(std::vector<float>& img, std::vector<float>& tmp, int w, int h,
                    const std::vector<float>& k, int r0, int r1, int c0, int c1, RowPool* pool) {
  const int radius = static_cast<int>(k.size() / 2);
  // The output box: every pixel within the kernel's reach of the input box.
  const int o_r0 = std::max(0, r0 - radius), o_r1 = std::min(h, r1 + radius);
  const int o_c0 = std::max(0, c0 - radius), o_c1 = std::min(w, c1 + radius);
  if (tmp.size() < img.size()) tmp.resize(img.size());
  // Horizontal pass over the input box's rows (the others are zero), BlurInPlace's loops
  // restricted to the output box's columns.
  RunRows(pool, r1 - r0, [&](int a, int b) {
    for (int r = r0 + a; r < r0 + b; ++r) {
      const float* in = &img[static_cast<std::size_t>(r) * w];
      float* out = &tmp[static_cast<std::size_t>(r) * w];
      std::fill(out + o_c0, out + o_c1, 0.f);
      for (int i = -radius; i <= radius; ++i) {
        const float kv = k[i + radius];
        for (int c = std::max(o_c0, -i); c < std::min(o_c1, w - i); ++c) out[c] += kv * in[c + i];
      }
    }
  });
  // Vertical pass into the output box, skipping the zero rows outside the input box.
  RunRows(pool, o_r1 - o_r0, [&](int a, int b) {
    for (int r = o_r0 + a; r < o_r0 + b; ++r) {
      const int lo = std::max(-radius, r0 - r), hi = std::min(radius, r1 - 1 - r);
      float* out = &img[static_cast<std::size_t>(r) * w];
      std::fill(out + o_c0, out + o_c1, 0.f);
      for (int i = lo; i <= hi; ++i) {
        const float kv = k[i + radius];
        const float* in = &tmp[static_cast<std::size_t>(r + i) * w];
        for (int c = o_c0; c < o_c1; ++c) out[c] += kv * in[c];
      }
    }
  });
}

ScatterPlan PlanScatter(const std::vector<ScatterLobe>& lobes, int width, int height) {
  ScatterPlan sp;
  double min_sigma = 1e9;
  for (const ScatterLobe& l : lobes) min_sigma = std::min(min_sigma, l.sigma_px);
  // Wide lobes are smooth: blur at 1/f resolution (f <= sigma/2) and interpolate back.
  sp.f = std::clamp(static_cast<int>(min_sigma / 2), 1, 8);
  const int f = sp.f;
  sp.rw = (width + f - 1) / f;
  sp.rh = (height + f - 1) / f;
  sp.weight.clear();
  sp.kernel.clear();
  for (const ScatterLobe& l : lobes) {
    if (l.weight <= 0) continue;
    sp.weight.push_back(static_cast<float>(l.weight) / static_cast<float>(f * f));
    sp.kernel.push_back(GaussianKernel(l.sigma_px / f));
  }
  // Bilinear upsampling; reduced pixel (i, j) covers full pixels [f*i, f*i + f).
  auto taps = [f](int n, int reduced, std::vector<int>& i0, std::vector<int>& i1,
                  std::vector<float>& w) {
    i0.resize(n);
    i1.resize(n);
    w.resize(n);
    for (int x = 0; x < n; ++x) {
      const double y = (x + 0.5) / f - 0.5;
      i0[x] = std::clamp(static_cast<int>(std::floor(y)), 0, reduced - 1);
      i1[x] = std::min(i0[x] + 1, reduced - 1);
      w[x] = static_cast<float>(std::clamp(y - i0[x], 0.0, 1.0));
    }
  };
  taps(width, sp.rw, sp.x0, sp.x1, sp.wx);
  taps(height, sp.rh, sp.y0, sp.y1, sp.wy);
  return sp;
}

void ScatterChannel(const ScatterPlan& sp, int width, int height, const std::vector<float>& src,
                    std::vector<float>& dst, std::vector<float> (&tmp)[4]) {
  const int f = sp.f, rw = sp.rw, rh = sp.rh;
  std::vector<float>& reduced = tmp[0];
  std::vector<float>& blurred = tmp[1];
  std::vector<float>& work = tmp[2];
  std::vector<float>& acc = tmp[3];
  reduced.assign(static_cast<std::size_t>(rw) * rh, 0.f);
  for (int r = 0; r < height; ++r) {
    float* dst_row = &reduced[static_cast<std::size_t>(r / f) * rw];
    const float* src_row = &src[static_cast<std::size_t>(r) * width];
    for (int c0 = 0, j = 0; c0 < width; c0 += f, ++j) {
      float a = 0;
      for (int c = c0; c < std::min(c0 + f, width); ++c) a += src_row[c];
      dst_row[j] += a;
    }
  }
  acc.assign(reduced.size(), 0.f);
  for (std::size_t l = 0; l < sp.weight.size(); ++l) {
    blurred = reduced;
    BlurInPlace(blurred, work, rw, rh, sp.kernel[l]);
    const float wl = sp.weight[l];
    for (std::size_t i = 0; i < acc.size(); ++i) acc[i] += wl * blurred[i];
  }
  // Bilinear upsampling: interpolate along the rows of the reduced image first (each
  // reduced row once), then between the two rows of every full row.
  work.resize(static_cast<std::size_t>(rh) * width);
  for (int j = 0; j < rh; ++j) {
    const float* a = &acc[static_cast<std::size_t>(j) * rw];
    float* o = &work[static_cast<std::size_t>(j) * width];
    for (int c = 0; c < width; ++c) {
      o[c] = (1 - sp.wx[c]) * a[sp.x0[c]] + sp.wx[c] * a[sp.x1[c]];
    }
  }
  std::vector<float>& d = dst;
  for (int r = 0; r < height; ++r) {
    const float* a = &work[static_cast<std::size_t>(sp.y0[r]) * width];
    const float* b = &work[static_cast<std::size_t>(sp.y1[r]) * width];
    const float wy = sp.wy[r];
    float* o = &d[static_cast<std::size_t>(r) * width];
    for (int c = 0; c < width; ++c) o[c] = (1 - wy) * a[c] + wy * b[c];
  }
}

// One-bounce diffuse inter-reflection: the LED lights a point x2, which reflects diffusely
// onto the pixel's surface point x1, which reflects diffusely into the camera. Per evaluated
// pixel (every second one in x and y), the irradiance arriving at x1 over that path is
// estimated from cosine-weighted hemisphere samples (E = π/N Σ L2, L2 the radiance of x2 towards
// x1, with a shadow ray from x2 to the emitter), as a phasor of the path LED -> x2 -> x1. It is
// then averaged over the evaluated points on the same surface within 3 px (same object, depth
// within 5 %, normals within 25°): indirect light varies slowly along a surface, and this turns
// N samples into ~12 N. Every pixel adds (ρ1/π) E times its camera factor, at the phase of the
// full path, as indirect light (not in direct_re/im, so the truth flags it as multipath when it
// shifts the phase). Diffuse only (no glossy or mirror at either end), no lamp or ambient light
// in the bounce; the sample pattern is fixed per pixel, so a static scene gives a static result.
void Interreflect(const InterreflectionContext& ic, const Eigen::Isometry3d& pose,
                  InterreflectionBuffers& buf, Render& out) {
  const int n = ic.samples;
  const int width = ic.rays->width, height = ic.rays->height;
  const std::vector<float>& center_x = ic.rays->center_x;
  const std::vector<float>& center_y = ic.rays->center_y;
  const std::vector<float>& center_z = ic.rays->center_z;
  const std::vector<float>& pixel_bg = ic.radiometry->pixel_bg;
  const float led_on_axis_w_sr = ic.radiometry->led_on_axis_w_sr;
  const float led_exponent = ic.radiometry->led_exponent;
  const std::vector<ShadeMaterial>& shade = ic.materials->shade;
  const SceneGeometry& geometry = *ic.geometry;
  const double range_m = ic.range_m;
  RowPool* pool = ic.pool;
  std::vector<float>&ir_t = buf.ir_t, &ir_nx = buf.ir_nx, &ir_ny = buf.ir_ny, &ir_nz = buf.ir_nz;
  std::vector<float>&ir_re = buf.ir_re, &ir_im = buf.ir_im, &ir_dc = buf.ir_dc;
  std::vector<int>& ir_obj = buf.ir_obj;
  const Eigen::Matrix3f rot = pose.linear().cast<float>();
  const Eigen::Vector3f org = pose.translation().cast<float>();
  const Eigen::Vector3f axis = rot.col(2);
  const std::size_t np = static_cast<std::size_t>(width) * height;
  for (auto* v : {&ir_t, &ir_nx, &ir_ny, &ir_nz, &ir_re, &ir_im, &ir_dc}) v->assign(np, 0.f);
  ir_obj.assign(np, -1);
  // Half the round-trip path in units of L: the phase of a path of total length P is π P / L.
  const float half_cycles = static_cast<float>(0.5 / range_m);
  const float two_pi = static_cast<float>(2 * kPi);
  pool->Run(height, [&](int r0, int r1, int /*thread*/) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    std::vector<RTCRayHit> rays(static_cast<std::size_t>(n));
    std::vector<RTCRay> shadow(static_cast<std::size_t>(n));
    std::vector<int> lit(static_cast<std::size_t>(n));
    for (int r = r0; r < r1; ++r) {
      for (int c = 0; c < width; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * width + c;
        const Eigen::Vector3f dir = rot * Eigen::Vector3f(center_x[p], center_y[p], center_z[p]);
        Eigen::Vector3f n1;
        int g1 = -1;
        const float t1 = geometry.Cast(org, dir, 0.f, ctx, n1, g1);
        if (!(t1 < kInf)) continue;
        if (n1.dot(dir) > 0) n1 = -n1;  // the side the camera sees
        ir_t[p] = t1;
        ir_obj[p] = g1;
        ir_nx[p] = n1.x();
        ir_ny[p] = n1.y();
        ir_nz[p] = n1.z();
        if (r % 2 != 0 || c % 2 != 0) continue;  // evaluated on every second pixel
        const Eigen::Vector3f x1 = org + t1 * dir + 1e-4f * n1;
        const Eigen::Vector3f helper =
            std::abs(n1.x()) > 0.9f ? Eigen::Vector3f(0, 1, 0) : Eigen::Vector3f(1, 0, 0);
        const Eigen::Vector3f tb = helper.cross(n1).normalized(), bb = n1.cross(tb);
        // A stratified pattern (R1 sequence) rotated per pixel by a hash of its index.
        const std::uint64_t h = (p + 1) * 0x9E3779B97F4A7C15ull;
        const float off1 = static_cast<float>((h >> 40) & 0xFFFFFF) / 16777216.0f;
        const float off2 = static_cast<float>((h >> 16) & 0xFFFFFF) / 16777216.0f;
        for (int k = 0; k < n; ++k) {
          float u1 = (static_cast<float>(k) + 0.5f) / static_cast<float>(n) + off1;
          float u2 = static_cast<float>(k) * 0.6180339887f + off2;
          u1 -= std::floor(u1);
          u2 -= std::floor(u2);
          const float rr = std::sqrt(u1), phi = two_pi * u2;
          const Eigen::Vector3f w = tb * (rr * std::cos(phi)) + bb * (rr * std::sin(phi)) +
                                    n1 * std::sqrt(std::max(0.f, 1.f - u1));
          SetRay(rays[k], x1, w, 0.f);
        }
        rtcIntersect1M(geometry.Handle(), &ctx, rays.data(), static_cast<unsigned>(n),
                       sizeof(RTCRayHit));
        int m = 0;
        for (int k = 0; k < n; ++k) {
          if (rays[k].hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
          const RTCRay& in = rays[k].ray;
          const Eigen::Vector3f x2 = Eigen::Vector3f(in.org_x, in.org_y, in.org_z) +
                                     in.tfar * Eigen::Vector3f(in.dir_x, in.dir_y, in.dir_z);
          const Eigen::Vector3f to = org - x2;
          const float d2 = to.norm();
          RTCRay& sr = shadow[m];
          sr.org_x = x2.x();
          sr.org_y = x2.y();
          sr.org_z = x2.z();
          sr.dir_x = to.x() / d2;
          sr.dir_y = to.y() / d2;
          sr.dir_z = to.z() / d2;
          sr.tnear = 1e-4f;
          sr.tfar = d2 * (1.f - 1e-5f);
          sr.mask = 0xFFFFFFFFu;
          sr.time = 0;
          sr.flags = 0;
          sr.id = 0;
          lit[m++] = k;
        }
        if (m == 0) continue;
        rtcOccluded1M(geometry.Handle(), &ctx, shadow.data(), static_cast<unsigned>(m),
                      sizeof(RTCRay));
        float re = 0, im = 0, dc = 0;
        for (int j = 0; j < m; ++j) {
          if (!(shadow[j].tfar >= 0)) continue;  // Embree sets tfar to -inf when occluded
          const RTCRayHit& hit = rays[lit[j]];
          const auto g2 = static_cast<int>(hit.hit.geomID);
          if (shade[g2].diffuse <= 0) continue;
          const Eigen::Vector3f w(hit.ray.dir_x, hit.ray.dir_y, hit.ray.dir_z);
          const Eigen::Vector3f n2 =
              Eigen::Vector3f(hit.hit.Ng_x, hit.hit.Ng_y, hit.hit.Ng_z).normalized();
          const Eigen::Vector3f to_led(shadow[j].dir_x, shadow[j].dir_y, shadow[j].dir_z);
          // The LED must light the side of x2 that faces x1.
          const float cos_led = n2.dot(to_led), cos_back = -n2.dot(w);
          if (cos_led * cos_back <= 0) continue;
          const float d2 = shadow[j].tfar / (1.f - 1e-5f);
          const float cos_axis = -axis.dot(to_led);
          if (!(cos_axis > 0)) continue;
          const float intensity = led_on_axis_w_sr * std::pow(cos_axis, led_exponent);
          const float radiance = shade[g2].diffuse * intensity * std::abs(cos_led) / (d2 * d2);
          const float cycles = half_cycles * (d2 + hit.ray.tfar);
          re += radiance * std::cos(two_pi * cycles);
          im += radiance * std::sin(two_pi * cycles);
          dc += radiance;
        }
        const float scale = static_cast<float>(kPi) / static_cast<float>(n);
        ir_re[p] = scale * re;
        ir_im[p] = scale * im;
        ir_dc[p] = scale * dc;
      }
    }
  });
  // Smooth along surfaces and add to the rendering.
  const float contrast = static_cast<float>(ic.contrast);
  pool->Run(height, [&](int r0, int r1, int /*thread*/) {
    for (int r = r0; r < r1; ++r) {
      for (int c = 0; c < width; ++c) {
        const std::size_t p = static_cast<std::size_t>(r) * width + c;
        const int g = ir_obj[p];
        if (g < 0 || shade[g].diffuse <= 0) continue;
        float re = 0, im = 0, dc = 0;
        int count = 0;
        for (int rr = std::max(0, (r - 3 + 1) & ~1); rr <= std::min(height - 1, r + 3); rr += 2) {
          for (int cc = std::max(0, (c - 3 + 1) & ~1); cc <= std::min(width - 1, c + 3); cc += 2) {
            const std::size_t q = static_cast<std::size_t>(rr) * width + cc;
            if (ir_obj[q] != g || std::abs(ir_t[q] - ir_t[p]) > 0.05f * ir_t[p] ||
                ir_nx[q] * ir_nx[p] + ir_ny[q] * ir_ny[p] + ir_nz[q] * ir_nz[p] < 0.9f) {
              continue;
            }
            re += ir_re[q];
            im += ir_im[q];
            dc += ir_dc[q];
            ++count;
          }
        }
        if (count == 0) continue;
        // Rate = camera factor x (ρ1/π) x E, at the phase of the leg x1 -> camera added.
        const float k = pixel_bg[p] * shade[g].diffuse / static_cast<float>(count);
        const float leg = two_pi * half_cycles * ir_t[p];
        const float cs = std::cos(leg), sn = std::sin(leg);
        out.re[p] += contrast * k * (re * cs - im * sn);
        out.im[p] += contrast * k * (re * sn + im * cs);
        out.dc[p] += k * dc;
      }
    }
  });
}

}  // namespace tofcam::sim::internal
