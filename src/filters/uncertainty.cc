#include "tofcam/filters/uncertainty.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "hot_loop.h"
#include "simd.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

// One row of the default uncertainty (no extrapolated edges) from padded rows (index -1 and w
// exist): `d` the usable distances (NaN where not usable or outside the image), `s` ΔL, `unknown`
// 1 where the pixel carries one of the unknown-neighbour flags; `du`, `dd` (`su`, `sd`, `ku`,
// `kd`) the rows above and below. The same double operations in the same order as the per-pixel
// form in ComputeUncertainty, four pixels per step (max of non-negative finite values is exact
// in any order): u = sqrt(s² + edge²), +inf for an unusable centre or an unknown neighbour.
TOFCAM_HOT_LOOP void UncertaintyRow(int w, double min_jump_sigma, double edge_fraction,
                                    const float* __restrict d, const float* __restrict s,
                                    const std::uint8_t* __restrict unknown,
                                    const float* __restrict du, const float* __restrict su,
                                    const std::uint8_t* __restrict ku, const float* __restrict dd,
                                    const float* __restrict sd, const std::uint8_t* __restrict kd,
                                    float* __restrict out) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int c = 0; c < w; ++c) {
    const double dc = d[c], sc = s[c];
    double edge = 0.0;
    // Neighbours up, down, left, right.
    const double dn[4] = {du[c], dd[c], d[c - 1], d[c + 1]};
    const double sn[4] = {su[c], sd[c], s[c - 1], s[c + 1]};
    for (int k = 0; k < 4; ++k) {
      const double step = std::abs(dn[k] - dc);
      // False for a NaN (unusable) neighbour.
      const bool edge_step = step > min_jump_sigma * std::sqrt(sc * sc + sn[k] * sn[k]);
      edge = std::max(edge, edge_step ? edge_fraction * step : 0.0);
    }
    const bool unbounded = (ku[c] | kd[c] | unknown[c - 1] | unknown[c + 1]) != 0;
    const float u = static_cast<float>(std::sqrt(sc * sc + edge * edge));
    out[c] = (dc == dc) && !unbounded ? u : kInf;
  }
}

// One row of the padded inputs of UncertaintyRow: the distance where the pixel is usable (no
// reject flag, finite distance and ΔL; NaN otherwise), ΔL, and the unknown-neighbour mask.
TOFCAM_HOT_LOOP void PadRow(int w, const float* __restrict d, const float* __restrict s,
                            const PixelFlags* __restrict flags, std::uint16_t unknown_flags,
                            float* __restrict pd, float* __restrict ps,
                            std::uint8_t* __restrict pk) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int c = 0; c < w; ++c) {
    const bool usable = ((flags[c].bits() & kRejectMask) == 0) & (std::abs(d[c]) < kInf) &
                        (std::abs(s[c]) < kInf);  // false for NaN and inf
    pd[c] = usable ? d[c] : std::numeric_limits<float>::quiet_NaN();
    ps[c] = s[c];
    pk[c] = static_cast<std::uint8_t>((flags[c].bits() & unknown_flags) != 0);
  }
}

// kLowConfidence where a pixel without a reject flag has u above `max` (or u NaN).
TOFCAM_HOT_LOOP void FlagRow(std::size_t n, const float* __restrict u,
                             const PixelFlags* __restrict flags, float max,
                             PixelFlags* __restrict out) {
  const auto bit = static_cast<std::uint16_t>(Flag::kLowConfidence);
  for (std::size_t i = 0; i < n; ++i) {
    const bool low = ((flags[i].bits() & kRejectMask) == 0) & !(u[i] <= max);
    out[i] = PixelFlags(static_cast<std::uint16_t>(low ? bit : 0));
  }
}

}  // namespace

void UncertaintyOptions::Validate() const {
  if (!(max_uncertainty_m > 0.0 && max_uncertainty_m <= 100.0)) {
    Bad("uncertainty.max_uncertainty_m = " + std::to_string(max_uncertainty_m) +
        " must be in (0, 100]");
  }
  if (!(edge_fraction >= 0.0 && edge_fraction <= 1.0)) {
    Bad("uncertainty.edge_fraction = " + std::to_string(edge_fraction) + " must be in [0, 1]");
  }
  if (!(min_jump_sigma > 0.0 && min_jump_sigma <= 100.0)) {
    Bad("uncertainty.min_jump_sigma = " + std::to_string(min_jump_sigma) + " must be in (0, 100]");
  }
}

