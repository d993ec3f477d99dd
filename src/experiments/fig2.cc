#include "experiment_common.h"

namespace tofcam::experiments::internal {
namespace {

// Per-pixel error (calibrated - true distance) over the frames of a static view.
struct PixelSeries {
  std::vector<double> sum, sum_sq;
  std::vector<int> n;
  explicit PixelSeries(std::size_t size) : sum(size, 0.0), sum_sq(size, 0.0), n(size, 0) {}
  void Add(std::size_t i, double e) {
    sum[i] += e;
    sum_sq[i] += e * e;
    ++n[i];
  }
  [[nodiscard]] double Mean(std::size_t i) const { return n[i] ? sum[i] / n[i] : kNaN; }
  // Sample variance (n - 1): the temporal noise, whatever the pixel's bias.
  [[nodiscard]] double Variance(std::size_t i) const {
    if (n[i] < 2) return kNaN;
    return std::max(0.0, (sum_sq[i] - sum[i] * sum[i] / n[i]) / (n[i] - 1));
  }
};

// Fig. 2: one exposure of the hand, its error statistics and per-pixel series.
struct HandExposure {
  int reg = 0;
  int frames = 0;
  ErrorPool all, background;
  PixelSeries series{0};
  Image<std::uint8_t> saturated;  // truth kSaturated in any frame
  Image<float> truth_m;
  Image<float> truth_sigma_m;  // closed-form shot-noise σ of the first frame (ground truth)
  Image<PixelFlags> causes;    // truth causes of the first frame
  ScatteringBias bias;
  Image<Rgb8> raw_image;
  long long saturated_pixels = 0;
};

HandExposure RunHandExposure(const ExperimentOptions& o, int reg, int frames,
                             std::uint64_t seed_offset) {
  const Shared& s = GetShared(o);
  const sim::Scene scene = sim::LoadBuiltinScene("hand");
  sim::SimulatedCamera camera(scene, s.model, Sim(o, seed_offset, reg));
  PipelineOptions popts = RawOptions(s);
  popts.color.far_m = 4.0;  // the wall is at 3 m
  Pipeline pipeline(popts, camera.Info());
  HandExposure h;
  h.reg = reg;
  h.frames = frames;
  h.series = PixelSeries(static_cast<std::size_t>(s.info.width()) * s.info.height());
  h.saturated = Image<std::uint8_t>(s.info.width(), s.info.height(), 0);
  PipelineResult res;
  for (int k = 0; k < frames; ++k) {
    pipeline.Process(*camera.Grab(), res);
    const MetricFrame& f = res.frame;
    if (k == 0) {
      h.raw_image = pipeline.RenderRaw(res);
      h.truth_m = f.truth->radial_distance_m;
      h.truth_sigma_m = f.truth->sigma_m;
      h.causes = f.truth->causes;
    }
    for (std::size_t i = 0; i < f.flags.size(); ++i) {
      if (f.truth->causes[i].Has(Flag::kSaturated)) {
        h.saturated[i] = 1;
        ++h.saturated_pixels;
      }
      if (!f.flags[i].Valid()) continue;
      h.all.Add(f, i);
      if (f.truth->radial_distance_m[i] > kBackgroundM) h.background.Add(f, i);
      const double e = ErrorAt(f, i);
      if (std::isfinite(e)) h.series.Add(i, e);
    }
  }
  h.bias = MeasureScatteringBias(scene, reg, 0.0, o);
  return h;
}

// Pooled statistics of the background pixels of one set at one exposure.
struct WallStats {
  long long pixels = 0;
  double mse = 0, noise_var = 0, truth_var = 0, bias_sq = 0, other_sq = 0;
  void Add(const HandExposure& h, std::size_t i) {
    const double mean = h.series.Mean(i), var = h.series.Variance(i), b = h.bias.bias_m[i];
    const double n = h.series.n[i];
    ++pixels;
    // Mean squared error over the frames = mean² + (n-1)/n · sample variance.
    mse += mean * mean + (n - 1) / n * var;
    noise_var += var;
    truth_var += static_cast<double>(h.truth_sigma_m[i]) * h.truth_sigma_m[i];
    bias_sq += b * b;
    // What the mean error keeps beyond the scattering bias, less the noise of an n-frame mean.
    other_sq += (mean - b) * (mean - b) - var / n;
  }
  [[nodiscard]] double Rmse() const { return pixels ? std::sqrt(mse / pixels) : kNaN; }
  [[nodiscard]] double Noise() const { return pixels ? std::sqrt(noise_var / pixels) : kNaN; }
  [[nodiscard]] double Bias() const { return pixels ? std::sqrt(bias_sq / pixels) : kNaN; }
  [[nodiscard]] double Other() const {
    return pixels ? std::sqrt(std::max(0.0, other_sq / pixels)) : kNaN;
  }
  [[nodiscard]] double TruthSigma() const { return pixels ? std::sqrt(truth_var / pixels) : kNaN; }
};

}  // namespace

ExperimentResult Fig2(const ExperimentOptions& o) {
  ExperimentResult r;
  r.title = "Fig. 2: the hand at 15 ms and at 4 ms";
  const Shared& s = GetShared(o);
  const int frames = Scaled(10, o.effort, 4);
  const HandExposure at15 = RunHandExposure(o, 59, frames, 20);
  const HandExposure at4 = RunHandExposure(o, 16, frames, 21);
  const double t15 = at15.reg * kRegisterMs, t4 = at4.reg * kRegisterMs;
  r.images.push_back({"fig2_15ms", F(t15, 3) + " ms (register 59), raw", at15.raw_image});
  r.images.push_back({"fig2_4ms", F(t4, 3) + " ms (register 16), raw", at4.raw_image});
  Table t{"fig2_errors",
          {"integration", "saturated px/frame", "RMSE all", "bad (>5 cm) all", "RMSE background",
           "bad background"},
          {},
          true};
  for (const HandExposure* h : {&at15, &at4}) {
    t.rows.push_back({F(h->reg * kRegisterMs, 3) + " ms",
                      F(static_cast<double>(h->saturated_pixels) / frames, 5), Mm(h->all.Rmse()),
                      Pct(h->all.BadFraction()), Mm(h->background.Rmse()),
                      Pct(h->background.BadFraction())});
  }
  r.tables.push_back(t);

  // Background pixels measured in every frame at both exposures, not saturated, not mixed (an edge
  // pixel's error is neither noise nor scattering). The bloomed neighbourhood: within 3 blooming
  // sigmas of a pixel saturated at 15 ms.
  const int w = s.info.width(), hgt = s.info.height();
  const int reach = static_cast<int>(std::ceil(3.0 * s.model.blooming_sigma_px));
  Image<std::uint8_t> near(w, hgt, 0);
  for (int y = 0; y < hgt; ++y) {
    for (int x = 0; x < w; ++x) {
      if (!at15.saturated(y, x)) continue;
      for (int dy = -reach; dy <= reach; ++dy) {
        for (int dx = -reach; dx <= reach; ++dx) {
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || yy >= hgt || xx < 0 || xx >= w || dx * dx + dy * dy > reach * reach)
            continue;
          near(yy, xx) = 1;
        }
      }
    }
  }
  WallStats zone15, zone4, rest15, rest4;
  double map_diff_sq = 0;
  long long map_n = 0, biased5_15 = 0, biased5_4 = 0, biased20_15 = 0, biased20_4 = 0;
  Image<float> bias_map(w, hgt, kNaNf);
  for (std::size_t i = 0; i < near.size(); ++i) {
    if (!(at15.truth_m[i] > kBackgroundM) || at15.causes[i].Has(Flag::kMixed)) continue;
    if (at15.saturated[i] || at4.saturated[i]) continue;
    if (at15.series.n[i] != frames || at4.series.n[i] != frames) continue;
    const double b15 = at15.bias.bias_m[i], b4 = at4.bias.bias_m[i];
    if (!std::isfinite(b15) || !std::isfinite(b4)) continue;
    bias_map[i] = static_cast<float>(b15);
    map_diff_sq += (b15 - b4) * (b15 - b4);
    ++map_n;
    biased5_15 += std::abs(b15) > 0.05;
    biased5_4 += std::abs(b4) > 0.05;
    biased20_15 += std::abs(b15) > 0.2;
    biased20_4 += std::abs(b4) > 0.2;
    (near[i] ? zone15 : rest15).Add(at15, i);
    (near[i] ? zone4 : rest4).Add(at4, i);
  }
  const double scale_to_15 = std::sqrt(t4 / t15);  // shot noise σ ∝ 1/sqrt(T)
  Table d{"fig2_decomposition",
          {"background pixels", "px", "integration", "RMSE", "noise σ (temporal)",
           "σ expected by 1/√T from the other exposure", "σ closed form (truth)",
           "scattering bias RMS (noise-free)", "other systematic RMS"},
          {},
          true};
  const auto row = [&](const std::string& set, const WallStats& a, double t_ms,
                       const WallStats& other, double scale) {
    d.rows.push_back({set, I(a.pixels), F(t_ms, 3) + " ms", Mm(a.Rmse()), Mm(a.Noise()),
                      Mm(other.Noise() * scale), Mm(a.TruthSigma()), Mm(a.Bias()), Mm(a.Other())});
  };
  const std::string zone_label = "within " + I(reach) + " px of a saturated pixel";
  row(zone_label, zone15, t15, zone4, scale_to_15);
  row(zone_label, zone4, t4, zone15, 1.0 / scale_to_15);
  row("rest of the background", rest15, t15, rest4, scale_to_15);
  row("rest of the background", rest4, t4, rest15, 1.0 / scale_to_15);
  r.tables.push_back(d);
  r.tables.push_back(MatrixTable("fig2_scattering_bias", bias_map));
  r.plots = {"fig2_bias"};

