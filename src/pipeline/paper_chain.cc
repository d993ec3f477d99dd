#include "tofcam/pipeline/paper_chain.h"

#include <string>
#include <utility>

#include "fused_pass.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "validate_section.h"

namespace tofcam {
using pipeline_internal::ValidateSection;

void PaperChainOptions::Validate() const {
  ValidateSection("metric_conversion", [&] { metric.Validate(); });
  ValidateSection("calibration", [&] {
    if (calibration) calibration->Validate();
  });
  ValidateSection("accuracy", [&] { accuracy.Validate(); });
  ValidateSection("threshold", [&] { threshold.Validate(); });
}

PaperChain::PaperChain(PaperChainOptions options, const CameraInfo& camera)
    : options_(std::move(options)), camera_(camera) {
  options_.Validate();
  if (options_.calibration) pipeline_internal::CheckCalibrationFits(*options_.calibration, camera_);
  rays_ = MakeRayTable(camera_.intrinsics);
  table_ = pipeline_internal::PrepareTable(options_.calibration, camera_);
}

void PaperChain::Process(const Frame& frame, MetricFrame& out, PointCloud& cloud) {
  if (frame.width() != camera_.width() || frame.height() != camera_.height()) {
    throw Error(ErrorCode::kMismatch, "frame is " + std::to_string(frame.width()) + "x" +
                                          std::to_string(frame.height()) + ", the camera " +
                                          camera_.model + " is " + std::to_string(camera_.width()) +
                                          "x" + std::to_string(camera_.height()));
  }
  pipeline_internal::FusedStages s;
  s.metric = options_.metric;
  s.calibration = options_.calibration ? &*options_.calibration : nullptr;
  s.table = table_ ? &*table_ : nullptr;
  s.table_range_m = UnambiguousRangeM(camera_.modulation_frequency_hz);
  s.accuracy = &options_.accuracy;
  s.filters.saturation_enabled = false;
  s.filters.accuracy_enabled = true;
  s.filters.accuracy = options_.threshold;
  s.rays = &rays_;
  s.cloud = &options_.cloud;
  pipeline_internal::FusedOutputs o;
  o.frame = &out;
  o.cloud = &cloud;
  pipeline_internal::RunFusedPass(frame, s, o);
}

}  // namespace tofcam
