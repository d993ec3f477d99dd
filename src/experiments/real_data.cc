#include "experiment_common.h"

namespace tofcam::experiments::internal {
namespace {

// ---- real data ------------------------------------------------------------------------------

std::vector<double> Ranks(const std::vector<double>& v) {
  std::vector<std::size_t> order(v.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return v[a] < v[b]; });
  std::vector<double> ranks(v.size());
  for (std::size_t i = 0; i < order.size();) {
    std::size_t j = i;
    while (j + 1 < order.size() && v[order[j + 1]] == v[order[i]]) ++j;
    for (std::size_t k = i; k <= j; ++k) ranks[order[k]] = 0.5 * (i + j);
    i = j + 1;
  }
  return ranks;
}

double Pearson(const std::vector<double>& a, const std::vector<double>& b) {
  const double n = static_cast<double>(a.size());
  const double ma = std::accumulate(a.begin(), a.end(), 0.0) / n;
  const double mb = std::accumulate(b.begin(), b.end(), 0.0) / n;
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return sab / std::sqrt(saa * sbb);
}

}  // namespace

ExperimentResult RealData(const ExperimentOptions& o) {
  ExperimentResult r;
  r.title = "Real data: the accuracy model on ifm O3D303 frames";
  const fs::path file = o.real_data_dir / "o3d3xx.h5";
  const ImportedSequence seq = ImportIfmO3d3xx(file);
  std::vector<MetricFrame> frames;
  for (const Frame& f : seq.frames) {
    MetricFrame m = ConvertToMetric(f);
    m.delta_l_m = ComputeDeltaL(m);
    frames.push_back(std::move(m));
  }
  if (frames.size() < 3) {
    throw Error(ErrorCode::kFormat,
                file.string() + ": needs at least 3 frames, has " + std::to_string(frames.size()));
  }
  const DeltaLScaleFit fit = FitDeltaLScale(frames);
  // Per-pixel temporal σ (sample, about the mean; no wrap: the O3D303 range is 32.8 m) vs ΔL.
  std::vector<double> sigma, delta;
  const std::size_t n = frames[0].radial_distance_m.size();
  const double nf = static_cast<double>(frames.size());
  for (std::size_t i = 0; i < n; ++i) {
    double sum = 0, sq = 0, dl = 0;
    bool ok = true;
    for (const MetricFrame& m : frames) {
      if (!m.flags[i].Valid() || !std::isfinite(m.delta_l_m[i])) ok = false;
      sum += m.radial_distance_m[i];
      dl += m.delta_l_m[i];
    }
    if (!ok) continue;
    for (const MetricFrame& m : frames) {
      sq += (m.radial_distance_m[i] - sum / nf) * (m.radial_distance_m[i] - sum / nf);
    }
    sigma.push_back(std::sqrt(sq / (nf - 1)));
    delta.push_back(dl / nf);
  }
  const double spearman = Pearson(Ranks(sigma), Ranks(delta));
  // Decile table: mean measured σ per decile of predicted ΔL.
  std::vector<std::size_t> order(delta.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return delta[a] < delta[b]; });
  Table t{"real_data_deciles",
          {"decile", "mean_delta_l_m", "rms_sigma_m", "predicted_sigma_m"},
          {},
          false};
  for (int d = 0; d < 10; ++d) {
    const std::size_t a = order.size() * d / 10, b = order.size() * (d + 1) / 10;
    double sd = 0, ss = 0;
    for (std::size_t k = a; k < b; ++k) {
      sd += delta[order[k]];
      ss += sigma[order[k]] * sigma[order[k]];
    }
    const double cnt = static_cast<double>(std::max<std::size_t>(1, b - a));
    t.rows.push_back(
        {I(d + 1), F(sd / cnt, 4), F(std::sqrt(ss / cnt), 4), F(fit.scale * sd / cnt, 4)});
  }
  r.tables.push_back(t);
  Table summary{"real_data_summary",
                {"frames", "pixels", "Spearman ρ(ΔL, σ)", "fitted scale", "median σ/ΔL", "R²",
                 "relative RMS"},
                {},
                true};
  summary.rows.push_back({I(static_cast<long long>(frames.size())),
                          I(static_cast<long long>(sigma.size())), F(spearman, 3), F(fit.scale, 4),
                          F(fit.median_ratio, 4), F(fit.r_squared, 3), F(fit.relative_rms, 3)});
  r.tables.push_back(summary);
  r.plots = {"real_data"};
  r.metrics["spearman"] = spearman;
  r.metrics["scale"] = fit.scale;
  r.metrics["pixels"] = static_cast<double>(sigma.size());
  int rises = 0;
  for (std::size_t d = 1; d < t.rows.size(); ++d) {
    rises += std::stod(t.rows[d][2]) > std::stod(t.rows[d - 1][2]);
  }
  const double sigma_rel_error = 1.0 / std::sqrt(2.0 * (nf - 1));
  r.metrics["decile_rises"] = rises;
  std::ostringstream text;
  text << "The ifm O3D303 recording in tests/data/real/ifm_o3d303 (" << frames.size()
       << " frames, licence alongside) has no intensity channel, so ΔL uses the amplitude-only "
          "form (I = 2.5 A). A temporal σ from "
       << frames.size() << " frames is itself a noisy estimate (relative standard error "
       << "1/√(2(n-1)) = " << Pct(sigma_rel_error)
       << "), which caps the per-pixel rank correlation well below 1 even for a perfect model. "
          "Over "
       << sigma.size() << " pixels the Spearman correlation of ΔL with the measured σ is "
       << F(spearman, 3);
  text << (spearman > 0.3 ? ": eq. 2 ranks the real camera's noise" : ": eq. 2 ranks it poorly");
  text << "; averaged over deciles of ΔL the measured σ rises in " << rises << " of "
       << t.rows.size() - 1 << " steps. The fitted scale (σ = " << F(fit.scale, 3) << " x ΔL; R² "
       << F(fit.r_squared, 3)
       << " of the per-pixel fit) is specific to this camera's register scaling.\n";
  r.text = text.str();
  return r;
}

}  // namespace tofcam::experiments::internal
