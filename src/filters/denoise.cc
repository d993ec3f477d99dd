#include "tofcam/filters/denoise.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "hot_loop.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

void CheckSameSize(const Image<float>& d, int w, int h, const char* name) {
  if (!d.empty() && !d.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument, std::string("denoise: ") + name + " is " +
                                                 std::to_string(d.width()) + "x" +
                                                 std::to_string(d.height()) + ", the distance " +
                                                 std::to_string(w) + "x" + std::to_string(h));
  }
}

// Per pixel: the distance where usable (NaN elsewhere, so that no support test holds), σ² and
// 1 / σ² (0 where not usable), and the amplitude (0 where there is none).
struct Prepared {
  std::vector<float> usable, var, inv_var, amplitude;
};

// Prepare's per-pixel loop (vectorised; `a` and `flags` point at zeros when the frame has
// none). |x| <= max float is false for NaN and ±inf.
TOFCAM_HOT_LOOP void PrepareSpan(std::size_t n, const float* __restrict d,
                                 const float* __restrict s, const float* __restrict a,
                                 const PixelFlags* __restrict flags, std::uint16_t blocking,
                                 float* __restrict usable, float* __restrict var,
                                 float* __restrict inv_var, float* __restrict amplitude) {
  constexpr float kMax = std::numeric_limits<float>::max();
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < n; ++i) {
    // ΔL in [1e-9, 1e9] m: σ² and 1 / σ² are normal floats, and sums of 49 of them finite;
    // |A| <= 1e15: 49 weights (<= 1e18) times A stay finite too.
    const bool ok = (std::abs(d[i]) <= kMax) & (s[i] >= 1e-9f) & (s[i] <= 1e9f) &
                    (std::abs(a[i]) <= 1e15f) & ((flags[i].bits() & blocking) == 0);
    const float v = ok ? s[i] * s[i] : 1.0f;
    usable[i] = ok ? d[i] : kNan;
    var[i] = ok ? v : 0.0f;
    inv_var[i] = ok ? 1.0f / v : 0.0f;
    amplitude[i] = ok ? a[i] : 0.0f;
  }
}

void Prepare(const MetricFrame& f, Prepared& p) {
  const std::size_t n = f.radial_distance_m.size();
  p.usable.resize(n);
  p.var.resize(n);
  p.inv_var.resize(n);
  p.amplitude.resize(n);
  // kHighDeltaL is what this stage lowers; every other reject bit excludes the pixel.
  const auto blocking =
      static_cast<std::uint16_t>(kRejectMask & ~static_cast<std::uint16_t>(Flag::kHighDeltaL));
  thread_local std::vector<float> zero_floats;
  thread_local std::vector<PixelFlags> zero_flags;
  const float* a = f.amplitude.data();
  if (f.amplitude.empty()) {
    zero_floats.assign(n, 0.0f);
    a = zero_floats.data();
  }
  const PixelFlags* flags = f.flags.data();
  if (f.flags.empty()) {
    zero_flags.assign(n, PixelFlags());
    flags = zero_flags.data();
  }
  PrepareSpan(n, f.radial_distance_m.data(), f.delta_l_m.data(), a, flags, blocking,
              p.usable.data(), p.var.data(), p.inv_var.data(), p.amplitude.data());
}

// One window offset over a row's columns: where the neighbour (dn, vn, wn, an) is within k
// combined σ of the centre (dc, vc) and within s (s2 = s², +inf for no limit), its weight,
// weighted deviation and weighted amplitude join
// the sums. NaN distances (unusable pixels) fail the test. Vectorised (clones for AVX2); built
// without contraction, so every clone rounds alike.
TOFCAM_HOT_LOOP void DenoiseOffset(int n, float k2, float s2, const float* __restrict dc,
                                   const float* __restrict vc, const float* __restrict dn,
                                   const float* __restrict vn, const float* __restrict wn,
                                   const float* __restrict an, float* __restrict sum_w,
                                   float* __restrict sum_dev, float* __restrict sum_a) {
  for (int i = 0; i < n; ++i) {
    const float dev = dn[i] - dc[i];
    const float limit = k2 * (vc[i] + vn[i]);
    const bool in = dev * dev <= (limit < s2 ? limit : s2);
    sum_w[i] += in ? wn[i] : 0.0f;
    sum_dev[i] += in ? wn[i] * dev : 0.0f;
    sum_a[i] += in ? wn[i] * an[i] : 0.0f;
  }
}

