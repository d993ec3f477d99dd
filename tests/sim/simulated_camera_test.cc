// Physics tests of the simulated camera. Each compares against an independent expectation: a
// closed form (shot-noise sigma, wrapped distance, mirrored path), the scene geometry (ground
// truth) or the documented parameter of the effect under test.
#include "tofcam/sim/simulated_camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <numeric>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::sim {
namespace {

constexpr double kL = kSpeedOfLightMPerS / (2 * 20e6);

double Metres(std::uint16_t reg) { return reg * kL / kDistanceRegisterSpan; }

// Signed error of a measured distance register against a true distance, wrapped to (-L/2, L/2].
double Err(std::uint16_t reg, double truth) { return std::remainder(Metres(reg) - truth, kL); }

Scene InlineScene(const std::string& yaml) { return ParseScene(yaml, "inline", {}); }

SimulatorOptions Only(void (*enable)(SimulatorOptions&)) {
  SimulatorOptions o = SimulatorOptions::Ideal();
  enable(o);
  return o;
}

// Per-pixel temporal sigma over `frames` frames and the closed-form prediction from the mean
// amplitude and intensity registers, for a central block.
struct NoiseStats {
  double measured_over_predicted = 0;  // mean over pixels
  double worst_pixel_ratio_error = 0;
  double mean_measured_m = 0;
};

NoiseStats MeasureNoise(SimulatedCamera& cam, int frames, double gain) {
  const int r0 = 54, c0 = 72, n = 16;
  std::vector<std::vector<double>> d(n * n), a(n * n), b(n * n);
  for (int f = 0; f < frames; ++f) {
    const Frame fr = *cam.Grab();
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        d[i * n + j].push_back(Metres(fr.distance(r0 + i, c0 + j)));
        a[i * n + j].push_back(fr.amplitude(r0 + i, c0 + j));
        b[i * n + j].push_back(fr.intensity(r0 + i, c0 + j));
      }
    }
  }
  NoiseStats s;
  double sum_ratio = 0, sum_sigma = 0;
  for (int p = 0; p < n * n; ++p) {
    const double ref = d[p][0];
    double m = 0, m2 = 0;
    for (double x : d[p]) {
      const double e = std::remainder(x - ref, kL);
      m += e;
      m2 += e * e;
    }
    m /= frames;
    const double var = (m2 / frames - m * m) * frames / (frames - 1);
    const double am = std::accumulate(a[p].begin(), a[p].end(), 0.0) / frames / gain;
    const double bm = std::accumulate(b[p].begin(), b[p].end(), 0.0) / frames / gain;
    const double predicted = kL * std::sqrt(bm) / (2 * std::sqrt(2.0) * kPi * am);
    const double ratio = std::sqrt(var) / predicted;
    sum_ratio += ratio;
    sum_sigma += std::sqrt(var);
    s.worst_pixel_ratio_error = std::max(s.worst_pixel_ratio_error, std::abs(ratio - 1));
  }
  s.measured_over_predicted = sum_ratio / (n * n);
  s.mean_measured_m = sum_sigma / (n * n);
  return s;
}

TEST(SimulatedCameraTest, ShotNoiseMatchesClosedFormAndScalesWithIntegrationTime) {
  const CameraModel model = ResolveCameraModel("sr2");
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.shot_noise = true; });
  o.integration_time_register = 4;
  SimulatedCamera cam(LoadBuiltinScene("wall", {{"distance_m", "3.0"}}), model, o);
  const NoiseStats short_t = MeasureNoise(cam, 200, model.gain_reg_per_e);
  // sigma = L sqrt(B) / (2 sqrt(2) pi A), B and A in electrons (tof-notes section 1).
  EXPECT_NEAR(short_t.measured_over_predicted, 1.0, 0.10);
  // 200 samples estimate one sigma to ~5 % (1 / sqrt(2 * 199)); 25 % is five of those.
  EXPECT_LT(short_t.worst_pixel_ratio_error, 0.25);
  EXPECT_GT(short_t.mean_measured_m, 0.003);  // the test must see real noise, not quantisation

  cam.SetIntegrationTimeRegister(16);  // 4x the time: A and B grow 4x, sigma falls by sqrt(4)
  const NoiseStats long_t = MeasureNoise(cam, 200, model.gain_reg_per_e);
  EXPECT_NEAR(long_t.measured_over_predicted, 1.0, 0.10);
  EXPECT_NEAR(short_t.mean_measured_m / long_t.mean_measured_m, 2.0, 0.2);
}

TEST(SimulatedCameraTest, GroundTruthSigmaIsTheClosedForm) {
  const CameraModel model = ResolveCameraModel("sr2");
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.integration_time_register = 20;
  SimulatedCamera cam(LoadBuiltinScene("wall"), model, o);
  const Frame f = *cam.Grab();
  const double a = f.amplitude(62, 80) / model.gain_reg_per_e;
  const double b = f.intensity(62, 80) / model.gain_reg_per_e;
  EXPECT_NEAR(f.truth->sigma_m(62, 80), kL * std::sqrt(b) / (2 * std::sqrt(2.0) * kPi * a),
              1e-3 * f.truth->sigma_m(62, 80) + 1e-6);
  // Wall at 2 m: true radial distance of the central pixel (0.5 px from the axis in x and y).
  const Eigen::Vector3d ray = model.intrinsics.Unproject({80, 62});
  EXPECT_NEAR(f.truth->radial_distance_m(62, 80), 2.0 / ray.z(), 1e-5);
  EXPECT_NEAR(Err(f.distance(62, 80), f.truth->radial_distance_m(62, 80)), 0.0, 0.001);
}

