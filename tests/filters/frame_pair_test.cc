#include "tofcam/filters/frame_pair.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

// A 2 x 1 frame: both pixels at distance d (wrapped into [0, L)), ΔL sigma.
MetricFrame Pixels(double f_hz, double d0, double d1, float sigma, int reg = 10) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(2, 1);
  m.amplitude = Image<float>(2, 1, 1000.0f);
  m.flags = Image<PixelFlags>(2, 1);
  m.delta_l_m = Image<float>(2, 1, sigma);
  m.info.modulation_frequency_hz = f_hz;
  m.info.integration_time_register = reg;
  const double l = UnambiguousRangeM(f_hz);
  m.radial_distance_m[0] = static_cast<float>(std::fmod(d0, l));
  m.radial_distance_m[1] = static_cast<float>(std::fmod(d1, l));
  return m;
}

TEST(FramePair, DualFrequencyUnwrapsBeyondBothRanges) {
  // A surface at 9 m reads 9 - L(20 MHz) = 1.505 m at 20 MHz and 9 - L(17 MHz) = 0.183 m at
  // 17 MHz; only the wrap counts (1, 1) make the two agree, at 9 m. Pixel 1 at 21.3 m needs
  // (2, 2). Equal σ: the result is the mean, σ / sqrt(2).
  const MetricFrame a = Pixels(20e6, 9.0, 21.3, 0.01f);
  MetricFrame b = Pixels(17e6, 9.0, 21.3, 0.01f);
  CombineFramePair(a, b);
  EXPECT_NEAR(b.radial_distance_m[0], 9.0, 1e-5);
  EXPECT_NEAR(b.radial_distance_m[1], 21.3, 1e-5);
  EXPECT_NEAR(b.delta_l_m[0], 0.01 / std::sqrt(2.0), 1e-7);
  EXPECT_FALSE(b.flags[0].Any(kRejectMask));
}

TEST(FramePair, UnwrapsEveryPixelOfALongFrame) {
  // 3000 pixels (the wrap search runs in blocks of pixels: several full ones and a partial one)
  // on a ramp from 0.5 m to 29.5 m, through every pair of wrap counts within the 30 m range:
  // each must read its own distance, none flagged.
  constexpr int kN = 3000;
  MetricFrame a, b;
  for (MetricFrame* m : {&a, &b}) {
    m->radial_distance_m = Image<float>(kN, 1);
    m->amplitude = Image<float>(kN, 1, 1000.0f);
    m->flags = Image<PixelFlags>(kN, 1);
    m->delta_l_m = Image<float>(kN, 1, 0.001f);
    m->info.integration_time_register = 10;
  }
  a.info.modulation_frequency_hz = 20e6;
  b.info.modulation_frequency_hz = 17e6;
  const double la = UnambiguousRangeM(20e6), lb = UnambiguousRangeM(17e6);
  for (int i = 0; i < kN; ++i) {
    const double d = 0.5 + 29.0 * i / (kN - 1);
    a.radial_distance_m[i] = static_cast<float>(std::fmod(d, la));
    b.radial_distance_m[i] = static_cast<float>(std::fmod(d, lb));
  }
  // Pixels rejected in the first frame at the start of a block and elsewhere: one phase alone
  // cannot be unwrapped (inconsistent), and their neighbours must not be disturbed.
  const int rejected[] = {0, 1024, 2048, 2999, 1500};
  for (int i : rejected) a.flags[i] = PixelFlags(Flag::kSaturated);
  CombineFramePair(a, b);
  for (int i = 0; i < kN; ++i) {
    if (std::find(std::begin(rejected), std::end(rejected), i) != std::end(rejected)) {
      ASSERT_TRUE(b.flags[i].Has(Flag::kInconsistent)) << i;
      continue;
    }
    const double d = 0.5 + 29.0 * i / (kN - 1);
    ASSERT_NEAR(b.radial_distance_m[i], d, 1e-4) << i;
    ASSERT_FALSE(b.flags[i].Any(kRejectMask)) << i;
  }
}

