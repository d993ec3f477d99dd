#include "tofcam/pipeline/pipeline.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <utility>

#include "../filters/filter_internal.h"
#include "fused_pass.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/filters/pixel_filters.h"
#include "validate_section.h"

namespace tofcam {
using pipeline_internal::ValidateSection;

namespace {

// src's pixels into dst, in dst's own buffer once it has src's size (every frame after the first).
void CopyPixels(const Image<float>& src, Image<float>& dst) {
  if (!dst.SameSize(src)) dst = Image<float>(src.width(), src.height());
  std::copy(src.data(), src.data() + src.size(), dst.data());
}

// The accuracy threshold's kHighDeltaL judged again on the frame's current ΔL, in its flags and
// in the filter flags (a stage after the fused pass changed ΔL). `raised` is scratch, reused.
void JudgeDeltaLAgain(const AccuracyThresholdOptions& o, MetricFrame& m,
                      Image<PixelFlags>& filter_flags, Image<PixelFlags>& raised) {
  const auto high = static_cast<std::uint16_t>(Flag::kHighDeltaL);
  const auto keep = static_cast<std::uint16_t>(~high);
  if (!raised.SameSize(m.radial_distance_m)) raised = Image<PixelFlags>(m.width(), m.height());
  std::fill(raised.data(), raised.data() + raised.size(), PixelFlags());
  filters_internal::AccuracyInto(m, o, raised);
  for (std::size_t i = 0; i < raised.size(); ++i) {
    m.flags[i] = PixelFlags(
        static_cast<std::uint16_t>((m.flags[i].bits() & keep) | (raised[i].bits() & high)));
    filter_flags[i] = PixelFlags(
        static_cast<std::uint16_t>((filter_flags[i].bits() & keep) | (raised[i].bits() & high)));
  }
}

}  // namespace

void PipelineOptions::Validate() const {
  ValidateSection("metric_conversion", [&] { metric.Validate(); });
  ValidateSection("calibration", [&] {
    if (calibration) calibration->Validate();
  });
  ValidateSection("scattering", [&] { scattering.Validate(); });
  ValidateSection("accuracy", [&] { accuracy.Validate(); });
  ValidateSection("filters.range", [&] { filters.range.Validate(); });
  ValidateSection("filters.amplitude", [&] { filters.amplitude.Validate(); });
  ValidateSection("filters.saturation", [&] { filters.saturation.Validate(); });
  ValidateSection("filters.accuracy", [&] { filters.accuracy.Validate(); });
  ValidateSection("filters.flying_pixel", [&] { filters.flying_pixel.Validate(); });
  ValidateSection("filters.jump_edge", [&] { filters.jump_edge.Validate(); });
  ValidateSection("filters.weingarten", [&] { filters.weingarten.Validate(); });
  ValidateSection("filters.confidence", [&] { filters.confidence.Validate(); });
  if (filters.accuracy_enabled && !accuracy_enabled) {
    throw Error(ErrorCode::kInvalidArgument,
                "filters.accuracy.enabled needs accuracy.enabled (the filter reads ΔL)");
  }
  ValidateSection("uncertainty", [&] { uncertainty.Validate(); });
  if (uncertainty_enabled && !accuracy_enabled) {
    throw Error(ErrorCode::kInvalidArgument,
                "uncertainty.enabled needs accuracy.enabled (the uncertainty starts from ΔL)");
  }
  ValidateSection("prediction", [&] { prediction.Validate(); });
  if (prediction_enabled && !accuracy_enabled) {
    throw Error(ErrorCode::kInvalidArgument,
                "prediction.enabled needs accuracy.enabled (the pairs are weighted by ΔL)");
  }
  if (prediction_enabled && denoise_enabled) {
    // Denoised readings are means over each 3x3 and share most of their readings, and their ΔL
    // is the mean's σ: the pairs would be far from independent and the prediction would hold
    // the centre's own reading, so σ_p and the posterior would be wrong.
    throw Error(ErrorCode::kInvalidArgument,
                "prediction.enabled and denoise.enabled exclude each other (the prediction needs "
                "independent readings; denoised ones share their neighbours')");
  }
  if (prediction_enabled && !uncertainty_enabled && !prediction_combine) {
    throw Error(ErrorCode::kInvalidArgument,
                "prediction.enabled without uncertainty.enabled or prediction.combine: nothing "
                "would read the prediction");
  }
  if (uncertainty.judge_combination && !(prediction_enabled && prediction_combine)) {
    throw Error(ErrorCode::kInvalidArgument,
                "uncertainty.judge_combination needs prediction.enabled and prediction.combine "
                "(it judges the combination the pipeline delivers)");
  }
  ValidateSection("denoise", [&] { denoise.Validate(); });
  if (denoise_enabled && !accuracy_enabled) {
    throw Error(ErrorCode::kInvalidArgument,
                "denoise.enabled needs accuracy.enabled (the weights are 1 / ΔL²)");
  }
  ValidateSection("smoothing", [&] { smoothing.Validate(); });
  ValidateSection("temporal", [&] { temporal.Validate(); });
  ValidateSection("frame_pair", [&] {
    frame_pair.Validate();
    if (!(alternate_modulation_frequency_hz >= 0.0) ||
        !std::isfinite(alternate_modulation_frequency_hz)) {
      throw Error(ErrorCode::kInvalidArgument,
                  "alternate_modulation_frequency_hz must be 0 (none) or a frequency > 0");
    }
    if (alternate_calibration) {
      if (alternate_modulation_frequency_hz == 0.0) {
        throw Error(ErrorCode::kInvalidArgument,
                    "alternate_calibration is set but alternate_modulation_frequency_hz is 0");
      }
      alternate_calibration->Validate();
    }
  });
  ValidateSection("frame_pair", [&] {
    if (hdr_exposure_ratio != 0.0 && !(hdr_exposure_ratio >= 1.5 && hdr_exposure_ratio <= 64.0)) {
      throw Error(ErrorCode::kInvalidArgument,
                  "hdr_exposure_ratio must be 0 (off) or in [1.5, 64], got " +
                      std::to_string(hdr_exposure_ratio));
    }
    if (hdr_exposure_ratio > 0.0 && !frame_pair_enabled) {
      throw Error(ErrorCode::kInvalidArgument,
                  "hdr_exposure_ratio needs frame_pair.enabled (the merge of the two exposures)");
    }
    if (hdr_exposure_ratio > 0.0 && alternate_modulation_frequency_hz > 0.0) {
      throw Error(ErrorCode::kInvalidArgument,
                  "hdr_exposure_ratio and alternate_modulation_frequency_hz both pair "
                  "consecutive frames: use one of them");
    }
  });
  if (frame_pair_enabled && denoise_enabled && frame_pair.two_returns_radius_px > 0 &&
      hdr_exposure_ratio == 0.0) {
    // Denoised readings share their neighbours', so a window's mean of them is far from the
    // mean of independent readings its σ assumes: the pooled check would flag noise.
    throw Error(ErrorCode::kInvalidArgument,
                "denoise.enabled and frame_pair.two_returns_radius_px > 0 exclude each other (the "
                "pooled two-returns check needs independent readings): set "
                "frame_pair.two_returns_radius_px to 0 with denoise");
  }
  if (frame_pair_enabled && !accuracy_enabled) {
    throw Error(ErrorCode::kInvalidArgument,
                "frame_pair.enabled needs accuracy.enabled (the combination weights by ΔL)");
  }
  ValidateSection("controller", [&] { controller.Validate(); });
  ValidateSection("false_color", [&] { color.Validate(); });
  ValidateSection("stats", [&] { stats.Validate(); });
}

Pipeline::Pipeline(PipelineOptions options, const CameraInfo& camera)
    : options_(std::move(options)), camera_(camera) {
  options_.Validate();
  if (options_.calibration) {
    pipeline_internal::CheckCalibrationFits(*options_.calibration, camera_);
  } else if (!options_.calibration_file.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "calibration file '" + options_.calibration_file +
                    "' is not loaded (LoadPipelineCalibration() in tofcam/io/pipeline_config.h)");
  }
  rays_ = MakeRayTable(camera_.intrinsics);
  if (options_.filters.jump_edge_enabled || options_.filters.weingarten_enabled) {
    prepared_rays_ = std::make_shared<const filters_internal::PreparedRays>(
        filters_internal::PrepareRays(rays_, options_.filters));
  }
  table_ = pipeline_internal::PrepareTable(options_.calibration, camera_);
  if (options_.alternate_calibration) {
    // The alternate calibration must fit the same camera running at the alternate frequency.
    CameraInfo alternate = camera_;
    alternate.modulation_frequency_hz = options_.alternate_modulation_frequency_hz;
    pipeline_internal::CheckCalibrationFits(*options_.alternate_calibration, alternate);
    alternate_table_ = pipeline_internal::PrepareTable(options_.alternate_calibration, alternate);
  } else if (options_.calibration && options_.alternate_modulation_frequency_hz > 0.0) {
    throw Error(ErrorCode::kInvalidArgument,
                "the pipeline alternates to " +
                    std::to_string(options_.alternate_modulation_frequency_hz) +
                    " Hz but the calibration was made at " +
                    std::to_string(options_.calibration->modulation_frequency_hz) +
                    " Hz only: calibrate at the alternate frequency too (alternate_calibration) "
                    "or run without a calibration");
  }

