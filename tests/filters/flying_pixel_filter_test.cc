#include "tofcam/filters/flying_pixel_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "filter_internal.h"    // internal: FlyingPixelInto (src/filters)
#include "test_scene.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// 11 x 3 image: columns 0-4 near (1 m, bright), column 5 a mixed pixel half-way (2 m),
// columns 6-10 far (3 m, dark). Amplitude falls with 1/d² as the physics would have it.
MetricFrame EdgeFrame() {
  MetricFrame f;
  f.radial_distance_m = Image<float>(11, 3);
  f.amplitude = Image<float>(11, 3);
  f.flags = Image<PixelFlags>(11, 3);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 11; ++c) {
      const float d = c < 5 ? 1.0f : (c == 5 ? 2.0f : 3.0f);
      f.radial_distance_m(r, c) = d;
      f.amplitude(r, c) = 9000.0f / (d * d);
    }
  }
  return f;
}

TEST(FlyingPixelFilterTest, FlagsMixedPixelBetweenSurfacesOnly) {
  const MetricFrame f = EdgeFrame();
  const Image<PixelFlags> out = FlyingPixelFilter(f, {});
  // Column 5: d - dmin = 1 m > 0.05, dmax - d = 1 m > 0.03, max 1 m > 0.1, and the window's
  // amplitudes (9000, 2250, 1000) have std/mean far above 0.05. Columns 4 and 6 sit at the
  // window minimum / maximum themselves, so one of the two distance tests fails.
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 11; ++c) {
      EXPECT_EQ(out(r, c).Has(Flag::kFlyingPixel), c == 5) << r << "," << c;
      EXPECT_EQ(out(r, c).bits() & ~static_cast<std::uint16_t>(Flag::kFlyingPixel), 0);
    }
  }
}

TEST(FlyingPixelFilterTest, NeedsAmplitudeContrast) {
  // Same geometry with a flat amplitude: std/mean = 0 < 0.05, so the edge is not "edge-aware"
  // confirmed and nothing is flagged.
  MetricFrame f = EdgeFrame();
  f.amplitude.Fill(3000.0f);
  const Image<PixelFlags> out = FlyingPixelFilter(f, {});
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(out[i].None()) << i;
  // The floor on the mean: amplitudes 0.9 / 0.225 / 0.1 have a large relative spread but a
  // std of ~0.35, far below 0.05 x the floor of 50, so nothing is flagged either.
  MetricFrame dim = EdgeFrame();
  for (std::size_t i = 0; i < dim.amplitude.size(); ++i) dim.amplitude[i] *= 1e-4f;
  const Image<PixelFlags> out2 = FlyingPixelFilter(dim, {});
  for (std::size_t i = 0; i < out2.size(); ++i) EXPECT_TRUE(out2[i].None()) << i;
}

TEST(FlyingPixelFilterTest, IgnoresRejectedPixels) {
  // With the far side rejected, the mixed pixel has no farther neighbour left: dmax = d.
  MetricFrame f = EdgeFrame();
  for (int r = 0; r < 3; ++r) {
    for (int c = 6; c < 11; ++c) f.flags(r, c) = Flag::kLowAmplitude;
  }
  Image<PixelFlags> out = FlyingPixelFilter(f, {});
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(out[i].None()) << i;
  // A rejected pixel itself is not judged.
  MetricFrame g = EdgeFrame();
  for (int r = 0; r < 3; ++r) g.flags(r, 5) = Flag::kSaturated;
  out = FlyingPixelFilter(g, {});
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(out[i].None()) << i;
}

TEST(FlyingPixelFilterTest, SmoothSceneKeepsInteriorPixels) {
  // On the plane-and-box scene only pixels at the box outline may be flagged.
  const test::Scene s = test::MakeScene();
  const Image<PixelFlags> out = FlyingPixelFilter(s.frame, {});
  for (int r = 1; r + 1 < s.frame.height(); ++r) {
    for (int c = 1; c + 1 < s.frame.width(); ++c) {
      bool mixed_window = false;
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) mixed_window |= s.on_box(r + dr, c + dc) != s.on_box(r, c);
      }
      if (!mixed_window) {
        EXPECT_FALSE(out(r, c).Has(Flag::kFlyingPixel)) << r << "," << c;
      }
    }
  }
}

