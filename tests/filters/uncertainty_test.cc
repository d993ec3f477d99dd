#include "tofcam/filters/uncertainty.h"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

MetricFrame Row(std::initializer_list<float> d, float sigma) {
  MetricFrame m;
  const int w = static_cast<int>(d.size());
  m.radial_distance_m = Image<float>(w, 1);
  m.amplitude = Image<float>(w, 1, 1000.0f);
  m.flags = Image<PixelFlags>(w, 1);
  m.delta_l_m = Image<float>(w, 1, sigma);
  int i = 0;
  for (float v : d) m.radial_distance_m[i++] = v;
  return m;
}

// A w x h frame of zeros with ΔL and no flags, amplitude 1000.
MetricFrame Blank(int w, int h) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(w, h);
  m.amplitude = Image<float>(w, h, 1000.0f);
  m.flags = Image<PixelFlags>(w, h);
  m.delta_l_m = Image<float>(w, h);
  return m;
}

// A row of pixels with the given distances and ΔL (sizes equal), m.
MetricFrame Pixels(std::initializer_list<float> d, std::initializer_list<float> sigma) {
  MetricFrame m = Row(d, 0.0f);
  int i = 0;
  for (float v : sigma) m.delta_l_m[i++] = v;
  return m;
}

// u of pixel (r, c) as the header defines it (default form, no extrapolated edges), straight
// from the frame in double.
float DefinitionU(const MetricFrame& m, int r, int c, const UncertaintyOptions& o) {
  const int w = m.width(), h = m.height();
  auto usable = [&](int rr, int cc) {
    return !m.flags(rr, cc).Any(kRejectMask) && std::isfinite(m.radial_distance_m(rr, cc)) &&
           std::isfinite(m.delta_l_m(rr, cc));
  };
  if (!usable(r, c)) return std::numeric_limits<float>::infinity();
  const double d = m.radial_distance_m(r, c), s = m.delta_l_m(r, c);
  double jump = 0.0;
  for (const auto& [dr, dc] : {std::pair{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
    const int rr = r + dr, cc = c + dc;
    if (rr < 0 || rr >= h || cc < 0 || cc >= w) continue;
    if (m.flags(rr, cc).Any(o.unknown_neighbour_flags)) {
      return std::numeric_limits<float>::infinity();
    }
    if (!usable(rr, cc)) continue;
    const double step = std::abs(static_cast<double>(m.radial_distance_m(rr, cc)) - d);
    const double sj = m.delta_l_m(rr, cc);
    if (step > o.min_jump_sigma * std::sqrt(s * s + sj * sj)) jump = std::max(jump, step);
  }
  const double edge = o.edge_fraction * jump;
  return static_cast<float>(std::sqrt(s * s + edge * edge));
}

// The filter's flag as the header defines it: kLowConfidence on a pixel without a reject flag
// whose u is above the threshold (as a float, the type of u).
bool DefinitionLow(const MetricFrame& m, int r, int c, const UncertaintyOptions& o) {
  return !m.flags(r, c).Any(kRejectMask) &&
         !(DefinitionU(m, r, c, o) <= static_cast<float>(o.max_uncertainty_m));
}

TEST(Uncertainty, EdgesAddHalfTheirJump) {
  // 1.0, 1.0 | 2.0: the pixels next to the 1 m step get sqrt(0.01² + 0.5²); the first one only
  // its noise. A 2 cm step is below 3 sqrt(2) σ = 4.2 cm: noise, not an edge.
  MetricFrame m = Row({1.0f, 1.0f, 2.0f, 2.02f}, 0.01f);
  const Image<float> u = ComputeUncertainty(m);
  EXPECT_NEAR(u[0], 0.01, 1e-7);
  EXPECT_NEAR(u[1], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[2], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[3], 0.01, 1e-7);
  const Image<PixelFlags> f = UncertaintyFilter(m);
  EXPECT_FALSE(f[0].Has(Flag::kLowConfidence));
  EXPECT_TRUE(f[1].Has(Flag::kLowConfidence));
  EXPECT_TRUE(f[2].Has(Flag::kLowConfidence));
  // A noisy pixel alone: ΔL 6 cm > 5 cm.
  EXPECT_TRUE(UncertaintyFilter(Row({3.0f}, 0.06f))[0].Has(Flag::kLowConfidence));
}

TEST(Uncertainty, ExtrapolatedEdgesChargeOnlyWhatLeavesTheOwnSurface) {
  // 1, 1, 1 | 1.5 (a mixed pixel) | 2, 2, 2 with σ 1 cm. Pixel 2 continues its line (1, 1): 0
  // off it, so its noise alone although it is next to a 0.5 m step. Pixel 3 is 0.5 m off the
  // line of 1, 1 and 0.5 m off that of 2, 2: u = sqrt(0.01² + 0.5²). A slope (steps of 10 cm, a
  // straight line) has no edge term at all, where the step rule charges half of each step.
  UncertaintyOptions on;
  on.extrapolate_edges = true;
  MetricFrame m = Row({1.0f, 1.0f, 1.0f, 1.5f, 2.0f, 2.0f, 2.0f}, 0.01f);
  Image<float> u = ComputeUncertainty(m, on);
  EXPECT_NEAR(u[2], 0.01, 1e-6);
  EXPECT_NEAR(u[3], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[4], 0.01, 1e-6);
  EXPECT_NEAR(u[1], 0.01, 1e-6);
  const Image<float> step_rule = ComputeUncertainty(m);
  EXPECT_NEAR(step_rule[2], std::sqrt(0.0001 + 0.0625), 1e-6);
  // Pixel 2 of a 5-pixel slope has a line on both sides: no edge term. Pixels 0, 1, 3 and 4
  // have a 10 cm step towards a side where their own line runs out of the image: the step rule.
  m = Row({1.0f, 1.1f, 1.2f, 1.3f, 1.4f}, 0.01f);
  u = ComputeUncertainty(m, on);
  for (int i = 0; i < 5; ++i) {
    const double expected = i == 2 ? 0.01 : std::sqrt(0.0001 + 0.0025);
    EXPECT_NEAR(u[i], expected, 1e-6) << i;
  }
  EXPECT_NEAR(ComputeUncertainty(m)[2], std::sqrt(0.0001 + 0.0025), 1e-6);
  // Off the line by less than 3 sqrt(6) σ = 7.3 cm is noise: 1, 1, 1.03 | 2 charges pixel 2
  // nothing (its 3 cm step back is no edge either); by 10 cm (1, 1, 1.1 | 2) it charges the
  // 10 cm (more than the step rule's 5 cm for the step back, whose own line is outside).
  m = Row({1.0f, 1.0f, 1.03f, 2.0f}, 0.01f);
  EXPECT_NEAR(ComputeUncertainty(m, on)[2], 0.01, 1e-6);
  m = Row({1.0f, 1.0f, 1.1f, 2.0f}, 0.01f);
  EXPECT_NEAR(ComputeUncertainty(m, on)[2], std::sqrt(0.0001 + 0.01), 1e-6);
}

// A mixed pixel as the sensor forms it: the phasor sum of two returns, share `own` from a surface
// at `near_m` whose full pixel returns amplitude `near_amp`, the rest from one at `far_m`
// returning `far_amp`, at 20 MHz. Its reading is the sum's phase as a distance in [0, L), its
// amplitude the sum's magnitude.
struct Mix {
  float distance_m;
  float amplitude;
};
Mix MixedPixel(double own, double near_m, double near_amp, double far_m, double far_amp) {
  const double k = 4.0 * kPi * 20e6 / kSpeedOfLightMPerS;  // rad per m of distance
  const std::complex<double> z =
      own * std::polar(near_amp, k * near_m) + (1.0 - own) * std::polar(far_amp, k * far_m);
  double phase = std::arg(z);
  if (phase < 0.0) phase += 2.0 * kPi;
  return {static_cast<float>(phase / k), static_cast<float>(std::abs(z))};
}

// Row 1.0, 1.0 | mixed | 4.0, 4.0 m: the near surface returns 1000, the far one 40 (a bright
// object in front of a dim wall). Distance σ 1 cm near, 5 cm far; edge_fraction 0 so that only
// the unmixing charges an edge.
MetricFrame EdgeRow(const Mix& mixed) {
  MetricFrame m = Row({1.0f, 1.0f, mixed.distance_m, 4.0f, 4.0f}, 0.01f);
  m.info.modulation_frequency_hz = 20e6;
  m.amplitude[2] = mixed.amplitude;
  m.amplitude[3] = m.amplitude[4] = 40.0f;
  m.delta_l_m[3] = m.delta_l_m[4] = 0.05f;
  return m;
}

UncertaintyOptions UnmixOnly() {
  UncertaintyOptions o;
  o.edge_fraction = 0.0;
  o.unmix_edges = true;
  return o;
}

TEST(Uncertainty, UnmixingChargesAPixelMostlyOnTheOtherSideTheWholeStep) {
  // 30 % of the pixel on the near object, 70 % on the wall: it reads the object (300 against 28
  // of amplitude, 7 cm towards the wall), but its centre lies on the wall, 2.93 m further.
  const Mix mostly_far = MixedPixel(0.3, 1.0, 1000.0, 4.0, 40.0);
  ASSERT_NEAR(mostly_far.distance_m, 1.07, 0.01);
  MetricFrame m = EdgeRow(mostly_far);
  Image<float> u = ComputeUncertainty(m, UnmixOnly());
  const double step = 4.0 - mostly_far.distance_m;
  EXPECT_NEAR(u[2], std::sqrt(0.0001 + step * step), 1e-5);
  // The pure pixels on either side keep their noise: each one has all its area on its own side
  // (t = 1).
  for (const int i : {0, 1, 3, 4}) EXPECT_NEAR(u[i], m.delta_l_m[i], 1e-7) << i;
  EXPECT_TRUE(UncertaintyFilter(m, UnmixOnly())[2].Has(Flag::kLowConfidence));
  // Off, the same pixel is charged nothing (edge_fraction 0).
  UncertaintyOptions off = UnmixOnly();
  off.unmix_edges = false;
  EXPECT_NEAR(ComputeUncertainty(m, off)[2], 0.01, 1e-7);

  // 70 % on the object: its centre is on the object, which it reads; no charge.
  m = EdgeRow(MixedPixel(0.7, 1.0, 1000.0, 4.0, 40.0));
  u = ComputeUncertainty(m, UnmixOnly());
  EXPECT_NEAR(u[2], 0.01, 1e-7);
  EXPECT_FALSE(UncertaintyFilter(m, UnmixOnly())[2].Has(Flag::kLowConfidence));

  // The same down a column.
  MetricFrame col = Blank(1, 5);
  col.info.modulation_frequency_hz = 20e6;
  m = EdgeRow(mostly_far);
  for (int i = 0; i < 5; ++i) {
    col.radial_distance_m[i] = m.radial_distance_m[i];
    col.amplitude[i] = m.amplitude[i];
    col.delta_l_m[i] = m.delta_l_m[i];
  }
  EXPECT_NEAR(ComputeUncertainty(col, UnmixOnly())[2], std::sqrt(0.0001 + step * step), 1e-5);
}

TEST(Uncertainty, UnmixingChargesAShareThatIsHalfWithinItsNoise) {
  // 52 % of the pixel on the object (it reads 1.027 m at amplitude 505): its centre may lie on
  // either side when the share is 1/2 within its noise. To first order t's σ is sqrt(var_i + t²
  // var_a + (1 - t)² var_j) / |z_a - z_j| (here 1033), each phasor's variance (amplitude x ΔL x
  // 4π f / c)². With ΔL 3 cm on the near side, σ_t = 0.0177 and 0.52 - 3 σ_t = 0.467: charged;
  // with 0.5 cm, σ_t = 0.0030 and 0.511: not; with 3 cm and min_jump_sigma 1, 0.502: not.
  const double k = 4.0 * kPi * 20e6 / kSpeedOfLightMPerS;
  const Mix half = MixedPixel(0.52, 1.0, 1000.0, 4.0, 40.0);
  struct Case {
    float near_sigma;
    double min_jump_sigma;
    bool charged;
  };
  for (const Case& c :
       {Case{0.03f, 3.0, true}, Case{0.005f, 3.0, false}, Case{0.03f, 1.0, false}}) {
    MetricFrame m = EdgeRow(half);
    for (const int i : {0, 1, 2}) m.delta_l_m[i] = c.near_sigma;
    const auto var = [&](int q) {
      const double s = m.amplitude[q] * m.delta_l_m[q] * k;
      return s * s;
    };
    const std::complex<double> za = std::polar(1000.0, k * 1.0), zj = std::polar(40.0, k * 4.0);
    const double sigma_t =
        std::sqrt(var(2) + 0.52 * 0.52 * var(1) + 0.48 * 0.48 * var(3)) / std::abs(za - zj);
    ASSERT_EQ(0.52 - c.min_jump_sigma * sigma_t < 0.5, c.charged) << sigma_t;
    UncertaintyOptions o = UnmixOnly();
    o.min_jump_sigma = c.min_jump_sigma;
    const double step = 4.0 - half.distance_m;
    EXPECT_NEAR(ComputeUncertainty(m, o)[2],
                c.charged ? std::sqrt(c.near_sigma * c.near_sigma + step * step) : c.near_sigma,
                1e-5)
        << c.near_sigma << " " << c.min_jump_sigma;
  }
}

TEST(Uncertainty, UnmixingLeavesPixelsBesideASmallStepAlone) {
  // Two bright surfaces s apart (amplitude 1000, σ 1 cm), no mixed pixel: the two beside the step
  // are each wholly on their own side (t = 1). For a small step the two sides' phasors are too
  // close for that to show: |z_a - z_j| = 2000 sin(k s / 2) must exceed 4 min_jump_sigma
  // sqrt(var_i + var_a) (17 cm here), so that a pixel wholly on its own side is shown to lie
  // there by more than half, with noise; below that the share decides nothing. At 8 cm the
  // phasors pass the plain separation test (3 sqrt(var_i + var_a + var_j)) and the step leaves
  // the pixel's own line (8 > 7.3 cm), but t - 3 σ_t would be 0.47 for a pixel at t = 1.
  for (const float s : {0.07f, 0.08f, 0.085f, 0.1f, 0.15f, 0.25f}) {
    MetricFrame m = Row({1.0f, 1.0f, 1.0f + s, 1.0f + s}, 0.01f);
    m.info.modulation_frequency_hz = 20e6;
    const Image<float> u = ComputeUncertainty(m, UnmixOnly());
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(u[i], 0.01, 1e-7) << s << " " << i;
  }
  // A pixel wholly on its own side whose reading is 1 σ towards a 10 cm step (1.01 m): its share
  // is 0.90 with σ_t 0.135, so 0.90 - 3 σ_t = 0.495 would charge it, had the phasors (84 apart,
  // against 4 x 3 x 11.9 = 142) been taken to tell.
  MetricFrame noisy = Row({1.0f, 1.01f, 1.1f, 1.1f}, 0.01f);
  noisy.info.modulation_frequency_hz = 20e6;
  const Image<float> u_noisy = ComputeUncertainty(noisy, UnmixOnly());
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(u_noisy[i], 0.01, 1e-7) << i;
  // The same beside a neighbour the filters rejected (no bend test for it), 4-8 cm away.
  for (const float s : {0.04f, 0.06f, 0.08f}) {
    MetricFrame m = Row({1.0f, 1.0f, 1.0f + s, 1.0f + s}, 0.01f);
    m.info.modulation_frequency_hz = 20e6;
    m.flags[2] = m.flags[3] = PixelFlags(Flag::kHighDeltaL);
    const Image<float> u = ComputeUncertainty(m, UnmixOnly());
    for (int i = 0; i < 2; ++i) EXPECT_NEAR(u[i], 0.01, 1e-7) << s << " " << i;
  }
}

TEST(Uncertainty, UnmixingLeavesASlopeAlone) {
  // One surface sloping away, read with noise: 1.00, 1.055, 1.18 m at equal amplitude, σ 1 cm.
  // The middle pixel's 12.5 cm step to the right passes the edge test (3 sqrt 2 σ = 4.2 cm), it
  // reads within half of it of its left neighbour, and the two sides' phasors are far enough
  // apart to decide (151 against 4 x 3 x 11.9 = 142), but the step continues the line through
  // the two (d_j - 2 d_i + d_a = 7.0 cm, within 3 sqrt(1 + 4 + 1) σ = 7.3 cm): no edge. Its
  // phasor lies between its neighbours' (share 0.69, σ 0.070: 0.69 - 3σ = 0.485), which alone
  // would charge it.
  MetricFrame m = Row({1.0f, 1.055f, 1.18f}, 0.01f);
  m.info.modulation_frequency_hz = 20e6;
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[i], 0.01, 1e-7) << i;
  // Where the step leaves that line (2.0 m instead of 1.18), it is an edge, and the pixel's
  // share on its own side is no charge either; a pixel half on a bright object and half on a
  // dim wall (it reads 1.029 m at amplitude 484) is charged.
  m.radial_distance_m[2] = 2.0f;
  EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[1], 0.01, 1e-7);
  m = EdgeRow(MixedPixel(0.5, 1.0, 1000.0, 4.0, 40.0));
  EXPECT_GT(ComputeUncertainty(m, UnmixOnly())[2], 2.0);
}

