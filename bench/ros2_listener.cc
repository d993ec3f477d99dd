// ros2_listener: the subscriber side of scripts/ros2_bench.py (docs/benchmarks.md, ROS 2). Takes
// PointCloud2 samples on rt<ns>/points and Image samples on rt<ns>/depth (best effort, keep
// last 5, as a ROS 2 sensor subscriber; --reliable 1 for a reliable reader) for --seconds, then
// prints one JSON line: samples per topic, and the transport latency (take time - the writer's
// source timestamp, same machine clock) mean / p50 / p99 / max in ms, and this process's CPU time.
#include <dds/dds.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"

namespace {

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

}  // namespace

int main(int argc, char** argv) {
  int domain = -1;
  double seconds = 10.0;
  std::string ns = "/tofcam";
  bool reliable = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--domain") domain = std::atoi(argv[i + 1]);
    if (k == "--seconds") seconds = std::atof(argv[i + 1]);
    if (k == "--namespace") ns = argv[i + 1];
    if (k == "--reliable") reliable = std::string(argv[i + 1]) == "1";
  }
  if (domain < 0) {
    std::fprintf(
        stderr,
        "usage: ros2_listener --domain N [--namespace /ns] [--seconds S] [--reliable 0|1]\n");
    return 2;
  }
  const dds_entity_t p = dds_create_participant(domain, nullptr, nullptr);
  if (p < 0) return 3;
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_MSECS(100));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 5);
  const std::string prefix = "rt" + (ns == "/" ? std::string("/") : ns + "/");
  const dds_entity_t points =
      dds_create_reader(p,
                        dds_create_topic(p, &sensor_msgs_msg_dds__PointCloud2__desc,
                                         (prefix + "points").c_str(), nullptr, nullptr),
                        qos, nullptr);
  const dds_entity_t depth =
      dds_create_reader(p,
                        dds_create_topic(p, &sensor_msgs_msg_dds__Image__desc,
                                         (prefix + "depth").c_str(), nullptr, nullptr),
                        qos, nullptr);
  dds_delete_qos(qos);
  const dds_entity_t ws = dds_create_waitset(p);
  dds_waitset_attach(ws, dds_create_readcondition(points, DDS_ANY_STATE), 0);
  dds_waitset_attach(ws, dds_create_readcondition(depth, DDS_ANY_STATE), 1);
  std::vector<double> latency_ms[2];
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    dds_waitset_wait(ws, nullptr, 0, DDS_MSECS(100));
    const dds_entity_t readers[2] = {points, depth};
    for (int r = 0; r < 2; ++r) {
      void* samples[8] = {};
      dds_sample_info_t infos[8];
      const int n = dds_take(readers[r], samples, infos, 8, 8);
      const dds_time_t now = dds_time();
      for (int i = 0; i < n; ++i) {
        if (infos[i].valid_data) {
          latency_ms[r].push_back(static_cast<double>(now - infos[i].source_timestamp) * 1e-6);
        }
      }
      if (n > 0) dds_return_loan(readers[r], samples, n);
    }
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const double cpu_s = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                       static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;
  std::printf("{");
  const char* names[2] = {"points", "depth"};
  for (int r = 0; r < 2; ++r) {
    const std::vector<double>& v = latency_ms[r];
    double mean = 0.0;
    for (double x : v) mean += x;
    mean = v.empty() ? 0.0 : mean / static_cast<double>(v.size());
    std::printf(
        "\"%s\": {\"samples\": %zu, \"latency_ms_mean\": %.3f, \"latency_ms_p50\": %.3f, "
        "\"latency_ms_p99\": %.3f, \"latency_ms_max\": %.3f}, ",
        names[r], v.size(), mean, Percentile(v, 0.5), Percentile(v, 0.99),
        v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()));
  }
  std::printf("\"cpu_s\": %.3f}\n", cpu_s);
  dds_delete(p);
  return 0;
}
