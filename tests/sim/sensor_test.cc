// Stage 4 of the simulator (src/sim/sensor.h): tap means, demodulation, ground-truth causes and
// saturation with blooming against hand-computed values.
#include "sensor.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <utility>
#include <vector>

#include "optics.h"
#include "parallel.h"
#include "rng.h"
#include "saturation.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/core/units.h"

namespace tofcam::sim::internal {
namespace {

TEST(SensorTest, PixelMeansWithoutSystematicErrorsAreThePhasorTimesTheIntegrationTime) {
  SensorConstants k;
  k.t_int_s = 0.01;
  k.dark_e = 50;
  k.m_to_rad = 2 * kPi / 7.5;
  const float re[2] = {3000, 0}, im[2] = {4000, 0}, dc[2] = {20000, 100};
  const float zero[2] = {0, 0};
  double a[2], b[2], cs[2], sn[2], shift[2];
  PixelMeans(k, 2, re, im, dc, zero, zero, zero, zero, a, b, cs, sn, shift);
  EXPECT_NEAR(a[0], 50.0, 1e-9);  // |3000 + 4000 i| * 0.01
  EXPECT_NEAR(b[0], 250.0, 1e-9);
  EXPECT_NEAR(cs[0], 0.6, 1e-12);
  EXPECT_NEAR(sn[0], 0.8, 1e-12);
  EXPECT_EQ(a[1], 0.0);  // no signal: amplitude 0, offset dark plus DC
  EXPECT_NEAR(b[1], 51.0, 1e-9);
}

TEST(SensorTest, ADistanceOffsetTurnsThePhasor) {
  SensorConstants k;
  k.t_int_s = 1;
  k.m_to_rad = 2 * kPi / 8.0;
  const float re[2] = {1, 1}, im[2] = {0, 0}, dc[2] = {2, 2}, zero[2] = {0, 0};
  const float fpn[2] = {0.05f, 2.0f};  // small (polynomial) and a quarter of L (libm)
  double a[2], b[2], cs[2], sn[2], shift[2];
  PixelMeans(k, 2, re, im, dc, zero, zero, zero, fpn, a, b, cs, sn, shift);
  const double small = 0.05f * 2 * kPi / 8.0;
  EXPECT_NEAR(cs[0], std::cos(small), 1e-9);
  EXPECT_NEAR(sn[0], std::sin(small), 1e-9);
  EXPECT_NEAR(cs[1], 0.0, 1e-12);
  EXPECT_NEAR(sn[1], 1.0, 1e-12);
}

TEST(SensorTest, TapMeansAreOffsetPlusAmplitudeTimesShiftedCosine) {
  SensorRow sr;
  sr.Resize(1);
  sr.a[0][0] = 100;
  sr.b[0][0] = 500;
  sr.cos_p[0][0] = std::cos(1.0);
  sr.sin_p[0][0] = std::sin(1.0);
  TapMeans(1, 1, sr);
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(sr.mu[k][0], 500 + 100 * std::cos(1.0 - k * kPi / 2), 1e-9) << k;
  }
  EXPECT_EQ(sr.a_mean[0], 100);
  // Four renderings: tap k from rendering k, means over the four.
  for (int s = 0; s < 4; ++s) {
    sr.a[s][0] = 100 + 10 * s;
    sr.b[s][0] = 500;
    sr.cos_p[s][0] = 1;
    sr.sin_p[s][0] = 0;
  }
  TapMeans(1, 4, sr);
  EXPECT_DOUBLE_EQ(sr.mu[0][0], 600);
  EXPECT_DOUBLE_EQ(sr.mu[2][0], 380);
  EXPECT_DOUBLE_EQ(sr.a_mean[0], 115);
}

TEST(SensorTest, DemodulationRecoversPhaseAmplitudeAndOffset) {
  const double phi = kPi / 3, amp = 100, off = 500;
  float taps[4];
  for (int k = 0; k < 4; ++k) taps[k] = static_cast<float>(off + amp * std::cos(phi - k * kPi / 2));
  const PixelRegisters r = Demodulate(taps, true, 1e5, 1.0, 0);
  EXPECT_EQ(r.distance, static_cast<std::uint16_t>(std::llround(65536.0 / 6)));
  EXPECT_EQ(r.amplitude, 100);
  EXPECT_EQ(r.intensity, 500);
  EXPECT_FALSE(r.saturated);
  // The offset register adds modulo 2^16.
  EXPECT_EQ(Demodulate(taps, true, 1e5, 1.0, 60000).distance,
            static_cast<std::uint16_t>((std::llround(65536.0 / 6) + 60000) % 65536));
  // A tap at the full well clips and flags; without clipping it does not.
  taps[0] = 2e5f;
  EXPECT_TRUE(Demodulate(taps, true, 1e5, 1.0, 0).saturated);
  EXPECT_FALSE(Demodulate(taps, false, 1e6, 0.01, 0).saturated);
  // An intensity beyond the register range clips and flags.
  const float bright[4] = {3e5f, 3e5f, 3e5f, 3e5f};
  const PixelRegisters b = Demodulate(bright, false, 1e6, 1.0, 0);
  EXPECT_EQ(b.intensity, kMaxSignalRegister);
  EXPECT_TRUE(b.saturated);
}

// DemodulateRow against Demodulate (libm atan2, llround, round) pixel by pixel.
void ExpectRowMatchesDemodulate(const std::vector<float> (&taps)[4], bool clip, double full_well,
                                double gain, int offset_register) {
  const int n = static_cast<int>(taps[0].size());
  std::vector<std::uint16_t> d(n), a(n), i(n);
  std::vector<std::uint8_t> sat(n);
  const float* const rows[4] = {taps[0].data(), taps[1].data(), taps[2].data(), taps[3].data()};
  DemodulateRow(n, rows, clip, full_well, gain, offset_register, d.data(), a.data(), i.data(),
                sat.data());
  int mismatches = 0;
  for (int c = 0; c < n; ++c) {
    const float t[4] = {taps[0][c], taps[1][c], taps[2][c], taps[3][c]};
    const PixelRegisters px = Demodulate(t, clip, full_well, gain, offset_register);
    mismatches += px.distance != d[c] || px.amplitude != a[c] || px.intensity != i[c] ||
                  px.saturated != (sat[c] != 0);
  }
  EXPECT_EQ(mismatches, 0);
}

TEST(SensorTest, RowDemodulationGivesDemodulatesRegistersBitForBit) {
  // 400,000 random pixels: tap charges from 0 to beyond the full well, some negative (read
  // noise), clipping on and off, the offset register wrapping. Then pixels whose register value
  // lies within 1e-5 of a rounding tie (found by search with libm): the row form redoes those with
  // libm (its atan2 differs from libm's by < 1e-6 register, so the margin is 10x that).
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-50.0f, 1.2e5f);
  std::vector<float> taps[4];
  for (auto& t : taps) t.resize(400000);
  for (int c = 0; c < 400000; ++c) {
    for (auto& t : taps) t[static_cast<std::size_t>(c)] = u(rng);
  }
  ExpectRowMatchesDemodulate(taps, true, 1e5, 0.5, 0);
  ExpectRowMatchesDemodulate(taps, false, 1e5, 0.05, 61000);