TEST(Uncertainty, UnmixingTakesADimRejectedOtherSide) {
  // The wall is so dim that its pixels read noise (here 3.5 and 0.4 m, ΔL 1 m) and the accuracy
  // filter rejected them; their phasors are still small, and the pixel's share is about its
  // amplitude against its own side's: 300 / 1000.
  const Mix mostly_far = MixedPixel(0.3, 1.0, 1000.0, 4.0, 8.0);
  MetricFrame m = EdgeRow(mostly_far);
  m.radial_distance_m[3] = 3.5f;
  m.radial_distance_m[4] = 0.4f;
  m.amplitude[3] = m.amplitude[4] = 8.0f;
  m.delta_l_m[3] = m.delta_l_m[4] = 1.0f;
  m.flags[3] = m.flags[4] = PixelFlags(Flag::kHighDeltaL);
  const double step = 3.5 - mostly_far.distance_m;
  EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], std::sqrt(0.0001 + step * step), 1e-5);
  // Had the filters kept such a neighbour, its 2.5 m step would be within 3 sqrt(1² + 0.01²) =
  // 3 m of noise: no edge, no charge.
  m.flags[3] = PixelFlags();
  EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 0.01, 1e-7);
  // A clipped or invalid neighbour's amplitude is no measurement: not unmixed, although its
  // reading (the wall's own phasor, 4 m and 8) gives a share below one half when rejected for
  // noise alone.
  m.radial_distance_m[3] = 4.0f;
  m.amplitude[3] = 8.0f;
  m.delta_l_m[3] = 0.05f;
  m.flags[3] = PixelFlags(Flag::kHighDeltaL);
  ASSERT_GT(ComputeUncertainty(m, UnmixOnly())[2], 1.0);
  for (const Flag f : {Flag::kSaturated, Flag::kInvalid}) {
    m.flags[3] = PixelFlags(f);
    EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 0.01, 1e-7);
  }
  // Nor one whose amplitude is 0 (rejected as too dark): a phasor of 0 would give t = 0.28.
  m.flags[3] = PixelFlags(Flag::kLowAmplitude);
  m.amplitude[3] = 0.0f;
  EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 0.01, 1e-7);
}

