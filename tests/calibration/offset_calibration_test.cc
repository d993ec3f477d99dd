#include "tofcam/calibration/offset_calibration.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

constexpr double kL20 = 7.49481145;  // c / (2 * 20 MHz)

OffsetCalibration MakeCalibration(int w, int h, float offset) {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = w;
  c.height = h;
  c.offset_m = Image<float>(w, h, offset);
  return c;
}

MetricFrame MakeFrame(int w, int h, float distance) {
  MetricFrame m;
  m.radial_distance_m = Image<float>(w, h, distance);
  m.amplitude = Image<float>(w, h, 1000.0f);
  m.intensity = Image<float>(w, h, 5000.0f);
  m.flags = Image<PixelFlags>(w, h);
  return m;
}

ErrorCode CodeOf(auto&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.code();
  }
  return ErrorCode::kInternal;  // "no error" never matches an expected code below
}

TEST(ApplyCalibrationTest, EquationOneHandValuesIncludingWrap) {
  OffsetCalibration c = MakeCalibration(4, 1, 0.0f);
  MetricFrame m = MakeFrame(4, 1, 0.0f);
  // (m, o) -> l = (m - o + r_e) mod r_e, r_e = 7.49481145 m.
  m.radial_distance_m(0, 0) = 0.1f;  // minus 0.3: plain subtraction would be -0.2
  c.offset_m(0, 0) = 0.3f;           // -> 7.29481145
  m.radial_distance_m(0, 1) = 2.0f;
  c.offset_m(0, 1) = 0.05f;  // -> 1.95
  m.radial_distance_m(0, 2) = 7.4f;
  c.offset_m(0, 2) = -0.2f;  // 7.6 wraps -> 0.10518855
  m.radial_distance_m(0, 3) = 3.0f;
  c.offset_m(0, 3) = 0.0f;  // unchanged
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_NEAR(l.radial_distance_m(0, 0), 7.29481145, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 1), 1.95, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 2), 0.10518855, 2e-6);
  EXPECT_FLOAT_EQ(l.radial_distance_m(0, 3), 3.0f);
  for (int col = 0; col < 4; ++col) {
    EXPECT_GE(l.radial_distance_m(0, col), 0.0f);
    EXPECT_LT(l.radial_distance_m(0, col), static_cast<float>(kL20));
  }
  // The input frame is not modified.
  EXPECT_FLOAT_EQ(m.radial_distance_m(0, 0), 0.1f);
}

TEST(ApplyCalibrationTest, InvalidPixelsPassThroughAndCalibrationFlagsAreAdded) {
  OffsetCalibration c = MakeCalibration(3, 1, 0.5f);
  c.pixel_flags = Image<PixelFlags>(3, 1);
  c.pixel_flags(0, 2) = PixelFlags(Flag::kInvalid);
  MetricFrame m = MakeFrame(3, 1, 2.0f);
  m.flags(0, 0) = PixelFlags(Flag::kInvalid);
  m.flags(0, 1) = PixelFlags(Flag::kSaturated);
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_FLOAT_EQ(l.radial_distance_m(0, 0), 2.0f);  // untouched
  EXPECT_EQ(l.flags(0, 0), PixelFlags(Flag::kInvalid));
  EXPECT_NEAR(l.radial_distance_m(0, 1), 1.5, 1e-6);  // saturated: corrected, flag kept
  EXPECT_EQ(l.flags(0, 1), PixelFlags(Flag::kSaturated));
  EXPECT_EQ(l.flags(0, 2), PixelFlags(Flag::kInvalid));  // uncalibrated pixel
}

TEST(ApplyCalibrationTest, RejectsMismatchedFrames) {
  const OffsetCalibration c = MakeCalibration(3, 2, 0.0f);
  EXPECT_EQ(CodeOf([&] { (void)ApplyCalibration(MakeFrame(2, 3, 1.0f), c); }),
            ErrorCode::kMismatch);
  MetricFrame m = MakeFrame(3, 2, 1.0f);
  m.info.modulation_frequency_hz = 30e6;
  EXPECT_EQ(CodeOf([&] { (void)ApplyCalibration(m, c); }), ErrorCode::kMismatch);
}