TEST(FramePair, DisagreementBeyondItsSigmaIsInconsistent) {
  // Second pixel moved 0.2 m between the frames; 4 σ of sqrt(2) x 1 cm is 5.7 cm.
  const MetricFrame a = Pixels(20e6, 3.0, 3.0, 0.01f);
  MetricFrame b = Pixels(17e6, 3.0, 3.2, 0.01f);
  FramePairOptions flag_motion;
  flag_motion.max_motion_m = 0.0;
  CombineFramePair(a, b, flag_motion);
  EXPECT_FALSE(b.flags[0].Has(Flag::kInconsistent));
  EXPECT_TRUE(b.flags[1].Has(Flag::kInconsistent));
  // One frequency alone cannot be unwrapped: a pixel rejected in one frame is inconsistent.
  MetricFrame c = Pixels(20e6, 3.0, 3.0, 0.01f);
  c.flags[0] = PixelFlags(Flag::kSaturated);
  MetricFrame d = Pixels(17e6, 3.0, 3.0, 0.01f);
  CombineFramePair(c, d);
  EXPECT_TRUE(d.flags[0].Has(Flag::kInconsistent));
}

TEST(FramePair, MotionThatLeavesTheWrapCountCertainKeepsTheNewestReading) {
  // The surface moved from 9.0 m to 9.2 m between the frames (both beyond both ranges: 20 MHz
  // reads 1.505 m, 17 MHz 0.383 m). The wrap counts (1, 1) agree best, by 0.2 m: beyond 4 σ
  // (5.7 cm), within max_motion_m (0.25 m), and every other pair is over 1 m off: motion. The
  // current (17 MHz) frame's reading is delivered unwrapped, 9.2 m, with its own ΔL (not the
  // average 9.1 m) and not flagged.
  // Pixel 1 jumped 0.9 m (9.0 -> 9.9 m: reads 1.505 and 1.083 m): now the pair (0, 0) agrees
  // best, by 0.42 m, and the right one (1, 1) is 0.9 m off. Neither is within the motion bound:
  // kInconsistent, not 1.08 m.
  const MetricFrame a = Pixels(20e6, 9.0, 9.0, 0.01f);
  MetricFrame b = Pixels(17e6, 9.2, 9.9, 0.01f);
  CombineFramePair(a, b);
  EXPECT_NEAR(b.radial_distance_m[0], 9.2, 1e-5);
  EXPECT_FLOAT_EQ(b.delta_l_m[0], 0.01f);
  EXPECT_FALSE(b.flags[0].Any(kRejectMask));
  EXPECT_TRUE(b.flags[1].Has(Flag::kInconsistent));
  // An amplitude per µs that more than doubled still says "moved": flagged within the bound.
  MetricFrame c = Pixels(17e6, 9.2, 9.2, 0.01f);
  c.amplitude[0] = 2500.0f;
  CombineFramePair(a, c);
  EXPECT_TRUE(c.flags[0].Has(Flag::kInconsistent));
  EXPECT_FALSE(c.flags[1].Any(kRejectMask));
  // The bound is an option: 0 flags every disagreement, as before.
  FramePairOptions strict;
  strict.max_motion_m = 0.0;
  MetricFrame d = Pixels(17e6, 9.2, 9.0, 0.01f);
  CombineFramePair(a, d, strict);
  EXPECT_TRUE(d.flags[0].Has(Flag::kInconsistent));
  EXPECT_NEAR(d.radial_distance_m[1], 9.0, 1e-5);
  strict.max_motion_m = -1.0;
  EXPECT_THROW(CombineFramePair(a, d, strict), Error);
}

TEST(FramePair, AmbiguousWrapCountsAreInconsistent) {
  // At 9 m with σ 30 cm per frame the tolerance is 4 x 0.42 = 1.7 m: the right pair (1, 1)
  // agrees exactly, but (0, 0) (1.505 vs 0.183 m, 1.32 m apart) agrees within it too, so the
  // noise cannot tell the two apart. With σ 5 cm (0.28 m) only the right one is within.
  const MetricFrame a = Pixels(20e6, 9.0, 9.0, 0.30f);
  MetricFrame b = Pixels(17e6, 9.0, 9.0, 0.30f);
  CombineFramePair(a, b);
  EXPECT_TRUE(b.flags[0].Has(Flag::kInconsistent));
  const MetricFrame c = Pixels(20e6, 9.0, 9.0, 0.05f);
  MetricFrame d = Pixels(17e6, 9.0, 9.0, 0.05f);
  CombineFramePair(c, d);
  EXPECT_FALSE(d.flags[0].Any(kRejectMask));
  EXPECT_NEAR(d.radial_distance_m[0], 9.0, 1e-5);
}

