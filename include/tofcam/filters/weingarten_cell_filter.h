#pragma once
/// \file
/// The baseline the paper names (Weingarten et al.): space is cut into cubic cells and a cell
/// counts as occupied only if it holds a minimum number of points; points in other cells are
/// noise.

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam {

struct WeingartenCellOptions {
  /// Cell edge, m; [0.001, 100]. Cells are aligned with the camera frame, the corner of cell
  /// (0, 0, 0) at the optical centre (for a camera fixed on a robot this is the robot grid up to
  /// a constant transform). Default 0.1 m: a wall at 3 m puts ~30 SR-2 pixels in a cell.
  double voxel_size_m = 0.1;
  /// Points a cell needs to be occupied; [1, 1'000'000]. Free parameter.
  int min_points = 4;
  void Validate() const;
};

/// kSparseCell on every usable point whose cell holds fewer than `min_points` usable points.
/// Usable = no kRejectMask bit in `frame.flags` and a finite, positive distance; other pixels
/// are neither counted nor flagged. Points are counted in a dense array over the box of their
/// cells (an open-addressing hash table when that box is too large), reused between calls on the
/// same thread (no per-frame allocation once warmed up). Coordinates more than 2^20 cells from
/// the origin are clamped to the outermost cell. Throws Error(kMismatch) when `rays` is not the
/// frame's size.
[[nodiscard]] Image<PixelFlags> WeingartenCellFilter(const MetricFrame& frame, const RayTable& rays,
                                                     const WeingartenCellOptions& options);

}  // namespace tofcam