  // The controller may not ask for a register the camera refuses; its own lower bound is 1.
  ControllerOptions& c = options_.controller;
  const int lo = std::max({c.min_register, camera_.min_integration_register, 1});
  int hi = std::min(c.max_register, camera_.max_integration_register);
  const bool camera_has_register = camera_.max_integration_register >= 1;
  if (camera_has_register && options_.controller_enabled) {
    // Camera rate: the frame (integration + readout) must fit the requested period.
    c.frame_rate_hz = c.frame_rate_hz > 0.0 ? c.frame_rate_hz : camera_.max_frame_rate_hz;
    const int fps_max = MaxRegisterForFrameRate(camera_, c.frame_rate_hz);
    if (lo > fps_max) {
      throw Error(ErrorCode::kInvalidArgument,
                  "controller.min_register " + std::to_string(lo) + " does not fit " +
                      std::to_string(c.frame_rate_hz) + " frames/s (at most register " +
                      std::to_string(fps_max) + ")");
    }
    hi = std::min(hi, fps_max);
  }
  if (!camera_has_register) {
    // Recordings and imported real-camera files have no integration time to set: nothing to
    // control, so the loop stays open instead of refusing the source.
    options_.controller_enabled = false;
  } else if (lo > hi) {
    throw Error(ErrorCode::kInvalidArgument,
                "controller registers [" + std::to_string(c.min_register) + ", " +
                    std::to_string(c.max_register) + "] and the camera's [" +
                    std::to_string(camera_.min_integration_register) + ", " +
                    std::to_string(camera_.max_integration_register) + "] do not overlap");
  }
  if (camera_has_register) {
    c.min_register = lo;
    c.max_register = hi;
    c.bias_register = std::clamp(c.bias_register, lo, hi);
  }
  if (options_.controller_enabled) controller_ = MakeController(c);
  hdr_base_register_ = c.bias_register;
  if (options_.temporal_enabled) temporal_.emplace(options_.temporal);
  // Frames that differ only in integration time are an HDR pair only when the pipeline alternates
  // exposures; otherwise the controller's next step is not a second exposure of the same scene.
  if (options_.frame_pair_enabled) {
    pair_.emplace(options_.frame_pair, /*pair_exposures=*/options_.hdr_exposure_ratio > 0.0);
  }