TEST(FramePair, AmplitudePerMicrosecondThatChangesMeansMotion) {
  // Pixel 0: the same surface (amplitude per µs equal); pixel 1: three times brighter in the
  // second frame (a hand came in), over the default ratio 2, although the distances agree.
  MetricFrame a = Pixels(20e6, 3.0, 3.0, 0.01f);
  MetricFrame b = Pixels(17e6, 3.0, 3.0, 0.01f);
  a.info.integration_time_us = b.info.integration_time_us = 2550.0;
  b.amplitude[1] = 3000.0f;
  CombineFramePair(a, b);
  EXPECT_FALSE(b.flags[0].Any(kRejectMask));
  EXPECT_TRUE(b.flags[1].Has(Flag::kInconsistent));
  // HDR: 4x the exposure, 4x the amplitude is the same surface; 1.5x is within the ratio too.
  MetricFrame shorter = Pixels(20e6, 3.0, 3.0, 0.01f, 10);
  MetricFrame longer = Pixels(20e6, 3.0, 3.0, 0.01f, 40);
  shorter.info.integration_time_us = 2550.0;
  longer.info.integration_time_us = 10200.0;
  longer.amplitude[0] = 4000.0f;
  longer.amplitude[1] = 6000.0f;
  CombineFramePair(shorter, longer);
  EXPECT_FALSE(longer.flags[0].Any(kRejectMask));
  EXPECT_FALSE(longer.flags[1].Any(kRejectMask));
  // Different exposures without known times cannot be compared: not checked.
  MetricFrame unknown = Pixels(20e6, 3.0, 3.0, 0.01f, 40);
  unknown.amplitude[1] = 100000.0f;
  CombineFramePair(Pixels(20e6, 3.0, 3.0, 0.01f, 10), unknown);
  EXPECT_FALSE(unknown.flags[1].Any(kRejectMask));
  // max_amplitude_ratio 0 turns the check off.
  MetricFrame c = Pixels(20e6, 3.0, 3.0, 0.01f);
  MetricFrame d = Pixels(17e6, 3.0, 3.0, 0.01f);
  d.amplitude[1] = 3000.0f;
  FramePairOptions off;
  off.max_amplitude_ratio = 0.0;
  CombineFramePair(c, d, off);
  EXPECT_FALSE(d.flags[1].Any(kRejectMask));
}

// An 81 x 1 pair at 20 and 17 MHz: pixels 0-79 single surfaces at 1.0 ... 4.95 m (enough for
// the pair's median amplitude ratio), pixel 80 the sum of two equal returns from 1 m and 4 m (a
// mixed pixel at a depth edge), each frame's distance and amplitude from the phasor sum in closed
// form; ΔL 5 mm. The 17 MHz frame has 0.9x the amplitude per µs everywhere (a demodulation contrast
// that differs by frequency).
MetricFrame MixedRow(double f_hz, double contrast) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(81, 1);
  m.amplitude = Image<float>(81, 1);
  m.flags = Image<PixelFlags>(81, 1);
  m.delta_l_m = Image<float>(81, 1, 0.005f);
  m.info.modulation_frequency_hz = f_hz;
  m.info.integration_time_us = 2550.0;
  const double l = UnambiguousRangeM(f_hz);
  auto set = [&](int i, double re, double im) {
    double phase = std::atan2(im, re);
    if (phase < 0) phase += 2 * kPi;
    m.radial_distance_m[i] = static_cast<float>(phase / (2 * kPi) * l);
    m.amplitude[i] = static_cast<float>(1000.0 * contrast * std::hypot(re, im));
  };
  for (int i = 0; i < 80; ++i) {
    const double phi = 2 * kPi * (1.0 + 0.05 * i) / l;
    set(i, std::cos(phi), std::sin(phi));
  }
  const double p1 = 2 * kPi * 1.0 / l, p2 = 2 * kPi * 4.0 / l;
  set(80, 0.5 * (std::cos(p1) + std::cos(p2)), 0.5 * (std::sin(p1) + std::sin(p2)));
  return m;
}