TEST(DistanceCorrectionTest, InterpolatesKnotsAndHoldsEnds) {
  DistanceCorrection g;
  g.start_m = 1.0;
  g.step_m = 0.5;
  // Samples of q(x) = 0.01 x^2 - 0.02 x at x = 1.0 .. 3.5.
  const auto q = [](double x) { return 0.01 * x * x - 0.02 * x; };
  for (int k = 0; k < 6; ++k) g.correction_m.push_back(static_cast<float>(q(1.0 + 0.5 * k)));
  EXPECT_NO_THROW(g.Validate());
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(g.Evaluate(1.0 + 0.5 * k), q(1.0 + 0.5 * k), 1e-7);
  // Catmull-Rom reproduces quadratics on interior intervals (knots k-1..k+2 all present).
  for (double x : {1.6, 2.0 + 1.0 / 3.0, 2.9}) EXPECT_NEAR(g.Evaluate(x), q(x), 1e-7) << x;
  EXPECT_NEAR(g.Evaluate(0.2), q(1.0), 1e-7);  // before the first knot: first value
  EXPECT_NEAR(g.Evaluate(9.0), q(3.5), 1e-7);  // after the last: last value
  EXPECT_NEAR(g.Evaluate(std::nan("")), q(1.0), 1e-7);
}

TEST(DistanceCorrectionTest, AppliedAfterEquationOneWithWrap) {
  OffsetCalibration c = MakeCalibration(2, 1, 0.1f);
  DistanceCorrection g;
  g.start_m = 0.0;
  g.step_m = 1.0;
  g.correction_m.assign(9, 0.02f);  // constant 20 mm too long
  c.distance_correction = g;
  MetricFrame m = MakeFrame(2, 1, 0.0f);
  m.radial_distance_m(0, 0) = 3.0f;   // eq. 1: 2.9, then 2.88
  m.radial_distance_m(0, 1) = 0.11f;  // eq. 1: 0.01, then -0.01 wraps to L - 0.01
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_NEAR(l.radial_distance_m(0, 0), 2.88, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 1), kL20 - 0.01, 2e-6);
}

// --- Dense resampling of the distance correction ---------------------------------------------

// A wiggle like the SR-2's (2 cm at period L/4, on a slow quadratic trend) sampled at 5 cm knots
// from 0.3 m to 7.75 m (beyond L, as a wall sweep may well end).
DistanceCorrection Wiggle() {
  DistanceCorrection g;
  g.start_m = 0.3;
  g.step_m = 0.05;
  for (int k = 0; k < 150; ++k) {
    const double x = g.start_m + k * g.step_m;
    g.correction_m.push_back(
        static_cast<float>(0.02 * std::sin(2.0 * 3.14159265358979 * x / (kL20 / 4.0)) +
                           0.001 * (x - 3.0) * (x - 3.0) - 0.005));
  }
  return g;
}

// max |g''| of the Catmull-Rom spline through the knots, from its closed form: on segment k,
// g(t) = p1 + (p2 - p0) t / 2 + (2p0 - 5p1 + 4p2 - p3) t^2 / 2 + (3(p1 - p2) + p3 - p0) t^3 / 2,
// so d2g/dx2 = ((2p0 - 5p1 + 4p2 - p3) + 3 (3(p1 - p2) + p3 - p0) t) / step^2, extreme at t = 0, 1.
// Only segments starting below `range_m` count (the table covers [0, L]).
double SplineMaxSecondDerivative(const DistanceCorrection& g, double range_m) {
  const std::vector<float>& p = g.correction_m;
  const std::size_t n = p.size();
  double m = 0.0;
  for (std::size_t k = 0; k + 1 < n && g.start_m + k * g.step_m < range_m; ++k) {
    const double p0 = p[k == 0 ? 0 : k - 1], p1 = p[k], p2 = p[k + 1],
                 p3 = p[std::min(k + 2, n - 1)];
    const double a = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
    const double b = 3.0 * (3.0 * (p1 - p2) + p3 - p0);
    m = std::max({m, std::abs(a), std::abs(a + b)});
  }
  return m / (g.step_m * g.step_m);
}