// One row's results from its sums: where a usable centre's own weight is in sum_w (> 0), the
// weighted mean and its σ; elsewhere the input, copied. Vectorised; the dropped lanes' division
// by zero is never stored.
TOFCAM_HOT_LOOP void DenoiseFinish(std::size_t n, const float* __restrict usable,
                                   const float* __restrict sum_w, const float* __restrict sum_dev,
                                   const float* __restrict sum_a, const float* __restrict d_in,
                                   const float* __restrict s_in, const float* __restrict a_in,
                                   float* __restrict d_out, float* __restrict s_out,
                                   float* __restrict a_out) {
  for (std::size_t i = 0; i < n; ++i) {
    const bool mean = sum_w[i] > 0.0f;
    d_out[i] = mean ? usable[i] + sum_dev[i] / sum_w[i] : d_in[i];
    s_out[i] = mean ? 1.0f / std::sqrt(sum_w[i]) : s_in[i];
    a_out[i] = mean ? sum_a[i] / sum_w[i] : a_in[i];
  }
}

// The plane fit's per-pixel inputs: normalised image coordinates u = x / z, v = y / z of the
// ray, and t = 1 / z = 1 / (d r_z) where usable (0 elsewhere: never in a support, so its weight
// is 0 and the finite 0 adds nothing). A usable pixel whose ray is 89.4° or more from the
// optical axis (r_z < 0.01), or whose distance is not positive, has no useful 1/z: its t is NaN,
// so every window containing it gets NaN sums (0 x NaN, in or out of the support) and falls back
// to the mean.
struct PlaneInputs {
  std::vector<float> u, v, t;
};

TOFCAM_HOT_LOOP void PreparePlaneSpan(std::size_t n, const float* __restrict usable,
                                      const float* __restrict rx, const float* __restrict ry,
                                      const float* __restrict rz, float* __restrict u,
                                      float* __restrict v, float* __restrict t) {
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < n; ++i) {
    const bool forward = rz[i] >= 0.01f;
    const float z = forward ? rz[i] : 1.0f;
    u[i] = rx[i] / z;
    v[i] = ry[i] / z;
    const float depth = usable[i] * z;
    const bool ok = usable[i] == usable[i];  // not NaN
    t[i] = !ok ? 0.0f : forward && depth > 0.0f ? 1.0f / depth : kNan;
  }
}

// The plane fit's inputs with a border of `pad` pixels on every side, so that a window never
// leaves the arrays: border pixels have a NaN distance (never in a support), and zero weights
// and offsets. Row stride w + 2 pad.
struct PaddedPlaneInputs {
  std::vector<float> d, var, inv_var, u, v, t;
};

void Pad(const std::vector<float>& in, int w, int h, int pad, float border,
         std::vector<float>& out) {
  const std::size_t pw = static_cast<std::size_t>(w + 2 * pad);
  out.assign(pw * static_cast<std::size_t>(h + 2 * pad), border);
  for (int r = 0; r < h; ++r) {
    std::copy_n(
        in.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(w), w,
        out.data() + static_cast<std::size_t>(r + pad) * pw + static_cast<std::size_t>(pad));
  }
}

