#include "tofcam/accuracy/delta_l.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "../filters/hot_loop.h"
#include "../pipeline/stage_kernels.h"
#include "temporal_sigma.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

void CheckPositive(double value, double max, const char* name) {
  if (!std::isfinite(value) || value <= 0.0 || value > max) {
    throw Error(ErrorCode::kInvalidArgument, std::string("accuracy option ") + name + " = " +
                                                 std::to_string(value) + " must be in (0, " +
                                                 std::to_string(max) + "]");
  }
}

void CheckMetricFrame(const MetricFrame& frame, const char* what) {
  const int w = frame.width();
  const int h = frame.height();
  if (w <= 0 || h <= 0) {
    throw Error(ErrorCode::kInvalidArgument, std::string(what) + ": empty frame");
  }
  if (!frame.amplitude.SameSize(w, h) ||
      (frame.has_intensity() && !frame.intensity.SameSize(w, h))) {
    throw Error(ErrorCode::kInvalidArgument,
                std::string(what) + ": distance, amplitude and intensity differ in size");
  }
  const double f = frame.info.modulation_frequency_hz;
  if (!std::isfinite(f) || f <= 0.0) {
    throw Error(ErrorCode::kInvalidArgument,
                std::string(what) + ": modulation frequency must be > 0 Hz");
  }
}

}  // namespace

void AccuracyOptions::Validate() const {
  CheckPositive(scale, 1e6, "scale");
  CheckPositive(intensity_per_amplitude, 1e6, "intensity_per_amplitude");
}

void DeltaLFitOptions::Validate() const {
  if (!(max_sigma_fraction_of_range > 0.0)) {  // also rejects NaN; +inf is allowed (no cut)
    throw Error(ErrorCode::kInvalidArgument, "noise fit option max_sigma_fraction_of_range = " +
                                                 std::to_string(max_sigma_fraction_of_range) +
                                                 " must be > 0");
  }
  if (min_pixels < 1 || min_pixels > (1 << 28)) {
    throw Error(
        ErrorCode::kInvalidArgument,
        "noise fit option min_pixels = " + std::to_string(min_pixels) + " must be in [1, 2^28]");
  }
  AccuracyOptions a = accuracy;
  a.scale = 1.0;
  a.Validate();
  saturation.Validate();
}

Image<float> ComputeDeltaL(const MetricFrame& frame, const AccuracyOptions& options) {
  Image<float> out;
  ComputeDeltaLInto(frame, options, out);
  return out;
}

namespace {

// ΔL = k sqrt(I) / A, computed for every pixel and then selected, so the loop has no branch and
// vectorises. An x86-64-v4 clone too: its square root and division run 16 lanes wide on AVX-512
// CPUs (a multiply, a square root and a division, built without contraction: the same values;
// the paper chain at SR-2 measured 8 % faster on a Zen 5, pipeline_bench, docs/benchmarks.md).
TOFCAM_HOT_LOOP_WIDE void DeltaLLoop(std::size_t n, float k, const float* __restrict a,
                                     const float* __restrict in, float* __restrict o) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const float ai = a[i];
    const float q = k * std::sqrt(std::max(in[i], 0.0f)) / ai;
    o[i] = ai > 0.0f ? q : kInf;
  }
}

// sqrt(k_I A) / A = sqrt(k_I) / sqrt(A).
TOFCAM_HOT_LOOP_WIDE void DeltaLAmplitudeLoop(std::size_t n, float ka, const float* __restrict a,
                                              float* __restrict o) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const float ai = a[i];
    const float q = ka / std::sqrt(std::max(ai, 0.0f));
    o[i] = ai > 0.0f ? q : kInf;
  }
}

// The fitted model: ln σ is a sum of per-channel terms; float logs and one exp per pixel.
void ModelLoop(const NoiseModel& m, std::size_t n, const float* d, const float* a, const float* in,
               const float* c, float* o) {
  const float c0 = static_cast<float>(m.intercept), ca = static_cast<float>(m.log_amplitude);
  const float ci = static_cast<float>(m.log_intensity), cr = static_cast<float>(m.log_distance);
  const float cs = static_cast<float>(m.amplitude_fraction / m.amplitude_ref);
  const float cc = static_cast<float>(m.log_confidence);
  const bool use_i = in != nullptr && ci != 0.0f, use_r = cr != 0.0f;
  const bool use_c = c != nullptr && cc != 0.0f;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t k = 0; k < n; ++k) {
    const float ak = a[k];
    if (!(ak > 0.0f)) {
      o[k] = kInf;
      continue;
    }
    float e = c0 + ca * std::log(ak) + cs * ak;
    if (use_i) e += ci * std::log(std::max(in[k], 1.0f));
    if (use_r) e += cr * std::log(std::max(d[k], 0.05f));
    if (use_c) e += cc * std::log1p(std::max(c[k], 0.0f));
    o[k] = std::exp(e);
  }
}

}  // namespace

