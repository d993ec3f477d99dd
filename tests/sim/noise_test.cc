// Stage 5 of the simulator (src/sim/noise.h): noise scales, seeded tap noise and the
// fixed-pattern map against closed forms and sample statistics of a fixed seed.
#include "noise.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "rng.h"
#include "tofcam/sim/camera_model.h"

namespace tofcam::sim::internal {
namespace {

TEST(NoiseTest, ScalesAreSqrtOfTheMeansAndTheTruthSigmaOfEq2) {
  const double mu0[2] = {400, 0}, mu1[2] = {900, 0}, mu2[2] = {100, 0}, mu3[2] = {1600, 0};
  const double a[2] = {50, 0}, b[2] = {700, 10};
  float sd0[2], sd1[2], sd2[2], sd3[2], sigma[2], noise[2];
  const double scale = 7.5 / (2 * std::sqrt(2.0) * 3.14159265358979323846);
  NoiseScales(2, 900, scale, mu0, mu1, mu2, mu3, a, b, sd0, sd1, sd2, sd3, sigma, noise);
  EXPECT_FLOAT_EQ(sd0[0], 20);
  EXPECT_FLOAT_EQ(sd1[0], 30);
  EXPECT_FLOAT_EQ(sd2[0], 10);
  EXPECT_FLOAT_EQ(sd3[0], 40);
  EXPECT_FLOAT_EQ(noise[0], 1600);
  EXPECT_NEAR(sigma[0], scale * 40 / 50, 1e-6);  // L sqrt(B + s^2) / (2 sqrt 2 pi A)
  EXPECT_EQ(sigma[1], 0.f);                      // no signal
}

TEST(NoiseTest, NoiselessTapsAreTheMeans) {
  const double m[4][3] = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}, {10, 11, 12.5}};
  const float s[4][3] = {};
  float out[4][3];
  const double* const mu[4] = {m[0], m[1], m[2], m[3]};
  const float* const sd[4] = {s[0], s[1], s[2], s[3]};
  float* const taps[4] = {out[0], out[1], out[2], out[3]};
  NoisyTaps(3, 42, false, 0.0, mu, sd, taps);
  for (int k = 0; k < 4; ++k) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(out[k][c], static_cast<float>(m[k][c]));
  }
}

// Mean and standard deviation of n draws of NoisyTaps for one mean on all taps.
void Stats(double mean, bool shot, double read_sigma, std::uint64_t seed, double& m, double& sd) {
  const int n = 5000;
  std::vector<double> mv(n, mean);
  std::vector<float> sv(n, static_cast<float>(std::sqrt(mean)));
  std::vector<float> out[4];
  for (auto& o : out) o.resize(n);
  const double* const mu[4] = {mv.data(), mv.data(), mv.data(), mv.data()};
  const float* const sd_in[4] = {sv.data(), sv.data(), sv.data(), sv.data()};
  float* const taps[4] = {out[0].data(), out[1].data(), out[2].data(), out[3].data()};
  NoisyTaps(n, seed, shot, read_sigma, mu, sd_in, taps);
  double s = 0, s2 = 0;
  for (const auto& o : out) {
    for (float v : o) {
      s += v;
      s2 += static_cast<double>(v) * v;
    }
  }
  m = s / (4 * n);
  sd = std::sqrt(s2 / (4 * n) - m * m);
}

TEST(NoiseTest, ShotAndReadNoiseHaveTheirClosedFormSpread) {
  // 20,000 draws each: the sample sigma is within 2 % of the truth with overwhelming
  // probability, and the seed is fixed, so the test is deterministic.
  double m = 0, sd = 0;
  Stats(1000, false, 30, 7, m, sd);  // read noise only
  EXPECT_NEAR(m, 1000, 1.0);
  EXPECT_NEAR(sd, 30, 0.6);
  Stats(1000, true, 0, 7, m, sd);  // shot noise, Gaussian regime
  EXPECT_NEAR(sd, std::sqrt(1000.0), 0.02 * std::sqrt(1000.0));
  Stats(4, true, 0, 7, m, sd);  // shot noise, exact Poisson regime
  EXPECT_NEAR(m, 4, 0.06);
  EXPECT_NEAR(sd, 2, 0.04);
  Stats(1000, true, 30, 9, m, sd);  // both: variances add
  EXPECT_NEAR(sd, std::sqrt(1000.0 + 900.0), 0.02 * std::sqrt(1900.0));
}

TEST(NoiseTest, TheStreamDependsOnlyOnTheSeed) {
  double m1, s1, m2, s2, m3, s3;
  Stats(500, true, 20, 11, m1, s1);
  Stats(500, true, 20, 11, m2, s2);
  Stats(500, true, 20, 12, m3, s3);
  EXPECT_EQ(m1, m2);
  EXPECT_EQ(s1, s2);
  EXPECT_NE(m1, m3);
  EXPECT_NE(RowSeed(5, 0), RowSeed(5, 1));
  EXPECT_EQ(RowSeed(5, 0), 5u);
}

