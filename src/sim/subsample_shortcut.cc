#include "subsample_shortcut.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <utility>

namespace tofcam::sim::internal {

namespace {

// Pointers of one row for the closed form (per pixel: the central ray's hit; per lane: in/out).
struct RowHits {
  const float *ct, *ch, *cnx, *cny, *cnz;  // per pixel: the central ray's hit
  const unsigned *cg, *cp;
  const float *dx, *dy, *dz;  // per lane: direction
  float* t;                   // per lane: out
  unsigned *g, *p;
  float *nx, *ny, *nz;
  std::uint8_t* ok;
};

// N lanes of T as a GCC/Clang vector.
template <typename T, int N>
struct Vec {
  typedef T type __attribute__((vector_size(sizeof(T) * N)));
};

// One pixel per block (S^2 does not divide the packet): plain scalar lanes.
inline void ClosedFormLanes(int width, int s2, const int* qoff, int center_s, const std::uint8_t* q,
                            const RowHits& r) {
  for (int c = 0; c < width; ++c) {
    const bool miss = r.cg[c] == RTC_INVALID_GEOMETRY_ID;
    for (int s = 0; s < s2; ++s) {
      const std::size_t i = static_cast<std::size_t>(c) * s2 + static_cast<std::size_t>(s);
      const float plane_t =
          r.ch[c] / (r.cnx[c] * r.dx[i] + r.cny[c] * r.dy[i] + r.cnz[c] * r.dz[i]);
      const bool plane_ok = miss || (plane_t > 0.f && plane_t < kInf);
      const bool is_center = s == center_s;
      r.ok[i] = static_cast<std::uint8_t>(is_center || (q[qoff[s] + c] != 0 && plane_ok));
      r.t[i] = is_center ? r.ct[c] : (miss ? kInf : plane_t);
      r.g[i] = r.cg[c];
      r.p[i] = r.cp[c];
      r.nx[i] = r.cnx[c];
      r.ny[i] = r.cny[c];
      r.nz[i] = r.cnz[c];
    }
  }
}

// GCC's auto-vectoriser leaves this loop scalar once it has unrolled the G lanes, so the lanes
// are written as GCC/Clang vector extensions: G floats per operation, the same IEEE operations
// as the scalar form in every lane.
template <int G>
[[gnu::always_inline]] inline void ClosedFormBlocks(int width, int s2, const int* qoff,
                                                    int center_s, const std::uint8_t* q,
                                                    const RowHits& r) {
  static_assert(G >= 2, "one pixel per block: ClosedFormLanes");
  using VF = typename Vec<float, G>::type;
  using VU = typename Vec<unsigned, G>::type;
  using VI = typename Vec<int, G>::type;
  // Vectors are loaded and stored with memcpy and never passed to or returned from a function
  // (that would change the ABI with the clone's instruction set).
  const VU invalid = VU{} + RTC_INVALID_GEOMETRY_ID;
  const VF inf = VF{} + kInf;
  const VF zero = VF{};
  for (int c0 = 0; c0 < width; c0 += G) {
    VF ax, ay, az, tc, hc;
    VU gc, pc;
    std::memcpy(&ax, r.cnx + c0, sizeof ax);
    std::memcpy(&ay, r.cny + c0, sizeof ay);
    std::memcpy(&az, r.cnz + c0, sizeof az);
    std::memcpy(&tc, r.ct + c0, sizeof tc);
    std::memcpy(&hc, r.ch + c0, sizeof hc);
    std::memcpy(&gc, r.cg + c0, sizeof gc);
    std::memcpy(&pc, r.cp + c0, sizeof pc);
    const VI miss = gc == invalid;
    for (int s = 0; s < s2; ++s) {
      const std::size_t i = static_cast<std::size_t>(c0) * s2 + static_cast<std::size_t>(s) * G;
      VF dx, dy, dz;
      std::memcpy(&dx, r.dx + i, sizeof dx);
      std::memcpy(&dy, r.dy + i, sizeof dy);
      std::memcpy(&dz, r.dz + i, sizeof dz);
      const VF plane_t = hc / (ax * dx + ay * dy + az * dz);
      // On the far side of the plane (never inside a quad of one triangle, but rounding at
      // grazing incidence could) or not finite: Embree decides.
      const VI plane_ok = miss | ((plane_t > zero) & (plane_t < inf));
      VI quad_ok;
      for (int k = 0; k < G; ++k) quad_ok[k] = q[qoff[s] + c0 + k] != 0 ? -1 : 0;
      const VI is_center = VI{} + (s == center_s ? -1 : 0);
      const VI ok = is_center | (quad_ok & plane_ok);
      for (int k = 0; k < G; ++k) r.ok[i + k] = static_cast<std::uint8_t>(ok[k] & 1);
      const VF t = is_center ? tc : (miss ? inf : plane_t);
      std::memcpy(r.t + i, &t, sizeof t);
      std::memcpy(r.g + i, &gc, sizeof gc);
      std::memcpy(r.p + i, &pc, sizeof pc);
      std::memcpy(r.nx + i, &ax, sizeof ax);
      std::memcpy(r.ny + i, &ay, sizeof ay);
      std::memcpy(r.nz + i, &az, sizeof az);
    }
  }
}

// The closed-form hits of one row's subsample rays (the loop the shortcut exists for), in the
// lane layout of PixelRays::Index: blocks of G pixels, each holding subsample s of its G pixels
// at lanes [s G, (s + 1) G). G is a compile-time constant so the inner loop reads the per-pixel
// arrays contiguously (no gathers) and vectorises. Subsample s's quad of pixel c is
// q[qoff[s] + c]; subsample `center_s` (odd S; -1 otherwise) is the pixel's central ray itself
// and copies its hit. `ok` says which lanes hold.
TOFCAM_SIM_LOOP void ClosedFormHits(int group, int width, int s2, const int* qoff, int center_s,
                                    const std::uint8_t* q, const RowHits& r) {
  switch (group) {
    case 16:
      ClosedFormBlocks<16>(width, s2, qoff, center_s, q, r);
      break;
    case 8:
      ClosedFormBlocks<8>(width, s2, qoff, center_s, q, r);
      break;
    case 4:
      ClosedFormBlocks<4>(width, s2, qoff, center_s, q, r);
      break;
    case 2:
      ClosedFormBlocks<2>(width, s2, qoff, center_s, q, r);
      break;
    default:
      ClosedFormLanes(width, s2, qoff, center_s, q, r);
  }
}

// Camera-frame vertices of a triangle clipped to z >= kNearZ: 0, 3 or 4 vertices.
constexpr double kNearZ = 1e-3;
int ClipNear(const std::array<Eigen::Vector3d, 3>& v, std::array<Eigen::Vector3d, 4>& out) {
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d& a = v[i];
    const Eigen::Vector3d& b = v[(i + 1) % 3];
    const bool a_in = a.z() >= kNearZ, b_in = b.z() >= kNearZ;
    if (a_in) out[n++] = a;
    if (a_in != b_in) {
      const double s = (kNearZ - a.z()) / (b.z() - a.z());
      out[n++] = a + s * (b - a);
    }
  }
  return n;
}

}  // namespace

