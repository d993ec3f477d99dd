#include "filters/kth_smallest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

namespace tofcam::filters_internal {
namespace {

// The value std::nth_element gives, on a copy.
double Reference(std::vector<double> v, std::size_t k) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// Random values, many ties, sorted and reversed runs, and orders that put the sample's
// bracket beside the k-th value (the sampled elements larger than all others) so that the
// fallback runs: every k the frame pair and other callers could ask for must give
// std::nth_element's value exactly.
TEST(KthSmallestTest, EqualsNthElementForEveryInputKind) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_int_distribution<int> small(0, 9);
  for (const std::size_t n : {1u, 2u, 100u, 16383u, 16384u, 20000u, 307200u}) {
    std::vector<std::vector<double>> inputs(5, std::vector<double>(n));
    for (std::size_t i = 0; i < n; ++i) {
      inputs[0][i] = normal(rng);
      inputs[1][i] = small(rng);  // ties everywhere
      inputs[2][i] = static_cast<double>(i);
      inputs[3][i] = -static_cast<double>(i);
      inputs[4][i] = normal(rng);
    }
    // Every sampled element (stride n / 1024) above all others: the bracket misses.
    if (n >= 16384) {
      for (std::size_t i = 0; i < 1024; ++i) inputs[4][i * (n / 1024)] = 100.0 + normal(rng);
    }
    for (std::size_t kind = 0; kind < inputs.size(); ++kind) {
      for (const std::size_t k : {std::size_t{0}, n / 4, n / 2, n - 1}) {
        std::vector<double> v = inputs[kind];
        EXPECT_EQ(KthSmallest(v, k), Reference(inputs[kind], k))
            << "n " << n << " kind " << kind << " k " << k;
      }
    }
  }
}

}  // namespace
}  // namespace tofcam::filters_internal