  std::vector<float> ties[4];
  for (int q = 0; q < 2000000 && ties[0].size() < 40; ++q) {
    const double i_comp = 30011.0, q_comp = q - 1000000.0;
    double phase = std::atan2(q_comp, i_comp);
    if (phase < 0) phase += 2 * kPi;
    const double x = phase / (2 * kPi) * kDistanceRegisterSpan;
    if (std::abs(x - std::floor(x) - 0.5) >= 1e-5) continue;
    // n0 - n2 = i_comp, n1 - n3 = q_comp with every tap a non-negative integer (exact in float).
    const double base = 1.1e6;
    ties[0].push_back(static_cast<float>(base + i_comp));
    ties[1].push_back(static_cast<float>(base + q_comp));
    ties[2].push_back(static_cast<float>(base));
    ties[3].push_back(static_cast<float>(base));
  }
  ASSERT_GE(ties[0].size(), 5u);  // the search found near-ties to test
  ExpectRowMatchesDemodulate(ties, false, 1e7, 0.01, 0);
}

TEST(SensorTest, TruthCausesFromTheComponents) {
  const float inf = std::numeric_limits<float>::infinity();
  // Pixel 0 direct only; 1 an indirect path at 90 degrees; 2 scattering at 90 degrees;
  // 3 mixed span; 4 no return; 5 beyond the range.
  const float re[6] = {1, 1, 1, 1, 0, 1}, im[6] = {0, 1, 0, 0, 0, 0};
  const float dre[6] = {1, 1, 1, 1, 0, 1}, dim[6] = {0, 0, 0, 0, 0, 0};
  const float sre[6] = {0, 0, 0, 0, 0, 0}, sim[6] = {0, 0, 1, 0, 0, 0};
  const float span[6] = {0, 0, 0, 0.2f, 0, 0}, td[6] = {2, 2, 2, 2, inf, 9};
  std::uint16_t bits[6];
  const double cos_bias = std::cos(0.01);
  TruthCauses(6, cos_bias * cos_bias, 1.0, 0.05, 7.5, re, im, dre, dim, sre, sim, span, td, bits);
  EXPECT_EQ(bits[0], 0);
  EXPECT_EQ(bits[1], static_cast<std::uint16_t>(Flag::kMultipath));
  EXPECT_EQ(bits[2], static_cast<std::uint16_t>(Flag::kScattering));
  EXPECT_EQ(bits[3], static_cast<std::uint16_t>(Flag::kMixed));
  EXPECT_EQ(bits[4], static_cast<std::uint16_t>(Flag::kNoReturn));
  EXPECT_EQ(bits[5], static_cast<std::uint16_t>(Flag::kBeyondUnambiguous));
}

