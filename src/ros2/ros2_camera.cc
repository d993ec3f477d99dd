#include "tofcam/ros2/ros2_camera.h"

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <utility>

#include "dds_util.h"
#include "tofcam/core/error.h"
#include "tofcam/ros2/publisher.h"

namespace tofcam::ros2 {
namespace {

using dds_internal::Check;
using Clock = std::chrono::steady_clock;

enum Channel { kDepth, kAmplitude, kIntensity, kChannels };

std::string Seconds(double s) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g s", s);
  return buffer;
}

}  // namespace

void Ros2CameraOptions::Validate() const {
  Ros2Options names;
  names.domain_id = domain_id;
  names.name_space = name_space;
  names.history_depth = history_depth;
  names.Validate();
  if (depth_topic.empty() || amplitude_topic.empty() || camera_info_topic.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 camera: depth, amplitude and camera_info "
                "topics must be given");
  }
  if (!(timeout_s > 0.0 && timeout_s <= 3600.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 camera: timeout " + Seconds(timeout_s) + " is not in (0, 3600] s");
  }
  if (!(frame.range_m > 0.0 && frame.range_m <= 1000.0)) {
    throw Error(ErrorCode::kInvalidArgument, "ros2 camera: range_m must be in (0, 1000] m");
  }
}

std::string ResolveTopic(const std::string& name_space, const std::string& topic) {
  if (!topic.empty() && topic.front() == '/') return topic;
  return (name_space == "/" ? std::string("/") : name_space + "/") + topic;
}

struct Ros2Camera::Impl {
  Ros2CameraOptions options;
  dds_internal::Participant participant;
  dds_entity_t readers[kChannels] = {};
  dds_entity_t info_reader = 0;
  dds_entity_t waitset = 0;
  std::array<std::string, 3> names;  // ROS topic names of depth, amplitude, intensity
  std::string info_name;
  tofcam::CameraInfo camera;
  RayTable rays;
  std::map<std::int64_t, ImageMessage> pending[kChannels];
  std::uint64_t received[kChannels] = {};
  std::uint64_t skipped = 0;
  std::string last_skip;
  std::uint64_t sequence = 0;
  std::int64_t first_stamp_ns = 0;
  std::int64_t last_stamp_ns = 0;        // of the last frame served
  std::atomic<bool> interrupted{false};  // Interrupt(): Grab() returns nullopt

  explicit Impl(const Ros2CameraOptions& o) : options(o), participant(o.domain_id) {}

  bool Active(int c) const { return readers[c] != 0; }

  void Skip(const std::string& why) {
    ++skipped;
    last_skip = why;
  }

  // Takes every available image of channel c into `pending`.
  void TakeImages(int c) {
    void* samples[8] = {};
    dds_sample_info_t infos[8];
    int n;
    while ((n = Check(dds_take(readers[c], samples, infos, 8, 8), "ros2 take " + names[c])) > 0) {
      for (int i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        ImageMessage m =
            dds_internal::FromC(*static_cast<const sensor_msgs_msg_dds__Image_*>(samples[i]));
        ++received[c];
        const std::int64_t stamp = m.header.stamp_ns;
        pending[c][stamp] = std::move(m);
      }
      dds_return_loan(readers[c], samples, n);
      for (void*& s : samples) s = nullptr;
    }
    // Unpaired leftovers: keep a bounded window.
    const std::size_t limit = static_cast<std::size_t>(2 * options.history_depth + 2);
    while (pending[c].size() > limit) {
      pending[c].erase(pending[c].begin());
      Skip(names[c] + ": image without a partner on the other topics (dropped)");
    }
  }

  // Takes the available CameraInfo samples; returns the last valid one's intrinsics if any.
  std::optional<CameraIntrinsics> TakeInfo(bool strict) {
    void* samples[4] = {};
    dds_sample_info_t infos[4];
    std::optional<CameraIntrinsics> out;
    int n;
    while ((n = Check(dds_take(info_reader, samples, infos, 4, 4), "ros2 take " + info_name)) > 0) {
      for (int i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        const CameraInfoMessage m =
            dds_internal::FromC(*static_cast<const sensor_msgs_msg_dds__CameraInfo_*>(samples[i]));
        try {
          out = IntrinsicsFromCameraInfo(m, info_name);
        } catch (const Error& e) {
          if (strict) {
            dds_return_loan(info_reader, samples, n);
            throw;
          }
          Skip(e.what());
        }
      }
      dds_return_loan(info_reader, samples, n);
      for (void*& s : samples) s = nullptr;
    }
    return out;
  }

