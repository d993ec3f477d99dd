#include "tofcam/cloud/point_cloud.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "pipeline/stage_kernels.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

MetricFrame Frame(const CameraIntrinsics& k, float distance) {
  MetricFrame f;
  f.radial_distance_m = Image<float>(k.width, k.height, distance);
  f.amplitude = Image<float>(k.width, k.height, 1234.0f);
  f.flags = Image<PixelFlags>(k.width, k.height);
  return f;
}

TEST(PointCloudTest, PointsProjectBackToTheirPixelAtTheirDistance) {
  for (bool distorted : {false, true}) {
    CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
    if (distorted) {
      k.k1 = -0.2;
      k.k2 = 0.05;
      k.p1 = 0.001;
    }
    const RayTable rays = MakeRayTable(k);
    MetricFrame f = Frame(k, 0.0f);
    for (int r = 0; r < k.height; ++r)
      for (int c = 0; c < k.width; ++c) f.radial_distance_m(r, c) = 0.5f + 0.01f * (r + c);
    const PointCloud cloud = MakePointCloud(f, rays);
    ASSERT_EQ(cloud.width, k.width);
    ASSERT_EQ(cloud.height, k.height);
    ASSERT_TRUE(cloud.organized());
    for (int r = 0; r < k.height; r += 7) {
      for (int c = 0; c < k.width; c += 9) {
        const std::size_t i = static_cast<std::size_t>(r) * k.width + c;
        const Eigen::Vector3d p(cloud.x[i], cloud.y[i], cloud.z[i]);
        // Independent of the ray table: the camera model's own projection.
        const Eigen::Vector2d px = k.Project(p);
        EXPECT_NEAR(px.x(), c, 2e-3) << r << "," << c;  // float coordinates: ~1e-7 relative
        EXPECT_NEAR(px.y(), r, 2e-3) << r << "," << c;
        EXPECT_NEAR(p.norm(), f.radial_distance_m(r, c), 1e-5);
        EXPECT_GT(p.z(), 0.0);
        EXPECT_EQ(cloud.amplitude[i], 1234.0f);
      }
    }
  }
}

TEST(PointCloudTest, CentrePixelOfOddImageLiesOnTheOpticalAxis) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.width = 5;
  k.height = 3;
  k.cx_px = 2.0;
  k.cy_px = 1.0;
  const PointCloud cloud = MakePointCloud(Frame(k, 2.5f), MakeRayTable(k));
  EXPECT_FLOAT_EQ(cloud.x[7], 0.0f);
  EXPECT_FLOAT_EQ(cloud.y[7], 0.0f);
  EXPECT_FLOAT_EQ(cloud.z[7], 2.5f);
  // Pixel (0, 4): x = (4 - 2) / fx, y = -1 / fy on the normalised plane, scaled to length 2.5.
  const Eigen::Vector3d ray = Eigen::Vector3d(2.0 / k.fx_px, -1.0 / k.fy_px, 1.0).normalized();
  EXPECT_NEAR(cloud.x[4], 2.5 * ray.x(), 1e-6);
  EXPECT_NEAR(cloud.y[4], 2.5 * ray.y(), 1e-6);
  EXPECT_NEAR(cloud.z[4], 2.5 * ray.z(), 1e-6);
}

TEST(PointCloudTest, RejectedAndNonFinitePixelsGetNanButKeepTheirData) {
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.width = 4;
  k.height = 1;
  k.cx_px = 1.5;
  k.cy_px = 0.0;
  const RayTable rays = MakeRayTable(k);
  MetricFrame f = Frame(k, 2.0f);
  f.flags[1] = Flag::kHighDeltaL;
  f.flags[2] = Flag::kMixed;  // a truth bit, not a reject bit: keeps its position
  f.radial_distance_m[3] = std::numeric_limits<float>::infinity();
  f.delta_l_m = Image<float>(4, 1, 0.02f);
  const PointCloud cloud = MakePointCloud(f, rays);
  EXPECT_TRUE(std::isfinite(cloud.x[0]));
  EXPECT_TRUE(std::isnan(cloud.x[1]) && std::isnan(cloud.y[1]) && std::isnan(cloud.z[1]));
  EXPECT_EQ(cloud.flags[1], PixelFlags(Flag::kHighDeltaL));
  EXPECT_EQ(cloud.amplitude[1], 1234.0f);
  EXPECT_EQ(cloud.delta_l_m[1], 0.02f);
  EXPECT_TRUE(std::isfinite(cloud.z[2]));
  EXPECT_TRUE(std::isnan(cloud.x[3]) && std::isnan(cloud.z[3]));
  EXPECT_TRUE(std::isnan(cloud.intensity[0]));  // no intensity channel
  EXPECT_EQ(cloud.CountValid(), 2u);
  EXPECT_TRUE(cloud.IsValid(2));
  // nan_mask = 0 keeps the rejected pixel's coordinates.
  PointCloudOptions keep;
  keep.nan_mask = 0;
  const PointCloud all = MakePointCloud(f, rays, keep);
  EXPECT_FLOAT_EQ(std::hypot(all.x[1], all.y[1], all.z[1]), 2.0f);
  EXPECT_FALSE(all.IsValid(1));  // still rejected by its flags
}

