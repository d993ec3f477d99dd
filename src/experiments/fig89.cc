#include "experiment_common.h"

namespace tofcam::experiments::internal {
namespace {

// The paper's working point (fig. 3): ChooseSetpoint on the pavilion sweep, computed once per
// seed and effort (the same sweep, seed and grid as the fig3 experiment, so the same I_A).
const ControllerSetpoint& PavilionSetpoint(const ExperimentOptions& o) {
  static std::mutex mutex;
  static std::map<std::pair<std::uint64_t, double>, ControllerSetpoint> cache;
  std::lock_guard<std::mutex> lock(mutex);
  const auto key = std::make_pair(o.seed, o.effort);
  auto it = cache.find(key);
  if (it == cache.end()) {
    const std::vector<SweepRow> rows =
        RegisterSweep("pavilion", RegisterGrid(Scaled(1, 1.0 / o.effort, 1)), o, 3);
    it = cache.emplace(key, SetpointOf(rows)).first;
  }
  return it->second;
}

// The register the paper's P-law (c_{t+1} = -V_p D_t + c_0 with the pavilion's set point) settles
// at on a view: it runs in closed loop for 30 frames on a static scene, or up to `time_s` on a
// dynamic one; the median of the last 10 registers it set (the position law may ring).
// With `incremental` the same I_A and V_p drive the incremental form c_{t+1} = c_t - V_p D_t,
// which has no steady-state offset (docs/controllers.md).
int PaperControllerRegister(const sim::Scene& scene, double time_s, const ExperimentOptions& o,
                            std::uint64_t seed_offset, bool incremental = false) {
  const Shared& s = GetShared(o);
  PipelineOptions popts = RawOptions(s);
  popts.controller_enabled = true;
  popts.controller = PavilionSetpoint(o).Apply(popts.controller);
  if (incremental) popts.controller.kind = ControllerKind::kMayIncremental;
  sim::SimulatedCamera camera(scene, s.model, Sim(o, seed_offset, 0));
  Pipeline pipeline(popts, camera.Info());
  camera.SetIntegrationTimeRegister(pipeline.InitialIntegrationRegister());
  PipelineResult res;
  std::vector<int> regs;
  for (int k = 0; k < (incremental ? 60 : 30) || camera.NextExposureStartS() + 1e-9 < time_s; ++k) {
    pipeline.Process(*camera.Grab(), res);
    camera.SetIntegrationTimeRegister(res.next_integration_register);
    regs.push_back(res.next_integration_register);
  }
  std::vector<int> last(regs.end() - std::min<std::ptrdiff_t>(10, std::ssize(regs)), regs.end());
  std::nth_element(last.begin(), last.begin() + last.size() / 2, last.end());
  return last[last.size() / 2];
}

// Fig. 8/9: background pixels of one view classified by their true scattering bias |b|, and
// what the accuracy filter (ΔL > 0.07 m of noise-calibrated ΔL, pipeline default) removes of
// each class.
struct BiasClass {
  long long pixels = 0;
  long long removed = 0;
  [[nodiscard]] double RemovedFraction() const { return Ratio(removed, pixels); }
};

// The pixels of one population (all background, or one wall) in the bias classes.
struct Population {
  long long pixels = 0;
  BiasClass unbiased;  // |b| < 1 cm (the simulator's kScattering threshold)
  BiasClass over5;     // |b| > 5 cm
  BiasClass over20;    // |b| > 20 cm
  // The same pixels again with the hand taken out of the scene.
  BiasClass over5_control, over20_control;
  ErrorPool raw, kept;
  double median_amplitude_ratio = kNaN;  // amplitude with / without scattering, median
};

struct ScatterRun {
  int reg = 0;
  int frames = 0;
  Population background, wall;
  long long good = 0, good_kept = 0;  // all measured pixels within 5 cm of the truth
  // Fig. 9's "gaps between two fingers": background pixels (not mixed) with hand pixels both
  // left and right of them on their row, within kGapPx; bad = more than 5 cm off.
  long long gap_pixels = 0, gap_bad = 0, gap_bad_removed = 0, gap_good = 0, gap_good_kept = 0;
  Image<Rgb8> raw_image, filtered_image;
  [[nodiscard]] double PerFrame(long long n) const { return static_cast<double>(n) / frames; }
};

// The scene without the hand (every object of material "skin"): the control view that tells
// whether the filter removes a pixel because of the hand's scattered light or anyway.
sim::Scene WithoutHand(sim::Scene scene) {
  int skin = -1;
  for (std::size_t m = 0; m < scene.materials.size(); ++m) {
    if (scene.materials[m].name == "skin") skin = static_cast<int>(m);
  }
  std::vector<sim::SceneObject> kept;
  int removed_before_bulbs = 0;
  for (std::size_t k = 0; k < scene.objects.size(); ++k) {
    if (scene.objects[k].material == skin) {
      removed_before_bulbs += static_cast<int>(k) < scene.lamp_bulb_begin;
      continue;
    }
    kept.push_back(std::move(scene.objects[k]));
  }
  scene.objects = std::move(kept);
  scene.lamp_bulb_begin -= removed_before_bulbs;
  return scene;
}

// One view through the pipeline defaults, its background pixels classified by the true
// scattering bias. Background: true distance > kBackgroundM, neither saturated nor mixed in the
// first frame (those are wrong for other reasons; the saturation rule takes the former).
// `wall_z_m` > 0 also collects the pixels on the plane z = wall_z_m (within 2 cm).
constexpr int kGapPx = 12;

// Background pixels between two parts of the hand on their row (within kGapPx either side).
Image<std::uint8_t> FingerGaps(const MetricFrame& f) {
  const int w = f.width(), h = f.height();
  Image<std::uint8_t> gap(w, h, 0);
  const auto hand = [&](int r, int c) {
    return f.truth->radial_distance_m(r, c) <= static_cast<float>(kBackgroundM);
  };
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      // Depth-edge (mixed) pixels are wrong for another reason, the jump-edge filters' business.
      if (hand(r, c) || !std::isfinite(f.truth->radial_distance_m(r, c)) ||
          f.truth->causes(r, c).Has(Flag::kMixed)) {
        continue;
      }
      bool left = false, right = false;
      for (int k = 1; k <= kGapPx && !left; ++k) left = c - k >= 0 && hand(r, c - k);
      for (int k = 1; k <= kGapPx && !right; ++k) right = c + k < w && hand(r, c + k);
      gap(r, c) = left && right;
    }
  }
  return gap;
}

