#include "tofcam/filters/denoise.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// A w x h frame at `distance` with σ = `sigma` and amplitude 1000 everywhere.
MetricFrame Flat(int w, int h, float distance, float sigma) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h, distance);
  f.amplitude = Image<float>(w, h, 1000.0f);
  f.delta_l_m = Image<float>(w, h, sigma);
  f.flags = Image<PixelFlags>(w, h);
  return f;
}

// A lens with distortion, so that the rays' normalised coordinates are not a regular grid.
RayTable DistortedRays(int w, int h) {
  CameraIntrinsics in = CameraIntrinsics::SwissRangerSr2();
  in.width = w;
  in.height = h;
  in.cx_px = (w - 1) / 2.0;
  in.cy_px = (h - 1) / 2.0;
  in.k1 = -0.2;
  in.k2 = 0.05;
  in.p1 = 0.001;
  return MakeRayTable(in);
}

// The radial distance at which each pixel's ray meets the plane n . p = c (double), σ `sigma`.
MetricFrame PlaneFrame(const RayTable& rays, const Eigen::Vector3d& n, double c, float sigma) {
  const int w = rays.x.width(), h = rays.x.height();
  MetricFrame f = Flat(w, h, 0.0f, sigma);
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    const Eigen::Vector3d r(rays.x[i], rays.y[i], rays.z[i]);
    f.radial_distance_m[i] = static_cast<float>(c / n.dot(r));
  }
  return f;
}

TEST(DenoiseTest, ACentreTakesTheInverseVarianceMeanOfItsWindow) {
  // Hand-computed: eight pixels at 2.00 m with σ 2 cm (weight 2500 m^-2) and amplitude 1000,
  // one at 2.03 m with σ 4 cm (weight 625) and amplitude 500. The centre's support is all nine
  // (0.03 m is far inside 3 sqrt(0.02² + 0.04²) = 0.134 m): Σw = 20625,
  // d = 2 + 625 x 0.03 / 20625, A = (20000 x 1000 + 625 x 500) / 20625, ΔL = 20625^-1/2.
  MetricFrame f = Flat(3, 3, 2.0f, 0.02f);
  f.radial_distance_m(0, 0) = 2.03f;
  f.delta_l_m(0, 0) = 0.04f;
  f.amplitude(0, 0) = 500.0f;
  f.intensity = Image<float>(3, 3, 3000.0f);
  f.intensity(1, 1) = 4000.0f;
  f.flags(1, 1).Set(Flag::kMixed);  // a truth bit, not a reject bit
  const MetricFrame out = Denoise(f, {});
  // Float sums of nine terms: a few float ulps (2^-24 relative) each, here ≤ 1e-6.
  EXPECT_NEAR(out.radial_distance_m(1, 1), 2.0 + 625.0 * 0.03 / 20625.0, 1e-6);
  EXPECT_NEAR(out.amplitude(1, 1), (20000.0 * 1000.0 + 625.0 * 500.0) / 20625.0, 1e-3);
  EXPECT_NEAR(out.delta_l_m(1, 1), 1.0 / std::sqrt(20625.0), 1e-8);
  // The corner (0, 0) has four pixels in its window: itself (625) and three at 2.00 m (2500).
  // Σw = 8125; as deviations from its own 2.03: d = 2.03 - 7500 x 0.03 / 8125.
  EXPECT_NEAR(out.radial_distance_m(0, 0), 2.03 - 7500.0 * 0.03 / 8125.0, 1e-6);
  EXPECT_NEAR(out.delta_l_m(0, 0), 1.0 / std::sqrt(8125.0), 1e-8);
  // Intensity and flags are copied.
  for (std::size_t i = 0; i < f.flags.size(); ++i) {
    EXPECT_EQ(out.flags[i].bits(), f.flags[i].bits()) << i;
    EXPECT_EQ(out.intensity[i], f.intensity[i]) << i;
  }
  EXPECT_TRUE(out.flags(1, 1).Has(Flag::kMixed));
}

TEST(DenoiseTest, AStepOfMoreThanKCombinedSigmaIsNotMixed) {
  // A near half (1 m) and a far half (3 m), σ 2 cm: 2 m is 70 combined σ. Every pixel's
  // support is its own half, all at the same distance: the distance stays exactly, and ΔL is
  // σ / sqrt(support): 6 pixels for a pixel on the step (not on the border rows), 9 inside.
  MetricFrame f = Flat(6, 5, 3.0f, 0.02f);
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 3; ++c) f.radial_distance_m(r, c) = 1.0f;
  }
  const MetricFrame out = Denoise(f, {});
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 6; ++c) {
      EXPECT_EQ(out.radial_distance_m(r, c), f.radial_distance_m(r, c)) << r << " " << c;
    }
  }
  EXPECT_NEAR(out.delta_l_m(2, 2), 0.02 / std::sqrt(6.0), 1e-8);
  EXPECT_NEAR(out.delta_l_m(2, 3), 0.02 / std::sqrt(6.0), 1e-8);
  EXPECT_NEAR(out.delta_l_m(2, 1), 0.02 / 3.0, 1e-8);
  // A k whose support spans the step mixes the two halves, unless max_step_m holds them apart.
  DenoiseOptions wide;
  wide.support_sigma = 100.0;  // 100 x 0.028 m = 2.8 m > 2 m
  wide.max_step_m = 0.0;       // no limit
  EXPECT_GT(Denoise(f, wide).radial_distance_m(2, 2), 1.5f);
  wide.max_step_m = 0.15;
  EXPECT_EQ(Denoise(f, wide).radial_distance_m(2, 2), 1.0f);
}

