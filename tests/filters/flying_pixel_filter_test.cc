#include "tofcam/filters/flying_pixel_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "test_scene.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// 11 x 3 image: columns 0-4 near (1 m, bright), column 5 a mixed pixel half-way (2 m),
// columns 6-10 far (3 m, dark). Amplitude falls with 1/d² as the physics would have it.
MetricFrame EdgeFrame() {
  MetricFrame f;
  f.radial_distance_m = Image<float>(11, 3);
  f.amplitude = Image<float>(11, 3);
  f.flags = Image<PixelFlags>(11, 3);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 11; ++c) {
      const float d = c < 5 ? 1.0f : (c == 5 ? 2.0f : 3.0f);
      f.radial_distance_m(r, c) = d;
      f.amplitude(r, c) = 9000.0f / (d * d);
    }
  }
  return f;
}

TEST(FlyingPixelFilterTest, FlagsMixedPixelBetweenSurfacesOnly) {
  const MetricFrame f = EdgeFrame();
  const Image<PixelFlags> out = FlyingPixelFilter(f, {});
  // Column 5: d - dmin = 1 m > 0.05, dmax - d = 1 m > 0.03, max 1 m > 0.1, and the window's
  // amplitudes (9000, 2250, 1000) have std/mean far above 0.05. Columns 4 and 6 sit at the
  // window minimum / maximum themselves, so one of the two distance tests fails.
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 11; ++c) {
      EXPECT_EQ(out(r, c).Has(Flag::kFlyingPixel), c == 5) << r << "," << c;
      EXPECT_EQ(out(r, c).bits() & ~static_cast<std::uint16_t>(Flag::kFlyingPixel), 0);
    }
  }
}

TEST(FlyingPixelFilterTest, NeedsAmplitudeContrast) {
  // Same geometry with a flat amplitude: std/mean = 0 < 0.05, so the edge is not "edge-aware"
  // confirmed and nothing is flagged.
  MetricFrame f = EdgeFrame();
  f.amplitude.Fill(3000.0f);
  const Image<PixelFlags> out = FlyingPixelFilter(f, {});
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(out[i].None()) << i;
  // The floor on the mean: amplitudes 0.9 / 0.225 / 0.1 have a large relative spread but a
  // std of ~0.35, far below 0.05 x the floor of 50, so nothing is flagged either.
  MetricFrame dim = EdgeFrame();
  for (std::size_t i = 0; i < dim.amplitude.size(); ++i) dim.amplitude[i] *= 1e-4f;
  const Image<PixelFlags> out2 = FlyingPixelFilter(dim, {});
  for (std::size_t i = 0; i < out2.size(); ++i) EXPECT_TRUE(out2[i].None()) << i;
}

TEST(FlyingPixelFilterTest, IgnoresRejectedPixels) {
  // With the far side rejected, the mixed pixel has no farther neighbour left: dmax = d.
  MetricFrame f = EdgeFrame();
  for (int r = 0; r < 3; ++r) {
    for (int c = 6; c < 11; ++c) f.flags(r, c) = Flag::kLowAmplitude;
  }
  Image<PixelFlags> out = FlyingPixelFilter(f, {});
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(out[i].None()) << i;
  // A rejected pixel itself is not judged.
  MetricFrame g = EdgeFrame();
  for (int r = 0; r < 3; ++r) g.flags(r, 5) = Flag::kSaturated;
  out = FlyingPixelFilter(g, {});
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(out[i].None()) << i;
}

TEST(FlyingPixelFilterTest, SmoothSceneKeepsInteriorPixels) {
  // On the plane-and-box scene only pixels at the box outline may be flagged.
  const test::Scene s = test::MakeScene();
  const Image<PixelFlags> out = FlyingPixelFilter(s.frame, {});
  for (int r = 1; r + 1 < s.frame.height(); ++r) {
    for (int c = 1; c + 1 < s.frame.width(); ++c) {
      bool mixed_window = false;
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) mixed_window |= s.on_box(r + dr, c + dc) != s.on_box(r, c);
      }
      if (!mixed_window) {
        EXPECT_FALSE(out(r, c).Has(Flag::kFlyingPixel)) << r << "," << c;
      }
    }
  }
}

TEST(FlyingPixelFilterTest, ErrorsAreReported) {
  MetricFrame f = EdgeFrame();
  FlyingPixelOptions bad;
  bad.amplitude_mean_floor = 0.0;
  EXPECT_THROW(bad.Validate(), Error);
  bad = {};
  bad.min_close_delta_m = -1.0;
  EXPECT_THROW((void)FlyingPixelFilter(f, bad), Error);
  f.amplitude = Image<float>();
  try {
    (void)FlyingPixelFilter(f, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
}

}  // namespace
}  // namespace tofcam
