#pragma once
// An exact k-th smallest value faster than std::nth_element on large inputs (internal to the
// filters; the frame pair's median amplitude ratio).

#include <algorithm>
#include <cstddef>
#include <vector>

namespace tofcam::filters_internal {

// The k-th smallest value of `v` (reordered; 0 <= k < v.size(); no NaN), exactly
// std::nth_element's. Large inputs first bracket it between two quantiles of a sample of 1024
// evenly spaced elements (±64 sample ranks: four standard deviations of the k-th value's sample
// rank for values in random order), count the values below the bracket and select within it,
// about an eighth of the values. Where the k-th value falls outside the bracket (values in an
// order that fools the sample) the whole vector is selected. In the frame pair at 640x480 the
// selection went from 18 % of the combination's time to 2 % (perf, docs/benchmarks.md).
inline double KthSmallest(std::vector<double>& v, std::size_t k) {
  constexpr std::size_t kSample = 1024, kMargin = 64;
  const std::size_t n = v.size();
  if (n >= 16 * kSample) {
    thread_local std::vector<double> sample, inside;
    sample.resize(kSample);
    const std::size_t step = n / kSample;
    for (std::size_t i = 0; i < kSample; ++i) sample[i] = v[i * step];
    const std::size_t at = std::min(kSample - 1, k / step);  // k's rank in the sample
    const std::size_t lo_rank = at > kMargin ? at - kMargin : 0;
    const std::size_t hi_rank = std::min(kSample - 1, at + kMargin);
    std::nth_element(sample.begin(), sample.begin() + static_cast<std::ptrdiff_t>(lo_rank),
                     sample.end());
    const double lo = sample[lo_rank];
    std::nth_element(sample.begin() + static_cast<std::ptrdiff_t>(lo_rank),
                     sample.begin() + static_cast<std::ptrdiff_t>(hi_rank), sample.end());
    const double hi = sample[hi_rank];
    std::size_t below = 0;
    inside.clear();
    for (const double x : v) {
      below += x < lo ? 1 : 0;
      if (x >= lo && x <= hi) inside.push_back(x);
    }
    if (below <= k && k - below < inside.size()) {
      const auto mid = inside.begin() + static_cast<std::ptrdiff_t>(k - below);
      std::nth_element(inside.begin(), mid, inside.end());
      return *mid;
    }
  }
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(k);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace tofcam::filters_internal
