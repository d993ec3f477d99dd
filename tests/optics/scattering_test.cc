#include "tofcam/optics/scattering.h"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <random>
#include <vector>

#include "tofcam/core/error.h"
#include "tofcam/core/units.h"
#include "tofcam/pipeline/pipeline.h"

namespace tofcam {
namespace {

constexpr int kW = 160, kH = 124;
const double kRange = UnambiguousRangeM(20e6);

TEST(ScatteringPsf, ConservesLightAndHasTheLobesVariance) {
  // One unit of light in the middle: the PSF spreads `weight` of it with variance sigma² per
  // axis, up to the rounding of three odd box widths (Kovesi 2010): widths wl and wl + 2 with
  // variance (w² - 1) / 12 each bracket sigma², so the error is at most half their difference,
  // (wl + 1) / 6 px², wl the largest odd width <= sqrt(4 sigma² + 1) (2 % in sigma at 9 px).
  std::vector<float> image(kW * kH, 0.0f);
  const int r0 = 62, c0 = 80;
  image[r0 * kW + c0] = 1.0f;
  for (double sigma : {2.0, 5.0, 9.0}) {
    const ScatteringLobe lobe{0.02, sigma};
    const std::vector<float> out = ApplyScatteringPsf(image, kW, kH, {&lobe, 1});
    double sum = 0, var_c = 0;
    for (int r = 0; r < kH; ++r) {
      for (int c = 0; c < kW; ++c) {
        sum += out[r * kW + c];
        var_c += out[r * kW + c] * (c - c0) * (c - c0);
      }
    }
    EXPECT_NEAR(sum, 0.02, 1e-6) << sigma;
    int wl = static_cast<int>(std::floor(std::sqrt(4 * sigma * sigma + 1)));
    if (wl % 2 == 0) --wl;
    EXPECT_NEAR(var_c / sum, sigma * sigma, (wl + 1) / 6.0 + 1e-3) << sigma;
  }
}

// A frame of true phasors `z` (amplitude registers, phase of distance), with the scattered
// light of `lobes` added as the camera's optics would, stored in registers.
Frame Encode(const std::vector<std::complex<double>>& z, const std::vector<double>& dc) {
  Frame f;
  f.distance = Image<std::uint16_t>(kW, kH);
  f.amplitude = Image<std::uint16_t>(kW, kH);
  f.intensity = Image<std::uint16_t>(kW, kH);
  f.info.modulation_frequency_hz = 20e6;
  for (std::size_t i = 0; i < z.size(); ++i) {
    double phi = std::arg(z[i]);
    if (phi < 0) phi += 2 * kPi;
    f.distance[i] = static_cast<std::uint16_t>(std::lround(phi / (2 * kPi) * 65536.0) & 0xFFFF);
    f.amplitude[i] = static_cast<std::uint16_t>(std::lround(std::abs(z[i])));
    f.intensity[i] = static_cast<std::uint16_t>(std::lround(dc[i]));
  }
  return f;
}

struct Scene {
  std::vector<std::complex<double>> z;
  std::vector<double> dc;
};

// A dim wall at 4 m with a bright card at 0.5 m in a 40 x 30 block (50x the wall's amplitude).
Scene CardScene(bool card) {
  Scene s;
  for (int r = 0; r < kH; ++r) {
    for (int c = 0; c < kW; ++c) {
      const bool in = card && r >= 47 && r < 77 && c >= 60 && c < 100;
      const double a = in ? 20000.0 : 400.0, d = in ? 0.5 : 4.0;
      s.z.push_back(std::polar(a, 2 * kPi * d / kRange));
      s.dc.push_back(2.5 * a);
    }
  }
  return s;
}

Scene Scatter(const Scene& truth, const std::vector<ScatteringLobe>& lobes) {
  std::vector<float> re, im, dc;
  for (std::size_t i = 0; i < truth.z.size(); ++i) {
    re.push_back(static_cast<float>(truth.z[i].real()));
    im.push_back(static_cast<float>(truth.z[i].imag()));
    dc.push_back(static_cast<float>(truth.dc[i]));
  }
  const auto sre = ApplyScatteringPsf(re, kW, kH, lobes);
  const auto sim = ApplyScatteringPsf(im, kW, kH, lobes);
  const auto sdc = ApplyScatteringPsf(dc, kW, kH, lobes);
  Scene out = truth;
  for (std::size_t i = 0; i < out.z.size(); ++i) {
    out.z[i] += std::complex<double>(sre[i], sim[i]);
    out.dc[i] += sdc[i];
  }
  return out;
}

double Metres(const Frame& f, std::size_t i) { return f.distance[i] * kRange / 65536.0; }

TEST(ScatteringPsf, IsTheSameAlongRowsAndColumns) {
  // The PSF is separable and symmetric, so blurring an image and blurring its transpose must
  // agree up to rounding. Rows and columns are computed by different code (prefix sums four
  // rows at a time with clamped borders, and running column sums), so this checks the borders,
  // windows wider than the image and row counts that are not a multiple of four. Tolerance:
  // each of the six box passes rounds to float (6e-8 relative) and the two forms sum in double
  // in different orders; 1e-5 of the largest value bounds both with a wide margin.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1000.0f);
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {3, 7}, {13, 9}, {40, 21}}) {
    std::vector<float> image(static_cast<std::size_t>(w) * h), transposed(image.size());
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        image[static_cast<std::size_t>(r) * w + c] = u(rng);
        transposed[static_cast<std::size_t>(c) * h + r] =
            image[static_cast<std::size_t>(r) * w + c];
      }
    }
    for (double sigma : {1.5, 4.0, 12.0}) {
      const ScatteringLobe lobe{0.3, sigma};
      const std::vector<float> a = ApplyScatteringPsf(image, w, h, {&lobe, 1});
      const std::vector<float> b = ApplyScatteringPsf(transposed, h, w, {&lobe, 1});
      for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) {
          ASSERT_NEAR(a[static_cast<std::size_t>(r) * w + c],
                      b[static_cast<std::size_t>(c) * h + r], 1e-5 * 1000.0)
              << w << "x" << h << " sigma " << sigma << " at (" << r << ", " << c << ")";
        }
      }
    }
  }
}