  const double sat15 = static_cast<double>(at15.saturated_pixels) / frames;
  const double sat4 = static_cast<double>(at4.saturated_pixels) / frames;
  const double zone_excess = zone15.Noise() / (zone4.Noise() * scale_to_15);
  const double rest_excess = rest15.Noise() / (rest4.Noise() * scale_to_15);
  const double map_rms_diff = map_n ? std::sqrt(map_diff_sq / map_n) : kNaN;
  const double noise_ratio = rest4.Noise() / rest15.Noise();
  r.metrics["saturated_15ms"] = sat15;
  r.metrics["saturated_4ms"] = sat4;
  r.metrics["background_bad_15ms"] = at15.background.BadFraction();
  r.metrics["background_bad_4ms"] = at4.background.BadFraction();
  r.metrics["zone_pixels"] = static_cast<double>(zone15.pixels);
  r.metrics["zone_noise_over_expected_15ms"] = zone_excess;
  r.metrics["rest_noise_over_expected_15ms"] = rest_excess;
  r.metrics["rest_noise_4ms_over_15ms"] = noise_ratio;
  r.metrics["rest_noise_15ms"] = rest15.Noise();
  r.metrics["rest_noise_4ms"] = rest4.Noise();
  r.metrics["expected_noise_ratio"] = 1.0 / scale_to_15;
  r.metrics["bias_map_rms_difference_m"] = map_rms_diff;
  r.metrics["bias_rms_15ms"] = std::sqrt((zone15.bias_sq + rest15.bias_sq) /
                                         std::max<long long>(1, zone15.pixels + rest15.pixels));
  r.metrics["biased5_15ms"] = static_cast<double>(biased5_15);
  r.metrics["biased5_4ms"] = static_cast<double>(biased5_4);
  r.metrics["biased20_15ms"] = static_cast<double>(biased20_15);
  r.metrics["wall_pixels"] = static_cast<double>(map_n);

