#pragma once
/// \file
/// Jump-edge filter of May's group (tof-notes §4): removes points whose neighbour lies almost
/// straight towards the camera, i.e. points on the far side of a depth discontinuity and the
/// mixed pixels between two surfaces.

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam {

struct JumpEdgeOptions {
  /// For point p (from the optical centre) and each 8-neighbour n with p·(n - p) < 0, the angle
  /// α = acos(p·(n - p) / (|p| |n - p|)) between p's viewing direction and the step to n; near
  /// 180° the neighbour lies almost on p's ray, in front of it. p is removed when the largest α
  /// exceeds this threshold, in degrees, (90, 180). The literature uses 155-160°.
  double max_angle_deg = 160.0;
  void Validate() const;
};

/// kJumpEdge as above. Points are radial distance times the unit ray of `rays`. Pixels already
/// rejected in `frame.flags` (any kRejectMask bit; empty flags = none) or with a non-finite or
/// non-positive distance are neither judged nor used as neighbours; image borders use the
/// neighbours that exist. No acos per pixel: the test is rewritten as d_p > d_n·λ(rays, angle)
/// with λ precomputed per ray table (docs/filters.md), cached per thread and rebuilt when the
/// ray table or the angle changes. Throws Error(kMismatch) when
/// `rays` is not the frame's size.
[[nodiscard]] Image<PixelFlags> JumpEdgeFilter(const MetricFrame& frame, const RayTable& rays,
                                               const JumpEdgeOptions& options);

}  // namespace tofcam