TEST(CompensateScattering, RemovesTheHaloOfABrightCard) {
  const std::vector<ScatteringLobe> lobes = {{0.01, 6.0}, {0.01, 32.0}};
  const Scene truth = CardScene(true);
  const Frame measured = Encode(Scatter(truth, lobes).z, Scatter(truth, lobes).dc);
  ScatteringOptions options;
  options.lobes = lobes;
  const Frame fixed = CompensateScattering(measured, options);
  // The wall pixels next to the card are pulled towards 0.5 m by decimetres before; after, each
  // is within 2 mm of 4 m (registers quantise phase to 0.11 mm and amplitude to 1 in 400; the
  // iteration's remainder falls like 0.02^4).
  double worst_before = 0, worst_after = 0;
  for (int r = 30; r < 94; ++r) {
    for (int c = 40; c < 120; ++c) {
      if (r >= 47 && r < 77 && c >= 60 && c < 100) continue;
      const std::size_t i = static_cast<std::size_t>(r) * kW + c;
      worst_before = std::max(worst_before, std::abs(Metres(measured, i) - 4.0));
      worst_after = std::max(worst_after, std::abs(Metres(fixed, i) - 4.0));
    }
  }
  EXPECT_GT(worst_before, 0.1);
  EXPECT_LT(worst_after, 0.002);
  // Amplitude and intensity of the wall come back too (within 1 register + 0.5 %).
  const std::size_t i = 40 * kW + 80;
  EXPECT_NEAR(fixed.amplitude[i], 400, 3);
  EXPECT_NEAR(fixed.intensity[i], 1000, 6);
  // No lobes: the frame is returned unchanged.
  const Frame same = CompensateScattering(measured, ScatteringOptions{});
  EXPECT_EQ(same.distance, measured.distance);
}

