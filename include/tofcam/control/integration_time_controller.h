#pragma once
/// \file
/// Stage 4: online integration-time control (paper section III-A). Frame t sets the register for
/// frame t + 1: `int next = controller->Update(metric_frame); camera.SetIntegrationTimeRegister(
/// next);`.
///
/// The controlled quantity is the mean intensity Ī_t over the region of interest and over the
/// pixels whose flags have none of `ControllerOptions::exclude_flags` (by default only kInvalid:
/// saturated pixels must count, they are what tells the controller to back off; fully clipped
/// pixels, which SwissRangers report with amplitude 0 and so kInvalid, count through
/// `clipped_intensity`). For frames
/// without an intensity channel the amplitude is averaged instead and I_A must be given in
/// amplitude units. Intensity and I_A are in register units (0..65532); the control variable is
/// the integration-time register (SR-2: 1..255, 255 µs per step).
///
///  - MayProportional: exactly the printed law  c_{t+1} = -V_p * D_t + c_0,  D_t = Ī_t - I_A,
///    rounded to the nearest register and clamped to [min_register, max_register]. Stateless:
///    in this position form the steady state keeps an offset unless c_0 is right.
///  - MayIncremental:  c_{t+1} = c_t - V_p * D_t. c_t is kept as a real number between frames
///    (so small corrections accumulate instead of rounding away) and clamped to the bounds
///    (anti-windup); the register is its nearest integer.
///
/// V_p = 0 (the default) schedules the gain from the frame itself: V_p,t = loop_gain * c_t / Ī_t,
/// c_t the frame's register. Ī is nearly proportional to the integration time (signal, ambient
/// and dark charge all are; tof-notes §2), so c_t / Ī_t is the inverse plant gain 1 / k of the
/// current scene and the loop gain V_p,t * k is `loop_gain` in every scene: a fixed V_p stable
/// for a hand at 20 cm (k ~ 10^3 per register) barely moves in a dim hall (k ~ 2), and one that
/// moves the hall limit-cycles on the hand. With the incremental form and loop_gain in (0, 1] the
/// error shrinks by (1 - loop_gain) per frame on a proportional plant; an ambient offset only
/// lowers the effective gain. The step is limited to a factor 4 per frame (dark frames). A
/// calibration's set point (tofcam calibrate --setpoint) gives the printed law its fixed V_p.
///  - VendorHistogram: tof-notes §4 (CSEM/MESA): intensity reduced to 8 bits (I >> 8),
///    histogram, x = the smallest 8-bit value that at most percent_over_pos % of the pixels
///    exceed; our step law (the vendor's is unpublished) is a damped multiplicative step
///    c_{t+1} = c_t * (1 + vendor_gain * (desired_pos / max(x, 1) - 1)), because intensity is
///    about proportional to integration time (a full step would jump to the predicted register),
///    limited to ±vendor_max_step_register per frame, no change while |x - desired_pos| <=
///    vendor_deadband, clamped to the bounds.
///  - Fixed: always c_0.
///  - ModelBased (not in the paper; docs/controllers.md): intensity and amplitude grow in
///    proportion to the integration time (signal, ambient and dark charge are all integrated;
///    tof-notes §2), so one frame predicts every pixel's brightest tap, I + A, at any register:
///    peak(c') = peak(c) c' / c. The longest exposure gives every pixel the most amplitude and so
///    the smallest ΔL (σ ∝ 1/sqrt(t)), as long as it does not clip: the law takes the q-quantile
///    of peak (q = 1 - max_clipped_fraction over the ROI) to model_headroom x clipped_intensity,
///    c' = c * model_headroom * clipped_intensity / peak_q. Pixels clipped now have no measured
///    peak: when more than max_clipped_fraction of them are clipped the register is divided by
///    model_backoff, or by 2 when at most 5 x max_clipped_fraction are (the model then finishes
///    the job from an unclipped frame). Steps up are
///    limited to a factor model_max_increase per frame; changes under model_deadband (relative)
///    are not made, so noise does not make it hunt. Without an intensity channel the amplitude
///    is the peak.
///
/// A frame with no usable pixel in the ROI leaves the register unchanged.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/core/camera.h"
#include "tofcam/core/frame.h"

