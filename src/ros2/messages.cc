#include "tofcam/ros2/messages.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam::ros2 {
namespace {

constexpr bool kHostBigEndian = std::endian::native == std::endian::big;

void InitImage(ImageMessage& out, const Header& header, int width, int height, const char* encoding,
               std::uint32_t bytes_per_pixel) {
  out.header = header;
  out.width = static_cast<std::uint32_t>(width);
  out.height = static_cast<std::uint32_t>(height);
  out.encoding = encoding;
  out.is_bigendian = kHostBigEndian ? 1 : 0;
  out.step = out.width * bytes_per_pixel;
  out.data.resize(static_cast<std::size_t>(out.step) * out.height);
}

std::uint32_t BytesPerPixel(std::string_view encoding) {
  if (encoding == "32FC1") return 4;
  if (encoding == "16UC1" || encoding == "mono16") return 2;
  if (encoding == "mono8" || encoding == "8UC1") return 1;
  if (encoding == "rgb8" || encoding == "bgr8") return 3;
  return 0;
}

// Pixel i (row-major over width) of a checked image as a double.
struct ImageReader {
  const ImageMessage& image;
  bool swap;  // stored in the other byte order than the host's

  double At(std::uint32_t row, std::uint32_t col) const {
    const std::uint8_t* p = image.data.data() + static_cast<std::size_t>(row) * image.step;
    if (image.encoding == "32FC1") {
      std::uint32_t bits;
      std::memcpy(&bits, p + 4 * static_cast<std::size_t>(col), 4);
      if (swap) bits = __builtin_bswap32(bits);
      return static_cast<double>(std::bit_cast<float>(bits));
    }
    std::uint16_t v;
    std::memcpy(&v, p + 2 * static_cast<std::size_t>(col), 2);
    if (swap) v = __builtin_bswap16(v);
    return v;
  }
};

ImageReader Reader(const ImageMessage& image) {
  return {image, (image.is_bigendian != 0) != kHostBigEndian};
}

// The importers' register rules (src/io/import_util.cc, SetDistanceMm / SetAmplitude).
void SetDistanceMm(Frame& frame, std::size_t i, double mm, double range_m) {
  const double reg = mm * kDistanceRegisterSpan / (range_m * 1000.0);
  if (!(mm > 0) || !(reg < kDistanceRegisterSpan - 0.5)) {
    frame.distance[i] = 0;
    frame.source_flags[i].Set(Flag::kInvalid);
    return;
  }
  frame.distance[i] = static_cast<std::uint16_t>(std::lround(reg));
}

std::uint16_t SignalRegister(double value, PixelFlags& flags) {
  if (!(value >= 0) || !std::isfinite(value)) {
    flags.Set(Flag::kInvalid);
    return 0;
  }
  if (value > kMaxSignalRegister) {
    flags.Set(Flag::kSaturated);
    return kMaxSignalRegister;
  }
  return static_cast<std::uint16_t>(std::lround(value));
}

std::string Num(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.9g", v);
  return buffer;
}

}  // namespace

void MakePointCloud2Into(const PointCloud& cloud, const Header& header, PointCloud2Message& out) {
  cloud.Validate();
  out.header = header;
  out.height = static_cast<std::uint32_t>(cloud.height);
  out.width = static_cast<std::uint32_t>(cloud.width);
  if (out.fields.size() != 6) {
    out.fields = {{"x", 0, kPointFieldFloat32, 1},        {"y", 4, kPointFieldFloat32, 1},
                  {"z", 8, kPointFieldFloat32, 1},        {"amplitude", 12, kPointFieldFloat32, 1},
                  {"delta_l", 16, kPointFieldFloat32, 1}, {"flags", 20, kPointFieldUint32, 1}};
  }
  out.is_bigendian = kHostBigEndian;
  out.point_step = kPointStepBytes;
  out.row_step = kPointStepBytes * out.width;
  out.is_dense = false;
  const std::size_t n = cloud.size();
  out.data.resize(n * kPointStepBytes);
  std::uint8_t* p = out.data.data();
  for (std::size_t i = 0; i < n; ++i, p += kPointStepBytes) {
    const float v[5] = {cloud.x[i], cloud.y[i], cloud.z[i], cloud.amplitude[i], cloud.delta_l_m[i]};
    const std::uint32_t flags = cloud.flags[i].bits();
    std::memcpy(p, v, sizeof v);
    std::memcpy(p + 20, &flags, 4);
  }
}

void MakeDepthImageInto(const PointCloud& cloud, const Header& header, ImageMessage& out) {
  cloud.Validate();
  InitImage(out, header, cloud.width, cloud.height, "32FC1", 4);
  std::memcpy(out.data.data(), cloud.z.data(), cloud.z.size() * sizeof(float));
}