SubsampleShortcut::SubsampleShortcut(const Scene& scene, const CameraModel& model,
                                     const PixelRays& rays)
    : width_(rays.width), height_(rays.height), s2_(rays.ss * rays.ss) {
  BuildEdgesAndMates(scene);
  const CameraIntrinsics& in = model.intrinsics;
  fx_ = in.fx_px;
  fy_ = in.fy_px;
  cx_ = in.cx_px;
  cy_ = in.cy_px;
  if (in.HasDistortion()) {
    // Bounds of the lens distortion over the image, on a grid of every 4th pixel and the border
    // rows and columns: the largest shift between a pixel and the pinhole image of its ray, and
    // the smallest ratio of distorted to pinhole distances between grid neighbours.
    std::vector<int> us, vs;
    for (int u = 0; u < width_; u += 4) us.push_back(u);
    if (us.back() != width_ - 1) us.push_back(width_ - 1);
    for (int v = 0; v < height_; v += 4) vs.push_back(v);
    if (vs.back() != height_ - 1) vs.push_back(height_ - 1);
    std::vector<Eigen::Vector2d> pin(us.size() * vs.size());
    double shift = 0, magnification = 1;
    for (std::size_t j = 0; j < vs.size(); ++j) {
      for (std::size_t i = 0; i < us.size(); ++i) {
        const Eigen::Vector2d px(us[i], vs[j]);
        const Eigen::Vector3d d = in.Unproject(px);
        Eigen::Vector2d& q = pin[j * us.size() + i];
        q = Eigen::Vector2d(fx_ * d.x() / d.z() + cx_, fy_ * d.y() / d.z() + cy_);
        shift = std::max(shift, (q - px).norm());
        if (i > 0) {
          const Eigen::Vector2d& l = pin[j * us.size() + i - 1];
          magnification = std::min(magnification, (us[i] - us[i - 1]) / (q - l).norm());
        }
        if (j > 0) {
          const Eigen::Vector2d& u = pin[(j - 1) * us.size() + i];
          magnification = std::min(magnification, (vs[j] - vs[j - 1]) / (q - u).norm());
        }
      }
    }
    distortion_shift_px_ = shift;
    // Clamped: a lens that shrinks the image 20x (an extreme fisheye) is outside this model.
    corner_width_px_ = kCornerWidthPx / std::max(magnification, 0.05);
  }
  // Subsample (i, j) at offset ((j + 1/2) / S - 1/2, (i + 1/2) / S - 1/2): offsets >= 0 take
  // the quad towards +1, the others towards -1. The padded quad row of pixel row r is then
  // r + (dv >= 0), its column c + (du >= 0).
  const int ss = rays.ss;
  group_ = rays.group;
  quad_offset_.resize(s2_);
  for (int i = 0; i < ss; ++i) {
    for (int j = 0; j < ss; ++j) {
      const bool down = (i + 0.5) / ss - 0.5 >= 0, right = (j + 0.5) / ss - 0.5 >= 0;
      quad_offset_[i * ss + j] = (down ? width_ + 1 : 0) + (right ? 1 : 0);
    }
  }
  center_sub_ = ss % 2 == 1 ? (ss / 2) * ss + ss / 2 : -1;
  const std::size_t np = static_cast<std::size_t>(width_) * height_;
  centers_.Resize(np);
  h_.assign(np, 0.f);
  quad_ok_.assign(static_cast<std::size_t>(width_ + 1) * (height_ + 1), 0);
}