// The rule of the header evaluated literally per pixel, in double, over the usable pixels of the
// window. 1 / 0 = flagged or not; -1 = within 1e-4 (relative) of a threshold, where float and
// double may legitimately disagree.
int ReferenceRule(const MetricFrame& f, int r, int c, const FlyingPixelOptions& o) {
  auto usable = [&](int y, int x) {
    return std::isfinite(f.radial_distance_m(y, x)) && std::isfinite(f.amplitude(y, x)) &&
           (f.flags(y, x).bits() & kRejectMask) == 0;
  };
  if (!usable(r, c)) return 0;
  double n = 0, sum = 0, sum2 = 0;
  double dmin = std::numeric_limits<double>::infinity(), dmax = -dmin;
  for (int y = std::max(r - 1, 0); y <= std::min(r + 1, f.height() - 1); ++y) {
    for (int x = std::max(c - 1, 0); x <= std::min(c + 1, f.width() - 1); ++x) {
      if (!usable(y, x)) continue;
      const double a = f.amplitude(y, x), d = f.radial_distance_m(y, x);
      n += 1;
      sum += a;
      sum2 += a * a;
      dmin = std::min(dmin, d);
      dmax = std::max(dmax, d);
    }
  }
  const double d = f.radial_distance_m(r, c);
  const double to_min = d - dmin, to_max = dmax - d;
  const double var = std::max(sum2 / n - (sum / n) * (sum / n), 0.0);
  const double contrast = std::sqrt(var) / std::max(sum / n, o.amplitude_mean_floor);
  const double margins[] = {contrast / o.min_amplitude_contrast - 1.0, to_min - o.min_close_delta_m,
                            to_max - o.min_far_delta_m,
                            std::max(to_min, to_max) - o.min_max_delta_m,
                            0.5 * (to_min + to_max) - o.min_avg_delta_m};
  bool all = true;
  bool near = false;
  for (int k = 0; k < 5; ++k) {
    // Contrast exactly at its threshold counts as passing (>=); the distance tests are strict.
    const bool pass = k == 0 ? margins[k] >= 0 : margins[k] > 0;
    all &= pass;
    near |= std::abs(margins[k]) < 1e-4;
  }
  return near ? -1 : (all ? 1 : 0);
}

MetricFrame BlankFrame(int w, int h) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h);
  f.amplitude = Image<float>(w, h);
  f.flags = Image<PixelFlags>(w, h);
  return f;
}

// Expects the filter's output to equal the rule at every pixel not within rounding of a
// threshold; returns the rule's verdict per pixel (row-major; -1 near a threshold).
std::vector<int> ExpectMatchesRule(const MetricFrame& f, const FlyingPixelOptions& o) {
  const Image<PixelFlags> out = FlyingPixelFilter(f, o);
  std::vector<int> verdicts;
  for (int r = 0; r < f.height(); ++r) {
    for (int c = 0; c < f.width(); ++c) {
      const int expected = ReferenceRule(f, r, c, o);
      verdicts.push_back(expected);
      if (expected >= 0) {
        EXPECT_EQ(out(r, c).Has(Flag::kFlyingPixel), expected == 1) << r << "," << c;
      }
    }
  }
  return verdicts;
}

