#pragma once
/// \file
/// The calibration procedure of paper section II-B on any tofcam::Camera, and the wall sweep
/// that adds the distance-dependent correction. See docs/calibration.md for the method.
///
/// Wall geometry: the wall is the plane n . x = wall_distance_m in the camera frame (x right,
/// y down, z forward), n a unit normal pointing away from the camera; the default n = (0, 0, 1)
/// is a wall perpendicular to the optical axis at z = wall_distance_m. The true radial distance
/// of a pixel is the ray-plane intersection t = wall_distance_m / (n . r) with r the pixel's unit
/// ray from the camera's intrinsics (distortion included).

#include <array>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/accuracy/noise_model.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/control/integration_time_controller.h"
#include "tofcam/core/camera.h"

namespace tofcam {

/// One progress report; the library never prints, a CLI may.
struct CalibrationProgress {
  /// "exposure", "warm-up", "averaging", "exposure-offset", "sweep", "held-out",
  /// "integration-sweep" or "noise".
  std::string_view phase;
  int frame = 0;        ///< Frames taken in this phase so far.
  int total = 0;        ///< Frames the phase needs at most (upper bound for "warm-up").
  std::string message;  ///< One human-readable line.
};
using ProgressCallback = std::function<void(const CalibrationProgress&)>;

/// The integration-time controller the calibration uses by default: VendorHistogram with its
/// median (percent_over_pos 50) held at 8-bit position 62 (intensity 15872, the paper's I_A for a
/// uniformly lit wall). Its multiplicative step converges whatever the intensity gained per
/// register step, which varies 200-fold over a 0.5-7 m sweep; MayIncremental with a fixed V_p
/// would overshoot near and crawl far.
[[nodiscard]] ControllerOptions DefaultCalibrationController();

struct WallCalibrationOptions {
  /// Perpendicular camera-to-wall distance, m, (0, L) of the camera's modulation frequency.
  double wall_distance_m = 1.5;
  /// Wall normal in the camera frame (normalised internally; must have z > 0).
  std::array<double, 3> wall_normal = {0.0, 0.0, 1.0};
  /// Frames averaged for the offset matrix, [1, 100000].
  int frames = 50;

  ControllerOptions controller = DefaultCalibrationController();
  /// The exposure phase ends when the register moved by at most 1 for this many consecutive
  /// frames, [1, 1000] ...
  int controller_settle_frames = 5;
  /// ... or fails with Error(kInvalidArgument) after this many frames, [1, 100000].
  int controller_max_frames = 300;

  /// Warm-up: the drift rate of the mean distance is the least-squares slope over this many
  /// frames, [3, 100000]. With ~20000 pixels and ~10 mm noise the per-frame mean is good to
  /// ~0.1 mm; 150 frames (5 s at 30 frames/s) resolve a rate of ~0.005 mm/s.
  int warmup_window_frames = 150;
  /// Warm-up ends when |slope| <= this, m/s, (0, 1]. 5e-5 m/s is 3 mm per minute.
  double warmup_max_drift_m_per_s = 5e-5;
  /// Error(kInvalidArgument) when the drift has not settled after this many frames, >= window.
  int warmup_max_frames = 9000;

  /// A pixel is calibrated when it was valid in at least this fraction of the averaged frames
  /// and its ray meets the wall closer than L; otherwise kInvalid in pixel_flags. (0, 1].
  double min_valid_fraction = 0.5;
  /// Error(kMismatch) when more than this fraction of the pixels stay uncalibrated (the wall
  /// does not fill the view, or the camera is blocked), [0, 1].
  double max_uncalibrated_fraction = 0.1;

  /// Exposure offset: after the averaging, the wall is also measured at these fractions of the
  /// calibration's register (rounded, clamped to the camera's range, duplicates dropped), each
  /// in (0, 4]; lower fractions by default, because the controller put the wall near the
  /// saturation-free maximum. Empty (or no distinct register) = not measured, s = 0.
  std::vector<double> exposure_offset_fractions = {0.25, 0.5};
  /// Frames per integration time for the exposure offset, taken round-robin (one frame per
  /// register in turn) so that any remaining warm-up drift hits every register alike, [1, 100000].
  int exposure_offset_frames = 20;

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// What the wall calibration measured, for reports.
struct WallCalibrationReport {
  int exposure_frames = 0;       ///< Frames the controller needed to settle.
  int integration_register = 0;  ///< Register used for the averaged frames.
  /// +1 when the exposure controller ended at the camera's (or its own) largest register, -1 at
  /// the smallest, 0 otherwise: at a bound the wall was too dark (or too bright) for its set
  /// point and the calibration was taken at a clipped exposure. Always 0 for the Fixed kind.
  int exposure_at_bound = 0;
  int warmup_frames = 0;       ///< Frames discarded while the drift settled (incl. the window).
  double drift_m_per_s = 0.0;  ///< Drift rate at the end of the warm-up, m/s.
  int uncalibrated_pixels = 0;
  double mean_offset_m = 0.0;  ///< Mean of the offset matrix over calibrated pixels.
  double offset_rms_m = 0.0;   ///< RMS of the offset matrix (how wrong an uncalibrated camera is).
  /// Mean per-pixel temporal σ of one frame, m (circular standard deviation). The offset of a
  /// pixel is known to about noise_sigma_m / sqrt(frames).
  double noise_sigma_m = 0.0;