TEST(Uncertainty, UnmixingLeavesOneSurfaceAndMissingAmplitudesAlone) {
  // One surface whose brightness falls across the pixels (1000, then 650 or 200, then 300): the
  // middle pixel's 2 cm step to the right is noise (below 3 sqrt(2) σ = 4.2 cm), so no edge,
  // although at 200 its share between its neighbours is -0.14 (at 650 it is 0.5: half way).
  MetricFrame m = Row({1.0f, 1.0f, 1.02f}, 0.01f);
  m.info.modulation_frequency_hz = 20e6;
  m.amplitude[1] = 650.0f;
  m.amplitude[2] = 300.0f;
  for (const float middle : {650.0f, 200.0f}) {
    m.amplitude[1] = middle;
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[i], 0.01, 1e-7);
  }
  // The same row above a rejected pixel (noise: kHighDeltaL) under the middle one, so that the
  // middle pixel is looked at: towards its right neighbour (2 cm, noise) its share is -0.14, but
  // that neighbour is usable and its step no edge, so it charges nothing.
  MetricFrame two = Blank(3, 2);
  two.info.modulation_frequency_hz = 20e6;
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) {
      two.radial_distance_m(r, c) = c == 2 ? 1.02f : 1.0f;
      two.delta_l_m(r, c) = 0.01f;
    }
  }
  two.amplitude(0, 1) = 200.0f;
  two.amplitude(0, 2) = 300.0f;
  two.flags(1, 1) = PixelFlags(Flag::kHighDeltaL);
  const Image<float> u_two = ComputeUncertainty(two, UnmixOnly());
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(u_two(0, c), 0.01, 1e-7) << c;
  // Two sides whose phasors lie within 3 σ of t's noise: no decision. With ΔL 2 m on the near
  // side, a phasor's σ is 1000 x 2 m x 0.84 rad/m = 1680 there, against about 1000 between the
  // two sides.
  const Mix mostly_far = MixedPixel(0.3, 1.0, 1000.0, 4.0, 40.0);
  m = EdgeRow(mostly_far);
  for (const int i : {0, 1, 2}) m.delta_l_m[i] = 2.0f;  // phasor σ 1000 x 2 m x 0.84 rad/m
  m.flags[3] = m.flags[4] = PixelFlags(Flag::kHighDeltaL);
  EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 2.0, 1e-6);
  // Without an amplitude image, with the pixel's amplitude 0, infinite or NaN, or without a
  // usable modulation frequency, nothing is unmixed. (The 0 cases pin the guards; with an
  // infinite or NaN value the phasors' noise test would also fail, and those cases show only
  // that nothing is charged.)
  m = EdgeRow(mostly_far);
  m.amplitude = Image<float>();
  EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 0.01, 1e-7);
  for (const float bad :
       {0.0f, std::numeric_limits<float>::infinity(), std::numeric_limits<float>::quiet_NaN()}) {
    m = EdgeRow(mostly_far);
    m.amplitude[2] = bad;
    EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 0.01, 1e-7) << bad;
  }
  for (const double f :
       {0.0, std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    m = EdgeRow(mostly_far);
    m.info.modulation_frequency_hz = f;
    EXPECT_NEAR(ComputeUncertainty(m, UnmixOnly())[2], 0.01, 1e-7) << f;
  }
}