  options_.stats.intensity_roi = c.roi;
  options_.stats.intensity_exclude_flags = c.exclude_flags;
  options_.stats.intensity_clipped = c.clipped_intensity;
}

Pipeline::~Pipeline() = default;
Pipeline::Pipeline(Pipeline&&) noexcept = default;
Pipeline& Pipeline::operator=(Pipeline&&) noexcept = default;

void Pipeline::Process(const Frame& camera_frame, PipelineResult& result) {
  // Scattering happens in the optics, before anything the camera computes: it is undone first.
  if (options_.scattering_enabled) {
    CompensateScatteringInto(camera_frame, options_.scattering, compensated_);
  }
  const Frame& frame = options_.scattering_enabled ? compensated_ : camera_frame;
  if (frame.width() != camera_.width() || frame.height() != camera_.height()) {
    throw Error(ErrorCode::kMismatch, "frame is " + std::to_string(frame.width()) + "x" +
                                          std::to_string(frame.height()) + ", the camera " +
                                          camera_.model + " is " + std::to_string(camera_.width()) +
                                          "x" + std::to_string(camera_.height()));
  }
  // Stages 1-3, the per-pixel filters and (when no neighbourhood filter follows) the cloud in
  // one fused pass into the result's buffers: no allocation once their sizes are stable.
  const FilterSetOptions& filters = options_.filters;
  const bool neighbourhood =
      filters.flying_pixel_enabled || filters.jump_edge_enabled || filters.weingarten_enabled;
  // Smoothing and the temporal filter change distances after the filters: the cloud follows.
  const bool confidence = filters.confidence_enabled && !frame.confidence.empty();
  // A noise model with an edge term makes ΔL a neighbourhood quantity: finished after the pass.
  const bool edge_term = options_.accuracy_enabled && options_.accuracy.model.has_value() &&
                         options_.accuracy.model->uses_edges();
  const bool late_cloud = edge_term || neighbourhood || confidence || options_.denoise_enabled ||
                          options_.smoothing_enabled || temporal_.has_value() ||
                          pair_.has_value() || options_.uncertainty_enabled ||
                          options_.prediction_enabled;
  MetricFrame& m = result.frame;
  pipeline_internal::FusedStages s;
  s.metric = options_.metric;
  s.calibration = options_.calibration ? &*options_.calibration : nullptr;
  s.table = table_ ? &*table_ : nullptr;
  s.table_range_m = UnambiguousRangeM(camera_.modulation_frequency_hz);
  // A frame at another frequency than the camera's is taken for one at the alternate frequency
  // when there is one (its own calibration, or none); a calibration's own check (eq. 1) refuses
  // a frame at a frequency it was not made for.
  const bool at_alternate = options_.alternate_modulation_frequency_hz > 0.0 &&
                            frame.info.modulation_frequency_hz != camera_.modulation_frequency_hz;
  if (at_alternate) {
    // A frame at the alternate frequency: its own calibration, or none.
    const std::optional<OffsetCalibration>& alt = options_.alternate_calibration;
    s.calibration = alt ? &*alt : nullptr;
    s.table = alternate_table_ ? &*alternate_table_ : nullptr;
    s.table_range_m = UnambiguousRangeM(options_.alternate_modulation_frequency_hz);
  }
  s.accuracy = options_.accuracy_enabled ? &options_.accuracy : nullptr;
  s.filters = filters;
  s.rays = &rays_;
  s.cloud = options_.cloud_enabled && !late_cloud ? &options_.cloud : nullptr;
  pipeline_internal::FusedOutputs out;
  out.frame = &m;
  out.input_flags = &result.input_flags;
  out.filter_flags = &result.filter_flags;
  out.cloud = &result.cloud;
  pipeline_internal::RunFusedPass(frame, s, out);
  if (edge_term) {
    ApplyNoiseModelEdgeTerm(*options_.accuracy.model, m.radial_distance_m, result.input_flags,
                            m.delta_l_m);
    // The pass judged ΔL without the edge term: judge again.
    if (filters.accuracy_enabled)
      JudgeDeltaLAgain(filters.accuracy, m, result.filter_flags, rejudged_);
  }
  if (confidence) {
    // The vendor channel is read by few sources, so it stays out of the fused pass.
    ConfidenceThresholdInto(m, filters.confidence, result.filter_flags);
    MergeFlags(m, result.filter_flags);
  }
  // HDR: the controller judges the base exposure alone, before the merge could hide its
  // clipped or dark pixels behind the long exposure's.
  const bool hdr = options_.hdr_exposure_ratio > 0.0;
  const bool hdr_long = hdr && hdr_long_;
  if (hdr && !hdr_long) {
    hdr_base_register_ = controller_ ? controller_->Update(m) : m.info.integration_time_register;
  }
  // Denoising: before the pair (which then unwraps the means) and the neighbourhood filters.
  if (options_.denoise_enabled) {
    DenoiseInto(m, rays_, options_.denoise, denoised_);
    // Copied, not swapped: the result's buffers stay the ones the caller (or a NumPy view of
    // them) holds, and none of the pipeline's own buffers ends up in the result.
    CopyPixels(denoised_.radial_distance_m, m.radial_distance_m);
    CopyPixels(denoised_.delta_l_m, m.delta_l_m);
    if (!m.amplitude.empty()) CopyPixels(denoised_.amplitude, m.amplitude);
    // A pixel rejected only for its single reading's ΔL is judged on its mean's.
    if (filters.accuracy_enabled)
      JudgeDeltaLAgain(filters.accuracy, m, result.filter_flags, rejudged_);
  }
  // Dual-frequency unwrapping or the HDR merge: after the per-pixel filters (each frame's own ΔL
  // judged it), before the neighbourhood filters (which then see the combined distances).
  result.combined = pair_ ? pair_->Process(m) : false;
  if (neighbourhood) {
    // m.flags = input flags | per-pixel filter bits, what the neighbourhood filters must treat
    // as rejected (as in ApplyFilters); they OR into the filter flags.
    filters_internal::NeighbourhoodFiltersInto(m, rays_, prepared_rays_.get(), filters,
                                               result.filter_flags);
    MergeFlags(m, result.filter_flags);
  }
  const NeighbourPrediction* prediction = nullptr;
  if (options_.prediction_enabled) {
    PredictFromNeighboursInto(m, options_.prediction, prediction_);
    prediction = &prediction_;
  }
  if (options_.uncertainty_enabled) {
    UncertaintyFilterInto(m, options_.uncertainty, uncertain_, prediction);
    MergeFlags(m, uncertain_);
    for (std::size_t i = 0; i < uncertain_.size(); ++i) result.filter_flags[i] |= uncertain_[i];
  }
  // The pixels still kept take the combination of reading and prediction, in place.
  if (prediction != nullptr && options_.prediction_combine) {
    CombineWithPredictionInto(m, *prediction, m.radial_distance_m);
  }
  if (options_.smoothing_enabled) {
    SpatialFilterInto(m, options_.smoothing, smoothed_);
    CopyPixels(smoothed_, m.radial_distance_m);  // in place, as the denoised channels above
  }
  if (temporal_) temporal_->Process(m);
  if (late_cloud && options_.cloud_enabled) {
    MakePointCloudInto(m, rays_, result.cloud, options_.cloud);
  }
  if (!options_.cloud_enabled) result.cloud = PointCloud();

  // Frame t sets the register of frame t + 1 (paper section III-A).
  if (hdr) {
    result.next_integration_register =
        hdr_long ? hdr_base_register_ : LongExposureRegister(hdr_base_register_);
    hdr_long_ = !hdr_long;
  } else {
    result.next_integration_register =
        controller_ ? controller_->Update(m) : m.info.integration_time_register;
  }

  result.next_modulation_frequency_hz = m.info.modulation_frequency_hz;
  if (options_.alternate_modulation_frequency_hz > 0.0) {
    result.next_modulation_frequency_hz =
        at_alternate ? camera_.modulation_frequency_hz : options_.alternate_modulation_frequency_hz;
  }
  result.stats = ComputeFrameStats(m, options_.stats);
  result.stats.next_integration_register = result.next_integration_register;
}

