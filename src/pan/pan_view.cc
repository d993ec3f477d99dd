#include "tofcam/pan/pan_view.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "../core/fast_atan2.h"
#include "../filters/hot_loop.h"
#include "tofcam/core/error.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr double kDeg = kPi / 180.0;

using internal::FastAtan2;
using internal::Sel;

// Geometry of the panorama for the per-point loop.
struct Strip {
  double forward[3], left[3], up[3];
  double max_azimuth_rad, max_tan_elevation, inv_resolution;
  int cols, rows;
};

// Moves n camera-frame points into the base frame (r * p + t, NaN stays NaN) and marks the valid
// ones (no reject flag, finite coordinates), as TransformPointCloud and PointCloud::IsValid do.
[[gnu::noinline]] TOFCAM_HOT_LOOP void TransformPoints(
    std::size_t n, const float* __restrict r, const float* __restrict t, const float* __restrict x,
    const float* __restrict y, const float* __restrict z, const std::uint16_t* __restrict flags,
    float* __restrict bx, float* __restrict by, float* __restrict bz,
    std::uint8_t* __restrict valid) {
  for (std::size_t i = 0; i < n; ++i) {
    const float px = r[0] * x[i] + r[3] * y[i] + r[6] * z[i] + t[0];
    const float py = r[1] * x[i] + r[4] * y[i] + r[7] * z[i] + t[1];
    const float pz = r[2] * x[i] + r[5] * y[i] + r[8] * z[i] + t[2];
    bx[i] = px;
    by[i] = py;
    bz[i] = pz;
    // Finite: |v| <= max (false for inf and NaN).
    const bool finite = (std::abs(px) <= std::numeric_limits<float>::max()) &
                        (std::abs(py) <= std::numeric_limits<float>::max()) &
                        (std::abs(pz) <= std::numeric_limits<float>::max());
    valid[i] = static_cast<std::uint8_t>(((flags[i] & kRejectMask) == 0) & finite);
  }
}

// Per base-frame point: its panorama cell (row * cols + col) or -1 when it is invalid, on the
// axis or outside the strip, and its distance from the rotation centre.
[[gnu::noinline]] TOFCAM_HOT_LOOP void CellsOfPoints(
    std::size_t n, const Strip& s, const float* __restrict bx, const float* __restrict by,
    const float* __restrict bz, const std::uint8_t* __restrict valid, std::int32_t* __restrict cell,
    float* __restrict range) {
  const double f0 = s.forward[0], f1 = s.forward[1], f2 = s.forward[2];
  const double l0 = s.left[0], l1 = s.left[1], l2 = s.left[2];
  const double u0 = s.up[0], u1 = s.up[1], u2 = s.up[2];
  const double cols = s.cols, rows = s.rows;
  const double max_az = s.max_azimuth_rad, max_tan = s.max_tan_elevation;
  const double inv_res = s.inv_resolution;
  const std::int32_t stride = s.cols;
  for (std::size_t i = 0; i < n; ++i) {
    const double px = bx[i], py = by[i], pz = bz[i];
    const double pf = px * f0 + py * f1 + pz * f2;
    const double pl = px * l0 + py * l1 + pz * l2;
    const double pu = px * u0 + py * u1 + pz * u2;
    const double rho = std::sqrt(pf * pf + pl * pl);
    const bool off_axis = rho >= 1e-6;  // on the axis: no azimuth
    const double az = FastAtan2(pl, pf);
    const double col = (max_az - az) * inv_res;
    const double row = (max_tan - pu / std::max(rho, 1e-6)) * inv_res;
    const bool in =
        (valid[i] != 0) & off_axis & (col >= 0.0) & (col < cols) & (row >= 0.0) & (row < rows);
    const auto c = static_cast<std::int32_t>(Sel(in, col, 0.0));
    const auto r = static_cast<std::int32_t>(Sel(in, row, 0.0));
    cell[i] = (r * stride + c + 1) * static_cast<std::int32_t>(in) - 1;  // -1 when out
    range[i] = static_cast<float>(std::sqrt(px * px + py * py + pz * pz));
  }
}