// The ground-truth ray is the pixel's central ray for every supersampling: for odd S it is the
// centre subsample's ray (cast once), for even S an extra ray; both equal the analytic distance to
// the wall, and the distance registers agree with it. Threads split rows, not results.
TEST(SimulatedCameraTest, GroundTruthIsTheCentralRayForAnySupersampling) {
  const CameraModel model = ResolveCameraModel("sr2");
  for (int ss : {1, 2, 3, 4}) {
    SimulatorOptions o = SimulatorOptions::Ideal();
    o.integration_time_register = 20;
    o.supersampling = ss;
    SimulatedCamera cam(LoadBuiltinScene("wall"), model, o);
    o.threads = 2;
    SimulatedCamera cam2(LoadBuiltinScene("wall"), model, o);
    const Frame f = *cam.Grab(), f2 = *cam2.Grab();
    for (auto [r, c] : {std::pair{62, 80}, {0, 0}, {123, 159}, {30, 120}}) {
      const Eigen::Vector3d ray = model.intrinsics.Unproject({c, r});
      EXPECT_NEAR(f.truth->radial_distance_m(r, c), 2.0 / ray.z(), 1e-5) << ss << " " << r;
      EXPECT_NEAR(Err(f.distance(r, c), f.truth->radial_distance_m(r, c)), 0.0, 0.002) << ss;
    }
    EXPECT_EQ(f.distance, f2.distance) << ss;
    EXPECT_EQ(f.truth->radial_distance_m, f2.truth->radial_distance_m) << ss;
  }
}

TEST(SimulatedCameraTest, SaturationRaisesFlagsAndLowersAmplitude) {
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.saturation = true; });
  o.integration_time_register = 1;
  SimulatedCamera cam(LoadBuiltinScene("wall", {{"distance_m", "0.5"}}), ResolveCameraModel("sr2"),
                      o);
  const Frame low = *cam.Grab();
  EXPECT_FALSE(low.truth->causes(62, 80).Has(Flag::kSaturated));
  cam.SetIntegrationTimeRegister(255);
  const Frame high = *cam.Grab();
  EXPECT_TRUE(high.truth->causes(62, 80).Has(Flag::kSaturated));
  // Without clipping the amplitude would grow 255-fold; clipped taps lose it.
  EXPECT_LT(high.amplitude(62, 80), 0.5 * 255 * low.amplitude(62, 80));
  int flagged = 0;
  for (const auto& c : high.truth->causes.pixels()) flagged += c.Has(Flag::kSaturated);
  EXPECT_GT(flagged, 1000);
}

TEST(SimulatedCameraTest, WallBeyondRangeWrapsToDistanceMinusL) {
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.integration_time_register = 255;
  SimulatedCamera cam(LoadBuiltinScene("beyond-range"), ResolveCameraModel("sr2"), o);
  const Frame f = *cam.Grab();
  for (int r = 52; r < 72; r += 3) {
    for (int c = 70; c < 90; c += 3) {
      const double truth = f.truth->radial_distance_m(r, c);
      EXPECT_NEAR(Metres(f.distance(r, c)), truth - kL, 0.002);
      EXPECT_TRUE(f.truth->causes(r, c).Has(Flag::kBeyondUnambiguous));
    }
  }
  EXPECT_NEAR(Metres(f.distance(62, 80)), 9.0 - kL, 0.005);  // "a 9 m wall reads 1.5 m"
}

TEST(SimulatedCameraTest, EdgePixelsLandBetweenTheSurfaces) {
  // A near board covers the left half up to x = 2.5 mm at 1 m: column 80 (centre 80.01 px of the
  // edge) straddles it; the wall behind is at 3 m.
  const Scene scene = InlineScene(
      "materials: {w: {albedo: 0.6}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [10, 10], position_m: [0, 0, 3]}\n"
      "  - {type: plane, material: w, size_m: [2, 2], position_m: [-0.9975, 0, 1]}\n");
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.supersampling = 4;
  o.integration_time_register = 60;
  SimulatedCamera cam(scene, ResolveCameraModel("sr2"), o);
  const Frame f = *cam.Grab();
  for (int r = 40; r < 80; r += 5) {
    const double edge = Metres(f.distance(r, 80));
    EXPECT_GT(edge, 1.05 / 1.0) << r;
    EXPECT_LT(edge, 2.95) << r;
    EXPECT_TRUE(f.truth->causes(r, 80).Has(Flag::kMixed));
    EXPECT_NEAR(Err(f.distance(r, 70), f.truth->radial_distance_m(r, 70)), 0.0, 0.002);
    EXPECT_NEAR(Err(f.distance(r, 90), f.truth->radial_distance_m(r, 90)), 0.0, 0.002);
    EXPECT_FALSE(f.truth->causes(r, 70).Has(Flag::kMixed));
    // Its footprint holds both surfaces: the board as its neighbour on the left sees it, the
    // wall as the one on the right does (its sub-rays lie 0.6-0.9 px from those centres, a few
    // mm of radial distance near the optical axis).
    const GroundTruth& t = *f.truth;
    EXPECT_NEAR(t.footprint_near_m(r, 80), t.radial_distance_m(r, 79), 0.005) << r;
    EXPECT_NEAR(t.footprint_far_m(r, 80), t.radial_distance_m(r, 81), 0.005) << r;
    // One surface: a footprint of a few mm around the central ray's distance.
    EXPECT_LE(t.footprint_near_m(r, 70), t.radial_distance_m(r, 70));
    EXPECT_GE(t.footprint_far_m(r, 70), t.radial_distance_m(r, 70));
    EXPECT_LT(t.footprint_far_m(r, 70) - t.footprint_near_m(r, 70), 0.005) << r;
  }
}

