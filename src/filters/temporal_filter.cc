#include "tofcam/filters/temporal_filter.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {

void TemporalFilterOptions::Validate() const {
  const auto bad = [](const std::string& field, const std::string& rule) {
    throw Error(ErrorCode::kInvalidArgument, "temporal filter " + field + " " + rule);
  };
  if (!(reset_sigma > 0.0 && reset_sigma <= 100.0)) bad("reset_sigma", "must be in (0, 100]");
  if (!(drift_sigma > 0.0 && drift_sigma <= reset_sigma)) {
    bad("drift_sigma", "must be in (0, reset_sigma]");
  }
  if (drift_frames < 2 || drift_frames > 100) bad("drift_frames", "must be in [2, 100]");
  if (max_frames < 1 || max_frames > 10000) bad("max_frames", "must be in [1, 10000]");
  if (max_gap_frames < 0 || max_gap_frames > 255) bad("max_gap_frames", "must be in [0, 255]");
  if (!(fallback_sigma_m > 0.0) || !std::isfinite(fallback_sigma_m)) {
    bad("fallback_sigma_m", "must be > 0");
  }
}

TemporalFilter::TemporalFilter(const TemporalFilterOptions& options) : options_(options) {
  options_.Validate();
}

void TemporalFilter::Reset() {
  std::fill(variance_m2_.begin(), variance_m2_.end(), 0.0f);
  std::fill(count_.begin(), count_.end(), std::uint16_t{0});
  std::fill(gap_.begin(), gap_.end(), std::uint8_t{0});
  std::fill(deviant_.begin(), deviant_.end(), std::uint8_t{0});
  std::fill(drift_.begin(), drift_.end(), std::int8_t{0});
}

void TemporalFilter::Process(MetricFrame& frame) {
  Image<float>& d = frame.radial_distance_m;
  if (!frame.flags.empty() && !frame.flags.SameSize(d)) {
    throw Error(ErrorCode::kInvalidArgument,
                "temporal filter: flags differ in size from the distances");
  }
  if (!frame.delta_l_m.empty() && !frame.delta_l_m.SameSize(d)) {
    throw Error(ErrorCode::kInvalidArgument,
                "temporal filter: delta_l_m differs in size from the distances");
  }
  if (d.width() != width_ || d.height() != height_) {
    width_ = d.width();
    height_ = d.height();
    mean_m_.assign(d.size(), 0.0f);
    variance_m2_.assign(d.size(), 0.0f);
    count_.assign(d.size(), 0);
    gap_.assign(d.size(), 0);
    deviant_.assign(d.size(), 0);
    drift_.assign(d.size(), 0);
  }
  const double k2 = options_.reset_sigma * options_.reset_sigma;
  const double drift2 = options_.drift_sigma * options_.drift_sigma;
  const double min_share = 1.0 / options_.max_frames;
  for (std::size_t i = 0; i < d.size(); ++i) {
    const float x = d[i];
    if (!std::isfinite(x) || (!frame.flags.empty() && !frame.flags[i].Valid())) {
      if (gap_[i] < 255) ++gap_[i];
      if (gap_[i] > options_.max_gap_frames) {
        variance_m2_[i] = 0.0f;
        count_[i] = 0;
      }
      continue;
    }
    gap_[i] = 0;
    double s = frame.delta_l_m.empty() ? 0.0 : frame.delta_l_m[i];
    if (!(std::isfinite(s) && s > 0.0)) s = options_.fallback_sigma_m;
    const double s2 = s * s;
    const double v = variance_m2_[i];
    const double e = static_cast<double>(x) - mean_m_[i];
    const bool beyond = e * e > k2 * (v + s2);
    // Signed run of frames whose innovation exceeds drift_sigma, one sign only.
    std::int8_t run = 0;
    if (e * e > drift2 * (v + s2)) {
      const std::int8_t sign = e > 0 ? 1 : -1;
      run = drift_[i] * sign > 0 ? static_cast<std::int8_t>(drift_[i] + sign) : sign;
    }
    drift_[i] = run;
    const bool drifting = std::abs(run) >= options_.drift_frames;
    if (v > 0.0 && beyond && deviant_[i] == 0 && !drifting) {
      deviant_[i] = 1;  // one frame off: an outlier of the noise, unless the next one is too
      continue;         // the measurement itself is the output; the state stays
    }
    deviant_[i] = 0;
    if (v <= 0.0 || beyond || drifting) {
      drift_[i] = 0;
      mean_m_[i] = x;  // first measurement, or the scene changed: start again
      variance_m2_[i] = static_cast<float>(s2);
      count_[i] = 1;
      continue;
    }
    const double g = v / (v + s2);
    const double mean = mean_m_[i] + g * e;
    mean_m_[i] = static_cast<float>(mean);
    variance_m2_[i] = static_cast<float>(std::max((1.0 - g) * v, s2 * min_share));
    if (count_[i] < options_.max_frames) ++count_[i];
    d[i] = static_cast<float>(mean);
  }
}

}  // namespace tofcam