// max |g'| by central differences of the double-precision spline at 10 µm, with 10 % margin.
double SplineMaxSlope(const DistanceCorrection& g, double range_m) {
  double m = 0.0;
  for (double x = 0.0; x < range_m; x += 1e-5) {
    m = std::max(m, std::abs(g.Evaluate(x + 5e-6) - g.Evaluate(x - 5e-6)) / 1e-5);
  }
  return 1.1 * m;
}

TEST(DenseDistanceCorrectionTest, MatchesTheCatmullRomSplineWithinTheInterpolationBound) {
  const DistanceCorrection g = Wiggle();
  const DenseDistanceCorrection d = DenseDistanceCorrection::Resample(g, kL20);
  // 5 cm knots, at most 1 mm: k = 50 samples per knot interval, so the step is exactly 1 mm.
  EXPECT_NEAR(d.step_m, 0.001, 1e-15);
  EXPECT_NEAR(d.origin_m, 0.3, 1e-15);  // the first knot; below it g is the first knot's value
  // Linear interpolation of a function with bounded g'': |error| <= h^2 / 8 max |g''|.
  const double bound = d.step_m * d.step_m / 8.0 * SplineMaxSecondDerivative(g, kL20);
  EXPECT_NEAR(d.max_interpolation_error_m, bound, 1e-15);
  // Inside, max |g''| ~ 0.02 (2 pi / 1.87 m)^2 = 0.23 /m; the first segment, where the spline
  // repeats the end knot, bends more (g'' = 2 g' / step ~ 2.7 /m). Either way the bound at 1 mm
  // is below a float ulp at L (4.8e-7 m).
  EXPECT_LT(d.max_interpolation_error_m, 4.8e-7);
  // The float evaluation adds: the position rounded to float, (d - origin) and the index scaled
  // by 1/h, together < 1e-6 m, times max |g'|; plus a few ulps of |g| <= 0.04 m for the value.
  const double tolerance = bound + SplineMaxSlope(g, kL20) * 1e-6 + 1e-8;
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> uniform(0.0f, static_cast<float>(kL20));
  double worst = 0.0;
  for (int i = 0; i < 200000; ++i) {
    const float x = uniform(rng);
    worst = std::max(worst, std::abs(static_cast<double>(d.Evaluate(x)) - g.Evaluate(x)));
  }
  EXPECT_LE(worst, tolerance);
  // Knots are samples: exact there up to float rounding of the value.
  for (int k = 0; k < 150; ++k) {
    const double x = g.start_m + k * g.step_m;
    if (x >= kL20) break;
    EXPECT_NEAR(d.Evaluate(static_cast<float>(x)), g.correction_m[k], 1e-6 * 0.05 + 1e-9) << k;
  }
}

TEST(DenseDistanceCorrectionTest, BoundIsAttainedWithCoarseSamples) {
  // One sample per knot (max step 5 cm): the error is now visible and must stay within
  // h^2/8 max|g''|, and not be far below it (the bound is not vacuous).
  const DistanceCorrection g = Wiggle();
  const DenseDistanceCorrection d = DenseDistanceCorrection::Resample(g, kL20, 0.05);
  EXPECT_NEAR(d.step_m, 0.05, 1e-15);
  double worst = 0.0;
  for (double x = 0.3; x < 7.4; x += 1e-4) {
    worst = std::max(
        worst, std::abs(d.Evaluate(static_cast<float>(x)) - g.Evaluate(static_cast<float>(x))));
  }
  EXPECT_LE(worst, d.max_interpolation_error_m + 1e-6);
  EXPECT_GE(worst, 0.1 * d.max_interpolation_error_m);
}