ScatterRun RunScatter(const sim::Scene& scene, int reg, double time_s, int frames,
                      const ExperimentOptions& o, std::uint64_t seed_offset, double far_m,
                      double wall_z_m = 0.0) {
  const Shared& s = GetShared(o);
  const ScatteringBias bias = MeasureScatteringBias(scene, reg, time_s, o);
  PipelineOptions popts = BaseOptions(s);  // saturation rule + accuracy threshold 0.07 m
  popts.color.far_m = far_m;
  ScatterRun run;
  run.reg = reg;
  run.frames = frames;
  Image<std::uint8_t> member;  // bit 0: background, bit 1: wall
  Image<std::uint8_t> gaps;
  std::vector<float> ratios_background, ratios_wall;
  PipelineResult res;
  for (const bool control : {false, true}) {
    sim::SimulatedCamera camera(control ? WithoutHand(scene) : scene, s.model,
                                Sim(o, seed_offset + (control ? 500 : 0), reg));
    Pipeline pipeline(popts, camera.Info());
    for (int k = 0; k < frames; ++k) {
      pipeline.Process(k == 0 ? GrabAt(camera, time_s) : *camera.Grab(), res);
      const MetricFrame& f = res.frame;
      if (!control && k == 0) {
        run.raw_image = pipeline.RenderRaw(res);
        run.filtered_image = pipeline.RenderFiltered(res);
        member = Image<std::uint8_t>(f.width(), f.height(), 0);
        gaps = FingerGaps(f);
        for (std::size_t i = 0; i < f.flags.size(); ++i) {
          const PixelFlags truth = f.truth->causes[i];
          const double d = f.truth->radial_distance_m[i];
          if (!(d > kBackgroundM) || truth.Has(Flag::kSaturated) || truth.Has(Flag::kMixed) ||
              !std::isfinite(bias.bias_m[i])) {
            continue;
          }
          const bool on_wall = wall_z_m > 0 && std::abs(d * pipeline.rays().z[i] - wall_z_m) < 0.02;
          member[i] = static_cast<std::uint8_t>(1 | (on_wall ? 2 : 0));
          if (std::isfinite(bias.amplitude_ratio[i])) {
            ratios_background.push_back(bias.amplitude_ratio[i]);
            if (on_wall) ratios_wall.push_back(bias.amplitude_ratio[i]);
          }
        }
      }
      for (std::size_t i = 0; i < f.flags.size(); ++i) {
        if (!control && res.input_flags[i].Valid() && !IsBad(f, i)) {
          ++run.good;
          run.good_kept += f.flags[i].Valid();
        }
        if (!control && gaps[i] && res.input_flags[i].Valid()) {
          ++run.gap_pixels;
          if (IsBad(f, i)) {
            ++run.gap_bad;
            run.gap_bad_removed += !f.flags[i].Valid();
          } else {
            ++run.gap_good;
            run.gap_good_kept += f.flags[i].Valid();
          }
        }
        if (!member[i] || !res.input_flags[i].Valid()) continue;
        const double b = std::abs(bias.bias_m[i]);
        const bool removed = res.filter_flags[i].Has(Flag::kHighDeltaL);
        for (Population* p : {&run.background, &run.wall}) {
          if (p == &run.wall && !(member[i] & 2)) continue;
          const auto add = [&](BiasClass& c) {
            ++c.pixels;
            c.removed += removed;
          };
          if (control) {
            if (b > 0.05) add(p->over5_control);
            if (b > 0.2) add(p->over20_control);
            continue;
          }
          ++p->pixels;
          p->raw.Add(f, i);
          if (f.flags[i].Valid()) p->kept.Add(f, i);
          if (b < 0.01) add(p->unbiased);
          if (b > 0.05) add(p->over5);
          if (b > 0.2) add(p->over20);
        }
      }
    }
  }
  const auto median = [](std::vector<float>& v) {
    if (v.empty()) return kNaN;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return static_cast<double>(v[v.size() / 2]);
  };
  run.background.median_amplitude_ratio = median(ratios_background);
  run.wall.median_amplitude_ratio = median(ratios_wall);
  return run;
}

