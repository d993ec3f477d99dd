#include "tofcam/accuracy/noise_model.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include "temporal_sigma.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

[[noreturn]] void Bad(const std::string& what) { throw Error(ErrorCode::kInvalidArgument, what); }

// One usable pixel: its measured σ and the per-pixel temporal means of its channels.
struct PixelSample {
  double sigma_m, amplitude, intensity, distance_m, confidence, eq2_m;
  double edge_m;   // local depth variation, the mean over the frames of each frame's
  bool training;   // in the training half (else held out)
  bool selection;  // training pixel that scores the choice of channels
};

// The model's channels. The base is either eq. 2's slopes held fixed (ln σ = c0 + ln ΔL of
// eq. 2 + extras; eq2_base) or free slopes in ln A (and ln I where present); the extras are the
// optional channels. Columns: [1, (ln A, ln I when free), ln r, A / A_ref, ln(1 + C)].
struct Features {
  bool eq2_base = false;
  bool has_intensity = false;  // the frames have an intensity channel
  double intensity_per_amplitude = 2.5;
  bool distance = false, saturation = false, confidence = false, edges = false;
  double amplitude_ref = 1.0;
  double edge_ref_m = 0.01;

  [[nodiscard]] bool free_intensity() const { return !eq2_base && has_intensity; }
  [[nodiscard]] int count() const {
    return 1 + (eq2_base ? 0 : 1) + int{free_intensity()} + int{distance} + int{saturation} +
           int{confidence} + int{edges};
  }
  // The fixed part of ln σ (eq. 2's slopes), 0 with free slopes.
  [[nodiscard]] double Offset(const PixelSample& p) const {
    if (!eq2_base) return 0.0;
    return has_intensity ? 0.5 * std::log(std::max(p.intensity, 1.0)) - std::log(p.amplitude)
                         : -0.5 * std::log(p.amplitude);
  }
  void Row(const PixelSample& p, double* out) const {
    int k = 0;
    out[k++] = 1.0;
    if (!eq2_base) out[k++] = std::log(p.amplitude);
    if (free_intensity()) out[k++] = std::log(std::max(p.intensity, 1.0));
    if (distance) out[k++] = std::log(std::max(p.distance_m, 0.05));
    if (saturation) out[k++] = p.amplitude / amplitude_ref;
    if (confidence) out[k++] = std::log1p(std::max(p.confidence, 0.0));
    if (edges) out[k++] = std::log1p(std::max(p.edge_m, 0.0) / edge_ref_m);
  }
  [[nodiscard]] NoiseModel ToModel(const Eigen::VectorXd& beta) const {
    NoiseModel m;
    int k = 0;
    m.intercept = beta[k++];
    if (eq2_base) {
      // ln of eq. 2's amplitude-only form: 0.5 ln(k_I A) - ln A; the constant goes to c0.
      m.log_amplitude = has_intensity ? -1.0 : -0.5;
      m.log_intensity = has_intensity ? 0.5 : 0.0;
      if (!has_intensity) m.intercept += 0.5 * std::log(intensity_per_amplitude);
    } else {
      m.log_amplitude = beta[k++];
      if (free_intensity()) m.log_intensity = beta[k++];
    }
    if (distance) m.log_distance = beta[k++];
    if (saturation) m.amplitude_fraction = beta[k++];
    if (confidence) m.log_confidence = beta[k++];
    if (edges) m.log_edge = beta[k++];
    m.amplitude_ref = amplitude_ref;
    m.edge_ref_m = edge_ref_m;
    return m;
  }
  [[nodiscard]] std::string Names() const {
    std::string s = eq2_base ? "eq. 2 slopes" : (free_intensity() ? "ln A, ln I" : "ln A");
    if (distance) s += ", ln r";
    if (saturation) s += ", A/A_ref";
    if (confidence) s += ", ln(1+C)";
    if (edges) s += ", ln(1+E/E_ref)";
    return s;
  }
};

