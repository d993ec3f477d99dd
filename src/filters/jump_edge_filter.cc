#include "tofcam/filters/jump_edge_filter.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "filter_internal.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace filters_internal {
namespace {

// The criterion in closed form. For p = d_p u_p and a neighbour n = d_n u_n whose unit rays
// enclose the angle γ, write a = d_p - d_n cos γ. Then p·(n - p) = -d_p a and
// |n - p|² = a² + d_n² sin²γ, so
//   α > θ  <=>  cos α < cos θ = -|cos θ|  <=>  a > 0 and a² sin²θ > cos²θ d_n² sin²γ
//          <=>  d_p > d_n (cos γ + |cot θ| sin γ) = d_n λ.
// λ depends only on the two rays and θ, so it is precomputed once per ray table; per pixel and
// neighbour the test is one multiply and one compare, and it avoids the cancellation of
// |n - p|² in float. λ is symmetric, so four tables (E, S, SE, SW pairs) serve all 8 neighbours.
//
// The λ tables together with the rays they were built from, to recognise the same table on the
// next call of the RayTable form (FilterSet and Pipeline keep their own JumpLambdas instead).
struct LambdaCache {
  JumpLambdas lambdas;
  std::vector<float> rays;  // copy of x, y, z
};

bool SameRays(const LambdaCache& c, const RayTable& rays, double angle_deg) {
  const std::size_t n = rays.x.size();
  if (c.lambdas.width != rays.x.width() || c.lambdas.height != rays.x.height() ||
      c.lambdas.angle_deg != angle_deg || c.rays.size() != 3 * n) {
    return false;
  }
  return std::memcmp(c.rays.data(), rays.x.data(), n * sizeof(float)) == 0 &&
         std::memcmp(c.rays.data() + n, rays.y.data(), n * sizeof(float)) == 0 &&
         std::memcmp(c.rays.data() + 2 * n, rays.z.data(), n * sizeof(float)) == 0;
}

// d where usable (finite, > 0, no reject bit in the prior), else +inf.
TOFCAM_HOT_LOOP void UsableDistances(int w, const float* __restrict d,
                                     const PixelFlags* __restrict pf, float* __restrict out) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int c = 0; c < w; ++c) {
    const bool usable = (d[c] > 0.0f) & (d[c] < kInf) & ((pf[c].bits() & kRejectMask) == 0);
    out[c] = usable ? d[c] : kInf;
  }
}

// One row: p is flagged (in f and in echo) when any usable neighbour n has d_p > d_n λ(p, n). `up`,
// `mid`, `down` are the padded distance rows at the row's first pixel; e/s/se/sw hold λ for the
// forward pairs of this row, s_up/se_up/sw_up those of the row above (the backward pairs).
TOFCAM_HOT_LOOP void JumpRow(int w, const float* __restrict up, const float* __restrict mid,
                             const float* __restrict down, const float* __restrict e,
                             const float* __restrict s, const float* __restrict se,
                             const float* __restrict sw, const float* __restrict s_up,
                             const float* __restrict se_up, const float* __restrict sw_up,
                             PixelFlags* __restrict f, PixelFlags* __restrict echo) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const std::uint16_t bit = static_cast<std::uint16_t>(Flag::kJumpEdge);
  for (int c = 0; c < w; ++c) {
    const float dp = mid[c];
    const unsigned jump = static_cast<unsigned>(dp > mid[c + 1] * e[c]) |
                          static_cast<unsigned>(dp > mid[c - 1] * e[c - 1]) |
                          static_cast<unsigned>(dp > down[c] * s[c]) |
                          static_cast<unsigned>(dp > up[c] * s_up[c]) |
                          static_cast<unsigned>(dp > down[c + 1] * se[c]) |
                          static_cast<unsigned>(dp > up[c - 1] * se_up[c - 1]) |
                          static_cast<unsigned>(dp > down[c - 1] * sw[c]) |
                          static_cast<unsigned>(dp > up[c + 1] * sw_up[c + 1]);
    const unsigned flag = jump & static_cast<unsigned>(dp < kInf);
    f[c] |= PixelFlags(static_cast<std::uint16_t>(flag * bit));
    echo[c] |= PixelFlags(static_cast<std::uint16_t>(flag * bit));
  }
}

}  // namespace

