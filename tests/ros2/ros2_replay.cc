// ros2_replay: publishes a recorded Azure Kinect frame (tests/data/real/azure_kinect) as the
// Azure Kinect ROS 2 driver does: <ns>/depth/image_raw (16UC1, mm along z), <ns>/ir/image_raw
// (16UC1) and <ns>/depth/camera_info (rational_polynomial, from the factory calibration.json),
// --frames times with stamps 1/30 s apart. The raw files' bytes go on the wire as they are.
// For the bad-input tests: --bad-at K --bad-kind encoding|step makes frame K's depth image
// malformed; --nan-intrinsics 1 sends K[0] = NaN. Waits for a subscriber first (--wait-s).
// Exit status 0 when everything was sent, 3 when no subscriber came, 2 on bad usage.
#include <dds/dds.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/Image.h"
#include "tofcam/io/importers.h"

namespace {

std::string Read(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string Topic(const std::string& ns, const char* name) {
  return "rt" + (ns == "/" ? std::string("/") : ns + "/") + name;
}

}  // namespace

int main(int argc, char** argv) {
  int domain = -1, frames = 1, bad_at = -1, nan_intrinsics = 0, reliable = 1;
  double wait_s = 30.0;
  std::string ns = "/azure", dir, bad_kind = "encoding";
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const std::string v = argv[i + 1];
    if (k == "--domain") {
      domain = std::atoi(v.c_str());
    } else if (k == "--namespace") {
      ns = v;
    } else if (k == "--azure-dir") {
      dir = v;
    } else if (k == "--frames") {
      frames = std::atoi(v.c_str());
    } else if (k == "--bad-at") {
      bad_at = std::atoi(v.c_str());
    } else if (k == "--bad-kind") {
      bad_kind = v;
    } else if (k == "--nan-intrinsics") {
      nan_intrinsics = std::atoi(v.c_str());
    } else if (k == "--reliable") {
      reliable = std::atoi(v.c_str());
    } else if (k == "--wait-s") {
      wait_s = std::atof(v.c_str());
    } else {
      std::fprintf(stderr, "ros2_replay: unknown option %s\n", k.c_str());
      return 2;
    }
  }
  if (domain < 0 || dir.empty() || frames < 1 || argc % 2 != 1) {
    std::fprintf(stderr,
                 "usage: ros2_replay --domain N --azure-dir DIR [--namespace /ns] "
                 "[--frames N] [--bad-at K --bad-kind encoding|step] "
                 "[--nan-intrinsics 0|1] [--reliable 0|1] [--wait-s S]\n");
    return 2;
  }
  constexpr int kWidth = 640, kHeight = 576;
  std::string depth = Read(std::filesystem::path(dir) / "depth_640x576_u16le.bin");
  std::string ir = Read(std::filesystem::path(dir) / "ir_640x576_u16le.bin");
  if (depth.size() != 2u * kWidth * kHeight || ir.size() != depth.size()) {
    std::fprintf(stderr, "ros2_replay: %s: unexpected file sizes\n", dir.c_str());
    return 2;
  }
  const tofcam::CameraIntrinsics k = tofcam::ParseAzureKinectCalibration(
      Read(std::filesystem::path(dir) / "calibration.json"), kWidth, kHeight, "calibration.json");

  const dds_entity_t participant = dds_create_participant(domain, nullptr, nullptr);
  if (participant < 0) return 3;
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 16);
  auto writer = [&](const dds_topic_descriptor_t* d, const char* name) {
    const dds_entity_t t =
        dds_create_topic(participant, d, Topic(ns, name).c_str(), nullptr, nullptr);
    return dds_create_writer(participant, t, qos, nullptr);
  };
  const dds_entity_t depth_w = writer(&sensor_msgs_msg_dds__Image__desc, "depth/image_raw");
  const dds_entity_t ir_w = writer(&sensor_msgs_msg_dds__Image__desc, "ir/image_raw");
  const dds_entity_t info_w = writer(&sensor_msgs_msg_dds__CameraInfo__desc, "depth/camera_info");
  dds_delete_qos(qos);
  if (depth_w < 0 || ir_w < 0 || info_w < 0) return 3;

  // Wait until the subscriber matched every topic.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
  for (dds_entity_t w : {info_w, depth_w, ir_w}) {
    dds_publication_matched_status_t st{};
    while (dds_get_publication_matched_status(w, &st) >= 0 && st.current_count < 1) {
      if (std::chrono::steady_clock::now() > deadline) {
        std::fprintf(stderr, "ros2_replay: no subscriber within %.1f s\n", wait_s);
        return 3;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }

  char frame_id[] = "depth_camera_link";
  sensor_msgs_msg_dds__CameraInfo_ info{};
  char model[] = "rational_polynomial";
  double d[8] = {k.k1, k.k2, k.p1, k.p2, k.k3, k.k4, k.k5, k.k6};
  info.header.frame_id = frame_id;
  info.width = kWidth;
  info.height = kHeight;
  info.distortion_model = model;
  info.d = {8, 8, d, false};
  const double kk[9] = {nan_intrinsics ? NAN : k.fx_px, 0, k.cx_px, 0, k.fy_px, k.cy_px, 0, 0, 1};
  std::copy(kk, kk + 9, info.k);
  const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::copy(r, r + 9, info.r);
  const double p[12] = {k.fx_px, 0, k.cx_px, 0, 0, k.fy_px, k.cy_px, 0, 0, 0, 1, 0};
  std::copy(p, p + 12, info.p);

  char u16[] = "16UC1", bgr8[] = "bgr8";
  const std::int64_t t0 = 1'700'000'000'000'000'000;
  for (int f = 0; f < frames; ++f) {
    const std::int64_t stamp = t0 + f * 33'333'333LL;
    std_msgs_msg_dds__Header_ header{{static_cast<std::int32_t>(stamp / 1'000'000'000),
                                      static_cast<std::uint32_t>(stamp % 1'000'000'000)},
                                     frame_id};
    info.header = header;
    sensor_msgs_msg_dds__Image_ di{};
    di.header = header;
    di.width = kWidth;
    di.height = kHeight;
    di.encoding = u16;
    di.step = 2 * kWidth;
    di.data = {static_cast<std::uint32_t>(depth.size()), static_cast<std::uint32_t>(depth.size()),
               reinterpret_cast<std::uint8_t*>(depth.data()), false};
    sensor_msgs_msg_dds__Image_ ii = di;
    ii.data._buffer = reinterpret_cast<std::uint8_t*>(ir.data());
    if (f == bad_at) {
      if (bad_kind == "encoding") di.encoding = bgr8;
      if (bad_kind == "step") di.step = 2 * kWidth + 2;  // data no longer step x height
    }
    if (dds_write(info_w, &info) < 0 || dds_write(depth_w, &di) < 0 || dds_write(ir_w, &ii) < 0) {
      std::fprintf(stderr, "ros2_replay: write failed\n");
      return 3;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  for (dds_entity_t w : {info_w, depth_w, ir_w}) dds_wait_for_acks(w, DDS_SECS(5));
  dds_delete(participant);
  return 0;
}