// The plane fit's support test for one window offset over a row (as DenoiseOffset's): each
// centre's weight of the neighbour at `off` (0 outside the support) and 1 or 0 for in or out.
// `d`, `var`, `inv_var` point at the row's first centre in the padded arrays.
TOFCAM_HOT_LOOP void PlaneSupport(int n, std::ptrdiff_t off, float k2, float s2,
                                  const float* __restrict d, const float* __restrict var,
                                  const float* __restrict inv_var, float* __restrict weight,
                                  float* __restrict in) {
  for (int i = 0; i < n; ++i) {
    const float dev = d[i + off] - d[i];
    const float limit = k2 * (var[i] + var[i + off]);
    const float one = dev * dev <= (limit < s2 ? limit : s2) ? 1.0f : 0.0f;
    // A product, not a select of a load: inv_var is finite (at most 1e18).
    weight[i] = one * inv_var[i + off];
    in[i] = one;
  }
}

// The fit over a window of radius R for one row (`u`, `v`, `t` at the row's first centre in the
// padded arrays, `weight` and `in` PlaneSupport's, offset k at k x n): the plane's distance and
// σ, and 1 where it applies (the support's pixels do not all lie on one line of the pixel grid:
// their unweighted offsets' covariance determinant, exact in small integers, is positive; the
// weighted one is resolved in double; the intercept and its variance are positive and finite),
// else 0. The sums are in double: with a
// few heavy neighbours the centred moments cancel. No data-dependent branch, so that it
// vectorises; a dropped lane's division by zero is never used.
template <int R>
TOFCAM_HOT_LOOP_WIDE void PlaneFit(int n, std::ptrdiff_t stride, const float* __restrict u,
                                   const float* __restrict v, const float* __restrict t,
                                   const float* __restrict rz, const float* __restrict weight,
                                   const float* __restrict in, float* __restrict plane_d,
                                   float* __restrict plane_sigma, float* __restrict ok) {
  constexpr int kSide = 2 * R + 1, kCount = kSide * kSide;
  for (int i = 0; i < n; ++i) {
    const double uc = u[i], vc = v[i], tc = t[i];
    double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, st = 0, stx = 0, sty = 0;
    float count = 0, px = 0, py = 0, pxx = 0, pxy = 0, pyy = 0;
    // Unrolled whole for the 3x3 window (radius 1, the default), so that the loop over the row
    // vectorises with the sums in registers; larger windows stay a loop (scalar, and a fifth of
    // the compile time: unrolling 25 and 49 offsets in three clones took 15 s).
#pragma GCC unroll 9
    for (int k = 0; k < kCount; ++k) {
      const int oy = k / kSide - R, ox = k % kSide - R;
      const std::ptrdiff_t j = i + oy * stride + ox;
      const std::ptrdiff_t ki = static_cast<std::ptrdiff_t>(k) * n + i;
      // w = 0 outside the support; t is finite there (0 for unusable pixels and the padding)
      // except next to the axis (see PreparePlaneSpan), so those neighbours add nothing.
      const double w = weight[ki];
      const double x = double{u[j]} - uc, y = double{v[j]} - vc, dt = double{t[j]} - tc;
      const double wx = w * x, wy = w * y, wdt = w * dt;
      sw += w;
      sx += wx;
      sy += wy;
      sxx += wx * x;
      sxy += wx * y;
      syy += wy * y;
      st += wdt;
      stx += wdt * x;
      sty += wdt * y;
      const float fx = in[ki] * static_cast<float>(ox), fy = in[ki] * static_cast<float>(oy);
      count += in[ki];
      px += fx;
      py += fy;
      pxx += fx * fx;
      pxy += fx * fy;
      pyy += fy * fy;
    }
    const double gxx = double{count} * pxx - double{px} * px;
    const double gyy = double{count} * pyy - double{py} * py;
    const double gxy = double{count} * pxy - double{px} * py;
    const double mx = sx / sw, my = sy / sw, mt = st / sw;
    const double cxx = sxx - sx * mx, cxy = sxy - sx * my, cyy = syy - sy * my;
    const double ctx = stx - sx * mt, cty = sty - sy * mt;
    const double det = cxx * cyy - cxy * cxy;
    const double gx = (cyy * ctx - cxy * cty) / det, gy = (cxx * cty - cxy * ctx) / det;
    const double b0 = tc + mt - gx * mx - gy * my;
    const double dist = 1.0 / (b0 * double{rz[i]});
    const double variance = 1.0 / sw + (cyy * mx * mx - 2.0 * cxy * mx * my + cxx * my * my) / det;
    const double sigma = std::sqrt(variance);
    // det > 1e-10 of the sxx syy about the centre pixel: below that the heavy pixels lie nearly
    // on one line away from the centre and the light ones' spread is near the double sums'
    // rounding (a margin of about 1e5), so the fit's slope across that line would rest on
    // rounding noise.
    const bool good = (sw > 0.0) & (gxx * gyy - gxy * gxy > 0.5) & (det > 1e-10 * sxx * syy) &
                      (b0 > 0.0) & (dist <= std::numeric_limits<float>::max()) & (variance > 0.0) &
                      (sigma <= std::numeric_limits<float>::max());
    ok[i] = good ? 1.0f : 0.0f;
    plane_d[i] = static_cast<float>(good ? dist : 0.0);
    plane_sigma[i] = static_cast<float>(good ? sigma : 0.0);
  }
}