TEST(FlyingPixelFilterTest, MatchesTheRuleOnNoisyFramesWithFewAndManyCandidates) {
  // 97 x 61 (odd sizes: no row is a multiple of the vector width). Top rows: a plane with
  // millimetre noise and a step edge (few candidates per row, tested one by one); bottom rows:
  // 10 cm noise over 1-4 m (a candidate at many pixels, the row tested whole). Random rejected
  // pixels, NaN and infinite distances and amplitudes throughout.
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const int w = 97, h = 61;
  MetricFrame f = BlankFrame(w, h);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      float d = 0.0f;
      if (r < h / 2) {
        d = (c < w / 2 ? 1.5f : 2.5f) + 0.002f * noise(rng);
      } else {
        d = 1.0f + 3.0f * u(rng) * 0.5f + 0.1f * noise(rng);
      }
      // Top rows: a mixed pixel half-way across the step on every other row; in the rows
      // of blocks 12k..12k+5 the amplitude is flat (no contrast: candidates that must fail),
      // elsewhere 1/d².
      const bool top = r < h / 2 - 2;
      if (top && c == w / 2 && r % 2 == 0) d = 2.0f;
      f.radial_distance_m(r, c) = d;
      f.amplitude(r, c) = top && (r / 6) % 2 == 0 ? 1000.0f * (1.0f + 0.002f * noise(rng))
                                                  : 4000.0f / (d * d) * (1.0f + 0.2f * noise(rng));
      const float x = top && c == w / 2 ? 1.0f : u(rng);
      if (x < 0.03f) f.radial_distance_m(r, c) = std::numeric_limits<float>::quiet_NaN();
      if (x > 0.03f && x < 0.04f) f.amplitude(r, c) = std::numeric_limits<float>::infinity();
      if (x > 0.04f && x < 0.10f) f.flags(r, c) = Flag::kHighDeltaL;
    }
  }
  const std::vector<int> verdicts = ExpectMatchesRule(f, FlyingPixelOptions{});
  int flagged_top = 0, flagged_bottom = 0, compared = 0, candidates_top = 0;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const int expected = verdicts[static_cast<std::size_t>(r * w + c)];
      if (expected < 0) continue;
      ++compared;
      (r < h / 2 - 2 ? flagged_top : flagged_bottom) += expected;
      candidates_top += r < h / 2 - 2 && c == w / 2 && r % 2 == 0;
    }
  }
  // Both regimes really occur (the test would prove little otherwise).
  EXPECT_GT(compared, w * h * 99 / 100);
  EXPECT_GT(flagged_top, 0);
  EXPECT_LT(flagged_top, candidates_top);  // some top candidates fail the contrast test
  EXPECT_GT(flagged_bottom, w * (h / 2) / 10);
}

TEST(FlyingPixelFilterTest, MatchesTheRuleWhenEveryRowHasManyCandidatesAtEvenAndOddHeights) {
  // Every row noisy (10 cm over 1-4 m): after the first row the filter decides rows two at a
  // time. With 40 rows the last row is decided alone; with 41 the last pair has the neutral row
  // below it. Both must equal the rule everywhere, edges included.
  for (const int h : {40, 41}) {
    SCOPED_TRACE(h);
    std::mt19937 rng(static_cast<unsigned>(h));
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::normal_distribution<float> noise(0.0f, 1.0f);
    const int w = 53;
    MetricFrame f = BlankFrame(w, h);
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        const float d = 1.0f + 1.5f * u(rng) + 0.1f * noise(rng);
        f.radial_distance_m(r, c) = d;
        f.amplitude(r, c) = 4000.0f / (d * d) * (1.0f + 0.2f * noise(rng));
        const float x = u(rng);
        if (x < 0.02f) f.radial_distance_m(r, c) = std::numeric_limits<float>::quiet_NaN();
        if (x > 0.02f && x < 0.06f) f.flags(r, c) = Flag::kHighDeltaL;
      }
    }
    const std::vector<int> verdicts = ExpectMatchesRule(f, FlyingPixelOptions{});
    int compared = 0;
    int flagged_first = 0, flagged_last = 0, flagged = 0;
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        const int expected = verdicts[static_cast<std::size_t>(r * w + c)];
        if (expected < 0) continue;
        ++compared;
        flagged += expected;
        flagged_first += r == 0 ? expected : 0;
        flagged_last += r == h - 1 ? expected : 0;
      }
    }
    EXPECT_GT(compared, w * h * 99 / 100);
    // Many candidates in every row, flagged ones in the first and last rows too.
    EXPECT_GT(flagged, w * h / 10);
    EXPECT_GT(flagged_first, 0);
    EXPECT_GT(flagged_last, 0);
  }
}