TEST(PointCloudTest, IntoReusedCloudEqualsFreshCloud) {
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  const RayTable rays = MakeRayTable(k);
  MetricFrame f = Frame(k, 3.0f);
  f.flags(5, 5) = Flag::kSaturated;
  f.intensity = Image<float>(k.width, k.height, 7.0f);
  // A cloud left over from another frame, with stale values and flags.
  PointCloud reused = MakePointCloud(Frame(k, 1.0f), rays);
  reused.flags[0] = Flag::kInvalid;
  MakePointCloudInto(f, rays, reused);
  const PointCloud fresh = MakePointCloud(f, rays);
  ASSERT_EQ(reused.size(), fresh.size());
  for (std::size_t i = 0; i < fresh.size(); ++i) {
    ASSERT_EQ(reused.flags[i], fresh.flags[i]) << i;
    ASSERT_EQ(std::isnan(reused.x[i]), std::isnan(fresh.x[i])) << i;
    if (!std::isnan(fresh.x[i])) {
      ASSERT_EQ(reused.x[i], fresh.x[i]) << i;
    }
    ASSERT_EQ(reused.intensity[i], fresh.intensity[i]) << i;
  }
  // And a frame without flags clears the stale ones.
  MetricFrame no_flags = Frame(k, 2.0f);
  no_flags.flags = Image<PixelFlags>();
  MakePointCloudInto(no_flags, rays, reused);
  EXPECT_TRUE(reused.flags[(5 * k.width) + 5].None());
  EXPECT_EQ(reused.CountValid(), reused.size());
}

// A cloud of kStreamCloudBytes or more is written with non-temporal stores; its values must be
// the definition's: d x ray in float (NaN where a reject bit is set or d is not finite), the
// channels copied, NaN / clear flags for missing ones. Checked against that per point, over two
// calls into one cloud; then the same cloud written span by span from odd starting points (as
// the fused pass writes it chunk by chunk), so that the streamed lines start at every alignment.
// Both store forms (64-byte on AVX-512 CPUs, 16-byte elsewhere) where the CPU has both.
class LargeCloudTest : public ::testing::TestWithParam<bool> {};