TEST(FramePair, AmplitudesThatDifferByFrequencyMeanTwoReturns) {
  // The mixed pixel reads 2.5 m at both frequencies (equal weights: the phase half-way), so
  // its distances agree; its amplitude does not: |cos(Δφ/2)| = 0.309 at 20 MHz, 0.482 at
  // 17 MHz (ln ratio 0.445 against 3 σ = 3 x 0.0055 and the 2 % floor, after the median 0.9 is
  // divided out). The single surfaces keep their ratio 0.9 exactly: not flagged.
  const MetricFrame a = MixedRow(20e6, 1.0);
  MetricFrame b = MixedRow(17e6, 0.9);
  EXPECT_NEAR(a.radial_distance_m[80], 2.5, 1e-4);
  EXPECT_NEAR(b.radial_distance_m[80], 2.5, 1e-4);
  CombineFramePair(a, b);
  for (int i = 0; i < 80; ++i) EXPECT_FALSE(b.flags[i].Any(kRejectMask)) << i;
  EXPECT_TRUE(b.flags[80].Has(Flag::kInconsistent));
  // Without the amplitude check the mixed pixel passes, 1.5 m from both of its surfaces.
  MetricFrame c = MixedRow(17e6, 0.9);
  FramePairOptions off;
  off.max_amplitude_disagreement_sigma = 0.0;
  CombineFramePair(a, c, off);
  EXPECT_FALSE(c.flags[80].Any(kRejectMask));
  EXPECT_NEAR(c.radial_distance_m[80], 2.5, 1e-4);
  // One frequency (HDR pairs): not checked (a mixed pixel's amplitude scales with exposure).
  MetricFrame d = MixedRow(20e6, 2.0);
  d.info.integration_time_us = 5100.0;
  d.info.integration_time_register = 20;
  CombineFramePair(a, d);
  EXPECT_FALSE(d.flags[80].Any(kRejectMask));
}

// Pixels whose amplitude is infinite in both frames have no amplitude ratio (inf / inf is NaN):
// they stay out of the pair's median, which the other 70 single surfaces still set to their
// ratio 0.9, so the surfaces pass and the mixed pixel is flagged as above.
TEST(FramePair, InfiniteAmplitudesStayOutOfTheMedian) {
  MetricFrame a = MixedRow(20e6, 1.0);
  MetricFrame b = MixedRow(17e6, 0.9);
  for (int i = 0; i < 10; ++i) {
    a.amplitude[i] = std::numeric_limits<float>::infinity();
    b.amplitude[i] = std::numeric_limits<float>::infinity();
  }
  CombineFramePair(a, b);
  for (int i = 10; i < 80; ++i) EXPECT_FALSE(b.flags[i].Any(kRejectMask)) << i;
  EXPECT_TRUE(b.flags[80].Has(Flag::kInconsistent));
}

// A 30 x 20 frame at `f_hz` whose pixels sum their returns in closed form (phasors): columns
// [0, region_cols) a wall at 2 m plus a second path `gap_m` longer of relative amplitude `eps`
// (multipath), the other columns a single return at `other_m`. Amplitude per µs 1000 x `contrast`
// x the sum's magnitude x `gain`; ΔL `sigma` everywhere.
MetricFrame TwoPathFrame(double f_hz, double contrast, int region_cols, double eps, double gap_m,
                         double other_m, float sigma, double region_m = 2.0, double gain = 1.0,
                         int region_first = 0) {
  constexpr int kW = 30, kH = 20;
  MetricFrame m;
  m.radial_distance_m = Image<float>(kW, kH);
  m.amplitude = Image<float>(kW, kH);
  m.flags = Image<PixelFlags>(kW, kH);
  m.delta_l_m = Image<float>(kW, kH, sigma);
  m.info.modulation_frequency_hz = f_hz;
  m.info.integration_time_us = 2550.0;
  const double l = UnambiguousRangeM(f_hz);
  for (int r = 0; r < kH; ++r) {
    for (int c = 0; c < kW; ++c) {
      const bool two = c >= region_first && c < region_first + region_cols;
      const double d = two ? region_m : other_m;
      const double p1 = 2 * kPi * d / l, p2 = 2 * kPi * (d + gap_m) / l;
      const double re = std::cos(p1) + (two ? eps * std::cos(p2) : 0.0);
      const double im = std::sin(p1) + (two ? eps * std::sin(p2) : 0.0);
      double phase = std::atan2(im, re);
      if (phase < 0) phase += 2 * kPi;
      m.radial_distance_m(r, c) = static_cast<float>(phase / (2 * kPi) * l);
      m.amplitude(r, c) = static_cast<float>(1000.0 * contrast * gain * std::hypot(re, im));
    }
  }
  return m;
}

int CountInconsistent(const MetricFrame& m, int c0, int c1) {
  int n = 0;
  for (int r = 0; r < m.height(); ++r) {
    for (int c = c0; c < c1; ++c) n += m.flags(r, c).Has(Flag::kInconsistent);
  }
  return n;
}

