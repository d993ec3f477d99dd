#pragma once
/// \file
/// The paper's pipeline in one object: registers -> metric (stage 1) -> per-pixel calibration,
/// eq. 1 (stage 2) -> ΔL, eq. 2 (stage 3) -> filters (stage 5) -> integration-time controller
/// (stage 4; frame t sets the register of frame t + 1) -> organised point cloud (stage 6), plus
/// per-frame statistics. False colour (stage 7) is rendered on request, for display only.
/// See docs/pipeline.md.
///
/// Typical loop:
///     Pipeline pipeline(options, camera.Info());
///     camera.SetIntegrationTimeRegister(pipeline.InitialIntegrationRegister());
///     PipelineResult result;
///     while (auto frame = camera.Grab()) {
///       pipeline.Process(*frame, result);
///       camera.SetIntegrationTimeRegister(result.next_integration_register);
///     }

#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "tofcam/accuracy/delta_l.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/color/false_color.h"
#include "tofcam/control/integration_time_controller.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/rgb.h"
#include "tofcam/filters/denoise.h"
#include "tofcam/filters/filter_set.h"
#include "tofcam/filters/frame_pair.h"
#include "tofcam/filters/neighbour_prediction.h"
#include "tofcam/filters/spatial_filter.h"
#include "tofcam/filters/temporal_filter.h"
#include "tofcam/filters/uncertainty.h"
#include "tofcam/optics/scattering.h"
#include "tofcam/pipeline/frame_stats.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {
namespace filters_internal {
struct PreparedRays;  // src/filters/filter_internal.h
}  // namespace filters_internal

/// Every stage's options. Defaults: no calibration, ΔL on, the paper's accuracy threshold and
/// saturation filters on, the paper's P-controller (MayProportional) on, point cloud on.
struct PipelineOptions {
  MetricConversionOptions metric;

  /// Calibration file (tofcam/io/calibration_file.h); "" = none. The core library does not read
  /// files: LoadPipelineCalibration() (tofcam/io/pipeline_config.h) loads it into `calibration`.
  std::string calibration_file;
  /// A loaded calibration; takes precedence over `calibration_file`. Must fit the camera.
  std::optional<OffsetCalibration> calibration;

  /// Scattering compensation on the camera's registers before every other stage
  /// (tofcam/optics/scattering.h; not in the paper). Off by default; the lobes come from
  /// EstimateScatteringPsf on a calibration scene.
  bool scattering_enabled = false;
  ScatteringOptions scattering;

  /// Compute ΔL (eq. 2) per pixel. Needed by the accuracy filter and the mean-ΔL statistic.
  bool accuracy_enabled = true;
  AccuracyOptions accuracy;

  FilterSetOptions filters;

  /// Denoising before the frame pair and the neighbourhood filters (tofcam/filters/denoise.h;
  /// not in the paper): each usable pixel's distance and amplitude become the inverse-variance
  /// weighted mean of its own surface's neighbours, its ΔL that mean's σ, and the accuracy
  /// threshold judges the lowered ΔL again. Needs ΔL (accuracy.enabled). Off by default.
  bool denoise_enabled = false;
  DenoiseOptions denoise;

  /// The neighbours' prediction (tofcam/filters/neighbour_prediction.h; not in the paper),
  /// after the frame pair and the neighbourhood filters: each pixel's distance predicted from
  /// the symmetric pairs of its window. The uncertainty, when enabled, then judges a predicted
  /// pixel's reading by its residual against the prediction instead of by its ΔL alone. Needs
  /// ΔL, and the uncertainty or `prediction_combine` (something must read it); excludes
  /// `denoise_enabled` (denoised readings are not independent). Off by default.
  bool prediction_enabled = false;
  NeighbourPredictionOptions prediction;
  /// With the prediction: every pixel that is still kept after the uncertainty and has a
  /// prediction is delivered as the combination of its reading and the prediction
  /// (CombineWithPrediction; ΔL unchanged), before the smoothing, the temporal filter and the
  /// cloud.
  bool prediction_combine = true;

  /// The combined uncertainty (ΔL plus edges, tofcam/filters/uncertainty.h) with one threshold
  /// in metres, after the other filters: kLowConfidence. Needs ΔL. Off by default.
  bool uncertainty_enabled = false;
  UncertaintyOptions uncertainty;

  /// Edge-preserving spatial smoothing of the kept pixels' distances after the filters (median
  /// or ΔL-weighted bilateral, tofcam/filters/spatial_filter.h). Off by default: the paper has
  /// none.
  bool smoothing_enabled = false;
  SpatialFilterOptions smoothing;
  /// Per-pixel running average over frames, weighted by ΔL and reset on motion, after the
  /// smoothing (tofcam/filters/temporal_filter.h). Off by default.
  bool temporal_enabled = false;
  TemporalFilterOptions temporal;

