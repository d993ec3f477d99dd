// tofcam::ros2 message conversions, without DDS: hand-made inputs, hand-computed outputs.
#include "tofcam/ros2/messages.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "tofcam/core/error.h"

namespace tofcam::ros2 {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();

PointCloud TwoByTwo() {
  PointCloud c;
  c.Resize(2, 2);
  const float xs[4] = {0.5f, -0.25f, kNan, 1.0f};
  for (int i = 0; i < 4; ++i) {
    c.x[i] = xs[i];
    c.y[i] = 0.125f * static_cast<float>(i);
    c.z[i] = i == 2 ? kNan : 1.5f + static_cast<float>(i);
    c.amplitude[i] = 100.0f * static_cast<float>(i + 1);
    c.delta_l_m[i] = 0.001f * static_cast<float>(i);
  }
  c.flags[2].Set(Flag::kInvalid);
  return c;
}

template <typename T>
T At(const std::vector<std::uint8_t>& data, std::size_t offset) {
  T v;
  std::memcpy(&v, data.data() + offset, sizeof v);
  return v;
}

TEST(Messages, PointCloud2LayoutAndBytes) {
  const PointCloud c = TwoByTwo();
  PointCloud2Message m;
  MakePointCloud2Into(c, {1'000'000'123, "cam"}, m);
  EXPECT_EQ(m.height, 2u);
  EXPECT_EQ(m.width, 2u);
  EXPECT_EQ(m.point_step, 24u);
  EXPECT_EQ(m.row_step, 48u);
  EXPECT_FALSE(m.is_dense);
  EXPECT_FALSE(m.is_bigendian);
  EXPECT_EQ(m.header.frame_id, "cam");
  EXPECT_EQ(m.header.stamp_ns, 1'000'000'123);
  ASSERT_EQ(m.fields.size(), 6u);
  const char* names[6] = {"x", "y", "z", "amplitude", "delta_l", "flags"};
  for (int f = 0; f < 6; ++f) {
    EXPECT_EQ(m.fields[f].name, names[f]);
    EXPECT_EQ(m.fields[f].offset, 4u * f);
    EXPECT_EQ(m.fields[f].datatype, f == 5 ? 6 : 7);  // UINT32 : FLOAT32
    EXPECT_EQ(m.fields[f].count, 1u);
  }
  ASSERT_EQ(m.data.size(), 96u);
  EXPECT_EQ(At<float>(m.data, 24 * 1 + 0), -0.25f);
  EXPECT_EQ(At<float>(m.data, 24 * 3 + 4), 0.375f);
  EXPECT_EQ(At<float>(m.data, 24 * 1 + 8), 2.5f);
  EXPECT_EQ(At<float>(m.data, 24 * 3 + 12), 400.0f);
  EXPECT_EQ(At<float>(m.data, 24 * 2 + 16), 0.002f);
  EXPECT_TRUE(std::isnan(At<float>(m.data, 24 * 2)));
  EXPECT_EQ(At<std::uint32_t>(m.data, 24 * 2 + 20), c.flags[2].bits());
  EXPECT_NE(c.flags[2].bits(), 0u);
  EXPECT_EQ(At<std::uint32_t>(m.data, 20), 0u);
}

TEST(Messages, DepthImagesFollowRep118) {
  PointCloud c = TwoByTwo();
  c.z[1] = 0.0004f;  // rounds to 0 mm -> no value
  c.z[3] = 70.0f;    // beyond 65.535 m -> no value in 16UC1
  ImageMessage m;
  MakeDepthImageInto(c, {}, m);
  EXPECT_EQ(m.encoding, "32FC1");
  EXPECT_EQ(m.step, 8u);
  EXPECT_EQ(At<float>(m.data, 0), 1.5f);
  EXPECT_TRUE(std::isnan(At<float>(m.data, 8)));
  MakeDepthMmImageInto(c, {}, m);
  EXPECT_EQ(m.encoding, "16UC1");
  EXPECT_EQ(m.step, 4u);
  EXPECT_EQ(At<std::uint16_t>(m.data, 0), 1500);
  EXPECT_EQ(At<std::uint16_t>(m.data, 2), 0);
  EXPECT_EQ(At<std::uint16_t>(m.data, 4), 0);
  EXPECT_EQ(At<std::uint16_t>(m.data, 6), 0);
}

TEST(Messages, Mono16RoundsAndClamps) {
  Image<float> a(3, 1);
  a[0] = 12.5f;  // round half away from zero
  a[1] = 70000.0f;
  a[2] = kNan;
  ImageMessage m;
  MakeMono16ImageInto(a, {}, m);
  EXPECT_EQ(m.encoding, "16UC1");
  EXPECT_EQ(At<std::uint16_t>(m.data, 0), 13);
  EXPECT_EQ(At<std::uint16_t>(m.data, 2), 65535);
  EXPECT_EQ(At<std::uint16_t>(m.data, 4), 0);
}

TEST(Messages, CameraInfoRoundTrip) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  CameraInfoMessage m = MakeCameraInfo(k, {});
  EXPECT_EQ(m.distortion_model, "plumb_bob");
  EXPECT_EQ(m.d.size(), 5u);
  EXPECT_EQ(m.k[0], k.fx_px);
  EXPECT_EQ(m.k[2], k.cx_px);
  EXPECT_EQ(m.k[4], k.fy_px);
  EXPECT_EQ(m.k[5], k.cy_px);
  EXPECT_EQ(m.p[3], 0.0);
  EXPECT_EQ(m.p[10], 1.0);
  k.k1 = 0.1;
  k.p2 = -0.01;
  k.k5 = 0.02;
  m = MakeCameraInfo(k, {});
  EXPECT_EQ(m.distortion_model, "rational_polynomial");
  ASSERT_EQ(m.d.size(), 8u);
  EXPECT_EQ(m.d[0], 0.1);
  EXPECT_EQ(m.d[3], -0.01);
  EXPECT_EQ(m.d[6], 0.02);
  const CameraIntrinsics back = IntrinsicsFromCameraInfo(m, "ci");
  EXPECT_EQ(back.k1, 0.1);
  EXPECT_EQ(back.p2, -0.01);
  EXPECT_EQ(back.k5, 0.02);
  EXPECT_EQ(back.fx_px, k.fx_px);
  EXPECT_EQ(back.width, 160);
}

void ExpectFormatError(const std::function<void()>& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one naming '" << needle << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFormat) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(Messages, BadCameraInfoIsAClearError) {
  const CameraInfoMessage good = MakeCameraInfo(CameraIntrinsics::SwissRangerSr2(), {});
  CameraInfoMessage m = good;
  m.k[0] = std::nan("");
  ExpectFormatError([&] { (void)IntrinsicsFromCameraInfo(m, "/cam/camera_info"); },
                    "/cam/camera_info: k[0] is nan");
  m = good;
  m.k[4] = 0;
  ExpectFormatError([&] { (void)IntrinsicsFromCameraInfo(m, "ci"); }, "must be > 0");
  m = good;
  m.d.pop_back();
  ExpectFormatError([&] { (void)IntrinsicsFromCameraInfo(m, "ci"); }, "needs 5 coefficients");
  m = good;
  m.distortion_model = "equidistant";
  ExpectFormatError([&] { (void)IntrinsicsFromCameraInfo(m, "ci"); }, "'equidistant'");
  m = good;
  m.width = 0;
  ExpectFormatError([&] { (void)IntrinsicsFromCameraInfo(m, "ci"); }, "size 0 x 124");
  m = good;
  m.d[1] = std::numeric_limits<double>::infinity();
  ExpectFormatError([&] { (void)IntrinsicsFromCameraInfo(m, "ci"); }, "d[1] is inf");
}

ImageMessage U16Image(int w, int h, std::initializer_list<std::uint16_t> values) {
  ImageMessage m;
  m.width = static_cast<std::uint32_t>(w);
  m.height = static_cast<std::uint32_t>(h);
  m.encoding = "16UC1";
  m.step = static_cast<std::uint32_t>(2 * w);
  m.data.resize(static_cast<std::size_t>(2 * w * h));
  std::size_t i = 0;
  for (std::uint16_t v : values) {
    std::memcpy(m.data.data() + 2 * i, &v, 2);
    ++i;
  }
  return m;
}

TEST(Messages, MalformedImagesAreNamedErrors) {
  const ImageMessage good = U16Image(2, 1, {1, 2});
  ImageMessage m = good;
  m.encoding = "bgr8";
  ExpectFormatError(
      [&] {
        CheckImage(m, 2, 1, {"16UC1", "32FC1"}, "/cam/depth");
      },
      "/cam/depth: encoding 'bgr8' is not one of 16UC1, 32FC1");
  m = good;
  m.step = 3;
  ExpectFormatError([&] { CheckImage(m, 2, 1, {"16UC1"}, "d"); }, "step 3 < width");
  m = good;
  m.data.pop_back();
  ExpectFormatError([&] { CheckImage(m, 2, 1, {"16UC1"}, "d"); }, "data holds 3 bytes");
  m = good;
  ExpectFormatError([&] { CheckImage(m, 3, 1, {"16UC1"}, "d"); }, "camera_info says 3 x 1");
  m = good;
  m.is_bigendian = 7;
  ExpectFormatError([&] { CheckImage(m, 2, 1, {"16UC1"}, "d"); }, "is_bigendian 7");
  // A padded row (step > width x 2) is fine.
  m = U16Image(3, 1, {1, 2, 0});
  m.width = 2;
  EXPECT_NO_THROW(CheckImage(m, 2, 1, {"16UC1"}, "d"));
}

TEST(Messages, FrameFromImagesUsesTheImportersRules) {
  // Two pixels of a pinhole camera 2 x 1 with fx = 1, cx = 0.5: pixel 0 at u = 0 looks along
  // (-0.5, 0, 1), so its ray has z = 1 / sqrt(1.25); pixel 1 along (0.5, 0, 1), the same z.
  CameraIntrinsics k;
  k.width = 2;
  k.height = 1;
  k.fx_px = 1.0;
  k.fy_px = 1.0;
  k.cx_px = 0.5;
  k.cy_px = 0.0;
  const RayTable rays = MakeRayTable(k);
  const ImageMessage depth = U16Image(2, 1, {1000, 0});
  const ImageMessage amplitude = U16Image(2, 1, {500, 65535});
  RosFrameOptions o;  // L = 8.192 m: register = 8 x mm
  const Frame f = FrameFromImages(depth, amplitude, nullptr, rays, o, {"d", "a", "i"});
  const double radial_mm = 1000.0 * std::sqrt(1.25);
  EXPECT_EQ(f.distance[0], static_cast<std::uint16_t>(std::lround(8.0 * radial_mm)));
  EXPECT_FALSE(f.source_flags[0].Has(Flag::kInvalid));
  EXPECT_EQ(f.distance[1], 0);
  EXPECT_TRUE(f.source_flags[1].Has(Flag::kInvalid));
  EXPECT_EQ(f.amplitude[0], 500);
  EXPECT_EQ(f.amplitude[1], kMaxSignalRegister);
  EXPECT_TRUE(f.source_flags[1].Has(Flag::kSaturated));
  EXPECT_FALSE(f.info.has_intensity);
  EXPECT_NEAR(f.info.modulation_frequency_hz, 299792458.0 / (2 * 8.192), 1e-6);

  // Radial depth in metres (32FC1), with an intensity channel.
  ImageMessage depth_m;
  depth_m.width = 2;
  depth_m.height = 1;
  depth_m.encoding = "32FC1";
  depth_m.step = 8;
  depth_m.data.resize(8);
  const float values[2] = {2.0f, std::numeric_limits<float>::quiet_NaN()};
  std::memcpy(depth_m.data.data(), values, 8);
  o.depth_is_radial = true;
  const ImageMessage intensity = U16Image(2, 1, {700, 800});
  const Frame g = FrameFromImages(depth_m, amplitude, &intensity, rays, o, {"d", "a", "i"});
  EXPECT_EQ(g.distance[0], 16000);  // 2000 mm x 8
  EXPECT_TRUE(g.source_flags[1].Has(Flag::kInvalid));
  EXPECT_TRUE(g.info.has_intensity);
  EXPECT_EQ(g.intensity[0], 700);
  EXPECT_EQ(g.intensity[1], 800);

  // Big-endian 16UC1 is read as such.
  ImageMessage big = U16Image(2, 1, {0x0100, 0x0200});  // bytes 00 01 / 00 02
  big.is_bigendian = 1;
  o.depth_is_radial = true;
  const Frame b = FrameFromImages(big, amplitude, nullptr, rays, o, {"d", "a", "i"});
  EXPECT_EQ(b.distance[0], 8);  // 1 mm
  EXPECT_EQ(b.distance[1], 16);

  // A wrong size names the topic.
  const ImageMessage small = U16Image(1, 1, {1});
  ExpectFormatError(
      [&] {
        (void)FrameFromImages(depth, small, nullptr, rays, o, {"d", "/amp", "i"});
      },
      "/amp: image is 1 x 1");
}

}  // namespace
}  // namespace tofcam::ros2