// The background-distance sweep of figs. 8/9 in words, each claim checked against the numbers.
std::string SweepText(const std::vector<double>& walls, const std::vector<ScatterRun>& runs,
                      double range, double hand_m) {
  std::ostringstream t;
  t << "**Background-distance sweep** (`hand?wall_distance_m=...`, table 2; wall pixels = those "
       "on the wall plane, the rest of the background is the floor between 1.4 m and the wall). "
       "Phasor geometry: the hand ("
    << hand_m << " m) returns phase 2π·" << hand_m << "/L ≈ " << F(360.0 * hand_m / range, 2)
    << "°, a wall at d returns 2π d/L. The scattered light adds "
       "the hand's phasor s to the wall's own a: with ρ = s/a and Δφ the phase difference the "
       "measured phase moves by atan(ρ sin Δφ / (1 + ρ cos Δφ)) and the amplitude becomes "
       "a·|1 + ρ e^{iΔφ}|. ρ grows as d² (the wall's light falls as 1/d², the scattered light "
       "does not depend on d), the phase can only move where sin Δφ ≠ 0, and the amplitude "
       "cancels where cos Δφ < 0, most at Δφ = 180° (d = L/2 + "
    << hand_m << " m = " << F(range / 2 + hand_m, 3)
    << " m). ΔL rises only where the amplitude "
       "falls, so eq. 2 sees the bias only through cancellation or a weak own signal.\n\n";
  std::vector<std::string> clean, moderate, strong;
  double max_clean_near = 0.0, moderate_removed_max = 0.0, strong_removed20_min = 1.0;
  std::size_t opposed = walls.size();  // the clean wall nearest to Δφ = 180°
  for (std::size_t k = 0; k < walls.size(); ++k) {
    const ScatterRun& run = runs[k];
    const Population& w = run.wall;
    const double phase = 360.0 * (walls[k] - hand_m) / range;
    const double f5 = Ratio(w.over5.pixels, w.pixels), f20 = Ratio(w.over20.pixels, w.pixels);
    const std::string name = F(walls[k], 3) + " m";
    t << "- " << name << " (Δφ = " << F(phase, 3) << "°): " << Pct(f5)
      << " of the wall biased by more than 5 cm, " << Pct(f20) << " by more than 20 cm; the "
      << "wall's median amplitude is " << F(w.median_amplitude_ratio, 3)
      << " x its unscattered value; the filter removes " << Pct(w.over5.RemovedFraction())
      << " of the > 5 cm and " << Pct(w.over20.RemovedFraction()) << " of the > 20 cm wall pixels"
      << (w.unbiased.pixels
              ? " and keeps " + Pct(1.0 - w.unbiased.RemovedFraction()) + " of the unbiased ones"
              : " (no wall pixel is unbiased)");
    const long long floor20 = run.background.over20.pixels - w.over20.pixels;
    if (floor20 > 0) {
      t << "; off the wall " << F(run.PerFrame(floor20), 4)
        << " floor pixels per frame are biased by more than 20 cm, "
        << Pct(Ratio(run.background.over20.removed - w.over20.removed, floor20)) << " removed";
    }
    t << ".\n";
    if (f5 < 0.01) {
      clean.push_back(name);
      if (walls[k] <= 1.6) max_clean_near = std::max(max_clean_near, walls[k]);
      if (std::abs(phase - 180.0) < 30.0 &&
          (opposed == walls.size() ||
           std::abs(phase - 180.0) < std::abs(360.0 * (walls[opposed] - hand_m) / range - 180.0))) {
        opposed = k;
      }
    } else if (f20 < 0.01) {
      moderate.push_back(name);
      moderate_removed_max = std::max(moderate_removed_max, w.over5.RemovedFraction());
    } else {
      strong.push_back(name);
      strong_removed20_min = std::min(strong_removed20_min, w.over20.RemovedFraction());
    }
  }
  const auto join = [](const std::vector<std::string>& v) {
    std::string out;
    for (std::size_t k = 0; k < v.size(); ++k) out += (k ? ", " : "") + v[k];
    return out.empty() ? std::string("none") : out;
  };
  t << "\nReading: walls with (almost) no biased pixel (< 1 % biased by more than 5 cm): "
    << join(clean) << ". ";
  if (max_clean_near >= 1.6) {
    t << "Walls up to 1.6 m are bright and ρ is small, as the geometry predicts. ";
  }
  if (opposed < walls.size()) {
    const Population& w = runs[opposed].wall;
    t << "At " << F(walls[opposed], 3) << " m the scattered phasor nearly opposes the wall's: "
      << "the phase does not move while ρ < 1, the amplitude drops instead (median "
      << F(w.median_amplitude_ratio, 3) << " x) and the filter removes "
      << Pct(w.unbiased.RemovedFraction()) << " of the unbiased wall pixels. ";
  }
  t << "Walls biased by 5-20 cm only: " << join(moderate)
    << "; walls with pixels biased by more than 20 cm: " << join(strong) << ". ";
  if (!moderate.empty() && moderate_removed_max < 0.5) {
    t << "On the moderately biased walls the amplitude hardly changes, ΔL stays low and the "
         "filter removes at most "
      << Pct(moderate_removed_max) << " of the pixels biased by more than 5 cm. ";
  }
  if (!strong.empty() && strong_removed20_min >= 0.5) {
    t << "On the far walls the hand's light outweighs the wall's own and the filter removes at "
         "least "
      << Pct(strong_removed20_min) << " of the pixels biased by more than 20 cm. ";
  }
  if (!moderate.empty() && moderate_removed_max < 0.5 && !strong.empty() &&
      strong_removed20_min >= 0.5) {
    t << "The paper's claim that the threshold filter removes \"all background information "
         "which is highly irritated\" therefore holds for strongly biased pixels in dim areas "
         "and fails for moderately biased ones on a well-lit background.";
  }
  t << "\n";
  return t.str();
}

}  // namespace