PipelineResult Pipeline::Process(const Frame& frame) {
  PipelineResult result;
  Process(frame, result);
  return result;
}

int Pipeline::InitialIntegrationRegister() const noexcept {
  return options_.controller.bias_register;
}

void Pipeline::ResetTemporal() {
  if (temporal_) temporal_->Reset();
  if (pair_) pair_->Reset();
}

void Pipeline::ResetController(int reg) {
  if (controller_) controller_->Reset(reg);
  hdr_base_register_ = reg;
  hdr_long_ = false;
}

int Pipeline::LongExposureRegister(int base_register) const {
  const ControllerOptions& c = options_.controller;
  const double step_us = camera_.integration_time_step_us;
  if (!(step_us > 0.0)) return base_register;
  // Integration time = base + register x step: the register whose time is ratio x the base's,
  // rounded down (never past the frame rate or the bounds the constructor intersected).
  const double long_us = options_.hdr_exposure_ratio * camera_.IntegrationTimeUs(base_register);
  const double reg = std::floor((long_us - camera_.integration_time_base_us) / step_us);
  return static_cast<int>(std::clamp(reg, static_cast<double>(base_register),
                                     static_cast<double>(std::max(base_register, c.max_register))));
}

void Pipeline::SetTargetIntensity(double target_intensity, int current_register) {
  if (!controller_) {
    throw Error(ErrorCode::kUnsupported, "the controller is off: no set point to change");
  }
  ControllerOptions c = options_.controller;
  c.target_intensity = target_intensity;
  ValidateSection("controller", [&] { c.Validate(); });
  controller_ = MakeController(c);
  controller_->Reset(current_register);
  options_.controller = c;
}

