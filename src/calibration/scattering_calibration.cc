#include "tofcam/calibration/scattering_calibration.h"

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/filters/pixel_filters.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {
namespace {

Frame GrabOrThrow(Camera& camera, const char* which) {
  std::optional<Frame> frame = camera.Grab();
  if (!frame) {
    throw Error(ErrorCode::kIo,
                std::string("scattering calibration: the ") + which + " camera stopped delivering");
  }
  return std::move(*frame);
}

double SaturatedFraction(const Frame& frame) {
  const MetricFrame m = ConvertToMetric(frame);
  const Image<PixelFlags> flags = SaturationFilter(m, SaturationOptions{});
  long long clipped = 0;
  for (std::size_t i = 0; i < flags.size(); ++i) {
    clipped += flags[i].Has(Flag::kSaturated) || m.flags[i].Has(Flag::kSaturated);
  }
  return flags.size() ? static_cast<double>(clipped) / flags.size() : 0.0;
}

void Progress(const ProgressCallback& progress, int frame, int total, std::string message) {
  if (progress) progress(CalibrationProgress{"scattering", frame, total, std::move(message)});
}

}  // namespace

void ScatteringCalibrationOptions::Validate() const {
  if (frames < 1 || frames > 10000) {
    throw Error(ErrorCode::kInvalidArgument, "scattering calibration frames = " +
                                                 std::to_string(frames) + " must be in [1, 10000]");
  }
  if (integration_time_register < 0) {
    throw Error(ErrorCode::kInvalidArgument,
                "scattering calibration register = " + std::to_string(integration_time_register) +
                    " must be >= 0 (0 = chosen)");
  }
  if (!(max_saturated_fraction >= 0.0 && max_saturated_fraction < 1.0)) {
    throw Error(ErrorCode::kInvalidArgument, "scattering calibration max_saturated_fraction = " +
                                                 std::to_string(max_saturated_fraction) +
                                                 " must be in [0, 1)");
  }
  fit.Validate();
}

ScatteringCalibration CalibrateScattering(Camera& without, Camera& with,
                                          const ScatteringCalibrationOptions& options,
                                          const ProgressCallback& progress) {
  options.Validate();
  const CameraInfo& a = without.Info();
  const CameraInfo& b = with.Info();
  if (a.width() != b.width() || a.height() != b.height()) {
    throw Error(ErrorCode::kInvalidArgument,
                "scattering calibration: the wall camera is " + std::to_string(a.width()) + "x" +
                    std::to_string(a.height()) + ", the card camera " + std::to_string(b.width()) +
                    "x" + std::to_string(b.height()));
  }
  const int lo = std::max(a.min_integration_register, b.min_integration_register);
  const int hi = std::min(a.max_integration_register, b.max_integration_register);
  int reg = options.integration_time_register;
  if (reg > 0) {
    if (reg < lo || reg > hi) {
      throw Error(ErrorCode::kInvalidArgument, "scattering calibration register " +
                                                   std::to_string(reg) +
                                                   " is outside the cameras' range " +
                                                   std::to_string(lo) + ".." + std::to_string(hi));
    }
    with.SetIntegrationTimeRegister(reg);
  } else {
    // The card is the brightest thing in view: shorten until it no longer clips.
    reg = std::clamp(with.IntegrationTimeRegister(), lo, hi);
    for (;;) {
      with.SetIntegrationTimeRegister(reg);
      const double clipped = SaturatedFraction(GrabOrThrow(with, "card"));
      Progress(progress, 0, options.frames,
               "register " + std::to_string(reg) + ": " + std::to_string(100.0 * clipped) +
                   " % of the card scene clipped");
      if (clipped <= options.max_saturated_fraction) break;
      if (reg <= lo) {
        throw Error(ErrorCode::kInvalidArgument,
                    "scattering calibration: the card clips even at register " +
                        std::to_string(reg) + " (move it further from the lens)");
      }
      reg = std::max(lo, reg / 2);
    }
  }
  without.SetIntegrationTimeRegister(reg);
  std::vector<Frame> wall, card;
  // The first frame after a register change may still be exposed at the old one.
  (void)GrabOrThrow(without, "wall");
  (void)GrabOrThrow(with, "card");
  for (int k = 1; k <= options.frames; ++k) {
    wall.push_back(GrabOrThrow(without, "wall"));
    card.push_back(GrabOrThrow(with, "card"));
    Progress(progress, k, options.frames, "grabbed " + std::to_string(k) + " frame pairs");
  }
  const ScatteringFit fit = EstimateScatteringPsf(wall, card, options.fit);
  ScatteringCalibration out;
  out.lobes = fit.psf.lobes;
  out.frames = options.frames;
  out.integration_time_register = reg;
  out.target_pixels = fit.target_pixels;
  out.fit_pixels = fit.fit_pixels;
  out.explained_fraction = fit.explained_fraction;
  out.Validate();
  return out;
}

}  // namespace tofcam
