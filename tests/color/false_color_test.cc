#include "tofcam/color/false_color.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <random>

#include "color/false_color_internal.h"  // internal: one row of the law (src/color)
#include "core/avx512_forms.h"           // internal: the portable / AVX-512 switch (src/core)
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

// Textbook HSV -> RGB (sector form, hue in degrees), written independently of the colour law's
// closed form; channels rounded half up.
Rgb8 Hsv(double h, double s, double v) {
  h = std::fmod(std::fmod(h, 360.0) + 360.0, 360.0);
  const double c = v * s;
  const double x = c * (1.0 - std::abs(std::fmod(h / 60.0, 2.0) - 1.0));
  const double m = v - c;
  double r = 0, g = 0, b = 0;
  switch (static_cast<int>(h / 60.0)) {
    case 0:
      r = c, g = x;
      break;
    case 1:
      r = x, g = c;
      break;
    case 2:
      g = c, b = x;
      break;
    case 3:
      g = x, b = c;
      break;
    case 4:
      r = x, b = c;
      break;
    default:
      r = c, b = x;
      break;
  }
  auto q = [&](double u) { return static_cast<std::uint8_t>(std::floor((u + m) * 255.0 + 0.5)); };
  return {q(r), q(g), q(b)};
}

MetricFrame Frame(std::vector<float> d) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(static_cast<int>(d.size()), 1);
  for (std::size_t i = 0; i < d.size(); ++i) f.radial_distance_m[i] = d[i];
  f.amplitude = Image<float>(static_cast<int>(d.size()), 1, 8000.0f);
  f.flags = Image<PixelFlags>(static_cast<int>(d.size()), 1);
  f.info.modulation_frequency_hz = 20e6;
  return f;
}

TEST(FalseColorTest, PaperColoursAtKnownDistances) {
  FalseColorOptions o;
  o.near_m = 1.0;
  o.far_m = 4.0;
  // t = 0, 1/3, 1/2, 2/3, 1: hue 60° yellow, 0° red, 330°, 300° magenta, 240° blue.
  const Image<Rgb8> img = FalseColor(Frame({1.0f, 2.0f, 2.5f, 3.0f, 4.0f}), o);
  EXPECT_EQ(img[0], (Rgb8{255, 255, 0}));
  EXPECT_EQ(img[1], (Rgb8{255, 0, 0}));
  EXPECT_EQ(img[2], (Rgb8{255, 0, 128}));  // B = 0.5 -> 127.5 rounds up
  EXPECT_EQ(img[3], (Rgb8{255, 0, 255}));
  EXPECT_EQ(img[4], (Rgb8{0, 0, 255}));
}

TEST(FalseColorTest, MatchesTextbookHsvAlongTheRange) {
  FalseColorOptions o;
  o.near_m = 0.5;
  o.far_m = 6.5;
  std::vector<float> d;
  for (int i = 0; i <= 600; ++i) d.push_back(0.5f + 0.01f * static_cast<float>(i));
  const Image<Rgb8> img = FalseColor(Frame(d), o);
  for (std::size_t i = 0; i < d.size(); ++i) {
    const double t = (d[i] - 0.5) / 6.0;
    const Rgb8 want = Hsv(60.0 - 180.0 * t, 1.0, 1.0);
    // The stage computes in float, the reference in double: a channel exactly at .5 may round
    // either way, so allow one level.
    EXPECT_LE(std::abs(img[i].r - want.r), 1) << d[i];
    EXPECT_LE(std::abs(img[i].g - want.g), 1) << d[i];
    EXPECT_LE(std::abs(img[i].b - want.b), 1) << d[i];
  }
}

TEST(FalseColorTest, DefaultRangeIsZeroToL) {
  const double l = UnambiguousRangeM(20e6);
  const Image<Rgb8> img =
      FalseColor(Frame({0.0f, static_cast<float>(l / 2), static_cast<float>(l)}), {});
  EXPECT_EQ(img[0], (Rgb8{255, 255, 0}));
  EXPECT_LE(std::abs(img[1].b - 128), 1);  // float t of L/2 may be 0.5 - 1 ulp
  EXPECT_EQ(img[1].r, 255);
  EXPECT_EQ(img[2], (Rgb8{0, 0, 255}));
}