double ScatterBias(double patch_albedo, bool scattering) {
  // A wall at 3 m and a bright board 0.5 m from the lens on the right; the background is measured
  // on the left, away from the board's own pixels.
  const Scene s = ParseScene(
      "parameters: {a: 0.5}\nmaterials: {w: {albedo: 0.5}, p: {albedo: $a}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [10, 10], position_m: [0, 0, 3]}\n"
      "  - {type: plane, material: p, size_m: [0.25, 0.4], position_m: [0.15, 0, 0.5]}\n",
      "inline", {}, {{"a", std::to_string(patch_albedo)}});
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.scattering = scattering;
  o.integration_time_register = 30;
  SimulatedCamera cam(s, ResolveCameraModel("sr2"), o);
  const Frame f = *cam.Grab();
  double sum = 0;
  int n = 0;
  for (int r = 40; r < 84; ++r) {
    for (int c = 55; c < 85; ++c) {  // background just left of the patch (it starts at col 90)
      sum += Err(f.distance(r, c), f.truth->radial_distance_m(r, c));
      ++n;
    }
  }
  return sum / n;
}

TEST(SimulatedCameraTest, ScatteringBiasGrowsWithNearObjectBrightness) {
  const double none = ScatterBias(0.8, false);
  const double dim = ScatterBias(0.2, true);
  const double bright = ScatterBias(0.8, true);
  EXPECT_NEAR(none, 0.0, 0.0002);
  // The scattered light carries the patch's (shorter) distance: the background reads short.
  EXPECT_LT(dim, -0.001);
  EXPECT_LT(bright, dim);
  // Small scattered fractions shift the phase in proportion: 4x brighter gives ~4x the bias (the
  // phasor sum saturates a little, hence the margin).
  EXPECT_GT(bright / dim, 2.5);
}

TEST(SimulatedCameraTest, LampRaisesIntensityNotAmplitude) {
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.background_light = true; });
  o.integration_time_register = 40;
  SimulatedCamera cam(LoadBuiltinScene("lamps"), ResolveCameraModel("sr2"), o);
  const Frame off = *cam.Grab();  // lamps off until 1 s
  while (cam.NextExposureStartS() < 1.2) (void)cam.Grab();
  const Frame on = *cam.Grab();
  double i_off = 0, i_on = 0, a_off = 0, a_on = 0;
  for (std::size_t p = 0; p < off.distance.size(); ++p) {
    if (off.truth->radial_distance_m[p] < 3.0) continue;  // the wall only, not shades or bulbs
    i_off += off.intensity[p];
    i_on += on.intensity[p];
    a_off += off.amplitude[p];
    a_on += on.amplitude[p];
  }
  EXPECT_GT(i_on, 1.1 * i_off);
  EXPECT_NEAR(a_on / a_off, 1.0, 1e-3);
}

// A glowing material (emission_w_m2_sr) that is not a lamp's bulb is unmodulated light like
// ambient: it raises the offset (intensity) and leaves the modulated amplitude alone. It used to
// be dropped for every object but the bulbs.
TEST(SimulatedCameraTest, AGlowingMaterialRaisesIntensityNotAmplitude) {
  const auto grab = [](double emission) {
    SimulatorOptions o = Only([](SimulatorOptions& x) { x.background_light = true; });
    o.integration_time_register = 20;
    const Scene s = InlineScene(
        "materials: {w: {albedo: 0.5, emission_w_m2_sr: " + std::to_string(emission) +
        "}}\nobjects:\n  - {type: plane, material: w, size_m: [10, 10], position_m: [0, 0, 2]}\n");
    SimulatedCamera cam(s, ResolveCameraModel("sr2"), o);
    return *cam.Grab();
  };
  const Frame plain = grab(0.0), glowing = grab(5.0);
  double i0 = 0, i1 = 0, a0 = 0, a1 = 0;
  for (std::size_t p = 0; p < plain.distance.size(); ++p) {
    i0 += plain.intensity[p];
    i1 += glowing.intensity[p];
    a0 += plain.amplitude[p];
    a1 += glowing.amplitude[p];
  }
  EXPECT_GT(i1, 1.1 * i0);
  EXPECT_NEAR(a1 / a0, 1.0, 1e-3);
}

