#pragma once
/// \file
/// Point-cloud files that PCL, Open3D and CloudCompare read: PLY (binary little-endian or ASCII)
/// and PCD v0.7 (binary). Per point: x, y, z (float, m), amplitude, intensity, delta_l (float;
/// delta_l in m) and flags (ushort, PixelFlags bits). Writes are atomic (a failed write leaves
/// the old file). Errors: Error(kInvalidArgument) for an inconsistent cloud, Error(kIo) naming
/// the path when the file cannot be written.

#include <filesystem>

#include "tofcam/cloud/point_cloud.h"

namespace tofcam {

enum class PlyFormat { kBinary, kAscii };

/// Writes `cloud` as PLY with one `vertex` element. With `only_valid` only points with finite
/// coordinates and no reject bit are written; otherwise every point (NaN coordinates written as
/// NaN / "nan"), and the header carries a comment "organized <width> <height>". ASCII floats use
/// 9 significant digits (round-trip exact).
void WritePly(const std::filesystem::path& path, const PointCloud& cloud,
              PlyFormat format = PlyFormat::kBinary, bool only_valid = false);

/// Writes `cloud` as binary PCD v0.7 (fields x y z amplitude intensity delta_l flags, sizes
/// 4 4 4 4 4 4 2, types F F F F F F U). With `only_valid` the cloud is unorganised
/// (WIDTH = points, HEIGHT = 1) and holds only valid points; otherwise WIDTH/HEIGHT are the
/// cloud's and rejected points keep NaN coordinates, as PCL expects of organised clouds.
void WritePcd(const std::filesystem::path& path, const PointCloud& cloud, bool only_valid = false);

}  // namespace tofcam