  // The oldest stamp present on every active channel, after dropping older unpaired images.
  std::optional<Frame> Assemble() {
    while (!pending[kDepth].empty()) {
      const std::int64_t stamp = pending[kDepth].begin()->first;
      bool complete = true;
      for (int c = kAmplitude; c < kChannels; ++c) {
        if (Active(c) && pending[c].find(stamp) == pending[c].end()) complete = false;
      }
      if (!complete) {
        // A newer depth image complete on every channel means this one's partners are lost.
        bool newer_complete = false;
        for (auto it = std::next(pending[kDepth].begin()); it != pending[kDepth].end(); ++it) {
          bool all = true;
          for (int c = kAmplitude; c < kChannels; ++c) {
            if (Active(c) && pending[c].find(it->first) == pending[c].end()) all = false;
          }
          if (all) newer_complete = true;
        }
        if (!newer_complete) return std::nullopt;
        pending[kDepth].erase(pending[kDepth].begin());
        Skip(names[kDepth] + ": image without a partner on the other topics (dropped)");
        continue;
      }
      ImageMessage depth = std::move(pending[kDepth].begin()->second);
      pending[kDepth].erase(pending[kDepth].begin());
      std::optional<ImageMessage> parts[kChannels];
      for (int c = kAmplitude; c < kChannels; ++c) {
        if (!Active(c)) continue;
        auto it = pending[c].find(stamp);
        parts[c] = std::move(it->second);
        // Anything older on this channel can no longer pair.
        pending[c].erase(pending[c].begin(), std::next(it));
      }
      if (sequence > 0 && stamp <= last_stamp_ns) {
        // Served frames' timestamps only grow (a recording refuses anything else): a frame
        // stamped at or before the last one (a restarted publisher, a clock set back) is
        // skipped, and the stream goes on once the stamps pass the last frame's.
        Skip(names[kDepth] + ": stamp " + std::to_string(stamp) +
             " ns is not after the previous frame's " + std::to_string(last_stamp_ns) +
             " ns (publisher restarted or its clock went back?)");
        continue;
      }
      try {
        Frame f = FrameFromImages(depth, *parts[kAmplitude],
                                  parts[kIntensity] ? &*parts[kIntensity] : nullptr, rays,
                                  options.frame, names);
        if (sequence == 0) first_stamp_ns = stamp;
        f.info.sequence = sequence++;
        f.info.timestamp_ns = stamp - first_stamp_ns;
        last_stamp_ns = stamp;
        return f;
      } catch (const Error& e) {
        Skip(e.what());
      }
    }
    return std::nullopt;
  }

  std::string Seen() const {
    std::string s;
    for (int c = 0; c < kChannels; ++c) {
      if (!Active(c)) continue;
      s += (s.empty() ? "" : ", ") + names[c] + " " + std::to_string(received[c]);
    }
    s += " images";
    if (skipped > 0) s += "; skipped " + std::to_string(skipped) + ", last: " + last_skip;
    return s;
  }
};

Ros2Camera::Ros2Camera(const Ros2CameraOptions& options) {
  options.Validate();
  impl_ = std::make_unique<Impl>(options);
  Impl& m = *impl_;
  const dds_entity_t p = m.participant.get();
  const auto qos = dds_internal::MakeQos(options.reliable, options.history_depth);
  const std::string topics[kChannels] = {options.depth_topic, options.amplitude_topic,
                                         options.intensity_topic};
  m.waitset = Check(dds_create_waitset(p), "ros2 waitset");
  for (int c = 0; c < kChannels; ++c) {
    if (topics[c].empty()) continue;
    m.names[c] = ResolveTopic(options.name_space, topics[c]);
    m.readers[c] = dds_internal::CreateReader(p, &sensor_msgs_msg_dds__Image__desc,
                                              "rt" + m.names[c], qos.get());
    Check(dds_waitset_attach(m.waitset, dds_create_readcondition(m.readers[c], DDS_ANY_STATE), c),
          "ros2 waitset");
  }
  m.info_name = ResolveTopic(options.name_space, options.camera_info_topic);
  m.info_reader = dds_internal::CreateReader(p, &sensor_msgs_msg_dds__CameraInfo__desc,
                                             "rt" + m.info_name, qos.get());
  const dds_entity_t info_ws = Check(dds_create_waitset(p), "ros2 waitset");
  Check(dds_waitset_attach(info_ws, dds_create_readcondition(m.info_reader, DDS_ANY_STATE), 0),
        "ros2 waitset");
  const auto deadline = Clock::now() + std::chrono::duration<double>(options.timeout_s);
  std::optional<CameraIntrinsics> intrinsics;
  while (!intrinsics) {
    const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
    if (left <= 0) {
      throw Error(ErrorCode::kNotFound,
                  "ros2: no CameraInfo on " + m.info_name + " within " +
                      Seconds(options.timeout_s) + " in DDS domain " +
                      std::to_string(options.domain_id) +
                      " (is the driver running, in this domain, with this namespace?)");
    }
    Check(dds_waitset_wait(info_ws, nullptr, 0, dds_internal::Seconds(left)), "ros2 wait");
    intrinsics = m.TakeInfo(/*strict=*/true);
  }
  m.camera = RosCameraInfo(*intrinsics, options.frame, !options.intensity_topic.empty());
  m.rays = MakeRayTable(*intrinsics);
}