// Least squares of y - offset on the features of `rows`, with the features standardised and a
// ridge of 1e-4 per sample on the standardised slopes (not the intercept): a channel that
// barely varies (distance on a flat wall) then keeps a small slope instead of an arbitrary one.
NoiseModel FitLogLinear(const std::vector<const PixelSample*>& rows, const std::vector<double>& y,
                        const Features& features) {
  const int p = features.count();
  const Eigen::Index n = static_cast<Eigen::Index>(rows.size());
  Eigen::MatrixXd x(n, p);
  Eigen::VectorXd yy(n);
  std::vector<double> row(static_cast<std::size_t>(p));
  for (Eigen::Index r = 0; r < n; ++r) {
    const PixelSample& sample = *rows[static_cast<std::size_t>(r)];
    features.Row(sample, row.data());
    for (int c = 0; c < p; ++c) x(r, c) = row[static_cast<std::size_t>(c)];
    yy[r] = y[static_cast<std::size_t>(r)] - features.Offset(sample);
  }
  Eigen::VectorXd mean = x.colwise().mean();
  Eigen::VectorXd scale = Eigen::VectorXd::Ones(p);
  for (int c = 1; c < p; ++c) {
    const double sd = std::sqrt((x.col(c).array() - mean[c]).square().mean());
    scale[c] = sd > 1e-12 ? sd : 1.0;
    x.col(c) = (x.col(c).array() - mean[c]) / scale[c];
  }
  Eigen::MatrixXd a = x.transpose() * x;
  for (int c = 1; c < p; ++c) a(c, c) += 1e-4 * static_cast<double>(n);
  const Eigen::VectorXd b = a.ldlt().solve(x.transpose() * yy);
  // Back to the raw features: slope_c = b_c / scale_c, intercept absorbs the means.
  Eigen::VectorXd beta(p);
  beta[0] = b[0];
  for (int c = 1; c < p; ++c) {
    beta[c] = b[c] / scale[c];
    beta[0] -= beta[c] * mean[c];
  }
  return features.ToModel(beta);
}

std::vector<double> Ranks(std::span<const double> v) {
  std::vector<std::size_t> idx(v.size());
  std::iota(idx.begin(), idx.end(), std::size_t{0});
  std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) { return v[a] < v[b]; });
  std::vector<double> r(v.size());
  for (std::size_t i = 0; i < idx.size();) {
    std::size_t j = i;
    while (j < idx.size() && v[idx[j]] == v[idx[i]]) ++j;
    for (std::size_t k = i; k < j; ++k) r[idx[k]] = 0.5 * static_cast<double>(i + j - 1);
    i = j;
  }
  return r;
}

// Rank and decile calibration of `predicted` against the measured σ of `pixels`.
PredictorValidation Validate(const std::string& name, const std::vector<double>& predicted,
                             const std::vector<const PixelSample*>& pixels, bool calibrated) {
  PredictorValidation v;
  v.name = name;
  v.available = true;
  v.calibrated = calibrated;
  std::vector<double> measured(pixels.size());
  for (std::size_t i = 0; i < pixels.size(); ++i) measured[i] = pixels[i]->sigma_m;
  v.spearman = SpearmanCorrelation(predicted, measured);
  if (!calibrated) return v;
  std::vector<std::size_t> order(pixels.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return predicted[a] < predicted[b]; });
  const std::size_t n = order.size();
  for (std::size_t d = 0; d < 10; ++d) {
    const std::size_t lo = d * n / 10, hi = (d + 1) * n / 10;
    double p2 = 0.0, m2 = 0.0;
    for (std::size_t k = lo; k < hi; ++k) {
      p2 += predicted[order[k]] * predicted[order[k]];
      m2 += measured[order[k]] * measured[order[k]];
    }
    const double count = static_cast<double>(std::max<std::size_t>(hi - lo, 1));
    v.predicted_m[d] = std::sqrt(p2 / count);
    v.measured_m[d] = std::sqrt(m2 / count);
    if (v.measured_m[d] > 0.0) {
      v.max_decile_error =
          std::max(v.max_decile_error, std::abs(v.predicted_m[d] / v.measured_m[d] - 1.0));
    }
  }
  return v;
}

// σ = s ΔL through the origin, in variances (unbiased): s² = Σ σ² ΔL² / Σ ΔL⁴.
double Eq2Scale(const std::vector<const PixelSample*>& pixels) {
  double num = 0.0, den = 0.0;
  for (const PixelSample* p : pixels) {
    num += p->sigma_m * p->sigma_m * p->eq2_m * p->eq2_m;
    den += p->eq2_m * p->eq2_m * p->eq2_m * p->eq2_m;
  }
  return den > 0.0 ? std::sqrt(num / den) : 1.0;
}

