// Stage 3 of the simulator (src/sim/optics.h): the Gaussian blur, the scattering PSF and the
// inter-reflection against closed forms.
#include "optics.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>

#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {
namespace {

TEST(OpticsTest, GaussianKernelIsNormalisedSymmetricAndGaussian) {
  const std::vector<float> k = GaussianKernel(1.5);
  ASSERT_EQ(k.size(), 11u);  // radius ceil(4.5) = 5
  EXPECT_NEAR(std::accumulate(k.begin(), k.end(), 0.0), 1.0, 1e-6);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(k[i], k[10 - i]);
  EXPECT_NEAR(k[6] / k[5], std::exp(-0.5 / (1.5 * 1.5)), 1e-6);
  EXPECT_EQ(GaussianKernel(0.1).size(), 3u);  // at least radius 1
}

TEST(OpticsTest, BlurOfADeltaIsTheOuterProductOfTheKernel) {
  const int w = 21, h = 17;
  std::vector<float> img(static_cast<std::size_t>(w) * h, 0.f), tmp;
  img[8 * w + 10] = 1.f;
  const std::vector<float> k = GaussianKernel(1.0);  // radius 3
  BlurInPlace(img, tmp, w, h, k);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const int dr = r - 8, dc = c - 10;
      const float expected = std::abs(dr) <= 3 && std::abs(dc) <= 3 ? k[dr + 3] * k[dc + 3] : 0.f;
      EXPECT_NEAR(img[static_cast<std::size_t>(r) * w + c], expected, 1e-7f) << r << "," << c;
    }
  }
}

TEST(OpticsTest, BlurLosesTheLightThatLeavesTheSensor) {
  const int w = 9, h = 9;
  std::vector<float> img(81, 0.f), tmp;
  img[4 * w + 0] = 1.f;  // on the left edge: the left half of the kernel falls off
  const std::vector<float> k = GaussianKernel(1.0);
  BlurInPlace(img, tmp, w, h, k);
  const double total = std::accumulate(img.begin(), img.end(), 0.0);
  EXPECT_NEAR(total, k[3] + k[4] + k[5] + k[6], 1e-6);
}

TEST(OpticsTest, BoxBlurIsTheWholeImageBlurBitForBit) {
  // Non-negative images that are zero outside a box: boxes in the middle, touching every edge,
  // narrower than the kernel, one pixel, and the whole image; kernels of radius 1 to 12 (sigma
  // up to 4 px: 25 taps, wider than the 23 x 19 image). Stale scratch must not leak in: tmp
  // starts as NaN.
  const int w = 23, h = 19;
  const int boxes[][4] = {{5, 9, 6, 12},  {0, 4, 0, 3},    {15, 19, 20, 23}, {0, 19, 0, 23},
                          {8, 9, 11, 12}, {0, 19, 10, 11}, {3, 4, 0, 23},    {17, 19, 0, 2}};
  int compared = 0;
  RowPool two(2);
  for (const double sigma : {0.3, 1.0, 2.3, 4.0}) {
    const std::vector<float> k = GaussianKernel(sigma);
    for (const auto& b : boxes) {
      std::vector<float> img(static_cast<std::size_t>(w) * h, 0.f);
      for (int r = b[0]; r < b[1]; ++r) {
        for (int c = b[2]; c < b[3]; ++c) {
          // Some zeros inside the box too, and values over several decades.
          const int v = (r * 31 + c * 17) % 7;
          img[static_cast<std::size_t>(r) * w + c] = v == 0 ? 0.f : std::ldexp(1.3f * v, v * 3);
        }
      }
      std::vector<float> whole = img, box = img, pooled = img, tmp_whole;
      std::vector<float> tmp_box(img.size(), std::numeric_limits<float>::quiet_NaN());
      std::vector<float> tmp_pooled = tmp_box;
      BlurInPlace(whole, tmp_whole, w, h, k);
      BlurBoxInPlace(box, tmp_box, w, h, k, b[0], b[1], b[2], b[3]);
      BlurBoxInPlace(pooled, tmp_pooled, w, h, k, b[0], b[1], b[2], b[3], &two);
      for (std::size_t i = 0; i < img.size(); ++i) {
        ASSERT_EQ(std::bit_cast<std::uint32_t>(box[i]), std::bit_cast<std::uint32_t>(whole[i]))
            << "sigma " << sigma << " box " << b[0] << " " << b[1] << " " << b[2] << " " << b[3]
            << " pixel " << i;
        ASSERT_EQ(std::bit_cast<std::uint32_t>(pooled[i]), std::bit_cast<std::uint32_t>(whole[i]))
            << "sigma " << sigma << " on a pool of two, pixel " << i;
        compared += whole[i] > 0;
      }
    }
  }
  EXPECT_GT(compared, 3000);  // not a comparison of empty images
}