  /// Dual-frequency unwrapping (tofcam/filters/frame_pair.h; not in the paper): each frame is
  /// combined with the one before when their modulation frequencies differ, after the
  /// per-pixel filters. With `alternate_modulation_frequency_hz` > 0 the result asks for the
  /// camera's frequency and that one in turn (PipelineResult::next_modulation_frequency_hz).
  /// Needs ΔL (accuracy.enabled). Off by default. A calibration is made at one frequency (eq. 1
  /// and the distance correction depend on L): frames at the alternate frequency get
  /// `alternate_calibration`. A calibrated pipeline that alternates needs it (the Pipeline
  /// refuses to leave every other frame uncalibrated); without any calibration both are raw.
  bool frame_pair_enabled = false;
  FramePairOptions frame_pair;
  double alternate_modulation_frequency_hz = 0.0;  ///< Hz, 0 = none; else > 0 and finite.
  /// HDR (two exposures, not in the paper): with a ratio > 0, every other frame is exposed that
  /// many times longer than the controller's register (as long as the camera's frame rate and
  /// the controller's bounds allow) and each frame is merged with the one before
  /// (FramePairCombiner: a pixel one exposure rejects, e.g. clipped or too dark, takes the
  /// other's value; both good are averaged by 1/ΔL²; a disagreement beyond
  /// frame_pair.max_disagreement_sigma, e.g. motion, is kInconsistent). The controller judges
  /// only the base exposures, before the merge and the neighbourhood filters. 0 = off; else in
  /// [1.5, 64]. Needs frame_pair_enabled and no alternate frequency.
  double hdr_exposure_ratio = 0.0;
  /// Calibration file made at `alternate_modulation_frequency_hz`, "" = none; loaded into
  /// `alternate_calibration` by LoadPipelineCalibration() like `calibration_file`.
  std::string alternate_calibration_file;
  /// Calibration made at `alternate_modulation_frequency_hz` (same camera model and size);
  /// unset = frames at that frequency are not calibrated. Must be unset without an alternate
  /// frequency.
  std::optional<OffsetCalibration> alternate_calibration;

  /// Run the integration-time controller. Off: next_integration_register repeats the frame's.
  bool controller_enabled = true;
  /// Bounds are intersected with the camera's register range by the Pipeline.
  ControllerOptions controller;

  bool cloud_enabled = true;  ///< Build the organised point cloud.
  PointCloudOptions cloud;

  FalseColorOptions color;   ///< For RenderRaw / RenderFiltered.
  bool color_legend = true;  ///< Append the legend bar to rendered images (>= 16 px wide).

  FrameStatsOptions stats;  ///< Its intensity ROI / flags are replaced by the controller's.

  /// Validates every stage's options (enabled or not, so a config file cannot hide a bad value);
  /// throws Error(kInvalidArgument) naming the stage and field, e.g. "filters.accuracy: ...".
  /// Also rejects a filter set whose accuracy filter is on while ΔL is off.
  void Validate() const;
};

/// Output of one frame. Reused between frames by Pipeline::Process(frame, result): every buffer
/// is overwritten in place, so a steady loop does not reallocate them.
struct PipelineResult {
  /// Calibrated distances, amplitude, intensity, ΔL (empty when accuracy is off), flags after
  /// all filters, info and truth of the input frame.
  MetricFrame frame;
  /// Flags before the filters (conversion, source and calibration flags): the "raw" view.
  Image<PixelFlags> input_flags;
  /// Flags raised by the filters alone.
  Image<PixelFlags> filter_flags;
  /// Organised cloud in the camera frame; empty when the cloud is off.
  PointCloud cloud;
  FrameStats stats;
  /// Register the controller chose for the next frame, within the camera's range.
  int next_integration_register = 0;
  /// Modulation frequency for the next frame, Hz: the frame's own unless the pipeline
  /// alternates frequencies (PipelineOptions::alternate_modulation_frequency_hz).
  double next_modulation_frequency_hz = 0.0;
  /// True when this frame was combined with the one before (dual-frequency unwrapping).
  bool combined = false;
};

/// The pipeline for one camera. Owns its stages (options, ray table, calibration, controller).
/// Not thread-safe; one instance per camera.
class Pipeline {
 public:
  /// Validates the options against the camera: the calibration must have been made for this
  /// camera (model, size, modulation frequency; Error(kMismatch) naming the field), a
  /// calibration_file without a loaded calibration is Error(kInvalidArgument), the controller's
  /// register bounds are intersected with the camera's (Error(kInvalidArgument) when disjoint).
  Pipeline(PipelineOptions options, const CameraInfo& camera);
  ~Pipeline();
  Pipeline(Pipeline&&) noexcept;
  Pipeline& operator=(Pipeline&&) noexcept;

