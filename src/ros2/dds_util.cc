#include "dds_util.h"

#include <algorithm>
#include <cmath>

#include "tofcam/core/error.h"

namespace tofcam::ros2::dds_internal {
namespace {

char* Str(const std::string& s) { return const_cast<char*>(s.c_str()); }
std::string Str(const char* s) { return s == nullptr ? std::string() : std::string(s); }

template <typename Seq, typename T>
void Alias(Seq& seq, const T* data, std::size_t n) {
  seq._maximum = static_cast<std::uint32_t>(n);
  seq._length = static_cast<std::uint32_t>(n);
  seq._buffer = const_cast<T*>(data);
  seq._release = false;
}

}  // namespace

dds_return_t Check(dds_return_t rc, const std::string& what) {
  if (rc < 0) throw Error(ErrorCode::kIo, what + ": DDS error: " + dds_strretcode(rc));
  return rc;
}

Participant::Participant(int domain_id) {
  if (domain_id < 0 || domain_id > 232) {
    throw Error(ErrorCode::kInvalidArgument,
                "DDS domain " + std::to_string(domain_id) + " is not in 0..232");
  }
  handle_ =
      Check(dds_create_participant(static_cast<dds_domainid_t>(domain_id), nullptr, nullptr),
            "DDS participant in domain " + std::to_string(domain_id) + " (check CYCLONEDDS_URI)");
}

Participant::~Participant() {
  if (handle_ > 0) dds_delete(handle_);
}

std::unique_ptr<dds_qos_t, QosDeleter> MakeQos(bool reliable, int depth) {
  std::unique_ptr<dds_qos_t, QosDeleter> q(dds_create_qos());
  dds_qset_reliability(q.get(), reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_MSECS(100));
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, depth);
  dds_qset_durability(q.get(), DDS_DURABILITY_VOLATILE);
  return q;
}

dds_entity_t CreateWriter(dds_entity_t participant, const dds_topic_descriptor_t* descriptor,
                          const std::string& topic, const dds_qos_t* qos) {
  const dds_entity_t t =
      Check(dds_create_topic(participant, descriptor, topic.c_str(), nullptr, nullptr),
            "DDS topic " + topic);
  return Check(dds_create_writer(participant, t, qos, nullptr), "DDS writer on " + topic);
}

dds_entity_t CreateReader(dds_entity_t participant, const dds_topic_descriptor_t* descriptor,
                          const std::string& topic, const dds_qos_t* qos) {
  const dds_entity_t t =
      Check(dds_create_topic(participant, descriptor, topic.c_str(), nullptr, nullptr),
            "DDS topic " + topic);
  return Check(dds_create_reader(participant, t, qos, nullptr), "DDS reader on " + topic);
}

void ToC(const Header& in, std_msgs_msg_dds__Header_& out) {
  const std::int64_t sec = in.stamp_ns >= 0 ? in.stamp_ns / 1000000000 : -1;
  if (sec < 0 || sec > 2147483647) {
    throw Error(ErrorCode::kInvalidArgument,
                "stamp " + std::to_string(in.stamp_ns) + " ns is outside builtin_interfaces/Time");
  }
  out.stamp.sec = static_cast<std::int32_t>(sec);
  out.stamp.nanosec = static_cast<std::uint32_t>(in.stamp_ns - sec * 1000000000);
  out.frame_id = Str(in.frame_id);
}

Header FromC(const std_msgs_msg_dds__Header_& in) {
  Header h;
  h.stamp_ns = std::int64_t{in.stamp.sec} * 1000000000 + std::int64_t{in.stamp.nanosec};
  h.frame_id = Str(in.frame_id);
  return h;
}

void ToC(const ImageMessage& in, sensor_msgs_msg_dds__Image_& out) {
  ToC(in.header, out.header);
  out.height = in.height;
  out.width = in.width;
  out.encoding = Str(in.encoding);
  out.is_bigendian = in.is_bigendian;
  out.step = in.step;
  Alias(out.data, in.data.data(), in.data.size());
}

