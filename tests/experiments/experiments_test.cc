// The paper's claims that the simulated data support, on small seeded runs (effort 0.25), and
// the error paths of the experiment runner. Expectations come from the paper (May et al., IROS
// 2006) and the physics, never from a previous run of this code.
#include "tofcam/experiments/experiments.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/experiments/cloud_outliers.h"

namespace tofcam::experiments {
namespace {

ExperimentOptions Small() {
  ExperimentOptions o;
  o.seed = 7;
  o.effort = 0.25;
  o.real_data_dir = std::filesystem::path(TOFCAM_TEST_DATA_DIR) / "real/ifm_o3d303";
  return o;
}

TEST(ExperimentsTest, Fig3AmplitudeHasAMaximumAfterSaturationStarts) {
  const ExperimentResult r = RunExperiment("fig3", Small());
  // Paper fig. 3: amplitude and intensity rise linearly with the integration time; the mean
  // amplitude reaches its maximum inside the sweep once pixels saturate, and falls clearly by the
  // end of it while the intensity keeps rising.
  EXPECT_GT(r.metrics.at("amplitude_slope_per_register"), 0.0);
  EXPECT_GT(r.metrics.at("intensity_slope_per_register"), 0.0);
  const double peak = r.metrics.at("amplitude_max_register");
  EXPECT_GT(peak, 20);
  EXPECT_LT(peak, 255);
  EXPECT_LT(r.metrics.at("amplitude_last_over_max"), 0.9);
  EXPECT_GT(r.metrics.at("intensity_last"), 2.0 * r.metrics.at("intensity_at_amplitude_max"));
  // Saturation must begin before (or at) the amplitude maximum: that is what bends it down.
  EXPECT_LE(r.metrics.at("saturation_onset_register"), peak);
  // Section III-A: I_A lies a small interval below the intensity at the amplitude maximum.
  // (That it also lands in the paper's 15000-18000 band is the simulator's tuning target, issue
  // 3: the LED power was chosen for it. Agreement by construction, not tested as a result.)
  EXPECT_LT(r.metrics.at("target_intensity"), r.metrics.at("intensity_at_amplitude_max"));
}

TEST(ExperimentsTest, Fig5NearObjectsMoveTheAmplitudeMaximumToShorterTimes) {
  const ExperimentResult r = RunExperiment("fig5", Small());
  // Paper fig. 5: near (bright) objects saturate first, so the amplitude peaks earlier.
  EXPECT_LT(r.metrics.at("near_amplitude_max_register"),
            r.metrics.at("far_amplitude_max_register"));
}

TEST(ExperimentsTest, Fig67PassingPixelsGrowWithIntegrationTimeUpToTheOptimum) {
  // What holds for every seed of a set, not one lucky run.
  for (const std::uint64_t seed : {7u, 8u, 9u}) {
    ExperimentOptions o = Small();
    o.seed = seed;
    const ExperimentResult r = RunExperiment("fig6-7", o);
    for (const std::string scene : {"oversaturated", "non-saturated"}) {
      SCOPED_TRACE(scene + " seed " + std::to_string(seed));
      // Paper section III-B: longer exposure lowers ΔL, so more pixels pass a fixed threshold
      // until saturation removes them. Nine steps in ten up to the optimum must rise: near the
      // optimum the expected gain of a step is smaller than the frame-to-frame noise of a count of
      // thousands of pixels (a few tens), so an occasional step may dip (at full effort 50 of 51
      // steps rise).
      EXPECT_GE(r.metrics.at(scene + ".passing_rise_fraction"), 0.9);
      // The optimum is not at the shortest exposure and lies near the amplitude maximum (beyond
      // it the saturating pixels are lost), within one coarse register step (20 at effort 0.25).
      EXPECT_GT(r.metrics.at(scene + ".max_passing_register"), 1.0);
      EXPECT_NEAR(r.metrics.at(scene + ".max_passing_register"),
                  r.metrics.at(scene + ".amplitude_max_register"), 20.0);
    }
    // Fig. 7: without near objects nothing saturates, so the count grows to the longest exposure.
    EXPECT_GE(r.metrics.at("non-saturated.max_passing_register"), 235.0);
  }
}

TEST(ExperimentsTest, Fig1011LampsRaiseDeltaLAndTheFilterRemovesTheCorruptedPixels) {
  const ExperimentResult r = RunExperiment("fig10-11", Small());
  // Lamps add offset without amplitude: eq. 2 predicts a larger ΔL (paper fig. 10).
  EXPECT_GT(r.metrics.at("on.mean_delta_l"), 1.3 * r.metrics.at("off.mean_delta_l"));
  EXPECT_GT(r.metrics.at("on.bad_pixels"), r.metrics.at("off.bad_pixels"));
  // Paper fig. 11: "the noisy area was filtered out completely". The noisy area is measured (the
  // lamps at least double a pixel's RMS error against the truth over the frames and push it past
  // 1.5 x the threshold), not the simulator's closed-form σ, which is eq. 2's own model: the
  // filter (ΔL from one frame's registers) must remove nearly all of it and keep nearly all
  // pixels whose measured RMS error stays below half the threshold.
  EXPECT_GT(r.metrics.at("on.noisy_area_pixels"), 100.0);
  EXPECT_GT(r.metrics.at("on.noisy_area_removed"), 0.9);
  EXPECT_GT(r.metrics.at("on.precise_kept"), 0.95);
  EXPECT_LT(r.metrics.at("on.rmse_after"), r.metrics.at("on.rmse_before"));
}

TEST(ExperimentsTest, Fig2DecomposesSaturationBloomingScatteringAndShotNoise) {
  const ExperimentResult r = RunExperiment("fig2", Small());
  // Paper fig. 2: 15 ms is "definitely too high" for the hand, 4 ms fits. Charge grows
  // linearly with T, so at 15 ms (3.7 x 4.08 ms) more pixels clip. (That the hand clips
  // thousands of pixels at 15 ms and none at 4 ms is the simulator's tuning target, issue 3: the
  // LED power and the wall distance were chosen for it. Not tested as a result.)
  EXPECT_GT(r.metrics.at("saturated_15ms"), r.metrics.at("saturated_4ms"));
  // Scattering is linear optics: the scattered and the direct light both scale with T, so the
  // noise-free bias map is the same at both exposures. 2 mm allows for the 0.11 mm distance
  // register step and the wiggling evaluated at a (identical) phase; a real dependence would be
  // centimetres, the size of the bias itself.
  EXPECT_GT(r.metrics.at("biased5_15ms"), 100.0);
  EXPECT_LT(r.metrics.at("bias_map_rms_difference_m"), 0.002);
  // The same pixels are biased by more than 5 cm at both exposures; 1 % for pixels whose bias
  // sits within a register step of the 5 cm line.
  EXPECT_NEAR(r.metrics.at("biased5_15ms"), r.metrics.at("biased5_4ms"),
              0.01 * r.metrics.at("biased5_15ms") + 1.0);
  // Shot noise σ ∝ 1/sqrt(T): the wall away from the hand is at least sqrt(15/4.08) = 1.92 x
  // noisier at 4 ms (read noise, which does not shrink with T, only adds). 10 % below that for
  // the estimate from 4 frames (pooled over thousands of pixels it is good to a few %).
  EXPECT_GT(r.metrics.at("rest_noise_4ms_over_15ms"), 0.9 * r.metrics.at("expected_noise_ratio"));
  // Blooming: charge spilled from saturated pixels is unmodulated, so the wall next to the hand
  // is noisier at 15 ms than the 1/sqrt(T) scaling predicts, relative to the rest of the wall
  // (which has the same read-noise share). 1.2 x: the excess is an offset of the order of the
  // pixels' own signal, not a few percent.
  EXPECT_GT(r.metrics.at("zone_pixels"), 100.0);
  EXPECT_GT(r.metrics.at("zone_noise_over_expected_15ms"),
            1.2 * r.metrics.at("rest_noise_over_expected_15ms"));
}

TEST(ExperimentsTest, Fig89FilterRemovesTheStronglyBiasedHaloAndKeepsUnbiasedPixels) {
  const ExperimentResult r = RunExperiment("fig8-9", Small());
  // The old assertion: at 4 ms nothing saturates; the threshold (0.07 m of σ) must keep most
  // pixels that are within 5 cm of the truth.
  EXPECT_GT(r.metrics.at("r16.good_kept"), 0.8);
  // Paper fig. 9 ("all background informations, which are highly irritated could be filtered
  // out") on the 3 m wall at the paper's 15 ms: most background pixels biased by more than 20 cm
  // go, while nearly all unbiased ones stay. "Most" = more than half; "nearly all" = 95 %
  // (unbiased pixels are removed only by noise beyond 0.07 m of σ, and the wall's σ at 15 ms is
  // ~4 cm, so a few percent may fall beyond it).
  EXPECT_GT(r.metrics.at("r59.over20_pixels"), 100.0);
  EXPECT_GT(r.metrics.at("r59.over20_removed"), 0.5);
  EXPECT_GT(r.metrics.at("r59.unbiased_kept"), 0.95);
  // ... and the hand is why: the same pixels with the hand taken out of the scene are removed
  // far less often. At least a quarter of the halo is removed because of the halo (measured:
  // 79 % against 29 % at full effort). In the paper's own setting (the pavilion with a hand)
  // the halo pixels are the dim far hall, removed with or without the hand (100 % both): no
  // evidence either way, so not asserted (docs/results.md says so).
  EXPECT_GT(r.metrics.at("r59.over20_removed") - r.metrics.at("r59.over20_removed_without_hand"),
            0.25);
  // Phasor geometry of the background-distance sweep (wall pixels only). The scattered phasor s
  // of the hand (phase ~10°) adds to the wall's a (phase 2π d/L); the wall's signal falls as
  // 1/d², so ρ = s/a grows as d².
  const auto fraction5 = [&](const std::string& wall) {
    return r.metrics.at("wall" + wall + ".over5_pixels") / r.metrics.at("wall" + wall + ".pixels");
  };
  // Near walls are bright (small ρ): no wall pixel moves by 5 cm ("none" = below 1 %).
  EXPECT_LT(fraction5("1.2"), 0.01);
  EXPECT_LT(fraction5("1.6"), 0.01);
  // At 2.5-3 m, Δφ = 110-134°: sin Δφ is large, so the phase moves (5 % of the wall at least).
  EXPECT_GT(fraction5("2.5"), 0.05);
  EXPECT_GT(fraction5("3"), 0.05);
  // At 3.75 m, Δφ = 171°: the phasors nearly oppose, the phase hardly moves while ρ < 1 and the
  // amplitude drops instead (below the 1.2 m wall's, where cos Δφ > 0 adds to it).
  EXPECT_LT(fraction5("3.75"), 0.01);
  EXPECT_LT(r.metrics.at("wall3.75.median_amplitude_ratio"),
            r.metrics.at("wall1.2.median_amplitude_ratio"));
  EXPECT_LT(r.metrics.at("wall3.75.median_amplitude_ratio"), 1.0);
  // At 5-6.5 m the wall is dim and the hand's light outweighs it (ρ > 1 near the hand): those
  // pixels are strongly biased, and dim, so eq. 2 removes most of them.
  EXPECT_GT(r.metrics.at("wall5.over20_pixels"), 10.0);
  EXPECT_GT(r.metrics.at("wall5.over20_removed"), 0.5);
  EXPECT_GT(r.metrics.at("wall6.5.over20_removed"), 0.5);
}

TEST(ExperimentsTest, MirrorPixelsMeasureTheLongerPath) {
  const ExperimentResult r = RunExperiment("mirror", Small());
  // Multipath through a mirror: the indirect path is longer than the direct one, so the error is
  // biased long (tof-notes §2), by far more than the 5 cm bad criterion.
  EXPECT_GT(r.metrics.at("multipath_pixels"), 100.0);
  EXPECT_GT(r.metrics.at("multipath_mean_error"), 0.05);
}

TEST(CloudOutliersTest, MatchBruteForceAndFindPlantedOutliers) {
  // A 20 x 20 grid on a plane (1 cm pitch) with jitter, plus three far points.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> jitter(-0.001f, 0.001f);
  std::vector<CloudPoint> points;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) {
      points.push_back({0.01f * i + jitter(rng), 0.01f * j + jitter(rng), 1.0f + jitter(rng)});
    }
  }
  points.push_back({0.5f, 0.5f, 1.5f});
  points.push_back({-0.4f, 0.1f, 0.7f});
  points.push_back({0.1f, -0.6f, 1.2f});
  const auto distance = [&](std::size_t a, std::size_t b) {
    double sq = 0;
    for (int d = 0; d < 3; ++d) sq += (points[a][d] - points[b][d]) * (points[a][d] - points[b][d]);
    return std::sqrt(sq);
  };
  const int k = 8;
  const std::vector<double> mean = KnnMeanDistances(points, k);
  const std::vector<int> counts = RadiusNeighbourCounts(points, 0.025, 16);
  for (std::size_t p = 0; p < points.size(); ++p) {
    std::vector<double> d;
    int within = 0;
    for (std::size_t q = 0; q < points.size(); ++q) {
      if (q == p) continue;
      d.push_back(distance(p, q));
      within += d.back() < 0.025;
    }
    std::sort(d.begin(), d.end());
    double sum = 0;
    for (int j = 0; j < k; ++j) sum += d[j];
    // Float coordinates: 1e-5 m is far below the 1 cm spacing.
    EXPECT_NEAR(mean[p], sum / k, 1e-5) << p;
    EXPECT_EQ(counts[p], std::min(within, 16)) << p;
  }
  // The planted points are tens of centimetres from everything: SOR (std_mul 2, Open3D's
  // tutorial value) and radius removal (fewer than 4 points within 2.5 cm) flag exactly them.
  const std::vector<bool> sor = StatisticalOutliers(mean, 2.0);
  const std::vector<bool> radius = RadiusOutliers(counts, 4);
  for (std::size_t p = 0; p < points.size(); ++p) {
    const bool planted = p >= 400;
    EXPECT_EQ(sor[p], planted) << p;
    EXPECT_EQ(radius[p], planted) << p;
  }
  EXPECT_THROW((void)KnnMeanDistances(points, 0), Error);
  EXPECT_THROW((void)RadiusNeighbourCounts(points, 0.0, 4), Error);
}