int Pipeline::SetControllerRegister(int reg) {
  if (!controller_) {
    throw Error(ErrorCode::kUnsupported, "the controller is off: no register to set");
  }
  ControllerOptions& c = options_.controller;
  c.bias_register = std::clamp(reg, c.min_register, c.max_register);
  controller_ = MakeController(c);
  controller_->Reset(c.bias_register);
  return c.bias_register;
}

std::string_view Pipeline::ControllerName() const {
  return controller_ ? controller_->Name() : std::string_view();
}

Image<Rgb8> Pipeline::Render(const PipelineResult& result, const Image<PixelFlags>& flags) const {
  const MetricFrame& m = result.frame;
  const double range_m = UnambiguousRangeM(m.info.modulation_frequency_hz);
  Image<Rgb8> image =
      FalseColorImage(m.radial_distance_m, flags, m.amplitude, range_m, options_.color);
  // AddLegend needs 16 px for its labels; tiny test images go without.
  if (!options_.color_legend || image.width() < 16) return image;
  const double far_m = options_.color.far_m > 0 ? options_.color.far_m : range_m;
  return AddLegend(image, options_.color.near_m, far_m);
}

Image<Rgb8> Pipeline::RenderRaw(const PipelineResult& result) const {
  return Render(result, result.input_flags);
}

Image<Rgb8> Pipeline::RenderFiltered(const PipelineResult& result) const {
  return Render(result, result.frame.flags);
}

}  // namespace tofcam
