#include "tofcam/accuracy/delta_l.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace tofcam {
namespace {

MetricFrame MakeMetric(int w, int h, float amplitude, float intensity) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(w, h, 1.0f);
  m.amplitude = Image<float>(w, h, amplitude);
  m.intensity = Image<float>(w, h, intensity);
  m.flags = Image<PixelFlags>(w, h);
  return m;
}

TEST(DeltaLTest, EquationTwoHandValues) {
  // ΔL = L / sqrt(8) * sqrt(I) / (2 A); L(20 MHz) = 7.49481145 m.
  MetricFrame m = MakeMetric(3, 1, 1000.0f, 10000.0f);
  m.amplitude(0, 1) = 50.0f;
  m.intensity(0, 1) = 400.0f;
  m.amplitude(0, 2) = 0.0f;
  const Image<float> dl = ComputeDeltaL(m);
  EXPECT_NEAR(dl(0, 0), 0.1324908, 1e-6);  // 7.49481145 / 2.8284271 * 100 / 2000
  EXPECT_NEAR(dl(0, 1), 0.5299632, 1e-6);  // 7.49481145 / 2.8284271 * 20 / 100
  EXPECT_TRUE(std::isinf(dl(0, 2)) && dl(0, 2) > 0);

  AccuracyOptions twice;
  twice.scale = 2.0;
  EXPECT_NEAR(ComputeDeltaL(m, twice)(0, 0), 2 * 0.1324908, 2e-6);

  m.info.modulation_frequency_hz = 30e6;  // L = 4.99654097 m
  EXPECT_NEAR(ComputeDeltaL(m)(0, 0), 0.0883272, 1e-6);
}

TEST(DeltaLTest, AmplitudeOnlyForm) {
  MetricFrame m = MakeMetric(2, 1, 1000.0f, 0.0f);
  m.intensity = Image<float>();
  m.amplitude(0, 1) = -3.0f;
  const Image<float> dl = ComputeDeltaL(m);
  // I replaced by 2.5 A = 2500: 7.49481145 / 2.8284271 * 50 / 2000.
  EXPECT_NEAR(dl(0, 0), 0.0662454, 1e-6);
  EXPECT_TRUE(std::isinf(dl(0, 1)));
  AccuracyOptions o;
  o.intensity_per_amplitude = 10.0;  // sqrt(10000) / 2000
  EXPECT_NEAR(ComputeDeltaL(m, o)(0, 0), 0.1324908, 1e-6);
}

TEST(DeltaLTest, RejectsBadOptionsAndFrames) {
  const MetricFrame m = MakeMetric(2, 2, 1.0f, 1.0f);
  for (double bad : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    AccuracyOptions o;
    o.scale = bad;
    EXPECT_THROW((void)ComputeDeltaL(m, o), Error) << bad;
    o = {};
    o.intensity_per_amplitude = bad;
    EXPECT_THROW((void)ComputeDeltaL(m, o), Error) << bad;
  }
  MetricFrame wrong = m;
  wrong.amplitude = Image<float>(3, 2);
  EXPECT_THROW((void)ComputeDeltaL(wrong), Error);
  EXPECT_THROW((void)ComputeDeltaL(MetricFrame{}), Error);
}

// Independent expectation for the noise calibration: an ideal 4-tap camera with shot noise,
// simulated here from first principles. With registers = g * electrons, tof-notes §1 gives
// σ_d = L sqrt(B) / (2 sqrt(2) π A) (electrons), hence σ_d / ΔL = 2 sqrt(g) / π.
// The first `dark` pixels are nearly dark (amplitude 5 e against an offset of 20000 e): their
// phase is almost uniform over [0, L), so σ saturates near L / sqrt(12) instead of following eq. 2.
std::vector<MetricFrame> FourTapFrames(double gain, int frames, std::uint64_t seed, int dark = 0) {
  constexpr int kW = 24, kH = 20;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<double> amp(kW * kH), offset(kW * kH), phase(kW * kH);
  for (int i = 0; i < kW * kH; ++i) {
    amp[i] = 2000.0 + 10000.0 * uniform(rng);  // electrons
    // Contrast 0.4 plus background; at most 50000, inside the 16-bit registers for g <= 1.
    offset[i] = amp[i] / 0.4 + 20000.0 * uniform(rng);
    // A third of the pixels sit on the 0 / L seam, where a naive σ would explode.
    phase[i] = (i % 3 == 0) ? 1e-4 : 2.0 * kPi * uniform(rng);
    if (i < dark) {
      amp[i] = 5.0;
      offset[i] = 20000.0;
    }
  }
  std::vector<MetricFrame> out;
  for (int t = 0; t < frames; ++t) {
    Frame f;
    f.distance = Image<std::uint16_t>(kW, kH);
    f.amplitude = Image<std::uint16_t>(kW, kH);
    f.intensity = Image<std::uint16_t>(kW, kH);
    for (int i = 0; i < kW * kH; ++i) {
      double n[4];
      for (int k = 0; k < 4; ++k) {
        const double mu = offset[i] + amp[i] * std::cos(phase[i] - k * kPi / 2.0);
        n[k] = mu + std::sqrt(mu) * normal(rng);  // Poisson, Gaussian approximation
      }
      const double in_phase = n[0] - n[2], quadrature = n[1] - n[3];
      double phi = std::atan2(quadrature, in_phase);
      if (phi < 0) phi += 2.0 * kPi;
      f.distance[i] = static_cast<std::uint16_t>(
          static_cast<long>(std::lround(phi / (2.0 * kPi) * 65536.0)) % 65536);
      f.amplitude[i] =
          static_cast<std::uint16_t>(std::lround(gain * std::hypot(in_phase, quadrature) / 2.0));
      f.intensity[i] =
          static_cast<std::uint16_t>(std::lround(gain * (n[0] + n[1] + n[2] + n[3]) / 4.0));
    }
    out.push_back(ConvertToMetric(f));
  }
  return out;
}