void MakeDepthMmImageInto(const PointCloud& cloud, const Header& header, ImageMessage& out) {
  cloud.Validate();
  InitImage(out, header, cloud.width, cloud.height, "16UC1", 2);
  for (std::size_t i = 0; i < cloud.z.size(); ++i) {
    // Rounded half away from zero (mm >= 0.5 here), without a libm call per pixel.
    const double mm = static_cast<double>(cloud.z[i]) * 1000.0;
    const std::uint16_t v =
        mm >= 0.5 && mm < 65535.5 ? static_cast<std::uint16_t>(mm + 0.5) : std::uint16_t{0};
    std::memcpy(out.data.data() + 2 * i, &v, 2);
  }
}

void MakeMono16ImageInto(const Image<float>& channel, const Header& header, ImageMessage& out) {
  InitImage(out, header, channel.width(), channel.height(), "16UC1", 2);
  for (std::size_t i = 0; i < channel.size(); ++i) {
    // NaN -> 0; else clamped to [0, 65535] and rounded half away from zero (non-negative here).
    const float c = channel[i];
    const float clamped = c >= 0.0f ? (c < 65535.0f ? c : 65535.0f) : 0.0f;
    const std::uint16_t v = static_cast<std::uint16_t>(clamped + 0.5f);
    std::memcpy(out.data.data() + 2 * i, &v, 2);
  }
}

void MakeRgb8ImageInto(const Image<Rgb8>& image, const Header& header, ImageMessage& out) {
  InitImage(out, header, image.width(), image.height(), "rgb8", 3);
  static_assert(sizeof(Rgb8) == 3);
  std::memcpy(out.data.data(), image.data(), image.size() * 3);
}

CameraInfoMessage MakeCameraInfo(const CameraIntrinsics& k, const Header& header) {
  k.Validate();
  CameraInfoMessage m;
  m.header = header;
  m.width = static_cast<std::uint32_t>(k.width);
  m.height = static_cast<std::uint32_t>(k.height);
  if (k.k4 == 0.0 && k.k5 == 0.0 && k.k6 == 0.0) {
    m.distortion_model = "plumb_bob";
    m.d = {k.k1, k.k2, k.p1, k.p2, k.k3};
  } else {
    m.distortion_model = "rational_polynomial";
    m.d = {k.k1, k.k2, k.p1, k.p2, k.k3, k.k4, k.k5, k.k6};
  }
  m.k = {k.fx_px, 0.0, k.cx_px, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 1.0};
  m.r = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  m.p = {k.fx_px, 0.0, k.cx_px, 0.0, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0};
  return m;
}

CameraIntrinsics IntrinsicsFromCameraInfo(const CameraInfoMessage& m, const std::string& what) {
  auto fail = [&](const std::string& problem) {
    throw Error(ErrorCode::kFormat, what + ": " + problem);
  };
  if (m.width == 0 || m.height == 0 || m.width > 65536 || m.height > 65536) {
    fail("size " + std::to_string(m.width) + " x " + std::to_string(m.height) +
         " is not in 1..65536");
  }
  for (std::size_t i = 0; i < m.k.size(); ++i) {
    if (!std::isfinite(m.k[i])) fail("k[" + std::to_string(i) + "] is " + Num(m.k[i]));
  }
  if (!(m.k[0] > 0) || !(m.k[4] > 0)) {
    fail("focal lengths k[0] = " + Num(m.k[0]) + ", k[4] = " + Num(m.k[4]) + " must be > 0");
  }
  if (m.k[1] != 0.0 || m.k[3] != 0.0 || m.k[6] != 0.0 || m.k[7] != 0.0 || m.k[8] != 1.0) {
    fail("k is not [fx 0 cx; 0 fy cy; 0 0 1] (skew or scale not supported)");
  }
  for (std::size_t i = 0; i < m.d.size(); ++i) {
    if (!std::isfinite(m.d[i])) fail("d[" + std::to_string(i) + "] is " + Num(m.d[i]));
  }
  CameraIntrinsics k;
  k.width = static_cast<int>(m.width);
  k.height = static_cast<int>(m.height);
  k.fx_px = m.k[0];
  k.cx_px = m.k[2];
  k.fy_px = m.k[4];
  k.cy_px = m.k[5];
  const std::vector<double>& d = m.d;
  if (m.distortion_model == "plumb_bob" || m.distortion_model == "rational_polynomial") {
    const std::size_t want = m.distortion_model == "plumb_bob" ? 5 : 8;
    // ROS drivers send an empty d for "no distortion" and rational_polynomial with 8.
    if (!d.empty() && d.size() != want) {
      fail("distortion_model " + m.distortion_model + " needs " + std::to_string(want) +
           " coefficients in d, got " + std::to_string(d.size()));
    }
    if (!d.empty()) {
      k.k1 = d[0];
      k.k2 = d[1];
      k.p1 = d[2];
      k.p2 = d[3];
      k.k3 = d[4];
      if (want == 8) {
        k.k4 = d[5];
        k.k5 = d[6];
        k.k6 = d[7];
      }
    }
  } else if (m.distortion_model.empty() || m.distortion_model == "none") {
    for (double v : d) {
      if (v != 0.0) fail("distortion_model '" + m.distortion_model + "' with non-zero d");
    }
  } else {
    fail("distortion_model '" + m.distortion_model +
         "' is not supported (plumb_bob, rational_polynomial)");
  }
  try {
    k.Validate();
  } catch (const Error& e) {
    fail(e.what());
  }
  return k;
}