TEST(DenseDistanceCorrectionTest, EndsHoldLikeTheSpline) {
  DistanceCorrection g;
  g.start_m = 1.0;
  g.step_m = 0.5;
  g.correction_m = {0.01f, -0.02f, 0.03f, 0.0f};  // knots at 1.0 .. 2.5 m
  const DenseDistanceCorrection d = DenseDistanceCorrection::Resample(g, kL20);
  EXPECT_NEAR(d.step_m, 0.5 / 500.0, 1e-15);
  EXPECT_FLOAT_EQ(d.Evaluate(0.0f), 0.01f);  // before the first knot: first value
  EXPECT_FLOAT_EQ(d.Evaluate(0.7f), 0.01f);
  EXPECT_FLOAT_EQ(d.Evaluate(2.5f), 0.0f);  // last knot
  EXPECT_FLOAT_EQ(d.Evaluate(7.0f), 0.0f);  // after it: last value
  EXPECT_FLOAT_EQ(d.Evaluate(1e9f), 0.0f);
  EXPECT_FLOAT_EQ(d.Evaluate(-5.0f), 0.01f);
  EXPECT_FLOAT_EQ(d.Evaluate(std::nanf("")), 0.01f);
  // Knots entirely beyond L: g is the first knot's value on [0, L).
  g.start_m = 8.0;
  const DenseDistanceCorrection beyond = DenseDistanceCorrection::Resample(g, kL20);
  EXPECT_FLOAT_EQ(beyond.Evaluate(0.0f), 0.01f);
  EXPECT_FLOAT_EQ(beyond.Evaluate(7.4f), 0.01f);
  // Bad arguments.
  EXPECT_EQ(CodeOf([&] { (void)DenseDistanceCorrection::Resample(g, 0.0); }),
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(CodeOf([&] { (void)DenseDistanceCorrection::Resample(g, kL20, 0.0); }),
            ErrorCode::kInvalidArgument);
  g.correction_m.resize(1);
  EXPECT_EQ(CodeOf([&] { (void)DenseDistanceCorrection::Resample(g, kL20); }),
            ErrorCode::kInvalidArgument);
}

// The per-pixel loop of ApplyCalibration before the dense table (tofcam 0.1, commit 56766bb):
// eq. 1, then the Catmull-Rom spline evaluated in single precision per pixel. Kept as the
// reference the table is checked against.
void ReferenceCatmullRomCalibration(MetricFrame& frame, const OffsetCalibration& c) {
  const float range = static_cast<float>(kL20);
  const std::size_t n = frame.radial_distance_m.size();
  float* d = frame.radial_distance_m.data();
  const PixelFlags* flags = frame.flags.data();
  const float* o = c.offset_m.data();
  for (std::size_t i = 0; i < n; ++i) {
    float l = d[i] - o[i] + range;
    l -= l >= range ? range : 0.0f;
    l -= l >= range ? range : 0.0f;
    d[i] = flags[i].Has(Flag::kInvalid) ? d[i] : l;
  }
  const DistanceCorrection& g = *c.distance_correction;
  const std::size_t knots = g.correction_m.size();
  std::vector<float> p(knots + 3);
  p[0] = g.correction_m.front();
  std::copy(g.correction_m.begin(), g.correction_m.end(), p.begin() + 1);
  p[knots + 1] = p[knots + 2] = g.correction_m.back();
  const float start = static_cast<float>(g.start_m);
  const float inv_step = static_cast<float>(1.0 / g.step_m);
  const float last = static_cast<float>(knots - 1);
  const int last_segment = static_cast<int>(knots) - 2;
  for (std::size_t i = 0; i < n; ++i) {
    const float l = d[i];
    const float x = std::clamp((l - start) * inv_step, 0.0f, last);
    const int k = std::min(static_cast<int>(x), last_segment);
    const float t = x - static_cast<float>(k);
    const float p0 = p[k], p1 = p[k + 1], p2 = p[k + 2], p3 = p[k + 3];
    const float corr = p1 + 0.5f * t *
                                ((p2 - p0) + t * ((2.0f * p0 - 5.0f * p1 + 4.0f * p2 - p3) +
                                                  t * (3.0f * (p1 - p2) + p3 - p0)));
    float v = l - corr + range;
    v -= v >= range ? range : 0.0f;
    d[i] = flags[i].Has(Flag::kInvalid) ? l : v;
  }
}

TEST(ApplyCalibrationTest, DenseTableAgreesWithTheCatmullRomLoopItReplaced) {
  const int w = 160, h = 124;
  OffsetCalibration c = MakeCalibration(w, h, 0.0f);
  c.distance_correction = Wiggle();
  c.pixel_flags = Image<PixelFlags>(w, h);
  MetricFrame m = MakeFrame(w, h, 0.0f);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> distance(0.0f, static_cast<float>(kL20) * 0.999999f);
  std::uniform_real_distribution<float> offset(-0.3f, 0.3f);
  for (std::size_t i = 0; i < m.radial_distance_m.size(); ++i) {
    m.radial_distance_m[i] = distance(rng);
    c.offset_m[i] = offset(rng);
    if (i % 17 == 0) m.flags[i] = PixelFlags(Flag::kInvalid);
    if (i % 23 == 0) m.flags[i] = PixelFlags(Flag::kSaturated);
    if (i % 29 == 0) c.pixel_flags[i] = PixelFlags(Flag::kInvalid);
  }
  MetricFrame reference = m;
  ReferenceCatmullRomCalibration(reference, c);
  const MetricFrame l = ApplyCalibration(m, c);
  // Tolerance: the table's interpolation bound, the float evaluation of both forms (position
  // rounding 1e-6 m times max |g'|, a few ulps of |g|) and one ulp of l - g + L in [8, 16) m
  // (9.5e-7 m): both forms round that sum to float, so a sub-ulp difference in g can move the
  // result by one ulp there.
  const DenseDistanceCorrection d = DenseDistanceCorrection::Resample(*c.distance_correction, kL20);
  const double ulp_2l = std::ldexp(1.0, 3 - 23);  // float spacing in [8, 16)
  const double tolerance = d.max_interpolation_error_m +
                           SplineMaxSlope(*c.distance_correction, kL20) * 1e-6 + 2e-8 + ulp_2l;
  double worst = 0.0;
  for (std::size_t i = 0; i < m.radial_distance_m.size(); ++i) {
    const float a = l.radial_distance_m[i], b = reference.radial_distance_m[i];
    if (m.flags[i].Has(Flag::kInvalid)) {
      EXPECT_EQ(a, m.radial_distance_m[i]) << i;  // untouched, bit for bit
      continue;
    }
    ASSERT_GE(a, 0.0f) << i;
    ASSERT_LT(a, static_cast<float>(kL20)) << i;
    const double diff = std::abs(static_cast<double>(a) - b);
    worst = std::max(worst, std::min(diff, kL20 - diff));  // either side of the wrap
    EXPECT_EQ(l.flags[i], m.flags[i] | c.pixel_flags[i]) << i;
  }
  EXPECT_LE(worst, tolerance);
  EXPECT_LT(tolerance, 2e-6);  // ~1 µm: far below the millimetres the table corrects
}

void EveryPixelIsEquationOneThenTheTable(const DistanceCorrection& g);

TEST(ApplyCalibrationTest, EveryPixelIsEquationOneThenTheDenseTableBitForBit) {
  // The per-pixel loop (vectorised: AVX-512, AVX2 and baseline forms) must compute exactly
  // eq. 1 followed by l - DenseDistanceCorrection::Evaluate(l) wrapped into [0, L), in single
  // precision. 157 x 123 pixels leave a scalar tail after the vector loop. Two corrections: the
  // wiggle over all of [0, L), and one over 2-4 m only, whose ends hold (the index clamps).
  DistanceCorrection short_range;
  short_range.start_m = 2.0;
  short_range.step_m = 0.05;
  for (int k = 0; k <= 40; ++k) short_range.correction_m.push_back(0.01f * std::sin(0.7f * k));
  // Both forms of the vector loop where the CPU has AVX-512 (16 and 8 pixels a step).
  for (const bool portable : {false, true}) {
    const internal::PortableFormsForTesting forms(portable);
    for (const DistanceCorrection& g : {Wiggle(), short_range}) {
      SCOPED_TRACE(testing::Message() << "start " << g.start_m << ", portable " << portable);
      EveryPixelIsEquationOneThenTheTable(g);
    }
  }
}

void EveryPixelIsEquationOneThenTheTable(const DistanceCorrection& g) {
  const int w = 157, h = 123;
  OffsetCalibration c = MakeCalibration(w, h, 0.0f);
  c.distance_correction = g;
  // The calibration's own flags are OR-ed in (in the vector loop and in its tail); its kInvalid
  // does not stop the correction: only the frame's flags before the OR decide that.
  c.pixel_flags = Image<PixelFlags>(w, h);
  MetricFrame m = MakeFrame(w, h, 0.0f);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> distance(0.0f, static_cast<float>(kL20) * 0.999999f);
  std::uniform_real_distribution<float> offset(-0.5f, 0.5f);
  for (std::size_t i = 0; i < m.radial_distance_m.size(); ++i) {
    m.radial_distance_m[i] = distance(rng);
    c.offset_m[i] = offset(rng);
    if (i % 13 == 0) m.flags[i] = PixelFlags(Flag::kInvalid);
    if (i % 7 == 0) c.pixel_flags[i] = PixelFlags(Flag::kInvalid);
    if (i % 11 == 0) c.pixel_flags[i].Set(Flag::kSaturated);
  }
  m.radial_distance_m[5] = std::nanf("");  // not invalid: NaN in, NaN out, no stray read
  const MetricFrame l = ApplyCalibration(m, c);
  const DenseDistanceCorrection d = DenseDistanceCorrection::Resample(*c.distance_correction, kL20);
  const float range = static_cast<float>(kL20);
  for (std::size_t i = 0; i < m.radial_distance_m.size(); ++i) {
    float expected = m.radial_distance_m[i];
    if (!m.flags[i].Has(Flag::kInvalid)) {
      float e1 = m.radial_distance_m[i] - c.offset_m[i] + range;
      e1 -= e1 >= range ? range : 0.0f;
      e1 -= e1 >= range ? range : 0.0f;
      expected = e1 - d.Evaluate(e1) + range;
      expected -= expected >= range ? range : 0.0f;
    }
    if (std::isnan(expected)) {
      EXPECT_TRUE(std::isnan(l.radial_distance_m[i])) << i;
    } else {
      ASSERT_EQ(l.radial_distance_m[i], expected) << i;
    }
    ASSERT_EQ(l.flags[i], m.flags[i] | c.pixel_flags[i]) << i;
  }
}

TEST(OffsetCalibrationTest, ValidateNamesTheProblem) {
  EXPECT_NO_THROW(MakeCalibration(3, 2, 0.1f).Validate());
  const auto message = [](const OffsetCalibration& c) {
    try {
      c.Validate();
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
      return std::string(e.what());
    }
    return std::string("no error");
  };
  OffsetCalibration c = MakeCalibration(3, 2, 0.1f);
  c.offset_m(1, 2) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(message(c).find("row 1, col 2"), std::string::npos) << message(c);
  c = MakeCalibration(3, 2, 4.0f);  // beyond L / 2
  EXPECT_NE(message(c).find("L/2"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.width = 4;
  EXPECT_NE(message(c).find("header says 4x2"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.version = OffsetCalibration::kVersion + 1;
  EXPECT_NE(message(c).find("version " + std::to_string(OffsetCalibration::kVersion + 1)),
            std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.scattering = ScatteringCalibration{};  // no lobes
  EXPECT_NE(message(c).find("scattering"), std::string::npos) << message(c);
  c = MakeCalibration(3, 2, 0.0f);
  c.modulation_frequency_hz = 0.0;
  EXPECT_NE(message(c).find("modulation_frequency_hz"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.distance_correction = DistanceCorrection{0.0, 0.0, {0.0f, 0.0f}};
  EXPECT_NE(message(c).find("step_m"), std::string::npos);
  c.distance_correction = DistanceCorrection{0.0, 0.1, {0.0f}};
  EXPECT_NE(message(c).find("knots"), std::string::npos);
  c.distance_correction =
      DistanceCorrection{0.0, 0.1, {0.0f, std::numeric_limits<float>::infinity()}};
  EXPECT_NE(message(c).find("correction_m[1]"), std::string::npos);
  c = MakeCalibration(3, 2, 0.0f);
  c.pixel_flags = Image<PixelFlags>(2, 2);
  EXPECT_NE(message(c).find("pixel_flags"), std::string::npos);
}

}  // namespace
}  // namespace tofcam

namespace tofcam {
namespace {

TEST(ExposureOffsetTest, EquationOneWithTheExposureTermHandValues) {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = 3;
  c.height = 1;
  c.offset_m = Image<float>(3, 1, 0.0f);
  c.integration_time_us = 5100.0;  // register 20 at 255 us
  c.exposure_offset_m_per_ms = 0.0005;
  MetricFrame m;
  m.radial_distance_m = Image<float>(3, 1, 0.0f);
  m.amplitude = Image<float>(3, 1, 1000.0f);
  m.intensity = Image<float>(3, 1, 5000.0f);
  m.flags = Image<PixelFlags>(3, 1);
  m.info.integration_time_us = 25500.0;  // register 100: t - t_cal = 20.4 ms -> 10.2 mm
  m.radial_distance_m(0, 0) = 2.0f;
  c.offset_m(0, 0) = 0.05f;  // 2.0 - 0.05 - 0.0102 = 1.9398
  m.radial_distance_m(0, 1) = 0.005f;
  c.offset_m(0, 1) = 0.0f;  // 0.005 - 0.0102 wraps: 7.49481145 - 0.0052 = 7.48961145
  m.radial_distance_m(0, 2) = 3.0f;
  m.flags(0, 2) = PixelFlags(Flag::kInvalid);  // untouched
  EXPECT_NEAR(ExposureShiftM(c, 25500.0), 0.0102, 1e-12);
  const MetricFrame l = ApplyCalibration(m, c);
  EXPECT_NEAR(l.radial_distance_m(0, 0), 1.9398, 2e-6);
  EXPECT_NEAR(l.radial_distance_m(0, 1), 7.48961145, 2e-6);
  EXPECT_FLOAT_EQ(l.radial_distance_m(0, 2), 3.0f);

  // At the calibration's own integration time, and when the frame's is unknown (0, e.g. an
  // imported camera), the term vanishes: plain eq. 1.
  for (const double t : {5100.0, 0.0}) {
    m.info.integration_time_us = t;
    EXPECT_EQ(ExposureShiftM(c, t), 0.0);
    const MetricFrame same = ApplyCalibration(m, c);
    EXPECT_NEAR(same.radial_distance_m(0, 0), 1.95, 2e-6) << t;
    EXPECT_NEAR(same.radial_distance_m(0, 1), 0.005, 2e-6) << t;
  }
  // Shorter than at calibration: the camera read short, so the term adds distance.
  m.info.integration_time_us = 1020.0;  // -4.08 ms -> -2.04 mm
  EXPECT_NEAR(ApplyCalibration(m, c).radial_distance_m(0, 0), 1.95204, 2e-6);
}

TEST(ExposureOffsetTest, ValidatesTheSlopeAndAbsurdShifts) {
  OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = 1;
  c.height = 1;
  c.offset_m = Image<float>(1, 1, 0.0f);
  c.exposure_offset_m_per_ms = 0.2;  // beyond ±0.1 m/ms
  EXPECT_THROW(c.Validate(), Error);
  c.exposure_offset_m_per_ms = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(c.Validate(), Error);
  c.exposure_offset_m_per_ms = 0.1;
  // s (t - t_cal) needs t_cal: without it every frame would shift by s t.
  try {
    c.Validate();
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("integration_time_us"), std::string::npos) << e.what();
  }
  c.integration_time_us = 1000.0;
  EXPECT_NO_THROW(c.Validate());
  MetricFrame m;
  m.radial_distance_m = Image<float>(1, 1, 1.0f);
  m.amplitude = Image<float>(1, 1, 1000.0f);
  m.flags = Image<PixelFlags>(1, 1);
  m.info.integration_time_us = 30000.0;  // 0.1 m/ms x (30 - 1) ms = 2.9 m > L/4
  try {
    (void)ApplyCalibration(m, c);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("beyond L/4"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tofcam