void NoiseModel::Validate() const {
  const std::pair<double, const char*> coefficients[] = {{intercept, "intercept"},
                                                         {log_amplitude, "log_amplitude"},
                                                         {log_intensity, "log_intensity"},
                                                         {log_distance, "log_distance"},
                                                         {amplitude_fraction, "amplitude_fraction"},
                                                         {log_confidence, "log_confidence"},
                                                         {log_edge, "log_edge"}};
  for (const auto& [value, name] : coefficients) {
    if (!std::isfinite(value) || std::abs(value) > 1e3) {
      throw Error(ErrorCode::kInvalidArgument, std::string("noise model ") + name + " = " +
                                                   std::to_string(value) +
                                                   " must be finite and within +-1e3");
    }
  }
  if (!(edge_ref_m > 0.0) || !std::isfinite(edge_ref_m)) {
    throw Error(ErrorCode::kInvalidArgument,
                "noise model edge_ref_m = " + std::to_string(edge_ref_m) + " must be > 0");
  }
  if (!(amplitude_ref > 0.0) || !std::isfinite(amplitude_ref)) {
    throw Error(ErrorCode::kInvalidArgument,
                "noise model amplitude_ref = " + std::to_string(amplitude_ref) + " must be > 0");
  }
}

double PredictSigmaM(const NoiseModel& m, double amplitude, double intensity, double distance_m,
                     double confidence, double edge_m) {
  if (!(amplitude > 0.0)) return std::numeric_limits<double>::infinity();
  double e = m.intercept + m.log_amplitude * std::log(amplitude) +
             m.amplitude_fraction * amplitude / m.amplitude_ref;
  if (m.log_intensity != 0.0) e += m.log_intensity * std::log(std::max(intensity, 1.0));
  if (m.log_distance != 0.0) e += m.log_distance * std::log(std::max(distance_m, 0.05));
  if (m.log_confidence != 0.0) e += m.log_confidence * std::log1p(std::max(confidence, 0.0));
  if (m.log_edge != 0.0) e += m.log_edge * std::log1p(std::max(edge_m, 0.0) / m.edge_ref_m);
  return std::exp(e);
}

void LocalDepthVariation(const Image<float>& d, const Image<PixelFlags>& flags, Image<float>& out) {
  const int w = d.width(), h = d.height();
  if (!flags.empty() && !flags.SameSize(w, h)) {
    throw Error(ErrorCode::kInvalidArgument,
                "local depth variation: flags differ in size from the distances");
  }
  if (!out.SameSize(w, h)) out = Image<float>(w, h);
  const auto usable = [&](std::size_t i) {
    return std::isfinite(d[i]) && (flags.empty() || !flags[i].Any(kRejectMask));
  };
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i =
          static_cast<std::size_t>(r) * static_cast<std::size_t>(w) + static_cast<std::size_t>(c);
      float e = 0.0f;
      if (std::isfinite(d[i])) {
        const auto take = [&](std::size_t n) {
          if (usable(n)) e = std::max(e, std::abs(d[n] - d[i]));
        };
        if (c > 0) take(i - 1);
        if (c + 1 < w) take(i + 1);
        if (r > 0) take(i - static_cast<std::size_t>(w));
        if (r + 1 < h) take(i + static_cast<std::size_t>(w));
      }
      out[i] = e;
    }
  }
}

