#include "tofcam/filters/neighbour_prediction.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// A w x h frame at `distance` with σ = `sigma` everywhere.
MetricFrame Flat(int w, int h, float distance, float sigma) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(w, h, distance);
  f.delta_l_m = Image<float>(w, h, sigma);
  f.flags = Image<PixelFlags>(w, h);
  return f;
}

NeighbourPredictionOptions Radius(int r) {
  NeighbourPredictionOptions o;
  o.radius_px = r;
  return o;
}

// The prediction of the file comment, computed here in double from the pairs listed by hand: the
// inverse-variance mean of the midpoints of 1/d, weights 4 / (σ_qa² + σ_qb²), σ_q = ΔL / d².
struct Expected {
  double p, sigma;
};
Expected ByHand(const MetricFrame& f, const std::vector<std::pair<int, int>>& pairs, int r0,
                int c0) {
  double sw = 0, swx = 0;
  for (const auto& [dr, dc] : pairs) {
    const double da = f.radial_distance_m(r0 + dr, c0 + dc),
                 db = f.radial_distance_m(r0 - dr, c0 - dc);
    const double sa = f.delta_l_m(r0 + dr, c0 + dc) / (da * da);
    const double sb = f.delta_l_m(r0 - dr, c0 - dc) / (db * db);
    const double w = 4.0 / (sa * sa + sb * sb);
    sw += w;
    swx += w * 0.5 * (1.0 / da + 1.0 / db);
  }
  const double p = sw / swx;  // 1 / q_p
  return {p, p * p / std::sqrt(sw)};
}

TEST(NeighbourPredictionTest, TheCentreIsTheWeightedMeanOfItsPairsMidpointsIn1OverD) {
  // A 3x3 window: four pairs (up-down, left-right and the two diagonals) with readings and σ
  // chosen so that every pair differs; the centre's own reading is far off and takes no part.
  MetricFrame f = Flat(3, 3, 2.0f, 0.02f);
  const float d[9] = {1.98f, 2.01f, 2.03f, 2.00f, 9.0f, 2.02f, 1.97f, 1.99f, 2.02f};
  const float s[9] = {0.02f, 0.03f, 0.01f, 0.02f, 0.5f, 0.04f, 0.02f, 0.02f, 0.03f};
  for (int i = 0; i < 9; ++i) {
    f.radial_distance_m[i] = d[i];
    f.delta_l_m[i] = s[i];
  }
  NeighbourPredictionOptions o = Radius(1);
  o.max_disagreement_sigma = 100.0;  // the hand case tests the sums, not the window test
  const NeighbourPrediction p = PredictFromNeighbours(f, o);
  const Expected e = ByHand(f, {{1, 0}, {0, 1}, {1, 1}, {1, -1}}, 1, 1);
  // Single-precision sums of four terms: a few float ulps (6e-8 relative) each.
  EXPECT_NEAR(p.distance_m(1, 1), e.p, 2e-6 * e.p);
  EXPECT_NEAR(p.sigma_m(1, 1), e.sigma, 2e-6 * e.sigma);
  // A corner has no symmetric pair inside the image; an edge pixel has one (left-right), which
  // the default min_pairs (2) does not accept and min_pairs 1 does.
  EXPECT_TRUE(std::isnan(p.distance_m(0, 0)));
  EXPECT_TRUE(std::isnan(p.sigma_m(0, 1)));
  o.min_pairs = 1;
  const NeighbourPrediction one = PredictFromNeighbours(f, o);
  const Expected edge = ByHand(f, {{0, 1}}, 0, 1);
  EXPECT_NEAR(one.distance_m(0, 1), edge.p, 2e-6 * edge.p);
  EXPECT_NEAR(one.sigma_m(0, 1), edge.sigma, 2e-6 * edge.sigma);
  EXPECT_TRUE(std::isnan(one.distance_m(0, 0)));
}