// The plane's distance and σ over the mean's where PlaneFit says it applies.
TOFCAM_HOT_LOOP void PlaneSelect(int n, const float* __restrict ok, const float* __restrict plane_d,
                                 const float* __restrict plane_sigma, float* __restrict d_out,
                                 float* __restrict s_out) {
  for (int i = 0; i < n; ++i) {
    const float old_d = d_out[i], old_s = s_out[i];
    d_out[i] = ok[i] > 0.0f ? plane_d[i] : old_d;
    s_out[i] = ok[i] > 0.0f ? plane_sigma[i] : old_s;
  }
}

// Per-row scratch of the plane fit: PlaneSupport's weights and flags for every window offset,
// and PlaneFit's results.
struct PlaneRowScratch {
  std::vector<float> weight, in, d, sigma, ok;
};

}  // namespace

void DenoiseOptions::Validate() const {
  if (radius_px < 1 || radius_px > 3) {
    throw Error(ErrorCode::kInvalidArgument,
                "denoise.radius_px = " + std::to_string(radius_px) + " is outside [1, 3]");
  }
  if (!(support_sigma > 0.0 && support_sigma <= 100.0)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "denoise.support_sigma = " + std::to_string(support_sigma) + " is outside (0, 100]");
  }
  if (!(max_step_m >= 0.0 && max_step_m <= 1e6)) {
    throw Error(ErrorCode::kInvalidArgument,
                "denoise.max_step_m = " + std::to_string(max_step_m) + " is outside [0, 1e6]");
  }
}

