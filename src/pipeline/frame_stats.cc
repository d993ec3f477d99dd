#include "tofcam/pipeline/frame_stats.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "../filters/hot_loop.h"
#include "../filters/simd.h"
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

// The per-pixel loops accumulate in eight explicit lanes (pixel i into lane i mod 8), summed in
// a fixed order at the end: they vectorise, and the result does not depend on the CPU. Counts
// are exact; the two double sums (ΔL, squared error) differ from a sequential sum by at most
// n * 2^-53 of the sum of magnitudes (frame_stats_test.cc checks this against a sequential
// reference).
constexpr int kLanes = 8;

struct KeptLanes {
  std::int64_t kept[kLanes] = {};
  double delta_l_sum[kLanes] = {};
  std::int64_t delta_l_count[kLanes] = {};
};

constexpr std::int32_t kMaxBits = 0x7f7fffff;  // FLT_MAX: |x| <= it as bits is "finite"

// kept = no reject bit; ΔL summed over kept pixels with a finite ΔL (NaN where there is none).
TOFCAM_HOT_LOOP void KeptAndDeltaL(std::size_t n, const PixelFlags* __restrict f,
                                   const float* __restrict dl, KeptLanes& out) {
  using namespace simd;
  D4 sum_lo = {}, sum_hi = {};
  I8 kept = {}, count = {};
  std::size_t i = 0;
  for (; i + kLanes <= n; i += kLanes) {
    const I8 k = (LoadFlags8(f + i) & kRejectMask) == 0;
    const F8 x = LoadF8(dl + i);
    const I8 use = k & (AbsBits(x) <= kMaxBits);
    const F8 used = Select(use, x);
    sum_lo += Low(used);
    sum_hi += High(used);
    kept -= k;  // masks are -1
    count -= use;
  }
  for (int j = 0; j < kLanes; ++j) {
    out.kept[j] = kept[j];
    out.delta_l_sum[j] = j < 4 ? sum_lo[j] : sum_hi[j - 4];
    out.delta_l_count[j] = count[j];
  }
  constexpr float kMax = std::numeric_limits<float>::max();
  for (int j = 0; i < n; ++i, ++j) {
    const bool k = (f[i].bits() & kRejectMask) == 0;
    const bool use = k & (std::abs(dl[i]) <= kMax);
    out.kept[j] += k ? 1 : 0;
    out.delta_l_sum[j] += use ? static_cast<double>(dl[i]) : 0.0;
    out.delta_l_count[j] += use ? 1 : 0;
  }
}

struct TruthLanes {
  std::int64_t bad[kLanes] = {};
  std::int64_t bad_kept[kLanes] = {};
  std::int64_t error_pixels[kLanes] = {};
  double squared_error[kLanes] = {};
};