// Reused per-frame buffers of MakePanView.
struct Scratch {
  PointCloud camera;
  std::vector<float> bx, by, bz, range;
  std::vector<std::uint8_t> valid;
  std::vector<std::int32_t> cell;
  void Resize(std::size_t n) {
    for (auto* v : {&bx, &by, &bz, &range}) v->resize(n);
    valid.resize(n);
    cell.resize(n);
  }
};

// Appends points [0, n) of one frame at `n_out` of the merged cloud (its arrays sized for every
// point of every frame): each point is written, the end advances past the kept ones (valid, or
// all with keep_all = 1). Returns the new end. Separate, with restrict pointers, so the compiler
// keeps every pointer in a register (through the vectors it reloads them after each store).
std::size_t AppendPoints(std::size_t n, std::uint8_t keep_all, const float* __restrict bx,
                         const float* __restrict by, const float* __restrict bz,
                         const float* __restrict a, const float* __restrict in,
                         const float* __restrict dl, const PixelFlags* __restrict f,
                         const std::uint8_t* __restrict valid, std::size_t n_out, PointCloud& out) {
  float* __restrict ox = out.x.data();
  float* __restrict oy = out.y.data();
  float* __restrict oz = out.z.data();
  float* __restrict oa = out.amplitude.data();
  float* __restrict oi = out.intensity.data();
  float* __restrict od = out.delta_l_m.data();
  PixelFlags* __restrict of = out.flags.data();
  for (std::size_t i = 0; i < n; ++i) {
    ox[n_out] = bx[i];
    oy[n_out] = by[i];
    oz[n_out] = bz[i];
    oa[n_out] = a[i];
    oi[n_out] = in[i];
    od[n_out] = dl[i];
    of[n_out] = f[i];
    n_out += static_cast<std::size_t>(valid[i] | keep_all);
  }
  return n_out;
}

// `nearer ? a : b` on the bits, as integer masks: GCC compiles the float select below into
// compare-and-branch, which mispredicted about every other point.
[[gnu::always_inline]] inline float Pick(std::uint32_t mask, float a, float b) {
  return std::bit_cast<float>((std::bit_cast<std::uint32_t>(a) & mask) |
                              (std::bit_cast<std::uint32_t>(b) & ~mask));
}

// Splat: the point nearest to the rotation centre wins its cell (the first of equals). Two
// forms with the same result. Coarse pixels (fewer points than cells, e.g. SR-2 frames on the
// default 0.5° strip): every point rewrites its cell branch-free, since neighbouring points
// compete for different cells in an order no branch predictor learns (points outside the strip,
// cell -1, rewrite cell 0 with its own values). Fine pixels (several points per cell): runs of
// points hit one cell and rarely win it, so a branch predicts well, while rewriting the cell
// every time would chain each point on the previous one's store (10 % slower at 1 MP).
void SplatBranchy(std::size_t n, const std::int32_t* __restrict cell, const float* __restrict range,
                  const float* __restrict d, const float* __restrict a, float* __restrict zb,
                  float* __restrict pano_d, float* __restrict pano_a) {
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t c = cell[i];
    if (c >= 0 && range[i] < zb[c]) {
      zb[c] = range[i];
      pano_d[c] = d[i];
      pano_a[c] = a[i];
    }
  }
}

void Splat(std::size_t n, const std::int32_t* __restrict cell, const float* __restrict range,
           const float* __restrict d, const float* __restrict a, float* __restrict zb,
           float* __restrict pano_d, float* __restrict pano_a) {
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t inside = -static_cast<std::int32_t>(cell[i] >= 0);
    const std::int32_t c = cell[i] & inside;
    const std::uint32_t nearer =
        static_cast<std::uint32_t>(inside & -static_cast<std::int32_t>(range[i] < zb[c]));
    zb[c] = Pick(nearer, range[i], zb[c]);
    pano_d[c] = Pick(nearer, d[i], pano_d[c]);
    pano_a[c] = Pick(nearer, a[i], pano_a[c]);
  }
}

}  // namespace

