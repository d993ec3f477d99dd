// Statistical and radius outlier removal (PCL / Open3D definitions) on a nanoflann kd-tree.
#include "tofcam/experiments/cloud_outliers.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <nanoflann.hpp>
#include <string>

#include "tofcam/core/error.h"

namespace tofcam::experiments {
namespace {

// nanoflann's dataset adaptor over the point vector.
struct CloudAdaptor {
  const std::vector<CloudPoint>& points;
  [[nodiscard]] std::size_t kdtree_get_point_count() const { return points.size(); }
  [[nodiscard]] float kdtree_get_pt(std::size_t index, std::size_t dim) const {
    return points[index][dim];
  }
  template <class BoundingBox>
  bool kdtree_get_bbox(BoundingBox& /*bb*/) const {
    return false;  // let nanoflann compute it
  }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, CloudAdaptor>,
                                        CloudAdaptor, 3, std::uint32_t>;

// Counts the points strictly within a squared radius and stops the search at `cap` + 1 (the
// query point itself is among them).
class CountWithin {
 public:
  CountWithin(float radius_sq, std::size_t cap) : radius_sq_(radius_sq), cap_(cap) {}
  void init() { count_ = 0; }
  [[nodiscard]] std::size_t size() const { return count_; }
  [[nodiscard]] bool full() const { return true; }
  bool addPoint(float dist_sq, std::uint32_t /*index*/) {
    if (dist_sq < radius_sq_) ++count_;
    return count_ <= cap_;  // false ends the search
  }
  [[nodiscard]] float worstDist() const { return radius_sq_; }

 private:
  float radius_sq_;
  std::size_t cap_;
  std::size_t count_ = 0;
};

}  // namespace

std::vector<double> KnnMeanDistances(const std::vector<CloudPoint>& points, int k) {
  if (k < 1)
    throw Error(ErrorCode::kInvalidArgument, "SOR k must be >= 1, got " + std::to_string(k));
  std::vector<double> mean(points.size(), 0.0);
  if (points.size() < 2) return mean;
  const CloudAdaptor adaptor{points};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const std::size_t want = std::min<std::size_t>(static_cast<std::size_t>(k) + 1, points.size());
  std::vector<std::uint32_t> index(want);
  std::vector<float> dist_sq(want);
  for (std::size_t p = 0; p < points.size(); ++p) {
    const std::size_t found = tree.knnSearch(points[p].data(), want, index.data(), dist_sq.data());
    // Skip the point itself; with duplicates it need not come first, and when it is missing
    // from the result (more than k duplicates) the farthest result is dropped instead.
    std::size_t skip = found - 1;
    for (std::size_t j = 0; j < found; ++j) {
      if (index[j] == p) {
        skip = j;
        break;
      }
    }
    double sum = 0.0;
    for (std::size_t j = 0; j < found; ++j) {
      if (j != skip) sum += std::sqrt(static_cast<double>(dist_sq[j]));
    }
    mean[p] = found > 1 ? sum / static_cast<double>(found - 1) : 0.0;
  }
  return mean;
}

std::vector<bool> StatisticalOutliers(const std::vector<double>& mean_distances, double std_mul) {
  std::vector<bool> out(mean_distances.size(), false);
  const std::size_t n = mean_distances.size();
  if (n < 2) return out;
  double sum = 0.0, sum_sq = 0.0;
  for (double v : mean_distances) {
    sum += v;
    sum_sq += v * v;
  }
  const double mean = sum / static_cast<double>(n);
  const double variance =
      std::max(0.0, (sum_sq - sum * sum / static_cast<double>(n)) / static_cast<double>(n - 1));
  const double threshold = mean + std_mul * std::sqrt(variance);
  for (std::size_t p = 0; p < n; ++p) out[p] = mean_distances[p] > threshold;
  return out;
}

std::vector<int> RadiusNeighbourCounts(const std::vector<CloudPoint>& points, double radius_m,
                                       int cap) {
  if (!(radius_m > 0) || cap < 1) {
    throw Error(ErrorCode::kInvalidArgument,
                "radius outlier removal needs radius > 0 and cap >= 1, got " +
                    std::to_string(radius_m) + " and " + std::to_string(cap));
  }
  std::vector<int> counts(points.size(), 0);
  if (points.size() < 2) return counts;
  const CloudAdaptor adaptor{points};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const auto radius_sq = static_cast<float>(radius_m * radius_m);
  CountWithin counter(radius_sq, static_cast<std::size_t>(cap));
  for (std::size_t p = 0; p < points.size(); ++p) {
    counter.init();
    tree.findNeighbors(counter, points[p].data(), nanoflann::SearchParams(32, 0.0f, false));
    // The point itself is always within the radius (distance 0).
    counts[p] = static_cast<int>(std::min<std::size_t>(counter.size() - 1, cap));
  }
  return counts;
}

std::vector<bool> RadiusOutliers(const std::vector<int>& counts, int min_neighbours) {
  std::vector<bool> out(counts.size(), false);
  for (std::size_t p = 0; p < counts.size(); ++p) out[p] = counts[p] < min_neighbours;
  return out;
}

}  // namespace tofcam::experiments
