// ros2_probe: an independent ROS 2 subscriber for the loopback tests. It uses only the Cyclone
// DDS C API and the idlc-generated types (not tofcam::ros2's conversions): it receives
// `--count` PointCloud2 samples on rt<ns>/points and the first CameraInfo on rt<ns>/camera_info
// and writes them as they came to --out:
//   clouds.txt       one line per cloud: stamp_ns height width point_step row_step is_dense
//                    is_bigendian fields (name:offset:datatype:count,...) data_bytes
//   cloud_<k>.bin    the cloud's data bytes
//   camera_info.txt  width height distortion_model, then k (9 numbers), then d
// --send-register R / --send-target T: after the first cloud, publish R on
// <ns>/controller/integration_register (std_msgs/Int32) / T on <ns>/controller/target_intensity
// (std_msgs/Float64), reliable, as `ros2 topic pub` does.
// Exit status 0 when everything arrived, 3 on a timeout (message on stderr), 2 on bad usage.
#include <dds/dds.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "std_msgs/msg/Float64.h"
#include "std_msgs/msg/Int32.h"

namespace {

struct Args {
  int domain = -1;
  std::string name_space = "/tofcam";
  int count = 1;
  double timeout_s = 20.0;
  bool reliable = false;
  std::string out;
  int send_register = -1;
  double send_target = -1.0;
};

bool Parse(int argc, char** argv, Args& a) {
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    const char* v = argv[i + 1];
    if (k == "--domain") {
      a.domain = std::atoi(v);
    } else if (k == "--namespace") {
      a.name_space = v;
    } else if (k == "--count") {
      a.count = std::atoi(v);
    } else if (k == "--timeout-s") {
      a.timeout_s = std::atof(v);
    } else if (k == "--reliable") {
      a.reliable = std::string(v) == "1";
    } else if (k == "--out") {
      a.out = v;
    } else if (k == "--send-register") {
      a.send_register = std::atoi(v);
    } else if (k == "--send-target") {
      a.send_target = std::atof(v);
    } else {
      return false;
    }
  }
  return a.domain >= 0 && a.count >= 1 && !a.out.empty() && argc % 2 == 1;
}