void SubsampleShortcut::BuildEdgesAndMates(const Scene& scene) {
  constexpr unsigned kNone = RTC_INVALID_GEOMETRY_ID;
  std::size_t total = 0;
  object_first_.resize(scene.objects.size());
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    object_first_[o] = total;
    total += scene.objects[o].triangles.size();
  }
  mates_.assign(total, {kNone, kNone, kNone});
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const SceneObject& obj = scene.objects[o];
    const auto vertex = [&](int i) {
      return obj.vertices[static_cast<std::size_t>(i)].cast<double>();
    };
    // Triangles by undirected edge; an edge shared by exactly two triangles may join mates.
    std::map<std::pair<int, int>, std::vector<unsigned>> by_edge;
    for (std::size_t t = 0; t < obj.triangles.size(); ++t) {
      for (int k = 0; k < 3; ++k) {
        const int u = obj.triangles[t][k], v = obj.triangles[t][(k + 1) % 3];
        by_edge[{std::min(u, v), std::max(u, v)}].push_back(static_cast<unsigned>(t));
      }
    }
    for (const auto& entry : by_edge) {
      const std::pair<int, int>& edge = entry.first;
      const std::vector<unsigned>& tris = entry.second;
      edges_.push_back({static_cast<unsigned>(o), edge.first, edge.second, tris});
      if (tris.size() != 2) continue;
      const Eigen::Vector3i& t1 = obj.triangles[tris[0]];
      const Eigen::Vector3i& t2 = obj.triangles[tris[1]];
      const auto apex = [&](const Eigen::Vector3i& t) {
        for (int k = 0; k < 3; ++k) {
          if (t[k] != edge.first && t[k] != edge.second) return t[k];
        }
        return -1;
      };
      const int ic = apex(t1), id = apex(t2);
      if (ic < 0 || id < 0) continue;  // degenerate triangle
      const Eigen::Vector3d a = vertex(edge.first), b = vertex(edge.second), c = vertex(ic),
                            d = vertex(id);
      const Eigen::Vector3d n = (b - a).cross(c - a);
      const double scale = std::max({(b - a).norm(), (c - a).norm(), (d - a).norm()});
      if (!(n.norm() > 0) || !(scale > 0)) continue;
      // Coplanar: d within 1e-6 of the size (and 10 µm) from the plane of (a, b, c), so the
      // closed form's plane differs from the mate's by far less than a register count (0.11 mm
      // at 20 MHz).
      if (std::abs(n.normalized().dot(d - a)) > std::min(1e-6 * scale, 1e-5)) continue;
      // Convex union a-c-b-d: c and d on opposite sides of ab, a and b on opposite sides of cd.
      const auto side = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& q,
                            const Eigen::Vector3d& r) { return n.dot((q - p).cross(r - p)); };
      if (!(side(a, b, c) * side(a, b, d) < 0) || !(side(c, d, a) * side(c, d, b) < 0)) continue;
      const auto add = [&](unsigned t, unsigned mate) {
        for (unsigned& m : mates_[object_first_[o] + t]) {
          if (m == kNone) {
            m = mate;
            return;
          }
        }
      };
      add(tris[0], tris[1]);
      add(tris[1], tris[0]);
    }
  }
}

