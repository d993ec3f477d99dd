#pragma once
/// \file
/// ROS 2 messages as plain C++ values, and the conversions between them and tofcam's types.
/// No DDS here: tofcam/ros2/publisher.h and tofcam/ros2/ros2_camera.h move these over Cyclone
/// DDS with the IDL in src/ros2/idl (docs/ros2.md). The structs mirror the ROS 2 Humble
/// interface definitions field by field; stamps are one signed 64-bit count of nanoseconds.
///
/// Conventions (REP 103, REP 117, REP 118): the optical frame is x right, y down, z forward, as
/// tofcam's camera frame; depth images hold z along the optical axis (32FC1 in m with NaN for
/// no value, 16UC1 in mm with 0 for no value); point clouds are organised, NaN for no value.

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "tofcam/cloud/point_cloud.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/rgb.h"

namespace tofcam::ros2 {

/// sensor_msgs/PointField datatypes (the message's constants; not on the wire).
inline constexpr std::uint8_t kPointFieldInt8 = 1;
inline constexpr std::uint8_t kPointFieldUint8 = 2;
inline constexpr std::uint8_t kPointFieldInt16 = 3;
inline constexpr std::uint8_t kPointFieldUint16 = 4;
inline constexpr std::uint8_t kPointFieldInt32 = 5;
inline constexpr std::uint8_t kPointFieldUint32 = 6;
inline constexpr std::uint8_t kPointFieldFloat32 = 7;
inline constexpr std::uint8_t kPointFieldFloat64 = 8;

/// diagnostic_msgs/DiagnosticStatus levels.
inline constexpr std::uint8_t kDiagnosticOk = 0;
inline constexpr std::uint8_t kDiagnosticWarn = 1;
inline constexpr std::uint8_t kDiagnosticError = 2;

/// std_msgs/Header with builtin_interfaces/Time as nanoseconds since the epoch.
struct Header {
  std::int64_t stamp_ns = 0;  ///< >= 0 and < 2^31 s (builtin_interfaces/Time: int32 sec).
  std::string frame_id;
};

/// sensor_msgs/Image.
struct ImageMessage {
  Header header;
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  std::string encoding;  ///< "32FC1", "16UC1", "mono16", "rgb8", ... (sensor_msgs image_encodings)
  std::uint8_t is_bigendian = 0;
  std::uint32_t step = 0;  ///< Bytes per row (>= width x bytes per pixel).
  std::vector<std::uint8_t> data;
};

/// sensor_msgs/CameraInfo (binning and ROI are sent as 0 / the full image).
struct CameraInfoMessage {
  Header header;
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  std::string distortion_model;  ///< "plumb_bob" (d: k1 k2 p1 p2 k3) or "rational_polynomial"
                                 ///< (d: k1 k2 p1 p2 k3 k4 k5 k6); "" or "none" for no d.
  std::vector<double> d;
  std::array<double, 9> k{};   ///< Row-major 3 x 3 camera matrix, px.
  std::array<double, 9> r{};   ///< Rectification rotation (identity for a monocular camera).
  std::array<double, 12> p{};  ///< Row-major 3 x 4 projection matrix, px.
  std::uint32_t binning_x = 0;
  std::uint32_t binning_y = 0;
};

/// sensor_msgs/PointField.
struct PointFieldMessage {
  std::string name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
  std::uint32_t count = 1;
};

/// sensor_msgs/PointCloud2.
struct PointCloud2Message {
  Header header;
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  std::vector<PointFieldMessage> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0;
  std::uint32_t row_step = 0;
  std::vector<std::uint8_t> data;
  bool is_dense = false;
};

/// diagnostic_msgs/KeyValue, DiagnosticStatus, DiagnosticArray.
struct KeyValueMessage {
  std::string key;
  std::string value;
};
struct DiagnosticStatusMessage {
  std::uint8_t level = kDiagnosticOk;
  std::string name;
  std::string message;
  std::string hardware_id;
  std::vector<KeyValueMessage> values;
};
struct DiagnosticArrayMessage {
  Header header;
  std::vector<DiagnosticStatusMessage> status;
};

// --- tofcam -> ROS 2 -------------------------------------------------------------------------

/// Bytes per point of MakePointCloud2: x y z amplitude delta_l (float32) and flags (uint32).
inline constexpr std::uint32_t kPointStepBytes = 24;

/// The organised cloud as PointCloud2 (height x width of the cloud, little-endian): fields x, y,
/// z (float32, m, NaN for no position), amplitude (float32, register units), delta_l (float32,
/// m, NaN when not computed), flags (uint32, tofcam PixelFlags bits); is_dense false. Reuses
/// `out`'s buffers. Throws Error(kInvalidArgument) for an inconsistent cloud.
void MakePointCloud2Into(const PointCloud& cloud, const Header& header, PointCloud2Message& out);

/// The cloud's z (m, along the optical axis; NaN for no position) as a 32FC1 depth image.
void MakeDepthImageInto(const PointCloud& cloud, const Header& header, ImageMessage& out);
/// The cloud's z as a 16UC1 depth image in mm (rounded; 0 for no position or z outside
/// (0, 65.535] m).
void MakeDepthMmImageInto(const PointCloud& cloud, const Header& header, ImageMessage& out);
/// A register-unit channel (amplitude, intensity) as 16UC1: rounded, clamped to [0, 65535],
/// 0 for NaN.
void MakeMono16ImageInto(const Image<float>& channel, const Header& header, ImageMessage& out);
/// An RGB image as rgb8.
void MakeRgb8ImageInto(const Image<Rgb8>& image, const Header& header, ImageMessage& out);

/// CameraInfo of the intrinsics: K = [fx 0 cx; 0 fy cy; 0 0 1], R = I, P = [K | 0];
/// "plumb_bob" (k1 k2 p1 p2 k3) when k4 = k5 = k6 = 0, else "rational_polynomial" (k1 k2 p1 p2
/// k3 k4 k5 k6). tofcam's pixel convention (centre of pixel (0, 0) at (0, 0)) is ROS's.
[[nodiscard]] CameraInfoMessage MakeCameraInfo(const CameraIntrinsics& intrinsics,
                                               const Header& header);

// --- ROS 2 -> tofcam -------------------------------------------------------------------------

/// The intrinsics a CameraInfo states. Throws Error(kFormat) naming `what` and the field for
/// non-finite or non-positive K, a size of 0, a distortion model other than plumb_bob /
/// rational_polynomial / none with the right number of coefficients, or non-finite d.
[[nodiscard]] CameraIntrinsics IntrinsicsFromCameraInfo(const CameraInfoMessage& info,
                                                        const std::string& what);

/// How ROS depth images become tofcam registers (the importers' conventions, docs/importers.md).
struct RosFrameOptions {
  /// Unambiguous range L of the register encoding, m, (0, 1000]: register = distance x 65536 /
  /// L. 8.192 m gives register = 8 x mm, as the ADI and Azure Kinect importers.
  double range_m = 8.192;
  /// False (REP 118): the depth image holds z along the optical axis, converted to radial
  /// distance with each pixel's ray. True: it holds radial distance (ifm3d's "distance").
  bool depth_is_radial = false;
  std::string model = "ROS 2";  ///< CameraInfo::model and FrameInfo::camera_model.
};

/// CameraInfo of a ROS 2 source: the intrinsics, L's modulation frequency, no settable
/// integration time (registers 0), intensity when the source has an intensity topic.
[[nodiscard]] tofcam::CameraInfo RosCameraInfo(const CameraIntrinsics& intrinsics,
                                               const RosFrameOptions& options, bool has_intensity);

/// Checks an Image against the expected size and the encodings `allowed` (e.g. {"16UC1",
/// "32FC1"}): known encoding, is_bigendian 0 or 1, step >= width x bytes per pixel, data size
/// == step x height. Throws Error(kFormat) naming `what` and the problem.
void CheckImage(const ImageMessage& image, std::uint32_t width, std::uint32_t height,
                const std::vector<std::string_view>& allowed, const std::string& what);

/// A tofcam Frame from ROS images of one instant, with the importers' rules: depth (16UC1 mm or
/// 32FC1 m; 0, NaN or beyond L -> kInvalid, register 0) converted with `rays` from z to radial
/// unless options.depth_is_radial; amplitude (16UC1 / mono16 / 32FC1) clamped at 65532 with
/// kSaturated above, kInvalid for NaN or < 0; intensity likewise when `intensity` is not null
/// (else zeros and has_intensity false). `rays` must be the camera's (MakeRayTable). Timestamp
/// and sequence are the caller's. Throws Error(kFormat) naming the topic for a malformed image
/// (see CheckImage) or one whose size is not the rays'.
[[nodiscard]] Frame FrameFromImages(const ImageMessage& depth, const ImageMessage& amplitude,
                                    const ImageMessage* intensity, const RayTable& rays,
                                    const RosFrameOptions& options,
                                    const std::array<std::string, 3>& topic_names);

}  // namespace tofcam::ros2