TEST(FlyingPixelFilterTest, PortableAndAvx512FormsGiveTheSameFlags) {
  // AVX-512 CPUs run the rule down 16-pixel column strips (masked loads and stores at the row's
  // end and edges), in bands of rows on large frames; other CPUs prepare rows and decide rows
  // with many candidates two at a time (8 pixels a step; GCC's clones). Every width from 1 to 70
  // (every remainder of both block sizes), the SR-2's 160 and one frame large enough (263 x 211)
  // that the strips run in bands of 104, 104 and 3 rows and the row preparation prefetches the
  // next row; two noisy rows, then a flat one (its candidates, if any, tested one by one when
  // the row is decided alone), NaN, infinite, rejected and ±0 pixels. In both forms the flags must
  // equal the rule, and the bits echoed into a second image (what FilterSet's later filters
  // see) must equal the flags, also when that image is the prior; the two forms must agree bit
  // for bit.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const bool avx512 = internal::CpuHasAvx512();
  int flagged = 0;
  std::vector<std::pair<int, int>> sizes;
  for (int w = 1; w <= 70; ++w) sizes.emplace_back(w, 3 + w % 5);
  sizes.emplace_back(160, 7);
  sizes.emplace_back(263, 211);
  for (const auto& [w, h] : sizes) {
    SCOPED_TRACE(testing::Message() << w << " x " << h);
    MetricFrame f = BlankFrame(w, h);
    for (int r = 0; r < h; ++r) {
      const bool noisy = r % 3 != 1;
      for (int c = 0; c < w; ++c) {
        const float d = noisy ? 1.0f + 1.5f * u(rng) + 0.1f * noise(rng)
                              : (c < w / 2 ? 1.5f : 2.5f) + 0.002f * noise(rng);
        f.radial_distance_m(r, c) = d;
        f.amplitude(r, c) = 4000.0f / (d * d) * (1.0f + 0.2f * noise(rng));
        const float x = u(rng);
        if (x < 0.02f) f.radial_distance_m(r, c) = std::numeric_limits<float>::quiet_NaN();
        if (x > 0.02f && x < 0.03f) f.amplitude(r, c) = -std::numeric_limits<float>::infinity();
        if (x > 0.03f && x < 0.07f) f.flags(r, c) = Flag::kHighDeltaL;
        // Zeros of both signs, where the forms' sums and extremes could differ in a zero's sign
        // (the AVX-512 form adds an unusable pixel's 0 by masking: AcrossRow16).
        if (x > 0.07f && x < 0.09f) f.amplitude(r, c) = c % 2 == 0 ? 0.0f : -0.0f;
        if (x > 0.09f && x < 0.10f) f.radial_distance_m(r, c) = c % 2 == 0 ? -0.0f : 0.0f;
      }
    }
    // The filter in one form: its flags, after checking them against the rule and the echo.
    auto run = [&](bool portable) {
      const internal::PortableFormsForTesting forms(portable);
      ExpectMatchesRule(f, FlyingPixelOptions{});
      Image<PixelFlags> out(w, h), echo(w, h);
      filters_internal::FlyingPixelInto(f, f.flags, FlyingPixelOptions{}, out, &echo);
      for (std::size_t i = 0; i < out.size(); ++i) {
        EXPECT_EQ(echo[i].bits(), out[i].bits() & static_cast<std::uint16_t>(Flag::kFlyingPixel))
            << i;
      }
      // The echo image as the prior too, as FilterSet passes them: the same flags (a bit echoed
      // too early would reject a neighbour's pixel), and the prior's bits plus the raised ones.
      Image<PixelFlags> shared = f.flags, out_shared(w, h);
      filters_internal::FlyingPixelInto(f, shared, FlyingPixelOptions{}, out_shared, &shared);
      for (std::size_t i = 0; i < out.size(); ++i) {
        EXPECT_EQ(out_shared[i].bits(), out[i].bits()) << i;
        EXPECT_EQ(shared[i].bits(), f.flags[i].bits() | out[i].bits()) << i;
      }
      return out;
    };
    const Image<PixelFlags> portable = run(true);
    const Image<PixelFlags> fast = run(false);
    for (std::size_t i = 0; i < fast.size(); ++i) {
      ASSERT_EQ(fast[i].bits(), portable[i].bits()) << i;
      flagged += fast[i].Has(Flag::kFlyingPixel);
    }
  }
  EXPECT_GT(flagged, 100);  // the comparison is not between two empty images
  if (!avx512) GTEST_SKIP() << "no AVX-512 on this CPU: only the portable form was compared";
}

TEST(FlyingPixelFilterTest, ErrorsAreReported) {
  MetricFrame f = EdgeFrame();
  FlyingPixelOptions bad;
  bad.amplitude_mean_floor = 0.0;
  EXPECT_THROW(bad.Validate(), Error);
  bad = {};
  bad.min_close_delta_m = -1.0;
  EXPECT_THROW((void)FlyingPixelFilter(f, bad), Error);
  f.amplitude = Image<float>();
  try {
    (void)FlyingPixelFilter(f, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
}

}  // namespace
}  // namespace tofcam