TEST(FalseColorTest, RejectedNonFiniteAndOutOfRangePixels) {
  MetricFrame f = Frame({2.0f, 2.0f, std::nanf(""), 0.2f, 9.0f});
  f.flags[1] = Flag::kHighDeltaL;
  FalseColorOptions o;
  o.near_m = 1.0;
  o.far_m = 4.0;
  Image<Rgb8> img = FalseColor(f, o);
  EXPECT_EQ(img[0], (Rgb8{255, 0, 0}));
  EXPECT_EQ(img[1], (Rgb8{0, 0, 0}));
  EXPECT_EQ(img[2], (Rgb8{0, 0, 0}));
  EXPECT_EQ(img[3], (Rgb8{255, 255, 0}));  // clamped to near: fixed range, no equalisation
  EXPECT_EQ(img[4], (Rgb8{0, 0, 255}));
  o.out_of_range_black = true;
  img = FalseColor(f, o);
  EXPECT_EQ(img[3], (Rgb8{0, 0, 0}));
  EXPECT_EQ(img[4], (Rgb8{0, 0, 0}));
  // A truth-only bit does not blacken a pixel.
  f.flags[0] = Flag::kMultipath;
  EXPECT_EQ(FalseColor(f, o)[0], (Rgb8{255, 0, 0}));
}

TEST(FalseColorTest, FixedRangeDoesNotDependOnOtherPixels) {
  FalseColorOptions o;
  o.near_m = 1.0;
  o.far_m = 4.0;
  const Image<Rgb8> a = FalseColor(Frame({2.0f, 2.1f}), o);
  const Image<Rgb8> b = FalseColor(Frame({2.0f, 3.9f}), o);
  EXPECT_EQ(a[0], b[0]);
}

TEST(FalseColorTest, AmplitudeShadingLaw) {
  MetricFrame f = Frame({1.0f, 1.0f, 1.0f, 1.0f});
  f.amplitude[0] = 8000.0f;   // V = 1
  f.amplitude[1] = 2000.0f;   // V = 0.25 + 0.75 * sqrt(1/4) = 0.625
  f.amplitude[2] = 0.0f;      // V = 0.25
  f.amplitude[3] = 32000.0f;  // capped at V = 1
  FalseColorOptions o;
  o.near_m = 1.0;
  o.far_m = 4.0;
  o.amplitude_shading = true;
  const Image<Rgb8> img = FalseColor(f, o);
  EXPECT_EQ(img[0], (Rgb8{255, 255, 0}));
  EXPECT_EQ(img[1], (Rgb8{159, 159, 0}));  // 0.625 * 255 = 159.375
  EXPECT_EQ(img[2], (Rgb8{64, 64, 0}));    // 0.25 * 255 = 63.75
  EXPECT_EQ(img[3], (Rgb8{255, 255, 0}));
}

TEST(FalseColorTest, EveryPixelFollowsTheLawOnWideRandomFrames) {
  // 53 x 3 pixels (rows of several vector widths plus a tail) with distances inside and outside
  // the range, NaN, ±inf, rejected pixels and amplitudes including NaN and negatives; shading and
  // black-outside on and off. Reference: the law of the header in double. Channels may differ by
  // 1 where the float evaluation of t rounds across a half; invisible pixels are exactly black.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const int w = 53, h = 3;
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h);
  f.amplitude = Image<float>(w, h);
  f.flags = Image<PixelFlags>(w, h);
  f.info.modulation_frequency_hz = 20e6;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    const float x = u(rng);
    f.radial_distance_m[i] = x < 0.05f   ? nan
                             : x < 0.08f ? inf
                             : x < 0.1f  ? -inf
                                         : -1.0f + 10.0f * u(rng);
    const float y = u(rng);
    f.amplitude[i] = y < 0.05f ? nan : y < 0.1f ? -5.0f : 12000.0f * u(rng);
    if (u(rng) < 0.1f) f.flags[i] = Flag::kSaturated;
  }
  for (const bool shade : {false, true}) {
    for (const bool black : {false, true}) {
      FalseColorOptions o;
      o.near_m = 0.5;
      o.far_m = 6.0;
      o.amplitude_shading = shade;
      o.out_of_range_black = black;
      const Image<Rgb8> img = FalseColor(f, o);
      int visible_count = 0;
      for (std::size_t i = 0; i < img.size(); ++i) {
        const double d = f.radial_distance_m[i];
        const double t_raw = (d - o.near_m) / (o.far_m - o.near_m);
        const bool in_range = t_raw >= 0.0 && t_raw <= 1.0;
        const bool visible = std::isfinite(d) && f.flags[i].bits() == 0 && (in_range || !black);
        if (!visible) {
          EXPECT_EQ(img[i], (Rgb8{0, 0, 0})) << i;
          continue;
        }
        ++visible_count;
        const double t = std::clamp(t_raw, 0.0, 1.0);
        const double a = std::isnan(f.amplitude[i]) ? 0.0 : std::max<double>(f.amplitude[i], 0.0);
        const double v = shade ? o.shading_min_value +
                                     (1.0 - o.shading_min_value) *
                                         std::min(1.0, std::sqrt(a / o.shading_reference_amplitude))
                               : 1.0;
        auto q = [&](double c) { return std::floor(255.0 * v * std::clamp(c, 0.0, 1.0) + 0.5); };
        EXPECT_NEAR(img[i].r, q(3.0 - 3.0 * t), 1.0) << i;
        EXPECT_NEAR(img[i].g, q(1.0 - 3.0 * t), 1.0) << i;
        EXPECT_NEAR(img[i].b, q(3.0 * t - 1.0), 1.0) << i;
      }
      EXPECT_GT(visible_count, w * h / 4);  // about 40 % with black outside
    }
  }
}

