#pragma once
// Simulator stage 1, optional (SimulatorOptions::planar_shortcut; internal to tofcam::sim,
// docs/simulator.md "The planar shortcut"): subsample rays cast in closed form on the triangle the
// pixel centres around them hit, so Embree casts one central ray per pixel plus the subsamples
// near edges, triangle corners and misses.
//
// A subsample ray of pixel (r, c) at offset (du, dv) in (-1/2, 1/2)^2 lies between four pixel
// centres: (r, c), (r, c + sign du), (r + sign dv, c), (r + sign dv, c + sign du), the "quad" of
// that subsample. When those four central rays hit the same triangle (or two coplanar triangles
// of one object that form a convex quadrilateral, such as a rectangle's two halves), the quad's
// square in the image lies inside that triangle's image (convexity), and the subsample ray is
// taken to hit its plane too (t = n . (hit - org) / n . d, n and hit of the pixel's own central
// ray); otherwise Embree casts it. Something else can be seen inside such a quad only through a
// part of another triangle that covers none of the four centres, and a triangle that covers part
// of a square but none of its corners does so near one of its own corners, where it is narrower
// than the square (a straight edge across the square always leaves a corner on each side). So
// every quad near a triangle's corner is cast too: the zone within which the triangle's image is
// narrower than kCornerWidthPx (a sharp corner's zone runs far along its edges; a thin triangle
// is all zone). That argument assumes that surfaces do not pass through each other: where they
// do, a visible region can also be bounded by the segment in which two triangles meet, and end
// away from every vertex; so every quad within corner_width_px_ of such a segment is cast too
// (the segments come from the triangles that Embree finds along every edge, found again whenever
// objects move; more than kMaxCrossingsPerEdge crossings on one edge cast the whole frame). Frames
// then
// differ from the exact ones (every subsample cast) by float rounding: Embree's t against the
// closed form's, a few units in the last place. The zones use the pinhole part of the camera
// model, grown by the lens distortion's largest displacement (and kCornerMarginPx) and widened by
// its smallest magnification. Left out: coincident surfaces (two coplanar triangles overlapping,
// which Embree itself resolves arbitrarily) and parts of a triangle closer than 1 mm to the
// camera plane.

#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "geometry.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {

/// Width of a triangle corner's image (px, the chord between its two edges, divided by the lens
/// distortion's smallest magnification along the image axes) below which its quads are cast. A
/// triangle that covers part of a unit square but none of its corners is, there, no wider than
/// the square's diagonal (sqrt 2 = 1.41 px); 2.5 px leaves a margin (also for the diagonal
/// magnification, which the axis ratios do not sample).
inline constexpr double kCornerWidthPx = 2.5;
/// Margin around each corner zone, px, on top of the lens distortion's largest displacement.
inline constexpr double kCornerMarginPx = 0.5;

class SubsampleShortcut {
 public:
  /// Layout of the rays' subsamples, the lens's distortion bounds and the scene's coplanar
  /// triangle pairs; allocates per-pixel hits.
  SubsampleShortcut(const Scene& scene, const CameraModel& model, const PixelRays& rays);

  /// Every pixel's central ray (row-major): the caller sets the directions of a row and traces
  /// them in place (Embree), then calls FinishRow. Distances are the truth distances.
  [[nodiscard]] RayBatch& Centers() noexcept { return centers_; }
  /// Row r's plane offsets, once its central rays are traced. Rows may run in parallel.
  void FinishRow(int r);

  /// Quads with top-left centre rows [y0, y1): 1 where the four centres hit the same triangle,
  /// or two triangles of one convex planar quadrilateral (mates), or all miss. Needs every row's
  /// centres stored. Rows may run in parallel.
  void MarkQuads(int y0, int y1);
  /// Clears the quads in every triangle corner's zone and along every segment where two
  /// triangles pass through each other (serial; after MarkQuads), the triangles at their current
  /// pose seen from `camera_pose` (camera to world).
  void ClearZones(const Scene& scene, const SceneGeometry& geometry,
                  const Eigen::Isometry3d& camera_pose);

  /// Closed-form hits of row r's subsample rays in b (directions set, ns = width * S^2 rays):
  /// writes t, geom, prim and the normal of every lane (valid where the shortcut holds, `ok`
  /// set), the positions of the others to `rest_at` (resized to ns), and returns how many those
  /// are; the caller has Embree cast them and overwrite their lanes.
  std::size_t Fill(int r, RayBatch& b, std::vector<unsigned>& rest_at,
                   std::vector<std::uint8_t>& ok) const;

 private:
  int width_ = 0, height_ = 0, s2_ = 1;
  double fx_ = 1, fy_ = 1, cx_ = 0, cy_ = 0;  // pinhole part of the intrinsics
  double distortion_shift_px_ = 0;            // largest |distorted - pinhole| in the image
  double corner_width_px_ = kCornerWidthPx;   // kCornerWidthPx / the smallest magnification
  int group_ = 1;                             // PixelRays::group
  std::vector<int> quad_offset_;  // per subsample: its quad's padded index - pixel's column
  int center_sub_ = -1;           // odd S: the subsample that is the central ray
  // Per pixel: the central ray and its hit, and the hit plane's offset h = n . (hit - org).
  RayBatch centers_;
  std::vector<float> h_;
  // (height + 1) x (width + 1) quads, padded: entry (y + 1, x + 1) is the quad of centres
  // (y, x) .. (y + 1, x + 1), y in [-1, height - 1], x in [-1, width - 1]; border quads stay 0.
  std::vector<std::uint8_t> quad_ok_;
  // Per triangle (object_first_[object] + prim): up to three edge-sharing triangles of the same
  // object that are coplanar with it and form a convex quadrilateral with it.
  std::vector<std::size_t> object_first_;
  std::vector<std::array<unsigned, 3>> mates_;

  // Every undirected edge of every object with its triangles.
  static constexpr unsigned kNoTriangle = ~0u;
  struct Edge {
    unsigned object;
    int a, b;                         // vertex indices
    std::vector<unsigned> triangles;  // one (a border), two, or more (non-manifold)
  };
  std::vector<Edge> edges_;
  // Segments (world frame) in which two triangles meet, where surfaces pass through each other.
  struct Segment {
    Eigen::Vector3d a, b;
  };
  std::vector<Segment> crossings_;         // at the current pose
  std::vector<Segment> static_crossings_;  // between objects that never move
  std::uint64_t crossings_version_ = 0;    // SceneGeometry::Version() they were found at
  bool crossings_found_ = false;
  // More crossings on one edge than kMaxCrossingsPerEdge: not all were found, so the frame is
  // cast without the shortcut.
  bool crossings_overflow_ = false, static_overflow_ = false;
  static constexpr int kMaxCrossingsPerEdge = 256;

  // edges_ and mates_ from the scene's meshes (object frames: both survive rigid motion).
  void BuildEdgesAndMates(const Scene& scene);
  void FindCrossings(const Scene& scene, const SceneGeometry& geometry);
  void ClearBox(double u0, double u1, double v0, double v1);
  [[nodiscard]] bool Mates(unsigned geom, unsigned p, unsigned q) const;
};

}  // namespace tofcam::sim::internal