void PanViewOptions::Validate() const {
  const Eigen::Vector3d a = pan_unit.axis;
  if (!a.allFinite() || a.norm() < 1e-9 || !pan_unit.camera_offset_m.allFinite()) {
    throw Error(ErrorCode::kInvalidArgument, "pan view: pan_unit axis must be finite and non-zero");
  }
  // The azimuth origin is the base z axis projected perpendicular to the axis.
  if (std::abs(a.normalized().z()) > 0.999) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: pan_unit axis must not be (nearly) the optical axis z");
  }
  if (!(resolution_deg >= 0.01 && resolution_deg <= 10.0)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "pan view: resolution_deg = " + std::to_string(resolution_deg) + " is outside [0.01, 10]");
  }
  if (!(min_azimuth_deg >= -180.0 && max_azimuth_deg <= 180.0 &&
        max_azimuth_deg > min_azimuth_deg)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: azimuth range [" + std::to_string(min_azimuth_deg) + ", " +
                    std::to_string(max_azimuth_deg) + "] deg must be non-empty within ±180");
  }
  if (!(max_elevation_deg > 0.0 && max_elevation_deg <= 80.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "pan view: max_elevation_deg = " + std::to_string(max_elevation_deg) +
                    " is outside (0, 80]");
  }
  color.Validate();
}

double PanView::RowElevationRad(int row) const noexcept {
  return std::atan(max_tan_elevation - (row + 0.5) * resolution_rad);
}

PointCloud TransformPointCloud(const PointCloud& cloud, const Eigen::Isometry3d& t) {
  cloud.Validate();
  PointCloud out = cloud;
  const Eigen::Matrix3f r = t.linear().cast<float>();
  const Eigen::Vector3f o = t.translation().cast<float>();
  for (std::size_t i = 0; i < out.size(); ++i) {
    const Eigen::Vector3f p = r * Eigen::Vector3f(cloud.x[i], cloud.y[i], cloud.z[i]) + o;
    out.x[i] = p.x();
    out.y[i] = p.y();
    out.z[i] = p.z();
  }
  return out;
}

PanView MakePanView(std::span<const MetricFrame> frames, const RayTable& rays,
                    const PanViewOptions& o) {
  PanView view;
  MakePanViewInto(frames, rays, o, view);
  return view;
}

