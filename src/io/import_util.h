#pragma once
// Private helpers shared by the importers (not installed).

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/core/camera.h"
#include "tofcam/core/frame.h"

namespace tofcam::io_internal {

/// Throws kInvalidArgument unless 0 < width, height <= 65536 and width * height <= 2^28.
void CheckImageSize(int width, int height, const std::string& name);

/// Reads a binary file that must hold exactly `expected_bytes` bytes (kNotFound / kFormat).
[[nodiscard]] std::string ReadExactly(const std::filesystem::path& file, std::size_t expected_bytes,
                                      const std::string& what);

/// A frame of zeros with source_flags and has_intensity = false.
[[nodiscard]] Frame BlankFrame(int width, int height, const std::string& model,
                               double modulation_frequency_hz);

/// CameraInfo of an imported camera: no settable registers, no intensity channel.
[[nodiscard]] CameraInfo ImportedCameraInfo(const std::string& model,
                                            const CameraIntrinsics& intrinsics,
                                            double modulation_frequency_hz);

/// Modulation frequency (Hz) whose unambiguous range is `range_m`.
[[nodiscard]] double FrequencyForRange(double range_m);

/// Stores a millimetre distance as register = mm * 65536 / (range_m * 1000), or flags the pixel
/// kInvalid (register 0) when mm is 0 or at/after the range.
void SetDistanceMm(Frame& frame, std::size_t i, double mm, double range_m);
/// Stores an amplitude; values above kMaxSignalRegister are clamped and flagged kSaturated;
/// non-finite or negative values flag kInvalid.
void SetAmplitude(Frame& frame, std::size_t i, double amplitude);

/// Least-squares pinhole intrinsics from camera-frame points (x right, y down, z forward, any
/// unit) of pixels (u, v): x/z = (u - cx)/fx, y/z = (v - cy)/fy. Returns `fallback` (with
/// width/height set) when fewer than 16 usable points or a non-positive focal length result.
struct PixelPoint {
  double u, v, x, y, z;
};
[[nodiscard]] CameraIntrinsics FitPinhole(const std::vector<PixelPoint>& points, int width,
                                          int height, CameraIntrinsics fallback);

}  // namespace tofcam::io_internal