// Blooming: over-full-well charge of the saturated hand reaches the neighbouring wall pixels as
// charge, not light, so it is shared equally by their four taps. Expected: their intensity rises,
// their amplitude and phase stay those of the wall (noise off, so the comparison is exact up to
// register rounding), and with shot noise on the Poisson spill adds exactly the noise the closed
// form predicts from the raised intensity (what eq. 2 sees).
TEST(SimulatedCameraTest, BloomingRaisesOffsetNotAmplitudeAndAddsItsShotNoise) {
  const CameraModel model = ResolveCameraModel("sr2");
  auto options = [](bool blooming, bool noise) {
    SimulatorOptions o = SimulatorOptions::Ideal();
    o.saturation = true;
    o.blooming = blooming;
    o.shot_noise = noise;
    o.integration_time_register = 59;  // 15 ms: the hand saturates
    return o;
  };
  SimulatedCamera with(LoadBuiltinScene("hand"), model, options(true, false));
  SimulatedCamera without(LoadBuiltinScene("hand"), model, options(false, false));
  const Frame fw = *with.Grab();
  const Frame fo = *without.Grab();
  const int w = fw.distance.width(), h = fw.distance.height();
  // Wall pixels (truth beyond 1 m, not saturated) within 2 px of a saturated pixel.
  std::vector<std::size_t> near;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      if (!(fw.truth->radial_distance_m(r, c) > 1.0f) ||
          fw.truth->causes(r, c).Has(Flag::kSaturated)) {
        continue;
      }
      bool close = false;
      for (int dr = -2; dr <= 2 && !close; ++dr) {
        for (int dc = -2; dc <= 2 && !close; ++dc) {
          const int rr = r + dr, cc = c + dc;
          close = rr >= 0 && rr < h && cc >= 0 && cc < w &&
                  fw.truth->causes(rr, cc).Has(Flag::kSaturated);
        }
      }
      if (close) near.push_back(static_cast<std::size_t>(r) * w + c);
    }
  }
  ASSERT_GT(near.size(), 100u);
  double i_with = 0, i_without = 0, a_with = 0, a_without = 0, max_shift_m = 0;
  for (std::size_t p : near) {
    i_with += fw.intensity[p];
    i_without += fo.intensity[p];
    a_with += fw.amplitude[p];
    a_without += fo.amplitude[p];
    max_shift_m = std::max(
        max_shift_m, std::abs(std::remainder(Metres(fw.distance[p]) - Metres(fo.distance[p]), kL)));
  }
  EXPECT_GT(i_with, 1.5 * i_without);  // the spill is larger than the wall's own offset here
  EXPECT_NEAR(a_with / a_without, 1.0, 2e-3);  // register rounding only
  EXPECT_LT(max_shift_m, 0.002);               // one distance register is 0.11 mm; no phase pull

  // Shot noise: temporal sigma of the bloomed pixels against L sqrt(B) / (2 sqrt(2) pi A) from
  // their mean registers (B includes the spilled charge).
  SimulatedCamera noisy(LoadBuiltinScene("hand"), model, options(true, true));
  constexpr int kFrames = 200;
  std::vector<double> sum_d(near.size()), sum_d2(near.size()), sum_a(near.size()),
      sum_i(near.size());
  std::vector<double> ref(near.size()), sum_truth_sigma(near.size());
  for (int f = 0; f < kFrames; ++f) {
    const Frame fr = *noisy.Grab();
    for (std::size_t k = 0; k < near.size(); ++k) {
      sum_truth_sigma[k] += fr.truth->sigma_m[near[k]];
      const double d = Metres(fr.distance[near[k]]);
      if (f == 0) ref[k] = d;
      const double e = std::remainder(d - ref[k], kL);
      sum_d[k] += e;
      sum_d2[k] += e * e;
      sum_a[k] += fr.amplitude[near[k]];
      sum_i[k] += fr.intensity[near[k]];
    }
  }
  double ratio_sum = 0, truth_ratio_sum = 0;
  for (std::size_t k = 0; k < near.size(); ++k) {
    const double m = sum_d[k] / kFrames;
    const double var = (sum_d2[k] / kFrames - m * m) * kFrames / (kFrames - 1);
    truth_ratio_sum += std::sqrt(var) / (sum_truth_sigma[k] / kFrames);
    const double a = sum_a[k] / kFrames / model.gain_reg_per_e;
    const double b = sum_i[k] / kFrames / model.gain_reg_per_e;
    ratio_sum += std::sqrt(var) / (kL * std::sqrt(b) / (2 * std::sqrt(2.0) * kPi * a));
  }
  // Same 10 % as the plain shot-noise test: the mean over hundreds of pixels of 200-frame sigmas.
  EXPECT_NEAR(ratio_sum / near.size(), 1.0, 0.10);
  // The ground-truth sigma includes the spilled charge too.
  EXPECT_NEAR(truth_ratio_sum / near.size(), 1.0, 0.10);
}

TEST(SimulatedCameraTest, MirrorReturnsTheMirroredPathLength) {
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.multipath = true; });
  o.integration_time_register = 100;
  SimulatedCamera cam(LoadBuiltinScene("mirror", {{"mirror_albedo", "0"}}),
                      ResolveCameraModel("sr2"), o);
  const Frame f = *cam.Grab();
  for (int r = 55; r < 70; r += 3) {
    for (int c = 72; c < 88; c += 3) {
      // Mirror at 1.5 m facing the camera, wall 1 m behind the camera: along a ray with
      // direction z-component dz the path is 1.5/dz out, (1.5 + 1)/dz back past the camera.
      const double truth = f.truth->radial_distance_m(r, c);
      const double dz = 1.5 / truth;
      EXPECT_NEAR(Metres(f.distance(r, c)), 4.0 / dz, 0.003);
      EXPECT_TRUE(f.truth->causes(r, c).Has(Flag::kMultipath));
    }
  }
  // Outside the mirror the front wall at 3 m reads 3 m.
  EXPECT_NEAR(Err(f.distance(62, 10), f.truth->radial_distance_m(62, 10)), 0.0, 0.002);
  EXPECT_FALSE(f.truth->causes(62, 10).Has(Flag::kMultipath));
}