TEST(DenoiseTest, MaxStepKeepsNoisySurfacesApart) {
  // Two noisy surfaces 0.2 m apart (σ 10 cm): 3 combined σ is 0.42 m, so k alone mixes them.
  // Hand-computed for the pixel (1, 1) on the near side of a 3x3 frame whose right column is
  // far: with no step limit all nine readings (equal weights) give 1 + 3 x 0.2 / 9; with
  // 0.15 m only its own six.
  MetricFrame f = Flat(3, 3, 1.0f, 0.1f);
  for (int r = 0; r < 3; ++r) f.radial_distance_m(r, 2) = 1.2f;
  DenoiseOptions o;
  o.max_step_m = 0.0;
  EXPECT_NEAR(Denoise(f, o).radial_distance_m(1, 1), 1.0 + 3.0 * 0.2 / 9.0, 1e-6);
  o.max_step_m = 0.15;
  const MetricFrame out = Denoise(f, o);
  EXPECT_EQ(out.radial_distance_m(1, 1), 1.0f);
  EXPECT_NEAR(out.delta_l_m(1, 1), 0.1 / std::sqrt(6.0), 1e-8);
  // No limit by default.
  EXPECT_NEAR(Denoise(f, {}).radial_distance_m(1, 1), 1.0 + 3.0 * 0.2 / 9.0, 1e-6);
}

TEST(DenoiseTest, RejectedPixelsAreNeitherChangedNorUsedExceptForTheirNoise) {
  MetricFrame f = Flat(3, 3, 2.0f, 0.02f);
  // A saturated neighbour 5 cm off: not support, and copied unchanged.
  f.radial_distance_m(0, 0) = 2.05f;
  f.amplitude(0, 0) = 123.0f;
  f.flags(0, 0).Set(Flag::kSaturated);
  // A neighbour rejected only for its ΔL, 3 cm off with σ 8 cm (weight 156.25): support.
  f.radial_distance_m(0, 1) = 2.03f;
  f.delta_l_m(0, 1) = 0.08f;
  f.flags(0, 1).Set(Flag::kHighDeltaL);
  const MetricFrame out = Denoise(f, {});
  EXPECT_EQ(out.radial_distance_m(0, 0), 2.05f);
  EXPECT_EQ(out.amplitude(0, 0), 123.0f);
  EXPECT_EQ(out.delta_l_m(0, 0), 0.02f);
  // Centre: seven at 2.00 (2500 each) and the noisy one: Σw = 17656.25.
  EXPECT_NEAR(out.radial_distance_m(1, 1), 2.0 + 156.25 * 0.03 / 17656.25, 1e-6);
  EXPECT_NEAR(out.delta_l_m(1, 1), 1.0 / std::sqrt(17656.25), 1e-8);
  // The flags are the caller's to judge again (the Pipeline does).
  EXPECT_TRUE(out.flags(0, 1).Has(Flag::kHighDeltaL));
  EXPECT_LT(out.delta_l_m(0, 1), 0.08f / 2.0f);
}

TEST(DenoiseTest, PixelsWithoutAUsableReadingAreCopiedAndIgnored) {
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // Row 1 holds five pixels without a usable reading; rows 0 and 2 are a plane at 2 m.
  MetricFrame f = Flat(5, 3, 2.0f, 0.02f);
  f.radial_distance_m(1, 0) = kNan;
  f.delta_l_m(1, 1) = 0.0f;  // below 1e-9 m
  f.delta_l_m(1, 2) = 2e9f;  // above 1e9 m
  f.amplitude(1, 3) = kInf;
  f.amplitude(1, 0) = 1e16f;  // beyond 1e15 (also NaN distance)
  f.delta_l_m(1, 4) = kNan;
  const MetricFrame out = Denoise(f, {});
  EXPECT_TRUE(std::isnan(out.radial_distance_m(1, 0)));
  EXPECT_EQ(out.delta_l_m(1, 1), 0.0f);
  EXPECT_EQ(out.delta_l_m(1, 2), 2e9f);
  EXPECT_EQ(out.amplitude(1, 3), kInf);
  EXPECT_TRUE(std::isnan(out.delta_l_m(1, 4)));
  // The plane's pixels see only their own row's usable pixels: as support, a NaN or infinite
  // value would spread and a ΔL of 0 would make ΔL 0.
  for (const int r : {0, 2}) {
    for (int c = 0; c < 5; ++c) {
      const int support = (c == 0 || c == 4) ? 2 : 3;
      EXPECT_EQ(out.radial_distance_m(r, c), 2.0f) << r << " " << c;
      EXPECT_NEAR(out.amplitude(r, c), 1000.0f, 1e-3) << r << " " << c;
      EXPECT_NEAR(out.delta_l_m(r, c), 0.02 / std::sqrt(support), 1e-8) << r << " " << c;
    }
  }
}