void SubsampleShortcut::FinishRow(int r) {
  const std::size_t row = static_cast<std::size_t>(r) * width_;
  const float* t = &centers_.t[row];
  const float *nx = &centers_.nx[row], *ny = &centers_.ny[row], *nz = &centers_.nz[row];
  const float *dx = &centers_.dx[row], *dy = &centers_.dy[row], *dz = &centers_.dz[row];
  float* h = &h_[row];
  // A miss's h is never read (its subsamples take the miss), whatever inf * garbage gives.
  for (int c = 0; c < width_; ++c) h[c] = t[c] * (nx[c] * dx[c] + ny[c] * dy[c] + nz[c] * dz[c]);
}

bool SubsampleShortcut::Mates(unsigned geom, unsigned p, unsigned q) const {
  const std::array<unsigned, 3>& m = mates_[object_first_[geom] + p];
  return m[0] == q || m[1] == q || m[2] == q;
}

void SubsampleShortcut::MarkQuads(int y0, int y1) {
  const std::size_t stride = static_cast<std::size_t>(width_) + 1;
  for (int y = std::max(y0, 0); y < std::min(y1, height_ - 1); ++y) {
    const std::size_t a = static_cast<std::size_t>(y) * width_, b = a + width_;
    std::uint8_t* q = &quad_ok_[(y + 1) * stride + 1];
    for (int x = 0; x + 1 < width_; ++x) {
      const unsigned* geom = centers_.geom.data();
      const unsigned g = geom[a + x];
      const bool same_g = geom[a + x + 1] == g && geom[b + x] == g && geom[b + x + 1] == g;
      if (!same_g || g == RTC_INVALID_GEOMETRY_ID) {
        q[x] = static_cast<std::uint8_t>(same_g);
        continue;
      }
      const unsigned* prim = centers_.prim.data();
      const unsigned p0 = prim[a + x], p1 = prim[a + x + 1], p2 = prim[b + x], p3 = prim[b + x + 1];
      if (p1 == p0 && p2 == p0 && p3 == p0) {
        q[x] = 1;
        continue;
      }
      // Two triangles of one convex planar quadrilateral (a rectangle's diagonal): the centres
      // lie in their union, which is convex, so the square between them does too.
      const unsigned other = p1 != p0 ? p1 : (p2 != p0 ? p2 : p3);
      const bool two =
          (p1 == p0 || p1 == other) && (p2 == p0 || p2 == other) && (p3 == p0 || p3 == other);
      q[x] = static_cast<std::uint8_t>(two && Mates(g, p0, other));
    }
  }
}

