#include "filters/exp_non_positive.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace tofcam::filters_internal {
namespace {

// The error in units in the last place of `want` (the spacing of doubles at |want|).
double Ulps(double got, double want) {
  return std::abs(got - want) / (std::nextafter(want, 2.0 * want + 1.0) - want);
}

// Against glibc's std::exp (documented within 1 ulp of e^x) over the whole range the function
// covers: 10^6 uniform draws in [-700, 0], 10^5 in [-1, 0] where the bilateral's weights mostly
// lie, and the ends. The bound of 4 ulp is the function's documented accuracy: the reduction's
// rounding (k ln 2 in two parts) and about a dozen roundings in the polynomial, each below half
// an ulp of a term of magnitude at most 1.5, plus std::exp's own ulp.
TEST(ExpNonPositiveTest, AgreesWithStdExpWithinFourUlps) {
  std::mt19937_64 rng(3);
  double worst = 0.0;
  const auto check = [&](double x) {
    const double u = Ulps(ExpNonPositive(x), std::exp(x));
    worst = std::max(worst, u);
    ASSERT_LE(u, 4.0) << "x = " << x;
  };
  std::uniform_real_distribution<double> wide(-700.0, 0.0), narrow(-1.0, 0.0);
  for (int i = 0; i < 1000000; ++i) check(wide(rng));
  for (int i = 0; i < 100000; ++i) check(narrow(rng));
  for (const double x : {-700.0, -699.999, -0.5 * std::log(2.0), -std::log(2.0), -1e-300, -1e-17}) {
    check(x);
  }
  RecordProperty("worst_ulps_x100", static_cast<int>(100 * worst));
}

TEST(ExpNonPositiveTest, EndsAndSpecialValues) {
  EXPECT_EQ(ExpNonPositive(0.0), 1.0);
  EXPECT_EQ(ExpNonPositive(-0.0), 1.0);
  EXPECT_EQ(ExpNonPositive(-700.5), 0.0);
  EXPECT_EQ(ExpNonPositive(-1e300), 0.0);
  EXPECT_EQ(ExpNonPositive(-std::numeric_limits<double>::infinity()), 0.0);
  EXPECT_TRUE(std::isnan(ExpNonPositive(std::numeric_limits<double>::quiet_NaN())));
}

}  // namespace
}  // namespace tofcam::filters_internal