TEST(DenoiseTest, AmplitudeIsOptional) {
  MetricFrame f = Flat(4, 4, 2.0f, 0.02f);
  f.amplitude = Image<float>();
  f.radial_distance_m(1, 1) = 2.01f;
  const MetricFrame out = Denoise(f, {});
  EXPECT_TRUE(out.amplitude.empty());
  EXPECT_NEAR(out.radial_distance_m(1, 1), 2.0 + 0.01 / 9.0, 1e-6);
}

// An independent expectation from statistics: on a plane with independent Gaussian noise σ,
// the mean of the 3x3 window has σ / 3 (k = 3 leaves out a neighbour only when two readings
// differ by 3 combined σ, P = 0.27 %, which changes that by well under 1 %). The reported ΔL is
// σ / sqrt(m) for a support of m readings.
TEST(DenoiseTest, TheNoiseFallsToTheReportedSigmaOnAPlane) {
  const int w = 200, h = 200;
  const float sigma = 0.05f;
  MetricFrame f = Flat(w, h, 3.0f, sigma);
  std::mt19937 rng(11);
  std::normal_distribution<float> noise(0.0f, sigma);
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    f.radial_distance_m[i] = 3.0f + noise(rng);
  }
  const MetricFrame out = Denoise(f, {});
  double sum = 0.0, sum2 = 0.0;
  long n = 0, full = 0;
  for (int r = 1; r + 1 < h; ++r) {
    for (int c = 1; c + 1 < w; ++c) {
      const double e = out.radial_distance_m(r, c) - 3.0;
      sum += e;
      sum2 += e * e;
      ++n;
      // ΔL is σ / sqrt(m) for a support of m readings: float sums of m equal weights and a
      // square root are within a few roundings (2^-24 relative) of it, below 1e-8 m here;
      // 1e-7 m still tells m from m ± 1 (σ / sqrt 8 - σ / 3 = 9e-4 m).
      const double m = std::round(std::pow(sigma / out.delta_l_m(r, c), 2.0));
      ASSERT_NEAR(out.delta_l_m(r, c), sigma / std::sqrt(m), 1e-7) << r << " " << c;
      full += m == 9.0;
    }
  }
  const double mean = sum / static_cast<double>(n);
  const double sd = std::sqrt(sum2 / static_cast<double>(n) - mean * mean);
  // 39,204 outputs, each sharing readings with its neighbours (about 4,400 independent windows):
  // the standard deviation is estimated to about 1 %; 5 % is 4.5 times that.
  EXPECT_NEAR(sd, sigma / 3.0, 0.05 * sigma / 3.0);
  // The mean of 39,204 outputs, about 4,400 independent windows of σ / 3 each: standard error
  // 2.5e-4 m; 1.3 mm is five of them.
  EXPECT_NEAR(mean, 0.0, 0.0013);
  // A neighbour n is in the support when |n - c| <= 3 sqrt(2) σ. The eight tests share the
  // centre's reading c, so all eight pass with P = E_c[(Φ(c/σ + 3√2) - Φ(c/σ - 3√2))^8] =
  // 0.9818 (integrated numerically over c ~ N(0, σ²); independent tests would give 0.9786).
  // Windows overlap, so an excluded reading counts in up to eight of them: the fraction over
  // 39,204 windows has a standard error of about 0.002 (the binomial 7e-4 times sqrt 8); 0.006
  // is three of them.
  EXPECT_NEAR(static_cast<double>(full) / static_cast<double>(n), 0.9818, 0.006);
}

// The file comment's definition, evaluated directly: the float support test, sums in double.
struct Reference {
  float d, a, s;
  // The plane fit's variance inflation: its σ² over the mean's, (Σ w)^-1 (1 where it is none).
  double inflation = 1.0;
};

Reference Definition(const MetricFrame& f, int row, int col, const DenoiseOptions& o) {
  const auto amplitude = [&](int r, int c) {
    return f.amplitude.empty() ? 0.0f : f.amplitude(r, c);
  };
  const auto usable = [&](int r, int c) {
    const float d = f.radial_distance_m(r, c), s = f.delta_l_m(r, c), a = amplitude(r, c);
    const auto others =
        static_cast<std::uint16_t>(kRejectMask & ~static_cast<std::uint16_t>(Flag::kHighDeltaL));
    return std::isfinite(d) && s >= 1e-9f && s <= 1e9f && std::abs(a) <= 1e15f &&
           (f.flags.empty() || (f.flags(r, c).bits() & others) == 0);
  };
  if (!usable(row, col)) {
    return {f.radial_distance_m(row, col), amplitude(row, col), f.delta_l_m(row, col)};
  }
  const float dc = f.radial_distance_m(row, col), sc = f.delta_l_m(row, col);
  const float k = static_cast<float>(o.support_sigma);
  const float k2 = k * k;
  const float step = static_cast<float>(o.max_step_m);
  double sw = 0.0, sdev = 0.0, sa = 0.0;
  for (int r = row - o.radius_px; r <= row + o.radius_px; ++r) {
    for (int c = col - o.radius_px; c <= col + o.radius_px; ++c) {
      if (r < 0 || c < 0 || r >= f.height() || c >= f.width() || !usable(r, c)) continue;
      const float dn = f.radial_distance_m(r, c), sn = f.delta_l_m(r, c);
      const float dev = dn - dc;
      if (!(dev * dev <= k2 * (sc * sc + sn * sn))) continue;
      if (o.max_step_m > 0.0 && !(dev * dev <= step * step)) continue;
      const double wn = 1.0 / (static_cast<double>(sn) * sn);
      sw += wn;
      sdev += wn * dev;
      sa += wn * amplitude(r, c);
    }
  }
  return {static_cast<float>(dc + sdev / sw), static_cast<float>(sa / sw),
          static_cast<float>(1.0 / std::sqrt(sw))};
}