void SubsampleShortcut::ClearBox(double u0, double u1, double v0, double v1) {
  if (!(u0 <= u1) || !(v0 <= v1)) return;  // empty or not finite
  // Quad (y, x) spans [x, x + 1] x [y, y + 1] in pixel coordinates; padded indices + 1. Clamped
  // in double first: a point near the camera plane can project far beyond int's range.
  const double grow = distortion_shift_px_ + kCornerMarginPx;
  const auto index = [](double a, int limit) {
    return static_cast<int>(std::clamp(a, -2.0, static_cast<double>(limit) + 1));
  };
  const int x0 = std::clamp(index(std::ceil(u0 - grow), width_) - 1, -1, width_ - 1);
  const int x1 = std::clamp(index(std::floor(u1 + grow), width_), -1, width_ - 1);
  const int y0 = std::clamp(index(std::ceil(v0 - grow), height_) - 1, -1, height_ - 1);
  const int y1 = std::clamp(index(std::floor(v1 + grow), height_), -1, height_ - 1);
  if (x0 > x1) return;
  const std::size_t stride = static_cast<std::size_t>(width_) + 1;
  for (int y = y0; y <= y1; ++y) {
    std::fill_n(quad_ok_.data() + (y + 1) * stride + x0 + 1, x1 - x0 + 1, 0);
  }
}