TEST(Uncertainty, ExtrapolatedEdgesWorkDownColumnsAndFallBackNextToRejectedPixels) {
  // The mixed-pixel row of the test above as a column (1 x 7): the same terms.
  UncertaintyOptions on;
  on.extrapolate_edges = true;
  MetricFrame m = Row({1.0f, 1.0f, 1.0f, 1.5f, 2.0f, 2.0f, 2.0f}, 0.01f);
  MetricFrame column;
  column.radial_distance_m = Image<float>(1, 7);
  column.flags = Image<PixelFlags>(1, 7);
  column.delta_l_m = Image<float>(1, 7, 0.01f);
  for (int i = 0; i < 7; ++i) column.radial_distance_m[i] = m.radial_distance_m[i];
  const Image<float> u = ComputeUncertainty(column, on);
  EXPECT_NEAR(u[2], 0.01, 1e-6);
  EXPECT_NEAR(u[3], std::sqrt(0.0001 + 0.25), 1e-6);
  EXPECT_NEAR(u[4], 0.01, 1e-6);
  // Pixel 1 rejected: pixel 2's own line (1, 2) is not measurable, so its step to pixel 3 (0.5 m)
  // is charged by the step rule, half of it.
  column.flags[1] = PixelFlags(Flag::kLowAmplitude);
  EXPECT_NEAR(ComputeUncertainty(column, on)[2], std::sqrt(0.0001 + 0.0625), 1e-6);
}

TEST(Uncertainty, RejectedPixelsAreInfiniteAndNotNeighbours) {
  MetricFrame m = Row({1.0f, 5.0f, 1.0f, 1.0f}, 0.01f);
  m.flags[1] = PixelFlags(Flag::kLowAmplitude);
  const Image<float> u = ComputeUncertainty(m);
  EXPECT_TRUE(std::isinf(u[1]));
  EXPECT_NEAR(u[0], 0.01, 1e-7);  // a rejected neighbour is no edge evidence
  EXPECT_FALSE(UncertaintyFilter(m)[1].Any(kRejectMask));  // its own flag already says why
}