// Every radius, k and step limit over frames from 1x1 to 64x5: two noisy tilted planes (near
// 1.5 and 4 m) seen through a distorted lens, σ from 5 mm to 15 cm, saturated and high-ΔL
// pixels and holes, each frame also without amplitude and flags (every flagged pixel then
// usable). For every pixel, `check(out, r, c, ref, at)` compares Denoise's output with
// `definition(f, rays, r, c, o)`.
template <typename DefinitionFn, typename Check>
void ForEveryPattern(std::uint32_t seed, bool fit_plane, DefinitionFn definition, Check check) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (const int radius : {1, 2, 3}) {
    for (const auto& [k, max_step] :
         {std::pair{0.5, 0.0}, std::pair{3.0, 0.06}, std::pair{3.0, 0.0}, std::pair{10.0, 0.05}}) {
      for (const auto& [w, h] : {std::pair{1, 1}, std::pair{7, 1}, std::pair{1, 9}, std::pair{2, 2},
                                 std::pair{37, 23}, std::pair{64, 5}}) {
        const RayTable rays = DistortedRays(w, h);
        const MetricFrame near =
            PlaneFrame(rays, Eigen::Vector3d(0.3, -0.2, 1.0).normalized(), 1.5, 0.02f);
        const MetricFrame far =
            PlaneFrame(rays, Eigen::Vector3d(-0.6, 0.1, 0.8).normalized(), 4.0, 0.02f);
        MetricFrame f = near;
        for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
          const float sigma = 0.005f + 0.145f * u(rng);
          const float surface =
              u(rng) < 0.3f ? far.radial_distance_m[i] : near.radial_distance_m[i];
          f.radial_distance_m[i] = surface + sigma * 2.0f * (u(rng) - 0.5f);
          f.delta_l_m[i] = sigma;
          f.amplitude[i] = 100.0f + 5000.0f * u(rng);
          const float x = u(rng);
          if (x < 0.05f) f.flags[i].Set(Flag::kSaturated);
          if (x > 0.9f) f.flags[i].Set(Flag::kHighDeltaL);
          if (x > 0.5f && x < 0.53f)
            f.radial_distance_m[i] = std::numeric_limits<float>::quiet_NaN();
        }
        DenoiseOptions o;
        o.radius_px = radius;
        o.support_sigma = k;
        o.max_step_m = max_step;
        o.fit_plane = fit_plane;
        for (const bool bare : {false, true}) {
          if (bare) {
            f.amplitude = Image<float>();
            f.flags = Image<PixelFlags>();
          }
          const MetricFrame out = fit_plane ? Denoise(f, rays, o) : Denoise(f, o);
          ASSERT_EQ(out.amplitude.empty(), bare);
          for (int r = 0; r < h; ++r) {
            for (int c = 0; c < w; ++c) {
              const std::string at = std::to_string(radius) + " " + std::to_string(k) + " " +
                                     std::to_string(max_step) + " " + std::to_string(w) + "x" +
                                     std::to_string(h) + " (" + std::to_string(r) + ", " +
                                     std::to_string(c) + ")";
              check(out, r, c, definition(f, rays, r, c, o), at);
            }
          }
        }
      }
    }
  }
}

TEST(DenoiseTest, EqualsItsDefinitionForEveryRadiusAndPattern) {
  ForEveryPattern(
      5, false,
      [](const MetricFrame& f, const RayTable&, int r, int c, const DenoiseOptions& o) {
        return Definition(f, r, c, o);
      },
      [](const MetricFrame& out, int r, int c, const Reference& ref, const std::string& at) {
        if (std::isnan(ref.d)) {
          EXPECT_TRUE(std::isnan(out.radial_distance_m(r, c))) << at;
          return;
        }
        // Float sums of at most 49 terms: each term's rounding is at most 2^-24 of it, so the
        // weighted deviation is off by at most 49 x 6e-8 of the largest deviation in the
        // support (below 1 m here: 3 combined σ is at most 0.64 m, and the wide k has a 5 cm
        // step limit), plus one rounding of d (below 6 m): below 4e-6 m. ΔL and the amplitude
        // likewise, relative: 49 x 6e-8 = 3e-6, here 1e-5.
        EXPECT_NEAR(out.radial_distance_m(r, c), ref.d, 4e-6) << at;
        EXPECT_NEAR(out.delta_l_m(r, c), ref.s, 1e-5 * ref.s) << at;
        if (!out.amplitude.empty()) {
          EXPECT_NEAR(out.amplitude(r, c), ref.a, 1e-5 * ref.a) << at;
        }
      });
}