void SubsampleShortcut::ClearZones(const Scene& scene, const SceneGeometry& geometry,
                                   const Eigen::Isometry3d& camera_pose) {
  const Eigen::Isometry3d to_camera = camera_pose.inverse();
  const double grow = distortion_shift_px_ + kCornerMarginPx;
  const auto clear = [&](double u0, double u1, double v0, double v1) { ClearBox(u0, u1, v0, v1); };
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const float* w = geometry.WorldVertices(o);
    for (const Eigen::Vector3i& tri : scene.objects[o].triangles) {
      std::array<Eigen::Vector3d, 3> v;
      for (int k = 0; k < 3; ++k) {
        const float* p = w + 3 * static_cast<std::size_t>(tri[k]);
        v[k] = to_camera * Eigen::Vector3d(p[0], p[1], p[2]);
      }
      std::array<Eigen::Vector3d, 4> clipped;
      const int n = ClipNear(v, clipped);
      if (n < 3) continue;  // behind the camera: no ray reaches it
      std::array<Eigen::Vector2d, 4> uv;
      double u0 = kInf, u1 = -kInf, v0 = kInf, v1 = -kInf;
      for (int k = 0; k < n; ++k) {
        uv[k] = Eigen::Vector2d(fx_ * clipped[k].x() / clipped[k].z() + cx_,
                                fy_ * clipped[k].y() / clipped[k].z() + cy_);
        u0 = std::min(u0, uv[k].x());
        u1 = std::max(u1, uv[k].x());
        v0 = std::min(v0, uv[k].y());
        v1 = std::max(v1, uv[k].y());
      }
      if (u1 < -1 - grow || u0 > width_ + grow || v1 < -1 - grow || v0 > height_ + grow) {
        continue;  // off the image: no pixel's quad reaches it
      }
      // Each corner's zone: the part of the polygon within d of the corner along both edges,
      // where d makes the chord between the two edges corner_width_px_ long. Beyond it the
      // polygon is at least that wide near this corner.
      for (int k = 0; k < n; ++k) {
        const Eigen::Vector2d& c = uv[k];
        const Eigen::Vector2d e1 = uv[(k + 1) % n] - c, e2 = uv[(k + n - 1) % n] - c;
        const double l1 = e1.norm(), l2 = e2.norm();
        if (!(l1 > 0) || !(l2 > 0)) {
          clear(c.x(), c.x(), c.y(), c.y());
          continue;
        }
        // Chord at distance d along both edges: 2 d sin(alpha / 2), sin(alpha / 2) from the
        // cosine of the corner's angle.
        const double cos_a = std::clamp(e1.dot(e2) / (l1 * l2), -1.0, 1.0);
        const double half_sin = std::sqrt((1 - cos_a) / 2);
        const double d = half_sin > 0 ? corner_width_px_ / (2 * half_sin) : kInf;
        const Eigen::Vector2d a = c + e1 * std::min(1.0, d / l1);
        const Eigen::Vector2d b = c + e2 * std::min(1.0, d / l2);
        clear(std::min({c.x(), a.x(), b.x()}), std::max({c.x(), a.x(), b.x()}),
              std::min({c.y(), a.y(), b.y()}), std::max({c.y(), a.y(), b.y()}));
      }
    }
  }
  // Where surfaces pass through each other, a visible region can also end on the segment where
  // two triangles meet, away from every vertex; the part of such a region narrower than
  // corner_width_px_ lies within that width of the segment, so a band that wide along every
  // meeting segment is cleared (clipped to the camera's side of z = kNearZ and to the image).
  FindCrossings(scene, geometry);
  if (crossings_overflow_) {
    std::fill(quad_ok_.begin(), quad_ok_.end(), 0);  // not every crossing found: cast everything
    return;
  }
  const double band = corner_width_px_;
  const double lo[2] = {-grow - band - 1, -grow - band - 1};
  const double hi[2] = {width_ + grow + band, height_ + grow + band};
  for (const Segment& seg : crossings_) {
    Eigen::Vector3d a = to_camera * seg.a, b = to_camera * seg.b;
    if (a.z() < kNearZ && b.z() < kNearZ) continue;  // behind the camera
    if (a.z() < kNearZ) a += (kNearZ - a.z()) / (b.z() - a.z()) * (b - a);
    if (b.z() < kNearZ) b += (kNearZ - b.z()) / (a.z() - b.z()) * (a - b);
    const Eigen::Vector2d pa(fx_ * a.x() / a.z() + cx_, fy_ * a.y() / a.z() + cy_);
    const Eigen::Vector2d pb(fx_ * b.x() / b.z() + cx_, fy_ * b.y() / b.z() + cy_);
    // The image segment pa + s (pb - pa), s in [0, 1], clipped to the image with margin.
    const Eigen::Vector2d d = pb - pa;
    double s0 = 0, s1 = 1;
    for (int k = 0; k < 2; ++k) {
      if (d[k] == 0) {
        if (pa[k] < lo[k] || pa[k] > hi[k]) s1 = -1;
        continue;
      }
      const double t0 = (lo[k] - pa[k]) / d[k], t1 = (hi[k] - pa[k]) / d[k];
      s0 = std::max(s0, std::min(t0, t1));
      s1 = std::min(s1, std::max(t0, t1));
    }
    if (!(s0 <= s1)) continue;  // off the image (or not finite)
    // Pieces of at most 2 px, each piece's box grown by the band.
    const double step = 2 / std::max(d.norm(), 2.0);
    for (double s = s0; s <= s1; s += step) {
      const Eigen::Vector2d q0 = pa + s * d, q1 = pa + std::min(s + step, s1) * d;
      clear(std::min(q0.x(), q1.x()) - band, std::max(q0.x(), q1.x()) + band,
            std::min(q0.y(), q1.y()) - band, std::max(q0.y(), q1.y()) + band);
    }
  }
}