TEST(SensorTest, SaturationClipsAndBloomsTheSpillIntoTheNeighboursConservingCharge) {
  const int w = 15, h = 15;
  std::vector<float> taps[4], bloom, tmp;
  for (auto& t : taps) t.assign(static_cast<std::size_t>(w) * h, 100.f);
  const std::size_t centre = 7 * w + 7;
  const float fw = 1000;
  taps[0][centre] = 1800;  // 800 over the full well
  taps[1][centre] = 1000;
  // Nothing bloomed without a bloom share: the excess goes to the drain.
  {
    std::vector<float> t2[4] = {taps[0], taps[1], taps[2], taps[3]};
    EXPECT_FALSE(Saturate(t2, bloom, tmp, w, h, 1.0, fw, 0.0, 0.0, 1, false));
    EXPECT_EQ(t2[0][centre], fw);
  }
  double before = 0;
  for (const auto& t : taps) before += std::accumulate(t.begin(), t.end(), 0.0);
  ASSERT_TRUE(Saturate(taps, bloom, tmp, w, h, 1.0, fw, 0.0, 1.0, 1, false));
  double after = 0;
  for (const auto& t : taps) after += std::accumulate(t.begin(), t.end(), 0.0);
  EXPECT_NEAR(after, before, 1e-2);       // sigma 1 px in a 15 px image: nothing leaves it
  EXPECT_EQ(taps[0][centre] > fw, true);  // it receives its own share of the spill back
  // Spill is charge, not light: every tap of a neighbour gets the same amount.
  const std::size_t nb = centre + 1;
  EXPECT_FLOAT_EQ(taps[0][nb], taps[1][nb]);
  EXPECT_FLOAT_EQ(taps[2][nb], taps[3][nb]);
  EXPECT_GT(taps[0][nb], 100.f);
  EXPECT_FLOAT_EQ(taps[0][0], 100.f);  // 7 px away: beyond the kernel radius of 3 px
}

// Saturate by its definition, pixel by pixel over the whole image (the form before blocks without
// overflow were skipped and the blooming blur and noise were bounded by the spilling pixels' box):
// OverflowPixel everywhere, the blur of the whole image, then per row its own stream drawing a
// Poisson spill for every pixel with bloom.
bool SaturateByDefinition(std::vector<float> (&taps)[4], std::vector<float>& bloom_mean, int w,
                          int h, double sigma_px, double full_well, double overflow, double bloom,
                          std::uint64_t frame_seed, bool shot_noise) {
  const std::size_t np = taps[0].size();
  bloom_mean.assign(np, 0.f);
  bool any = false;
  for (std::size_t i = 0; i < np; ++i) {
    float n[4];
    for (int k = 0; k < 4; ++k) n[k] = taps[k][i];
    const float out = OverflowPixel(n, static_cast<float>(full_well), static_cast<float>(overflow));
    for (int k = 0; k < 4; ++k) taps[k][i] = n[k];
    const float spill = static_cast<float>(bloom) * out;
    if (spill > 0) {
      bloom_mean[i] = spill / 4;
      any = true;
    }
  }
  if (!any) return false;
  std::vector<float> tmp;
  BlurInPlace(bloom_mean, tmp, w, h, sigma_px);
  for (int r = 0; r < h; ++r) {
    Rng rng(frame_seed ^ 0xB10060000000000Dull ^
            (static_cast<std::uint64_t>(r) * 0xA24BAED4963EE407ull));
    for (int c = 0; c < w; ++c) {
      const float mean = bloom_mean[static_cast<std::size_t>(r) * w + c];
      if (!(mean > 0)) continue;
      for (auto& tap : taps) {
        tap[static_cast<std::size_t>(r) * w + c] +=
            shot_noise ? static_cast<float>(rng.Poisson(mean)) : mean;
      }
    }
  }
  return true;
}