TEST(DenoiseTest, AFittedPlaneIsExactOnATiltedPlaneWhereTheMeanIsNot) {
  // A plane at 4 m turned 75° about the vertical axis, seen through a distorted lens: the
  // distance changes by several cm a pixel, and is not linear in the pixel. Without noise, and
  // with k = 100 (100 combined σ of 5 cm span any step here), the support is every neighbour.
  // The plane's 1/z is affine in (u, v), so the fit returns the input itself up to float
  // rounding. The mean is off by the distance's curvature across the window inside the image
  // (about d'' / 3 per direction) and by its slope at the border, where the support is
  // lopsided (centimetres there).
  const RayTable rays = DistortedRays(40, 30);
  const double tilt = 75.0 * std::numbers::pi / 180.0;
  const Eigen::Vector3d normal(std::sin(tilt), 0.0, std::cos(tilt));
  const MetricFrame f = PlaneFrame(rays, normal, 4.0 * std::cos(tilt), 0.05f);
  DenoiseOptions plane;
  plane.support_sigma = 100.0;  // every neighbour in support, however steep the slope
  plane.fit_plane = true;
  DenoiseOptions mean = plane;
  mean.fit_plane = false;
  const MetricFrame fitted = Denoise(f, rays, plane);
  const MetricFrame averaged = Denoise(f, rays, mean);
  double worst_plane = 0.0, worst_mean = 0.0;
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    const double d = f.radial_distance_m[i];
    worst_plane = std::max(worst_plane, std::abs(fitted.radial_distance_m[i] - d) / d);
    worst_mean = std::max(worst_mean, std::abs(averaged.radial_distance_m[i] - d) / d);
  }
  // Float inputs and sums: 1/z and the offsets carry relative roundings of about 6e-8, and the
  // intercept of a window's fit amplifies them by the window's extrapolation (at most 2 for a
  // corner's 2x2 support): 1e-5 relative is a hundred of them. The mean's worst error is a
  // property of the geometry (a border pixel's slope), 3e-4 relative at least.
  EXPECT_LT(worst_plane, 1e-5);
  EXPECT_GT(worst_mean, 3e-4);
}

// The plane fit by its definition, independently: double-precision weighted least squares of
// 1/z on (1, u - u_c, v - v_c) by Eigen's LU over the same float support (the mean's support
// test), and the weighted mean where the support does not span a plane.
Reference PlaneDefinition(const MetricFrame& f, const RayTable& rays, int row, int col,
                          const DenoiseOptions& o) {
  DenoiseOptions as_mean = o;
  as_mean.fit_plane = false;
  const Reference mean = Definition(f, row, col, as_mean);
  const auto usable = [&](int r, int c) {
    const float d = f.radial_distance_m(r, c), s = f.delta_l_m(r, c);
    const float a = f.amplitude.empty() ? 0.0f : f.amplitude(r, c);
    const auto others =
        static_cast<std::uint16_t>(kRejectMask & ~static_cast<std::uint16_t>(Flag::kHighDeltaL));
    return std::isfinite(d) && s >= 1e-9f && s <= 1e9f && std::abs(a) <= 1e15f &&
           (f.flags.empty() || (f.flags(r, c).bits() & others) == 0);
  };
  if (!usable(row, col)) return mean;
  // A usable pixel anywhere in the window without a useful 1/z (a distance that is not
  // positive, a ray with r_z < 0.01) sends the window to the mean (the header's rule).
  for (int r = row - o.radius_px; r <= row + o.radius_px; ++r) {
    for (int c = col - o.radius_px; c <= col + o.radius_px; ++c) {
      if (r < 0 || c < 0 || r >= f.height() || c >= f.width() || !usable(r, c)) continue;
      if (!(f.radial_distance_m(r, c) > 0.0f && rays.z(r, c) >= 0.01f)) return mean;
    }
  }
  const float dc = f.radial_distance_m(row, col), sc = f.delta_l_m(row, col);
  const float k2 = static_cast<float>(o.support_sigma) * static_cast<float>(o.support_sigma);
  const float step = static_cast<float>(o.max_step_m);
  const double uc = rays.x(row, col) / double{rays.z(row, col)};
  const double vc = rays.y(row, col) / double{rays.z(row, col)};
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  std::vector<std::pair<int, int>> grid;  // the support's pixels
  double sw = 0.0;
  for (int r = row - o.radius_px; r <= row + o.radius_px; ++r) {
    for (int c = col - o.radius_px; c <= col + o.radius_px; ++c) {
      if (r < 0 || c < 0 || r >= f.height() || c >= f.width() || !usable(r, c)) continue;
      const float dn = f.radial_distance_m(r, c), sn = f.delta_l_m(r, c);
      const float dev = dn - dc;
      if (!(dev * dev <= k2 * (sc * sc + sn * sn))) continue;
      if (o.max_step_m > 0.0 && !(dev * dev <= step * step)) continue;
      const double z = rays.z(r, c);
      const Eigen::Vector3d a(1.0, rays.x(r, c) / z - uc, rays.y(r, c) / z - vc);
      const double wn = 1.0 / (double{sn} * sn);
      m += wn * a * a.transpose();
      b += wn / (double{dn} * z) * a;
      grid.emplace_back(c, r);
      sw += wn;
    }
  }
  // Spans a plane (the header's rule): the support's pixels are not all on one grid line.
  if (grid.size() < 3) return mean;
  bool line = true;
  for (std::size_t j = 2; j < grid.size() && line; ++j) {
    const auto [x0, y0] = grid[0];
    const auto [x1, y1] = grid[1];
    const auto [x2, y2] = grid[j];
    line = (x1 - x0) * (y2 - y0) == (y1 - y0) * (x2 - x0);
  }
  if (line) return mean;
  // The offsets' weighted spread must be resolvable in double sums (the header's 1e-10 rule):
  // the Schur complement of Σw in the normal matrix against the uncentred second moments.
  const Eigen::Matrix2d centred =
      m.bottomRightCorner<2, 2>() - m.block<2, 1>(1, 0) * m.block<1, 2>(0, 1) / sw;
  if (!(centred.determinant() > 1e-10 * m(1, 1) * m(2, 2))) return mean;
  const Eigen::Matrix3d inv = m.inverse();
  const double b0 = (inv * b)(0);
  const double d = 1.0 / (b0 * rays.z(row, col));
  if (!(b0 > 0.0 && std::isfinite(d) && inv(0, 0) > 0.0 && std::isfinite(inv(0, 0)))) return mean;
  return {static_cast<float>(d), mean.a, static_cast<float>(std::sqrt(inv(0, 0))), inv(0, 0) * sw};
}

