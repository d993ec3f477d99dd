#include "tofcam/filters/spatial_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "tofcam/core/error.h"

namespace tofcam {
namespace {

MetricFrame Frame(int w, int h, float value) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h, value);
  f.amplitude = Image<float>(w, h, 1000.0f);
  f.flags = Image<PixelFlags>(w, h);
  return f;
}

SpatialFilterOptions Median(double max_jump_m) {
  SpatialFilterOptions o;
  o.kind = SpatialFilterKind::kMedian;
  o.max_jump_m = max_jump_m;
  return o;
}

TEST(SpatialFilterTest, MedianRemovesASpikeWithoutALimitAndKeepsItWithOne) {
  MetricFrame f = Frame(5, 5, 2.0f);
  f.radial_distance_m(2, 2) = 5.0f;
  // No range limit: the 3x3 support is eight 2.0 and one 5.0, median 2.0.
  EXPECT_FLOAT_EQ(SpatialFilter(f, Median(0.0)).radial_distance_m(2, 2), 2.0f);
  // 10 cm limit: the spike's support is itself alone (1 < min_support 3): it stays, and its
  // neighbours ignore it (their support is the 2.0 plane).
  const MetricFrame limited = SpatialFilter(f, Median(0.1));
  EXPECT_FLOAT_EQ(limited.radial_distance_m(2, 2), 5.0f);
  EXPECT_FLOAT_EQ(limited.radial_distance_m(2, 1), 2.0f);
}

TEST(SpatialFilterTest, TheLimitKeepsTheCornerOfANearObjectOnItsSurface) {
  // A near square (1 m) in the top-left 2x2 of a far wall (3 m). The near pixel (1, 1) sees 4
  // near and 5 far pixels in its 3x3 window: without a limit the median is far and the corner
  // jumps 2 m back; with the limit its support is the near surface only.
  MetricFrame f = Frame(6, 6, 3.0f);
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) f.radial_distance_m(r, c) = 1.0f;
  }
  EXPECT_FLOAT_EQ(SpatialFilter(f, Median(0.0)).radial_distance_m(1, 1), 3.0f);
  EXPECT_FLOAT_EQ(SpatialFilter(f, Median(0.1)).radial_distance_m(1, 1), 1.0f);
}

TEST(SpatialFilterTest, RejectedPixelsAreNeitherChangedNorUsed) {
  MetricFrame f = Frame(3, 3, 2.0f);
  f.radial_distance_m(0, 0) = 100.0f;
  f.flags(0, 0).Set(Flag::kHighDeltaL);
  f.radial_distance_m(1, 1) = 2.3f;
  const MetricFrame out = SpatialFilter(f, Median(0.0));
  EXPECT_FLOAT_EQ(out.radial_distance_m(0, 0), 100.0f);  // passed through
  // Centre: the 8 usable values are seven 2.0 and its own 2.3: median (lower middle) 2.0.
  EXPECT_FLOAT_EQ(out.radial_distance_m(1, 1), 2.0f);
  EXPECT_EQ(out.flags(0, 0), f.flags(0, 0));
}

TEST(SpatialFilterTest, BilateralIsTheHandComputedWeightedMean) {
  MetricFrame f = Frame(3, 1, 0.0f);
  f.radial_distance_m(0, 0) = 2.00f;
  f.radial_distance_m(0, 1) = 2.01f;
  f.radial_distance_m(0, 2) = 2.03f;
  f.delta_l_m = Image<float>(3, 1, 0.01f);
  f.delta_l_m(0, 2) = 0.02f;  // a noisier neighbour counts less
  SpatialFilterOptions o;
  o.kind = SpatialFilterKind::kBilateral;
  o.max_jump_m = 0.0;
  o.min_support = 1;
  // Centre (0, 1): k σ = 2 x 0.01 m; w_n = exp(-(d_n - 2.01)^2 / (2 * 0.02^2)) / σ_n^2.
  const double w0 = std::exp(-0.0001 / 0.0008) / 1e-4;
  const double w1 = 1.0 / 1e-4;
  const double w2 = std::exp(-0.0004 / 0.0008) / 4e-4;
  const double expected = (w0 * 2.00 + w1 * 2.01 + w2 * 2.03) / (w0 + w1 + w2);
  EXPECT_NEAR(SpatialFilter(f, o).radial_distance_m(0, 1), expected, 1e-6);
}