// Columns 0-9 sum a wall at 2 m and a second path 2.9 m longer at 0.2 of its amplitude: they read
// 2.18 m at 20 MHz and 2.27 m at 17 MHz, and their amplitude ratio is 0.071 above the wall's
// (ln). With ΔL 4 cm one pixel cannot tell: 3 σ of the ln ratio is 0.132 and the distances'
// tolerance 4 sqrt(2) ΔL = 0.23 m. A 7x7 window's mean has 1/7 of each σ: 3 σ = 0.019 (floor
// 2 %: 0.0198) and 0.024 m, which both the ratio (0.071 + 2 ln(2.27 / 2.18) = 0.149) and the
// distances' difference (0.088 m) exceed. The single surface (columns 10-29) is the pair's
// median.
TEST(FramePair, APooledCheckFindsARegionThatSumsTwoPaths) {
  const MetricFrame a = TwoPathFrame(20e6, 1.0, 10, 0.2, 2.9, 2.0, 0.04f);
  const MetricFrame b = TwoPathFrame(17e6, 0.9, 10, 0.2, 2.9, 2.0, 0.04f);
  EXPECT_NEAR(a.radial_distance_m(0, 0), 2.182, 0.002);
  EXPECT_NEAR(b.radial_distance_m(0, 0), 2.269, 0.002);
  FramePairOptions per_pixel;
  per_pixel.two_returns_radius_px = 0;
  MetricFrame alone = b;
  CombineFramePair(a, alone, per_pixel);
  EXPECT_EQ(CountInconsistent(alone, 0, 30), 0);
  MetricFrame pooled = b;
  CombineFramePair(a, pooled);  // the default window: 7x7
  EXPECT_EQ(CountInconsistent(pooled, 0, 10), 200);
  // A flagged pixel delivers its current reading, unwrapped, with its own ΔL (not the average).
  EXPECT_NEAR(pooled.radial_distance_m(0, 0), 2.269, 0.002);
  EXPECT_FLOAT_EQ(pooled.delta_l_m(0, 0), 0.04f);
  // The same-surface test compares the current readings: the region's (2.27 m) lie 0.27 m from
  // the wall's, beyond 4 combined σ (0.226 m), another surface, which the wall's pixels beside
  // it do not pool. Were they pooled, column 10 (3 of its window's 7 columns in the region) would
  // have 3/7 of both departures, beyond both bounds.
  EXPECT_EQ(CountInconsistent(pooled, 10, 30), 0);
  // The same region in columns 20-29, which a row of 30 leaves to the loop's one-pixel tail
  // (after one block of 16): flagged alike.
  const MetricFrame a_tail = TwoPathFrame(20e6, 1.0, 10, 0.2, 2.9, 2.0, 0.04f, 2.0, 1.0, 20);
  MetricFrame b_tail = TwoPathFrame(17e6, 0.9, 10, 0.2, 2.9, 2.0, 0.04f, 2.0, 1.0, 20);
  CombineFramePair(a_tail, b_tail);
  EXPECT_EQ(CountInconsistent(b_tail, 20, 30), 200);
  EXPECT_EQ(CountInconsistent(b_tail, 0, 20), 0);
  // Frames of other sizes in between (the check's buffers are the thread's) and of no pixels.
  const MetricFrame small_a = Pixels(20e6, 1.0, 2.0, 0.01f);
  MetricFrame small_b = Pixels(17e6, 1.0, 2.0, 0.01f);
  CombineFramePair(small_a, small_b);
  EXPECT_FALSE(small_b.flags[0].Any(kRejectMask));
  MetricFrame empty_a = small_a, empty_b = small_b;
  for (MetricFrame* f : {&empty_a, &empty_b}) {
    f->radial_distance_m = Image<float>(0, 4);
    f->amplitude = Image<float>(0, 4);
    f->delta_l_m = Image<float>(0, 4);
    f->flags = Image<PixelFlags>(0, 4);
  }
  EXPECT_NO_THROW(CombineFramePair(empty_a, empty_b));
  // A ΔL whose weights would overflow the float sums (1e-25 m, inside the region) leaves that
  // pixel out of the pools, so its neighbours are judged as before (were it pooled, the sums of
  // the 49 windows that hold it would be inf or NaN and none of them flagged); the per-pixel
  // check flags it itself (its ratio departs beyond a σ of 1e-25). An infinite ΔL on the wall
  // is flagged by the per-pixel wrap search: every pair of wrap counts agrees within an
  // infinite tolerance.
  MetricFrame a_odd = a, b_odd = b;
  for (MetricFrame* f : {&a_odd, &b_odd}) {
    f->delta_l_m(5, 5) = 1e-25f;
    f->delta_l_m(6, 25) = std::numeric_limits<float>::infinity();
  }
  CombineFramePair(a_odd, b_odd);
  EXPECT_EQ(CountInconsistent(b_odd, 0, 10), 200);
  EXPECT_TRUE(b_odd.flags(6, 25).Has(Flag::kInconsistent));
  EXPECT_EQ(CountInconsistent(b_odd, 10, 30), 1);
  MetricFrame again = b;
  CombineFramePair(a, again);
  EXPECT_EQ(CountInconsistent(again, 0, 10), 200);
  EXPECT_EQ(CountInconsistent(again, 10, 30), 0);
  // Infinite amplitudes (no ratio) in a column of the wall stay out of the median and the sums.
  MetricFrame a_inf = a, b_inf = b;
  for (int r = 0; r < 20; ++r) {
    a_inf.amplitude(r, 20) = std::numeric_limits<float>::infinity();
    b_inf.amplitude(r, 20) = std::numeric_limits<float>::infinity();
  }
  CombineFramePair(a_inf, b_inf);
  EXPECT_EQ(CountInconsistent(b_inf, 0, 10), 200);
  EXPECT_EQ(CountInconsistent(b_inf, 10, 30), 0);
  // A line of multipath one pixel wide pools along itself: column 0's pixels at rows 3-16 pool 7
  // readings (3 σ: 0.050 and 0.064 m, against 0.149 and 0.088 m). Its end pixels pool 4-6
  // readings, fewer than the window's side (7), and are left to the per-pixel check.
  const MetricFrame a1 = TwoPathFrame(20e6, 1.0, 1, 0.2, 2.9, 2.0, 0.04f);
  MetricFrame b1 = TwoPathFrame(17e6, 0.9, 1, 0.2, 2.9, 2.0, 0.04f);
  CombineFramePair(a1, b1);
  for (int r = 0; r < 20; ++r)
    EXPECT_EQ(b1.flags(r, 0).Has(Flag::kInconsistent), r >= 3 && r <= 16);
  EXPECT_EQ(CountInconsistent(b1, 1, 30), 0);
}