// One-bounce diffuse inter-reflection in a concave corner: a back wall at z = 2 m and a side wall
// at x = 0.4 m (z = 0.5..2 m), both albedo 0.8. The expectation integrates the side wall's
// contribution to a back-wall point x1 numerically, written out here independently of the
// simulator: the LED (on-axis intensity P (m+1) / 2π, cos^m falloff) lights x2 on the side wall,
// which reflects ρ/π of it towards x1 (cosines at both ends over s²), along the path
// |x2| + s + |x1|; the ratio R of that complex irradiance to the direct one gives the distance
// shift L/(2π) arg(1 + R).
TEST(SimulatedCameraTest, DiffuseInterreflectionBiasesCornersLongAsIntegrated) {
  const char* kCorner = R"(
name: corner
materials:
  white: {albedo: 0.8}
objects:
  - {name: back, type: plane, material: white, size_m: [10, 10], position_m: [0, 0, 2.0]}
  - {name: side, type: plane, material: white, size_m: [1.5, 4], position_m: [0.4, 0, 1.25],
     rotation_deg: [0, 90, 0]}
)";
  const CameraModel model = ResolveCameraModel("sr2");
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.integration_time_register = 100;
  o.interreflection_samples = 64;  // Monte-Carlo error of the estimate: a few % (see below)
  SimulatedCamera off(InlineScene(kCorner), model, o);
  o.interreflection = true;
  SimulatedCamera on(InlineScene(kCorner), model, o);
  const Frame f_off = *off.Grab(), f_on = *on.Grab();
  const double m_exp = -std::log(2.0) / std::log(std::cos(model.led_half_angle_deg * kPi / 180));
  const double rho = 0.8;
  for (const double x1x : {0.37, 0.30, 0.20}) {
    SCOPED_TRACE(x1x);
    const int c =
        static_cast<int>(std::lround(model.intrinsics.cx_px + model.intrinsics.fx_px * x1x / 2.0));
    const int r = static_cast<int>(std::lround(model.intrinsics.cy_px));
    const Eigen::Vector3d dir = model.intrinsics.Unproject({c, r});
    const Eigen::Vector3d x1 = dir * (2.0 / dir.z());
    const double t1 = x1.norm();
    // Direct irradiance at x1 (the LED's intensity cancels in R).
    const double e_dir = std::pow(x1.z() / t1, m_exp) * (2.0 / t1) / (t1 * t1);
    std::complex<double> e_ind = 0.0;
    const double step = 0.002;
    for (double z = 0.5 + step / 2; z < 2.0; z += step) {
      for (double y = -2.0 + step / 2; y < 2.0; y += step) {
        const Eigen::Vector3d x2(0.4, y, z);
        const double d2 = x2.norm();
        const double l2 = rho / kPi * std::pow(z / d2, m_exp) * (0.4 / d2) / (d2 * d2);
        const Eigen::Vector3d to1 = x1 - x2;
        const double sd = to1.norm();
        const double cos2 = -to1.x() / sd;  // side wall normal (-1, 0, 0)
        const double cos1 = to1.z() / sd;   // back wall normal (0, 0, -1), towards x2
        const double phase = kPi * (d2 + sd + t1) / kL;
        e_ind += l2 * cos1 * cos2 / (sd * sd) * step * step * std::polar(1.0, phase);
      }
    }
    const std::complex<double> ratio = e_ind / (e_dir * std::polar(1.0, 2 * kPi * t1 / kL));
    const double expected_m = kL / (2 * kPi) * std::arg(1.0 + ratio);
    const double measured_m =
        std::remainder(Metres(f_on.distance(r, c)) - Metres(f_off.distance(r, c)), kL);
    std::printf("x1.x %.2f m: indirect/direct %.4f, expected shift %.2f mm, simulated %.2f mm\n",
                x1x, std::abs(ratio), expected_m * 1e3, measured_m * 1e3);
    EXPECT_GT(expected_m, 0.002);  // the longer path pulls the distance long
    // The simulator averages its estimate over evaluated points within 3 px on the same surface
    // (±3 cm here, where the indirect light changes by ~10 %, mostly linearly, which the
    // symmetric window cancels) and samples 64 directions per point: 15 % of the shift.
    EXPECT_NEAR(measured_m, expected_m, 0.15 * expected_m + 0.0002);
    // The truth flags the indirect light as multipath where it shifts the distance by more than
    // truth_bias_m (1 cm); away from that boundary the flag must agree with the integration.
    if (std::abs(expected_m - o.truth_bias_m) > 0.002) {
      EXPECT_EQ(f_on.truth->causes(r, c).Has(Flag::kMultipath), expected_m > o.truth_bias_m);
    }
    EXPECT_FALSE(f_off.truth->causes(r, c).Has(Flag::kMultipath));
  }
  // A single wall has no second surface: the effect changes nothing.
  SimulatorOptions w = SimulatorOptions::Ideal();
  SimulatedCamera wall_off(LoadBuiltinScene("wall"), model, w);
  w.interreflection = true;
  SimulatedCamera wall_on(LoadBuiltinScene("wall"), model, w);
  const Frame a = *wall_off.Grab(), b = *wall_on.Grab();
  for (std::size_t p = 0; p < a.distance.size(); ++p) {
    ASSERT_EQ(a.distance[p], b.distance[p]) << p;
    ASSERT_EQ(a.amplitude[p], b.amplitude[p]) << p;
  }
}

TEST(SimulatedCameraTest, FixedPatternMagnitudesMatchParameters) {
  const CameraModel model = ResolveCameraModel("sr2");
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.fixed_pattern = true; });
  o.integration_time_register = 40;
  SimulatedCamera cam(LoadBuiltinScene("wall"), model, o);
  const Frame f = *cam.Grab();
  const int w = f.width(), h = f.height();
  Image<double> err(w, h);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) err(r, c) = Err(f.distance(r, c), f.truth->radial_distance_m(r, c));
  }
  // Bowl: fpn_bowl_m * (u^2 + v^2) / 2 with u, v the offsets from the principal point normalised to
  // 1 at the image edges. Average it out of the spread over blocks.
  const double cx = model.intrinsics.cx_px, cy = model.intrinsics.cy_px;
  auto block = [&](int r0, int c0, double& measured, double& expected) {
    measured = expected = 0;
    for (int r = r0; r < r0 + 10; ++r) {
      for (int c = c0; c < c0 + 10; ++c) {
        measured += err(r, c) / 100;
        const double u = (c - cx) / cx, v = (r - cy) / cy;
        expected += model.fpn_bowl_m * 0.5 * (u * u + v * v) / 100;
      }
    }
  };
  // Tolerance: the block mean of 100 pixels carries spread/10 of noise; 4 of those.
  const double tol = 4 * model.fpn_spread_m / 10 + 0.0005;
  for (auto [r0, c0] : {std::pair{0, 0}, {0, w - 10}, {h - 10, 0}, {h - 10, w - 10}, {57, 75}}) {
    double m, e;
    block(r0, c0, m, e);
    EXPECT_NEAR(m, e, tol) << r0 << "," << c0;
  }
  // Pixel-to-pixel spread from horizontal neighbour differences (the bowl changes < 1 mm/px).
  double s2 = 0;
  int n = 0;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c + 1 < w; c += 2) {
      const double d = err(r, c + 1) - err(r, c);
      s2 += d * d;
      ++n;
    }
  }
  EXPECT_NEAR(std::sqrt(s2 / n / 2), model.fpn_spread_m, 0.1 * model.fpn_spread_m);
  // The map is a property of the unit: another noise seed gives the same map.
  SimulatorOptions o2 = o;
  o2.seed = 99;
  SimulatedCamera other(LoadBuiltinScene("wall"), model, o2);
  EXPECT_EQ(other.FixedPatternOffsetM(), cam.FixedPatternOffsetM());
}