tofcam::CameraInfo RosCameraInfo(const CameraIntrinsics& intrinsics, const RosFrameOptions& options,
                                 bool has_intensity) {
  if (!(options.range_m > 0.0 && options.range_m <= 1000.0)) {
    throw Error(ErrorCode::kInvalidArgument,
                "range_m " + Num(options.range_m) + " must be in (0, 1000] m");
  }
  tofcam::CameraInfo info;
  info.model = options.model;
  info.intrinsics = intrinsics;
  info.modulation_frequency_hz = kSpeedOfLightMPerS / (2.0 * options.range_m);
  info.integration_time_step_us = 0.0;
  info.integration_time_base_us = 0.0;
  info.min_integration_register = 0;
  info.max_integration_register = 0;
  info.has_intensity = has_intensity;
  info.has_ground_truth = false;
  return info;
}

void CheckImage(const ImageMessage& image, std::uint32_t width, std::uint32_t height,
                const std::vector<std::string_view>& allowed, const std::string& what) {
  auto fail = [&](const std::string& problem) {
    throw Error(ErrorCode::kFormat, what + ": " + problem);
  };
  if (std::find(allowed.begin(), allowed.end(), image.encoding) == allowed.end()) {
    std::string list;
    for (std::string_view a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
    fail("encoding '" + image.encoding + "' is not one of " + list);
  }
  if (image.is_bigendian > 1) fail("is_bigendian " + std::to_string(image.is_bigendian));
  if (image.width != width || image.height != height) {
    fail("image is " + std::to_string(image.width) + " x " + std::to_string(image.height) +
         ", camera_info says " + std::to_string(width) + " x " + std::to_string(height));
  }
  const std::uint64_t row = std::uint64_t{image.width} * BytesPerPixel(image.encoding);
  if (image.step < row) {
    fail("step " + std::to_string(image.step) +
         " < width x bytes per pixel = " + std::to_string(row));
  }
  if (image.data.size() != std::uint64_t{image.step} * image.height) {
    fail("data holds " + std::to_string(image.data.size()) +
         " bytes, step x height = " + std::to_string(std::uint64_t{image.step} * image.height));
  }
}

Frame FrameFromImages(const ImageMessage& depth, const ImageMessage& amplitude,
                      const ImageMessage* intensity, const RayTable& rays,
                      const RosFrameOptions& options,
                      const std::array<std::string, 3>& topic_names) {
  const int width = rays.x.width();
  const int height = rays.x.height();
  const auto w = static_cast<std::uint32_t>(width);
  const auto h = static_cast<std::uint32_t>(height);
  CheckImage(depth, w, h, {"16UC1", "32FC1"}, topic_names[0]);
  CheckImage(amplitude, w, h, {"16UC1", "mono16", "32FC1"}, topic_names[1]);
  if (intensity != nullptr) {
    CheckImage(*intensity, w, h, {"16UC1", "mono16", "32FC1"}, topic_names[2]);
  }
  Frame f;
  f.distance = Image<std::uint16_t>(width, height);
  f.amplitude = Image<std::uint16_t>(width, height);
  f.intensity = Image<std::uint16_t>(width, height);
  f.source_flags = Image<PixelFlags>(width, height);
  f.info.camera_model = options.model;
  f.info.modulation_frequency_hz = kSpeedOfLightMPerS / (2.0 * options.range_m);
  f.info.has_intensity = intensity != nullptr;
  const ImageReader d = Reader(depth);
  const ImageReader a = Reader(amplitude);
  const double depth_to_mm = depth.encoding == "32FC1" ? 1000.0 : 1.0;
  std::size_t i = 0;
  for (std::uint32_t row = 0; row < h; ++row) {
    for (std::uint32_t col = 0; col < w; ++col, ++i) {
      const double value_mm = d.At(row, col) * depth_to_mm;
      double radial_mm = value_mm;
      if (!options.depth_is_radial) {
        const double ray_z = rays.z[i];
        radial_mm = ray_z > 0 ? value_mm / ray_z : 0.0;
      }
      SetDistanceMm(f, i, std::isfinite(radial_mm) ? radial_mm : 0.0, options.range_m);
      f.amplitude[i] = SignalRegister(a.At(row, col), f.source_flags[i]);
    }
  }
  if (intensity != nullptr) {
    const ImageReader r = Reader(*intensity);
    i = 0;
    for (std::uint32_t row = 0; row < h; ++row) {
      for (std::uint32_t col = 0; col < w; ++col, ++i) {
        f.intensity[i] = SignalRegister(r.At(row, col), f.source_flags[i]);
      }
    }
  }
  return f;
}

}  // namespace tofcam::ros2