// Motion moves the distances alone. Columns 0-9 are a surface that moved from 2.0 to 2.08 m
// between the frames (single returns), the rest a wall at 3 m that stayed; ΔL 3 cm. The moved
// pixels' amplitude fell by (2.0 / 2.08)², as one surface's does: ln ratio 0.078 below the
// wall's, within one pixel's 3 σ (0.099), and their distances differ by 0.08 m, within 4
// combined σ (0.17 m). A 7x7 window's mean of the distances' difference departs (3 σ: 0.018 m),
// but corrected for the distance the amplitude ratio is the wall's: not flagged. A moved
// surface whose amplitude did not fall contradicts one return (corrected ratio 2 ln(2.08 / 2) =
// 0.078 against 3 σ = 0.014, floor 0.0198): flagged.
TEST(FramePair, APooledCheckLeavesMotionAlone) {
  const MetricFrame a = TwoPathFrame(20e6, 1.0, 10, 0.0, 0.0, 3.0, 0.03f, 2.0);
  const double fall = (2.0 / 2.08) * (2.0 / 2.08);
  MetricFrame b = TwoPathFrame(17e6, 0.9, 10, 0.0, 0.0, 3.0, 0.03f, 2.08);
  for (int r = 0; r < b.height(); ++r) {
    for (int c = 0; c < 10; ++c) b.amplitude(r, c) *= static_cast<float>(fall);
  }
  CombineFramePair(a, b);
  EXPECT_EQ(CountInconsistent(b, 0, 30), 0);
  MetricFrame bright = TwoPathFrame(17e6, 0.9, 10, 0.0, 0.0, 3.0, 0.03f, 2.08);
  FramePairOptions per_pixel;
  per_pixel.two_returns_radius_px = 0;
  MetricFrame bright_alone = bright;
  CombineFramePair(a, bright_alone, per_pixel);
  EXPECT_EQ(CountInconsistent(bright_alone, 0, 30), 0);
  CombineFramePair(a, bright);
  EXPECT_EQ(CountInconsistent(bright, 0, 10), 200);
  EXPECT_EQ(CountInconsistent(bright, 10, 30), 0);
}

