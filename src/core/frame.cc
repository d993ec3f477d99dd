#include "tofcam/core/frame.h"

#include <cmath>

#include "tofcam/core/error.h"

namespace tofcam {

void ValidateFrame(const Frame& frame, const std::string& what) {
  const int w = frame.distance.width();
  const int h = frame.distance.height();
  if (w <= 0 || h <= 0) throw Error(ErrorCode::kInvalidArgument, what + ": empty distance image");
  if (!frame.amplitude.SameSize(w, h) || !frame.intensity.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument,
                what + ": distance, amplitude and intensity images differ in size");
  }
  const auto same_or_empty = [w, h](const Image<float>& image) {
    return image.empty() || image.SameSize(w, h);
  };
  if (frame.truth &&
      (!frame.truth->radial_distance_m.SameSize(w, h) || !frame.truth->causes.SameSize(w, h) ||
       !same_or_empty(frame.truth->sigma_m) || !same_or_empty(frame.truth->footprint_near_m) ||
       !frame.truth->footprint_far_m.SameSize(frame.truth->footprint_near_m.width(),
                                              frame.truth->footprint_near_m.height()))) {
    throw Error(ErrorCode::kInvalidArgument, what + ": ground truth differs in size from frame");
  }
  if (!frame.source_flags.empty() && !frame.source_flags.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument, what + ": source flags differ in size from frame");
  }
  if (!frame.confidence.empty() && !frame.confidence.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument, what + ": confidence differs in size from frame");
  }
  const double f = frame.info.modulation_frequency_hz;
  if (!std::isfinite(f) || f <= 0.0) {
    throw Error(ErrorCode::kInvalidArgument, what + ": modulation frequency must be > 0 Hz");
  }
}

}  // namespace tofcam