TEST(OpticsTest, ScatterPlanReducesWideLobes) {
  const ScatterPlan sp = PlanScatter({{0.01, 8.0}, {0.02, 40.0}}, 176, 144);
  EXPECT_EQ(sp.f, 4);  // min sigma / 2
  EXPECT_EQ(sp.rw, 44);
  EXPECT_EQ(sp.rh, 36);
  ASSERT_EQ(sp.weight.size(), 2u);
  EXPECT_FLOAT_EQ(sp.weight[1], 0.02f / 16);
  EXPECT_EQ(PlanScatter({{0.01, 1.0}}, 10, 10).f, 1);
  EXPECT_EQ(PlanScatter({{0.01, 100.0}}, 10, 10).f, 8);
  EXPECT_TRUE(PlanScatter({{0.0, 5.0}}, 10, 10).weight.empty());  // zero-weight lobe dropped
}

TEST(OpticsTest, ScatteringOfUniformLightIsTheLobeWeightAwayFromTheEdges) {
  for (const double sigma : {2.0, 8.0}) {  // full resolution and reduced by 4
    const int w = 160, h = 160;
    const ScatterPlan sp = PlanScatter({{0.05, sigma}}, w, h);
    const std::vector<float> src(static_cast<std::size_t>(w) * h, 1.f);
    std::vector<float> dst(src.size()), tmp[4];
    ScatterChannel(sp, w, h, src, dst, tmp);
    EXPECT_NEAR(dst[80 * w + 80], 0.05f, 1e-4f) << sigma;
    EXPECT_LT(dst[0], 0.05f * 0.5f) << sigma;  // a corner gets about a quarter
  }
}

TEST(OpticsTest, AFlatWallFacingTheCameraReflectsNothingOntoItself) {
  const Scene scene = ParseScene(
      "materials: {w: {albedo: 0.8}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [20, 20], position_m: [0, 0, 2]}\n",
      "inline", {});
  const CameraModel model = WithResolution(ResolveCameraModel("sr2"), 16, 12);
  const SceneGeometry geometry(scene);
  PixelRays rays;
  rays.group = 1;
  SubsampleRadiometry rad;
  BuildPixelRays(model, 1, rays, rad);
  const MaterialTable mats = BuildMaterials(scene, false);
  RowPool pool(1);
  InterreflectionContext ic;
  ic.geometry = &geometry;
  ic.rays = &rays;
  ic.radiometry = &rad;
  ic.materials = &mats;
  ic.pool = &pool;
  ic.samples = 16;
  ic.range_m = 7.5;
  ic.contrast = 0.5;
  InterreflectionBuffers buf;
  Render out;
  out.Resize(16 * 12);
  Interreflect(ic, Eigen::Isometry3d::Identity(), buf, out);
  for (std::size_t p = 0; p < out.re.size(); ++p) {
    EXPECT_EQ(out.re[p], 0.f);
    EXPECT_EQ(out.dc[p], 0.f);
    EXPECT_NEAR(buf.ir_t[p], 2.0f / rays.center_z[p], 1e-4f);  // the first surface is found
  }
}

TEST(OpticsTest, AConcaveCornerReflectsLightWithALongerPath) {
  // Two walls meeting at a right angle 3 m in front of the camera, the corner opening towards it:
  // each lights the other.
  const Scene scene = ParseScene(
      "materials: {w: {albedo: 0.8}}\nobjects:\n"
      "  - {type: plane, material: w, size_m: [6, 6], position_m: [-1, 0, 2], "
      "rotation_deg: [0, -45, 0]}\n"
      "  - {type: plane, material: w, size_m: [6, 6], position_m: [1, 0, 2], "
      "rotation_deg: [0, 45, 0]}\n",
      "inline", {});
  const CameraModel model = WithResolution(ResolveCameraModel("sr2"), 16, 12);
  const SceneGeometry geometry(scene);
  PixelRays rays;
  rays.group = 1;
  SubsampleRadiometry rad;
  BuildPixelRays(model, 1, rays, rad);
  const MaterialTable mats = BuildMaterials(scene, false);
  RowPool pool(1);
  InterreflectionContext ic{&geometry, &rays, &rad, &mats, &pool, 32, 7.5, 0.5};
  InterreflectionBuffers buf;
  Render out;
  out.Resize(16 * 12);
  Interreflect(ic, Eigen::Isometry3d::Identity(), buf, out);
  int lit = 0;
  for (std::size_t p = 0; p < out.re.size(); ++p) {
    if (out.dc[p] > 0) {
      ++lit;
      // Modulated part at most contrast times the DC part (phasors of different phase add to
      // less).
      EXPECT_LE(std::hypot(out.re[p], out.im[p]), 0.5f * out.dc[p] * (1 + 1e-5f));
    }
  }
  EXPECT_GT(lit, 16 * 12 / 2);
}

}  // namespace
}  // namespace tofcam::sim::internal