TEST(Uncertainty, NextToAClippedPixelTheJumpIsUnbounded) {
  // Pixel 1 clipped: its distance is unknown, pixels 0 and 2 may mix with it (u = inf, flagged);
  // pixel 3 is two away and keeps its noise. Without the flag in unknown_neighbour_flags, a
  // clipped neighbour is merely unusable, as any rejected one. The same for kInconsistent.
  MetricFrame m = Row({1.0f, 5.0f, 1.0f, 1.0f}, 0.01f);
  m.flags[1] = PixelFlags(Flag::kSaturated);
  UncertaintyOptions on;
  on.unknown_neighbour_flags =
      PixelFlags(Flag::kSaturated).bits() | PixelFlags(Flag::kInconsistent).bits();
  const Image<float> u = ComputeUncertainty(m, on);
  EXPECT_TRUE(std::isinf(u[0]));
  EXPECT_TRUE(std::isinf(u[2]));
  EXPECT_NEAR(u[3], 0.01, 1e-7);
  const Image<PixelFlags> f = UncertaintyFilter(m, on);
  EXPECT_TRUE(f[0].Has(Flag::kLowConfidence));
  EXPECT_TRUE(f[2].Has(Flag::kLowConfidence));
  EXPECT_FALSE(f[1].Any(kRejectMask));  // its own kSaturated says why
  EXPECT_FALSE(f[3].Any(kRejectMask));
  UncertaintyOptions off;
  off.unknown_neighbour_flags = 0;
  EXPECT_NEAR(ComputeUncertainty(m, off)[0], 0.01, 1e-7);
  m.flags[1] = PixelFlags(Flag::kInconsistent);
  EXPECT_TRUE(std::isinf(ComputeUncertainty(m, on)[0]));
}

// The file comment's definition, pixel by pixel, against the filter's rows on random frames:
// surfaces with steps, noise-sized and edge-sized; NaN, inf and rejected pixels; missing ΔL; a
// clipped (unknown) neighbour; every size from one pixel up, so that no row length, border or
// image edge is special. The same double formula, so the same bits.
TEST(Uncertainty, RowsEqualTheDefinitionForEverySizeAndPattern) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  constexpr float kInf = std::numeric_limits<float>::infinity();
  int finite = 0, edges = 0;
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{
           {1, 1}, {2, 3}, {5, 1}, {7, 6}, {16, 4}, {17, 2}, {32, 3}, {33, 2}, {37, 9}}) {
    MetricFrame m = Blank(w, h);
    for (std::size_t i = 0; i < m.flags.size(); ++i) {
      m.radial_distance_m[i] =
          1.0f + 0.5f * static_cast<float>(static_cast<int>(u(rng) * 3)) + 0.01f * u(rng);
      m.delta_l_m[i] = 0.002f + 0.02f * u(rng);
      const float roll = u(rng);
      if (roll < 0.04f) m.radial_distance_m[i] = std::numeric_limits<float>::quiet_NaN();
      if (roll > 0.04f && roll < 0.07f) m.radial_distance_m[i] = kInf;
      if (roll > 0.07f && roll < 0.10f) m.delta_l_m[i] = std::numeric_limits<float>::quiet_NaN();
      if (roll > 0.10f && roll < 0.15f) m.flags[i] = PixelFlags(Flag::kLowAmplitude);
      if (roll > 0.15f && roll < 0.18f) m.flags[i] = PixelFlags(Flag::kSaturated);
    }
    UncertaintyOptions o;
    o.unknown_neighbour_flags = static_cast<std::uint16_t>(Flag::kSaturated);
    // Both forms: the AVX-512 row where the CPU has it, and the portable one.
    for (const bool portable : {false, true}) {
      SCOPED_TRACE(portable ? "portable" : "AVX-512 if available");
      const internal::PortableFormsForTesting forms(portable);
      const Image<float> got = ComputeUncertainty(m, o);
      for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) {
          const float expected = DefinitionU(m, r, c, o);
          finite += !portable && expected < kInf;
          edges += !portable && expected < kInf && expected != m.delta_l_m(r, c);
          ASSERT_EQ(std::memcmp(&got(r, c), &expected, sizeof expected), 0)
              << w << "x" << h << " at (" << r << ", " << c << "): " << got(r, c) << " vs "
              << expected;
        }
      }
      // The filter flags exactly the usable pixels above the threshold (and those next to a
      // clipped one).
      const Image<PixelFlags> flags = UncertaintyFilter(m, o);
      for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) {
          EXPECT_EQ(flags(r, c).Has(Flag::kLowConfidence), DefinitionLow(m, r, c, o))
              << w << "x" << h << " at (" << r << ", " << c << ")";
        }
      }
    }
  }
  EXPECT_GT(finite, 100);
  EXPECT_GT(edges, 30);
}

TEST(Uncertainty, AStepThatTiesTheThresholdIsNoEdge) {
  // The edge test is step > min_jump_sigma x sqrt(s² + s_n²). With s = 0.375, s_n = 0.5 the
  // square root is 0.625 exactly, so a step of 3 x 0.625 = 1.875 ties the threshold (no edge:
  // u = s) and the next float above it is an edge (u = sqrt(s² + (step / 2)²)). The rows test
  // squares (step² against 9 x 0.390625), where a tie sits in the band left to the exact test.
  MetricFrame m;
  m.radial_distance_m = Image<float>(3, 1);
  m.delta_l_m = Image<float>(3, 1);
  m.flags = Image<PixelFlags>(3, 1);
  m.amplitude = Image<float>(3, 1, 1000.0f);
  m.radial_distance_m[0] = 1.0f;
  m.radial_distance_m[1] = 2.875f;  // 1.875 from pixel 0
  m.radial_distance_m[2] = 2.875f;
  m.delta_l_m[0] = 0.375f;
  m.delta_l_m[1] = 0.5f;
  m.delta_l_m[2] = 0.5f;
  const float above = std::nextafter(2.875f, 4.0f);
  const double half_step = 0.5 * (static_cast<double>(above) - 1.0);
  for (const bool portable : {false, true}) {
    SCOPED_TRACE(portable ? "portable" : "AVX-512 if available");
    const internal::PortableFormsForTesting forms(portable);
    m.radial_distance_m[1] = 2.875f;
    EXPECT_EQ(ComputeUncertainty(m, {})[0], 0.375f);
    m.radial_distance_m[1] = above;
    const float edge = ComputeUncertainty(m, {})[0];
    EXPECT_EQ(edge, static_cast<float>(std::sqrt(0.140625 + half_step * half_step)));
    EXPECT_GT(edge, 0.9f);
  }
}