// The definition of the file comment, per pixel in double, for any frame: the largest window
// from R down whose usable pairs (both pixels in the image, no reject bit, d in [0.01, 1e4], ΔL in
// [1e-5, 100]) number at least min_pairs and all lie within k of their σ of the window's
// prediction.
Expected Definition(const MetricFrame& f, int r0, int c0, const NeighbourPredictionOptions& o) {
  const int w = f.width(), h = f.height();
  const auto usable = [&](int r, int c) {
    if (r < 0 || r >= h || c < 0 || c >= w || f.flags(r, c).Any(kRejectMask)) return false;
    const float d = f.radial_distance_m(r, c), s = f.delta_l_m(r, c);
    return d >= 0.01f && d <= 1e4f && s >= 1e-5f && s <= 100.0f;
  };
  for (int radius = o.radius_px; radius >= 1; --radius) {
    std::vector<std::pair<double, double>> mids;  // midpoint, weight
    for (int dr = 0; dr <= radius; ++dr) {
      for (int dc = -radius; dc <= radius; ++dc) {
        if (dr == 0 && dc <= 0) continue;
        if (!usable(r0 + dr, c0 + dc) || !usable(r0 - dr, c0 - dc)) continue;
        const double da = f.radial_distance_m(r0 + dr, c0 + dc);
        const double db = f.radial_distance_m(r0 - dr, c0 - dc);
        const double sa = f.delta_l_m(r0 + dr, c0 + dc) / (da * da);
        const double sb = f.delta_l_m(r0 - dr, c0 - dc) / (db * db);
        mids.emplace_back(0.5 * (1 / da + 1 / db), 4 / (sa * sa + sb * sb));
      }
    }
    if (static_cast<int>(mids.size()) < o.min_pairs) continue;
    double sw = 0, swx = 0;
    for (const auto& [m, w8] : mids) {
      sw += w8;
      swx += w8 * m;
    }
    const double q = swx / sw;
    bool agree = true;
    for (const auto& [m, w8] : mids) {
      agree =
          agree && (m - q) * (m - q) * w8 <= o.max_disagreement_sigma * o.max_disagreement_sigma;
    }
    if (agree) return {1 / q, 1 / (q * q) / std::sqrt(sw)};
  }
  return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
}

TEST(NeighbourPredictionTest, EqualsTheDefinitionOnAWideFrameWithStepsSlopesAndHoles) {
  // 600 pixels wide (more than one block of columns), 40 rows: a slope, a depth step, noise,
  // saturated pixels, NaN ΔL and zero distances, every radius.
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  MetricFrame f = Flat(600, 40, 0.0f, 0.0f);
  for (int r = 0; r < 40; ++r) {
    for (int c = 0; c < 600; ++c) {
      const float sigma = 0.005f + 0.05f * u(rng);
      f.radial_distance_m(r, c) = (c < 350 ? 2.0f + 0.004f * c : 5.0f) + sigma * noise(rng);
      f.delta_l_m(r, c) = sigma;
      const float x = u(rng);
      if (x < 0.03f)
        f.flags(r, c).Set(Flag::kSaturated);
      else if (x < 0.04f)
        f.delta_l_m(r, c) = std::numeric_limits<float>::quiet_NaN();
      else if (x < 0.05f)
        f.radial_distance_m(r, c) = 0.0f;
    }
  }
  for (int radius = 1; radius <= 5; ++radius) {
    NeighbourPredictionOptions o = Radius(radius);
    const NeighbourPrediction p = PredictFromNeighbours(f, o);
    long predicted = 0;
    for (int r = 0; r < 40; ++r) {
      for (int c = 0; c < 600; ++c) {
        const Expected e = Definition(f, r, c, o);
        ASSERT_EQ(std::isnan(e.p), std::isnan(p.distance_m(r, c)))
            << radius << " " << r << " " << c;
        if (std::isnan(e.p)) continue;
        ++predicted;
        // Single-precision sums of up to 60 terms against double: 1e-5 relative.
        EXPECT_NEAR(p.distance_m(r, c), e.p, 1e-5 * e.p) << radius << " " << r << " " << c;
        EXPECT_NEAR(p.sigma_m(r, c), e.sigma, 1e-5 * e.sigma) << radius << " " << r << " " << c;
      }
    }
    EXPECT_GT(predicted, 600 * 40 / 2) << radius;
  }
}