void ApplyNoiseModelEdgeTerm(const NoiseModel& m, const Image<float>& distance_m,
                             const Image<PixelFlags>& flags, Image<float>& delta_l) {
  if (!m.uses_edges()) return;
  if (!delta_l.SameSize(distance_m.width(), distance_m.height())) {
    throw Error(ErrorCode::kInvalidArgument, "noise model edge term: ΔL differs in size");
  }
  thread_local Image<float> edge;
  LocalDepthVariation(distance_m, flags, edge);
  for (std::size_t i = 0; i < delta_l.size(); ++i) {
    delta_l[i] =
        static_cast<float>(delta_l[i] * std::pow(1.0 + edge[i] / m.edge_ref_m, m.log_edge));
  }
}

namespace kernels {

DeltaLPlan PrepareDeltaL(const MetricFrame& frame, const AccuracyOptions& options,
                         Image<float>& out) {
  options.Validate();
  CheckMetricFrame(frame, "ComputeDeltaL");
  const int w = frame.width();
  const int h = frame.height();
  if (!out.SameSize(w, h)) out = Image<float>(w, h);
  // ΔL = k sqrt(I) / A with k = scale L / (2 sqrt(8)).
  const double range_m = UnambiguousRangeM(frame.info.modulation_frequency_hz);
  DeltaLPlan plan;
  plan.k = static_cast<float>(options.scale * range_m / (2.0 * std::sqrt(8.0)));
  plan.ka = plan.k * static_cast<float>(std::sqrt(options.intensity_per_amplitude));
  plan.has_intensity = frame.has_intensity();
  if (options.model) {
    options.model->Validate();
    if (options.model->uses_intensity() && !frame.has_intensity()) {
      throw Error(ErrorCode::kMismatch,
                  "ComputeDeltaL: the noise model needs an intensity channel, the frame has none");
    }
    if (options.model->uses_confidence() && !frame.confidence.SameSize(w, h)) {
      throw Error(ErrorCode::kMismatch,
                  "ComputeDeltaL: the noise model needs the camera's confidence channel, the "
                  "frame has none");
    }
    plan.model = &*options.model;
  }
  return plan;
}

void DeltaLSpan(const DeltaLPlan& plan, std::size_t n, const float* d, const float* a,
                const float* i, const float* c, float* out) {
  if (plan.model != nullptr) {
    ModelLoop(*plan.model, n, d, a, plan.has_intensity ? i : nullptr, c, out);
  } else if (plan.has_intensity) {
    DeltaLLoop(n, plan.k, a, i, out);
  } else {
    DeltaLAmplitudeLoop(n, plan.ka, a, out);
  }
}

}  // namespace kernels

void ComputeDeltaLInto(const MetricFrame& frame, const AccuracyOptions& options,
                       Image<float>& out) {
  const kernels::DeltaLPlan plan = kernels::PrepareDeltaL(frame, options, out);
  kernels::DeltaLSpan(plan, out.size(), frame.radial_distance_m.data(), frame.amplitude.data(),
                      frame.has_intensity() ? frame.intensity.data() : nullptr,
                      frame.confidence.empty() ? nullptr : frame.confidence.data(), out.data());
  if (options.model)
    ApplyNoiseModelEdgeTerm(*options.model, frame.radial_distance_m, frame.flags, out);
}