TEST(SpatialFilterTest, NoiseShrinksAsTheOrderStatisticsPredict) {
  // A flat wall with Gaussian noise σ: the 3x3 mean has σ/3; the median of 9 has about
  // sqrt(π / (2 * 9)) σ = 0.418 σ (asymptotic efficiency of the median; 0.41-0.45 for n = 9).
  std::mt19937 rng(2);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  MetricFrame f = Frame(200, 200, 2.0f);
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) f.radial_distance_m[i] += noise(rng);
  f.delta_l_m = Image<float>(200, 200, 0.01f);
  const auto sd = [](const MetricFrame& m) {
    double s = 0, s2 = 0;
    int n = 0;
    for (int r = 2; r < 198; ++r) {
      for (int c = 2; c < 198; ++c) {
        const double x = m.radial_distance_m(r, c) - 2.0;
        s += x;
        s2 += x * x;
        ++n;
      }
    }
    return std::sqrt(s2 / n - (s / n) * (s / n));
  };
  const double median = sd(SpatialFilter(f, Median(0.0))) / 0.01;
  EXPECT_GT(median, 0.38);
  EXPECT_LT(median, 0.47);
  SpatialFilterOptions o;
  o.kind = SpatialFilterKind::kBilateral;
  o.max_jump_m = 0.0;
  o.range_sigma_factor = 100.0;  // range weights ~1: the plain mean of 9 (correlated neighbours
                                 // do not matter for the per-pixel σ)
  EXPECT_NEAR(sd(SpatialFilter(f, o)) / 0.01, 1.0 / 3.0, 0.02);
}

// The 3x3 median by its definition, pixel by pixel: the support is every usable pixel of the
// window (finite, no reject flag) within max_jump_m of the centre (compared in single
// precision, as documented); with at least min_support of them the result is the sorted
// support's element (n - 1) / 2. Every size, window position and support pattern the frames
// below produce must give the same bits as the filter (whose interior rows run eight pixels at
// a time through a sorting network).
TEST(SpatialFilterTest, MedianEqualsTheSortedSupportForEverySizeAndPattern) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  int checked = 0, smoothed = 0;
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{
           {1, 1}, {3, 3}, {9, 4}, {10, 5}, {17, 6}, {26, 3}, {31, 7}, {160, 12}}) {
    for (const auto& [jump, min_support] :
         std::vector<std::pair<double, int>>{{0.1, 3}, {0.0, 1}, {0.25, 9}, {0.1, 5}}) {
      MetricFrame f = Frame(w, h, 0.0f);
      for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
        // Three surfaces 0.5 m apart with 0.125 m steps (exact in binary: ties, and differences
        // exactly at the 0.25 m limit), holes, rejected and inf pixels.
        const float surface = 1.0f + 0.5f * static_cast<float>(static_cast<int>(u(rng) * 3));
        f.radial_distance_m[i] =
            surface + 0.125f * static_cast<float>(static_cast<int>(u(rng) * 3));
        const float roll = u(rng);
        if (roll < 0.05f) f.radial_distance_m[i] = std::numeric_limits<float>::quiet_NaN();
        if (roll > 0.97f) f.radial_distance_m[i] = std::numeric_limits<float>::infinity();
        if (roll > 0.05f && roll < 0.12f) f.flags[i] = PixelFlags(Flag::kSaturated);
      }
      SpatialFilterOptions o = Median(jump);
      o.min_support = min_support;
      const MetricFrame out = SpatialFilter(f, o);
      const float limit =
          jump > 0.0 ? static_cast<float>(jump) : std::numeric_limits<float>::infinity();
      auto usable = [&](int r, int c) {
        const float v = f.radial_distance_m(r, c);
        return std::isfinite(v) && f.flags(r, c).Valid();
      };
      for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) {
          float expected = f.radial_distance_m(r, c);
          if (usable(r, c)) {
            std::vector<float> support;
            for (int y = std::max(0, r - 1); y <= std::min(h - 1, r + 1); ++y) {
              for (int x = std::max(0, c - 1); x <= std::min(w - 1, c + 1); ++x) {
                if (usable(y, x) &&
                    std::abs(f.radial_distance_m(y, x) - f.radial_distance_m(r, c)) <= limit) {
                  support.push_back(f.radial_distance_m(y, x));
                }
              }
            }
            if (static_cast<int>(support.size()) >= min_support) {
              std::sort(support.begin(), support.end());
              expected = support[(support.size() - 1) / 2];
              smoothed += expected != f.radial_distance_m(r, c);
            }
          }
          const float got = out.radial_distance_m(r, c);
          ASSERT_EQ(std::memcmp(&got, &expected, sizeof got), 0)
              << w << "x" << h << " jump " << jump << " min " << min_support << " at (" << r << ", "
              << c << "): " << got << " vs " << expected;
          ++checked;
        }
      }
    }
  }
  EXPECT_GT(smoothed, checked / 10);  // the frames exercise the median, not only copies
}