TEST(NeighbourPredictionTest, OnAFlatWallSigmaIsTheClosedForm) {
  // Equal readings d and σ: each pair's midpoint has variance σ_q² / 2, so a window of n pairs
  // gives σ_q / sqrt(2 n) and σ_p = σ / sqrt(2 n): n = 4, 12, 24, 40 for R = 1..4.
  const MetricFrame f = Flat(15, 15, 3.0f, 0.05f);
  for (int r = 1; r <= 4; ++r) {
    const NeighbourPrediction p = PredictFromNeighbours(f, Radius(r));
    const int n = (2 * r + 1) * (2 * r + 1) / 2;
    EXPECT_NEAR(p.distance_m(7, 7), 3.0, 1e-6) << r;
    EXPECT_NEAR(p.sigma_m(7, 7), 0.05 / std::sqrt(2.0 * n), 1e-6 * 0.05) << r;
    // Column 1: only pairs within one column of the centre have both pixels in the image:
    // 3 R + 1 of them.
    EXPECT_NEAR(p.sigma_m(7, 1), 0.05 / std::sqrt(2.0 * (3 * r + 1)), 1e-6 * 0.05) << r;
  }
}

TEST(NeighbourPredictionTest, IsNearlyExactOnASlantedPlaneWhereTheMeanOfDistancesIsNot) {
  // A plane at 60° to the optical axis seen by the SR-2's lens (with its distortion): 1/z is
  // affine in the normalised coordinates, and 1/d = r_z / z changes to second order with r_z, so
  // the midpoints of 1/d are exact up to that curvature. The same pairs' midpoints of d carry
  // the distance's own curvature, which is larger on a slanted plane.
  const CameraIntrinsics in = CameraIntrinsics::SwissRangerSr2();
  const RayTable rays = MakeRayTable(in);
  const int w = in.width, h = in.height;
  MetricFrame f = Flat(w, h, 0.0f, 0.01f);
  const Eigen::Vector3d n = Eigen::Vector3d(std::sin(M_PI / 3), 0.0, std::cos(M_PI / 3));
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    const Eigen::Vector3d r(rays.x[i], rays.y[i], rays.z[i]);
    f.radial_distance_m[i] = static_cast<float>(3.0 * std::cos(M_PI / 3) / n.dot(r));
  }
  const NeighbourPrediction p = PredictFromNeighbours(f, Radius(3));
  double worst_q = 0, worst_d = 0;
  int predicted = 0;
  for (int r = 3; r < h - 3; ++r) {
    for (int c = 3; c < w - 3; ++c) {
      const double d = f.radial_distance_m(r, c);
      if (!(d > 0.5 && d < 20.0)) continue;
      ASSERT_FALSE(std::isnan(p.distance_m(r, c))) << c << " " << r;
      ++predicted;
      worst_q = std::max(worst_q, std::abs(p.distance_m(r, c) - d) / d);
      // The unweighted mean of the 24 pairs' midpoints of d (σ is equal on this frame, but
      // the weights of 1/d differ by d², so the plain mean is the fair comparison).
      double mean_d = 0;
      int pairs = 0;
      for (int dr = 0; dr <= 3; ++dr) {
        for (int dc = -3; dc <= 3; ++dc) {
          if (dr == 0 && dc <= 0) continue;
          mean_d +=
              0.5 * (f.radial_distance_m(r + dr, c + dc) + f.radial_distance_m(r - dr, c - dc));
          ++pairs;
        }
      }
      worst_d = std::max(worst_d, std::abs(mean_d / pairs - d) / d);
    }
  }
  EXPECT_GT(predicted, w * h / 4);
  // Measured: 1.6e-4 relative with midpoints of 1/d against 2.7e-3 with midpoints of d (0.5 mm
  // and 8 mm at 3 m). The bound 4e-4 is 2.5 times what was measured: a change of the lens model
  // or of the sums that doubles the error still passes, one that loses the 1/d model does not.
  EXPECT_LT(worst_q, 4e-4);
  EXPECT_GT(worst_d, 10 * worst_q);
}

