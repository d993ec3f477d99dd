#pragma once
/// \file
/// Pinhole camera with Brown-Conrady distortion (OpenCV's rational model: k1..k6, p1, p2).
///
/// Conventions: camera frame x right, y down, z forward (optical axis); metres. Pixel
/// coordinates (u, v) = (column, row) with the centre of the top-left pixel at (0, 0), as in
/// OpenCV; the image spans [-0.5, width - 0.5] x [-0.5, height - 0.5].

#include <Eigen/Core>
#include <string>

#include "tofcam/core/image.h"

namespace tofcam {

struct CameraIntrinsics {
  int width = 160;                ///< Pixels per row (> 0).
  int height = 124;               ///< Rows (> 0).
  double fx_px = 204.0816;        ///< Focal length / horizontal pixel pitch, px (> 0).
  double fy_px = 145.9854;        ///< Focal length / vertical pixel pitch, px (> 0).
  double cx_px = 79.5;            ///< Principal point column, px.
  double cy_px = 61.5;            ///< Principal point row, px.
  double k1 = 0, k2 = 0, k3 = 0;  ///< Radial numerator coefficients.
  double k4 = 0, k5 = 0, k6 = 0;  ///< Radial denominator coefficients (rational model).
  double p1 = 0, p2 = 0;          ///< Tangential coefficients.

  /// SwissRanger SR-2 (tof-notes §3): 160 x 124 px, 8 mm lens, pitch 39.2 µm horizontal and
  /// 54.8 µm vertical (our choice: the notes leave the axis open; this one reproduces the listed
  /// 42.8° x 46.0° field of view), principal point at the image centre, no distortion (none is
  /// published).
  [[nodiscard]] static CameraIntrinsics SwissRangerSr2();

  /// Throws Error(kInvalidArgument) naming the field when a value is out of range or not
  /// finite, or when the image centre has no ray. Pixels beyond a folding lens's first branch
  /// are allowed (they have NaN rays); see RequireUnfoldedDistortion.
  void Validate() const;

  [[nodiscard]] bool HasDistortion() const noexcept;

  /// Pixel of a camera-frame point. `point.z()` must be > 0; otherwise returns NaNs.
  [[nodiscard]] Eigen::Vector2d Project(const Eigen::Vector3d& point) const noexcept;
  /// Distorted normalised coordinates (x/z, y/z after distortion) of undistorted ones.
  [[nodiscard]] Eigen::Vector2d Distort(const Eigen::Vector2d& normalized) const noexcept;
  /// Inverse of Distort by Newton iteration (converges to < 1e-12 for any realistic lens);
  /// returns NaNs if it does not converge, or if the root lies beyond the lens's first fold
  /// (the Jacobian turns non-positive on the way out from the axis: a direction a model fitted
  /// within the field of view does not describe).
  [[nodiscard]] Eigen::Vector2d Undistort(const Eigen::Vector2d& distorted) const noexcept;
  /// Unit-length ray (z > 0) through pixel coordinates `pixel`.
  [[nodiscard]] Eigen::Vector3d Unproject(const Eigen::Vector2d& pixel) const noexcept;

  /// Full field of view between the outer pixel edges through the principal point, radians.
  [[nodiscard]] double HorizontalFovRad() const noexcept;
  [[nodiscard]] double VerticalFovRad() const noexcept;
};

/// Throws Error(kInvalidArgument) saying that pixel coordinates (u, v) have no ray (a lens
/// model Validate() let through but Unproject() cannot invert there).
[[noreturn]] void NoRay(double u, double v);

/// Throws Error(kInvalidArgument) when the distortion folds over inside the image: along rays
/// from the optical axis (32 directions and the corners' four) it must stay one to one out to
/// the image's farthest corner. A renderer needs this (every pixel a ray on the lens's first
/// branch). CameraIntrinsics::Validate does not require it: a real camera's fitted model may
/// fold beyond its field of view (the Azure Kinect's wide mode at its unlit corners), where
/// Unproject gives NaN rays and so no points.
void RequireUnfoldedDistortion(const CameraIntrinsics& k);

/// Unit rays of every pixel centre, structure-of-arrays for vectorised point-cloud conversion.
/// Point (m) = radial distance (m) * (x, y, z)(row, col).
struct RayTable {
  Image<float> x;
  Image<float> y;
  Image<float> z;
};

/// Precomputes the unit ray of every pixel (validates the intrinsics first).
[[nodiscard]] RayTable MakeRayTable(const CameraIntrinsics& intrinsics);

}  // namespace tofcam
