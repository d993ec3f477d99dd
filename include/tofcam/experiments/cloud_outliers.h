#pragma once
/// \file
/// Point-cloud outlier removal as PCL and Open3D define it, for the filters experiment (the
/// baselines a user would reach for instead of the paper's accuracy filter, tof-notes §4). Exact
/// neighbour searches on a kd-tree (nanoflann, private to tofcam::experiments). Points are in
/// metres; NaN or infinite coordinates are not allowed.

#include <array>
#include <vector>

namespace tofcam::experiments {

using CloudPoint = std::array<float, 3>;

/// Mean Euclidean distance of every point to its k nearest *other* points (PCL's
/// StatisticalOutlierRemoval statistic: it searches k + 1 and skips the point itself). A cloud
/// with at most k points uses all other points; a single point gets 0. k >= 1, else
/// Error(kInvalidArgument).
[[nodiscard]] std::vector<double> KnnMeanDistances(const std::vector<CloudPoint>& points, int k);

/// Statistical outlier removal on the statistic above: a point is an outlier when its mean
/// distance exceeds mean + std_mul * std over all points (sample standard deviation, n - 1, as
/// PCL and Open3D compute it). Returns one flag per point.
[[nodiscard]] std::vector<bool> StatisticalOutliers(const std::vector<double>& mean_distances,
                                                    double std_mul);

/// Number of other points within `radius_m` (strictly closer) of every point, counted up to
/// `cap` (a search stops there: the radius filter only asks "at least m"). radius_m > 0, cap >=
/// 1, else Error(kInvalidArgument).
[[nodiscard]] std::vector<int> RadiusNeighbourCounts(const std::vector<CloudPoint>& points,
                                                     double radius_m, int cap);

/// Radius outlier removal: a point is an outlier when fewer than `min_neighbours` other points lie
/// within the radius (PCL's RadiusOutlierRemoval with setMinNeighborsInRadius(m); Open3D's
/// remove_radius_outlier counts the point itself, so its nb_points is m + 1). Counts must have
/// been taken with cap >= min_neighbours.
[[nodiscard]] std::vector<bool> RadiusOutliers(const std::vector<int>& counts, int min_neighbours);

}  // namespace tofcam::experiments
