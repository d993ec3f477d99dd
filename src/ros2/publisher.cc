#include "tofcam/ros2/publisher.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>
#include <vector>

#include "dds_util.h"
#include "tofcam/core/error.h"
#include "tofcam/ros2/messages.h"

namespace tofcam::ros2 {
namespace {

using dds_internal::Check;
using dds_internal::ToC;

bool ValidNamespace(std::string_view ns) {
  if (ns == "/") return true;
  if (ns.size() < 2 || ns.front() != '/' || ns.back() == '/') return false;
  char previous = '/';
  for (char c : ns.substr(1)) {
    const bool word =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
    if (!word && c != '/') return false;
    if (c == '/' && previous == '/') return false;
    previous = c;
  }
  return true;
}

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "nan";
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%.*f", digits, v);
  return buffer;
}

}  // namespace

void Ros2Options::Validate() const {
  if (domain_id < 0 || domain_id > 232) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 domain " + std::to_string(domain_id) + " is not in 0..232");
  }
  if (!ValidNamespace(name_space)) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 namespace '" + name_space +
                    "' must be '/' or '/name[/name...]' (letters, digits, '_')");
  }
  if (frame_id.empty()) throw Error(ErrorCode::kInvalidArgument, "ros2 frame_id is empty");
  if (history_depth < 1 || history_depth > 1000) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 history_depth " + std::to_string(history_depth) + " is not in 1..1000");
  }
}

std::string DdsTopicName(std::string_view name_space, std::string_view name) {
  std::string topic = "rt";
  topic += name_space;
  if (topic.back() != '/') topic += '/';
  topic += name;
  return topic;
}

enum Topic { kPoints, kDepth, kDepthMm, kAmplitude, kIntensity, kFalseColor, kInfo, kDiag, kCount };

struct Ros2Publisher::Impl {
  Ros2Options options;
  tofcam::CameraInfo camera;
  dds_internal::Participant participant;
  dds_entity_t writers[kCount] = {};
  dds_entity_t target_reader = 0;
  dds_entity_t register_reader = 0;
  bool started = false;
  std::int64_t wall0_ns = 0;
  std::int64_t first_timestamp_ns = 0;
  std::int64_t last_timestamp_ns = 0;
  std::int64_t last_stamp_ns = 0;
  std::uint64_t published = 0;
  std::uint64_t rejected = 0;
  // Reused between frames.
  PointCloud2Message cloud;
  std::vector<sensor_msgs_msg_dds__PointField_> fields;
  ImageMessage images[kCount];
  CameraInfoMessage info;

  Impl(const Ros2Options& o, const tofcam::CameraInfo& c)
      : options(o), camera(c), participant(o.domain_id) {}

  void Write(Topic t, const void* sample) { Check(dds_write(writers[t], sample), "ros2 publish"); }

  void WriteImage(Topic t) {
    sensor_msgs_msg_dds__Image_ c{};
    ToC(images[t], c);
    Write(t, &c);
  }
};

Ros2Publisher::Ros2Publisher(const Ros2Options& options, const tofcam::CameraInfo& camera) {
  options.Validate();
  impl_ = std::make_unique<Impl>(options, camera);
  Impl& m = *impl_;
  const dds_entity_t p = m.participant.get();
  const auto qos = dds_internal::MakeQos(options.reliable, options.history_depth);
  const std::string& ns = options.name_space;
  auto writer = [&](Topic t, const dds_topic_descriptor_t* d, const char* name) {
    m.writers[t] = dds_internal::CreateWriter(p, d, DdsTopicName(ns, name), qos.get());
  };
  writer(kPoints, &sensor_msgs_msg_dds__PointCloud2__desc, "points");
  writer(kDepth, &sensor_msgs_msg_dds__Image__desc, "depth");
  writer(kDepthMm, &sensor_msgs_msg_dds__Image__desc, "depth/mm");
  writer(kAmplitude, &sensor_msgs_msg_dds__Image__desc, "amplitude");
  if (camera.has_intensity) writer(kIntensity, &sensor_msgs_msg_dds__Image__desc, "intensity");
  writer(kFalseColor, &sensor_msgs_msg_dds__Image__desc, "false_color");
  writer(kInfo, &sensor_msgs_msg_dds__CameraInfo__desc, "camera_info");
  writer(kDiag, &diagnostic_msgs_msg_dds__DiagnosticArray__desc, "diagnostics");
  // Commands: reliable, as `ros2 topic pub` sends by default.
  const auto command_qos = dds_internal::MakeQos(true, 10);
  m.target_reader = dds_internal::CreateReader(p, &std_msgs_msg_dds__Float64__desc,
                                               DdsTopicName(ns, "controller/target_intensity"),
                                               command_qos.get());
  m.register_reader = dds_internal::CreateReader(
      p, &std_msgs_msg_dds__Int32__desc, DdsTopicName(ns, "controller/integration_register"),
      command_qos.get());
  m.info = MakeCameraInfo(camera.intrinsics, {});
}

Ros2Publisher::~Ros2Publisher() = default;