TEST(DenoiseTest, AFittedPlaneEqualsItsDefinitionForEveryRadiusAndPattern) {
  ForEveryPattern(
      9, true, PlaneDefinition,
      [](const MetricFrame& out, int r, int c, const Reference& ref, const std::string& at) {
        if (std::isnan(ref.d)) {
          EXPECT_TRUE(std::isnan(out.radial_distance_m(r, c))) << at;
          return;
        }
        // The offsets and 1/z come from float rays and distances (relative roundings of 6e-8 of
        // u, v and 1/z, so 1e-5 of an offset of a pixel pitch and of a 1/z deviation of a few
        // σ/d); the extrapolation of a lopsided support multiplies that by about the variance
        // inflation (σ² over the mean's). 2e-5 x inflation relative bounds it; a wrong support,
        // weight or offset changes the result by a percent or more.
        const double tol = 2e-5 * std::max(1.0, ref.inflation);
        EXPECT_NEAR(out.radial_distance_m(r, c), ref.d, tol * ref.d) << at;
        EXPECT_NEAR(out.delta_l_m(r, c), ref.s, tol * ref.s) << at;
        if (!out.amplitude.empty()) {
          EXPECT_NEAR(out.amplitude(r, c), ref.a, 1e-5 * ref.a) << at;
        }
      });
}

TEST(DenoiseTest, AFittedPlaneHasTheMeansNoiseOnAFullWindowAndMoreWhereItExtrapolates) {
  // A fronto-parallel plane with σ 5 cm: where the whole window is support, the offsets are
  // symmetric (no distortion), so the intercept's σ is the mean's, σ / 3. A pixel whose support
  // is its own column and one side's (the plane's edge: the other side is a hole) extrapolates
  // one column: for three rows of equal weights at x = 0 and 1 the intercept's variance is
  // σ² (1/6 + 0.25 / 1.5) = σ² / 3.
  CameraIntrinsics in = CameraIntrinsics::SwissRangerSr2();
  in.width = 200;
  in.height = 200;
  in.cx_px = 99.5;
  in.cy_px = 99.5;
  const RayTable rays = MakeRayTable(in);
  const float sigma = 0.05f;
  MetricFrame f = PlaneFrame(rays, Eigen::Vector3d(0, 0, 1), 3.0, sigma);
  const MetricFrame truth = f;
  std::mt19937 rng(12);
  std::normal_distribution<float> noise(0.0f, sigma);
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) f.radial_distance_m[i] += noise(rng);
  for (int r = 0; r < 200; ++r)
    f.radial_distance_m(r, 100) = std::numeric_limits<float>::quiet_NaN();
  DenoiseOptions o;
  o.fit_plane = true;
  const MetricFrame out = Denoise(f, rays, o);
  double sum2_full = 0.0, sum2_edge = 0.0;
  long n_full = 0, n_edge = 0;
  for (int r = 1; r + 1 < 200; ++r) {
    for (int c = 1; c + 1 < 200; ++c) {
      if (c == 100) continue;
      const double e = out.radial_distance_m(r, c) - truth.radial_distance_m(r, c);
      const double s = out.delta_l_m(r, c);
      if (c == 99 || c == 101) {
        // Only pixels whose three support columns... whose six readings are all support.
        if (std::abs(s - sigma / std::sqrt(3.0)) < 1e-4) {
          sum2_edge += e * e;
          ++n_edge;
        }
      } else if (std::abs(s - sigma / 3.0) < 1e-5) {
        sum2_full += e * e;
        ++n_full;
      }
    }
  }
  // Full windows: at least 95 % of the interior (P(all nine in support) is 0.98, see above).
  EXPECT_GT(n_full, static_cast<long>(0.95 * 196 * 196));
  // The RMS error matches the reported σ: about 4,000 independent windows estimate it to about
  // 1.1 %; 5 % is 4.5 times that.
  EXPECT_NEAR(std::sqrt(sum2_full / static_cast<double>(n_full)), sigma / 3.0, 0.05 * sigma / 3.0);
  // The edge columns: about 380 pixels, overlapping in threes (about 130 independent): the RMS
  // is estimated to about 6 %; 15 % is 2.5 of those, and excludes the mean's σ / sqrt 6 of
  // the same six readings (29 % lower).
  ASSERT_GT(n_edge, 300);
  EXPECT_NEAR(std::sqrt(sum2_edge / static_cast<double>(n_edge)), sigma / std::sqrt(3.0),
              0.15 * sigma / std::sqrt(3.0));
}

