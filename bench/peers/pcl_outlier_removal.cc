// PCL peer for the outlier-removal comparison (issue 7): pcl::StatisticalOutlierRemoval and
// pcl::RadiusOutlierRemoval on the clouds `tofcam bench --export-peers DIR` writes, judged with
// the simulator's ground truth carried in each point (bad = |measured - true| > 5 cm or no true
// surface). Single-threaded (both filters are); the time per frame includes the KD-tree each
// filter builds for its cloud, as a user's call would.
//
// Usage: pcl_outlier_removal DIR [RESOLUTION ...]   (default resolutions: 160x124 640x480)
// Reads DIR/<RESOLUTION>_frame<k>.f32 (float32 rows x, y, z, bad) for k = 0, 1, ... and writes
// DIR/pcl.json (one row per method and resolution, the fields of tofcam_filters.json) and a
// table on stdout. Run through `make bench-peers`.
#include <pcl/filters/radius_outlier_removal.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace {

struct Frame {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud;
  std::vector<bool> bad;
};

std::vector<Frame> Load(const std::string& dir, const std::string& resolution) {
  std::vector<Frame> frames;
  for (int k = 0;; ++k) {
    const std::string path = dir + "/" + resolution + "_frame" + std::to_string(k) + ".f32";
    std::ifstream in(path, std::ios::binary);
    if (!in) break;
    std::vector<float> rows;
    float v[4];
    while (in.read(reinterpret_cast<char*>(v), sizeof v)) rows.insert(rows.end(), v, v + 4);
    Frame f;
    f.cloud.reset(new pcl::PointCloud<pcl::PointXYZ>);
    f.cloud->reserve(rows.size() / 4);
    for (std::size_t i = 0; i + 3 < rows.size(); i += 4) {
      f.cloud->push_back(pcl::PointXYZ(rows[i], rows[i + 1], rows[i + 2]));
      f.bad.push_back(rows[i + 3] > 0.5f);
    }
    frames.push_back(std::move(f));
  }
  return frames;
}

struct Method {
  const char* label;
  bool statistical;
  int k_or_min;          // mean K (statistical) or minimum neighbours in the radius
  double std_or_radius;  // stddev multiplier (statistical) or radius in m
};

// The parameter sets of bench/peers/peer_outlier_removal.py (Open3D), for a like-for-like table.
const Method kMethods[] = {
    {"PCL statistical (k=20, std=2.0)", true, 20, 2.0},
    {"PCL statistical (k=50, std=1.0)", true, 50, 1.0},
    {"PCL radius (r=0.10 m, min 6)", false, 6, 0.10},
    {"PCL radius (r=0.05 m, min 4)", false, 4, 0.05},
};

// Indices of the points the filter keeps.
std::vector<int> Run(const Method& m, const pcl::PointCloud<pcl::PointXYZ>::Ptr& cloud) {
  pcl::Indices kept;
  if (m.statistical) {
    pcl::StatisticalOutlierRemoval<pcl::PointXYZ> f;
    f.setInputCloud(cloud);
    f.setMeanK(m.k_or_min);
    f.setStddevMulThresh(m.std_or_radius);
    f.filter(kept);
  } else {
    pcl::RadiusOutlierRemoval<pcl::PointXYZ> f;
    f.setInputCloud(cloud);
    f.setRadiusSearch(m.std_or_radius);
    f.setMinNeighborsInRadius(m.k_or_min);
    f.filter(kept);
  }
  return std::vector<int>(kept.begin(), kept.end());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: pcl_outlier_removal DIR [RESOLUTION ...]\n";
    return 2;
  }
  const std::string dir = argv[1];
  std::vector<std::string> resolutions(argv + 2, argv + argc);
  if (resolutions.empty()) resolutions = {"160x124", "640x480"};
  std::string json = "[\n";
  bool first = true;
  for (const std::string& res : resolutions) {
    const std::vector<Frame> frames = Load(dir, res);
    if (frames.empty()) {
      std::cerr << "pcl_outlier_removal: no " << res << "_frame*.f32 in " << dir << "\n";
      continue;
    }
    for (const Method& m : kMethods) {
      double total_s = 0.0;
      long long bad = 0, good = 0, bad_removed = 0, good_lost = 0;
      for (const Frame& f : frames) {
        const auto t0 = std::chrono::steady_clock::now();
        const std::vector<int> kept_idx = Run(m, f.cloud);
        total_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::vector<bool> kept(f.bad.size(), false);
        for (int i : kept_idx) kept[static_cast<std::size_t>(i)] = true;
        for (std::size_t i = 0; i < f.bad.size(); ++i) {
          if (f.bad[i]) {
            ++bad;
            bad_removed += kept[i] ? 0 : 1;
          } else {
            ++good;
            good_lost += kept[i] ? 0 : 1;
          }
        }
      }
      const double ms = 1e3 * total_s / static_cast<double>(frames.size());
      std::printf("%-10s %-45s %9.3f %8lld %5.1f%% %8lld %5.1f%%\n", res.c_str(), m.label, ms,
                  bad_removed, 100.0 * bad_removed / std::max(bad, 1LL), good_lost,
                  100.0 * good_lost / std::max(good, 1LL));
      char row[512];
      std::snprintf(row, sizeof row,
                    "%s  {\"method\": \"%s\", \"resolution\": \"%s\", \"frames\": %zu, "
                    "\"ms_per_frame\": %.6f, \"bad_points\": %lld, \"good_points\": %lld, "
                    "\"bad_removed\": %lld, \"good_lost\": %lld}",
                    first ? "" : ",\n", m.label, res.c_str(), frames.size(), ms, bad, good,
                    bad_removed, good_lost);
      json += row;
      first = false;
    }
  }
  json += "\n]\n";
  const std::string out = dir + "/pcl.json";
  std::ofstream(out + ".tmp") << json;
  std::rename((out + ".tmp").c_str(), out.c_str());
  return 0;
}
