// Stage 2 of the simulator (src/sim/radiometry.h): the camera equation, LED profile, shading,
// phasors and per-pixel sums against hand-computed values.
#include "radiometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tofcam/core/units.h"
#include "tofcam/sim/camera_model.h"
#include "tofcam/sim/scene.h"

namespace tofcam::sim::internal {
namespace {

TEST(RadiometryTest, RadiometricConstantFollowsTheCameraEquation) {
  CameraModel m;
  m.f_number = 2.0;
  m.pixel_pitch_x_um = 40;
  m.pixel_pitch_y_um = 50;
  m.fill_factor = 0.5;
  m.quantum_efficiency = 0.8;
  m.wavelength_nm = 850;
  m.tap_duty = 0.25;
  // pi / (4 * 4) * 2e-9 m^2 * 0.5 * 0.8 * (850e-9 / (h c)) * 0.25, by hand:
  const double photons_per_j = 850e-9 / (6.62607015e-34 * 299792458.0);
  const double expected = kPi / 16 * 2e-9 * 0.5 * 0.8 * photons_per_j * 0.25;
  EXPECT_NEAR(RadiometricConstant(m) / expected, 1.0, 1e-12);
  m.f_number = 1.0;  // four times the light
  EXPECT_NEAR(RadiometricConstant(m) / expected, 4.0, 1e-12);
}

TEST(RadiometryTest, LedProfileHalvesAtTheHalfAngleAndCarriesItsPower) {
  CameraModel m;
  m.led_half_angle_deg = 60;  // cos 60 = 1/2: Lambertian, m = 1
  m.led_power_w = 2.0;
  EXPECT_NEAR(LedExponent(m), 1.0, 1e-12);
  EXPECT_NEAR(LedOnAxisWPerSr(m), 2.0 / kPi, 1e-12);  // P (m + 1) / (2 pi)
  m.led_half_angle_deg = 30;
  EXPECT_NEAR(std::pow(std::cos(30 * kPi / 180), LedExponent(m)), 0.5, 1e-12);
}

TEST(RadiometryTest, PixelRaysCarryTheCosineFourthFalloffAndLedProfile) {
  CameraModel m = WithResolution(ResolveCameraModel("sr2"), 8, 6);
  PixelRays rays;
  rays.group = 1;
  SubsampleRadiometry rad;
  BuildPixelRays(m, 2, rays, rad);
  ASSERT_EQ(rad.sub_bg.size(), 8u * 6u * 4u);
  const double k = RadiometricConstant(m);
  const double m_exp = LedExponent(m);
  const double i0 = LedOnAxisWPerSr(m);
  for (int p = 0; p < 48; ++p) {
    float sum = 0;
    for (int s = 0; s < 4; ++s) {
      const std::size_t i = static_cast<std::size_t>(p) * 4 + s;
      const double cz = rays.sub_z[i];  // unit direction: z is the cosine to the axis
      EXPECT_NEAR(std::hypot(std::hypot(rays.sub_x[i], rays.sub_y[i]), rays.sub_z[i]), 1.0, 1e-6);
      EXPECT_NEAR(rad.sub_bg[i] / (k * std::pow(cz, 4) / 4), 1.0, 1e-5);
      EXPECT_NEAR(rad.sub_active[i] / rad.sub_bg[i], i0 * std::pow(cz, m_exp), 1e-4 * i0);
      sum += rad.sub_bg[i];
    }
    EXPECT_FLOAT_EQ(rad.pixel_bg[p], sum);
  }
}

TEST(RadiometryTest, MaterialsAreLambertPlusNormalisedLobeWithAZeroMissEntry) {
  const Scene scene = ParseScene(
      "materials: {a: {albedo: 0.8}, g: {albedo: 0.2, specular: 0.5, shininess: 12}, "
      "m: {albedo: 0.1, mirror: 0.9}}\nobjects:\n"
      "  - {type: plane, material: a, size_m: [1, 1], position_m: [0, 0, 1]}\n"
      "  - {type: plane, material: g, size_m: [1, 1], position_m: [0, 0, 2]}\n"
      "  - {type: plane, material: m, size_m: [1, 1], position_m: [0, 0, 3]}\n",
      "inline", {});
  const MaterialTable t = BuildMaterials(scene, true);
  ASSERT_EQ(t.mat_diffuse.size(), 4u);
  EXPECT_FLOAT_EQ(t.mat_diffuse[0], static_cast<float>(0.8 / kPi));
  EXPECT_FLOAT_EQ(t.mat_glossy[1], static_cast<float>(0.5 * 20 / (8 * kPi)));
  EXPECT_EQ(t.mat_power[1], 12);
  EXPECT_EQ(t.power_bits, 4);  // 12 = 0b1100
  EXPECT_TRUE(t.any_mirror);
  EXPECT_EQ(t.mat_diffuse[3], 0.f);
  EXPECT_EQ(t.mat_glossy[3], 0.f);
  EXPECT_EQ(BuildMaterials(scene, false).mat_glossy[1], 0.f);
}

TEST(RadiometryTest, CosIncidenceAndShading) {
  const float nx[2] = {0, 0}, ny[2] = {0, 0}, nz[2] = {-2, 1};  // normals need not be unit
  const float dx[2] = {0, 0}, dy[2] = {0.6f, 0}, dz[2] = {0.8f, 1};
  float cos_i[2];
  CosIncidence(2, nx, ny, nz, dx, dy, dz, cos_i);
  EXPECT_NEAR(cos_i[0], 0.8f, 1e-7f);
  EXPECT_NEAR(cos_i[1], 1.0f, 1e-7f);
  // Object 0 diffuse, object 1 glossy; index 2 is the miss entry.
  const unsigned geom[3] = {0, 1, RTC_INVALID_GEOMETRY_ID};
  const float t[3] = {2, 3, std::numeric_limits<float>::infinity()};
  const float cin[3] = {0.5f, 0.7f, 123.f}, bg_k[3] = {10, 10, 10};
  const float diffuse[3] = {0.25f, 0.1f, 0}, glossy[3] = {0, 0.4f, 0}, radiance[3] = {2, 3, 0};
  float brdf[3], cos_out[3], dist[3], bg[3];
  unsigned at[3];
  const std::size_t n_glossy = ShadeSurfaces(3, 2, geom, t, cin, bg_k, diffuse, glossy, radiance,
                                             brdf, cos_out, dist, bg, at);
  EXPECT_EQ(n_glossy, 1u);
  EXPECT_EQ(at[0], 1u);
  EXPECT_FLOAT_EQ(brdf[0], 0.25f);
  EXPECT_FLOAT_EQ(dist[1], 3.f);
  EXPECT_FLOAT_EQ(bg[1], 30.f);
  EXPECT_EQ(brdf[2], 0.f);     // a miss reflects nothing
  EXPECT_EQ(cos_out[2], 0.f);  // and its garbage normal is ignored
  EXPECT_EQ(dist[2], 1.f);     // finite, so its phase stays finite
  EXPECT_EQ(bg[2], 0.f);
}

TEST(RadiometryTest, PhasorFallsWithDistanceSquaredAndTurnsWithPathLength) {
  const float range = 7.5f;
  const float dist[2] = {range / 4, range / 2};
  float weight[2] = {8, 8}, re[2], im[2];
  Phasors(2, 1 / range, 0.5f, dist, weight, re, im);
  EXPECT_NEAR(weight[0], 8 / (dist[0] * dist[0]), 1e-5f);
  EXPECT_NEAR(re[0], 0.f, 1e-4f);  // a quarter of L: 90 degrees
  EXPECT_NEAR(im[0], 0.5f * weight[0], 1e-4f * weight[0]);
  EXPECT_NEAR(re[1], -0.5f * weight[1], 1e-4f * weight[1]);  // half of L: 180 degrees
  EXPECT_NEAR(im[1], 0.f, 1e-4f);
}

TEST(RadiometryTest, GlossyLobeIsCosineToTheWholePower) {
  const float x[3] = {0.5f, 0.9f, 0.3f};
  const int n[3] = {3, 0, 12};
  double base[3], result[3];
  PowIntRow(3, 4, x, n, base, result);
  EXPECT_EQ(result[0], 0.125);
  EXPECT_EQ(result[1], 1.0);
  const double x2 = 0.3f;  // the float input, exactly
  EXPECT_NEAR(result[2], std::pow(x2, 12), 1e-14 * std::pow(x2, 12));
}

TEST(RadiometryTest, SubsampleSumsAndDistanceSpan) {
  const float inf = std::numeric_limits<float>::infinity();
  // Three pixels of four subsamples, pixel-major (group 1): all hit, one misses, all miss.
  const float re[12] = {1, 2, 3, 4, 1, 1, 1, 0, 0, 0, 0, 0};
  const float im[12] = {0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0};
  const float active[12] = {1, 1, 1, 1, 2, 2, 2, 0, 0, 0, 0, 0};
  const float bg[12] = {0.5f, 0.5f, 0.5f, 0.5f, 0, 0, 0, 1, 1, 1, 1, 1};
  const float t[12] = {2.0f, 2.1f, 2.5f, 2.2f, 1, 1, 1, inf, inf, inf, inf, inf};
  float out_re[3], out_im[3], out_dc[3], span[3], near[3], far[3];
  SumSubsamples(1, 3, 4, re, im, active, bg, t, out_re, out_im, out_dc, span, near, far);
  EXPECT_FLOAT_EQ(out_re[0], 10.f);
  EXPECT_FLOAT_EQ(out_im[0], 1.f);
  EXPECT_FLOAT_EQ(out_dc[0], 6.f);
  EXPECT_FLOAT_EQ(span[0], 0.5f);
  EXPECT_EQ(span[1], inf);  // some subsamples miss: the pixel straddles an edge to nothing
  EXPECT_EQ(span[2], 0.f);  // all miss
  EXPECT_FLOAT_EQ(out_dc[2], 4.f);
  // Footprint: nearest and farthest hit; a miss counts for neither.
  EXPECT_EQ(near[0], 2.0f);
  EXPECT_EQ(far[0], 2.5f);
  EXPECT_EQ(near[1], 1.0f);
  EXPECT_EQ(far[1], 1.0f);
  EXPECT_EQ(near[2], inf);
  EXPECT_EQ(far[2], 0.f);
}

TEST(RadiometryTest, FootprintOfTheVectorisedGroupOfFour) {
  // Group 4 (SumBlocks4): subsample s of pixel g at index s * 4 + g. Pixel 0 straddles an edge
  // (1 m and 3 m), pixel 1 sees one wall, pixel 2 misses once, pixel 3 misses always.
  const float inf = std::numeric_limits<float>::infinity();
  float t[16], zero[16] = {};
  const float per_pixel[4][4] = {
      {3, 1, 3, 1}, {2, 2.01f, 2.02f, 2.03f}, {inf, 5, 4, 6}, {inf, inf, inf, inf}};
  for (int g = 0; g < 4; ++g) {
    for (int s = 0; s < 4; ++s) t[s * 4 + g] = per_pixel[g][s];
  }
  float out_re[4], out_im[4], out_dc[4], span[4], near[4], far[4];
  SumSubsamples(4, 4, 4, zero, zero, zero, zero, t, out_re, out_im, out_dc, span, near, far);
  EXPECT_EQ(near[0], 1.f);
  EXPECT_EQ(far[0], 3.f);
  EXPECT_EQ(span[0], 2.f);
  EXPECT_EQ(near[1], 2.f);
  EXPECT_EQ(far[1], 2.03f);
  EXPECT_EQ(near[2], 4.f);
  EXPECT_EQ(far[2], 6.f);
  EXPECT_EQ(span[2], inf);
  EXPECT_EQ(near[3], inf);
  EXPECT_EQ(far[3], 0.f);
  EXPECT_EQ(span[3], 0.f);
}

TEST(RadiometryTest, LampIrradianceIsInverseSquareWithCosine) {
  Scene scene;
  Lamp lamp;
  lamp.position_m = Eigen::Vector3d(0, 0, 2);
  lamp.ir_power_w = 4 * kPi;  // 1 W/sr
  scene.lamps.push_back(lamp);
  scene.lamp_bulb_begin = 5;
  const std::vector<char> on = {1}, off = {0};
  EXPECT_NEAR(LampIrradiance(scene, {0, 0, 0}, {0, 0, 1}, 0, on), 0.25f, 1e-6f);
  // 45 degrees: cos 45 / (2 sqrt 2)^2... the lamp at (2, 0, 2): d^2 = 8, cos = 1 / sqrt 2.
  EXPECT_NEAR(LampIrradiance(scene, {-2, 0, 0}, {0, 0, 1}, 0, on),
              static_cast<float>(1.0 / std::sqrt(2.0) / 8), 1e-6f);
  EXPECT_EQ(LampIrradiance(scene, {0, 0, 0}, {0, 0, 1}, 0, off), 0.f);
  EXPECT_EQ(LampIrradiance(scene, {0, 0, 0}, {0, 0, 1}, 5, on), 0.f);  // its own bulb
}

}  // namespace
}  // namespace tofcam::sim::internal