TEST(DenoiseTest, AFittedPlaneFallsBackToTheMeanWhereTheSupportIsALine) {
  // A one-row frame: every support lies on one line, so the plane is undetermined and the
  // result is the weighted mean's, bit for bit.
  const RayTable rays = DistortedRays(9, 1);
  MetricFrame f = Flat(9, 1, 2.0f, 0.03f);
  for (int c = 0; c < 9; ++c) f.radial_distance_m(0, c) = 2.0f + 0.01f * static_cast<float>(c % 3);
  DenoiseOptions o;
  o.fit_plane = true;
  const MetricFrame plane = Denoise(f, rays, o);
  o.fit_plane = false;
  const MetricFrame mean = Denoise(f, rays, o);
  for (int c = 0; c < 9; ++c) {
    EXPECT_EQ(plane.radial_distance_m(0, c), mean.radial_distance_m(0, c)) << c;
    EXPECT_EQ(plane.delta_l_m(0, c), mean.delta_l_m(0, c)) << c;
  }
}

TEST(DenoiseTest, AFittedPlaneFallsBackToTheMeanNextToAPixelWithoutA1OverZ) {
  // A usable pixel without a useful 1/z: a ray 89.7° from the optical axis (r_z = 0.005), or a
  // distance that is not positive. Every window holding that pixel gets the mean, bit for bit;
  // windows without it get the plane (here, on a noisy tilted plane, a different value).
  for (const bool along_image_plane : {true, false}) {
    SCOPED_TRACE(along_image_plane ? "ray at 89.7 degrees" : "distance -0.5 m");
    RayTable rays = DistortedRays(7, 7);
    MetricFrame f =
        PlaneFrame(DistortedRays(7, 7), Eigen::Vector3d(0.5, 0.0, 1.0).normalized(), 2.0, 0.05f);
    std::mt19937 rng(4);
    std::normal_distribution<float> noise(0.0f, 0.05f);
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      f.radial_distance_m[i] += noise(rng);
    }
    if (along_image_plane) {
      const float rz = 0.005f;
      rays.x(3, 3) = std::sqrt(1.0f - rz * rz);
      rays.y(3, 3) = 0.0f;
      rays.z(3, 3) = rz;
    } else {
      f.radial_distance_m(3, 3) = -0.5f;
    }
    DenoiseOptions o;
    o.support_sigma = 100.0;  // every neighbour in support
    o.fit_plane = true;
    const MetricFrame plane = Denoise(f, rays, o);
    o.fit_plane = false;
    const MetricFrame mean = Denoise(f, rays, o);
    for (int r = 0; r < 7; ++r) {
      for (int c = 0; c < 7; ++c) {
        if (std::abs(r - 3) <= 1 && std::abs(c - 3) <= 1) {
          EXPECT_EQ(plane.radial_distance_m(r, c), mean.radial_distance_m(r, c)) << r << " " << c;
          EXPECT_EQ(plane.delta_l_m(r, c), mean.delta_l_m(r, c)) << r << " " << c;
        } else {
          EXPECT_NE(plane.radial_distance_m(r, c), mean.radial_distance_m(r, c)) << r << " " << c;
        }
      }
    }
  }
}

TEST(DenoiseTest, AFittedPlaneFallsBackToTheMeanWhereWeightsDifferTooMuchToResolve) {
  // A noise-free 3x3 frame on a tilted plane, through a lens without distortion (so that the
  // heavy row is straight to float precision), whose top row is heavy (σ 1 µm, weight 1e12) and
  // whose other rows, the centre's among them, are light. The centre's value then rests on the
  // light rows' offsets from the heavy one. det C / (Σ w x² Σ w y²) is about the light rows'
  // share of the weight: at a ratio of 1e18 and of 1e12 it is below the guard's 1e-10 and the
  // centre gets the mean, bit for bit; at 1e6 the fit is used, and on a plane it is the input
  // (exact) where the mean, pulled to the top row, is not.
  CameraIntrinsics in = CameraIntrinsics::SwissRangerSr2();
  in.width = 3;
  in.height = 3;
  in.cx_px = 1.0;
  in.cy_px = 1.0;
  const RayTable rays = MakeRayTable(in);
  const MetricFrame plane_frame =
      PlaneFrame(rays, Eigen::Vector3d(0.0, 0.6, 0.8).normalized(), 2.0, 1e-6f);
  for (const auto& [light_sigma, resolved] :
       {std::pair{1e3f, false}, std::pair{1.0f, false}, std::pair{1e-3f, true}}) {
    MetricFrame f = plane_frame;
    for (const int r : {1, 2}) {
      for (int c = 0; c < 3; ++c) f.delta_l_m(r, c) = light_sigma;
    }
    DenoiseOptions o;
    o.support_sigma = 100.0;
    o.fit_plane = true;
    const MetricFrame plane = Denoise(f, rays, o);
    o.fit_plane = false;
    const MetricFrame mean = Denoise(f, rays, o);
    if (resolved) {
      EXPECT_NE(plane.radial_distance_m(1, 1), mean.radial_distance_m(1, 1)) << light_sigma;
      EXPECT_NEAR(plane.radial_distance_m(1, 1), f.radial_distance_m(1, 1),
                  1e-5 * f.radial_distance_m(1, 1));
    } else {
      EXPECT_EQ(plane.radial_distance_m(1, 1), mean.radial_distance_m(1, 1)) << light_sigma;
      EXPECT_EQ(plane.delta_l_m(1, 1), mean.delta_l_m(1, 1)) << light_sigma;
    }
  }
}

