#include "tofcam/pipeline/pipeline.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/filters/pixel_filters.h"

namespace tofcam {
namespace {

// Runs `validate` and prefixes its message with the option section, so a message from a stage
// ("max_delta_l_m must be ...") says where in the configuration the value lives.
template <typename F>
void ValidateSection(const char* section, F&& validate) {
  try {
    validate();
  } catch (const Error& e) {
    throw Error(e.code(), std::string(section) + ": " + e.what());
  }
}

void CheckCalibrationFits(const OffsetCalibration& c, const CameraInfo& camera) {
  if (c.camera_model != camera.model) {
    throw Error(ErrorCode::kMismatch, "calibration is for camera model '" + c.camera_model +
                                          "', the camera is '" + camera.model + "'");
  }
  if (c.width != camera.width() || c.height != camera.height()) {
    throw Error(ErrorCode::kMismatch, "calibration is " + std::to_string(c.width) + "x" +
                                          std::to_string(c.height) + ", the camera is " +
                                          std::to_string(camera.width()) + "x" +
                                          std::to_string(camera.height()));
  }
  if (!(std::abs(c.modulation_frequency_hz - camera.modulation_frequency_hz) <=
        1e-9 * camera.modulation_frequency_hz)) {
    throw Error(ErrorCode::kMismatch, "calibration was made at " +
                                          std::to_string(c.modulation_frequency_hz) +
                                          " Hz, the camera runs at " +
                                          std::to_string(camera.modulation_frequency_hz) + " Hz");
  }
}

// Copies `src` into `dst`, reusing dst's buffer when the sizes agree (Image's copy assignment
// goes through std::vector's, which keeps the capacity).
void CopyInto(const Image<PixelFlags>& src, Image<PixelFlags>& dst) { dst = src; }

}  // namespace

void PipelineOptions::Validate() const {
  ValidateSection("metric_conversion", [&] { metric.Validate(); });
  ValidateSection("calibration", [&] {
    if (calibration) calibration->Validate();
  });
  ValidateSection("accuracy", [&] { accuracy.Validate(); });
  ValidateSection("filters.range", [&] { filters.range.Validate(); });
  ValidateSection("filters.amplitude", [&] { filters.amplitude.Validate(); });
  ValidateSection("filters.saturation", [&] { filters.saturation.Validate(); });
  ValidateSection("filters.accuracy", [&] { filters.accuracy.Validate(); });
  ValidateSection("filters.flying_pixel", [&] { filters.flying_pixel.Validate(); });
  ValidateSection("filters.jump_edge", [&] { filters.jump_edge.Validate(); });
  ValidateSection("filters.weingarten", [&] { filters.weingarten.Validate(); });
  if (filters.accuracy_enabled && !accuracy_enabled) {
    throw Error(ErrorCode::kInvalidArgument,
                "filters.accuracy.enabled needs accuracy.enabled (the filter reads ΔL)");
  }
  ValidateSection("controller", [&] { controller.Validate(); });
  ValidateSection("false_color", [&] { color.Validate(); });
  ValidateSection("stats", [&] { stats.Validate(); });
}

Pipeline::Pipeline(PipelineOptions options, const CameraInfo& camera)
    : options_(std::move(options)), camera_(camera) {
  options_.Validate();
  if (options_.calibration) {
    CheckCalibrationFits(*options_.calibration, camera_);
  } else if (!options_.calibration_file.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "calibration file '" + options_.calibration_file +
                    "' is not loaded (LoadPipelineCalibration() in tofcam/io/pipeline_config.h)");
  }
  rays_ = MakeRayTable(camera_.intrinsics);

  // The controller may not ask for a register the camera refuses; its own lower bound is 1.
  ControllerOptions& c = options_.controller;
  const int lo = std::max({c.min_register, camera_.min_integration_register, 1});
  const int hi = std::min(c.max_register, camera_.max_integration_register);
  const bool camera_has_register = camera_.max_integration_register >= 1;
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

  options_.stats.intensity_roi = c.roi;
  options_.stats.intensity_exclude_flags = c.exclude_flags;
}

Pipeline::~Pipeline() = default;
Pipeline::Pipeline(Pipeline&&) noexcept = default;
Pipeline& Pipeline::operator=(Pipeline&&) noexcept = default;

void Pipeline::Process(const Frame& frame, PipelineResult& result) {
  if (frame.width() != camera_.width() || frame.height() != camera_.height()) {
    throw Error(ErrorCode::kMismatch, "frame is " + std::to_string(frame.width()) + "x" +
                                          std::to_string(frame.height()) + ", the camera " +
                                          camera_.model + " is " + std::to_string(camera_.width()) +
                                          "x" + std::to_string(camera_.height()));
  }
  MetricFrame& m = result.frame;
  ConvertToMetricInto(frame, options_.metric, m);
  if (options_.calibration) ApplyCalibrationInPlace(m, *options_.calibration);
  if (options_.accuracy_enabled) {
    ComputeDeltaLInto(m, options_.accuracy, m.delta_l_m);
  } else {
    m.delta_l_m = Image<float>();
  }
  CopyInto(m.flags, result.input_flags);
  result.filter_flags = ApplyFilters(m, rays_, options_.filters);
  MergeFlags(m, result.filter_flags);

  // Frame t sets the register of frame t + 1 (paper section III-A).
  result.next_integration_register =
      controller_ ? controller_->Update(m) : m.info.integration_time_register;

  if (options_.cloud_enabled) {
    MakePointCloudInto(m, rays_, result.cloud, options_.cloud);
  } else {
    result.cloud = PointCloud();
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

void Pipeline::ResetController(int reg) {
  if (controller_) controller_->Reset(reg);
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