namespace tofcam {

enum class ControllerKind {
  kMayProportional,
  kMayIncremental,
  kVendorHistogram,
  kFixed,
  kModelBased
};

/// Register units of intensity at which a pixel counts as clipped by default: 98 % of full scale,
/// as SaturationOptions::max_peak.
inline constexpr double kDefaultClippedIntensity = 64221.0;

/// "may-proportional", "may-incremental", "vendor-histogram", "fixed", "model-based".
[[nodiscard]] std::string_view ControllerKindName(ControllerKind kind) noexcept;
/// Inverse of ControllerKindName; throws Error(kInvalidArgument) naming the unknown kind.
[[nodiscard]] ControllerKind ParseControllerKind(std::string_view name);

/// Rectangle of pixels, (row, col) of its top-left corner and its size. rows == 0 or cols == 0
/// means the whole image. A ROI that leaves the frame is clipped to it.
struct RegionOfInterest {
  int row = 0;
  int col = 0;
  int rows = 0;
  int cols = 0;
};

struct ControllerOptions {
  /// The default is the incremental law with a scheduled gain: it holds Ī at I_A in every scene
  /// without a calibration. The paper's printed law is kMayProportional.
  ControllerKind kind = ControllerKind::kMayIncremental;
  /// I_A: intensity set point, register units, (0, 65532]. The paper: 15000..18000 worked.
  double target_intensity = 16000.0;
  /// V_p: registers per intensity unit, [0, 1]; 0 = scheduled from each frame (see above).
  double gain_register_per_intensity = 0.0;
  /// Loop gain of the scheduled V_p (used when gain_register_per_intensity is 0), (0, 1].
  double loop_gain = 0.5;
  /// Frame rate the integration time must allow, Hz: the Pipeline lowers max_register so that
  /// integration + readout fit 1 / frame_rate_hz (MaxRegisterForFrameRate). 0 = the camera's
  /// maximum frame rate (CameraInfo::max_frame_rate_hz; SR-2: 30); >= 0.
  double frame_rate_hz = 0.0;
  /// c_0: bias of the proportional law, start value of the others, Fixed's register.
  /// [min_register, max_register].
  int bias_register = 40;
  int min_register = 1;    ///< Lower clamp, [1, max_register] (SR-2: 1).
  int max_register = 255;  ///< Upper clamp, [min_register, 65535] (SR-2: 255).
  RegionOfInterest roi;    ///< Pixels Ī_t is taken over; whole image by default.
  /// Pixels with any of these flag bits are left out of Ī_t and of the histogram ...
  std::uint16_t exclude_flags = static_cast<std::uint16_t>(Flag::kInvalid);
  /// ... unless their intensity is at least this (register units, [0, 65532]; 0 = off): a
  /// SwissRanger pixel whose taps all clipped reports amplitude 0 (so kInvalid: no phase) with
  /// intensity at full scale; it is what tells the controller to back off and must count. The
  /// default is 98 % of full scale, as SaturationOptions::max_peak.
  double clipped_intensity = kDefaultClippedIntensity;

  // VendorHistogram (tof-notes §4; SR-3000 vendor settings by default).
  double percent_over_pos = 10.0;     ///< percentOverPos, % of pixels above x, [0, 100).
  int desired_pos = 45;               ///< desiredPos, 8-bit set point for x, [1, 255].
  double vendor_gain = 0.5;           ///< Fraction of the predicted step taken per frame, (0, 1].
  int vendor_max_step_register = 20;  ///< Largest change per frame, registers, >= 1.
  int vendor_deadband = 2;            ///< No change while |x - desired_pos| <= this, [0, 254].
  // ModelBased (see above).
  /// Fraction of ROI pixels allowed to clip, [0, 0.5].
  double max_clipped_fraction = 0.01;
  /// The peak quantile is placed at this fraction of clipped_intensity, (0, 1].
  double model_headroom = 0.85;
  /// Largest factor up per frame, [1, 1000]. As large as the back-off: the prediction from an
  /// unclipped frame is exact on a proportional plant, the limit only guards against frames
  /// whose pixels are all near zero.
  double model_max_increase = 8.0;
  /// Factor down when more than max_clipped_fraction of the pixels clip now, (1, 1000].
  double model_backoff = 8.0;
  /// Relative changes smaller than this are not made, [0, 0.5].
  double model_deadband = 0.05;

