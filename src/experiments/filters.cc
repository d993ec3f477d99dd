#include "experiment_common.h"

namespace tofcam::experiments::internal {
namespace {

// ---- filters over all scenes ----------------------------------------------------------------

struct Confusion {
  long long flagged_bad = 0, flagged = 0, bad = 0;
  long long flagged_bad3 = 0, bad3 = 0;
  double kept_sq = 0;
  long long kept_n = 0;
  double kept_sq_in_range = 0;  // kept pixels whose surface lies within L (no phase wrap)
  long long kept_n_in_range = 0;
  double seconds = 0;
  long long frames = 0;
};

// One row of the filters experiment: a pixel filter of the catalogue, a cloud filter, or a
// pixel filter set followed by a cloud filter on the points it kept.
struct FilterRow {
  std::string name;
  std::string parameter;
  Confusion confusion;
};

// The cloud of the pixels `keep` admits (camera frame, metres) and their pixel indices.
void BuildCloud(const MetricFrame& f, const RayTable& rays, const Image<PixelFlags>* extra,
                std::vector<CloudPoint>& points, std::vector<std::size_t>& pixels) {
  points.clear();
  pixels.clear();
  for (std::size_t i = 0; i < f.flags.size(); ++i) {
    const float d = f.radial_distance_m[i];
    if (!f.flags[i].Valid() || (extra && (*extra)[i].Any(kRejectMask)) || !std::isfinite(d)) {
      continue;
    }
    points.push_back({d * rays.x[i], d * rays.y[i], d * rays.z[i]});
    pixels.push_back(i);
  }
}

}  // namespace

// The smoothing stages (not in the paper: every camera SDK has them) after the paper's accuracy
// filter, on every built-in scene: the same frames through four pipelines that differ only in
// the smoothing, errors of the kept pixels against the truth. Dynamic scenes run their whole
// duration, so the temporal filter must follow the motion (hand, lamps, the approach).
void SmoothingTable(const ExperimentOptions& o, const Shared& s, ExperimentResult& r,
                    std::ostringstream& text) {
  struct Variant {
    std::string name;
    bool smoothing = false;
    SpatialFilterKind kind = SpatialFilterKind::kMedian;
    bool temporal = false;
  };
  const std::vector<Variant> variants = {
      {"none"},
      {"median 3x3", true, SpatialFilterKind::kMedian},
      {"bilateral 3x3 (ΔL)", true, SpatialFilterKind::kBilateral},
      {"temporal (ΔL, 8 frames)", false, {}, true}};
  Table t{"filters_smoothing",
          {"scene", "smoothing", "kept pixels", "median |error|", "RMSE within L",
           "bad (> 5 cm) among kept"},
          {},
          true};
  std::vector<double> median_sum(variants.size(), 0.0), rmse_sum(variants.size(), 0.0);
  int scenes = 0, scene_index = 0;  // scenes with kept pixels (beyond-range has none)
  for (const std::string& name : sim::BuiltinSceneNames()) {
    sim::Scene scene = sim::LoadBuiltinScene(name);
    const bool dynamic = scene.duration_s > 0;
    const double duration = dynamic ? scene.duration_s * std::min(1.0, o.effort * 2) : 0.0;
    sim::SimulatedCamera camera(std::move(scene), s.model, Sim(o, 500 + scene_index++, 0));
    std::vector<Pipeline> pipelines;
    for (const Variant& v : variants) {
      PipelineOptions p = BaseOptions(s);
      p.smoothing_enabled = v.smoothing;
      p.smoothing.kind = v.kind;
      p.temporal_enabled = v.temporal;
      p.controller_enabled = pipelines.empty();  // the first one sets the exposure for all
      pipelines.emplace_back(p, camera.Info());
    }
    camera.SetIntegrationTimeRegister(pipelines.front().InitialIntegrationRegister());
    std::vector<std::vector<double>> errors(variants.size());
    std::vector<long long> bad(variants.size(), 0);
    const int static_frames = Scaled(16, o.effort, 10);
    PipelineResult res;
    for (int k = 0;; ++k) {
      if (dynamic ? camera.NextExposureStartS() >= duration : k >= static_frames) break;
      const Frame frame = *camera.Grab();
      // Scored: the last half of a static run (the temporal filter settled), every 5th frame of
      // a dynamic one after its first second.
      const bool scored = dynamic ? (k % 5 == 0 && frame.info.timestamp_ns > 1'000'000'000)
                                  : k >= static_frames / 2;
      for (std::size_t v = 0; v < variants.size(); ++v) {
        pipelines[v].Process(frame, res);
        if (v == 0) camera.SetIntegrationTimeRegister(res.next_integration_register);
        if (!scored) continue;
        const MetricFrame& f = res.frame;
        for (std::size_t i = 0; i < f.flags.size(); ++i) {
          if (!f.flags[i].Valid() || f.truth->causes[i].Has(Flag::kBeyondUnambiguous)) continue;
          const double e = ErrorAt(f, i);
          if (!std::isfinite(e)) continue;
          errors[v].push_back(std::abs(e));
          bad[v] += std::abs(e) > kBadErrorM;
        }
      }
    }
    if (!errors.front().empty()) ++scenes;
    for (std::size_t v = 0; v < variants.size(); ++v) {
      std::vector<double>& e = errors[v];
      double sq = 0;
      for (double x : e) sq += x * x;
      const double rmse = e.empty() ? kNaN : std::sqrt(sq / e.size());
      double median = kNaN;
      if (!e.empty()) {
        std::nth_element(e.begin(), e.begin() + e.size() / 2, e.end());
        median = e[e.size() / 2];
      }
      if (!e.empty()) {
        median_sum[v] += median;
        rmse_sum[v] += rmse;
      }
      t.rows.push_back({name, variants[v].name, I(static_cast<long long>(e.size())), Mm(median),
                        Mm(rmse), Pct(Ratio(bad[v], static_cast<long long>(e.size())))});
      r.metrics["smoothing." + name + "." + variants[v].name + ".median_error"] = median;
      r.metrics["smoothing." + name + "." + variants[v].name + ".rmse"] = rmse;
    }
  }
  r.tables.push_back(t);
  text << "\n\nSmoothing after the accuracy filter (not in the paper; every camera SDK has "
          "it): the same frames of every built-in scene through four pipelines that differ "
          "only in the smoothing (tofcam/filters/spatial_filter.h, temporal_filter.h; support "
          "limited to 10 cm around the centre; the temporal average capped at 8 frames, reset "
          "after two frames beyond 3 σ); errors of the kept pixels (within L) against the "
          "truth. Mean over the scenes of the median |error|:";
  for (std::size_t v = 0; v < variants.size(); ++v) {
    text << (v ? ", " : " ") << variants[v].name << " " << Mm(median_sum[v] / scenes);
    r.metrics["smoothing.mean_median_error." + variants[v].name] = median_sum[v] / scenes;
    r.metrics["smoothing.mean_rmse." + variants[v].name] = rmse_sum[v] / scenes;
  }
  text << "; mean RMSE:";
  for (std::size_t v = 0; v < variants.size(); ++v) {
    text << (v ? ", " : " ") << variants[v].name << " " << Mm(rmse_sum[v] / scenes);
  }
  text << " (over the " << scenes
       << " scenes with kept pixels). Smoothing lowers the noise of the kept pixels; it cannot "
          "remove what the filters kept by mistake (mixed pixels, scattering bias), which "
          "dominates the RMSE. The temporal filter assumes each pixel sees one surface for a "
          "while: on the approach (the robot drives at 0.75 m/s) it has to restart often, see its "
          "row.";
}

ExperimentResult Filters(const ExperimentOptions& o) {
  ExperimentResult r;
  r.title = "Filters over all built-in scenes";
  const Shared& s = GetShared(o);
  const std::vector<NamedFilter> filters = FilterCatalogue(true);
  // Cloud filters (tof-notes §4: what a user would reach for instead). SOR as in the PCL and
  // Open3D tutorials (k 50 / 20, std_mul 1 / 2) and around; radius outlier removal around
  // Open3D's tutorial (16 points in 5 cm): the SR-2's pixel pitch is ~1/200 rad, so 5 cm holds
  // ~100 neighbours at 1 m and ~6 at 4 m.
  const std::vector<int> sor_k = {8, 20, 50};
  const std::vector<double> sor_std = {0.5, 1.0, 2.0, 3.0};
  const std::vector<double> radii = {0.02, 0.05, 0.1};
  const std::vector<int> min_points = {2, 4, 8, 16};
  // Pixel filter + cloud filter on what the pixel filter kept.
  FilterSetOptions pixel_default = NoFilters();
  pixel_default.saturation_enabled = true;
  pixel_default.accuracy_enabled = true;
  std::vector<FilterRow> rows;
  for (const NamedFilter& nf : filters) rows.push_back({nf.name, nf.parameter, {}});
  const std::size_t sor_begin = rows.size();
  for (int k : sor_k) {
    for (double a : sor_std) rows.push_back({"sor", "k " + I(k) + ", std_mul " + F(a, 2), {}});
  }
  const std::size_t radius_begin = rows.size();
  for (double rad : radii) {
    for (int m : min_points) {
      rows.push_back({"radius", "r " + F(rad, 2) + " m, min " + I(m), {}});
    }
  }
  const std::size_t combo_begin = rows.size();
  rows.push_back({"combination", "sat+acc 0.07+sor k 20, std_mul 2", {}});
  rows.push_back({"combination", "sat+acc 0.07+radius r 0.05 m, min 4", {}});
  const int frames_per_scene = Scaled(3, o.effort, 1);
  int scene_index = 0;
  std::string registers_text;
  std::vector<CloudPoint> points;
  std::vector<std::size_t> pixels;
  for (const std::string& name : sim::BuiltinSceneNames()) {
    sim::Scene scene = sim::LoadBuiltinScene(name);
    const double duration = scene.duration_s;
    sim::SimulatedCamera camera(std::move(scene), s.model, Sim(o, 300 + scene_index++, 0));
    // Exposure as the running system would choose it: the incremental P-controller (no
    // steady-state offset) with the library's defaults, running on every frame.
    PipelineOptions popts = RawOptions(s);
    popts.controller_enabled = true;
    popts.controller.kind = ControllerKind::kMayIncremental;
    Pipeline pipeline(popts, camera.Info());
    camera.SetIntegrationTimeRegister(pipeline.InitialIntegrationRegister());
    PipelineResult res;
    auto step = [&] {
      pipeline.Process(*camera.Grab(), res);
      camera.SetIntegrationTimeRegister(res.next_integration_register);
    };
    if (duration <= 0) {
      for (int k = 0; k < 30; ++k) step();  // settle on the static scene
    }
    registers_text += (registers_text.empty() ? "" : ", ") + name + " ";
    for (int k = 0; k < frames_per_scene; ++k) {
      if (duration > 0) {
        const double t = duration * (k + 0.5) / frames_per_scene;
        while (camera.NextExposureStartS() + 1e-9 < t) step();
      }
      step();
      registers_text += (k ? "/" : "") + I(res.stats.integration_time_register);
      const MetricFrame& f = res.frame;
      const RayTable& rays = pipeline.rays();
      // Scores one row: `flagged(i)` for every measured pixel, `seconds` of work.
      const auto account = [&](FilterRow& row, const std::vector<bool>& flagged, double seconds) {
        Confusion& c = row.confusion;
        c.seconds += seconds;
        ++c.frames;
        for (std::size_t i = 0; i < f.flags.size(); ++i) {
          if (!f.flags[i].Valid()) continue;
          const double e = ErrorAt(f, i);
          const bool bad = !std::isfinite(e) || std::abs(e) > kBadErrorM;
          const double sigma = f.truth->sigma_m[i];
          const bool bad3 = !std::isfinite(e) || (sigma > 0 && std::abs(e) > 3.0 * sigma);
          const bool flag = flagged[i];
          c.bad += bad;
          c.bad3 += bad3;
          c.flagged += flag;
          c.flagged_bad += flag && bad;
          c.flagged_bad3 += flag && bad3;
          if (!flag && std::isfinite(e)) {
            c.kept_sq += e * e;
            ++c.kept_n;
            if (!f.truth->causes[i].Has(Flag::kBeyondUnambiguous)) {
              c.kept_sq_in_range += e * e;
              ++c.kept_n_in_range;
            }
          }
        }
      };
      const auto seconds_since = [](Clock::time_point start) {
        return std::chrono::duration<double>(Clock::now() - start).count();
      };
      std::vector<bool> flagged(f.flags.size());
      for (std::size_t n = 0; n < filters.size(); ++n) {
        const Clock::time_point start = Clock::now();
        const Image<PixelFlags> flags = ApplyFilters(f, rays, filters[n].options);
        const double seconds = seconds_since(start);
        for (std::size_t i = 0; i < flagged.size(); ++i) flagged[i] = flags[i].Any(kRejectMask);
        account(rows[n], flagged, seconds);
      }
      // Cloud filters: the time of one setting is its cloud, kd-tree, search and threshold
      // (the settings of one k or radius share the search here, so it is measured once).
      const auto to_pixels = [&](const std::vector<bool>& outlier) {
        std::fill(flagged.begin(), flagged.end(), false);
        for (std::size_t p = 0; p < outlier.size(); ++p) flagged[pixels[p]] = outlier[p];
      };
      std::size_t row = sor_begin;
      for (int neighbours : sor_k) {
        const Clock::time_point start = Clock::now();
        BuildCloud(f, rays, nullptr, points, pixels);
        const std::vector<double> mean = KnnMeanDistances(points, neighbours);
        const double search = seconds_since(start);
        for (double a : sor_std) {
          const Clock::time_point t0 = Clock::now();
          const std::vector<bool> outlier = StatisticalOutliers(mean, a);
          const double threshold = seconds_since(t0);
          to_pixels(outlier);
          account(rows[row++], flagged, search + threshold);
        }
      }
      row = radius_begin;
      for (double rad : radii) {
        const Clock::time_point start = Clock::now();
        BuildCloud(f, rays, nullptr, points, pixels);
        const std::vector<int> counts = RadiusNeighbourCounts(points, rad, min_points.back());
        const double search = seconds_since(start);
        for (int m : min_points) {
          const Clock::time_point t0 = Clock::now();
          const std::vector<bool> outlier = RadiusOutliers(counts, m);
          const double threshold = seconds_since(t0);
          to_pixels(outlier);
          account(rows[row++], flagged, search + threshold);
        }
      }
      // Combinations: the pipeline's default pixel filters, then a cloud filter on the rest.
      for (std::size_t c = 0; c < 2; ++c) {
        const Clock::time_point start = Clock::now();
        const Image<PixelFlags> base = ApplyFilters(f, rays, pixel_default);
        BuildCloud(f, rays, &base, points, pixels);
        const std::vector<bool> outlier =
            c == 0 ? StatisticalOutliers(KnnMeanDistances(points, 20), 2.0)
                   : RadiusOutliers(RadiusNeighbourCounts(points, 0.05, 4), 4);
        to_pixels(outlier);
        for (std::size_t i = 0; i < flagged.size(); ++i) {
          flagged[i] = flagged[i] || base[i].Any(kRejectMask);
        }
        account(rows[combo_begin + c], flagged, seconds_since(start));
      }
    }
  }
  Table t{"filters_pr",
          {"filter", "parameter", "precision_5cm", "recall_5cm", "f1_5cm", "precision_3sigma",
           "recall_3sigma", "rmse_kept_m", "rmse_kept_within_l_m", "kept_fraction", "ms_per_frame"},
          {},
          false};
  double best_f1 = -1;
  std::size_t best = 0;
  std::map<std::string, std::pair<double, std::size_t>> best_per_filter;
  std::map<std::string, double> f1_of;
  for (const FilterRow& row : rows) {
    const Confusion& c = row.confusion;
    const double p = Ratio(c.flagged_bad, c.flagged), rc = Ratio(c.flagged_bad, c.bad);
    const double f1 = (p + rc) > 0 ? 2 * p * rc / (p + rc) : 0.0;
    const double p3 = Ratio(c.flagged_bad3, c.flagged), r3 = Ratio(c.flagged_bad3, c.bad3);
    const double rmse = c.kept_n ? std::sqrt(c.kept_sq / c.kept_n) : kNaN;
    const double rmse_in =
        c.kept_n_in_range ? std::sqrt(c.kept_sq_in_range / c.kept_n_in_range) : kNaN;
    const long long measured = c.flagged + c.kept_n;  // flagged or kept with a finite error
    t.rows.push_back({row.name, row.parameter, F(p, 4), F(rc, 4), F(f1, 4), F(p3, 4), F(r3, 4),
                      F(rmse, 4), F(rmse_in, 4), F(Ratio(c.kept_n, measured), 4),
                      F(1e3 * c.seconds / c.frames, 3)});
    const double f1_safe = std::isfinite(f1) ? f1 : 0.0;
    if (f1_safe > best_f1) {
      best_f1 = f1_safe;
      best = t.rows.size() - 1;
    }
    auto it = best_per_filter.find(row.name);
    if (it == best_per_filter.end() || f1_safe > it->second.first) {
      best_per_filter[row.name] = {f1_safe, t.rows.size() - 1};
    }
    r.metrics[row.name + "[" + row.parameter + "].precision"] = p;
    r.metrics[row.name + "[" + row.parameter + "].recall"] = rc;
    r.metrics[row.name + "[" + row.parameter + "].f1"] = f1_safe;
    r.metrics[row.name + "[" + row.parameter + "].ms"] = 1e3 * c.seconds / c.frames;
    r.metrics[row.name + "[" + row.parameter + "].kept_fraction"] = Ratio(c.kept_n, measured);
    // The population is the same for every row: the precision of a filter that flags at random.
    r.metrics["bad_fraction"] = Ratio(c.bad, measured);
  }
  Table summary{"filters_best",
                {"filter", "best parameter (F1, 5 cm)", "precision", "recall", "F1", "precision 3σ",
                 "recall 3σ", "RMSE kept", "RMSE kept within L", "kept", "ms/frame"},
                {},
                true};
  std::vector<std::pair<double, std::string>> ranking;
  for (const auto& [name, value] : best_per_filter) {
    const auto& row = t.rows[value.second];
    summary.rows.push_back({name, row[1], row[2], row[3], row[4], row[5], row[6],
                            Mm(std::stod(row[7])), Mm(std::stod(row[8])), Pct(std::stod(row[9])),
                            row[10]});
    r.metrics[name + ".best_f1"] = value.first;
    ranking.emplace_back(value.first, name);
  }
  std::sort(ranking.rbegin(), ranking.rend());
  r.tables.push_back(t);
  r.tables.push_back(summary);
  std::ostringstream smoothing_text;
  SmoothingTable(o, s, r, smoothing_text);
  r.plots = {"filters_pr"};
  r.metrics["best_f1"] = best_f1;
  std::ostringstream text;
  text << "Every built-in scene (" << sim::BuiltinSceneNames().size() << " scenes, "
       << frames_per_scene
       << " frame(s) each, spread over dynamic scenes' duration), exposure set by the "
          "may-incremental controller running on every frame (registers used: "
       << registers_text
       << "), calibrated, noise-calibrated ΔL. Population: pixels with a measurement. A pixel "
          "is bad when |error| > 5 cm (or > 3 x its true σ), or when its ray hits nothing. "
          "Precision = bad among flagged, recall = flagged among bad; RMSE and fraction of the "
          "kept pixels (\"within L\": without the pixels whose surface lies beyond the "
          "unambiguous range and reads d - L, which dominate the plain RMSE). Cloud filters: `sor` "
          "= statistical outlier removal (PCL / Open3D: mean "
          "distance to the k nearest neighbours, outlier above mean + std_mul x std), `radius` "
          "= radius outlier removal (fewer than min other points within r), both exact on a "
          "nanoflann kd-tree over the valid pixels' points; `combination` rows run the "
          "pipeline's default pixel filters (saturation + accuracy 0.07 m) and then a cloud "
          "filter on the points they kept. Time per frame is measured on the shared 2-core "
          "machine (indicative only; a cloud filter's time includes building the cloud and "
          "the kd-tree).\n\n";
  text << "Best F1 (5 cm) per filter, best first: ";
  for (std::size_t k = 0; k < ranking.size(); ++k) {
    text << (k ? ", " : "") << ranking[k].second << " " << F(ranking[k].first, 3);
  }
  text << ". The overall best is " << t.rows[best][0] << " (" << t.rows[best][1] << ", F1 "
       << F(best_f1, 3) << ").";
  const double acc = best_per_filter.count("accuracy") ? best_per_filter["accuracy"].first : 0;
  const double sor = best_per_filter.count("sor") ? best_per_filter["sor"].first : 0;
  const double rad = best_per_filter.count("radius") ? best_per_filter["radius"].first : 0;
  text << " The paper's accuracy filter " << (acc > std::max(sor, rad) ? "beats" : "does not beat")
       << " the cloud outlier filters a user would reach for (best F1 " << F(acc, 3)
       << " against SOR " << F(sor, 3) << " and radius " << F(rad, 3) << ")";
  text << (acc > std::max(sor, rad)
               ? ": a cloud filter judges only how isolated a point is, eq. 2 the pixel's own "
                 "signal."
               : ".");
  std::vector<std::pair<double, std::string>> combos;
  for (const FilterRow& row : rows) {
    if (row.name != "combination") continue;
    combos.emplace_back(r.metrics["combination[" + row.parameter + "].f1"], row.parameter);
  }
  std::sort(combos.rbegin(), combos.rend());
  text << " Combinations by F1: ";
  for (std::size_t k = 0; k < combos.size(); ++k) {
    text << (k ? ", " : "") << combos[k].second << " " << F(combos[k].first, 3);
  }
  text << ".";
  text << "\n";
  r.text = text.str() + smoothing_text.str();
  return r;
}

}  // namespace tofcam::experiments::internal