TEST(Uncertainty, ThresholdsWithinAnUlpOfTheStepFollowTheDefinition) {
  // min_jump_sigma set to step / sqrt(s² + s_n²) and its neighbouring doubles, for random
  // distances and ΔL: the step lies within an ulp of the threshold, where comparing squares
  // without the band would decide some cases differently from the definition (asserted below, so
  // that the test can fail when the band or the exact redo is missing).
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> dist(1.0f, 3.0f), sigma(0.05f, 0.5f);
  int squares_disagree = 0, edges = 0, cases = 0, flag_is_edge = 0;
  for (int i = 0; i < 3000; ++i) {
    const float d0 = dist(rng), s0 = sigma(rng), d1 = dist(rng), s1 = sigma(rng);
    const MetricFrame m = Pixels({d0, d1}, {s0, s1});
    const double s = m.delta_l_m[0], sn = m.delta_l_m[1];
    const double step =
        std::abs(static_cast<double>(m.radial_distance_m[1]) - m.radial_distance_m[0]);
    if (step == 0.0) continue;
    const double m0 = step / std::sqrt(s * s + sn * sn);
    for (const double jump_sigma :
         {std::nextafter(m0, 0.0), m0, std::nextafter(m0, std::numeric_limits<double>::max())}) {
      const bool edge = step > jump_sigma * std::sqrt(s * s + sn * sn);  // the definition
      squares_disagree += (step * step > jump_sigma * jump_sigma * (s * s + sn * sn)) != edge;
      edges += edge;
      ++cases;
      const double e = edge ? 0.5 * step : 0.0;
      const float expected = static_cast<float>(std::sqrt(s * s + e * e));
      UncertaintyOptions o;
      o.min_jump_sigma = jump_sigma;
      // A threshold between u without and with the edge term, so that the flag follows the edge
      // test (unless both u round to the threshold's float: counted below).
      o.max_uncertainty_m = std::sqrt(s * s + 0.125 * step * step);
      const bool low = DefinitionLow(m, 0, 0, o);
      flag_is_edge += low == edge;
      for (const bool portable : {false, true}) {
        const internal::PortableFormsForTesting forms(portable);
        const float got = ComputeUncertainty(m, o)[0];
        ASSERT_EQ(std::memcmp(&got, &expected, sizeof got), 0)
            << "case " << i << (portable ? " portable" : " AVX-512 if available") << ": step "
            << step << ", min_jump_sigma " << jump_sigma;
        ASSERT_EQ(UncertaintyFilter(m, o)[0].Has(Flag::kLowConfidence), low)
            << "case " << i << (portable ? " portable" : " AVX-512 if available") << ": step "
            << step << ", min_jump_sigma " << jump_sigma;
      }
    }
  }
  EXPECT_GT(squares_disagree, 10);            // the band and the exact redo matter here
  EXPECT_GT(flag_is_edge, 99 * cases / 100);  // the flags test the edge decisions
  EXPECT_GT(edges, cases / 4);                // both outcomes occur
  EXPECT_LT(edges, 3 * cases / 4);
}

TEST(Uncertainty, FlagsAtThresholdsWithinAnUlpOfUFollowTheDefinition) {
  // Two pixels a clear edge apart; max_uncertainty_m set to the first pixel's u and to the floats
  // next to it, so that u <= max decides by one ulp. The filter's AVX-512 form tests u² against
  // max² in float, where these cases lie in the band it leaves to the exact test; the float
  // squares alone would decide some of them differently (asserted, so that the test can fail
  // when the band or the redo is missing).
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> dist(1.0f, 2.0f), sigma(0.01f, 0.05f);
  int float_disagrees = 0, lows = 0, cases = 0;
  for (int i = 0; i < 3000; ++i) {
    const float d0 = dist(rng), d1 = d0 + 1.0f + dist(rng), s0 = sigma(rng), s1 = sigma(rng);
    const MetricFrame m = Pixels({d0, d1}, {s0, s1});
    UncertaintyOptions o;
    const float u = DefinitionU(m, 0, 0, o);
    const float step = m.radial_distance_m[1] - m.radial_distance_m[0];
    const float s = m.delta_l_m[0];
    for (const float max : {std::nextafter(u, 0.0f), u, std::nextafter(u, 100.0f)}) {
      o.max_uncertainty_m = max;
      const bool low = DefinitionLow(m, 0, 0, o);
      lows += low;
      ++cases;
      float_disagrees += (std::fma(0.25f, step * step, s * s) > max * max) != low;
      for (const bool portable : {false, true}) {
        const internal::PortableFormsForTesting forms(portable);
        ASSERT_EQ(UncertaintyFilter(m, o)[0].Has(Flag::kLowConfidence), low)
            << "case " << i << (portable ? " portable" : " AVX-512 if available") << ": u " << u
            << ", max " << max;
      }
    }
  }
  EXPECT_GT(float_disagrees, 10);
  EXPECT_GT(lows, cases / 4);  // both outcomes occur
  EXPECT_LT(lows, 3 * cases / 4);
}