void MakePanViewInto(std::span<const MetricFrame> frames, const RayTable& rays,
                     const PanViewOptions& o, PanView& view) {
  o.Validate();
  if (frames.empty()) throw Error(ErrorCode::kInvalidArgument, "pan view: no frames");
  view.resolution_rad = o.resolution_deg * kDeg;
  view.max_azimuth_rad = o.max_azimuth_deg * kDeg;
  view.max_tan_elevation = std::tan(o.max_elevation_deg * kDeg);
  const int cols = static_cast<int>(
      std::ceil((o.max_azimuth_deg - o.min_azimuth_deg) / o.resolution_deg - 1e-9));
  const int rows =
      static_cast<int>(std::ceil(2.0 * view.max_tan_elevation / view.resolution_rad - 1e-9));
  // Reused storage: the previous view's images and a per-thread z-buffer (a fresh 100 KB+ image
  // per call is a fresh mapping from the kernel, page-faulted in on every call).
  auto reset = [cols, rows](Image<float>& image, float value) {
    if (image.SameSize(cols, rows)) {
      std::fill(image.data(), image.data() + image.size(), value);
    } else {
      image = Image<float>(cols, rows, value);
    }
  };
  reset(view.panorama_distance_m, kNan);
  reset(view.panorama_amplitude, kNan);
  thread_local Image<float> zbuffer;
  reset(zbuffer, std::numeric_limits<float>::infinity());
  view.frame_offsets.clear();
  view.camera_to_base.clear();

  const Eigen::Vector3d up = o.pan_unit.axis.normalized();
  const Eigen::Vector3d z(0.0, 0.0, 1.0);
  const Eigen::Vector3d forward = (z - z.dot(up) * up).normalized();
  const Eigen::Vector3d left = up.cross(forward);
  Strip strip{};
  for (int i = 0; i < 3; ++i) {
    strip.forward[i] = forward[i];
    strip.left[i] = left[i];
    strip.up[i] = up[i];
  }
  strip.max_azimuth_rad = view.max_azimuth_rad;
  strip.max_tan_elevation = view.max_tan_elevation;
  strip.inv_resolution = 1.0 / view.resolution_rad;
  strip.cols = cols;
  strip.rows = rows;
  view.cloud.height = 1;
  view.frame_offsets.push_back(0);

  // The merged cloud is written in place (at most every point of every frame), then trimmed.
  std::size_t capacity = 0;
  for (const MetricFrame& frame : frames) capacity += frame.radial_distance_m.size();
  PointCloud& out = view.cloud;
  for (auto* v : {&out.x, &out.y, &out.z, &out.amplitude, &out.intensity, &out.delta_l_m}) {
    v->resize(capacity);
  }
  out.flags.resize(capacity);
  std::size_t n_out = 0;
  thread_local Scratch sc;
  float* zb = zbuffer.data();
  float* pano_d = view.panorama_distance_m.data();
  float* pano_a = view.panorama_amplitude.data();

  for (std::size_t k = 0; k < frames.size(); ++k) {
    const MetricFrame& frame = frames[k];
    MakePointCloudInto(frame, rays, sc.camera, o.cloud);
    const Eigen::Isometry3d pose = o.pan_unit.CameraToBase(frame.info.pan_angle_rad);
    if (!std::isfinite(frame.info.pan_angle_rad)) {
      throw Error(ErrorCode::kInvalidArgument,
                  "pan view: frame " + std::to_string(k) + " has a non-finite pan angle");
    }
    view.camera_to_base.push_back(pose);
    const Eigen::Matrix3f rot = pose.linear().cast<float>();  // column-major
    const Eigen::Vector3f tr = pose.translation().cast<float>();
    const PointCloud& cam = sc.camera;
    const std::size_t n = cam.size();
    sc.Resize(n);
    static_assert(sizeof(PixelFlags) == sizeof(std::uint16_t));
    TransformPoints(n, rot.data(), tr.data(), cam.x.data(), cam.y.data(), cam.z.data(),
                    reinterpret_cast<const std::uint16_t*>(cam.flags.data()), sc.bx.data(),
                    sc.by.data(), sc.bz.data(), sc.valid.data());
    // Append (the valid points, or all) in input order, branch-free: every point is written at
    // the end and the end advances only past the kept ones (the capacity has room for all).
    n_out = AppendPoints(n, o.only_valid ? 0 : 1, sc.bx.data(), sc.by.data(), sc.bz.data(),
                         cam.amplitude.data(), cam.intensity.data(), cam.delta_l_m.data(),
                         cam.flags.data(), sc.valid.data(), n_out, out);
    view.frame_offsets.push_back(n_out);

    // Panorama cells, then the z-buffered splat.
    CellsOfPoints(n, strip, sc.bx.data(), sc.by.data(), sc.bz.data(), sc.valid.data(),
                  sc.cell.data(), sc.range.data());
    const bool coarse = n < zbuffer.size();
    (coarse ? Splat : SplatBranchy)(n, sc.cell.data(), sc.range.data(),
                                    frame.radial_distance_m.data(), cam.amplitude.data(), zb,
                                    pano_d, pano_a);
  }
  for (auto* v : {&out.x, &out.y, &out.z, &out.amplitude, &out.intensity, &out.delta_l_m}) {
    v->resize(n_out);
  }
  out.flags.resize(n_out);
  view.cloud.width = static_cast<int>(view.cloud.x.size());
  if (view.cloud.width == 0) view.cloud.height = 0;

  const double f_hz = frames[0].info.modulation_frequency_hz;
  const double far_default = (std::isfinite(f_hz) && f_hz > 0.0) ? UnambiguousRangeM(f_hz) : 0.0;
  FalseColorImageInto(view.panorama_distance_m, Image<PixelFlags>(), view.panorama_amplitude,
                      far_default, o.color, view.panorama);
}

}  // namespace tofcam