// The least squares of ln σ predicts the geometric mean of σ; scatter the model does not
// explain makes that fall short of σ's RMS, which the filter's threshold is about. One shift of
// c0 makes Σ predicted² = Σ s² over `rows` (s² is an unbiased estimate of σ²).
void MatchVariance(NoiseModel& m, const std::vector<const PixelSample*>& rows) {
  double pred2 = 0.0, meas2 = 0.0;
  for (const PixelSample* p : rows) {
    const double q =
        PredictSigmaM(m, p->amplitude, p->intensity, p->distance_m, p->confidence, p->edge_m);
    pred2 += q * q;
    meas2 += p->sigma_m * p->sigma_m;
  }
  if (pred2 > 0.0 && meas2 > 0.0 && std::isfinite(pred2))
    m.intercept += 0.5 * std::log(meas2 / pred2);
}

double Percentile(std::vector<double> v, double q) {
  const std::size_t k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

double SpearmanCorrelation(std::span<const double> a, std::span<const double> b) {
  if (a.size() != b.size() || a.size() < 2) return 0.0;
  const std::vector<double> ra = Ranks(a), rb = Ranks(b);
  const double n = static_cast<double>(a.size());
  const double mean = 0.5 * (n - 1.0);
  double sab = 0.0, saa = 0.0, sbb = 0.0;
  for (std::size_t i = 0; i < ra.size(); ++i) {
    sab += (ra[i] - mean) * (rb[i] - mean);
    saa += (ra[i] - mean) * (ra[i] - mean);
    sbb += (rb[i] - mean) * (rb[i] - mean);
  }
  return saa > 0.0 && sbb > 0.0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

void NoiseModelFitOptions::Validate() const {
  if (min_frames < 3 || min_frames > 1000000) {
    Bad("noise model option min_frames = " + std::to_string(min_frames) + " must be in [3, 1e6]");
  }
  if (min_pixels < 10 || min_pixels > (1 << 28)) {
    Bad("noise model option min_pixels = " + std::to_string(min_pixels) + " must be in [10, 2^28]");
  }
  if (block_px < 1 || block_px > 4096) {
    Bad("noise model option block_px = " + std::to_string(block_px) + " must be in [1, 4096]");
  }
  if (!(max_sigma_fraction_of_range > 0.0)) {
    Bad("noise model option max_sigma_fraction_of_range = " +
        std::to_string(max_sigma_fraction_of_range) + " must be > 0");
  }
  AccuracyOptions a = accuracy;
  a.scale = 1.0;
  a.model.reset();
  a.Validate();
  saturation.Validate();
}

NoiseModelFit FitNoiseModel(std::span<const MetricFrame> frames,
                            const NoiseModelFitOptions& options) {
  options.Validate();
  if (frames.size() < static_cast<std::size_t>(options.min_frames)) {
    Bad("noise model fit needs at least " + std::to_string(options.min_frames) +
        " static frames, got " + std::to_string(frames.size()));
  }
  const MetricFrame& first = frames.front();
  const int w = first.width(), h = first.height();
  const double f_hz = first.info.modulation_frequency_hz;
  if (w <= 0 || h <= 0) Bad("noise model fit: empty frame");
  bool has_intensity = true, has_confidence = true;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const MetricFrame& f = frames[k];
    const std::string what = "noise model fit frame " + std::to_string(k);
    if (f.width() != w || f.height() != h || !f.amplitude.SameSize(w, h) ||
        (!f.flags.empty() && !f.flags.SameSize(w, h))) {
      Bad(what + ": size differs from frame 0");
    }
    if (f.info.modulation_frequency_hz != f_hz) Bad(what + ": modulation frequency differs");
    has_intensity = has_intensity && f.has_intensity() && f.intensity.SameSize(w, h);
    has_confidence = has_confidence && f.confidence.SameSize(w, h);
  }
  if (!std::isfinite(f_hz) || f_hz <= 0.0) Bad("noise model fit: modulation frequency must be > 0");
  const double range_m = UnambiguousRangeM(f_hz);
  // Eq. 2 (scale 1) of the mean channels: the baseline and the predictor the cut is made on.
  AccuracyOptions eq2 = options.accuracy;
  eq2.scale = 1.0;
  eq2.model.reset();
  const double k_eq2 = range_m / (2.0 * std::sqrt(8.0));

  const double n = static_cast<double>(frames.size());
  const std::vector<std::uint8_t> clipped =
      accuracy_internal::ClippedInAnyFrame(frames, options.saturation);
  // The edge channel: each frame's local depth variation, averaged (ΔL sees one frame's).
  std::vector<double> edge_sum(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0.0);
  if (options.use_edges) {
    Image<float> e;
    for (const MetricFrame& f : frames) {
      LocalDepthVariation(f.radial_distance_m, f.flags, e);
      for (std::size_t i = 0; i < edge_sum.size(); ++i) edge_sum[i] += e[i];
    }
  }
  std::vector<PixelSample> samples;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i =
          static_cast<std::size_t>(r) * static_cast<std::size_t>(w) + static_cast<std::size_t>(c);
      if (clipped[i]) continue;
      PixelSample p{};
      if (!accuracy_internal::TemporalSigma(frames, i, range_m, p.sigma_m)) continue;
      bool ok = true;
      for (const MetricFrame& f : frames) {
        ok = ok && std::isfinite(f.amplitude[i]);
        p.amplitude += f.amplitude[i];
        p.distance_m += f.radial_distance_m[i];
        if (has_intensity) p.intensity += f.intensity[i];
        if (has_confidence) p.confidence += f.confidence[i];
      }
      p.edge_m = edge_sum[i] / n;
      p.amplitude /= n;
      p.intensity /= n;
      p.distance_m /= n;
      p.confidence /= n;
      if (!ok || !(p.amplitude > 0.0) || !std::isfinite(p.confidence)) continue;
      const double i_eff =
          has_intensity ? std::max(p.intensity, 0.0) : eq2.intensity_per_amplitude * p.amplitude;
      p.eq2_m = k_eq2 * std::sqrt(i_eff) / p.amplitude;
      const int bx = c / options.block_px, by = r / options.block_px;
      p.training = (bx + by) % 2 == 0;
      p.selection = p.training && bx % 2 == 1;
      samples.push_back(p);
    }
  }
  // The cut on the predictor (see the option): median σ / ΔL first.
  if (!samples.empty() && std::isfinite(options.max_sigma_fraction_of_range)) {
    std::vector<double> ratio;
    ratio.reserve(samples.size());
    for (const PixelSample& p : samples) ratio.push_back(p.sigma_m / p.eq2_m);
    const double median = Percentile(ratio, 0.5);
    if (median > 0.0) {
      const double max_eq2 = options.max_sigma_fraction_of_range * range_m / median;
      std::erase_if(samples, [&](const PixelSample& p) { return !(p.eq2_m <= max_eq2); });
    }
  }
  std::vector<const PixelSample*> train, test, all;
  for (const PixelSample& p : samples) {
    (p.training ? train : test).push_back(&p);
    all.push_back(&p);
  }
  if (train.size() < static_cast<std::size_t>(options.min_pixels) ||
      test.size() < static_cast<std::size_t>(options.min_pixels)) {
    Bad("noise model fit: " + std::to_string(train.size()) + " training and " +
        std::to_string(test.size()) + " held-out pixels usable in every frame, need " +
        std::to_string(options.min_pixels) + " each (is the scene static and lit?)");
  }
  // Frames that never change (a looped one-frame source, a frozen driver) have no temporal
  // noise to predict: every verdict would be vacuous ("eq. 2, scale 0, within 25 %").
  if (std::none_of(samples.begin(), samples.end(),
                   [](const PixelSample& p) { return p.sigma_m > 0.0; })) {
    Bad("noise model fit: no pixel varies from frame to frame (temporal σ 0 everywhere): the "
        "frames are copies of each other (a looped or frozen source?)");
  }

  // ln s of N frames is biased low against ln σ; only the intercept absorbs that, and
  // MatchVariance sets the intercept. s = 0 (identical readings, a quantised camera) is floored
  // at the register step / sqrt(12), the quantisation noise.
  const double floor_m = range_m / kDistanceRegisterSpan / std::sqrt(12.0);
  auto targets = [&](const std::vector<const PixelSample*>& rows) {
    std::vector<double> y(rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i) {
      y[i] = std::log(std::max(rows[i]->sigma_m, floor_m));
    }
    return y;
  };
  // Channels are chosen on the training half alone, split again into a fitting and a selection
  // part, so the held-out pixels judge a choice they took no part in.
  std::vector<const PixelSample*> fit_part, select_part;
  for (const PixelSample* p : train) (p->selection ? select_part : fit_part).push_back(p);
  Features base;
  base.has_intensity = has_intensity;
  base.intensity_per_amplitude = eq2.intensity_per_amplitude;
  {
    std::vector<double> amplitudes;
    for (const PixelSample* p : train) amplitudes.push_back(p->amplitude);
    base.amplitude_ref = std::max(Percentile(amplitudes, 0.99), 1e-9);
    std::vector<double> edges;
    for (const PixelSample* p : train) edges.push_back(p->edge_m);
    const double median_edge = Percentile(edges, 0.5);
    base.edge_ref_m = median_edge > 1e-6 ? median_edge : 0.01;
  }
  struct Scored {
    Features features;
    PredictorValidation v;
  };
  auto score = [&](const Features& f) {
    NoiseModel m = FitLogLinear(fit_part, targets(fit_part), f);
    MatchVariance(m, fit_part);
    std::vector<double> pred;
    for (const PixelSample* p : select_part) {
      pred.push_back(
          PredictSigmaM(m, p->amplitude, p->intensity, p->distance_m, p->confidence, p->edge_m));
    }
    return Scored{f, Validate("", pred, select_part, true)};
  };
  // Better: a higher ρ beyond 2 standard errors, or a ρ within them and a smaller worst decile.
  const double n_select = static_cast<double>(select_part.size());
  auto better = [&](const Scored& a, const Scored& b) {
    const double rho = b.v.spearman;
    const double se =
        (1 - rho * rho) * std::sqrt((1 + rho * rho / 2) / std::max(n_select - 3, 1.0));
    if (a.v.spearman > rho + 2 * se) return true;
    if (a.v.spearman < rho - 2 * se) return false;
    return a.v.max_decile_error < b.v.max_decile_error - 0.01;
  };
  std::optional<Scored> best;
  for (const bool eq2_base : {true, false}) {
    Features f = base;
    f.eq2_base = eq2_base;
    Scored current = score(f);
    while (true) {  // forward selection of the optional channels
      std::optional<Scored> step;
      for (int extra = 0; extra < 4; ++extra) {
        Features g = current.features;
        bool* flag = extra == 0   ? &g.distance
                     : extra == 1 ? &g.saturation
                     : extra == 2 ? &g.confidence
                                  : &g.edges;
        const bool allowed = extra == 0   ? options.use_distance
                             : extra == 1 ? options.use_saturation
                             : extra == 2 ? options.use_confidence && has_confidence
                                          : options.use_edges;
        if (*flag || !allowed) continue;
        *flag = true;
        Scored candidate = score(g);
        if (better(candidate, current) && (!step || better(candidate, *step))) step = candidate;
      }
      if (!step) break;
      current = *step;
    }
    if (!best || better(current, *best)) best = current;
  }
  const Features features = best->features;

  NoiseModelFit fit;
  fit.frames = static_cast<int>(frames.size());
  fit.training_pixels = static_cast<int>(train.size());
  fit.held_out_pixels = static_cast<int>(test.size());
  fit.features = features.Names();

  // Held-out validation: every predictor fitted (where it has parameters) on the training half.
  NoiseModel trained = FitLogLinear(train, targets(train), features);
  MatchVariance(trained, train);
  const double trained_scale = Eq2Scale(train);
  std::vector<double> model_pred, eq2_pred, vendor_pred;
  for (const PixelSample* p : test) {
    model_pred.push_back(PredictSigmaM(trained, p->amplitude, p->intensity, p->distance_m,
                                       p->confidence, p->edge_m));
    eq2_pred.push_back(trained_scale * p->eq2_m);
    vendor_pred.push_back(-p->confidence);
  }
  fit.fitted = Validate("fitted model", model_pred, test, true);
  fit.eq2 = Validate("eq. 2", eq2_pred, test, true);
  if (has_confidence) {
    fit.vendor = Validate("vendor confidence", vendor_pred, test, false);
  } else {
    fit.vendor.name = "vendor confidence";
  }

  // The stored model and scale use every pixel.
  fit.model = FitLogLinear(all, targets(all), features);
  MatchVariance(fit.model, all);
  fit.eq2_scale = Eq2Scale(all);
  fit.model.Validate();
  return fit;
}

}  // namespace tofcam