TEST_P(LargeCloudTest, IsStreamedWithTheSameValues) {
  const internal::PortableFormsForTesting portable(GetParam());
  const std::size_t points = kernels::kStreamCloudBytes / kernels::kCloudBytesPerPoint + 1;
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.width = 1021;
  k.height = static_cast<int>((points + 1020) / 1021);
  k.cx_px = 510.0;
  k.cy_px = k.height / 2.0;
  const RayTable rays = MakeRayTable(k);
  PointCloud cloud;
  for (const bool channels : {true, false}) {
    SCOPED_TRACE(channels ? "all channels" : "distance only");
    MetricFrame f;
    f.radial_distance_m = Image<float>(k.width, k.height);
    const std::size_t n = f.radial_distance_m.size();
    ASSERT_GE(n * kernels::kCloudBytesPerPoint, kernels::kStreamCloudBytes);
    for (std::size_t i = 0; i < n; ++i) f.radial_distance_m[i] = 0.25f + 1e-5f * (i % 70001);
    f.radial_distance_m[77] = std::numeric_limits<float>::quiet_NaN();
    f.radial_distance_m[n - 1] = std::numeric_limits<float>::infinity();
    if (channels) {
      f.amplitude = Image<float>(k.width, k.height);
      f.intensity = Image<float>(k.width, k.height);
      f.delta_l_m = Image<float>(k.width, k.height);
      f.flags = Image<PixelFlags>(k.width, k.height);
      for (std::size_t i = 0; i < n; ++i) {
        f.amplitude[i] = static_cast<float>(i);
        f.intensity[i] = 0.5f * static_cast<float>(i);
        f.delta_l_m[i] = 1e-3f * static_cast<float>(i % 97);
        f.flags[i] = i % 13 == 0   ? PixelFlags(Flag::kLowAmplitude)
                     : i % 17 == 0 ? PixelFlags(Flag::kMixed)  // not a reject bit
                                   : PixelFlags();
      }
    }
    MakePointCloudInto(f, rays, cloud);
    ASSERT_EQ(cloud.size(), n);
    std::size_t mismatches = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const float d = f.radial_distance_m[i];
      const bool rejected = channels && f.flags[i].Has(Flag::kLowAmplitude);
      const bool nan = rejected || !std::isfinite(d);
      const float ex = nan ? 0.0f : d * rays.x[i], ey = nan ? 0.0f : d * rays.y[i],
                  ez = nan ? 0.0f : d * rays.z[i];
      const auto same = [nan](float got, float want) {
        return nan ? std::isnan(got) : got == want;
      };
      const auto same_or_nan = [channels](float got, float want) {
        return channels ? got == want : std::isnan(got);
      };
      const bool ok = same(cloud.x[i], ex) && same(cloud.y[i], ey) && same(cloud.z[i], ez) &&
                      same_or_nan(cloud.amplitude[i], channels ? f.amplitude[i] : 0.0f) &&
                      same_or_nan(cloud.intensity[i], channels ? f.intensity[i] : 0.0f) &&
                      same_or_nan(cloud.delta_l_m[i], channels ? f.delta_l_m[i] : 0.0f) &&
                      cloud.flags[i] == (channels ? f.flags[i] : PixelFlags());
      if (!ok && ++mismatches <= 5) ADD_FAILURE() << "point " << i;
    }
    EXPECT_EQ(mismatches, 0u);

    PointCloud spans;
    kernels::PrepareCloud(f, rays, spans);
    const auto at = [](const auto& image, std::size_t b) {
      return image.empty() ? nullptr : image.data() + b;
    };
    const std::size_t bounds[] = {0, 1, 4, 19, 12345, n - 70, n};
    for (int s = 0; s + 1 < 7; ++s) {
      const std::size_t b = bounds[s], len = bounds[s + 1] - b;
      kernels::CloudSpan(rays, PointCloudOptions(), b, len, f.radial_distance_m.data() + b,
                         at(f.flags, b), at(f.amplitude, b), at(f.intensity, b), at(f.delta_l_m, b),
                         spans);
    }
    const auto same_bits = [](const std::vector<float>& x, const std::vector<float>& y) {
      return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * 4) == 0;
    };
    EXPECT_TRUE(same_bits(spans.x, cloud.x));
    EXPECT_TRUE(same_bits(spans.y, cloud.y));
    EXPECT_TRUE(same_bits(spans.z, cloud.z));
    EXPECT_TRUE(same_bits(spans.amplitude, cloud.amplitude));
    EXPECT_TRUE(same_bits(spans.intensity, cloud.intensity));
    EXPECT_TRUE(same_bits(spans.delta_l_m, cloud.delta_l_m));
    EXPECT_TRUE(spans.flags == cloud.flags);
  }
}

INSTANTIATE_TEST_SUITE_P(StoreForms, LargeCloudTest, ::testing::Bool(),
                         [](const ::testing::TestParamInfo<bool>& param) {
                           return param.param ? std::string("Portable") : std::string("Native");
                         });

TEST(PointCloudTest, ErrorsAreReported) {
  const CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  const RayTable rays = MakeRayTable(k);
  EXPECT_THROW((void)MakePointCloud(MetricFrame{}, rays), Error);
  MetricFrame f = Frame(k, 1.0f);
  f.amplitude = Image<float>(3, 3);
  try {
    (void)MakePointCloud(f, rays);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
  CameraIntrinsics other = k;
  other.width = 176;
  other.height = 144;
  try {
    (void)MakePointCloud(Frame(k, 1.0f), MakeRayTable(other));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  PointCloud broken;
  broken.Resize(2, 2);
  broken.flags.pop_back();
  EXPECT_THROW(broken.Validate(), Error);
}

}  // namespace
}  // namespace tofcam