// The bilateral by its definition, pixel by pixel, in double precision with std::exp and a
// division by σ_n² (the filter's scalar form before its offset passes were vectorised, up to
// where it multiplied by 1 / (2 (k σ)²) instead of dividing): the
// support is every usable pixel of the (2 r + 1)² window within max_jump_m of the centre
// (single precision), each weighted exp(-(d_n - d)² / (2 (k σ)²)) / σ_n², σ = ΔL where finite
// and positive, else fallback_sigma_m. The filter computes e^x with its own polynomial and
// multiplies by 1 / σ_n², so its weights may differ from these by a few units in the last place
// of a double (1e-15 relative); the mean, rounded to float, can then differ only where it lies
// within that of a float rounding boundary: by one float ulp at most. Every size, radius, window
// position and support pattern below must agree to that; σ from 0.5 mm to 20 cm against steps
// of up to 0.5 m puts the exponent anywhere from 0 to beyond e^-700 (a zero weight).
TEST(SpatialFilterTest, BilateralEqualsItsDefinitionForEverySizeAndPattern) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  long long checked = 0, smoothed = 0, smoothed_exact = 0;
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{
           {1, 1}, {2, 5}, {3, 3}, {9, 4}, {17, 6}, {31, 7}, {160, 12}}) {
    for (int radius = 1; radius <= 3; ++radius) {
      // The last configuration without ΔL: every pixel takes fallback_sigma_m.
      for (const auto& [jump, min_support] :
           std::vector<std::pair<double, int>>{{0.1, 3}, {0.0, 1}, {0.25, 9}}) {
        MetricFrame f = Frame(w, h, 0.0f);
        f.delta_l_m = Image<float>(w, h);
        for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
          const float surface = 1.0f + 0.5f * static_cast<float>(static_cast<int>(u(rng) * 3));
          f.radial_distance_m[i] = surface + 0.05f * u(rng);
          const float roll = u(rng);
          if (roll < 0.04f) f.radial_distance_m[i] = std::numeric_limits<float>::quiet_NaN();
          if (roll > 0.98f) f.radial_distance_m[i] = std::numeric_limits<float>::infinity();
          if (roll > 0.04f && roll < 0.1f) f.flags[i] = PixelFlags(Flag::kSaturated);
          // σ log-uniform in [0.5 mm, 20 cm]; some pixels without a usable ΔL (fallback).
          f.delta_l_m[i] = 0.0005f * std::pow(400.0f, u(rng));
          const float s_roll = u(rng);
          if (s_roll < 0.03f) f.delta_l_m[i] = std::numeric_limits<float>::quiet_NaN();
          if (s_roll > 0.97f) f.delta_l_m[i] = -0.01f;
        }
        if (min_support == 9) f.delta_l_m = Image<float>();
        SpatialFilterOptions o;
        o.kind = SpatialFilterKind::kBilateral;
        o.radius_px = radius;
        o.max_jump_m = jump;
        o.min_support = min_support;
        const MetricFrame out = SpatialFilter(f, o);
        const float limit =
            jump > 0.0 ? static_cast<float>(jump) : std::numeric_limits<float>::infinity();
        const auto usable = [&](int r, int c) {
          return std::isfinite(f.radial_distance_m(r, c)) && f.flags(r, c).Valid();
        };
        const auto sigma = [&](int r, int c) {
          const double s = f.delta_l_m.empty() ? 0.0 : f.delta_l_m(r, c);
          return std::isfinite(s) && s > 0.0 ? s : o.fallback_sigma_m;
        };
        for (int r = 0; r < h; ++r) {
          for (int c = 0; c < w; ++c) {
            float expected = f.radial_distance_m(r, c);
            bool mean = false;
            if (usable(r, c)) {
              const double dc = f.radial_distance_m(r, c);
              const double ks = o.range_sigma_factor * sigma(r, c);
              int n = 0;
              double weight_sum = 0.0, weighted = 0.0;
              for (int y = std::max(0, r - radius); y <= std::min(h - 1, r + radius); ++y) {
                for (int x = std::max(0, c - radius); x <= std::min(w - 1, c + radius); ++x) {
                  if (!usable(y, x) ||
                      !(std::abs(f.radial_distance_m(y, x) - f.radial_distance_m(r, c)) <= limit)) {
                    continue;
                  }
                  const double dn = f.radial_distance_m(y, x), sn = sigma(y, x);
                  const double weight =
                      std::exp(-(dn - dc) * (dn - dc) / (2.0 * ks * ks)) / (sn * sn);
                  weight_sum += weight;
                  weighted += weight * dn;
                  ++n;
                }
              }
              if (n >= min_support) {
                expected = static_cast<float>(weighted / weight_sum);
                mean = true;
              }
            }
            const float got = out.radial_distance_m(r, c);
            const bool same = std::memcmp(&got, &expected, sizeof got) == 0;
            smoothed += mean;
            smoothed_exact += mean && same;
            ASSERT_TRUE(same ||
                        std::abs(got - expected) <= std::nextafter(expected, 1e30f) - expected)
                << w << "x" << h << " r " << radius << " jump " << jump << " min " << min_support
                << " at (" << r << ", " << c << "): " << got << " vs " << expected;
            ++checked;
          }
        }
      }
    }
  }
  EXPECT_GT(smoothed, checked / 2);  // the frames exercise the weighted mean, not only copies
  // How many weighted means were the definition's bit for bit (all of them on the machine the
  // filter was written on; the assertion above is the one-ulp bound).
  RecordProperty("smoothed", static_cast<int>(smoothed));
  RecordProperty("smoothed_bit_identical", static_cast<int>(smoothed_exact));
}

TEST(SpatialFilterTest, BadOptionsAndSizes) {
  MetricFrame f = Frame(3, 3, 1.0f);
  SpatialFilterOptions o;
  o.radius_px = 0;
  EXPECT_THROW((void)SpatialFilter(f, o), Error);
  o = {};
  o.max_jump_m = std::nan("");
  EXPECT_THROW((void)SpatialFilter(f, o), Error);
  o = {};
  f.delta_l_m = Image<float>(2, 2);
  EXPECT_THROW((void)SpatialFilter(f, o), Error);
  EXPECT_THROW((void)ParseSpatialFilterKind("gauss"), Error);
  EXPECT_EQ(ParseSpatialFilterKind(SpatialFilterKindName(SpatialFilterKind::kBilateral)),
            SpatialFilterKind::kBilateral);
}

}  // namespace
}  // namespace tofcam