TEST(SensorTest, SaturationEqualsItsWholeImageDefinitionBitForBit) {
  // Overflowing pixels at the image's corners and edges, on both sides of the 64-pixel blocks the
  // overflow scan skips by, alone and in clusters; NaN and negative taps; blooming kernels from
  // radius 1 to wider than the image; with and without shot noise; on the calling thread and on a
  // pool of two (rows in chunks, each with its own stream). 37 x 23 for the edge cases, 640 x 64
  // so that the pool's worker takes chunks of its own (four rows each). Stale scratch (NaN, and
  // the previous case's bloom) must not leak into the result.
  int compared = 0, bloomed = 0, cases = 0;
  RowPool two(2);
  for (const auto& [w, h] : {std::pair{37, 23}, std::pair{640, 64}}) {
    const std::size_t np = static_cast<std::size_t>(w) * h;
    const std::size_t sw = static_cast<std::size_t>(w);
    const std::vector<std::vector<std::size_t>> hot = {
        {0},
        {np - 1},
        {63, 64, 127, 128},
        {sw - 1, sw * (h - 1), np / 2, np / 2 + 1, np / 2 + 2, np / 2 + sw},
        {},
    };
    std::vector<float> bloom_mean(np, std::numeric_limits<float>::quiet_NaN());
    std::vector<float> tmp(np, std::numeric_limits<float>::quiet_NaN());
    const std::vector<double> sigmas =
        w < 100 ? std::vector<double>{0.3, 1.5, 9.0} : std::vector<double>{1.5};
    for (const double sigma : sigmas) {
      for (const bool shot : {false, true}) {
        for (const auto& pixels : hot) {
          for (RowPool* pool : {static_cast<RowPool*>(nullptr), &two}) {
            std::vector<float> taps[4];
            for (int k = 0; k < 4; ++k) {
              taps[k].resize(np);
              for (std::size_t i = 0; i < np; ++i) {
                taps[k][i] =
                    200.f + static_cast<float>((i * 13 + static_cast<std::size_t>(k) * 5) % 300);
              }
            }
            taps[2][np / 2 + 100] = std::numeric_limits<float>::quiet_NaN();
            taps[3][np / 2 + 101] = -40.f;
            for (std::size_t p : pixels) {
              taps[p % 4][p] = 1100.f + static_cast<float>(p % 7) * 300.f;  // above the full well
              taps[(p + 1) % 4][p] = 980.f;
            }
            std::vector<float> want[4] = {taps[0], taps[1], taps[2], taps[3]};
            std::vector<float> want_bloom;
            const bool got_any =
                Saturate(taps, bloom_mean, tmp, w, h, sigma, 1000.0, 0.6, 0.3, 77, shot, pool);
            const bool want_any =
                SaturateByDefinition(want, want_bloom, w, h, sigma, 1000.0, 0.6, 0.3, 77, shot);
            ASSERT_EQ(got_any, want_any) << w << " x " << h << " sigma " << sigma;
            ++cases;
            bloomed += got_any;
            for (int k = 0; k < 4; ++k) {
              for (std::size_t i = 0; i < np; ++i) {
                ASSERT_EQ(std::bit_cast<std::uint32_t>(taps[k][i]),
                          std::bit_cast<std::uint32_t>(want[k][i]))
                    << w << " x " << h << " sigma " << sigma << " shot " << shot << " pool "
                    << (pool != nullptr) << " tap " << k << " pixel " << i;
                ++compared;
              }
            }
            // The bloom image: the definition's, or all zeros when nothing spilled.
            for (std::size_t i = 0; i < np; ++i) {
              ASSERT_EQ(std::bit_cast<std::uint32_t>(bloom_mean[i]),
                        std::bit_cast<std::uint32_t>(got_any ? want_bloom[i] : 0.f))
                  << w << " x " << h << " bloom at pixel " << i;
            }
          }
        }
      }
    }
  }
  EXPECT_EQ(cases, 80);
  EXPECT_EQ(bloomed, 64);  // every case with overflowing pixels bloomed, with and without a pool
  EXPECT_GT(compared, 2000000);
}

}  // namespace
}  // namespace tofcam::sim::internal