void Ros2Publisher::Publish(const PipelineResult& result, const Image<Rgb8>& false_color,
                            const Ros2ControllerState& controller) {
  Impl& m = *impl_;
  const MetricFrame& frame = result.frame;
  // Anchor the camera's clock to the wall clock at the first frame, and again when the camera's
  // timestamps go backwards (a looping playback), so stamps never decrease.
  if (!m.started || frame.info.timestamp_ns <= m.last_timestamp_ns) {
    const std::int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                    std::chrono::system_clock::now().time_since_epoch())
                                    .count();
    m.wall0_ns = m.started ? std::max(now_ns, m.last_stamp_ns + 1) : now_ns;
    m.first_timestamp_ns = frame.info.timestamp_ns;
    m.started = true;
  }
  m.last_timestamp_ns = frame.info.timestamp_ns;
  const Header header{m.wall0_ns + (frame.info.timestamp_ns - m.first_timestamp_ns),
                      m.options.frame_id};
  m.last_stamp_ns = header.stamp_ns;
  if (!result.cloud.empty()) {
    MakePointCloud2Into(result.cloud, header, m.cloud);
    sensor_msgs_msg_dds__PointCloud2_ c{};
    ToC(m.cloud, m.fields, c);
    m.Write(kPoints, &c);
    MakeDepthImageInto(result.cloud, header, m.images[kDepth]);
    m.WriteImage(kDepth);
    MakeDepthMmImageInto(result.cloud, header, m.images[kDepthMm]);
    m.WriteImage(kDepthMm);
  }
  MakeMono16ImageInto(frame.amplitude, header, m.images[kAmplitude]);
  m.WriteImage(kAmplitude);
  if (m.writers[kIntensity] != 0 && frame.has_intensity()) {
    MakeMono16ImageInto(frame.intensity, header, m.images[kIntensity]);
    m.WriteImage(kIntensity);
  }
  if (!false_color.empty()) {
    MakeRgb8ImageInto(false_color, header, m.images[kFalseColor]);
    m.WriteImage(kFalseColor);
  }
  {
    m.info.header = header;
    sensor_msgs_msg_dds__CameraInfo_ c{};
    ToC(m.info, c);
    m.Write(kInfo, &c);
  }
  {
    const FrameStats& s = result.stats;
    DiagnosticArrayMessage d;
    d.header = header;
    DiagnosticStatusMessage status;
    status.name = "tofcam: camera";
    status.hardware_id = m.camera.model;
    status.level = s.kept_pixels > 0 ? kDiagnosticOk : kDiagnosticWarn;
    status.message = s.kept_pixels > 0 ? "ok" : "no valid pixels";
    status.values = {
        {"frame", std::to_string(s.sequence)},
        {"integration_register", std::to_string(s.integration_time_register)},
        {"integration_time_us", Fixed(s.integration_time_us, 1)},
        {"mean_intensity", Fixed(s.mean_intensity, 1)},
        {"valid_percent", Fixed(s.valid_fraction * 100.0, 2)},
        {"mean_delta_l_m", Fixed(s.mean_delta_l_m, 6)},
        {"controller", controller.name.empty() ? "none" : controller.name},
        {"target_intensity", Fixed(controller.target_intensity, 1)},
        {"next_integration_register", std::to_string(controller.next_integration_register)}};
    d.status.push_back(std::move(status));
    std::vector<diagnostic_msgs_msg_dds__DiagnosticStatus_> cs;
    std::vector<std::vector<diagnostic_msgs_msg_dds__KeyValue_>> cv;
    diagnostic_msgs_msg_dds__DiagnosticArray_ c{};
    ToC(d, cs, cv, c);
    m.Write(kDiag, &c);
  }
  ++m.published;
}

int Ros2Publisher::MatchedSubscribers() const {
  int most = 0;
  for (dds_entity_t w : impl_->writers) {
    if (w == 0) continue;
    dds_publication_matched_status_t st{};
    Check(dds_get_publication_matched_status(w, &st), "ros2 matched status");
    most = std::max(most, static_cast<int>(st.current_count));
  }
  return most;
}

bool Ros2Publisher::WaitForSubscribers(int count, double timeout_s) {
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(std::max(timeout_s, 0.0));
  while (MatchedSubscribers() < count) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

void Ros2Publisher::Flush(double timeout_s) {
  if (!impl_->options.reliable) return;
  for (dds_entity_t w : impl_->writers) {
    // A timeout here means a reader stopped acknowledging: nothing left to do about it.
    if (w != 0) dds_wait_for_acks(w, dds_internal::Seconds(timeout_s));
  }
}

Ros2Commands Ros2Publisher::TakeCommands() {
  Impl& m = *impl_;
  Ros2Commands out;
  constexpr int kMax = 16;
  void* samples[kMax] = {};
  dds_sample_info_t infos[kMax];
  int n = Check(dds_take(m.target_reader, samples, infos, kMax, kMax), "ros2 command");
  for (int i = 0; i < n; ++i) {
    if (!infos[i].valid_data) continue;
    const double v = static_cast<const std_msgs_msg_dds__Float64_*>(samples[i])->data;
    if (std::isfinite(v)) {
      out.target_intensity = v;
    } else {
      ++m.rejected;
    }
  }
  if (n > 0) dds_return_loan(m.target_reader, samples, n);
  void* registers[kMax] = {};
  n = Check(dds_take(m.register_reader, registers, infos, kMax, kMax), "ros2 command");
  for (int i = 0; i < n; ++i) {
    if (infos[i].valid_data) {
      out.integration_register = static_cast<const std_msgs_msg_dds__Int32_*>(registers[i])->data;
    }
  }
  if (n > 0) dds_return_loan(m.register_reader, registers, n);
  return out;
}

std::uint64_t Ros2Publisher::rejected_commands() const noexcept { return impl_->rejected; }
std::uint64_t Ros2Publisher::published_frames() const noexcept { return impl_->published; }

}  // namespace tofcam::ros2
