#pragma once
/// \file
/// Scattering calibration (not in the paper; issue 18, docs/beyond.md): the camera's point-spread
/// measured on a wall without and with a small bright card near the lens, stored in the
/// calibration file (OffsetCalibration::scattering) for the pipeline's scattering compensation.

#include "tofcam/calibration/calibration_procedure.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/core/camera.h"
#include "tofcam/optics/scattering.h"

namespace tofcam {

struct ScatteringCalibrationOptions {
  int frames = 8;  ///< Frames averaged per scene, [1, 10000].
  /// Register both scenes are shot at; 0 = chosen: the camera's current register, halved until
  /// at most `max_saturated_fraction` of the card scene's pixels clip. Else within the cameras'
  /// register range.
  int integration_time_register = 0;
  /// [0, 1). The card is the light source of the fit: a clipped card pixel's phasor is wrong
  /// (its amplitude collapses), and the card covers a few % of the image, so the default allows
  /// none.
  double max_saturated_fraction = 0.0;
  ScatteringFitOptions fit;  ///< Passed to EstimateScatteringPsf.

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// Grabs `frames` frames of the wall alone (`without`) and of the same wall with the card
/// (`with`) at one register and fits the point-spread (EstimateScatteringPsf). The two cameras
/// must have the same size. Throws Error(kInvalidArgument) for bad options, mismatched cameras,
/// a register the cameras refuse, a card that clips even at the shortest register, or no card
/// found (EstimateScatteringPsf's errors); Error(kIo) when a camera stops delivering.
[[nodiscard]] ScatteringCalibration CalibrateScattering(
    Camera& without, Camera& with, const ScatteringCalibrationOptions& options = {},
    const ProgressCallback& progress = {});

}  // namespace tofcam