  /// Throws Error(kInvalidArgument) naming the field when a value is out of range or not finite.
  void Validate() const;
};

/// One interface for every integration-time controller.
class IntegrationTimeController {
 public:
  virtual ~IntegrationTimeController() = default;
  /// Consumes frame t (metric, flags set) and returns the register for frame t + 1, within
  /// [min_register, max_register]. Never throws for a well-formed frame; pixels outside the
  /// frame are ignored.
  virtual int Update(const MetricFrame& frame) = 0;
  /// Stable name, as ControllerKindName.
  [[nodiscard]] virtual std::string_view Name() const = 0;
  /// Forgets the history and continues from `current_register` (e.g. after a manual change),
  /// clamped to the bounds.
  virtual void Reset(int current_register) = 0;
};

/// c_{t+1} = -V_p (Ī_t - I_A) + c_0, rounded and clamped (stateless).
class MayProportional final : public IntegrationTimeController {
 public:
  /// Throws Error(kInvalidArgument) for invalid options.
  explicit MayProportional(const ControllerOptions& options);
  int Update(const MetricFrame& frame) override;
  [[nodiscard]] std::string_view Name() const override;
  void Reset(int current_register) override;

 private:
  ControllerOptions options_;
  int last_register_;
};

/// c_{t+1} = c_t - V_p (Ī_t - I_A), real-valued state clamped to the bounds, output rounded.
class MayIncremental final : public IntegrationTimeController {
 public:
  explicit MayIncremental(const ControllerOptions& options);
  int Update(const MetricFrame& frame) override;
  [[nodiscard]] std::string_view Name() const override;
  void Reset(int current_register) override;

 private:
  ControllerOptions options_;
  double state_;
};

/// The model-based exposure law above (stateful: the register as a real number).
class ModelBased final : public IntegrationTimeController {
 public:
  explicit ModelBased(const ControllerOptions& options);
  int Update(const MetricFrame& frame) override;
  [[nodiscard]] std::string_view Name() const override;
  void Reset(int current_register) override;
  /// Fraction of usable ROI pixels clipped in the last frame, [0, 1] (0 before the first).
  [[nodiscard]] double last_clipped_fraction() const noexcept { return last_clipped_fraction_; }

 private:
  ControllerOptions options_;
  double state_;
  double last_clipped_fraction_ = 0.0;
  std::vector<float> peaks_;  // scratch, reused per frame
};

/// The CSEM/MESA 8-bit histogram auto-exposure with the damped multiplicative step above.
class VendorHistogram final : public IntegrationTimeController {
 public:
  explicit VendorHistogram(const ControllerOptions& options);
  int Update(const MetricFrame& frame) override;
  [[nodiscard]] std::string_view Name() const override;
  void Reset(int current_register) override;
  /// The 8-bit value x of the last Update (-1 before the first or after an empty frame).
  [[nodiscard]] int last_position() const noexcept { return last_position_; }

 private:
  ControllerOptions options_;
  double state_;
  int last_position_ = -1;
};

/// Always returns c_0 (bias_register).
class Fixed final : public IntegrationTimeController {
 public:
  explicit Fixed(const ControllerOptions& options);
  int Update(const MetricFrame& frame) override;
  [[nodiscard]] std::string_view Name() const override;
  void Reset(int current_register) override;