namespace {

// The segment in which triangles p and q meet (world frame); false when they do not meet in
// one (apart, touching at a point, or coplanar).
bool MeetingSegment(const std::array<Eigen::Vector3d, 3>& p,
                    const std::array<Eigen::Vector3d, 3>& q, Eigen::Vector3d& a,
                    Eigen::Vector3d& b) {
  const Eigen::Vector3d np = (p[1] - p[0]).cross(p[2] - p[0]);
  const Eigen::Vector3d nq = (q[1] - q[0]).cross(q[2] - q[0]);
  const Eigen::Vector3d dir = np.cross(nq);
  if (!(dir.squaredNorm() > 1e-24 * np.squaredNorm() * nq.squaredNorm())) return false;
  // Where the edges of triangle t cross the plane (n, n . o): an interval along dir.
  const auto interval = [&](const std::array<Eigen::Vector3d, 3>& t, const Eigen::Vector3d& n,
                            const Eigen::Vector3d& o, Eigen::Vector3d& lo, Eigen::Vector3d& hi) {
    bool any = false;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& u = t[k];
      const Eigen::Vector3d& v = t[(k + 1) % 3];
      const double du = n.dot(u - o), dv = n.dot(v - o);
      if ((du > 0 && dv > 0) || (du < 0 && dv < 0) || du == dv) continue;
      const Eigen::Vector3d x = u + du / (du - dv) * (v - u);
      if (!any || dir.dot(x) < dir.dot(lo)) lo = x;
      if (!any || dir.dot(x) > dir.dot(hi)) hi = x;
      any = true;
    }
    return any;
  };
  Eigen::Vector3d p_lo, p_hi, q_lo, q_hi;
  if (!interval(p, nq, q[0], p_lo, p_hi) || !interval(q, np, p[0], q_lo, q_hi)) return false;
  a = dir.dot(p_lo) > dir.dot(q_lo) ? p_lo : q_lo;
  b = dir.dot(p_hi) < dir.dot(q_hi) ? p_hi : q_hi;
  return dir.dot(a) <= dir.dot(b);
}

}  // namespace

