#pragma once
/// \file
/// Organised point clouds: one point per sensor pixel, structure of arrays.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/pixel_flags.h"

namespace tofcam {

/// A point cloud as parallel arrays of `width * height` elements (row-major when organised;
/// `height == 1` for an unorganised cloud). Coordinates are metres in the frame the producer
/// states (camera frame for MakePointCloud: x right, y down, z forward). A point whose
/// coordinates are NaN has no position (rejected or unusable); its other fields are kept.
struct PointCloud {
  int width = 0;
  int height = 0;
  std::vector<float> x, y, z;     ///< Position, m.
  std::vector<float> amplitude;   ///< Amplitude, register units.
  std::vector<float> intensity;   ///< Intensity, register units; NaN when the source has none.
  std::vector<float> delta_l_m;   ///< Predicted inaccuracy ΔL, m; NaN when not computed.
  std::vector<PixelFlags> flags;  ///< Pixel flags.

  [[nodiscard]] std::size_t size() const noexcept { return x.size(); }
  [[nodiscard]] bool empty() const noexcept { return x.empty(); }
  [[nodiscard]] bool organized() const noexcept { return height > 1; }
  /// True when point i has finite coordinates and no reject bit.
  [[nodiscard]] bool IsValid(std::size_t i) const noexcept;
  /// Number of valid points.
  [[nodiscard]] std::size_t CountValid() const noexcept;
  /// Resizes every array to width * height (new elements: NaN floats, clear flags).
  void Resize(int new_width, int new_height);
  /// Throws Error(kInvalidArgument) unless every array holds width * height elements.
  void Validate() const;
};

struct PointCloudOptions {
  /// Pixels with any of these flag bits get NaN coordinates. Default: every reject bit. Set 0
  /// to keep the coordinates of all pixels with a finite distance (flags still tell).
  std::uint16_t nan_mask = kRejectMask;
};

/// Point = radial distance (m) × the pixel's unit ray from `rays`, in the camera frame. The
/// cloud is organised (frame width × height). Pixels with a `nan_mask` bit or a non-finite
/// distance get NaN x, y, z but keep amplitude, intensity, ΔL and flags, so the cloud stays
/// organised. Missing intensity / ΔL channels become NaN. Throws Error(kInvalidArgument) for an
/// empty or inconsistent frame and Error(kMismatch) when `rays` is not the frame's size.
[[nodiscard]] PointCloud MakePointCloud(const MetricFrame& frame, const RayTable& rays,
                                        const PointCloudOptions& options = {});

/// The same into an existing cloud, reusing its storage: no allocation when `cloud` already has
/// the frame's size (the per-frame loop of a pipeline). Every element is overwritten.
void MakePointCloudInto(const MetricFrame& frame, const RayTable& rays, PointCloud& cloud,
                        const PointCloudOptions& options = {});

}  // namespace tofcam