Ros2Camera::~Ros2Camera() = default;

std::optional<Frame> Ros2Camera::Grab() {
  Impl& m = *impl_;
  const auto deadline = Clock::now() + std::chrono::duration<double>(m.options.timeout_s);
  while (true) {
    if (m.interrupted.load()) return std::nullopt;
    for (int c = 0; c < kChannels; ++c) {
      if (m.Active(c)) m.TakeImages(c);
    }
    (void)m.TakeInfo(/*strict=*/false);  // later CameraInfo: checked, not applied
    if (std::optional<Frame> f = m.Assemble()) return f;
    const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
    if (left <= 0) {
      if (m.sequence > 0) return std::nullopt;  // the publisher stopped: end of stream
      throw Error(ErrorCode::kNotFound,
                  "ros2: no complete frame on " + m.names[kDepth] + " + " + m.names[kAmplitude] +
                      (m.Active(kIntensity) ? " + " + m.names[kIntensity] : std::string()) +
                      " within " + Seconds(m.options.timeout_s) + " in DDS domain " +
                      std::to_string(m.options.domain_id) + " (received " + m.Seen() + ")");
    }
    Check(dds_waitset_wait(m.waitset, nullptr, 0, dds_internal::Seconds(std::min(left, 0.5))),
          "ros2 wait");
  }
}

const tofcam::CameraInfo& Ros2Camera::Info() const { return impl_->camera; }

void Ros2Camera::Interrupt() noexcept { impl_->interrupted.store(true); }

namespace {
[[noreturn]] void Unsupported(const std::string& what) {
  throw Error(ErrorCode::kUnsupported,
              "a ROS 2 camera source cannot change " + what + " (it belongs to the driver)");
}
}  // namespace

void Ros2Camera::SetIntegrationTimeRegister(int reg) {
  if (reg != 0) Unsupported("the integration time");
}
void Ros2Camera::SetModulationFrequencyHz(double hz) {
  if (hz != impl_->camera.modulation_frequency_hz) Unsupported("the modulation frequency");
}
void Ros2Camera::SetDistanceOffsetRegister(int reg) {
  if (reg != 0) Unsupported("the distance offset");
}
void Ros2Camera::SetPanAngleRad(double angle_rad) {
  if (angle_rad != 0.0) Unsupported("the pan angle");
}

std::uint64_t Ros2Camera::skipped() const noexcept { return impl_->skipped; }
const std::string& Ros2Camera::last_skip() const noexcept { return impl_->last_skip; }

}  // namespace tofcam::ros2

namespace tofcam::ros2 {
namespace {

double ParseNumber(const std::string& key, const std::string& value) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != value.size() || value.empty()) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 camera: " + key + "=" + value + " is not a number");
  }
  return v;
}

int ParseInt(const std::string& key, const std::string& value) {
  const double v = ParseNumber(key, value);
  if (v != std::floor(v) || std::abs(v) > 1e9) {
    throw Error(ErrorCode::kInvalidArgument,
                "ros2 camera: " + key + "=" + value + " is not an integer");
  }
  return static_cast<int>(v);
}