  std::ostringstream text;
  const double truth_ratio = rest4.TruthSigma() / rest15.TruthSigma();
  r.metrics["rest_truth_sigma_4ms_over_15ms"] = truth_ratio;
  text << "False colour of the raw (unfiltered, calibrated) distances, 0 m yellow to 4 m blue "
          "(the wall is at 3 m), black = no measurement; "
       << frames << " frames per exposure. The second table splits what differs between the "
       << "two exposures against the ground truth, over the " << map_n
       << " background pixels (true distance > " << kBackgroundM
       << " m: the wall and the floor) measured in every frame at both exposures, not saturated "
          "and not on a depth edge: the temporal noise σ (per pixel over the frames), the "
          "closed-form shot-noise σ of the simulator's truth, the scattering bias from "
          "noise-free renderings with the scattering PSF on and off (map below, "
       << F(t15, 3) << " ms), and what remains of the mean error beyond both.\n\n";
  text << "- **Saturation:** " << F(sat15, 4) << " pixels per frame saturate at " << F(t15, 3)
       << " ms, " << F(sat4, 4) << " at " << F(t4, 3) << " ms"
       << (sat4 == 0 ? " (the hand is unsaturated, as in the paper's fig. 2b)" : "") << ".\n";
  text << "- **Blooming:** the " << zone15.pixels << " background pixels within " << reach
       << " px (3 blooming σ) of a saturated pixel have a temporal σ of " << Mm(zone15.Noise())
       << " at " << F(t15, 3) << " ms, " << F(zone_excess, 3)
       << " x what the 1/√T scaling of their σ at " << F(t4, 3) << " ms predicts ("
       << Mm(zone4.Noise() * scale_to_15) << "); the rest of the background, which blooming "
       << "does not reach, comes out at " << F(rest_excess, 3) << " x. ";
  if (zone_excess > 1.2 * rest_excess) {
    text << "Relative to it the bloomed neighbourhood is " << F(zone_excess / rest_excess, 3)
         << " x noisier: the bloomed charge arrives unmodulated, so it raises the offset (and "
            "its shot noise) but not the amplitude; the closed-form σ, which includes the "
            "spill, is "
         << Mm(zone15.TruthSigma()) << " there.\n";
  } else {
    text << "Blooming adds no noise beyond the 1/√T expectation here.\n";
  }
  text << "- **Scattering:** " << biased5_15 << " background pixels are biased by more than 5 cm ("
       << biased20_15 << " by more than 20 cm) at " << F(t15, 3) << " ms and " << biased5_4
       << " at " << F(t4, 3) << " ms; the two bias maps differ by " << Mm(map_rms_diff) << " RMS. ";
  if (map_rms_diff < 0.005) {
    text << "The scattering bias does not depend on the exposure: scattering is linear optics, "
            "the light the hand scatters onto a background pixel and the pixel's own light both "
            "grow with T, so their phasor sum keeps its phase; saturation happens after the "
            "optics and does not change what is scattered.";
    if (biased5_4 > 0) {
      text << " **Against the paper:** the 4 ms frame is not clean; its background carries the "
              "same scattering bias as the 15 ms frame, and the paper's impression of a cleaner "
              "image comes from the missing saturation and blooming, not from less scattering.";
    }
    text << "\n";
  } else {
    text << "The bias maps differ between the exposures more than quantisation explains.\n";
  }
  text << "- **Shot noise:** away from the hand the background's σ is " << Mm(rest4.Noise())
       << " at " << F(t4, 3) << " ms and " << Mm(rest15.Noise()) << " at " << F(t15, 3)
       << " ms, a ratio of " << F(noise_ratio, 3)
       << " where pure shot noise gives √(T15/T4) = " << F(1.0 / scale_to_15, 3)
       << ". The closed-form σ predicts " << F(truth_ratio, 3);
  if (std::abs(truth_ratio / noise_ratio - 1.0) < 0.15) {
    text << ", so the extra comes from what the closed form adds to the signal's shot noise: "
            "read noise and dark current, which do not grow with the signal and weigh more in "
            "the short exposure";
  }
  text << ". The background's RMSE away from the hand is " << Mm(rest4.Rmse()) << " at " << F(t4, 3)
       << " ms against " << Mm(rest15.Rmse()) << " at " << F(t15, 3) << " ms"
       << (rest4.Rmse() > rest15.Rmse() ? ": the short exposure is worse there" : "") << ".\n";
  r.text = text.str();
  return r;
}

}  // namespace tofcam::experiments::internal
