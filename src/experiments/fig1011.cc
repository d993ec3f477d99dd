#include "experiment_common.h"

namespace tofcam::experiments::internal {

// ---- fig. 10/11: lamps --------------------------------------------------------------------

ExperimentResult Fig1011(const ExperimentOptions& o) {
  ExperimentResult r;
  r.title = "Figs. 10 and 11: lamps off and on, without and with the filter";
  const Shared& s = GetShared(o);
  const int frames = Scaled(16, o.effort, 6);
  constexpr int kRegister = 60;  // 15.3 ms, the paper's working exposure
  sim::SimulatedCamera camera(sim::LoadBuiltinScene("lamps"), s.model, Sim(o, 40, kRegister));
  PipelineOptions popts = BaseOptions(s);
  popts.color.far_m = 5.0;
  Pipeline pipeline(popts, camera.Info());
  Table t{"fig1011_lamps",
          {"lamps", "mean intensity", "mean amplitude", "mean ΔL", "bad before", "bad after",
           "RMSE before", "RMSE after", "bad removed", "good kept", "noisy area removed",
           "precise kept"},
          {},
          true};
  // The "noisy area" of fig. 10, measured, not predicted: pixels whose RMS error against the truth
  // over the frames (noise and bias as they came out of the simulated sensor) the lamps at least
  // double and raise clearly past the threshold (1.5 x: ΔL is itself estimated from noisy
  // registers, so pixels right at the threshold fall either side); "precise" pixels keep an RMS
  // error below half the threshold with the lamps on. (Judging by the simulator's closed-form σ
  // instead would be circular: that σ is eq. 2's own model.)
  std::vector<double> sq_off, sq_on;      // Σ error² per pixel over the frames
  std::vector<int> n_off, n_on, kept_on;  // frames with a finite error; frames kept (on)
  const double kThreshold = popts.filters.accuracy.max_delta_l_m;
  // scenes/lamps.yaml: off 0-1 s, on 1-3 s.
  for (const auto& [label, start_s] :
       {std::pair<const char*, double>{"off", 0.2}, std::pair<const char*, double>{"on", 1.4}}) {
    ErrorPool raw, kept, bad_raw, bad_kept, good_raw, good_kept;
    long long lamp_bad = 0, lamp_bad_removed = 0, untouched_good = 0, untouched_good_kept = 0;
    const bool on = std::string(label) == "on";
    double si = 0, sa = 0;
    long long n = 0;
    for (int k = 0; k < frames; ++k) {
      PipelineResult res = pipeline.Process(k == 0 ? GrabAt(camera, start_s) : *camera.Grab());
      const MetricFrame& f = res.frame;
      if (k == 0) {
        r.images.push_back({std::string("fig10_lamps_") + label + "_raw",
                            std::string("lamps ") + label + ", without filter",
                            pipeline.RenderRaw(res)});
        r.images.push_back({std::string("fig11_lamps_") + label + "_filtered",
                            std::string("lamps ") + label + ", with filter",
                            pipeline.RenderFiltered(res)});
      }
      std::vector<double>& sq = on ? sq_on : sq_off;
      std::vector<int>& count = on ? n_on : n_off;
      if (k == 0) {
        sq.assign(f.flags.size(), 0.0);
        count.assign(f.flags.size(), 0);
        if (on) kept_on.assign(f.flags.size(), 0);
      }
      for (std::size_t i = 0; i < f.flags.size(); ++i) {
        if (!res.input_flags[i].Valid()) continue;
        const double e = ErrorAt(f, i);
        if (std::isfinite(e)) {
          sq[i] += e * e;
          ++count[i];
          if (on && f.flags[i].Valid()) ++kept_on[i];
        }
        const bool ok = f.flags[i].Valid();
        si += f.intensity[i];
        sa += f.amplitude[i];
        ++n;
        raw.Add(f, i);
        if (ok) kept.Add(f, i);
        const bool bad = IsBad(f, i);
        if (bad) {
          bad_raw.Add(f, i);
          if (ok) bad_kept.Add(f, i);
        } else {
          good_raw.Add(f, i);
          if (ok) good_kept.Add(f, i);
        }
      }
    }
    if (on) {
      for (std::size_t i = 0; i < sq_on.size(); ++i) {
        // Pixels measured in every frame of both phases.
        if (n_on[i] != frames || n_off[i] != frames) continue;
        const double rms_on = std::sqrt(sq_on[i] / frames);
        const double rms_off = std::sqrt(sq_off[i] / frames);
        if (rms_on >= 2.0 * rms_off && rms_on >= 1.5 * kThreshold) {
          lamp_bad += frames;
          lamp_bad_removed += frames - kept_on[i];
        } else if (rms_on < 0.5 * kThreshold) {
          untouched_good += frames;
          untouched_good_kept += kept_on[i];
        }
      }
    }
    const double lamp_removed = Ratio(lamp_bad_removed, lamp_bad);
    const double untouched_kept = Ratio(untouched_good_kept, untouched_good);
    const double bad_removed = 1.0 - Ratio(bad_kept.pixels, bad_raw.pixels);
    const double good_kept_fraction = Ratio(good_kept.pixels, good_raw.pixels);
    t.rows.push_back({label, F(si / n, 5), F(sa / n, 5), Mm(raw.MeanDeltaL()),
                      I(bad_raw.pixels / frames), I(bad_kept.pixels / frames), Mm(raw.Rmse()),
                      Mm(kept.Rmse()), Pct(bad_removed), Pct(good_kept_fraction),
                      on ? Pct(lamp_removed) + " of " + I(lamp_bad / frames) : "-",
                      on ? Pct(untouched_kept) + " of " + I(untouched_good / frames) : "-"});
    if (on) {
      r.metrics["on.noisy_area_removed"] = lamp_removed;
      r.metrics["on.noisy_area_pixels"] = static_cast<double>(lamp_bad) / frames;
      r.metrics["on.precise_kept"] = untouched_kept;
    }
    const std::string key = label;
    r.metrics[key + ".mean_delta_l"] = raw.MeanDeltaL();
    r.metrics[key + ".mean_amplitude"] = sa / n;
    r.metrics[key + ".mean_intensity"] = si / n;
    r.metrics[key + ".bad_removed"] = bad_removed;
    r.metrics[key + ".good_kept"] = good_kept_fraction;
    r.metrics[key + ".bad_pixels"] = static_cast<double>(bad_raw.pixels) / frames;
    r.metrics[key + ".rmse_before"] = raw.Rmse();
    r.metrics[key + ".rmse_after"] = kept.Rmse();
  }
  r.tables.push_back(t);
  const auto metric = [&](const std::string& key) { return r.metrics.at(key); };
  const double intensity_gain = metric("on.mean_intensity") / metric("off.mean_intensity");
  const double amplitude_gain = metric("on.mean_amplitude") / metric("off.mean_amplitude");
  std::ostringstream text;
  text << "`lamps` scene at register 60 (15.3 ms), " << frames
       << " frames with the lamps off (from 0.2 s) and on (from 1.4 s); counts are per frame, "
          "bad = |error| > 5 cm. Switching the lamps on multiplies the mean intensity by "
       << F(intensity_gain, 3) << " and the mean amplitude by " << F(amplitude_gain, 3)
       << " and raises the mean ΔL from " << Mm(metric("off.mean_delta_l")) << " to "
       << Mm(metric("on.mean_delta_l"));
  if (intensity_gain > 1.5 && std::abs(amplitude_gain - 1) < 0.05) {
    text << ": the lamps' infrared is offset without modulation, so it adds shot noise and "
            "no signal, as the paper's section III-C describes";
  }
  text << ". Noisy area, as measured: pixels whose RMS error against the truth over the " << frames
       << " frames the lamps at least double and raise clearly past the threshold (to 1.5 x 7 "
          "cm or more: ΔL is estimated from noisy registers, so pixels right at the threshold "
          "fall either side); precise: pixels whose RMS error stays below 3.5 cm with the lamps "
          "on. (Not the simulator's closed-form σ, which is eq. 2's own model: judging the "
          "filter by it would be circular.) The filter removes "
       << Pct(metric("on.noisy_area_removed")) << " of the " << F(metric("on.noisy_area_pixels"), 4)
       << " noisy-area pixels and keeps " << Pct(metric("on.precise_kept"))
       << " of the precise ones";
  text << (metric("on.noisy_area_removed") > 0.9 && metric("on.precise_kept") > 0.9
               ? ": the paper's fig. 11 (\"the noisy area was filtered out completely\") holds."
               : ": the paper's fig. 11 is not reproduced.");
  text << " The plain \"bad removed\" column also counts pixels that are more than 5 cm off by "
          "chance while their σ is below the threshold; the filter keeps those by design.\n";
  r.text = text.str();
  return r;
}

}  // namespace tofcam::experiments::internal
