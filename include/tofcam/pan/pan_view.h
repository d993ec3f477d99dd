#pragma once
/// \file
/// The paper's virtual 180° view: frames taken at several pan angles of the servo are moved
/// into one base frame (tofcam::PanUnit, the geometry the simulator uses too), concatenated into
/// one cloud and rendered as a panoramic false-colour strip.

#include <Eigen/Geometry>
#include <cstddef>
#include <span>
#include <vector>

#include "tofcam/cloud/point_cloud.h"
#include "tofcam/color/false_color.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pan_unit.h"
#include "tofcam/core/rgb.h"

namespace tofcam {

/// Most cells a panorama may have (e.g. 0.02° over 180° x ±30°: 9000 x 3308 = 29.8 million).
inline constexpr double kMaxPanoramaCells = 5e7;

/// Panorama geometry: a cylinder of radius 1 around the pan axis through the rotation centre,
/// unrolled. Azimuth is the angle about the axis from the base z axis (the camera's view at pan
/// angle 0), positive counter-clockwise about the axis (to the left with the default axis, the
/// same sense as the pan angle); a point at azimuth φ and height h over radius ρ lands at
/// column (max_azimuth - φ) / resolution (left of the strip = largest azimuth, as a viewer
/// inside the cylinder sees it) and row (tan(max_elevation) - h/ρ) / resolution. Cells are
/// square on the cylinder.
struct PanViewOptions {
  PanUnit pan_unit;                 ///< Axis and camera offset; must match the camera's pan unit.
  PointCloudOptions cloud;          ///< Which flags make a point NaN (default: every reject bit).
  bool only_valid = true;           ///< Merged cloud keeps only valid points (false: all points).
  double resolution_deg = 0.5;      ///< Cell size, degrees of azimuth; [0.01, 10]. Choose it no
                                    ///< finer than the camera's pixel pitch or the strip has holes.
  double min_azimuth_deg = -90.0;   ///< Right edge of the strip, degrees; >= -180.
  double max_azimuth_deg = 90.0;    ///< Left edge, degrees; > min_azimuth_deg, <= 180.
  double max_elevation_deg = 30.0;  ///< Strip spans ±this elevation, degrees; (0, 80].
  FalseColorOptions color;          ///< Colour law; far_m = 0 uses L of the first frame.
  /// Throws Error(kInvalidArgument) for an option outside its range or a strip of no cell or of
  /// more than kMaxPanoramaCells cells.
  void Validate() const;
};

/// The assembled view.
struct PanView {
  /// Points of all frames in the base frame, concatenated in input order; unorganised
  /// (height 1). Frame k's points are [frame_offsets[k], frame_offsets[k + 1]).
  PointCloud cloud;
  std::vector<std::size_t> frame_offsets;
  std::vector<Eigen::Isometry3d> camera_to_base;  ///< Pose of each input frame.
  /// Per cell, the measured radial distance (m, from its camera) of the point nearest to the
  /// rotation centre that falls in the cell (by x² + y² + z² in double precision from the float
  /// base-frame coordinates; the first of equals); NaN where no point fell.
  Image<float> panorama_distance_m;
  Image<float> panorama_amplitude;  ///< Amplitude of that point; NaN where empty.
  Image<Rgb8> panorama;             ///< False colour of panorama_distance_m; empty cells black.
  double resolution_rad = 0.0;
  double max_azimuth_rad = 0.0;
  double max_tan_elevation = 0.0;

  /// Azimuth (rad) of the centre of column `col`.
  [[nodiscard]] double ColumnAzimuthRad(int col) const noexcept {
    return max_azimuth_rad - (col + 0.5) * resolution_rad;
  }
  /// Elevation (rad) of the centre of row `row`.
  [[nodiscard]] double RowElevationRad(int row) const noexcept;
};

/// Moves every point of `cloud` by `transform` (NaN points stay NaN); other fields are copied.
[[nodiscard]] PointCloud TransformPointCloud(const PointCloud& cloud,
                                             const Eigen::Isometry3d& transform);

/// Builds the view from frames whose `info.pan_angle_rad` says where the servo pointed. Each
/// frame becomes a camera-frame cloud (MakePointCloud), is moved by
/// `pan_unit.CameraToBase(pan_angle_rad)` and appended; valid points are splatted into the
/// panorama cell they fall in (nearest to the rotation centre wins). The cloud is that
/// construction's bit for bit, though built in one pass per frame; a point's cell is defined in
/// double precision (its azimuth within 1e-10 rad of atan2's). Throws
/// Error(kInvalidArgument) for no frames or bad options, Error(kMismatch) when a frame does not
/// fit `rays`.
[[nodiscard]] PanView MakePanView(std::span<const MetricFrame> frames, const RayTable& rays,
                                  const PanViewOptions& options);

/// The same into `view`, reusing its storage (cloud, panorama images) when a previous view of
/// the same strip is passed in: a loop that assembles a view per sweep allocates nothing once
/// the sizes are stable. Every field is overwritten. Throws like MakePanView, before touching
/// `view` (an Error leaves it as it was).
void MakePanViewInto(std::span<const MetricFrame> frames, const RayTable& rays,
                     const PanViewOptions& options, PanView& view);

}  // namespace tofcam