TEST(CompensateScattering, LeavesUnknownPixelsAlone) {
  Frame f = Encode(CardScene(true).z, CardScene(true).dc);
  f.source_flags = Image<PixelFlags>(kW, kH);
  const std::size_t clipped = 60 * kW + 70;
  f.source_flags[clipped] = PixelFlags(Flag::kSaturated);
  ScatteringOptions options;
  options.lobes = {{0.02, 8.0}};
  const Frame out = CompensateScattering(f, options);
  EXPECT_EQ(out.distance[clipped], f.distance[clipped]);
  EXPECT_EQ(out.amplitude[clipped], f.amplitude[clipped]);
}

TEST(EstimateScatteringPsf, RecoversTheLobesFromACardScene) {
  // Widths on the default grid (third octaves): found exactly.
  const std::vector<ScatteringLobe> lobes = {{0.012, 6.35}, {0.008, 32.0}};
  const Scene without = Scatter(CardScene(false), lobes), with = Scatter(CardScene(true), lobes);
  const std::vector<Frame> a = {Encode(without.z, without.dc)}, b = {Encode(with.z, with.dc)};
  const ScatteringFit fit = EstimateScatteringPsf(a, b);
  ASSERT_EQ(fit.psf.lobes.size(), 2u);
  EXPECT_EQ(fit.psf.lobes[0].sigma_px, 6.35);
  EXPECT_EQ(fit.psf.lobes[1].sigma_px, 32.0);
  EXPECT_NEAR(fit.psf.lobes[0].weight, 0.012, 0.0012);
  EXPECT_NEAR(fit.psf.lobes[1].weight, 0.008, 0.0008);
  EXPECT_GT(fit.explained_fraction, 0.99);
  EXPECT_EQ(fit.target_pixels, 40 * 30);
}

TEST(CompensateScattering, PipelineStageIsTheFunctionFirst) {
  const std::vector<ScatteringLobe> lobes = {{0.01, 6.0}, {0.01, 32.0}};
  const Scene s = Scatter(CardScene(true), lobes);
  const Frame measured = Encode(s.z, s.dc);
  CameraInfo camera;
  camera.intrinsics = CameraIntrinsics::SwissRangerSr2();
  camera.modulation_frequency_hz = 20e6;
  PipelineOptions on;
  on.controller_enabled = false;
  on.scattering_enabled = true;
  on.scattering.lobes = lobes;
  PipelineOptions off = on;
  off.scattering_enabled = false;
  Pipeline with(on, camera), without(off, camera);
  ScatteringOptions options;
  options.lobes = lobes;
  const PipelineResult a = with.Process(measured);
  const PipelineResult b = without.Process(CompensateScattering(measured, options));
  EXPECT_EQ(a.frame.radial_distance_m, b.frame.radial_distance_m);
  EXPECT_EQ(a.frame.flags, b.frame.flags);
  on.scattering.lobes = {{0.6, 5.0}};
  EXPECT_THROW(Pipeline(on, camera), Error);
}

TEST(ScatteringOptions, BadValuesAreClearErrors) {
  ScatteringOptions o;
  o.lobes = {{0.3, 5.0}, {0.3, 20.0}};
  EXPECT_THROW(o.Validate(), Error);  // sum 0.6
  o.lobes = {{0.01, 0.0}};
  EXPECT_THROW(o.Validate(), Error);
  o.lobes = {{-0.01, 5.0}};
  EXPECT_THROW(o.Validate(), Error);
  o.lobes = {{0.01, 5.0}};
  o.iterations = 0;
  EXPECT_THROW(o.Validate(), Error);
  const Scene s = CardScene(false);
  const std::vector<Frame> a = {Encode(s.z, s.dc)};
  EXPECT_THROW((void)EstimateScatteringPsf(a, a), Error);  // no target
}

}  // namespace
}  // namespace tofcam