DeltaLScaleFit FitDeltaLScale(std::span<const MetricFrame> frames,
                              const DeltaLFitOptions& options) {
  options.Validate();
  if (frames.size() < 3) {
    throw Error(ErrorCode::kInvalidArgument,
                "noise fit needs at least 3 static frames, got " + std::to_string(frames.size()));
  }
  const MetricFrame& first = frames.front();
  CheckMetricFrame(first, "noise fit frame 0");
  const int w = first.width();
  const int h = first.height();
  const double f_hz = first.info.modulation_frequency_hz;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const std::string what = "noise fit frame " + std::to_string(k);
    CheckMetricFrame(frames[k], what.c_str());
    if (frames[k].width() != w || frames[k].height() != h ||
        (!frames[k].flags.empty() && !frames[k].flags.SameSize(w, h))) {
      throw Error(ErrorCode::kInvalidArgument, what + ": size differs from frame 0");
    }
    if (frames[k].info.modulation_frequency_hz != f_hz) {
      throw Error(ErrorCode::kInvalidArgument, what + ": modulation frequency differs");
    }
  }
  AccuracyOptions accuracy = options.accuracy;
  accuracy.scale = 1.0;
  std::vector<Image<float>> delta_l;
  delta_l.reserve(frames.size());
  for (const MetricFrame& f : frames) delta_l.push_back(ComputeDeltaL(f, accuracy));

  const double range_m = UnambiguousRangeM(f_hz);
  const std::size_t n_pix = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  const double n_frames = static_cast<double>(frames.size());
  const std::vector<std::uint8_t> clipped =
      accuracy_internal::ClippedInAnyFrame(frames, options.saturation);
  std::vector<double> sigma, dl;
  for (std::size_t i = 0; i < n_pix; ++i) {
    if (clipped[i]) continue;
    double mean_dl = 0.0;
    bool ok = true;
    for (std::size_t k = 0; k < frames.size() && ok; ++k) {
      ok = std::isfinite(delta_l[k][i]);
      mean_dl += delta_l[k][i];
    }
    double pixel_sigma = 0.0;
    if (!ok || !accuracy_internal::TemporalSigma(frames, i, range_m, pixel_sigma)) continue;
    mean_dl /= n_frames;
    if (!(mean_dl > 0.0)) continue;
    sigma.push_back(pixel_sigma);
    dl.push_back(mean_dl);
  }
  // The cut needs the scale it is part of: a first, robust estimate (the median of σ / ΔL, which
  // the few near-dark pixels cannot move far) predicts each pixel's σ.
  if (!sigma.empty() && std::isfinite(options.max_sigma_fraction_of_range)) {
    std::vector<double> ratio(sigma.size());
    for (std::size_t i = 0; i < sigma.size(); ++i) ratio[i] = sigma[i] / dl[i];
    std::nth_element(ratio.begin(), ratio.begin() + static_cast<std::ptrdiff_t>(ratio.size() / 2),
                     ratio.end());
    const double max_dl = options.max_sigma_fraction_of_range * range_m / ratio[ratio.size() / 2];
    std::size_t kept = 0;
    for (std::size_t i = 0; i < sigma.size(); ++i) {
      if (!(dl[i] <= max_dl)) continue;
      sigma[kept] = sigma[i];
      dl[kept] = dl[i];
      ++kept;
    }
    sigma.resize(kept);
    dl.resize(kept);
  }
  if (sigma.size() < static_cast<std::size_t>(options.min_pixels)) {
    throw Error(ErrorCode::kInvalidArgument, "noise fit: only " + std::to_string(sigma.size()) +
                                                 " usable pixels, need " +
                                                 std::to_string(options.min_pixels));
  }
  DeltaLScaleFit fit;
  fit.frames = static_cast<int>(frames.size());
  fit.pixels_used = static_cast<int>(sigma.size());
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < sigma.size(); ++i) {
    num += sigma[i] * sigma[i] * dl[i] * dl[i];
    den += dl[i] * dl[i] * dl[i] * dl[i];
  }
  if (!(num > 0.0)) {
    // Copies of one frame (a looped one-frame source, a frozen driver): scale 0 would be
    // refused later as an invalid calibration without saying why.
    throw Error(ErrorCode::kInvalidArgument,
                "noise fit: no pixel varies from frame to frame (temporal σ 0 at all " +
                    std::to_string(sigma.size()) +
                    " usable pixels): the frames are copies (a looped or frozen source?)");
  }
  fit.scale = std::sqrt(num / den);
  std::vector<double> ratio(sigma.size());
  double ss_res = 0.0, ss_tot = 0.0, rel = 0.0, mean_sigma = 0.0;
  for (double v : sigma) mean_sigma += v;
  mean_sigma /= static_cast<double>(sigma.size());
  for (std::size_t i = 0; i < sigma.size(); ++i) {
    ratio[i] = sigma[i] / dl[i];
    const double model = fit.scale * dl[i];
    ss_res += (sigma[i] - model) * (sigma[i] - model);
    ss_tot += (sigma[i] - mean_sigma) * (sigma[i] - mean_sigma);
    rel += (sigma[i] - model) * (sigma[i] - model) / (model * model);
  }
  std::nth_element(ratio.begin(), ratio.begin() + static_cast<std::ptrdiff_t>(ratio.size() / 2),
                   ratio.end());
  fit.median_ratio = ratio[ratio.size() / 2];
  fit.r_squared = ss_tot > 0.0 ? 1.0 - ss_res / ss_tot : 0.0;
  fit.relative_rms = std::sqrt(rel / static_cast<double>(sigma.size()));
  return fit;
}

}  // namespace tofcam