TEST(ExperimentsTest, PreambleQuotesTheMeasuredNumbers) {
  ExperimentResult fig2;
  fig2.name = "fig2";
  fig2.metrics = {{"rest_noise_15ms", 0.043}, {"rest_noise_4ms", 0.126}};
  const std::string md = ResultsPreamble({fig2}, Small());
  EXPECT_NE(md.find("43.0 mm at 15 ms"), std::string::npos) << md;
  EXPECT_NE(md.find("126.0 mm at 4 ms"), std::string::npos) << md;
  // Notes whose experiments did not run are left out (the lamps' note needs fig10-11); the
  // note on predictions and tuning targets is always there.
  EXPECT_EQ(md.find("Dim far walls"), std::string::npos) << md;
  EXPECT_NE(md.find("Predictions and tuning targets"), std::string::npos) << md;
}

TEST(ExperimentsTest, CalibrationReducesTheHeldOutErrorToTheNoiseFloor) {
  const ExperimentResult r = RunExperiment("calibration", Small());
  const double after = r.metrics.at("held_out_rms_after");
  const double floor = r.metrics.at("held_out_noise_floor");
  // The distance correction removes the wiggling (±30 mm) down to the noise of the averaged
  // frames: what is left above that floor in quadrature is smaller than the floor itself
  // (after < 1.5 x floor; measured 1.1 x at full effort, 1.4 x at this effort's fewer frames).
  // A fall back to the offsets alone (31 mm against a 4-7 mm floor) fails this.
  EXPECT_LT(after, 1.5 * floor);
  EXPECT_GT(r.metrics.at("held_out_rms_before"), 2.5 * after);
}

