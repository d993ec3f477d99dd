#include "tofcam/pipeline/frame_stats.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double Ratio(double numerator, double denominator) {
  return denominator > 0 ? numerator / denominator : kNaN;
}

void RequireSize(bool same, const char* what) {
  if (!same) {
    throw Error(ErrorCode::kInvalidArgument,
                std::string("frame statistics: ") + what + " differs in size from the distance");
  }
}

}  // namespace

void FrameStatsOptions::Validate() const {
  if (!(bad_error_m > 0.0 && bad_error_m <= 100.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "stats.bad_error_m " + std::to_string(bad_error_m) + " must be in (0, 100]");
  }
  if (intensity_roi.row < 0 || intensity_roi.col < 0 || intensity_roi.rows < 0 ||
      intensity_roi.cols < 0) {
    throw Error(ErrorCode::kInvalidArgument, "stats.intensity_roi must not be negative");
  }
}

FrameStats ComputeFrameStats(const MetricFrame& frame, const FrameStatsOptions& options) {
  options.Validate();
  const Image<float>& distance = frame.radial_distance_m;
  if (distance.empty()) {
    throw Error(ErrorCode::kInvalidArgument, "frame statistics: empty frame");
  }
  const bool has_flags = !frame.flags.empty();
  const bool has_delta_l = !frame.delta_l_m.empty();
  if (has_flags) RequireSize(frame.flags.SameSize(distance), "flags");
  if (has_delta_l) RequireSize(frame.delta_l_m.SameSize(distance), "delta_l_m");
  const GroundTruth* truth = frame.truth ? &*frame.truth : nullptr;
  if (truth != nullptr) {
    RequireSize(truth->radial_distance_m.SameSize(distance), "truth.radial_distance_m");
  }

  FrameStats s;
  s.sequence = frame.info.sequence;
  s.timestamp_s = static_cast<double>(frame.info.timestamp_ns) * 1e-9;
  s.integration_time_register = frame.info.integration_time_register;
  s.integration_time_us = frame.info.integration_time_us;
  s.mean_intensity =
      MeanControlIntensity(frame, options.intensity_roi, options.intensity_exclude_flags);
  s.pixels = static_cast<int>(distance.size());
  s.has_truth = truth != nullptr;

  double delta_l_sum = 0.0;
  int delta_l_count = 0;
  const float bad_error = static_cast<float>(options.bad_error_m);
  const std::size_t n = distance.size();
  for (std::size_t i = 0; i < n; ++i) {
    const bool kept = !has_flags || frame.flags[i].Valid();
    if (kept) {
      ++s.kept_pixels;
      if (has_delta_l && std::isfinite(frame.delta_l_m[i])) {
        delta_l_sum += frame.delta_l_m[i];
        ++delta_l_count;
      }
    }
    if (truth == nullptr) continue;
    const float measured = distance[i];
    const float true_distance = truth->radial_distance_m[i];
    const float error = measured - true_distance;
    const bool finite = std::isfinite(error);
    const bool bad = !finite || std::abs(error) > bad_error;
    if (bad) {
      ++s.bad_pixels;
      if (!kept) ++s.bad_removed;
    } else {
      ++s.good_pixels;
      if (kept) ++s.good_kept;
    }
    if (kept && finite) {
      ++s.truth_error_pixels;
      s.sum_squared_error_m2 += static_cast<double>(error) * error;
    }
  }
  s.valid_fraction = Ratio(s.kept_pixels, s.pixels);
  s.mean_delta_l_m = Ratio(delta_l_sum, delta_l_count);
  if (truth != nullptr) {
    s.rmse_m = std::sqrt(Ratio(s.sum_squared_error_m2, s.truth_error_pixels));
    s.bad_removed_fraction = Ratio(s.bad_removed, s.bad_pixels);
    s.good_kept_fraction = Ratio(s.good_kept, s.good_pixels);
  } else {
    s.rmse_m = s.bad_removed_fraction = s.good_kept_fraction = kNaN;
  }
  return s;
}

std::string FrameStatsCsvHeader() {
  return "sequence,timestamp_s,integration_register,integration_time_us,next_register,"
         "mean_intensity,kept_pixels,valid_fraction,mean_delta_l_m,rmse_m,bad_pixels,bad_removed,"
         "bad_removed_fraction,good_pixels,good_kept,good_kept_fraction";
}

std::string FrameStatsCsvRow(const FrameStats& s) {
  std::string row;
  char buffer[64];
  const auto real = [&](double v) {
    if (std::isnan(v)) {
      row += "nan,";
    } else {
      std::snprintf(buffer, sizeof buffer, "%.9g,", v);
      row += buffer;
    }
  };
  const auto integer = [&](long long v) { row += std::to_string(v) + ","; };
  integer(static_cast<long long>(s.sequence));
  real(s.timestamp_s);
  integer(s.integration_time_register);
  real(s.integration_time_us);
  integer(s.next_integration_register);
  real(s.mean_intensity);
  integer(s.kept_pixels);
  real(s.valid_fraction);
  real(s.mean_delta_l_m);
  real(s.rmse_m);
  integer(s.bad_pixels);
  integer(s.bad_removed);
  real(s.bad_removed_fraction);
  integer(s.good_pixels);
  integer(s.good_kept);
  real(s.good_kept_fraction);
  row.pop_back();  // the last comma
  return row;
}

void RunStatsAccumulator::Add(const FrameStats& s) noexcept {
  ++frames_;
  valid_fraction_sum_ += std::isfinite(s.valid_fraction) ? s.valid_fraction : 0.0;
  if (std::isfinite(s.mean_delta_l_m)) {
    delta_l_sum_ += s.mean_delta_l_m;
    ++delta_l_frames_;
  }
  if (std::isfinite(s.mean_intensity)) {
    intensity_sum_ += s.mean_intensity;
    ++intensity_frames_;
  }
  if (s.has_truth) {
    ++truth_frames_;
    squared_error_sum_ += s.sum_squared_error_m2;
    error_pixels_ += s.truth_error_pixels;
    bad_pixels_ += s.bad_pixels;
    bad_removed_ += s.bad_removed;
    good_pixels_ += s.good_pixels;
    good_kept_ += s.good_kept;
  }
}

RunSummary RunStatsAccumulator::Summary() const noexcept {
  RunSummary r;
  r.frames = frames_;
  r.mean_valid_fraction = Ratio(valid_fraction_sum_, static_cast<double>(frames_));
  r.mean_delta_l_m = Ratio(delta_l_sum_, static_cast<double>(delta_l_frames_));
  r.mean_intensity = Ratio(intensity_sum_, static_cast<double>(intensity_frames_));
  r.has_truth = frames_ > 0 && truth_frames_ == frames_;
  r.bad_pixels = bad_pixels_;
  r.good_pixels = good_pixels_;
  if (truth_frames_ > 0) {
    r.rmse_m = std::sqrt(Ratio(squared_error_sum_, static_cast<double>(error_pixels_)));
    r.bad_removed_fraction =
        Ratio(static_cast<double>(bad_removed_), static_cast<double>(bad_pixels_));
    r.good_kept_fraction =
        Ratio(static_cast<double>(good_kept_), static_cast<double>(good_pixels_));
  } else {
    r.rmse_m = r.bad_removed_fraction = r.good_kept_fraction = kNaN;
  }
  return r;
}

}  // namespace tofcam