TEST(NeighbourPredictionTest, AWindowAcrossAStepFallsBackToOneOnTheOwnSide) {
  // Columns 0-6 at 2 m, 7-13 at 3 m, σ 1 cm. Column 5: the 7x7 and 5x5 windows reach column 7
  // and beyond (pairs across the step disagree by tens of σ), the 3x3 does not.
  MetricFrame f = Flat(14, 9, 2.0f, 0.01f);
  for (int r = 0; r < 9; ++r) {
    for (int c = 7; c < 14; ++c) f.radial_distance_m(r, c) = 3.0f;
  }
  const NeighbourPrediction p = PredictFromNeighbours(f, Radius(3));
  EXPECT_NEAR(p.distance_m(4, 5), 2.0, 1e-6);
  EXPECT_NEAR(p.sigma_m(4, 5), 0.01 / std::sqrt(8.0), 1e-8);
  // Column 6 touches the step in every window: no prediction. Column 3: the full 7x7 fits.
  EXPECT_TRUE(std::isnan(p.distance_m(4, 6)));
  EXPECT_NEAR(p.sigma_m(4, 3), 0.01 / std::sqrt(48.0), 1e-8);
}

TEST(NeighbourPredictionTest, RejectedAndOutOfRangeNeighboursAreNoSupport) {
  MetricFrame f = Flat(3, 3, 2.0f, 0.02f);
  f.flags(1, 0).Set(Flag::kSaturated);  // left: the left-right pair goes
  f.delta_l_m(0, 0) = 200.0f;           // beyond 100 m: the diagonal pair goes
  f.flags(0, 1).Set(Flag::kMixed);      // a truth bit, not a reject bit: stays
  const NeighbourPrediction p = PredictFromNeighbours(f, Radius(1));
  EXPECT_NEAR(p.sigma_m(1, 1), 0.02 / std::sqrt(4.0), 1e-8);  // two pairs
  NeighbourPredictionOptions o = Radius(1);
  o.min_pairs = 3;
  EXPECT_TRUE(std::isnan(PredictFromNeighbours(f, o).distance_m(1, 1)));
}

TEST(NeighbourPredictionTest, TheCentresOwnReadingAndFlagsChangeNothing) {
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.0f, 0.03f);
  MetricFrame f = Flat(21, 17, 4.0f, 0.03f);
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) f.radial_distance_m[i] += noise(rng);
  const NeighbourPrediction before = PredictFromNeighbours(f);
  f.radial_distance_m(8, 10) = 7.0f;
  f.flags(8, 10).Set(Flag::kSaturated);
  const NeighbourPrediction after = PredictFromNeighbours(f);
  EXPECT_EQ(before.distance_m(8, 10), after.distance_m(8, 10));
  EXPECT_EQ(before.sigma_m(8, 10), after.sigma_m(8, 10));
}