// Topic names, depth axis, range and model of the ROS 2 drivers (docs/ros2.md).
void ApplyDriver(const std::string& driver, Ros2CameraOptions& o) {
  if (driver == "tofcam") {
    o.depth_topic = "depth";
    o.amplitude_topic = "amplitude";
    o.camera_info_topic = "camera_info";
    o.frame.depth_is_radial = false;
  } else if (driver == "azure-kinect") {
    // Azure_Kinect_ROS_Driver: depth/image_raw 16UC1 mm (z), ir/image_raw 16UC1.
    o.depth_topic = "depth/image_raw";
    o.amplitude_topic = "ir/image_raw";
    o.camera_info_topic = "depth/camera_info";
    o.frame.depth_is_radial = false;
    o.frame.range_m = 8.192;
    o.frame.model = "Azure Kinect";
  } else if (driver == "ifm3d") {
    // ifm3d-ros2: distance (radial), amplitude, camera_info under /ifm3d/camera.
    o.depth_topic = "distance";
    o.amplitude_topic = "amplitude";
    o.camera_info_topic = "camera_info";
    o.frame.depth_is_radial = true;
    o.frame.range_m = 32.768;
    o.frame.model = "ifm O3D3xx";
  } else if (driver == "royale") {
    // pmd Royale's ROS sample: depth_image 32FC1 (z), gray_image mono16, camera_info.
    o.depth_topic = "depth_image";
    o.amplitude_topic = "gray_image";
    o.camera_info_topic = "camera_info";
    o.frame.depth_is_radial = false;
    o.frame.range_m = 8.192;
    o.frame.model = "pmd Royale";
  } else {
    throw Error(ErrorCode::kInvalidArgument, "ros2 camera: driver '" + driver +
                                                 "' is not one of tofcam, azure-kinect, ifm3d, "
                                                 "royale");
  }
}

}  // namespace

Ros2CameraOptions ParseRos2CameraSpec(const std::string& spec, int domain_id) {
  Ros2CameraOptions o;
  o.domain_id = domain_id;
  const auto q = spec.find('?');
  o.name_space = spec.substr(0, q);
  if (o.name_space.empty()) o.name_space = "/";
  if (o.name_space.front() != '/') o.name_space = "/" + o.name_space;
  std::vector<std::pair<std::string, std::string>> pairs;
  if (q != std::string::npos) {
    const std::string rest = spec.substr(q + 1);
    std::size_t start = 0;
    while (start <= rest.size()) {
      const auto amp = rest.find('&', start);
      const std::string kv =
          rest.substr(start, amp == std::string::npos ? std::string::npos : amp - start);
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == kv.size()) {
        throw Error(ErrorCode::kInvalidArgument,
                    "ros2 camera '" + spec + "': expected key=value, got '" + kv + "'");
      }
      pairs.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
      if (amp == std::string::npos) break;
      start = amp + 1;
    }
  }
  for (const auto& [key, value] : pairs) {
    if (key == "driver") ApplyDriver(value, o);
  }
  for (const auto& [key, value] : pairs) {
    if (key == "driver") {
      continue;
    } else if (key == "depth") {
      o.depth_topic = value;
    } else if (key == "amplitude") {
      o.amplitude_topic = value;
    } else if (key == "intensity") {
      o.intensity_topic = value == "none" ? std::string() : value;
    } else if (key == "camera_info") {
      o.camera_info_topic = value;
    } else if (key == "depth_axis") {
      if (value != "z" && value != "radial") {
        throw Error(ErrorCode::kInvalidArgument,
                    "ros2 camera: depth_axis=" + value + " is not z or radial");
      }
      o.frame.depth_is_radial = value == "radial";
    } else if (key == "range_m") {
      o.frame.range_m = ParseNumber(key, value);
    } else if (key == "model") {
      o.frame.model = value;
    } else if (key == "timeout_s") {
      o.timeout_s = ParseNumber(key, value);
    } else if (key == "reliable") {
      if (value != "0" && value != "1") {
        throw Error(ErrorCode::kInvalidArgument,
                    "ros2 camera: reliable=" + value + " is not 0 or 1");
      }
      o.reliable = value == "1";
    } else if (key == "history") {
      o.history_depth = ParseInt(key, value);
    } else if (key == "domain") {
      o.domain_id = ParseInt(key, value);
    } else {
      throw Error(ErrorCode::kInvalidArgument,
                  "ros2 camera: unknown key '" + key +
                      "' (driver, depth, amplitude, intensity, camera_info, depth_axis, range_m, "
                      "model, timeout_s, reliable, history, domain)");
    }
  }
  o.Validate();
  return o;
}

}  // namespace tofcam::ros2