TEST(FalseColorTest, Avx512AndPortableFormsGiveTheSameBytes) {
  // Rows of every width from 1 to 40 (every tail of a 16-pixel block) and a camera's 160, with
  // the special values of the test above and distances that put 3t - 1 and 1 - 3t near 0 and
  // 3 - 3t near 1, where a clamp on the wrong side would show; all four option combinations.
  // On an AVX-512 CPU the default form is the 16-pixel kernel; it must give the portable forms'
  // bytes exactly (the colours of a frame do not depend on the CPU).
  const bool avx512 = internal::CpuHasAvx512();
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<int> widths;
  for (int w = 1; w <= 40; ++w) widths.push_back(w);
  widths.push_back(160);
  int lit = 0;
  for (const int w : widths) {
    const int h = 2 + w % 3;
    MetricFrame f;
    f.radial_distance_m = Image<float>(w, h);
    f.amplitude = Image<float>(w, h);
    f.flags = Image<PixelFlags>(w, h);
    f.info.modulation_frequency_hz = 20e6;
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      const float x = u(rng);
      // t = 1/3 and t = 0 (near = 0.5, far = 6.5, so d = 2.5 and 0.5), nudged by a few ulps.
      const float knee = (x < 0.6f ? 2.5f : 0.5f) * (1.0f + 1e-7f * std::floor(8.0f * u(rng) - 4));
      f.radial_distance_m[i] = x < 0.04f   ? nan
                               : x < 0.06f ? inf
                               : x < 0.08f ? -inf
                               : x < 0.3f  ? knee
                               : x < 0.35f ? -0.0f
                                           : -1.0f + 9.0f * u(rng);
      const float y = u(rng);
      f.amplitude[i] = y < 0.05f ? nan : y < 0.1f ? -5.0f : y < 0.15f ? inf : 12000.0f * u(rng);
      if (u(rng) < 0.1f) f.flags[i] = Flag::kSaturated;
    }
    for (const bool shade : {false, true}) {
      for (const bool black : {false, true}) {
        SCOPED_TRACE(testing::Message()
                     << "width " << w << ", shading " << shade << ", black " << black);
        FalseColorOptions o;
        o.near_m = 0.5;
        o.far_m = 6.5;
        o.amplitude_shading = shade;
        o.out_of_range_black = black;
        Image<Rgb8> portable;
        {
          const internal::PortableFormsForTesting forms(true);
          portable = FalseColor(f, o);
        }
        const Image<Rgb8> fast = FalseColor(f, o);
        for (std::size_t i = 0; i < fast.size(); ++i) {
          ASSERT_EQ(fast[i], portable[i]) << "pixel " << i;
          lit += fast[i] != Rgb8{0, 0, 0};
        }
      }
    }
  }
  EXPECT_GT(lit, 1000);  // the comparison is not between black images
  if (!avx512) GTEST_SKIP() << "no AVX-512 on this CPU: only the portable form was compared";
}