TEST(NeighbourPredictionTest, PredictedSigmasAndThePosteriorHoldOnNoisyWalls) {
  // Gaussian noise of σ = ΔL on a wall at 3 m, many independent frames. The prediction's error
  // p - truth must have the spread σ_p; given the residual, the reading's squared error must
  // average m² + v (also among the readings the neighbours contradict, |r| > 2σ), and the
  // combination's error must have variance v. Tolerances: ~1e5 interior pixels per check, whose
  // neighbouring predictions share readings (about 1 independent value per 7x7 window, ~2000
  // in all): a spread's relative standard error ~ 1/sqrt(2 x 2000) = 1.6 %, a mean square's
  // ~ sqrt(2 / 2000) = 3.2 %; 8 % and 12 % are about 4 standard errors.
  constexpr double kTruth = 3.0, kSigma = 0.05;
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, kSigma);
  double pred_sq = 0, pred_var = 0, pred_mean = 0;
  double e2 = 0, post2 = 0, comb_sq = 0, comb_var = 0;
  double far_e2 = 0, far_post2 = 0;
  long n = 0, far = 0, unpredicted = 0;
  for (int frame = 0; frame < 40; ++frame) {
    MetricFrame f = Flat(64, 48, 0.0f, static_cast<float>(kSigma));
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      f.radial_distance_m[i] = static_cast<float>(kTruth + noise(rng));
    }
    const NeighbourPrediction p = PredictFromNeighbours(f);
    for (int r = 3; r < 45; ++r) {
      for (int c = 3; c < 61; ++c) {
        const double d = f.radial_distance_m(r, c);
        if (std::isnan(p.distance_m(r, c))) {
          ++unpredicted;
          continue;
        }
        const ReadingPosterior post =
            PosteriorOfReading(d, kSigma, p.distance_m(r, c), p.sigma_m(r, c));
        const double pe = p.distance_m(r, c) - kTruth;
        pred_sq += pe * pe;
        pred_mean += pe;
        pred_var += p.sigma_m(r, c) * p.sigma_m(r, c);
        const double e = d - kTruth;
        e2 += e * e;
        post2 += post.ReadingRmsErrorM() * post.ReadingRmsErrorM();
        const double ce = d - post.mean_error_m - kTruth;
        comb_sq += ce * ce;
        comb_var += post.variance_m2;
        if (std::abs(d - p.distance_m(r, c)) > 2 * kSigma) {
          far_e2 += e * e;
          far_post2 += post.ReadingRmsErrorM() * post.ReadingRmsErrorM();
          ++far;
        }
        ++n;
      }
    }
  }
  // A window of pure noise fails the 4σ test now and then (24 pairs: about 0.15 %); then the
  // next smaller one is used. Pixels left without any are rare.
  EXPECT_LT(unpredicted, n / 100);
  // 1/d of a noisy reading is biased by σ²/d relative (E[1/(d + e)] = (1 + σ²/d²)/d): 0.8 mm
  // here, well inside the spread.
  EXPECT_LT(std::abs(pred_mean / n), 2 * kSigma * kSigma / kTruth);
  EXPECT_NEAR(std::sqrt(pred_sq / n), std::sqrt(pred_var / n), 0.08 * std::sqrt(pred_var / n));
  EXPECT_NEAR(e2 / n, post2 / n, 0.12 * post2 / n);
  EXPECT_NEAR(comb_sq / n, comb_var / n, 0.12 * comb_var / n);
  ASSERT_GT(far, 1000);
  EXPECT_NEAR(far_e2 / far, far_post2 / far, 0.12 * far_post2 / far);
  // The contradicted readings are the bad ones: their mean square is several σ².
  EXPECT_GT(far_e2 / far, 3 * kSigma * kSigma);
}

TEST(NeighbourPredictionTest, PosteriorOfAHandCase) {
  // d 3.1, σ 3 cm, p 3.0, σ_p 4 cm: gain 9 / (9 + 16) = 0.36, m = 0.1 x 0.36 = 0.036,
  // v = 0.0016 x 0.36 = 5.76e-4, sqrt(m² + v) = sqrt(1.872e-3).
  const ReadingPosterior post = PosteriorOfReading(3.1, 0.03, 3.0, 0.04);
  EXPECT_NEAR(post.mean_error_m, 0.036, 1e-12);
  EXPECT_NEAR(post.variance_m2, 5.76e-4, 1e-15);
  EXPECT_NEAR(post.ReadingRmsErrorM(), std::sqrt(1.872e-3), 1e-12);
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(std::isnan(PosteriorOfReading(3.1, 0.0, 3.0, 0.04).mean_error_m));
  EXPECT_TRUE(std::isnan(PosteriorOfReading(3.1, 0.03, kNaN, 0.04).mean_error_m));
  EXPECT_TRUE(std::isnan(PosteriorOfReading(kNaN, 0.03, 3.0, 0.04).variance_m2));
  EXPECT_TRUE(std::isnan(PosteriorOfReading(3.1, 0.03, 3.0, -1.0).variance_m2));
  // Huge σ does not overflow: the gain tends to 1, the variance to σ_p²; a huge σ_p: the gain
  // tends to 0, the variance to σ².
  const ReadingPosterior wide = PosteriorOfReading(3.1, 1e200, 3.0, 0.04);
  EXPECT_NEAR(wide.mean_error_m, 0.1, 1e-12);
  EXPECT_NEAR(wide.variance_m2, 0.0016, 1e-15);
  const ReadingPosterior vague = PosteriorOfReading(3.1, 0.03, 3.0, 1e200);
  EXPECT_NEAR(vague.mean_error_m, 0.0, 1e-12);
  EXPECT_NEAR(vague.variance_m2, 9e-4, 1e-15);
}