std::string Topic(const std::string& ns, const char* name) {
  return "rt" + (ns == "/" ? std::string("/") : ns + "/") + name;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!Parse(argc, argv, a)) {
    std::fprintf(stderr,
                 "usage: ros2_probe --domain N --out DIR [--namespace /ns] [--count N] "
                 "[--timeout-s S] [--reliable 0|1]\n");
    return 2;
  }
  const dds_entity_t participant = dds_create_participant(a.domain, nullptr, nullptr);
  if (participant < 0) {
    std::fprintf(stderr, "ros2_probe: participant: %s\n", dds_strretcode(participant));
    return 3;
  }
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, a.reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_MSECS(100));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  const dds_entity_t cloud_topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__PointCloud2__desc,
                       Topic(a.name_space, "points").c_str(), nullptr, nullptr);
  const dds_entity_t info_topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__CameraInfo__desc,
                       Topic(a.name_space, "camera_info").c_str(), nullptr, nullptr);
  const dds_entity_t clouds = dds_create_reader(participant, cloud_topic, qos, nullptr);
  const dds_entity_t infos = dds_create_reader(participant, info_topic, qos, nullptr);
  dds_delete_qos(qos);
  if (clouds < 0 || infos < 0) {
    std::fprintf(stderr, "ros2_probe: readers failed\n");
    return 3;
  }
  const dds_entity_t waitset = dds_create_waitset(participant);
  dds_waitset_attach(waitset, dds_create_readcondition(clouds, DDS_ANY_STATE), 0);
  dds_waitset_attach(waitset, dds_create_readcondition(infos, DDS_ANY_STATE), 1);

  std::FILE* list = std::fopen((a.out + "/clouds.txt").c_str(), "w");
  if (list == nullptr) {
    std::fprintf(stderr, "ros2_probe: cannot write %s\n", a.out.c_str());
    return 2;
  }
  // Command writers (created up front so discovery happens while the clouds flow).
  dds_qos_t* command_qos = dds_create_qos();
  dds_qset_reliability(command_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(command_qos, DDS_HISTORY_KEEP_LAST, 7);
  dds_entity_t register_writer = 0, target_writer = 0;
  if (a.send_register >= 0) {
    const dds_entity_t t = dds_create_topic(
        participant, &std_msgs_msg_dds__Int32__desc,
        Topic(a.name_space, "controller/integration_register").c_str(), nullptr, nullptr);
    register_writer = dds_create_writer(participant, t, command_qos, nullptr);
  }
  if (a.send_target >= 0) {
    const dds_entity_t t = dds_create_topic(
        participant, &std_msgs_msg_dds__Float64__desc,
        Topic(a.name_space, "controller/target_intensity").c_str(), nullptr, nullptr);
    target_writer = dds_create_writer(participant, t, command_qos, nullptr);
  }
  dds_delete_qos(command_qos);
  bool sent = false;
  int received = 0;
  bool have_info = false;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(a.timeout_s);
  while (received < a.count || !have_info) {
    const double left =
        std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
    if (left <= 0) break;
    dds_waitset_wait(waitset, nullptr, 0, static_cast<dds_duration_t>(left * 1e9));
    void* samples[1] = {nullptr};
    dds_sample_info_t info;
    while (received < a.count && dds_take(clouds, samples, &info, 1, 1) > 0) {
      const auto* c = static_cast<const sensor_msgs_msg_dds__PointCloud2_*>(samples[0]);
      if (info.valid_data) {
        std::fprintf(
            list, "%lld %u %u %u %u %d %d ",
            static_cast<long long>(c->header.stamp.sec) * 1000000000LL + c->header.stamp.nanosec,
            c->height, c->width, c->point_step, c->row_step, c->is_dense ? 1 : 0,
            c->is_bigendian ? 1 : 0);
        for (std::uint32_t f = 0; f < c->fields._length; ++f) {
          const auto& field = c->fields._buffer[f];
          std::fprintf(list, "%s%s:%u:%u:%u", f ? "," : "", field.name, field.offset,
                       field.datatype, field.count);
        }
        std::fprintf(list, " %u\n", c->data._length);
        const std::string path = a.out + "/cloud_" + std::to_string(received) + ".bin";
        std::FILE* bin = std::fopen(path.c_str(), "wb");
        if (bin == nullptr ||
            std::fwrite(c->data._buffer, 1, c->data._length, bin) != c->data._length) {
          std::fprintf(stderr, "ros2_probe: cannot write %s\n", path.c_str());
          return 2;
        }
        std::fclose(bin);
        ++received;
      }
      dds_return_loan(clouds, samples, 1);
      samples[0] = nullptr;
    }
    if (received > 0 && !sent) {
      sent = true;
      for (dds_entity_t w : {register_writer, target_writer}) {
        if (w <= 0) continue;
        dds_publication_matched_status_t st{};
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (dds_get_publication_matched_status(w, &st) >= 0 && st.current_count < 1 &&
               std::chrono::steady_clock::now() < until) {
          dds_sleepfor(DDS_MSECS(5));
        }
      }
      if (register_writer > 0) {
        const std_msgs_msg_dds__Int32_ m{a.send_register};
        dds_write(register_writer, &m);
      }
      if (target_writer > 0) {
        const std_msgs_msg_dds__Float64_ m{a.send_target};
        dds_write(target_writer, &m);
      }
    }
    while (dds_take(infos, samples, &info, 1, 1) > 0) {
      const auto* ci = static_cast<const sensor_msgs_msg_dds__CameraInfo_*>(samples[0]);
      if (info.valid_data && !have_info) {
        std::FILE* f = std::fopen((a.out + "/camera_info.txt").c_str(), "w");
        if (f == nullptr) return 2;
        std::fprintf(f, "%u %u %s\n", ci->width, ci->height, ci->distortion_model);
        for (double k : ci->k) std::fprintf(f, "%.17g ", k);
        std::fprintf(f, "\n");
        for (std::uint32_t i = 0; i < ci->d._length; ++i) {
          std::fprintf(f, "%.17g ", ci->d._buffer[i]);
        }
        std::fprintf(f, "\n");
        std::fclose(f);
        have_info = true;
      }
      dds_return_loan(infos, samples, 1);
      samples[0] = nullptr;
    }
  }
  std::fclose(list);
  for (dds_entity_t w : {register_writer, target_writer}) {
    if (w > 0) dds_wait_for_acks(w, DDS_SECS(5));
  }
  dds_delete(participant);
  if (received < a.count || !have_info) {
    std::fprintf(stderr, "ros2_probe: timeout after %.1f s: %d of %d clouds, camera_info %s\n",
                 a.timeout_s, received, a.count, have_info ? "received" : "missing");
    return 3;
  }
  return 0;
}