TEST(DenoiseTest, AFittedPlaneNeedsRaysOfTheFramesSize) {
  const MetricFrame f = Flat(4, 4, 2.0f, 0.02f);
  DenoiseOptions o;
  o.fit_plane = true;
  try {
    (void)Denoise(f, o);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("fit_plane needs the camera's rays"), std::string::npos);
  }
  try {
    (void)Denoise(f, DistortedRays(5, 4), o);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
    EXPECT_NE(std::string(e.what()).find("rays' x is 5x4"), std::string::npos);
  }
  // The channel that does not fit is named.
  RayTable bad_z = DistortedRays(4, 4);
  bad_z.z = Image<float>(4, 3, 1.0f);
  try {
    (void)Denoise(f, bad_z, o);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
    EXPECT_NE(std::string(e.what()).find("rays' z is 4x3"), std::string::npos);
  }
  // An empty table is none, through either overload.
  for (const bool into : {false, true}) {
    try {
      DenoisedChannels c;
      if (into) {
        DenoiseInto(f, RayTable{}, o, c);
      } else {
        (void)Denoise(f, RayTable{}, o);
      }
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find("fit_plane needs the camera's rays"), std::string::npos);
    }
  }
  // Without fit_plane the rays are not needed, but must still fit when given.
  o.fit_plane = false;
  EXPECT_THROW((void)Denoise(f, DistortedRays(5, 4), o), Error);
  EXPECT_NO_THROW((void)Denoise(f, o));
  EXPECT_NO_THROW((void)Denoise(f, RayTable{}, o));
}

TEST(DenoiseTest, BadOptionsAndFramesAreErrorsNamingTheProblem) {
  const MetricFrame f = Flat(4, 4, 2.0f, 0.02f);
  const auto message = [&](const MetricFrame& frame, const DenoiseOptions& o) {
    try {
      (void)Denoise(frame, o);
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
      return std::string(e.what());
    }
    return std::string("no error");
  };
  DenoiseOptions o;
  for (const int r : {0, 4, -1}) {
    o = {};
    o.radius_px = r;
    EXPECT_NE(message(f, o).find("radius_px"), std::string::npos) << r;
  }
  for (const double k : {0.0, -1.0, 101.0, std::numeric_limits<double>::quiet_NaN()}) {
    o = {};
    o.support_sigma = k;
    EXPECT_NE(message(f, o).find("support_sigma"), std::string::npos) << k;
  }
  for (const double s : {-0.01, 2e6, std::numeric_limits<double>::quiet_NaN()}) {
    o = {};
    o.max_step_m = s;
    EXPECT_NE(message(f, o).find("max_step_m"), std::string::npos) << s;
  }
  MetricFrame no_sigma = f;
  no_sigma.delta_l_m = Image<float>();
  EXPECT_NE(message(no_sigma, {}).find("delta_l_m is empty"), std::string::npos);
  MetricFrame wrong = f;
  wrong.amplitude = Image<float>(3, 4);
  EXPECT_NE(message(wrong, {}).find("amplitude is 3x4"), std::string::npos);
  wrong = f;
  wrong.delta_l_m = Image<float>(4, 5, 0.02f);
  EXPECT_NE(message(wrong, {}).find("delta_l_m is 4x5"), std::string::npos);
  wrong = f;
  wrong.flags = Image<PixelFlags>(2, 2);
  EXPECT_NE(message(wrong, {}).find("flags"), std::string::npos);
  EXPECT_NE(message(MetricFrame{}, {}).find("empty distance"), std::string::npos);
}

TEST(DenoiseTest, IntoReusesItsBuffers) {
  MetricFrame f = Flat(8, 6, 2.0f, 0.02f);
  DenoisedChannels c;
  DenoiseInto(f, {}, c);
  const float* d = c.radial_distance_m.data();
  f.radial_distance_m(3, 3) = 2.05f;
  DenoiseInto(f, {}, c);
  EXPECT_EQ(c.radial_distance_m.data(), d);
  EXPECT_NEAR(c.radial_distance_m(3, 3), 2.0 + 0.05 / 9.0, 1e-6);
}

}  // namespace
}  // namespace tofcam