TEST(Uncertainty, ExtremeValuesAndOptionsFollowTheDefinition) {
  // Distances and ΔL from zero and subnormals to the float maximum, NaN and inf among them, and
  // options at and beyond the limits of the filter's float form (which leaves values outside
  // 1e-10..1e15 and such options to the exact tests): both forms give the definition's u and
  // flags.
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const float magnitudes[] = {0.0f, 1e-40f, 1e-30f, 1e-12f, 5e-11f, 1e-10f, 0.003f, 0.02f, 1.0f,
                              2.5f, 7.0f,   1e14f,  1e15f,  2e15f,  1e20f,  3e38f,  kInf};
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> pick(0, static_cast<int>(std::size(magnitudes)) - 1);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<UncertaintyOptions> options(11);
  options[1].min_jump_sigma = 1e-3;
  options[2].min_jump_sigma = 5e-4;
  options[3].max_uncertainty_m = 1e-10;
  options[4].max_uncertainty_m = 100.0;
  options[5].edge_fraction = 1e-6;
  options[6].edge_fraction = 0.0;
  options[7].edge_fraction = 1.0;
  options[8].unknown_neighbour_flags = static_cast<std::uint16_t>(Flag::kSaturated);
  options[9].max_uncertainty_m = 9e-11;  // below the float form's limits: the exact form
  options[10].edge_fraction = 5e-7;
  int lows = 0, judged = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const int w = 37, h = 9;
    MetricFrame m = Blank(w, h);
    for (std::size_t i = 0; i < m.flags.size(); ++i) {
      // Most pixels ordinary (a surface at 1-2 m with ΔL of 1-5 cm), the rest extreme.
      const bool ordinary = u(rng) < 0.5f;
      m.radial_distance_m[i] = ordinary ? 1.0f + u(rng) : magnitudes[pick(rng)];
      m.delta_l_m[i] = ordinary ? 0.01f + 0.04f * u(rng) : magnitudes[pick(rng)];
      const float roll = u(rng);
      if (roll < 0.1f) m.radial_distance_m[i] = -m.radial_distance_m[i];
      if (roll > 0.1f && roll < 0.13f) m.delta_l_m[i] = std::numeric_limits<float>::quiet_NaN();
      if (roll > 0.13f && roll < 0.16f) m.flags[i] = PixelFlags(Flag::kSaturated);
      if (roll > 0.16f && roll < 0.19f) m.flags[i] = PixelFlags(Flag::kLowAmplitude);
    }
    for (std::size_t k = 0; k < options.size(); ++k) {
      const UncertaintyOptions& o = options[k];
      for (const bool portable : {false, true}) {
        const internal::PortableFormsForTesting forms(portable);
        const Image<float> got_u = ComputeUncertainty(m, o);
        const Image<PixelFlags> got = UncertaintyFilter(m, o);
        for (int r = 0; r < h; ++r) {
          for (int c = 0; c < w; ++c) {
            const float expected = DefinitionU(m, r, c, o);
            ASSERT_EQ(std::memcmp(&got_u(r, c), &expected, sizeof expected), 0)
                << "trial " << trial << ", options " << k << (portable ? ", portable" : "")
                << " at (" << r << ", " << c << ")";
            const bool low = DefinitionLow(m, r, c, o);
            ASSERT_EQ(got(r, c).Has(Flag::kLowConfidence), low)
                << "trial " << trial << ", options " << k << (portable ? ", portable" : "")
                << " at (" << r << ", " << c << "): d " << m.radial_distance_m(r, c) << ", ΔL "
                << m.delta_l_m(r, c) << ", u " << expected;
            lows += low;
            judged += !m.flags(r, c).Any(kRejectMask);
          }
        }
      }
    }
  }
  EXPECT_GT(lows, judged / 10);  // both outcomes occur
  EXPECT_LT(lows, 9 * judged / 10);
}

TEST(Uncertainty, IntoOverwritesAReusedImageOfAnySize) {
  // UncertaintyFilterInto into an image of another size (resized), then into the same image
  // filled with other bits (every pixel overwritten): the flags of the definition each time, in
  // both forms (the AVX-512 form where the CPU has it, and the portable one).
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  MetricFrame m = Blank(37, 9);
  // Two planes side by side (an edge down the middle), millimetres of noise, some clipped pixels.
  for (int r = 0; r < m.height(); ++r) {
    for (int c = 0; c < m.width(); ++c) {
      m.radial_distance_m(r, c) = (c < m.width() / 2 ? 1.0f : 2.0f) + 0.01f * u(rng);
      m.delta_l_m(r, c) = 0.002f + 0.03f * u(rng);
      if (u(rng) < 0.05f) m.flags(r, c) = Flag::kSaturated;
    }
  }
  const UncertaintyOptions o;
  for (const bool portable : {false, true}) {
    SCOPED_TRACE(portable ? "portable" : "AVX-512 where available");
    const internal::PortableFormsForTesting forms(portable);
    Image<PixelFlags> out(5, 5, PixelFlags(Flag::kJumpEdge));
    for (int pass = 0; pass < 2; ++pass) {
      UncertaintyFilterInto(m, o, out);
      ASSERT_EQ(out.width(), m.width());
      ASSERT_EQ(out.height(), m.height());
      int low = 0;
      for (int r = 0; r < m.height(); ++r) {
        for (int c = 0; c < m.width(); ++c) {
          const bool expected = DefinitionLow(m, r, c, o);
          low += expected;
          EXPECT_EQ(out(r, c).bits(),
                    expected ? static_cast<std::uint16_t>(Flag::kLowConfidence) : 0u)
              << r << "," << c;
        }
      }
      EXPECT_GT(low, 10);  // the edge between the two planes is flagged
      EXPECT_LT(low, m.width() * m.height() / 2);
      for (std::size_t i = 0; i < out.size(); ++i) out[i] = PixelFlags(Flag::kJumpEdge);
    }
  }
}

