#pragma once
/// \file
/// The per-pixel calibration file (format documented in docs/calibration.md): YAML, versioned,
/// human-readable, with the offset matrix as one flow sequence per row. Floats are written with
/// 9 significant digits, so a save/load round trip is bit-exact.

#include <filesystem>

#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/core/camera.h"

namespace tofcam {

/// Writes `calibration` atomically (tofcam/core/atomic_file.h). Throws Error(kInvalidArgument)
/// when the calibration does not validate and Error(kIo) naming the path when it cannot be
/// written.
void SaveCalibration(const std::filesystem::path& path, const OffsetCalibration& calibration);

/// Reads and validates a calibration file. Throws Error(kNotFound) for a missing file and
/// Error(kFormat) naming the file, the line where known, and the problem for anything else:
/// not YAML, wrong format tag, unsupported version, missing, unknown or repeated keys, wrong
/// types, sizes
/// above 16384 x 16384 or 2^24 pixels, a matrix whose shape differs from width x height,
/// non-finite numbers, offsets beyond ±L/2, or files over 256 MiB.
[[nodiscard]] OffsetCalibration LoadCalibration(const std::filesystem::path& path);

/// Throws Error(kMismatch) naming the field (camera model, width, height, modulation frequency)
/// when `calibration` was not made for a camera like `camera`. The integration time is not
/// compared: the controller changes it all the time and its effect on distance is small.
void CheckCalibrationMatches(const OffsetCalibration& calibration, const CameraInfo& camera);

}  // namespace tofcam