namespace {

// The fit_plane path of DenoiseImpl: `out` already holds the mean's results (the fallback).
void DenoisePlane(const MetricFrame& frame, const RayTable& rays, const DenoiseOptions& options,
                  const Prepared& p, DenoisedChannels& out) {
  const int w = frame.radial_distance_m.width(), h = frame.radial_distance_m.height();
  const std::size_t n = frame.radial_distance_m.size();
  thread_local PlaneInputs q;
  q.u.resize(n);
  q.v.resize(n);
  q.t.resize(n);
  PreparePlaneSpan(n, p.usable.data(), rays.x.data(), rays.y.data(), rays.z.data(), q.u.data(),
                   q.v.data(), q.t.data());
  const int r = options.radius_px;
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  thread_local PaddedPlaneInputs padded;
  Pad(p.usable, w, h, r, kNan, padded.d);
  Pad(p.var, w, h, r, 0.0f, padded.var);
  Pad(p.inv_var, w, h, r, 0.0f, padded.inv_var);
  Pad(q.u, w, h, r, 0.0f, padded.u);
  Pad(q.v, w, h, r, 0.0f, padded.v);
  Pad(q.t, w, h, r, 0.0f, padded.t);
  const float k = static_cast<float>(options.support_sigma);
  const float k2 = k * k;
  const float s = static_cast<float>(options.max_step_m);
  const float s2 = options.max_step_m > 0.0 ? s * s : std::numeric_limits<float>::infinity();
  const std::ptrdiff_t stride = w + 2 * r;
  const int side = 2 * r + 1, count = side * side;
  const std::size_t wn = static_cast<std::size_t>(w);
  thread_local PlaneRowScratch scratch;
  scratch.weight.resize(static_cast<std::size_t>(count) * wn);
  scratch.in.resize(static_cast<std::size_t>(count) * wn);
  scratch.d.resize(wn);
  scratch.sigma.resize(wn);
  scratch.ok.resize(wn);
  const auto fit = r == 1 ? PlaneFit<1> : r == 2 ? PlaneFit<2> : PlaneFit<3>;
  for (int row = 0; row < h; ++row) {
    const std::size_t at = static_cast<std::size_t>(row + r) * static_cast<std::size_t>(stride) +
                           static_cast<std::size_t>(r);
    for (int o = 0; o < count; ++o) {
      const std::ptrdiff_t off = (o / side - r) * stride + (o % side - r);
      const std::size_t kw = static_cast<std::size_t>(o) * wn;
      PlaneSupport(w, off, k2, s2, padded.d.data() + at, padded.var.data() + at,
                   padded.inv_var.data() + at, scratch.weight.data() + kw, scratch.in.data() + kw);
    }
    fit(w, stride, padded.u.data() + at, padded.v.data() + at, padded.t.data() + at,
        rays.z.Row(row).data(), scratch.weight.data(), scratch.in.data(), scratch.d.data(),
        scratch.sigma.data(), scratch.ok.data());
    PlaneSelect(w, scratch.ok.data(), scratch.d.data(), scratch.sigma.data(),
                out.radial_distance_m.Row(row).data(), out.delta_l_m.Row(row).data());
  }
}

void DenoiseImpl(const MetricFrame& frame, const RayTable* rays, const DenoiseOptions& options,
                 DenoisedChannels& out) {
  options.Validate();
  // An empty table is no table (Denoise without rays passes one).
  if (rays != nullptr && rays->x.empty() && rays->y.empty() && rays->z.empty()) rays = nullptr;
  if (options.fit_plane && rays == nullptr) {
    throw Error(ErrorCode::kInvalidArgument,
                "denoise.fit_plane needs the camera's rays (a RayTable of the frame's size)");
  }
  const Image<float>& d = frame.radial_distance_m;
  if (d.empty()) throw Error(ErrorCode::kInvalidArgument, "denoise: empty distance image");
  const int w = d.width(), h = d.height();
  if (frame.delta_l_m.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "denoise: delta_l_m is empty (run the accuracy stage first)");
  }
  CheckSameSize(frame.delta_l_m, w, h, "delta_l_m");
  CheckSameSize(frame.amplitude, w, h, "amplitude");
  if (!frame.flags.empty() && !frame.flags.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument, "denoise: flags differ in size from the distance");
  }
  if (rays != nullptr) {
    for (const auto& [channel, name] :
         {std::pair{&rays->x, "x"}, std::pair{&rays->y, "y"}, std::pair{&rays->z, "z"}}) {
      if (!channel->SameSize(w, h)) {
        throw Error(ErrorCode::kMismatch,
                    std::string("denoise: the rays' ") + name + " is " +
                        std::to_string(channel->width()) + "x" + std::to_string(channel->height()) +
                        ", the distance " + std::to_string(w) + "x" + std::to_string(h));
      }
    }
  }
  const bool has_a = !frame.amplitude.empty();
  if (!out.radial_distance_m.SameSize(w, h)) out.radial_distance_m = Image<float>(w, h);
  if (!out.delta_l_m.SameSize(w, h)) out.delta_l_m = Image<float>(w, h);
  if (!has_a) {
    out.amplitude = Image<float>();
  } else if (!out.amplitude.SameSize(w, h)) {
    out.amplitude = Image<float>(w, h);
  }

  thread_local Prepared p;
  Prepare(frame, p);
  thread_local std::vector<float> sum_w, sum_dev, sum_a, discard;
  sum_w.resize(static_cast<std::size_t>(w));
  sum_dev.resize(static_cast<std::size_t>(w));
  sum_a.resize(static_cast<std::size_t>(w));
  discard.resize(has_a ? 0 : static_cast<std::size_t>(w));  // the amplitude a frame lacks
  const float k = static_cast<float>(options.support_sigma);
  const float k2 = k * k;
  const float s = static_cast<float>(options.max_step_m);
  const float s2 = options.max_step_m > 0.0 ? s * s : std::numeric_limits<float>::infinity();
  const int r = options.radius_px;
  for (int row = 0; row < h; ++row) {
    std::fill(sum_w.begin(), sum_w.end(), 0.0f);
    std::fill(sum_dev.begin(), sum_dev.end(), 0.0f);
    std::fill(sum_a.begin(), sum_a.end(), 0.0f);
    const std::size_t c0 = static_cast<std::size_t>(row) * static_cast<std::size_t>(w);
    for (int y = std::max(0, row - r); y <= std::min(h - 1, row + r); ++y) {
      for (int dx = -r; dx <= r; ++dx) {
        // Columns [first, last) have their neighbour at dx inside the image.
        const int first = std::max(0, -dx), last = std::min(w, w - dx);
        if (first >= last) continue;
        const std::size_t at = c0 + static_cast<std::size_t>(first);
        const std::size_t n_at = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                                 static_cast<std::size_t>(first + dx);
        DenoiseOffset(last - first, k2, s2, p.usable.data() + at, p.var.data() + at,
                      p.usable.data() + n_at, p.var.data() + n_at, p.inv_var.data() + n_at,
                      p.amplitude.data() + n_at, sum_w.data() + first, sum_dev.data() + first,
                      sum_a.data() + first);
      }
    }
    const std::size_t wn = static_cast<std::size_t>(w);
    DenoiseFinish(wn, p.usable.data() + c0, sum_w.data(), sum_dev.data(), sum_a.data(),
                  d.Row(row).data(), frame.delta_l_m.Row(row).data(),
                  has_a ? frame.amplitude.Row(row).data() : p.amplitude.data() + c0,
                  out.radial_distance_m.Row(row).data(), out.delta_l_m.Row(row).data(),
                  has_a ? out.amplitude.Row(row).data() : discard.data());
  }
  if (options.fit_plane) DenoisePlane(frame, *rays, options, p, out);
}

}  // namespace

void DenoiseInto(const MetricFrame& frame, const DenoiseOptions& options, DenoisedChannels& out) {
  DenoiseImpl(frame, nullptr, options, out);
}

void DenoiseInto(const MetricFrame& frame, const RayTable& rays, const DenoiseOptions& options,
                 DenoisedChannels& out) {
  DenoiseImpl(frame, &rays, options, out);
}

MetricFrame Denoise(const MetricFrame& frame, const DenoiseOptions& options) {
  return Denoise(frame, RayTable{}, options);
}

MetricFrame Denoise(const MetricFrame& frame, const RayTable& rays, const DenoiseOptions& options) {
  DenoisedChannels c;
  DenoiseImpl(frame, &rays, options, c);
  MetricFrame out = frame;
  out.radial_distance_m = std::move(c.radial_distance_m);
  out.delta_l_m = std::move(c.delta_l_m);
  if (!frame.amplitude.empty()) out.amplitude = std::move(c.amplitude);
  return out;
}

}  // namespace tofcam