TEST(Uncertainty, BadInputIsAClearError) {
  MetricFrame m = Row({1.0f}, 0.01f);
  m.delta_l_m = Image<float>();
  EXPECT_THROW((void)ComputeUncertainty(m), Error);
  UncertaintyOptions o;
  o.max_uncertainty_m = 0;
  EXPECT_THROW((void)ComputeUncertainty(Row({1.0f}, 0.01f), o), Error);
  Image<PixelFlags> out;
  EXPECT_THROW(UncertaintyFilterInto(m, {}, out), Error);
  EXPECT_THROW(UncertaintyFilterInto(Row({1.0f}, 0.01f), o, out), Error);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

// A prediction set by hand: p and σ_p everywhere (NaN = none).
NeighbourPrediction HandPrediction(int w, int h, float p, float sigma_p) {
  NeighbourPrediction pred;
  pred.distance_m = Image<float>(w, h, p);
  pred.sigma_m = Image<float>(w, h, sigma_p);
  return pred;
}

TEST(Uncertainty, WithAPredictionTheNoiseTermIsTheReadingsExpectedError) {
  // Three pixels, no edges (steps within 3 combined σ), each judged against a prediction of
  // 2.00 m with σ_p 1 cm:
  //  - a quiet reading (σ 1 cm) 8 cm off the prediction: gain 1/2, m = 4 cm, v = 0.5e-4:
  //    u = sqrt(16e-4 + 0.5e-4) = 4.06 cm: kept at 5 cm (ΔL alone: 1 cm);
  //  - the same but 12 cm off: m = 6 cm, u = 6.04 cm: flagged (ΔL alone would keep it);
  //  - a noisy reading (σ 8 cm) 2 cm off: gain 64/65, m = 1.97 cm, v = 0.985e-4: u = 2.21 cm:
  //    kept (ΔL alone: 8 cm, flagged).
  const MetricFrame f = Pixels({2.08f, 2.12f, 2.02f}, {0.01f, 0.01f, 0.08f});
  UncertaintyOptions o;
  o.min_jump_sigma = 100.0;  // no edge terms: only the noise term is tested
  const NeighbourPrediction p = HandPrediction(3, 1, 2.0f, 0.01f);
  const Image<float> u = ComputeUncertainty(f, o, &p);
  const auto expected = [](double d, double s, double sp) {
    const double gain = s * s / (s * s + sp * sp);
    const double m = (d - 2.0) * gain;
    return std::sqrt(m * m + sp * sp * gain);
  };
  // Float readings (2.08f is 2.08 within 5e-8): 1e-6 m.
  EXPECT_NEAR(u[0], expected(2.08f, 0.01f, 0.01f), 1e-6);
  EXPECT_NEAR(u[1], expected(2.12f, 0.01f, 0.01f), 1e-6);
  EXPECT_NEAR(u[2], expected(2.02f, 0.08f, 0.01f), 1e-6);
  const Image<PixelFlags> flags = UncertaintyFilter(f, o, &p);
  EXPECT_FALSE(flags[0].Has(Flag::kLowConfidence));
  EXPECT_TRUE(flags[1].Has(Flag::kLowConfidence));
  EXPECT_FALSE(flags[2].Has(Flag::kLowConfidence));
  // Without the prediction, ΔL decides: the reverse for the last two.
  const Image<PixelFlags> plain = UncertaintyFilter(f, o);
  EXPECT_FALSE(plain[1].Has(Flag::kLowConfidence));
  EXPECT_TRUE(plain[2].Has(Flag::kLowConfidence));
  // judge_combination: the combination's σ, sqrt(v), whatever the residual.
  o.judge_combination = true;
  const Image<float> uc = ComputeUncertainty(f, o, &p);
  EXPECT_NEAR(uc[1], std::sqrt(0.5e-4), 1e-6);
  EXPECT_NEAR(uc[2], 0.01 * std::sqrt(64.0 / 65.0), 1e-6);
  // Where there is no prediction, ΔL: the pixel's σ.
  NeighbourPrediction none = HandPrediction(3, 1, std::numeric_limits<float>::quiet_NaN(),
                                            std::numeric_limits<float>::quiet_NaN());
  o.judge_combination = false;
  const Image<float> un = ComputeUncertainty(f, o, &none);
  EXPECT_NEAR(un[2], 0.08, 1e-7);
  // Edge terms still add: a step beyond 3 combined σ next to a predicted pixel.
  o.min_jump_sigma = 3.0;
  const MetricFrame g = Pixels({2.0f, 2.0f, 3.0f}, {0.01f, 0.01f, 0.01f});
  const NeighbourPrediction q = HandPrediction(3, 1, 2.0f, 0.01f);
  const Image<float> ue = ComputeUncertainty(g, o, &q);
  EXPECT_NEAR(ue[1], std::sqrt(0.5e-4 + 0.25), 1e-6);  // v + (half the 1 m step)²
}

TEST(Uncertainty, WithoutAnyPredictedPixelThePerPixelFormGivesTheSameBits) {
  // A prediction makes every frame take the per-pixel form; where no pixel has one it must equal
  // the row form bit for bit: random frames with steps near the edge test's threshold, rejected
  // pixels and unknown-neighbour flags.
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int trial = 0; trial < 20; ++trial) {
    const int w = 3 + static_cast<int>(u(rng) * 40), h = 1 + static_cast<int>(u(rng) * 20);
    MetricFrame f = Blank(w, h);
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      f.radial_distance_m[i] = 2.0f + (u(rng) < 0.3f ? 0.5f * u(rng) : 0.02f * u(rng));
      f.delta_l_m[i] = 0.005f + 0.03f * u(rng);
      const float x = u(rng);
      if (x < 0.05f) f.flags[i].Set(Flag::kSaturated);
      if (x > 0.95f) f.flags[i].Set(Flag::kInconsistent);
    }
    UncertaintyOptions o;
    o.unknown_neighbour_flags = PixelFlags(Flag::kSaturated).bits();
    const NeighbourPrediction none = HandPrediction(w, h, std::numeric_limits<float>::quiet_NaN(),
                                                    std::numeric_limits<float>::quiet_NaN());
    const Image<float> a = ComputeUncertainty(f, o), b = ComputeUncertainty(f, o, &none);
    for (std::size_t i = 0; i < a.size(); ++i) {
      ASSERT_EQ(std::memcmp(&a[i], &b[i], sizeof(float)), 0)
          << trial << " " << i << " " << a[i] << " " << b[i];
    }
  }
}

TEST(Uncertainty, APredictionOfAnotherSizeIsRefused) {
  const MetricFrame f = Pixels({2.0f, 2.0f}, {0.01f, 0.01f});
  const NeighbourPrediction p = HandPrediction(3, 1, 2.0f, 0.01f);
  try {
    (void)ComputeUncertainty(f, {}, &p);
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  Image<PixelFlags> out;
  EXPECT_THROW(UncertaintyFilterInto(f, {}, out, &p), Error);
}

}  // namespace
}  // namespace tofcam