TEST(FalseColorTest, EachFormWritesExactlyItsRowsBytes) {
  // One row of every width from 1 to 40 into a buffer with guard bytes after its 3 w bytes: both
  // forms fill the row with the same bytes and leave the guard alone (a store mask one pixel too
  // wide would write into it; inside an image it would land in the next row and be overwritten).
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 8.0f);
  constexpr std::uint8_t kGuard = 0xA5;
  for (int w = 1; w <= 40; ++w) {
    std::vector<float> d(static_cast<std::size_t>(w)), a(d.size(), 5000.0f);
    std::vector<PixelFlags> flags(d.size());
    for (float& x : d) x = u(rng);
    for (const bool shade : {false, true}) {
      SCOPED_TRACE(testing::Message() << "width " << w << ", shading " << shade);
      FalseColorOptions o;
      o.amplitude_shading = shade;
      std::vector<std::vector<std::uint8_t>> rows;
      for (const bool portable : {true, false}) {
        const internal::PortableFormsForTesting forms(portable);
        std::vector<std::uint8_t> rgb(3 * d.size() + 64, kGuard);
        color_internal::ColorRowForTesting(w, o, 7.5, d.data(), flags.data(), a.data(), rgb.data());
        for (std::size_t i = 3 * d.size(); i < rgb.size(); ++i) {
          ASSERT_EQ(rgb[i], kGuard) << "byte " << i << " past the row, portable " << portable;
        }
        rows.push_back(rgb);
      }
      EXPECT_EQ(rows[0], rows[1]);
      // The row itself was written: no colour of the law has r = g = b = 0xA5.
      EXPECT_FALSE(rows[1][0] == kGuard && rows[1][1] == kGuard && rows[1][2] == kGuard);
    }
  }
}

TEST(FalseColorTest, ErrorsAreReported) {
  FalseColorOptions o;
  o.near_m = 3.0;
  o.far_m = 2.0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.near_m = 8.0;  // beyond L = 7.49 m with far_m = 0
  EXPECT_THROW((void)FalseColor(Frame({1.0f}), o), Error);
  o = {};
  o.amplitude_shading = true;
  MetricFrame f = Frame({1.0f});
  f.amplitude = Image<float>();
  try {
    (void)FalseColor(f, o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("amplitude"), std::string::npos);
  }
  EXPECT_THROW((void)FalseColor(MetricFrame{}, {}), Error);
  o = {};
  o.far_m = 1e-39;  // 1 / (far - near) overflows a float: t would be NaN at d = 0
  EXPECT_THROW((void)FalseColor(Frame({0.0f}), o), Error);
}

TEST(LegendTest, AppendsBarTicksAndKeepsTheImage) {
  Image<Rgb8> img(160, 124, Rgb8{10, 20, 30});
  const Image<Rgb8> out = AddLegend(img, 0.0, 7.5);
  ASSERT_EQ(out.width(), 160);
  ASSERT_GT(out.height(), 124 + 8);
  for (int r = 0; r < 124; ++r)
    for (int c = 0; c < 160; ++c) ASSERT_EQ(out(r, c), img(r, c));
  // Bar (default 8 px, 2 px below the image, margins of 2 px): yellow at the left end, blue at
  // the right end, red at one third.
  const int bar_row = 124 + 2 + 4;
  EXPECT_EQ(out(bar_row, 2), (Rgb8{255, 255, 0}));
  EXPECT_EQ(out(bar_row, 157), (Rgb8{0, 0, 255}));
  const Rgb8 third = out(bar_row, 2 + 155 / 3);
  EXPECT_EQ(third.r, 255);
  EXPECT_LE(third.g + third.b, 12);  // within a pixel of pure red
  // Ticks: white pixels just under the bar at 0 m (x = 2) and at every whole metre that fits:
  // 155 px for 7.5 m is 20.7 px/m, enough for one-character labels at 1 m steps.
  const int tick_row = 124 + 2 + 8;
  int ticks = 0;
  for (int c = 0; c < 160; ++c) ticks += out(tick_row, c) == Rgb8{255, 255, 255} ? 1 : 0;
  EXPECT_EQ(ticks, 8);  // 0, 1, ..., 7 m
  EXPECT_EQ(out(tick_row, 2), (Rgb8{255, 255, 255}));
  EXPECT_EQ(out(tick_row, 2 + static_cast<int>(std::lround(155.0 / 7.5 * 4))),
            (Rgb8{255, 255, 255}));
  // Some label pixels exist below the ticks.
  int text = 0;
  for (int r = tick_row + 2; r < out.height(); ++r)
    for (int c = 0; c < 160; ++c) text += out(r, c) == Rgb8{255, 255, 255} ? 1 : 0;
  EXPECT_GT(text, 8 * 5);
}

TEST(LegendTest, ErrorsAreReported) {
  EXPECT_THROW((void)AddLegend(Image<Rgb8>(8, 8), 0.0, 1.0), Error);
  EXPECT_THROW((void)AddLegend(Image<Rgb8>(64, 8), 2.0, 1.0), Error);
  LegendOptions o;
  o.font_scale = 0;
  EXPECT_THROW((void)AddLegend(Image<Rgb8>(64, 8), 0.0, 1.0, o), Error);
}

}  // namespace
}  // namespace tofcam