TEST(SimulatedCameraTest, WarmupDriftDecaysWithItsTimeConstant) {
  const CameraModel model = ResolveCameraModel("sr2");
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.warmup_drift = true; });
  o.integration_time_register = 40;
  o.power_on_time_s = 0;
  auto mean_err = [](const Frame& f) {
    double s = 0;
    int n = 0;
    for (int r = 52; r < 72; ++r) {
      for (int c = 70; c < 90; ++c, ++n)
        s += Err(f.distance(r, c), f.truth->radial_distance_m(r, c));
    }
    return s / n;
  };
  SimulatedCamera cold(LoadBuiltinScene("wall"), model, o);
  const Frame f0 = *cold.Grab();
  const double t0 = f0.info.timestamp_ns * 1e-9;
  EXPECT_NEAR(mean_err(f0), model.warmup_amplitude_m * std::exp(-t0 / model.warmup_time_constant_s),
              0.0005);
  o.power_on_time_s = model.warmup_time_constant_s;  // one time constant later: 1/e of the drift
  SimulatedCamera warm(LoadBuiltinScene("wall"), model, o);
  const Frame f1 = *warm.Grab();
  EXPECT_NEAR(mean_err(f1), model.warmup_amplitude_m / std::exp(1.0), 0.0005);
}

TEST(SimulatedCameraTest, WigglingHasPeriodQuarterRangeAndItsAmplitude) {
  const CameraModel model = ResolveCameraModel("sr2");
  SimulatorOptions o = Only([](SimulatorOptions& x) { x.wiggling = true; });
  o.integration_time_register = 100;
  // error(d) = a sin(8 pi d / L + phase): at d = L/16 (+ k L/4) it is +a, at 3L/16 it is -a.
  double peak = 0, trough = 0;
  for (auto [d, sign] : {std::pair{kL / 16, 1.0}, {3 * kL / 16, -1.0}, {5 * kL / 16, 1.0}}) {
    SimulatedCamera cam(LoadBuiltinScene("wall", {{"distance_m", std::to_string(d)}}), model, o);
    const Frame f = *cam.Grab();
    const double e = Err(f.distance(62, 80), f.truth->radial_distance_m(62, 80));
    // The error is evaluated at the measured (not the true) phase; 0.5 mm covers that and the
    // 0.5 px off-axis centre pixel.
    (sign > 0 ? peak : trough) = e;
    EXPECT_NEAR(e, sign * model.wiggle_amplitude_m, 0.001) << d;
  }
  EXPECT_GT(peak - trough, 1.9 * model.wiggle_amplitude_m);
}

TEST(SimulatedCameraTest, SameSeedGivesBitIdenticalFrames) {
  SimulatorOptions o;
  o.seed = 7;
  o.integration_time_register = 40;
  SimulatedCamera a(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), o);
  SimulatedCamera b(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), o);
  o.seed = 8;
  SimulatedCamera c(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), o);
  for (int i = 0; i < 3; ++i) {
    const Frame fa = *a.Grab(), fb = *b.Grab(), fc = *c.Grab();
    EXPECT_EQ(fa.distance, fb.distance);
    EXPECT_EQ(fa.amplitude, fb.amplitude);
    EXPECT_EQ(fa.intensity, fb.intensity);
    EXPECT_EQ(fa.truth->causes, fb.truth->causes);
    EXPECT_EQ(fa.truth->sigma_m, fb.truth->sigma_m);
    EXPECT_NE(fa.distance, fc.distance);
  }
  // Threads split rows, but every row draws from its own stream: same frames on 2 threads.
  o.seed = 7;
  o.threads = 2;
  SimulatedCamera d(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), o);
  SimulatedCamera e(LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), [] {
    SimulatorOptions x;
    x.seed = 7;
    x.integration_time_register = 40;
    return x;
  }());
  EXPECT_EQ(d.Grab()->distance, e.Grab()->distance);
}

TEST(SimulatedCameraTest, FootprintOfPixelsThatSeeNothingIsInfinite) {
  // A 1 m board at 3 m in empty space: the image corners see nothing; pixels on the board's rim
  // whose central ray misses it still have it in their footprint.
  const Scene scene = InlineScene(
      "materials: {w: {albedo: 0.6}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [1, 1], position_m: [0, 0, 3]}\n");
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.supersampling = 4;
  SimulatedCamera cam(scene, ResolveCameraModel("sr2"), o);
  const Frame f = *cam.Grab();
  const GroundTruth& t = *f.truth;
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(t.footprint_near_m(0, 0), inf);
  EXPECT_EQ(t.footprint_far_m(0, 0), inf);
  int rim = 0;
  for (std::size_t i = 0; i < t.radial_distance_m.size(); ++i) {
    if (std::isinf(t.radial_distance_m[i])) {
      // Nothing on the central ray: either nothing at all, or the board within the footprint.
      EXPECT_TRUE((std::isinf(t.footprint_near_m[i]) && std::isinf(t.footprint_far_m[i])) ||
                  (t.footprint_near_m[i] > 2.99f && t.footprint_far_m[i] < 3.2f))
          << i;
      rim += std::isfinite(t.footprint_near_m[i]);
    }
  }
  EXPECT_GT(rim, 0);
}