JumpLambdas MakeJumpLambdas(const RayTable& rays, double angle_deg) {
  JumpLambdas c;
  const int w = rays.x.width(), h = rays.x.height();
  c.width = w;
  c.height = h;
  c.angle_deg = angle_deg;
  const double cot = std::abs(1.0 / std::tan(angle_deg * kPi / 180.0));
  const std::ptrdiff_t pw = w + 2;
  const std::size_t padded = static_cast<std::size_t>(pw) * static_cast<std::size_t>(h + 2);
  // Pairs leaving the image get λ = +inf: d_p > d_n·inf never holds.
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (auto* t : {&c.east, &c.south, &c.south_east, &c.south_west}) t->assign(padded, kInf);
  auto ray = [&](int r, int col) {
    return Eigen::Vector3d(rays.x(r, col), rays.y(r, col), rays.z(r, col)).normalized();
  };
  auto lambda = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    // atan2-free: cos from the dot product, sin from the cross product (accurate for small γ).
    return static_cast<float>(a.dot(b) + cot * a.cross(b).norm());
  };
  for (int r = 0; r < h; ++r) {
    for (int col = 0; col < w; ++col) {
      const std::size_t i = static_cast<std::size_t>((r + 1) * pw + col + 1);
      const Eigen::Vector3d p = ray(r, col);
      if (col + 1 < w) c.east[i] = lambda(p, ray(r, col + 1));
      if (r + 1 < h) c.south[i] = lambda(p, ray(r + 1, col));
      if (r + 1 < h && col + 1 < w) c.south_east[i] = lambda(p, ray(r + 1, col + 1));
      if (r + 1 < h && col > 0) c.south_west[i] = lambda(p, ray(r + 1, col - 1));
    }
  }
  return c;
}

void JumpEdgeInto(const MetricFrame& frame, const Image<PixelFlags>& prior, const RayTable& rays,
                  const JumpEdgeOptions& o, Image<PixelFlags>& out, Image<PixelFlags>* echo) {
  thread_local LambdaCache cache;
  if (!SameRays(cache, rays, o.max_angle_deg)) {
    const std::size_t n = rays.x.size();
    cache.rays.clear();  // an allocation failure below leaves the cache recognising no table
    cache.lambdas = MakeJumpLambdas(rays, o.max_angle_deg);
    cache.rays.resize(3 * n);
    std::memcpy(cache.rays.data(), rays.x.data(), n * sizeof(float));
    std::memcpy(cache.rays.data() + n, rays.y.data(), n * sizeof(float));
    std::memcpy(cache.rays.data() + 2 * n, rays.z.data(), n * sizeof(float));
  }
  JumpEdgeInto(frame, prior, cache.lambdas, out, echo);
}

void JumpEdgeInto(const MetricFrame& frame, const Image<PixelFlags>& prior,
                  const JumpLambdas& lambdas, Image<PixelFlags>& out, Image<PixelFlags>* echo) {
  const int w = frame.width(), h = frame.height();
  const std::ptrdiff_t pw = w + 2;
  const std::size_t padded = static_cast<std::size_t>(pw) * static_cast<std::size_t>(h + 2);

  // Distances padded by one pixel; unusable pixels (and the pad) are +inf, which never makes a
  // neighbour "in front" (d_p > inf·λ is false) and marks the centre as not to be judged.
  constexpr float kInf = std::numeric_limits<float>::infinity();
  thread_local std::vector<float> dist;
  dist.assign(padded, kInf);
  const PixelFlags* prior_px = PriorOrZeros(prior, frame.radial_distance_m.size());
  for (int r = 0; r < h; ++r) {
    UsableDistances(w, frame.radial_distance_m.Row(r).data(),
                    prior_px + static_cast<std::size_t>(r) * w, dist.data() + (r + 1) * pw + 1);
  }

  const JumpLambdas& c = lambdas;
  thread_local std::vector<PixelFlags> echo_sink;  // a row nobody reads, without an echo image
  echo_sink.resize(static_cast<std::size_t>(w));
  for (int r = 0; r < h; ++r) {
    const std::ptrdiff_t base = (r + 1) * pw + 1;
    // λ of the pairs (p, neighbour): forward pairs at p, backward pairs at the neighbour.
    JumpRow(w, dist.data() + base - pw, dist.data() + base, dist.data() + base + pw,
            c.east.data() + base, c.south.data() + base, c.south_east.data() + base,
            c.south_west.data() + base, c.south.data() + base - pw, c.south_east.data() + base - pw,
            c.south_west.data() + base - pw, out.Row(r).data(),
            echo != nullptr ? echo->Row(r).data() : echo_sink.data());
  }
}

}  // namespace filters_internal

void JumpEdgeOptions::Validate() const {
  if (!(max_angle_deg > 90.0 && max_angle_deg < 180.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "jump_edge.max_angle_deg = " + std::to_string(max_angle_deg) +
                    " is outside (90, 180) degrees");
  }
}

Image<PixelFlags> JumpEdgeFilter(const MetricFrame& frame, const RayTable& rays,
                                 const JumpEdgeOptions& options) {
  options.Validate();
  filters_internal::CheckFrame(frame, "jump edge filter");
  filters_internal::CheckRays(frame, rays, "jump edge filter");
  Image<PixelFlags> out(frame.width(), frame.height());
  filters_internal::JumpEdgeInto(frame, frame.flags, rays, options, out);
  return out;
}

}  // namespace tofcam