TEST(ExperimentsTest, RealDataDeltaLRanksTheMeasuredNoise) {
  const ExperimentResult r = RunExperiment("real-data", Small());
  // Eq. 2 must order the pixels by their temporal noise. The file is fixed, so the value is too
  // (0.784); 3-frame σ estimates are noisy (relative error ~50 %), which caps how close to 1 it
  // can get. 0.7: a swapped or misscaled amplitude channel drops it below 0.5.
  EXPECT_GT(r.metrics.at("spearman"), 0.7);
  EXPECT_GT(r.metrics.at("scale"), 0.0);
}

TEST(ExperimentsTest, ControllersDefaultHoldsTheSetPointTheOldDefaultsDidNot) {
  ExperimentOptions o = Small();
  o.effort = 1.0;  // the whole 10 s sequences: every change is followed by a segment to time
  const ExperimentResult r = RunExperiment("controllers", o);
  const auto m = [&](const std::string& label, const std::string& key) {
    return r.metrics.at(label + "." + key);
  };
  const std::string old = "may-proportional (V_p 2.5e-4, the old defaults)";
  const std::string hot = "may-proportional (V_p 0.012)";
  const std::string inc = "may-incremental (scheduled V_p, the default)";
  // The printed law with V_p = 2.5e-4 and c_0 = 40 can only reach c_0 - V_p (65532 - 16000) =
  // 27.6 to c_0 + V_p 16000 = 44 (hand-computed from the law and the register range).
  EXPECT_GE(m(old, "register_min"), 27.0);
  EXPECT_LE(m(old, "register_max"), 44.0);
  // V_p = 0.012 against the hand's dĪ/dc of thousands per register: loop gain >> 2, the
  // register swings between its bounds.
  EXPECT_GT(m(hot, "reversals"), 10.0);
  // The default: within 10 % of I_A wherever it is in reach (one register is 1-3 % of Ī at the
  // registers used; the scene moves throughout), without swinging.
  EXPECT_LT(m(inc, "steady_state_error_in_reach"), 0.1);
  EXPECT_LT(m(old, "steady_state_error_in_reach"), 1.0);
  EXPECT_GT(m(old, "steady_state_error_in_reach"), 3.0 * m(inc, "steady_state_error_in_reach"));
  EXPECT_LE(m(inc, "reversals"), 5.0);
  // The model-based controller (issue 18's targets; predictions, nothing was tuned to this
  // scene: its constants are the documented defaults): once more than 1 % of the pixels clip it
  // takes at most 3 frames to get back under (2 measured), at most 5 % of the frames have more
  // than 1 % clipped (2 of 150 measured), and it keeps more valid pixels than the paper's law
  // and the vendor's histogram.
  const std::string model = "model-based (not in the paper)";
  EXPECT_LE(m(model, "longest_run_over_1pct_saturated"), 3.0);
  // Settled within 3 frames after each change of the scene has ended (the hand's 0.5 s moves
  // in and out are changes that last 15 frames; measured at full effort: 0/0/0/1 frames).
  EXPECT_EQ(m(model, "settle_segments_measured"), 4.0);  // every change's segment is timed
  EXPECT_LE(m(model, "max_settle_frames_after_change"), 3.0);
  EXPECT_LE(m(model, "frames_over_1pct_saturated"), 0.05 * m(model, "frames"));
  for (const std::string other : {"may-proportional (scheduled V_p)",
                                  "may-proportional (sweep set point)", "vendor-histogram"}) {
    EXPECT_GT(m(model, "mean_valid"), m(other, "mean_valid")) << other;
  }
  // The same targets on the demo sequence (hand enters) and the static hand scene, against the
  // printed law and the vendor's histogram (measured at full effort: demo 5 of 301 frames, run
  // 3; hand 1 of 60), and settling, also on the two sequences with the hand's moves made steps.
  for (const std::string scene : {"demo", "hand", "approach, hand steps", "demo, hand steps"}) {
    const auto n = [&](const std::string& label, const std::string& key) {
      return r.metrics.at(scene + "." + label + "." + key);
    };
    EXPECT_LE(n(model, "frames_over_1pct_saturated"), 0.05 * n(model, "frames")) << scene;
    // Full effort: demo 0/0/3/1 frames, hand 2; with the hand's moves made steps, approach
    // 2/1/0/1 and demo 2/1/3/1 (a clipped frame, the back-off, the model's register).
    EXPECT_EQ(n(model, "settle_segments_measured"), scene == "hand" ? 1.0 : 4.0) << scene;
    EXPECT_LE(n(model, "max_settle_frames_after_change"), 3.0) << scene;
    for (const std::string other : {"may-proportional (scheduled V_p)", "vendor-histogram"}) {
      EXPECT_GT(n(model, "mean_valid"), n(other, "mean_valid")) << scene << " " << other;
    }
  }
  // Every controller stays within the 30-frames/s registers.
  for (const auto& [key, value] : r.metrics) {
    if (key.size() > 13 && key.substr(key.size() - 13) == ".register_max") {
      EXPECT_LE(value, 115.0) << key;
    }
  }
}