TEST(DeltaLFitTest, RecoversTheShotNoiseFactorOfAnIdealFourTapCamera) {
  for (double gain : {0.25, 1.0}) {
    const std::vector<MetricFrame> frames = FourTapFrames(gain, 40, 7);
    const DeltaLScaleFit fit = FitDeltaLScale(frames);
    const double expected = 2.0 * std::sqrt(gain) / kPi;  // 0.318 and 0.637
    // 480 pixels x 40 frames: the pooled variance fit has a relative standard error of about
    // 1 / sqrt(2 * 480 * 39) = 0.5 % in σ²; 3 % leaves room for register rounding.
    EXPECT_NEAR(fit.scale, expected, 0.03 * expected) << "gain " << gain;
    EXPECT_NEAR(fit.median_ratio, expected, 0.05 * expected);
    EXPECT_EQ(fit.pixels_used, 480);
    EXPECT_EQ(fit.frames, 40);
    EXPECT_GT(fit.r_squared, 0.8);  // σ follows ΔL over a 10x range of ΔL
    // Each per-pixel σ from 40 samples has a relative spread of 1 / sqrt(78) = 11 %.
    EXPECT_LT(fit.relative_rms, 0.2)
        << fit.scale << " " << fit.median_ratio << " " << fit.r_squared;
  }
}

TEST(DeltaLFitTest, LeavesOutNearlyDarkPixels) {
  // 24 of 480 pixels are nearly dark: their measured amplitude is mostly noise (~100 e), so eq. 2
  // predicts σ ~ 1 m, far beyond 1 % of L = 7.5 cm, while their true σ saturates near
  // L / sqrt(12) = 2.2 m. The fit leaves them out and recovers the ideal factor as above; without
  // the cut their large ΔL dominates the least squares and drags it far off.
  const std::vector<MetricFrame> frames = FourTapFrames(1.0, 40, 11, 24);
  const double expected = 2.0 / kPi;
  const DeltaLScaleFit fit = FitDeltaLScale(frames);
  EXPECT_EQ(fit.pixels_used, 480 - 24);
  EXPECT_NEAR(fit.scale, expected, 0.03 * expected);
  DeltaLFitOptions no_cut;
  no_cut.max_sigma_fraction_of_range = std::numeric_limits<double>::infinity();
  const DeltaLScaleFit all = FitDeltaLScale(frames, no_cut);
  EXPECT_EQ(all.pixels_used, 480);
  EXPECT_GT(std::abs(all.scale - expected), 0.1 * expected) << all.scale;
  no_cut.max_sigma_fraction_of_range = 0.0;
  EXPECT_THROW((void)FitDeltaLScale(frames, no_cut), Error);
}

TEST(DeltaLFitTest, SkipsPixelsClippedInAnyFrame) {
  // Three pixels clip in one frame each (the brightest-tap rule: intensity + amplitude at full
  // scale; the SR-2 sets no saturation bit), one of them with its phase thrown 1 m off. They are
  // left out, and the fit recovers the ideal factor as without them.
  std::vector<MetricFrame> frames = FourTapFrames(1.0, 40, 5);
  for (int k : {0, 1, 2}) {
    frames[static_cast<std::size_t>(10 * k + 3)].intensity[static_cast<std::size_t>(100 * k)] =
        65000.0f;
  }
  frames[13].radial_distance_m[100] += 1.0f;
  const DeltaLScaleFit fit = FitDeltaLScale(frames);
  EXPECT_EQ(fit.pixels_used, 480 - 3);
  const double expected = 2.0 / kPi;
  EXPECT_NEAR(fit.scale, expected, 0.03 * expected);
  DeltaLFitOptions blind;
  // Above any register: the rule never fires.
  blind.saturation.max_intensity = blind.saturation.max_amplitude = blind.saturation.max_peak = 1e9;
  EXPECT_EQ(FitDeltaLScale(frames, blind).pixels_used, 480);
  blind.saturation.max_intensity = -1.0;
  EXPECT_THROW((void)FitDeltaLScale(frames, blind), Error);
}

TEST(DeltaLFitTest, SkipsInvalidPixelsAndRejectsTooFewFrames) {
  std::vector<MetricFrame> frames = FourTapFrames(1.0, 5, 3);
  frames[2].flags(0, 0) = PixelFlags(Flag::kInvalid);
  EXPECT_EQ(FitDeltaLScale(frames).pixels_used, 479);
  EXPECT_THROW((void)FitDeltaLScale(std::span(frames.data(), 2)), Error);
  DeltaLFitOptions strict;
  strict.min_pixels = 1000;
  EXPECT_THROW((void)FitDeltaLScale(frames, strict), Error);
  frames[1].info.modulation_frequency_hz = 30e6;
  EXPECT_THROW((void)FitDeltaLScale(frames), Error);
  frames[1] = MakeMetric(3, 3, 1, 1);
  EXPECT_THROW((void)FitDeltaLScale(frames), Error);
  // Copies of one frame: σ = 0 everywhere, a scale of 0 that a calibration then refused
  // without saying why. Now the fit says so itself.
  const std::vector<MetricFrame> copies(5, FourTapFrames(1.0, 1, 3).front());
  try {
    (void)FitDeltaLScale(copies);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("copies"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tofcam