void ToC(const CameraInfoMessage& in, sensor_msgs_msg_dds__CameraInfo_& out) {
  ToC(in.header, out.header);
  out.height = in.height;
  out.width = in.width;
  out.distortion_model = Str(in.distortion_model);
  Alias(out.d, in.d.data(), in.d.size());
  std::copy(in.k.begin(), in.k.end(), out.k);
  std::copy(in.r.begin(), in.r.end(), out.r);
  std::copy(in.p.begin(), in.p.end(), out.p);
  out.binning_x = in.binning_x;
  out.binning_y = in.binning_y;
  out.roi = {0, 0, 0, 0, false};
}

void ToC(const PointCloud2Message& in, std::vector<sensor_msgs_msg_dds__PointField_>& fields,
         sensor_msgs_msg_dds__PointCloud2_& out) {
  ToC(in.header, out.header);
  out.height = in.height;
  out.width = in.width;
  fields.resize(in.fields.size());
  for (std::size_t i = 0; i < fields.size(); ++i) {
    const PointFieldMessage& f = in.fields[i];
    fields[i] = {Str(f.name), f.offset, f.datatype, f.count};
  }
  Alias(out.fields, fields.data(), fields.size());
  out.is_bigendian = in.is_bigendian;
  out.point_step = in.point_step;
  out.row_step = in.row_step;
  Alias(out.data, in.data.data(), in.data.size());
  out.is_dense = in.is_dense;
}

void ToC(const DiagnosticArrayMessage& in,
         std::vector<diagnostic_msgs_msg_dds__DiagnosticStatus_>& status,
         std::vector<std::vector<diagnostic_msgs_msg_dds__KeyValue_>>& values,
         diagnostic_msgs_msg_dds__DiagnosticArray_& out) {
  ToC(in.header, out.header);
  status.resize(in.status.size());
  values.resize(in.status.size());
  for (std::size_t i = 0; i < status.size(); ++i) {
    const DiagnosticStatusMessage& s = in.status[i];
    values[i].resize(s.values.size());
    for (std::size_t j = 0; j < s.values.size(); ++j) {
      values[i][j] = {Str(s.values[j].key), Str(s.values[j].value)};
    }
    status[i].level = s.level;
    status[i].name = Str(s.name);
    status[i].message = Str(s.message);
    status[i].hardware_id = Str(s.hardware_id);
    Alias(status[i].values, values[i].data(), values[i].size());
  }
  Alias(out.status, status.data(), status.size());
}

ImageMessage FromC(const sensor_msgs_msg_dds__Image_& in) {
  ImageMessage m;
  m.header = FromC(in.header);
  m.height = in.height;
  m.width = in.width;
  m.encoding = Str(in.encoding);
  m.is_bigendian = in.is_bigendian;
  m.step = in.step;
  m.data.assign(in.data._buffer, in.data._buffer + in.data._length);
  return m;
}

CameraInfoMessage FromC(const sensor_msgs_msg_dds__CameraInfo_& in) {
  CameraInfoMessage m;
  m.header = FromC(in.header);
  m.height = in.height;
  m.width = in.width;
  m.distortion_model = Str(in.distortion_model);
  m.d.assign(in.d._buffer, in.d._buffer + in.d._length);
  std::copy(in.k, in.k + 9, m.k.begin());
  std::copy(in.r, in.r + 9, m.r.begin());
  std::copy(in.p, in.p + 12, m.p.begin());
  m.binning_x = in.binning_x;
  m.binning_y = in.binning_y;
  return m;
}

PointCloud2Message FromC(const sensor_msgs_msg_dds__PointCloud2_& in) {
  PointCloud2Message m;
  m.header = FromC(in.header);
  m.height = in.height;
  m.width = in.width;
  for (std::uint32_t i = 0; i < in.fields._length; ++i) {
    const sensor_msgs_msg_dds__PointField_& f = in.fields._buffer[i];
    m.fields.push_back({Str(f.name), f.offset, f.datatype, f.count});
  }
  m.is_bigendian = in.is_bigendian;
  m.point_step = in.point_step;
  m.row_step = in.row_step;
  m.data.assign(in.data._buffer, in.data._buffer + in.data._length);
  m.is_dense = in.is_dense;
  return m;
}

dds_duration_t Seconds(double s) noexcept {
  if (!(s > 0)) return 0;
  return static_cast<dds_duration_t>(std::min(s, 1e6) * 1e9);
}

}  // namespace tofcam::ros2::dds_internal