TEST(ExperimentsTest, FiltersBeatChanceAndAThresholdRejectsASupersetAsItFalls) {
  const ExperimentResult r = RunExperiment("filters", Small());
  const double chance = r.metrics.at("bad_fraction");
  ASSERT_GT(chance, 0.0);
  ASSERT_LT(chance, 1.0);
  // A filter that flags at random has precision = the bad fraction; every filter's best setting
  // must do better (it removes bad pixels more often than good ones).
  int filters = 0;
  for (const auto& [key, value] : r.metrics) {
    if (key.size() > 8 && key.substr(key.size() - 8) == ".best_f1") {
      ++filters;
      EXPECT_GT(value, 0.0) << key;
    }
    if (key.size() > 10 && key.substr(key.size() - 10) == ".precision" && std::isfinite(value)) {
      EXPECT_GT(value, chance) << key;
    }
  }
  EXPECT_GE(filters, 6);
  // The accuracy threshold: a smaller ΔL limit flags a superset, so recall can only rise and the
  // kept fraction only fall as it shrinks (exact, whatever the simulator).
  std::vector<std::pair<double, std::string>> thresholds;
  for (const auto& [key, value] : r.metrics) {
    if (key.rfind("accuracy[", 0) == 0 && key.size() > 7 &&
        key.substr(key.size() - 7) == ".recall") {
      thresholds.emplace_back(std::stod(key.substr(9, key.find(']') - 9)),
                              key.substr(0, key.find(']') + 1));
    }
  }
  // Smoothing after the accuracy filter (not in the paper): on static scenes the kept pixels'
  // error is mostly noise, which a median of 9 or a running average over frames must shrink.
  for (const std::string scene : {"wall", "pavilion", "lamps"}) {
    const std::string key = "smoothing." + scene + ".";
    const double none = r.metrics.at(key + "none.median_error");
    EXPECT_LT(r.metrics.at(key + "median 3x3.median_error"), none) << scene;
    EXPECT_LT(r.metrics.at(key + "bilateral 3x3 (ΔL).median_error"), none) << scene;
    EXPECT_LT(r.metrics.at(key + "temporal (ΔL, 8 frames).median_error"), none) << scene;
  }
  ASSERT_GE(thresholds.size(), 3u);
  std::sort(thresholds.begin(), thresholds.end());
  for (std::size_t k = 1; k < thresholds.size(); ++k) {
    const std::string& lo = thresholds[k - 1].second;
    const std::string& hi = thresholds[k].second;
    EXPECT_GE(r.metrics.at(lo + ".recall"), r.metrics.at(hi + ".recall")) << lo << " " << hi;
    EXPECT_LE(r.metrics.at(lo + ".kept_fraction"), r.metrics.at(hi + ".kept_fraction"));
  }
}