Image<float> ComputeUncertainty(const MetricFrame& frame, const UncertaintyOptions& options) {
  options.Validate();
  const int w = frame.width(), h = frame.height();
  if (w <= 0 || h <= 0) Bad("uncertainty: empty frame");
  if (!frame.delta_l_m.SameSize(w, h) || !frame.flags.SameSize(w, h)) {
    Bad("uncertainty: the frame needs ΔL and flags of its size (enable the accuracy stage)");
  }
  constexpr float kInf = std::numeric_limits<float>::infinity();
  auto usable = [&](std::size_t i) {
    return !frame.flags[i].Any(kRejectMask) && std::isfinite(frame.radial_distance_m[i]) &&
           std::isfinite(frame.delta_l_m[i]);
  };
  // How far pixel i lies off the straight line through its two neighbours in direction
  // (dr, dc), m: 0 when that deviation is within min_jump_sigma of its σ (sqrt(σ_i² + 4 σ_a² +
  // σ_b²)); NaN when either neighbour is outside the image or unusable.
  const auto off_line = [&](int r, int c, int dr, int dc, std::size_t i) -> double {
    const int r1 = r + dr, c1 = c + dc, r2 = r + 2 * dr, c2 = c + 2 * dc;
    if (r2 < 0 || r2 >= h || c2 < 0 || c2 >= w) return std::numeric_limits<double>::quiet_NaN();
    const std::size_t a = static_cast<std::size_t>(r1) * w + c1;
    const std::size_t b = static_cast<std::size_t>(r2) * w + c2;
    if (!usable(a) || !usable(b)) return std::numeric_limits<double>::quiet_NaN();
    const double dev = std::abs(static_cast<double>(frame.radial_distance_m[i]) -
                                2.0 * frame.radial_distance_m[a] + frame.radial_distance_m[b]);
    const double si = frame.delta_l_m[i], sa = frame.delta_l_m[a], sb = frame.delta_l_m[b];
    return dev > options.min_jump_sigma * std::sqrt(si * si + 4 * sa * sa + sb * sb) ? dev : 0.0;
  };
  Image<float> out(w, h, kInf);
  if (!options.extrapolate_edges) {
    // Padded rows (one pixel each side; rows outside the image all padding): distances NaN
    // where not usable, ΔL, and the unknown-neighbour mask.
    const std::size_t pw = static_cast<std::size_t>(w) + 2;
    thread_local std::vector<float> pd, ps;
    thread_local std::vector<std::uint8_t> pk;
    const std::size_t rows = static_cast<std::size_t>(h) + 2;
    pd.assign(rows * pw, std::numeric_limits<float>::quiet_NaN());
    ps.assign(rows * pw, 0.0f);
    pk.assign(rows * pw, 0);
    for (int r = 0; r < h; ++r) {
      const std::size_t o = (static_cast<std::size_t>(r) + 1) * pw + 1;
      PadRow(w, frame.radial_distance_m.Row(r).data(), frame.delta_l_m.Row(r).data(),
             frame.flags.Row(r).data(), options.unknown_neighbour_flags, &pd[o], &ps[o], &pk[o]);
    }
    for (int r = 0; r < h; ++r) {
      const std::size_t up = static_cast<std::size_t>(r) * pw + 1, mid = up + pw, down = mid + pw;
      UncertaintyRow(w, options.min_jump_sigma, options.edge_fraction, &pd[mid], &ps[mid], &pk[mid],
                     &pd[up], &ps[up], &pk[up], &pd[down], &ps[down], &pk[down], out.Row(r).data());
    }
    return out;
  }
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      if (!usable(i)) continue;
      const double d = frame.radial_distance_m[i], s = frame.delta_l_m[i];
      double edge = 0.0;  // m
      const int dr[4] = {-1, 1, 0, 0}, dc[4] = {0, 0, -1, 1};
      for (int k = 0; k < 4; ++k) {
        const int rr = r + dr[k], cc = c + dc[k];
        if (rr < 0 || rr >= h || cc < 0 || cc >= w) continue;
        const std::size_t j = static_cast<std::size_t>(rr) * w + cc;
        if (frame.flags[j].Any(options.unknown_neighbour_flags)) {
          edge = std::numeric_limits<double>::infinity();
          break;
        }
        if (!usable(j)) continue;
        const double dj = frame.radial_distance_m[j];
        const double step = std::abs(dj - d);
        const double sj = frame.delta_l_m[j];
        if (!(step > options.min_jump_sigma * std::sqrt(s * s + sj * sj))) continue;
        double e = options.edge_fraction * step;
        if (options.extrapolate_edges) {
          // The step's other side is the neighbour's business; this pixel is wrong only as far
          // as it leaves its own side's surface (a mixed pixel) or that is unknown.
          const double dev = off_line(r, c, -dr[k], -dc[k], i);
          if (!std::isnan(dev)) e = dev;
        }
        edge = std::max(edge, e);
      }
      if (std::isinf(edge)) continue;  // next to a clipped pixel: unbounded
      out[i] = static_cast<float>(std::sqrt(s * s + edge * edge));
    }
  }
  return out;
}

Image<PixelFlags> UncertaintyFilter(const MetricFrame& frame, const UncertaintyOptions& options) {
  const Image<float> u = ComputeUncertainty(frame, options);
  Image<PixelFlags> out(frame.width(), frame.height());
  // Rejected pixels (u = inf) already carry their reason; the others are judged (u = inf
  // there: next to a clipped pixel, or no ΔL).
  FlagRow(u.size(), u.data(), frame.flags.data(), static_cast<float>(options.max_uncertainty_m),
          out.data());
  return out;
}

}  // namespace tofcam
