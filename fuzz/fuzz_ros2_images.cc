// Fuzzes the ROS 2 camera source's handling of received samples (tofcam/ros2/messages.h): a
// CameraInfo and depth / amplitude / intensity Images with arbitrary fields, as a hostile or
// broken driver could send them. Layout: 12 doubles of K and d, then per image (3 of them) a
// header byte (encoding, is_bigendian, intensity on/off), width and height (1..32), a step
// adjustment and a data length adjustment, the rest is pixel data shared by the images.
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

#include "tofcam/core/error.h"
#include "tofcam/ros2/messages.h"

namespace {

const char* const kEncodings[] = {"16UC1", "32FC1", "mono16", "rgb8", "8UC1", "", "32FC3"};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tofcam::ros2;
  constexpr std::size_t kInfoBytes = 12 * 8;
  constexpr std::size_t kImageBytes = 5;
  if (size < kInfoBytes + 3 * kImageBytes + 2) return 0;
  CameraInfoMessage info;
  double v[12];
  std::memcpy(v, data, sizeof v);
  info.width = 1 + data[kInfoBytes] % 32;
  info.height = 1 + data[kInfoBytes + 1] % 32;
  info.k = {v[0], 0, v[1], 0, v[2], v[3], 0, 0, 1};
  info.distortion_model = (data[kInfoBytes] & 0x80) ? "rational_polynomial" : "plumb_bob";
  info.d.assign(v + 4, v + ((data[kInfoBytes] & 0x80) ? 12 : 9));
  const std::uint8_t* p = data + kInfoBytes + 2;
  std::size_t left = size - kInfoBytes - 2;
  ImageMessage images[3];
  bool with_intensity = false;
  for (ImageMessage& m : images) {
    m.encoding = kEncodings[p[0] % 7];
    m.is_bigendian = (p[0] >> 3) % 3;
    with_intensity = with_intensity || (p[0] & 0x40);
    m.width = (p[1] & 0x80) ? info.width : 1 + p[1] % 32;
    m.height = (p[2] & 0x80) ? info.height : 1 + p[2] % 32;
    // A step near a plausible one (4 bytes per pixel +- 8) and a data size near step x height.
    const std::int64_t step =
        std::max<std::int64_t>(0, std::int64_t{m.width} * 4 + static_cast<std::int8_t>(p[3]) / 16);
    m.step = static_cast<std::uint32_t>(step);
    m.data.resize(static_cast<std::size_t>(
        std::max<std::int64_t>(0, step * m.height + static_cast<std::int8_t>(p[4]) % 3)));
    p += kImageBytes;
    left -= kImageBytes;
    for (std::size_t i = 0; i < m.data.size() && left > 0; ++i) m.data[i] = p[i % left];
  }
  try {
    const tofcam::CameraIntrinsics k = IntrinsicsFromCameraInfo(info, "fuzz/camera_info");
    const tofcam::RayTable rays = tofcam::MakeRayTable(k);
    RosFrameOptions options;
    options.depth_is_radial = data[0] & 1;
    const tofcam::Frame f =
        FrameFromImages(images[0], images[1], with_intensity ? &images[2] : nullptr, rays, options,
                        {"fuzz/depth", "fuzz/amplitude", "fuzz/intensity"});
    tofcam::ValidateFrame(f);
  } catch (const tofcam::Error&) {
  }
  return 0;
}