  /// Exposure offset s, m/ms: least-squares slope of the mean (over pixels valid at every
  /// register) distance change against the integration time. 0 when not measured.
  double exposure_offset_m_per_ms = 0.0;
  /// Registers of the exposure measurement (the calibration's first) and the mean shift at each
  /// against the calibration's register, m.
  std::vector<int> exposure_registers;
  std::vector<double> exposure_shift_m;
  /// Spread (standard deviation over pixels) of the per-pixel slopes, m/ms, and the part of it
  /// the per-pixel noise alone explains: when the two agree, one global s is all there is.
  double exposure_pixel_slope_sd_m_per_ms = 0.0;
  double exposure_pixel_slope_noise_m_per_ms = 0.0;
  int exposure_pixels = 0;  ///< Pixels used for s.
};

/// Runs the paper's calibration on `camera` facing a flat wall: distance-offset register to 0,
/// integration time set by the controller, warm-up until the drift settles, then `frames` frames
/// averaged per pixel as phasors (so the 0 / L seam cannot bias the mean) and stored as
/// measured minus true radial distance, wrapped into [-L/2, L/2); then the exposure offset s
/// (OffsetCalibration::exposure_offset_m_per_ms) from the wall at the `exposure_offset_fractions`
/// of the register. One global s rather than one per pixel: the shift is a property of the
/// modulation electronics, and a per-pixel slope from two integration times would carry the noise
/// of two averages (see the report's pixel-slope spread, docs/calibration.md). The camera is left
/// at the calibration's integration time. Throws Error(kInvalidArgument) for bad options or when
/// the controller or the warm-up does not settle, Error(kMismatch) when too few pixels see the
/// wall, Error(kIo) when the camera stops delivering frames, and passes on the camera's errors.
[[nodiscard]] OffsetCalibration CalibrateOffsets(Camera& camera,
                                                 const WallCalibrationOptions& options,
                                                 const ProgressCallback& progress = {},
                                                 WallCalibrationReport* report = nullptr);

/// Opens or moves a camera so that it faces the wall at a perpendicular distance (m) and
/// returns it; the reference must stay valid until the next call. The camera must have the
/// calibration's model, size and modulation frequency.
using WallCameraSource = std::function<Camera&(double wall_distance_m)>;

struct SweepOptions {
  double from_m = 0.5;   ///< First wall distance, m, > 0.
  double to_m = 7.0;     ///< Last wall distance, m, in [from_m, L).
  double step_m = 0.25;  ///< Spacing, m, > 0; at most 1000 distances.
  /// Also measure the midpoints between sweep distances, held out of the fit, to report the
  /// error before and after on distances the correction never saw.
  bool held_out = true;
  int frames_per_distance = 10;  ///< Frames averaged per distance, [1, 100000].
  double lut_step_m = 0.05;      ///< Knot spacing of the correction, m, (0, 1].
  /// Knots with fewer samples are interpolated from their neighbours, [1, 2^30].
  int lut_min_samples = 20;
  /// Residuals beyond this (m) are left out of the fit (pixels that missed the wall), (0, L/2).
  double outlier_m = 0.3;
  /// Alternations between the global correction g(l) and the per-pixel offsets, [0, 20]. The
  /// wall calibration's offsets contain the wiggling error at each pixel's own wall distance;
  /// without refinement that per-pixel part stays behind. 0 keeps the offsets as measured.
  int refine_iterations = 3;
  /// Wall normal and exposure settings (warm-up is not repeated; frames, min_valid_fraction
  /// apply per distance).
  WallCalibrationOptions wall;