// NoisyTapsRows against NoisyTaps row by row, bit for bit: the AVX-512 form (eight streams in
// vector lanes, on AVX-512 CPUs) and the portable rows. Means of every regime: Gaussian (the
// vector path), below kPoissonGaussMean, zero, negative and NaN (the lanes' exact Poisson path),
// huge; widths around the eight-column blocks; 1 to 8 rows; shot and read noise each on and off.
// 640 columns of eight rows draw about 41,000 normals, so the outermost table cells (one draw in
// 2048, Rng::Tail) occur about 20 times.
TEST(NoiseTest, EightRowsAtOnceDrawWhatEachRowDrawsAlone) {
  const double special[] = {0.0, -5.0, 3.0, 29.9, 30.0, std::nan(""), 1e12};
  int compared = 0;
  for (const int width : {1, 7, 8, 9, 17, 640}) {
    for (const int rows : {1, 5, 8}) {
      for (const bool shot : {true, false}) {
        for (const double read_sigma : {0.0, 30.0}) {
          SCOPED_TRACE(testing::Message()
                       << width << " x " << rows << " shot " << shot << " read " << read_sigma);
          const std::size_t n = static_cast<std::size_t>(rows) * width;
          std::vector<double> mu[4];
          std::vector<float> sd[4];
          for (int k = 0; k < 4; ++k) {
            mu[k].resize(n);
            sd[k].resize(n);
            for (std::size_t i = 0; i < n; ++i) {
              // Mostly lit pixels; every 97th pixel (and tap) something special.
              const std::size_t h = i * 31 + static_cast<std::size_t>(k) * 7;
              mu[k][i] =
                  h % 97 == 0 ? special[(h / 97) % 7] : 100.0 + static_cast<double>(h % 5000);
              sd[k][i] = static_cast<float>(std::sqrt(std::max(mu[k][i], 0.0)));
            }
          }
          std::vector<std::uint64_t> seeds(static_cast<std::size_t>(rows));
          for (int j = 0; j < rows; ++j) seeds[j] = RowSeed(99, j);
          const double* const mu_p[4] = {mu[0].data(), mu[1].data(), mu[2].data(), mu[3].data()};
          const float* const sd_p[4] = {sd[0].data(), sd[1].data(), sd[2].data(), sd[3].data()};
          // Expected: each row alone.
          std::vector<float> want[4], got[4], portable[4];
          for (int k = 0; k < 4; ++k) {
            want[k].assign(n, -1.f);
            got[k].assign(n, -2.f);
            portable[k].assign(n, -3.f);
          }
          float* want_rows[8][4];
          float* got_rows[8][4];
          float* portable_rows[8][4];
          for (int j = 0; j < rows; ++j) {
            const std::size_t at = static_cast<std::size_t>(j) * width;
            for (int k = 0; k < 4; ++k) {
              want_rows[j][k] = want[k].data() + at;
              got_rows[j][k] = got[k].data() + at;
              portable_rows[j][k] = portable[k].data() + at;
            }
            const double* const mu_j[4] = {mu_p[0] + at, mu_p[1] + at, mu_p[2] + at, mu_p[3] + at};
            const float* const sd_j[4] = {sd_p[0] + at, sd_p[1] + at, sd_p[2] + at, sd_p[3] + at};
            NoisyTaps(width, seeds[j], shot, read_sigma, mu_j, sd_j, want_rows[j]);
          }
          NoisyTapsRows(rows, width, static_cast<std::size_t>(width), seeds.data(), shot,
                        read_sigma, mu_p, sd_p, got_rows);
          {
            const tofcam::internal::PortableFormsForTesting forms(true);
            NoisyTapsRows(rows, width, static_cast<std::size_t>(width), seeds.data(), shot,
                          read_sigma, mu_p, sd_p, portable_rows);
          }
          for (int k = 0; k < 4; ++k) {
            for (std::size_t i = 0; i < n; ++i) {
              // Bit patterns, so that NaN taps (from NaN means) compare too.
              ASSERT_EQ(std::bit_cast<std::uint32_t>(got[k][i]),
                        std::bit_cast<std::uint32_t>(want[k][i]))
                  << "tap " << k << " pixel " << i << ": " << got[k][i] << " vs " << want[k][i];
              ASSERT_EQ(std::bit_cast<std::uint32_t>(portable[k][i]),
                        std::bit_cast<std::uint32_t>(want[k][i]))
                  << "tap " << k << " pixel " << i;
              ++compared;
            }
          }
        }
      }
    }
  }
  EXPECT_GT(compared, 100000);
  if (!tofcam::internal::CpuHasAvx512()) {
    GTEST_SKIP() << "no AVX-512 on this CPU: only the portable rows were compared";
  }
}

TEST(NoiseTest, FixedPatternIsABowlReachingItsDepthAtTheCorners) {
  CameraModel m = WithResolution(ResolveCameraModel("sr2"), 21, 11);  // centre (10, 5)
  m.fpn_bowl_m = 0.04;
  m.fpn_spread_m = 0;
  const Image<float> fpn = FixedPatternMap(m);
  EXPECT_NEAR(fpn(5, 10), 0.0, 1e-7);
  EXPECT_NEAR(fpn(0, 0), 0.04, 1e-7);
  EXPECT_NEAR(fpn(10, 20), 0.04, 1e-7);
  EXPECT_NEAR(fpn(5, 20), 0.02, 1e-7);  // u = 1, v = 0: half the depth
  m.fpn_bowl_m = 0;
  m.fpn_spread_m = 0.01;
  const Image<float> spread = FixedPatternMap(m);
  double s = 0, s2 = 0;
  for (std::size_t i = 0; i < spread.size(); ++i) {
    s += spread.data()[i];
    s2 += static_cast<double>(spread.data()[i]) * spread.data()[i];
  }
  const double n = static_cast<double>(spread.size());
  EXPECT_NEAR(std::sqrt(s2 / n - (s / n) * (s / n)), 0.01, 0.0015);  // 231 pixels
  EXPECT_EQ(FixedPatternMap(m)(3, 3), spread(3, 3));                 // the unit seed fixes it
}

}  // namespace
}  // namespace tofcam::sim::internal