ExperimentResult Fig89(const ExperimentOptions& o) {
  ExperimentResult r;
  r.title = "Figs. 8 and 9: the scattering hand without and with the accuracy filter";
  const Shared& s = GetShared(o);
  const int frames = Scaled(10, o.effort, 3);
  const ControllerSetpoint& sp = PavilionSetpoint(o);
  Table t{
      "fig89_filter",
      {"view", "register", "background px", "biased > 5 cm", "removed", "removed without the hand",
       "biased > 20 cm", "removed (> 20 cm)", "removed without the hand (> 20 cm)",
       "unbiased (< 1 cm)", "kept", "background RMSE before", "after"},
      {},
      true};
  const auto add_row = [&](const std::string& view, const ScatterRun& run) {
    const Population& p = run.background;
    t.rows.push_back(
        {view, I(run.reg) + " (" + F(run.reg * kRegisterMs, 3) + " ms)",
         F(run.PerFrame(p.pixels), 5), F(run.PerFrame(p.over5.pixels), 4),
         Pct(p.over5.RemovedFraction()), Pct(p.over5_control.RemovedFraction()),
         F(run.PerFrame(p.over20.pixels), 4), Pct(p.over20.RemovedFraction()),
         Pct(p.over20_control.RemovedFraction()), F(run.PerFrame(p.unbiased.pixels), 5),
         Pct(1.0 - p.unbiased.RemovedFraction()), Mm(p.raw.Rmse()), Mm(p.kept.Rmse())});
  };
  const auto store = [&](const std::string& key, const ScatterRun& run, const Population& p) {
    r.metrics[key + ".register"] = run.reg;
    r.metrics[key + ".pixels"] = run.PerFrame(p.pixels);
    r.metrics[key + ".over5_pixels"] = run.PerFrame(p.over5.pixels);
    r.metrics[key + ".over20_pixels"] = run.PerFrame(p.over20.pixels);
    r.metrics[key + ".over5_removed"] = p.over5.RemovedFraction();
    r.metrics[key + ".over5_removed_without_hand"] = p.over5_control.RemovedFraction();
    r.metrics[key + ".over20_removed"] = p.over20.RemovedFraction();
    r.metrics[key + ".over20_removed_without_hand"] = p.over20_control.RemovedFraction();
    r.metrics[key + ".unbiased_kept"] = 1.0 - p.unbiased.RemovedFraction();
    r.metrics[key + ".unbiased_pixels"] = run.PerFrame(p.unbiased.pixels);
    r.metrics[key + ".median_amplitude_ratio"] = p.median_amplitude_ratio;
    r.metrics[key + ".rmse_before"] = p.raw.Rmse();
    r.metrics[key + ".rmse_after"] = p.kept.Rmse();
    r.metrics[key + ".good_kept"] = Ratio(run.good_kept, run.good);
    r.metrics[key + ".gap_pixels"] = run.PerFrame(run.gap_pixels);
    r.metrics[key + ".gap_bad_fraction"] = Ratio(run.gap_bad, run.gap_pixels);
    r.metrics[key + ".gap_bad_removed"] = Ratio(run.gap_bad_removed, run.gap_bad);
    r.metrics[key + ".gap_good_kept"] = Ratio(run.gap_good_kept, run.gap_good);
  };

  // The paper's figure: the hand in front of the 3 m wall at 15 ms and at the registers the
  // paper's P-law settles at (printed position form, and the incremental form without offset).
  const sim::Scene hand = sim::LoadBuiltinScene("hand");
  const int hand_reg = PaperControllerRegister(hand, 0.0, o, 60);
  const int hand_reg_inc = PaperControllerRegister(hand, 0.0, o, 65, true);
  const ScatterRun at15 = RunScatter(hand, 59, 0.0, frames, o, 61, 4.0);
  const ScatterRun atp = RunScatter(hand, hand_reg, 0.0, frames, o, 62, 4.0);
  const ScatterRun ati = RunScatter(hand, hand_reg_inc, 0.0, frames, o, 66, 4.0);
  const ScatterRun at4 = RunScatter(hand, 16, 0.0, frames, o, 67, 4.0);
  add_row("hand, wall 3 m, 15 ms", at15);
  add_row("hand, wall 3 m, 4 ms", at4);
  add_row("hand, wall 3 m, P-law", atp);
  add_row("hand, wall 3 m, incremental P-law", ati);
  store("r59", at15, at15.background);
  store("r16", at4, at4.background);
  store("p", atp, atp.background);
  store("incremental", ati, ati.background);
  r.images.push_back({"fig8_raw", "hand, 15 ms, without filter", at15.raw_image});
  r.images.push_back(
      {"fig9_filtered", "hand, 15 ms, with the accuracy filter", at15.filtered_image});
  // The paper's own setting: the pavilion with a hand entering at the bottom (demo scene: hand
  // in view from 2.5 s, lamps off until 6 s), exposure from the P-law running since t = 0.
  constexpr double kDemoTimeS = 3.0;
  const sim::Scene demo = sim::LoadBuiltinScene("demo");
  const int demo_reg = PaperControllerRegister(demo, kDemoTimeS, o, 63);
  const ScatterRun pav = RunScatter(demo, demo_reg, kDemoTimeS, frames, o, 64, 0.0);
  add_row("pavilion + hand (demo, 3 s), P-law", pav);
  store("pavilion", pav, pav.background);
  r.images.push_back({"fig8_pavilion_raw", "pavilion + hand, without filter", pav.raw_image});
  r.images.push_back(
      {"fig9_pavilion_filtered", "pavilion + hand, with the accuracy filter", pav.filtered_image});

  // Background-distance sweep at the P-law's register for each wall.
  const double range = s.info.unambiguous_range_m();
  constexpr double kHandM = 0.2;  // hand_distance_m of scenes/hand.yaml
  Table sweep{"fig89_distance",
              {"wall m", "phase wall - hand", "register", "background > 20 cm",
               "removed (background > 20 cm)", "wall px", "wall > 5 cm", "removed (wall > 5 cm)",
               "wall > 20 cm", "removed (wall > 20 cm)", "wall unbiased kept",
               "wall amplitude with / without scattering"},
              {},
              true};
  const int sweep_frames = Scaled(4, o.effort, 2);
  const std::vector<double> walls = {1.2, 1.6, 2.5, 3.0, 3.75, 5.0, 6.5};
  std::vector<ScatterRun> runs;
  for (std::size_t k = 0; k < walls.size(); ++k) {
    const double wall = walls[k];
    const sim::Scene scene = sim::LoadBuiltinScene("hand", {{"wall_distance_m", F(wall, 4)}});
    const int reg = PaperControllerRegister(scene, 0.0, o, 70 + k);
    runs.push_back(RunScatter(scene, reg, 0.0, sweep_frames, o, 80 + k, 0.0, wall));
    const ScatterRun& run = runs.back();
    const Population& bg = run.background;
    const Population& wp = run.wall;
    sweep.rows.push_back({F(wall, 3), F(360.0 * (wall - kHandM) / range, 3) + "°", I(reg),
                          F(run.PerFrame(bg.over20.pixels), 4), Pct(bg.over20.RemovedFraction()),
                          F(run.PerFrame(wp.pixels), 5), F(run.PerFrame(wp.over5.pixels), 4),
                          Pct(wp.over5.RemovedFraction()), F(run.PerFrame(wp.over20.pixels), 4),
                          Pct(wp.over20.RemovedFraction()),
                          Pct(1.0 - wp.unbiased.RemovedFraction()),
                          F(wp.median_amplitude_ratio, 3)});
    store("wall" + F(wall, 3), run, wp);
    store("background" + F(wall, 3), run, bg);
  }
  r.tables.push_back(t);
  r.tables.push_back(sweep);
  r.plots = {"fig89_distance"};

  std::ostringstream text;
  text << "Background = pixels whose true distance exceeds " << kBackgroundM
       << " m, neither saturated nor on a depth edge. Each is classified by its true scattering "
          "bias b (noise-free renderings with the scattering PSF on and off, as in fig. 2); "
          "\"removed\" = flagged by the accuracy filter (ΔL > 0.07 m of noise-calibrated ΔL, "
          "pipeline default); \"removed without the hand\" = the same pixels in the same view "
          "with the hand taken out of the scene (what the filter does to them anyway). Counts "
          "are per frame over "
       << frames << " frames. The P-law is the paper's c_{t+1} = -V_p D_t + c_0 with fig. 3's "
       << "set point (I_A = " << F(sp.target_intensity, 5) << ", c_0 = " << sp.bias_register
       << ", V_p = " << F(sp.gain_register_per_intensity, 3)
       << "), run in closed loop on the view; the incremental P-law c_{t+1} = c_t - V_p D_t with "
          "the same I_A and V_p has no steady-state offset. On the hand the printed law settles "
          "at register "
       << hand_reg << " (" << F(hand_reg * kRegisterMs, 3) << " ms)"
       << (std::abs(hand_reg - 59) <= 3
               ? ", about the 15 ms the paper calls \"definitely too high\" for this scene: with "
                 "the pavilion's c_0 the position form's offset keeps the exposure long"
               : "")
       << "; the incremental law settles at register " << hand_reg_inc << " ("
       << F(hand_reg_inc * kRegisterMs, 3) << " ms).\n\n";
  const auto line = [&](const std::string& view, const ScatterRun& run) {
    const Population& p = run.background;
    text << "- " << view << " (register " << run.reg << "): " << F(run.PerFrame(p.over5.pixels), 4)
         << " background pixels per frame are biased by more than 5 cm, "
         << F(run.PerFrame(p.over20.pixels), 4) << " by more than 20 cm; the filter removes "
         << Pct(p.over5.RemovedFraction()) << " and " << Pct(p.over20.RemovedFraction())
         << " of them and keeps " << Pct(1.0 - p.unbiased.RemovedFraction()) << " of the "
         << F(run.PerFrame(p.unbiased.pixels), 5) << " unbiased ones (|b| < 1 cm).";
    if (p.over20.pixels == 0) {
      text << " Nothing is biased by more than 20 cm.";
    } else if (p.over20.RemovedFraction() >= 0.5) {
      text << " Most of the strongly biased halo goes, as in the paper's fig. 9. Without the "
              "hand the filter removes "
           << Pct(p.over20_control.RemovedFraction()) << " of the same pixels: ";
      text << (p.over20_control.RemovedFraction() < 0.5 * p.over20.RemovedFraction()
                   ? "it reacts to the hand's scattered light."
                   : "they are dim and noisy anyway, which is also why the hand's light can "
                     "bias them (the paper's fig. 8b: \"areas with low intensity are being more "
                     "influenced by scattering light\").");
    } else {
      text << " Most of the strongly biased halo survives the filter.";
    }
    text << "\n";
  };
  line("Hand, wall 3 m, " + F(59 * kRegisterMs, 3) + " ms", at15);
  line("Hand, wall 3 m, " + F(16 * kRegisterMs, 3) + " ms", at4);
  line("Hand, wall 3 m, P-law", atp);
  line("Hand, wall 3 m, incremental P-law", ati);
  line("Pavilion with the hand (demo scene at 3 s)", pav);
  // Fig. 9: "It is amazing, that the gaps between two fingers could also be determined."
  text << "\n**Gaps between the fingers** (paper fig. 9): background pixels (not on a depth "
          "edge) with the hand on both sides within "
       << kGapPx << " pixels on their row. ";
  for (const auto& [view, run] :
       {std::pair<std::string, const ScatterRun*>{"hand at 15 ms", &at15},
        std::pair<std::string, const ScatterRun*>{"hand at 4 ms", &at4},
        std::pair<std::string, const ScatterRun*>{"pavilion with the hand", &pav}}) {
    text << view << ": " << F(run->PerFrame(run->gap_pixels), 4) << " gap pixels per frame, "
         << Pct(Ratio(run->gap_bad, run->gap_pixels)) << " of them off by more than 5 cm; the "
         << "filter removes " << Pct(Ratio(run->gap_bad_removed, run->gap_bad))
         << " of those and keeps " << Pct(Ratio(run->gap_good_kept, run->gap_good))
         << " of the rest. ";
  }
  const auto holds = [](const ScatterRun& run) {
    return Ratio(run.gap_bad_removed, run.gap_bad) >= 0.8;
  };
  text << "The paper's observation (\"the gaps between two fingers could also be determined\") "
       << (holds(pav) ? "holds in the pavilion, its own setting, where the gaps show the dim far "
                        "hall"
                      : "does not hold in the pavilion")
       << (holds(at15) ? ", and on the 3 m wall too."
                       : "; on the lit 3 m wall it does not: there most corrupted gap pixels "
                         "keep a ΔL below the threshold, because the scattered light biases "
                         "their phase without costing them much amplitude (see the sweep "
                         "below).");
  text << "\n\n" << SweepText(walls, runs, range, kHandM);
  r.text = text.str();
  return r;
}

}  // namespace tofcam::experiments::internal