// error = measured - true; bad = not finite or |error| > bad_error; RMSE over kept pixels with
// a finite error.
TOFCAM_HOT_LOOP void Truth(std::size_t n, const PixelFlags* __restrict f, const float* __restrict d,
                           const float* __restrict t, float bad_error, TruthLanes& out) {
  using namespace simd;
  D4 sq_lo = {}, sq_hi = {};
  I8 bad = {}, bad_kept = {}, pixels = {};
  std::size_t i = 0;
  for (; i + kLanes <= n; i += kLanes) {
    const I8 k = (LoadFlags8(f + i) & kRejectMask) == 0;
    const F8 error = LoadF8(d + i) - LoadF8(t + i);
    const I8 finite = AbsBits(error) <= kMaxBits;
    const F8 magnitude = reinterpret_cast<F8>(AbsBits(error));
    const I8 b = ~(magnitude <= bad_error);  // NaN, inf or beyond the threshold
    const I8 use = k & finite;
    const F8 e = Select(use, error);
    const D4 lo = Low(e), hi = High(e);
    sq_lo += lo * lo;
    sq_hi += hi * hi;
    bad -= b;
    bad_kept -= b & k;
    pixels -= use;
  }
  for (int j = 0; j < kLanes; ++j) {
    out.bad[j] = bad[j];
    out.bad_kept[j] = bad_kept[j];
    out.error_pixels[j] = pixels[j];
    out.squared_error[j] = j < 4 ? sq_lo[j] : sq_hi[j - 4];
  }
  constexpr float kMax = std::numeric_limits<float>::max();
  for (int j = 0; i < n; ++i, ++j) {
    const bool k = (f[i].bits() & kRejectMask) == 0;
    const float error = d[i] - t[i];
    const bool finite = std::abs(error) <= kMax;
    const bool b = !(std::abs(error) <= bad_error);
    out.bad[j] += b ? 1 : 0;
    out.bad_kept[j] += (b & k) ? 1 : 0;
    out.error_pixels[j] += (k & finite) ? 1 : 0;
    out.squared_error[j] += (k & finite) ? static_cast<double>(error) * error : 0.0;
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
  if (!(intensity_clipped >= 0.0 && intensity_clipped <= 65532.0)) {
    throw Error(ErrorCode::kInvalidArgument, "stats.intensity_clipped must be in [0, 65532]");
  }
}

double FootprintErrorM(double measured_m, double truth_m, double near_m, double far_m) noexcept {
  double e = std::numeric_limits<double>::infinity();
  for (const double x : {truth_m, near_m, far_m}) {
    const double candidate = std::abs(measured_m - x);
    if (std::isfinite(x) && candidate < e) e = candidate;  // false for a NaN measurement
  }
  return e;
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
    if (!truth->footprint_near_m.empty()) {
      RequireSize(
          truth->footprint_near_m.SameSize(distance) && truth->footprint_far_m.SameSize(distance),
          "truth footprint");
    }
  }

  FrameStats s;
  s.sequence = frame.info.sequence;
  s.timestamp_s = static_cast<double>(frame.info.timestamp_ns) * 1e-9;
  s.integration_time_register = frame.info.integration_time_register;
  s.integration_time_us = frame.info.integration_time_us;
  s.mean_intensity = MeanControlIntensity(
      frame, options.intensity_roi, options.intensity_exclude_flags, options.intensity_clipped);
  s.pixels = static_cast<int>(distance.size());
  s.has_truth = truth != nullptr;

  const std::size_t n = distance.size();
  thread_local std::vector<PixelFlags> no_flags;
  thread_local std::vector<float> no_delta_l;
  if (!has_flags && no_flags.size() < n) no_flags.resize(n);
  if (!has_delta_l && no_delta_l.size() < n) {
    no_delta_l.assign(n, std::numeric_limits<float>::quiet_NaN());
  }
  const PixelFlags* flags = has_flags ? frame.flags.data() : no_flags.data();
  KeptLanes kept;
  KeptAndDeltaL(n, flags, has_delta_l ? frame.delta_l_m.data() : no_delta_l.data(), kept);
  double delta_l_sum = 0.0;
  std::int64_t delta_l_count = 0;
  for (int j = 0; j < kLanes; ++j) {
    s.kept_pixels += static_cast<int>(kept.kept[j]);
    delta_l_sum += kept.delta_l_sum[j];
    delta_l_count += kept.delta_l_count[j];
  }
  if (truth != nullptr) {
    TruthLanes t;
    Truth(n, flags, distance.data(), truth->radial_distance_m.data(),
          static_cast<float>(options.bad_error_m), t);
    std::int64_t bad = 0, bad_kept = 0, error_pixels = 0;
    for (int j = 0; j < kLanes; ++j) {
      bad += t.bad[j];
      bad_kept += t.bad_kept[j];
      error_pixels += t.error_pixels[j];
      s.sum_squared_error_m2 += t.squared_error[j];
    }
    // Every pixel is bad or good; kept ones too.
    s.bad_pixels = static_cast<int>(bad);
    s.bad_removed = static_cast<int>(bad - bad_kept);
    s.good_pixels = static_cast<int>(static_cast<std::int64_t>(n) - bad);
    s.good_kept = static_cast<int>(s.kept_pixels - bad_kept);
    s.truth_error_pixels = static_cast<int>(error_pixels);
    const Image<float>& near = truth->footprint_near_m;
    const Image<float>& far = truth->footprint_far_m;
    if (!near.empty()) {
      // The pixels of the RMSE above: kept, with a finite error against the central truth.
      const float* d = distance.data();
      const float* central = truth->radial_distance_m.data();
      for (std::size_t i = 0; i < n; ++i) {
        if ((flags[i].bits() & kRejectMask) != 0 || !std::isfinite(d[i] - central[i])) continue;
        const double e = FootprintErrorM(d[i], central[i], near[i], far[i]);
        s.footprint_sum_squared_error_m2 += e * e;
      }
    }
  }
  s.valid_fraction = Ratio(s.kept_pixels, s.pixels);
  s.mean_delta_l_m = Ratio(delta_l_sum, delta_l_count);
  if (truth != nullptr) {
    s.rmse_m = std::sqrt(Ratio(s.sum_squared_error_m2, s.truth_error_pixels));
    s.footprint_rmse_m =
        truth->footprint_near_m.empty()
            ? kNaN
            : std::sqrt(Ratio(s.footprint_sum_squared_error_m2, s.truth_error_pixels));
    s.bad_removed_fraction = Ratio(s.bad_removed, s.bad_pixels);
    s.good_kept_fraction = Ratio(s.good_kept, s.good_pixels);
  } else {
    s.rmse_m = s.footprint_rmse_m = s.bad_removed_fraction = s.good_kept_fraction = kNaN;
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
    if (!std::isnan(s.footprint_rmse_m)) {
      footprint_squared_error_sum_ += s.footprint_sum_squared_error_m2;
      ++footprint_frames_;
    }
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
    r.footprint_rmse_m =
        footprint_frames_ == truth_frames_
            ? std::sqrt(Ratio(footprint_squared_error_sum_, static_cast<double>(error_pixels_)))
            : kNaN;
    r.bad_removed_fraction =
        Ratio(static_cast<double>(bad_removed_), static_cast<double>(bad_pixels_));
    r.good_kept_fraction =
        Ratio(static_cast<double>(good_kept_), static_cast<double>(good_pixels_));
  } else {
    r.rmse_m = r.footprint_rmse_m = r.bad_removed_fraction = r.good_kept_fraction = kNaN;
  }
  return r;
}

}  // namespace tofcam