void SubsampleShortcut::FindCrossings(const Scene& scene, const SceneGeometry& geometry) {
  if (crossings_found_ && crossings_version_ == geometry.Version()) return;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  const auto world = [&](unsigned o, int i) {
    const float* w = geometry.WorldVertices(o) + 3 * static_cast<std::size_t>(i);
    return Eigen::Vector3d(w[0], w[1], w[2]);
  };
  const auto corners = [&](unsigned o, unsigned t) {
    const Eigen::Vector3i& tri = scene.objects[o].triangles[t];
    return std::array<Eigen::Vector3d, 3>{world(o, tri[0]), world(o, tri[1]), world(o, tri[2])};
  };
  // Every triangle an edge passes through, ends excluded, of the objects `want`s (static ones,
  // moving ones or any): the segment where it meets each of the edge's triangles, into `out`.
  // Triangles touching the edge's ends are its neighbours, not crossings (compared by position:
  // a box's faces have their own vertices).
  enum class Want { kStatic, kMoving, kAny };
  const auto cast_edge = [&](const Edge& edge, Want want, std::vector<Segment>& out) {
    const Eigen::Vector3d a = world(edge.object, edge.a), b = world(edge.object, edge.b);
    const double length = (b - a).norm();
    if (!(length > 0)) return;
    const Eigen::Vector3d dir = (b - a) / length;
    const double end_tolerance = 1e-6 * length;
    float t_near = static_cast<float>(1e-5 * length);
    for (int k = 0;; ++k) {
      if (k == kMaxCrossingsPerEdge) {
        crossings_overflow_ = true;
        return;
      }
      RTCRayHit rh;
      SetRay(rh, a.cast<float>(), dir.cast<float>(), t_near);
      rh.ray.tfar = static_cast<float>(length * (1 - 1e-5));
      rtcIntersect1(geometry.Handle(), &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return;
      t_near = std::nextafter(rh.ray.tfar, kInf);
      const unsigned g = rh.hit.geomID, prim = rh.hit.primID;
      if (want != Want::kAny && geometry.Dynamic(g) != (want == Want::kMoving)) continue;
      const std::array<Eigen::Vector3d, 3> hit = corners(g, prim);
      bool neighbour = false;
      for (const Eigen::Vector3d& v : hit) {
        neighbour = neighbour || (v - a).norm() <= end_tolerance || (v - b).norm() <= end_tolerance;
      }
      if (neighbour) continue;
      for (const unsigned t : edge.triangles) {
        Segment seg;
        if (t != kNoTriangle && MeetingSegment(corners(edge.object, t), hit, seg.a, seg.b)) {
          out.push_back(seg);
        }
      }
    }
  };
  crossings_overflow_ = false;
  if (!crossings_found_) {
    // Static edges through static objects never change: found once.
    for (const Edge& edge : edges_) {
      if (!geometry.Dynamic(edge.object)) cast_edge(edge, Want::kStatic, static_crossings_);
    }
    static_overflow_ = crossings_overflow_;
  }
  crossings_overflow_ = static_overflow_;
  crossings_ = static_crossings_;
  // Moving objects, at their current pose: every edge of one, and static edges only where they
  // reach a moving object's bounding box.
  std::vector<Eigen::AlignedBox3d> moving_boxes;
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    if (!geometry.Dynamic(o)) continue;
    Eigen::AlignedBox3d box;
    for (std::size_t i = 0; i < scene.objects[o].vertices.size(); ++i) {
      box.extend(world(static_cast<unsigned>(o), static_cast<int>(i)));
    }
    moving_boxes.push_back(box);
  }
  if (!moving_boxes.empty()) {
    for (const Edge& edge : edges_) {
      if (geometry.Dynamic(edge.object)) {
        cast_edge(edge, Want::kAny, crossings_);
        continue;
      }
      Eigen::AlignedBox3d span(world(edge.object, edge.a));
      span.extend(world(edge.object, edge.b));
      bool near_moving = false;
      for (const Eigen::AlignedBox3d& box : moving_boxes) {
        near_moving = near_moving || box.intersects(span);
      }
      if (near_moving) cast_edge(edge, Want::kMoving, crossings_);
    }
  }
  crossings_version_ = geometry.Version();
  crossings_found_ = true;
}

std::size_t SubsampleShortcut::Fill(int r, RayBatch& b, std::vector<unsigned>& rest_at,
                                    std::vector<std::uint8_t>& ok) const {
  const std::size_t ns = static_cast<std::size_t>(width_) * s2_;
  const std::size_t row = static_cast<std::size_t>(r) * width_;
  ok.resize(ns);
  rest_at.resize(ns);
  RowHits h;
  h.ct = &centers_.t[row];
  h.ch = &h_[row];
  h.cnx = &centers_.nx[row];
  h.cny = &centers_.ny[row];
  h.cnz = &centers_.nz[row];
  h.cg = &centers_.geom[row];
  h.cp = &centers_.prim[row];
  h.dx = b.dx.data();
  h.dy = b.dy.data();
  h.dz = b.dz.data();
  h.t = b.t.data();
  h.g = b.geom.data();
  h.p = b.prim.data();
  h.nx = b.nx.data();
  h.ny = b.ny.data();
  h.nz = b.nz.data();
  h.ok = ok.data();
  ClosedFormHits(group_, width_, s2_, quad_offset_.data(), center_sub_,
                 &quad_ok_[static_cast<std::size_t>(r) * (width_ + 1)], h);
  std::size_t m = 0;
  for (std::size_t i = 0; i < ns; ++i) {
    if (!ok[i]) rest_at[m++] = static_cast<unsigned>(i);
  }
  return m;
}

}  // namespace tofcam::sim::internal