TEST(SimulatedCameraTest, MotionDuringExposureIsFlagged) {
  const Scene scene = InlineScene(
      "materials: {w: {albedo: 0.6}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [10, 10], position_m: [0, 0, 4]}\n"
      "  - type: box\n    material: w\n    size_m: [0.4, 0.4, 0.4]\n"
      "    motion: [{t: 0, position_m: [-0.2, 0, 1.5]}, {t: 1, position_m: [9.8, 0, 1.5]}]\n");
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.integration_time_register = 60;
  auto count = [&](bool motion) {
    o.motion = motion;
    SimulatedCamera cam(scene, ResolveCameraModel("sr2"), o);
    const Frame f = *cam.Grab();
    int n = 0;
    for (const auto& c : f.truth->causes.pixels()) n += c.Has(Flag::kMotion);
    return n;
  };
  EXPECT_GT(count(true), 20);  // 10 m/s: 0.15 m during the 15 ms exposure
  EXPECT_EQ(count(false), 0);
  // The footprint spans the whole exposure: pixels whose central ray sees only the wall at
  // mid-exposure but whose taps saw the box (near side 1.3 m) have it as their nearest surface.
  // The outer tap renderings lie 3/8 of the exposure either side of the middle: the box's
  // edges move +-0.057 m, at 1.3 m 0.044 rad or 9 px (fx 204 px), on both sides of its 0.4 m
  // (45 rows at fy 146 px): about 800 such pixels (954 measured once, with its side faces).
  // Without motion the footprint is one rendering's: only the box's edge pixels (126 once).
  auto swept = [&](bool motion) {
    o.motion = motion;
    SimulatedCamera cam(scene, ResolveCameraModel("sr2"), o);
    const Frame f = *cam.Grab();
    int n = 0;
    for (std::size_t i = 0; i < f.truth->radial_distance_m.size(); ++i) {
      n += f.truth->radial_distance_m[i] > 3.5f && f.truth->footprint_near_m[i] < 2.0f;
    }
    return n;
  };
  const int with_motion = swept(true), without = swept(false);
  EXPECT_GT(with_motion, 500);
  EXPECT_LT(without, 150);
}

TEST(SimulatedCameraTest, FrameTimingFollowsIntegrationTime) {
  SimulatorOptions o = SimulatorOptions::Ideal();
  o.integration_time_register = 10;
  SimulatedCamera cam(LoadBuiltinScene("wall"), ResolveCameraModel("sr2"), o);
  const Frame a = *cam.Grab(), b = *cam.Grab();
  EXPECT_EQ(b.info.sequence, 1u);
  // 2.55 ms + readout is shorter than 1/30 s: the frame rate cap rules.
  EXPECT_NEAR((b.info.timestamp_ns - a.info.timestamp_ns) * 1e-9, 1.0 / 30, 1e-6);
  cam.SetIntegrationTimeRegister(255);
  const Frame c = *cam.Grab(), d = *cam.Grab();
  const CameraModel m = ResolveCameraModel("sr2");
  EXPECT_NEAR((d.info.timestamp_ns - c.info.timestamp_ns) * 1e-9,
              0.065025 + m.readout_time_us * 1e-6, 1e-6);
  EXPECT_DOUBLE_EQ(d.info.integration_time_us, 65025.0);
  EXPECT_EQ(d.info.camera_model, "SR-2");
}

TEST(SimulatedCameraTest, DistanceOffsetRegisterAddsModulo16Bit) {
  SimulatorOptions o = SimulatorOptions::Ideal();
  SimulatedCamera cam(LoadBuiltinScene("wall", {{"distance_m", "7.3"}}), ResolveCameraModel("sr2"),
                      o);
  const Frame a = *cam.Grab();
  cam.SetDistanceOffsetRegister(4000);
  const Frame b = *cam.Grab();
  EXPECT_EQ(b.info.distance_offset_register, 4000);
  EXPECT_EQ(static_cast<std::uint16_t>(a.distance(62, 80) + 4000), b.distance(62, 80));
  EXPECT_LT(b.distance(62, 80), a.distance(62, 80));  // 7.3 m + 4000 steps (0.46 m) wraps past L
}

TEST(SimulatedCameraTest, OutOfRangeSettingsThrowAndLeaveCameraUnchanged) {
  SimulatedCamera cam(LoadBuiltinScene("wall"), ResolveCameraModel("sr2"),
                      SimulatorOptions::Ideal());
  const int reg = cam.IntegrationTimeRegister();
  for (int bad : {0, 256, -3}) {
    try {
      cam.SetIntegrationTimeRegister(bad);
      FAIL();
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find(std::to_string(bad)), std::string::npos);
    }
  }
  EXPECT_EQ(cam.IntegrationTimeRegister(), reg);
  EXPECT_THROW(cam.SetModulationFrequencyHz(30e6), Error);
  EXPECT_THROW(cam.SetModulationFrequencyHz(std::nan("")), Error);
  EXPECT_NO_THROW(cam.SetModulationFrequencyHz(20e6));
  EXPECT_THROW(cam.SetDistanceOffsetRegister(65536), Error);
  EXPECT_THROW(cam.SetDistanceOffsetRegister(-1), Error);
  EXPECT_THROW(cam.SetPanAngleRad(std::nan("")), Error);
  SimulatorOptions bad;
  bad.supersampling = 0;
  EXPECT_THROW(SimulatedCamera(LoadBuiltinScene("wall"), ResolveCameraModel("sr2"), bad), Error);
  bad = SimulatorOptions{};
  bad.integration_time_register = 300;
  EXPECT_THROW(SimulatedCamera(LoadBuiltinScene("wall"), ResolveCameraModel("sr2"), bad), Error);
}

TEST(SimulatedCameraTest, ModulationFrequencyChangesTheRange) {
  // SR-3000 at 40 MHz: L = 3.75 m, so a 5 m wall reads 1.25 m.
  SimulatorOptions o = SimulatorOptions::Ideal();
  SimulatedCamera cam(LoadBuiltinScene("wall", {{"distance_m", "5.0"}}),
                      ResolveCameraModel("sr3000"), o);
  cam.SetModulationFrequencyHz(40e6);
  EXPECT_NEAR(cam.Info().unambiguous_range_m(), kL / 2, 1e-9);
  const Frame f = *cam.Grab();
  const int r = f.height() / 2, c = f.width() / 2;
  const double truth = f.truth->radial_distance_m(r, c);
  EXPECT_NEAR(f.distance(r, c) * (kL / 2) / kDistanceRegisterSpan, truth - kL / 2, 0.002);
}