  /// Runs every stage on `frame` into `result` (see PipelineResult). Throws Error(kMismatch) when
  /// the frame's size differs from the camera's or, in a calibrated pipeline, its modulation
  /// frequency from the one its calibration was made for (the camera's, or with
  /// `alternate_modulation_frequency_hz` the alternate calibration's for a frame at another
  /// frequency); an uncalibrated pipeline converts every frame with the frame's own frequency.
  /// Throws Error(kInvalidArgument) for an inconsistent frame.
  ///
  /// Once `result` holds a frame of this pipeline with the same size and the same channels
  /// (intensity, ground truth), Process writes into its buffers in place: no buffer is replaced,
  /// so pointers into them stay valid and show the new frame. A buffer is replaced (the old one
  /// freed) when the size changes, when a channel comes or goes, or when `result` last came from
  /// a pipeline that keeps other channels (ΔL, the cloud).
  void Process(const Frame& frame, PipelineResult& result);
  /// Same, into a fresh result.
  [[nodiscard]] PipelineResult Process(const Frame& frame);

  /// Register to set before the first frame: the controller's c_0 within the bounds.
  [[nodiscard]] int InitialIntegrationRegister() const noexcept;
  /// Forgets the controller's history (e.g. after the pan unit moved), continuing at `reg`.
  void ResetController(int reg);
  /// Changes the controller's set point I_A while running (e.g. a remote command): the
  /// controller continues from `current_register` (its next output depends on the new I_A from
  /// the next frame on). `target_intensity` in (0, 65532] register units; the histogram and
  /// fixed controllers do not use it. Throws Error(kInvalidArgument) out of range and
  /// Error(kUnsupported) when the controller is off.
  void SetTargetIntensity(double target_intensity, int current_register);
  /// Sets the controller's register c_0 while running: the fixed controller holds it, the
  /// proportional law uses it as its bias, the others continue from it. Clamped to the
  /// controller's bounds; returns the register set. Throws Error(kUnsupported) when the
  /// controller is off.
  int SetControllerRegister(int reg);
  /// Forgets the temporal filter's per-pixel history (e.g. after the pan unit moved).
  void ResetTemporal();

  /// False colour of the distances with only the input flags black (no filters).
  [[nodiscard]] Image<Rgb8> RenderRaw(const PipelineResult& result) const;
  /// False colour after the filters (rejected pixels black).
  [[nodiscard]] Image<Rgb8> RenderFiltered(const PipelineResult& result) const;

  [[nodiscard]] const PipelineOptions& options() const noexcept { return options_; }
  [[nodiscard]] const CameraInfo& camera() const noexcept { return camera_; }
  [[nodiscard]] const RayTable& rays() const noexcept { return rays_; }
  /// Name of the controller ("" when off).
  [[nodiscard]] std::string_view ControllerName() const;

 private:
  [[nodiscard]] Image<Rgb8> Render(const PipelineResult& result,
                                   const Image<PixelFlags>& flags) const;
  // HDR: the register of the long exposure that follows a base exposure at `base_register`.
  [[nodiscard]] int LongExposureRegister(int base_register) const;

  PipelineOptions options_;
  CameraInfo camera_;
  RayTable rays_;
  // What the jump-edge and cell filters derive from rays_ (null when neither is enabled).
  std::shared_ptr<const filters_internal::PreparedRays> prepared_rays_;
  std::optional<DenseDistanceCorrection> table_;            // the calibration's, resampled once
  std::optional<DenseDistanceCorrection> alternate_table_;  // the alternate calibration's
  std::unique_ptr<IntegrationTimeController> controller_;
  std::optional<TemporalFilter> temporal_;
  Image<float> smoothed_;
  DenoisedChannels denoised_;       // the denoising's output, swapped into the frame
  Image<PixelFlags> rejudged_;      // the accuracy threshold judged again (JudgeDeltaLAgain)
  Image<PixelFlags> uncertain_;     // the uncertainty filter's flags (UncertaintyFilterInto)
  NeighbourPrediction prediction_;  // PredictFromNeighboursInto's output, reused per frame
  Frame compensated_;               // the scattering compensation's output, reused per frame
  std::optional<FramePairCombiner> pair_;
  // HDR: the register the controller chose at the last base exposure, and whether the frame
  // being processed is the long one.
  int hdr_base_register_ = 0;
  bool hdr_long_ = false;
};

}  // namespace tofcam