// With fewer than 64 contributors the pooled ratio's reference is the per-pixel check's median.
// A 30x20 pair at contrast 0.9 whose pixels all jumped 1 m between the frames (2 -> 3 m: beyond
// the motion bound, so kInconsistent, and not contributors) except a block of 8x5 that moved
// 8 cm with its amplitude falling as 1/d²: the per-pixel median is ln 0.9 (all 600 pixels), and
// the block's motion-corrected ratio is ln 0.9 too, so it departs from nothing, while its
// distances' difference (0.08 m) departs by many σ. Had the reference been 0 (equal contrast),
// the block's ratio would depart by 0.105 and the whole block would be flagged.
TEST(FramePair, APooledCheckWithFewContributorsTakesThePairsMedian) {
  const MetricFrame a = TwoPathFrame(20e6, 1.0, 0, 0.0, 0.0, 2.0, 0.03f);
  MetricFrame b = TwoPathFrame(17e6, 0.9, 0, 0.0, 0.0, 3.0, 0.03f);
  const double fall = (2.0 / 2.08) * (2.0 / 2.08);
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 8; ++c) {
      b.radial_distance_m(r, c) = 2.08f;
      b.amplitude(r, c) = static_cast<float>(900.0 * fall);
    }
  }
  CombineFramePair(a, b);
  int block = 0;
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 8; ++c) block += b.flags(r, c).Has(Flag::kInconsistent);
  }
  EXPECT_EQ(block, 0);
  EXPECT_EQ(CountInconsistent(b, 0, 30), 600 - 40);  // the jumps
}

TEST(FramePair, HdrTakesTheOtherExposureWhereOneClippedAndWeightsBySigma) {
  // Long exposure (previous): σ 1 cm; short exposure (current): σ 3 cm, 2 cm further off.
  // Weights 1/σ²: (3.00 / 1e-4 + 3.02 / 9e-4) / (1/1e-4 + 1/9e-4) = 3.002 m.
  const MetricFrame longer = Pixels(20e6, 3.0, 5.0, 0.01f, 40);
  MetricFrame shorter = Pixels(20e6, 3.02, 5.0, 0.03f, 10);
  shorter.flags[1] = PixelFlags(Flag::kSaturated);  // clipped here: the long one is used
  shorter.radial_distance_m[1] = 0.0f;
  CombineFramePair(longer, shorter);
  EXPECT_NEAR(shorter.radial_distance_m[0], 3.002, 1e-5);
  EXPECT_NEAR(shorter.delta_l_m[0], 1.0 / std::sqrt(1e4 + 1e4 / 9.0), 1e-7);
  EXPECT_NEAR(shorter.radial_distance_m[1], 5.0, 1e-6);
  EXPECT_FALSE(shorter.flags[1].Any(kRejectMask));
}

TEST(FramePairCombiner, CombinesOnlyWhenSettingsAlternate) {
  FramePairCombiner combiner;
  MetricFrame a = Pixels(20e6, 9.0, 9.0, 0.01f);
  MetricFrame b = Pixels(17e6, 9.0, 9.0, 0.01f);
  MetricFrame c = Pixels(20e6, 9.0, 9.0, 0.01f);
  MetricFrame c2 = c;
  EXPECT_FALSE(combiner.Process(a));  // first frame
  EXPECT_TRUE(combiner.Process(b));
  EXPECT_NEAR(b.radial_distance_m[0], 9.0, 1e-5);
  EXPECT_TRUE(combiner.Process(c));  // combined with b as it came in (0.183 m), not 9 m
  EXPECT_NEAR(c.radial_distance_m[0], 9.0, 1e-5);
  EXPECT_FALSE(combiner.Process(c2));  // same settings as the frame before: passed through
}

TEST(FramePairCombiner, PairsExposuresOnlyWhenAskedTo) {
  // A controller's step (register 10 -> 40) at one frequency. Pixel 1 is clipped in the second
  // frame: as HDR it takes the first frame's 5 m and loses the reject bit; without exposure
  // pairing the frame passes through as it came, clipped pixel and all.
  MetricFrame first = Pixels(20e6, 3.0, 5.0, 0.03f, 10);
  MetricFrame second = Pixels(20e6, 3.02, 5.0, 0.01f, 40);
  second.flags[1] = PixelFlags(Flag::kSaturated);
  second.radial_distance_m[1] = 0.0f;
  MetricFrame first_copy = first, second_copy = second;

  FramePairCombiner hdr;  // pair_exposures: the default
  EXPECT_FALSE(hdr.Process(first));
  EXPECT_TRUE(hdr.Process(second));
  EXPECT_NEAR(second.radial_distance_m[1], 5.0, 1e-6);
  EXPECT_FALSE(second.flags[1].Any(kRejectMask));

  FramePairCombiner frequencies_only({}, /*pair_exposures=*/false);
  EXPECT_FALSE(frequencies_only.Process(first_copy));
  EXPECT_FALSE(frequencies_only.Process(second_copy));
  EXPECT_EQ(second_copy.radial_distance_m[0], 3.02f);
  EXPECT_EQ(second_copy.radial_distance_m[1], 0.0f);
  EXPECT_TRUE(second_copy.flags[1].Has(Flag::kSaturated));
  // A change of frequency is still a pair: a surface at 9 m, unwrapped from 20 and 17 MHz.
  MetricFrame third = Pixels(20e6, 9.0, 9.0, 0.01f, 40);
  MetricFrame fourth = Pixels(17e6, 9.0, 9.0, 0.01f, 40);
  EXPECT_FALSE(frequencies_only.Process(third));  // same settings as the frame before
  EXPECT_TRUE(frequencies_only.Process(fourth));
  EXPECT_NEAR(fourth.radial_distance_m[0], 9.0, 1e-5);
}