TEST(NeighbourPredictionTest, OnlyKeptPixelsWithAPredictionAreCombined) {
  MetricFrame f = Flat(5, 5, 2.0f, 0.04f);
  f.radial_distance_m(0, 0) = 2.3f;  // a corner: no pair, no prediction
  f.radial_distance_m(2, 2) = 2.1f;  // contradicted by its neighbours
  f.radial_distance_m(1, 2) = 2.05f;
  f.flags(1, 2).Set(Flag::kLowConfidence);  // rejected: stays as read
  const NeighbourPrediction p = PredictFromNeighbours(f, Radius(1));
  const Image<float> out = CombineWithPrediction(f, p);
  const ReadingPosterior post = PosteriorOfReading(2.1, 0.04, p.distance_m(2, 2), p.sigma_m(2, 2));
  EXPECT_NEAR(out(2, 2), 2.1 - post.mean_error_m, 1e-6);
  EXPECT_LT(std::abs(out(2, 2) - 2.0), 0.1 / 3);  // pulled most of the way to the wall
  EXPECT_EQ(out(1, 2), 2.05f);
  EXPECT_EQ(out(0, 0), 2.3f);  // no prediction at the corner
  // In place gives the same.
  MetricFrame g = f;
  CombineWithPredictionInto(g, p, g.radial_distance_m);
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_EQ(g.radial_distance_m[i], out[i]) << i;
  // `out` may not be ΔL or the prediction, which the loop reads.
  EXPECT_THROW(CombineWithPredictionInto(g, p, g.delta_l_m), Error);
  NeighbourPrediction q = p;
  EXPECT_THROW(CombineWithPredictionInto(f, q, q.distance_m), Error);
  NeighbourPrediction small = p;
  small.distance_m = Image<float>(4, 5);
  try {
    (void)CombineWithPrediction(f, small);
    ADD_FAILURE() << "a prediction of another size was taken";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
}

TEST(NeighbourPredictionTest, BadOptionsAndFramesAreRefusedByName) {
  const MetricFrame f = Flat(4, 4, 2.0f, 0.02f);
  const auto refuses = [&](NeighbourPredictionOptions o, const std::string& field) {
    try {
      (void)PredictFromNeighbours(f, o);
      ADD_FAILURE() << field << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  NeighbourPredictionOptions o;
  o.radius_px = 0;
  refuses(o, "radius_px");
  o.radius_px = 6;
  refuses(o, "radius_px");
  o = {};
  o.max_disagreement_sigma = 0.0;
  refuses(o, "max_disagreement_sigma");
  o.max_disagreement_sigma = std::numeric_limits<double>::quiet_NaN();
  refuses(o, "max_disagreement_sigma");
  o = {};
  o.min_pairs = 0;
  refuses(o, "min_pairs");
  o.min_pairs = 25;  // a 7x7 window has 24 pairs
  refuses(o, "min_pairs");
  o.radius_px = 1;
  o.min_pairs = 5;  // a 3x3 has 4
  refuses(o, "min_pairs");
  MetricFrame no_delta = f;
  no_delta.delta_l_m = Image<float>();
  EXPECT_THROW((void)PredictFromNeighbours(no_delta), Error);
  EXPECT_THROW((void)PredictFromNeighbours(MetricFrame{}), Error);
}

}  // namespace
}  // namespace tofcam