// Issue 18's methods in closed loops on every built-in scene. Predictions from the physics, not
// from a run: one frequency cannot keep a surface beyond L right (it reads d - L, metres off, or a
// rejected pixel); a second frequency unwraps such surfaces; the combined set removes the
// wrapped and scattered pixels the paper's filters keep, so its rejections score a higher F1 and
// its kept pixels a lower RMSE. The absolute targets (F1 >= 0.9, RMSE within L <= 50 mm) are met
// by the row with edge pixels unmixed at the full effort, but its forms were designed while
// looking at this experiment, so they are targets, not predictions, and not asserted:
// docs/beyond.md.
TEST(ExperimentsTest, BeyondMethodsBeatThePaperAndTheVendor) {
  const ExperimentResult r = RunExperiment("beyond", Small());
  const auto m = [&](const std::string& key) { return r.metrics.at(key); };
  EXPECT_GT(m("beyond.f1"), m("paper.f1"));
  EXPECT_GT(m("beyond.f1"), m("vendor.f1"));
  EXPECT_LT(m("beyond.rmse_kept_within_l"), m("paper.rmse_kept_within_l"));
  // A pixel 5 cm short of L could still read right by noise: "almost never", not "never".
  EXPECT_LE(m("paper.beyond_right"), 0.01);
  EXPECT_LE(m("vendor.beyond_right"), 0.01);
  EXPECT_GT(m("beyond.beyond_right"), 10.0 * std::max(0.01, m("paper.beyond_right")));
  // Of the pixels beyond L a method keeps: one frequency reads every one of them wrapped, L or
  // more short, so none is right (a prediction; the paper's filters keep some of them: the
  // ratio is not NaN). With two frequencies a kept pixel's wrap count passed the pair's
  // consistency and ambiguity checks, so most are right: the bound 0.5 is "most", set after the
  // full experiment had measured 82 %.
  ASSERT_FALSE(std::isnan(m("paper.beyond_kept_right")));
  EXPECT_LE(m("paper.beyond_kept_right"), 0.01);
  EXPECT_GT(m("beyond.beyond_kept_right"), 0.5);
  // The per-pixel ceiling bounds every single-frame method's F1 (a rule told each pixel's σ and
  // systematic cause can do no worse than one that estimates them), and it is below 1 where
  // noise alone makes pixels bad.
  for (const char* method : {"paper", "vendor"}) {
    EXPECT_LE(m(std::string(method) + ".f1"), m(std::string(method) + ".ceiling_f1")) << method;
    EXPECT_LT(m(std::string(method) + ".ceiling_f1"), 1.0) << method;
    // The same bound under the footprint truth (a pixel reading a surface inside its footprint
    // is right), and that truth forgives: its error is at most the central ray's.
    EXPECT_LE(m(std::string(method) + ".footprint_f1"),
              m(std::string(method) + ".footprint_ceiling_f1"))
        << method;
    EXPECT_LE(m(std::string(method) + ".footprint_rmse_kept_within_l"),
              m(std::string(method) + ".rmse_kept_within_l"))
        << method;
  }
  // Smoothing after every filter rejects nothing and touches only kept pixels, so the same
  // pixels are kept; averaging a pixel with its own surface's neighbours lowers its noise, so
  // fewer of them are more than 5 cm off: a lower bad fraction among the kept and a higher F1.
  EXPECT_DOUBLE_EQ(m("smoothed.kept"), m("beyond.kept"));
  EXPECT_DOUBLE_EQ(m("smoothed.precision"), m("beyond.precision"));
  EXPECT_LT(m("smoothed.kept_bad_fraction"), m("beyond.kept_bad_fraction"));
  EXPECT_GT(m("smoothed.f1"), m("beyond.f1"));
  // Denoising before the pair averages each pixel with its own surface's neighbours before the
  // accuracy threshold judges it and before its wrap count is chosen: a pixel rejected for one
  // reading's noise is kept when its mean's σ passes, and the wrap count of a dim surface beyond
  // L is chosen from the mean. So more pixels are kept good, and more surfaces beyond L right.
  EXPECT_GT(m("denoised.good_kept"), m("beyond.good_kept"));
  EXPECT_GT(m("denoised.beyond_right"), m("beyond.beyond_right"));
  // A step limit in metres keeps depth steps between noisy surfaces apart that k combined σ
  // alone averages across, so fewer kept edge pixels read between two surfaces: a lower RMSE
  // under the footprint truth (which forgives a pixel reading either surface, not a blend).
  EXPECT_LT(m("denoised_step_limit.footprint_rmse_kept_within_l"),
            m("denoised.footprint_rmse_kept_within_l"));
  // A plane fitted to the same support is exact on a slanted plane, and a lopsided support (a
  // dim pixel beside bright neighbours of another surface, which dominate a 1/σ² mean) pins the
  // plane only at those neighbours' positions: fewer kept pixels read a blend. A lower RMSE
  // under the footprint truth. (Measured in a prototype before this prediction was written:
  // docs/beyond.md.)
  EXPECT_LT(m("denoised_plane.footprint_rmse_kept_within_l"),
            m("denoised.footprint_rmse_kept_within_l"));
  // Denoised distances on a slanted surface step by the slope from pixel to pixel, many times
  // their mean's small σ, so the default edge test takes them for edges; the own side's edge
  // term is how far a pixel leaves the line through its neighbours, near zero on a plane. So
  // more good pixels are kept. (Measured in a prototype before this prediction was written:
  // docs/beyond.md.)
  EXPECT_GT(m("denoised_plane_own_side.good_kept"), m("denoised_plane.good_kept"));
  EXPECT_GT(m("denoised_plane_own_side.f1"), m("denoised_plane.f1"));
  // The neighbours' prediction shows most of a pixel's noise draw, which ΔL does not: judging
  // the reading's residual scores a higher F1 than judging ΔL (the two-frequency row), and
  // combining the kept pixels with the prediction afterwards rejects exactly the same pixels
  // but leaves fewer of them more than 5 cm off, like the smoothing above, and more so than the
  // 3x3 bilateral after ΔL's rejections (the best row before it: F1 0.850). Judging the
  // combination instead of the reading keeps the pixels whose combination is good although
  // their reading is not: more good pixels kept. (Measured in a prototype before these
  // predictions were written: docs/beyond.md.)
  EXPECT_GT(m("predicted.f1"), m("beyond.f1"));
  EXPECT_DOUBLE_EQ(m("predicted_combined.kept"), m("predicted.kept"));
  EXPECT_DOUBLE_EQ(m("predicted_combined.precision"), m("predicted.precision"));
  EXPECT_LT(m("predicted_combined.kept_bad_fraction"), m("predicted.kept_bad_fraction"));
  EXPECT_GT(m("predicted_combined.f1"), m("smoothed_own_side.f1"));
  EXPECT_GT(m("predicted_judged_combination.good_kept"), m("predicted_combined.good_kept"));
  EXPECT_GT(m("predicted_judged_combination.good_kept"), m("smoothed_own_side.good_kept"));
  // Held out: scene variants with other parameters, which chose nothing. The prediction judges
  // each reading by what its own neighbours say, whatever the scene, so its advantage must hold
  // there too. (Written before the held-out variants were first run.)
  EXPECT_GT(m("predicted_combined.held_out_f1"), m("smoothed_own_side.held_out_f1"));
  EXPECT_GT(m("predicted_combined.held_out_f1"), m("beyond.held_out_f1"));
  EXPECT_GT(m("predicted_combined.held_out_f1"), m("paper.held_out_f1"));
  EXPECT_GT(m("predicted_judged_combination.held_out_good_kept"),
            m("smoothed_own_side.held_out_good_kept"));
  // The pooled F1 weighs the dynamic variants most; the plain mean over the variants weighs each
  // alike, and the lead must hold there too. (Written before the per-variant F1 was first
  // computed.)
  EXPECT_GT(m("predicted_combined.held_out_mean_f1"), m("smoothed_own_side.held_out_mean_f1"));
  // The frame pair's two-returns check pooled over 7x7 windows (its default) against the same
  // row with the check per pixel only. Multipath sums two paths over whole regions (the mirror),
  // which one pixel's noise hides and a window's mean shows; removing it lowers the kept pixels'
  // RMSE within L under the footprint truth, where multipath was the largest remaining error.
  // The held-out variants include a larger mirror further away, which chose nothing. (Measured
  // with the full experiment before these predictions were written: docs/beyond.md,
  // "Multipath found over regions".)
  EXPECT_LT(m("predicted_combined.footprint_rmse_kept_within_l"),
            m("predicted_combined_per_pixel_pair.footprint_rmse_kept_within_l"));
  EXPECT_LT(m("predicted_combined.rmse_kept_within_l"),
            m("predicted_combined_per_pixel_pair.rmse_kept_within_l"));
  EXPECT_GT(m("predicted_combined.held_out_mean_f1"),
            m("predicted_combined_per_pixel_pair.held_out_mean_f1"));
  // Unmixing edge pixels (uncertainty.unmix_edges): a pixel whose phasor does not show most of
  // its area on its own side's surface may have its centre across the step, which the central
  // truth scores, although it reads its own side (a bright near object outweighs a dim wall's
  // larger area). Rejecting those lowers the kept pixels' RMSE within L under the central truth.
  // Held out too. (Measured with the full experiment before these predictions were written,
  // 131.6 -> 45.7 mm and held out 184.8 -> 75.6 mm with the share's point estimate, 21.3 and
  // 23.7 mm with its 3 σ bound: docs/beyond.md, "Mixed pixels unmixed"; asserted here at the
  // test's reduced effort.)
  EXPECT_LT(m("predicted_combined_unmixed.rmse_kept_within_l"),
            m("predicted_combined.rmse_kept_within_l"));
  EXPECT_LT(m("predicted_combined_unmixed.held_out_rmse_kept_within_l"),
            m("predicted_combined.held_out_rmse_kept_within_l"));
}