TEST(WrapCheck, FlagsSurfacesTooDarkForTheirDistance) {
  // Pixel 0: a white wall at 2 m. Pixel 1: the same wall at 9.5 m, read as 2.005 m at 20 MHz,
  // amplitude (2/9.5)² of pixel 0's: exactly on the line for margin 1, below it for the
  // default 1.5. Pixel 2: a 60 % grey surface at 2 m: kept.
  MetricFrame m;
  m.radial_distance_m = Image<float>(3, 1);
  m.amplitude = Image<float>(3, 1);
  m.flags = Image<PixelFlags>(3, 1);
  m.info.modulation_frequency_hz = 20e6;
  const double l = UnambiguousRangeM(20e6);
  m.radial_distance_m[0] = 2.0f;
  m.amplitude[0] = 4000.0f;
  m.radial_distance_m[1] = static_cast<float>(9.5 - l);
  m.amplitude[1] = static_cast<float>(4000.0 * (2.0 / 9.5) * (2.0 / 9.5));
  m.radial_distance_m[2] = 2.0f;
  m.amplitude[2] = 2400.0f;
  WrapCheckOptions o;
  o.envelope_quantile = 1.0;  // the white wall is the brightest surface
  // Rays along the optical axis and isolated pixels (no neighbour in the next row): cos θ = 1.
  RayTable rays{Image<float>(3, 1, 0.0f), Image<float>(3, 1, 0.0f), Image<float>(3, 1, 1.0f)};
  const Image<PixelFlags> f = WrapCheckFilter(m, rays, o);
  EXPECT_FALSE(f[0].Has(Flag::kInconsistent));
  EXPECT_TRUE(f[1].Has(Flag::kInconsistent));
  EXPECT_FALSE(f[2].Has(Flag::kInconsistent));
}

TEST(FramePair, BadInputIsAClearError) {
  MetricFrame a = Pixels(20e6, 1, 1, 0.01f);
  MetricFrame b = Pixels(17e6, 1, 1, 0.01f);
  b.delta_l_m = Image<float>();
  EXPECT_THROW(CombineFramePair(a, b), Error);
  for (double bad : {0.0, -17e6, 1e15, std::numeric_limits<double>::infinity(), std::nan("")}) {
    MetricFrame c = Pixels(17e6, 1, 1, 0.01f);
    c.info.modulation_frequency_hz = bad;
    EXPECT_THROW(CombineFramePair(a, c), Error) << bad;
    EXPECT_THROW(CombineFramePair(c, a), Error) << bad;
  }
  FramePairOptions o;
  o.max_disagreement_sigma = 0;
  EXPECT_THROW(FramePairCombiner{o}, Error);
  for (double bad : {0.5, -1.0, 2e6, std::nan("")}) {
    FramePairOptions r;
    r.max_amplitude_ratio = bad;
    EXPECT_THROW(FramePairCombiner{r}, Error) << bad;
  }
  for (double bad : {-0.5, 1001.0, std::nan("")}) {
    FramePairOptions r;
    r.max_amplitude_disagreement_sigma = bad;
    EXPECT_THROW(FramePairCombiner{r}, Error) << bad;
    r = {};
    r.min_amplitude_tolerance = bad > 1000 ? 1.5 : bad;
    EXPECT_THROW(FramePairCombiner{r}, Error) << bad;
  }
  for (int bad : {-1, FramePairOptions::kMaxTwoReturnsRadiusPx + 1}) {
    FramePairOptions r;
    r.two_returns_radius_px = bad;
    EXPECT_THROW(FramePairCombiner{r}, Error) << bad;
  }
  WrapCheckOptions w;
  w.margin = 0;
  RayTable rays{Image<float>(2, 1, 0.0f), Image<float>(2, 1, 0.0f), Image<float>(2, 1, 1.0f)};
  EXPECT_THROW((void)WrapCheckFilter(a, rays, w), Error);
}

}  // namespace
}  // namespace tofcam