  void Validate() const;
};

/// Error at one sweep distance, RMS over the pixels used (averaged frames, so the noise floor
/// is about noise_sigma / sqrt(frames_per_distance)).
struct SweepDistanceResult {
  double wall_distance_m = 0.0;
  bool held_out = false;
  int pixels = 0;  ///< Pixels with a valid average and a true distance below L.
  int integration_register = 0;
  double rms_raw_m = 0.0;     ///< No calibration at all.
  double rms_before_m = 0.0;  ///< Offset matrix only (paper eq. 1).
  double rms_after_m = 0.0;   ///< Refined offsets and distance correction.
  /// Noise of the averages: sqrt(mean over pixels of σ² / frames). An RMS error at this level
  /// is all noise; sqrt(rms² - floor²) is the systematic part.
  double noise_floor_m = 0.0;
};

struct SweepReport {
  std::vector<SweepDistanceResult> distances;
  double held_out_rms_before_m = 0.0;  ///< Pooled over all held-out pixels.
  double held_out_rms_after_m = 0.0;
  double training_rms_before_m = 0.0;
  double training_rms_after_m = 0.0;
  double held_out_noise_floor_m = 0.0;  ///< Pooled like the RMS values (in quadrature).
};

/// The wall sweep: for each distance, `source(distance)`, exposure settled by the controller,
/// frames averaged as phasors and moved to the calibration's integration time with `base`'s
/// exposure offset (so g holds no exposure-dependent part); then g(l) (bin averages of the residual
/// over the eq.-1-corrected distance, Catmull-Rom between knots) alternated with per-pixel offset
/// refinement. Returns `base` with refined offsets and the correction. Throws
/// Error(kInvalidArgument) for bad options, Error(kMismatch) when a camera does not fit `base`, and
/// the camera's errors.
[[nodiscard]] OffsetCalibration CalibrateDistanceCorrection(const OffsetCalibration& base,
                                                            const WallCameraSource& source,
                                                            const SweepOptions& options,
                                                            const ProgressCallback& progress = {},
                                                            SweepReport* report = nullptr);

/// The integration-time sweep of paper fig. 3 on the scene the camera looks at.
struct IntegrationSweepOptions {
  /// Registers from_register, from_register + step, ... up to to_register (always included);
  /// 0 = the camera's minimum / maximum. Within the camera's range, from < to.
  int from_register = 0;
  int to_register = 0;
  int steps = 32;  ///< Number of registers, [3, 1000] (fewer when the range is shorter).
  /// Frames grabbed per register; the last is measured (a real camera may deliver one frame at
  /// the old setting). [1, 100].
  int frames_per_step = 1;
  /// Intensity from which a pixel counts as clipped (CountsForExposure): such pixels count with
  /// their collapsed amplitude although they have no phase. Register units, [0, 65532]; 0 = only
  /// pixels without kInvalid. The controllers' default.
  double clipped_intensity = ControllerOptions{}.clipped_intensity;

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// Sweeps the integration time over the options' registers and returns, per register, the
/// frame's mean intensity (amplitude without an intensity channel), mean amplitude and saturated
/// fraction over the pixels without kInvalid, plus those whose intensity is clipped
/// (>= options.clipped_intensity; saturated pixels count: their collapsed amplitude is what makes
/// the amplitude maximum). The camera is left at its previous register. Throws
/// Error(kInvalidArgument) for bad options and Error(kIo) when the camera stops delivering.
[[nodiscard]] std::vector<IntegrationSweepPoint> SweepIntegrationTime(
    Camera& camera, const IntegrationSweepOptions& options = {},
    const ProgressCallback& progress = {});

/// The noise calibration of stage 3 on a camera looking at a static scene.
struct NoiseCalibrationOptions {
  /// Frames grabbed, [3, 100000]; a finite source (recording, import) that ends earlier is used
  /// with the frames it had (at least 3).
  int frames = 30;
  DeltaLFitOptions fit;  ///< Passed to FitDeltaLScale.
  /// Also fit the noise model (FitNoiseModel) when at least model_fit.min_frames frames came;
  /// it is stored only when its held-out Spearman ρ is at least eq. 2's.
  bool fit_model = true;
  NoiseModelFitOptions model_fit;

  void Validate() const;
};

/// What CalibrateNoise did about the noise model.
struct NoiseModelReport {
  std::optional<NoiseModelFit> fit;  ///< The fit with its held-out validation, when it ran.
  bool stored = false;               ///< The model went into the NoiseCalibration.
  std::string note;                  ///< Why it was (not) stored or did not run, one line.
};

/// Grabs static frames at the camera's current integration time and fits the ΔL scale
/// (FitDeltaLScale). Throws Error(kInvalidArgument) for bad options or too few usable pixels,
/// Error(kIo) when a source ends before 3 frames. `fit` receives the full fit when not null;
/// with options.fit_model, the noise model is fitted too and `model` (when not null) says
/// what became of it.
[[nodiscard]] NoiseCalibration CalibrateNoise(Camera& camera,
                                              const NoiseCalibrationOptions& options = {},
                                              const ProgressCallback& progress = {},
                                              DeltaLScaleFit* fit = nullptr,
                                              NoiseModelReport* model = nullptr);

/// The noise scale a simulator's ground truth gives for one frame: least squares of the true
/// per-pixel σ² (GroundTruth::sigma_m) on ΔL² of eq. 2 with scale 1, through the origin, over
/// pixels without reject flags, with 0 < σ <= options.max_sigma_fraction_of_range x L (as
/// FitDeltaLScale). nullopt when the frame has no truth σ or fewer than options.min_pixels such
/// pixels.
[[nodiscard]] std::optional<double> GroundTruthNoiseScale(const MetricFrame& frame,
                                                          const DeltaLFitOptions& options = {});

/// True radial distance (m) of every pixel to the wall plane (+inf where the ray misses it).
[[nodiscard]] Image<float> WallRadialDistance(const CameraIntrinsics& intrinsics,
                                              double wall_distance_m,
                                              const std::array<double, 3>& wall_normal);

}  // namespace tofcam