TEST(ExperimentsTest, WritesCsvAndMarkdown) {
  const ExperimentResult r = RunExperiment("real-data", Small());
  const auto dir = std::filesystem::temp_directory_path() / "tofcam_experiments_test";
  std::filesystem::remove_all(dir);
  WriteExperimentFiles(r, dir);
  std::ifstream csv(dir / "real_data_summary.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header.rfind("frames,pixels,", 0), 0u);
  // Cells with commas are quoted (RFC 4180), so every row keeps its column count.
  ExperimentResult quoted;
  quoted.tables.push_back({"quoted", {"name", "value"}, {{"k 8, std_mul \"2\"", "1"}}, false});
  WriteExperimentFiles(quoted, dir);
  std::ifstream quoted_csv(dir / "quoted.csv");
  std::string line;
  std::getline(quoted_csv, line);
  std::getline(quoted_csv, line);
  EXPECT_EQ(line, "\"k 8, std_mul \"\"2\"\"\",1");
  // A "|" inside a markdown table cell is escaped, so the table keeps its columns.
  quoted.tables[0].columns[1] = "|a-b|";
  quoted.tables[0].in_markdown = true;
  EXPECT_NE(ExperimentMarkdown(quoted, "").find("| \\|a-b\\| |"), std::string::npos);
  const std::string md = ExperimentMarkdown(r, "results/");
  EXPECT_NE(md.find("## "), std::string::npos);
  EXPECT_NE(md.find("(results/real_data.png)"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(ExperimentsTest, ErrorPaths) {
  ExperimentOptions o = Small();
  try {
    (void)RunExperiment("fig4", o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
    EXPECT_NE(std::string(e.what()).find("fig4"), std::string::npos);
  }
  o.effort = 0.0;
  EXPECT_THROW((void)RunExperiment("fig3", o), Error);
  o.effort = std::nan("");
  EXPECT_THROW((void)RunExperiment("fig3", o), Error);
  o = Small();
  o.threads = 0;
  EXPECT_THROW((void)RunExperiment("fig3", o), Error);
  o = Small();
  o.real_data_dir = "/nonexistent/dir";
  try {
    (void)RunExperiment("real-data", o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
  }
}

}  // namespace
}  // namespace tofcam::experiments
