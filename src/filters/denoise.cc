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

void DenoiseInto(const MetricFrame& frame, const DenoiseOptions& options, DenoisedChannels& out) {
  options.Validate();
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
}

MetricFrame Denoise(const MetricFrame& frame, const DenoiseOptions& options) {
  DenoisedChannels c;
  DenoiseInto(frame, options, c);
  MetricFrame out = frame;
  out.radial_distance_m = std::move(c.radial_distance_m);
  out.delta_l_m = std::move(c.delta_l_m);
  if (!frame.amplitude.empty()) out.amplitude = std::move(c.amplitude);
  return out;
}

}  // namespace tofcam