TEST(SimulatedCameraTest, PanUnitTurnsTheView) {
  // A wall only on the left (x < -1): at pan 0 the centre sees nothing, at +90 deg (turned left
  // about "up") it faces the wall 2 m away, minus the 5 cm camera offset of the pan unit.
  const Scene scene = InlineScene(
      "materials: {w: {albedo: 0.6}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [10, 10], position_m: [-2, 0, 0], rotation_deg: [0, "
      "90, 0]}\n");
  SimulatedCamera cam(scene, ResolveCameraModel("sr2"), SimulatorOptions::Ideal());
  const Frame a = *cam.Grab();
  EXPECT_TRUE(a.truth->causes(62, 80).Has(Flag::kNoReturn));
  cam.SetPanAngleRad(kPi / 2);
  const Frame b = *cam.Grab();
  EXPECT_DOUBLE_EQ(b.info.pan_angle_rad, kPi / 2);
  const Eigen::Vector3d ray = ResolveCameraModel("sr2").intrinsics.Unproject({80, 62});
  EXPECT_NEAR(b.truth->radial_distance_m(62, 80), (2.0 - 0.05) / ray.z(), 1e-4);
}

}  // namespace
}  // namespace tofcam::sim

namespace tofcam::sim {
namespace {

// Paper fig. 2: the hand 0.2 m from the lens saturates at 15 ms and not at 4 ms. That exact
// split is the simulator's tuning target (the camera's LED power and the wall distance were
// chosen for it, docs/simulator.md), so it is not asserted here; what physics fixes is that the
// charge grows linearly with T, so every pixel that clips at 4 ms clips at 15 ms and more do.
// And at 15 ms the area around the hand is noisy: the over-full-well charge spilled into the
// neighbouring wall pixels is offset without amplitude.
// Without it the wall's sigma would fall as 1/sqrt(T) from 4 to 15 ms; the expectation is that
// near the hand it falls clearly less. (Until 2026-11 this test counted wall pixels off by more
// than 20 cm, which came from the old per-tap blooming that copied the hand's phase into its
// neighbours; BloomingRaisesOffsetNotAmplitudeAndAddsItsShotNoise checks the charge model.)
TEST(SaturationTest, HandClipsMoreAtLongerExposureAndBloomingRaisesNearbyNoise) {
  auto grab = [](int reg) {
    SimulatorOptions o;
    o.integration_time_register = reg;
    SimulatedCamera cam(LoadBuiltinScene("hand"), ResolveCameraModel("sr2"), o);
    return *cam.Grab();
  };
  const Frame f4 = grab(16);   // 4.08 ms
  const Frame f15 = grab(59);  // 15.0 ms
  int sat4 = 0, sat15 = 0, sat4_not15 = 0;
  for (std::size_t p = 0; p < f4.distance.size(); ++p) {
    const bool s4 = f4.truth->causes[p].Has(Flag::kSaturated);
    const bool s15 = f15.truth->causes[p].Has(Flag::kSaturated);
    sat4 += s4;
    sat15 += s15;
    sat4_not15 += s4 && !s15;
  }
  EXPECT_EQ(sat4_not15, 0);
  EXPECT_GT(sat15, sat4);
  // Wall pixels (truth beyond 1 m) next to a saturated pixel at 15 ms (4-neighbourhood).
  const int w = f15.distance.width(), h = f15.distance.height();
  double sigma4 = 0, sigma15 = 0;
  int n = 0;
  for (int r = 1; r + 1 < h; ++r) {
    for (int c = 1; c + 1 < w; ++c) {
      if (!(f15.truth->radial_distance_m(r, c) > 1.0f) ||
          f15.truth->causes(r, c).Has(Flag::kSaturated)) {
        continue;
      }
      const bool next_to_hand = f15.truth->causes(r - 1, c).Has(Flag::kSaturated) ||
                                f15.truth->causes(r + 1, c).Has(Flag::kSaturated) ||
                                f15.truth->causes(r, c - 1).Has(Flag::kSaturated) ||
                                f15.truth->causes(r, c + 1).Has(Flag::kSaturated);
      if (!next_to_hand) continue;
      sigma4 += f4.truth->sigma_m(r, c);
      sigma15 += f15.truth->sigma_m(r, c);
      ++n;
    }
  }
  ASSERT_GT(n, 100);
  EXPECT_GT(sigma15, 1.5 * sigma4 * std::sqrt(16.0 / 59.0));
}

// Paper fig. 3: over the register range the mean amplitude of the pavilion rises, peaks and falls
// while the mean intensity keeps rising towards saturation.
TEST(PaperTuningTest, PavilionAmplitudeHasAMaximumAndIntensitySaturates) {
  SimulatorOptions o;
  SimulatedCamera cam(LoadBuiltinScene("pavilion"), ResolveCameraModel("sr2"), o);
  double best_amp = 0, amp_last = 0, int_first = 0, int_last = 0;
  int best_reg = 0;
  for (int reg = 5; reg <= 255; reg += 25) {
    cam.SetIntegrationTimeRegister(reg);
    const Frame f = *cam.Grab();
    double a = 0, i = 0;
    for (std::size_t p = 0; p < f.distance.size(); ++p) {
      a += f.amplitude[p];
      i += f.intensity[p];
    }
    a /= f.distance.size();
    i /= f.distance.size();
    if (a > best_amp) {
      best_amp = a;
      best_reg = reg;
    }
    if (reg == 5) int_first = i;
    amp_last = a;
    int_last = i;
  }
  EXPECT_GT(best_reg, 5);
  EXPECT_LT(best_reg, 255);
  EXPECT_LT(amp_last, 0.9 * best_amp);
  EXPECT_GT(int_last, 10 * int_first);
}

}  // namespace
}  // namespace tofcam::sim