 private:
  int register_;
};

/// Whether pixel i of `frame` counts for exposure statistics (the controllers' Ī, the sweeps of
/// paper fig. 3): it has none of `exclude_flags`, or it is clipped (intensity >=
/// `clipped_intensity` > 0), whatever its flags. Frames without flags count every pixel.
[[nodiscard]] bool CountsForExposure(const MetricFrame& frame, std::size_t i,
                                     std::uint16_t exclude_flags,
                                     double clipped_intensity) noexcept;

/// Mean of intensity (amplitude without an intensity channel) over the ROI and the pixels
/// without `exclude_flags` (or with intensity >= `clipped_intensity` when that is > 0, see
/// ControllerOptions); NaN when no pixel qualifies. Exposed for status lines and tests.
[[nodiscard]] double MeanControlIntensity(const MetricFrame& frame, const RegionOfInterest& roi,
                                          std::uint16_t exclude_flags,
                                          double clipped_intensity = 0.0);

/// Ī_t exactly as a controller with `options` sees it (its ROI, excluded flags and clipped rule):
/// the one function behind the controllers and every reported mean intensity.
[[nodiscard]] double ControlledMeanIntensity(const MetricFrame& frame,
                                             const ControllerOptions& options);

/// The largest register whose frame fits the period 1 / frame_rate_hz: integration time
/// (camera.IntegrationTimeUs) + camera.readout_time_us <= 1e6 / frame_rate_hz. Throws
/// Error(kInvalidArgument) when frame_rate_hz is not positive and finite, or when even
/// camera.min_integration_register does not fit (naming the rate and the shortest frame).
/// At most camera.max_integration_register.
[[nodiscard]] int MaxRegisterForFrameRate(const CameraInfo& camera, double frame_rate_hz);

/// One step of an integration-time sweep (paper fig. 3): the register and the frame's means.
struct IntegrationSweepPoint {
  int integration_register = 0;  ///< Register of the frame, >= 1.
  /// Ī over the pixels that count for exposure (CountsForExposure with kInvalid excluded, clipped
  /// pixels included), register units (>= 0).
  double mean_intensity = 0.0;
  double mean_amplitude = 0.0;      ///< Mean amplitude over the same pixels, register units (>= 0).
  double saturated_fraction = 0.0;  ///< Fraction of those pixels flagged kSaturated, [0, 1].
};

/// How ChooseSetpoint derives the P-controller's constants from a sweep.
struct SetpointOptions {
  /// I_A = this x the mean intensity at the amplitude maximum ("a little below"), (0, 1].
  double target_fraction = 0.9;
  /// The mean amplitude of a scene often has a flat top rather than a peak (the paper: "mean
  /// amplitude functions do not provide stable approximations of working points"); on a plateau
  /// the arg-max is decided by noise. The amplitude maximum is therefore the lowest register whose
  /// mean amplitude is within this fraction of the largest one: the start of the plateau, where
  /// saturation begins to cost amplitude. 0 = the plain arg-max. [0, 0.5].
  double plateau_tolerance = 0.02;
  /// Upper bound of the loop gain V_p * k at c_0 (k = intensity gained per register there). The
  /// printed position law's error is multiplied by -V_p k each frame, so below 1 it decays;
  /// 0.5 halves it per frame with little ringing. (0, 1).
  double max_loop_gain = 0.5;
  /// Intensity of a fully saturated image (register units): V_p is at least large enough that
  /// such an image drives the law to min_register, unless max_loop_gain forbids it. (0, 65532].
  double saturated_intensity = 65532.0;
  int min_register = 1;    ///< Register bounds of the camera, 1 <= min <= max <= 65535.
  int max_register = 255;  ///< (the same as ControllerOptions).

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
};

/// The set point of the paper's controller, chosen the way the paper chose I_A (section III-A):
/// from an integration-time sweep of the working scene, a little below the mean intensity at the
/// amplitude maximum, with c_0 at the register where the scene gives I_A.
struct ControllerSetpoint {
  double target_intensity = 16000.0;            ///< I_A, register units, (0, 65532].
  int bias_register = 40;                       ///< c_0: register where Ī = I_A, >= 1.
  double gain_register_per_intensity = 2.5e-4;  ///< V_p, registers per intensity unit, [0, 1].
  int amplitude_max_register = 0;        ///< Register of the sweep's amplitude maximum (info).
  double amplitude_max_intensity = 0.0;  ///< Ī there (info), register units.
  double intensity_per_register = 0.0;   ///< k at c_0 (info), intensity units per register.
  std::string scene;                     ///< What the camera looked at during the sweep (info).

  /// Throws Error(kInvalidArgument) naming the field.
  void Validate() const;
  /// `base` with I_A, c_0 and V_p replaced by the set point's and kind = kMayProportional.
  [[nodiscard]] ControllerOptions Apply(ControllerOptions base) const;
};

/// Picks the amplitude maximum of `sweep` (the lowest register whose mean amplitude is within
/// plateau_tolerance of the largest; with tolerance 0 the first of equal maxima), sets
/// I_A = target_fraction x its mean intensity, c_0 = the register where the mean intensity
/// crosses I_A (linear interpolation between sweep points, rounded; the lowest register of the
/// sweep when even that is brighter), k = the intensity slope around c_0 and
/// V_p = min((c_0 - min_register) / (saturated_intensity - I_A), max_loop_gain / k).
/// Throws Error(kInvalidArgument) for bad options, fewer than 3 points, registers not strictly
/// increasing, or non-finite / negative means.
[[nodiscard]] ControllerSetpoint ChooseSetpoint(std::span<const IntegrationSweepPoint> sweep,
                                                const SetpointOptions& options = {});

/// Validates the options and builds the controller of `options.kind`.
[[nodiscard]] std::unique_ptr<IntegrationTimeController> MakeController(
    const ControllerOptions& options);

}  // namespace tofcam
