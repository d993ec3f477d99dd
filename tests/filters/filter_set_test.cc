#include "tofcam/filters/filter_set.h"

#include <gtest/gtest.h>

#include "test_scene.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// The scene with a mixed pixel, a saturated pixel, a high-ΔL pixel and an outlier.
test::Scene Prepared() {
  test::Scene s = test::MakeScene();
  s.frame.delta_l_m(10, 10) = 0.5f;
  s.frame.intensity(20, 20) = 65532.0f;
  s.frame.amplitude(30, 30) = 5.0f;
  s.frame.radial_distance_m(40, 40) = 9.0f;
  s.frame.radial_distance_m(70, 100) = 0.7f;
  s.frame.flags(50, 50) = Flag::kInvalid;
  return s;
}

TEST(FilterSetTest, DefaultsRunAccuracyAndSaturationOnly) {
  const test::Scene s = Prepared();
  const Image<PixelFlags> out = ApplyFilters(s.frame, s.rays, {});
  EXPECT_EQ(out(10, 10), PixelFlags(Flag::kHighDeltaL));
  EXPECT_EQ(out(20, 20), PixelFlags(Flag::kSaturated));
  EXPECT_TRUE(out(30, 30).None());  // amplitude filter off by default
  EXPECT_TRUE(out(40, 40).None());  // range filter off by default
  EXPECT_TRUE(out(50, 50).None());  // returns raised flags only, not the frame's
}

TEST(FilterSetTest, EqualsChainingThePublicFiltersInDocumentedOrder) {
  test::Scene s = Prepared();
  FilterSetOptions o;
  o.range_enabled = o.amplitude_enabled = o.saturation_enabled = o.accuracy_enabled = true;
  o.flying_pixel_enabled = o.jump_edge_enabled = o.weingarten_enabled = true;
  o.weingarten.min_points = 3;
  const Image<PixelFlags> combined = ApplyFilters(s.frame, s.rays, o);

  // Independent path: run each public filter on a frame whose flags are updated in between.
  MetricFrame f = s.frame;
  MergeFlags(f, RangeFilter(f, o.range));
  MergeFlags(f, AmplitudeThresholdFilter(f, o.amplitude));
  MergeFlags(f, SaturationFilter(f, o.saturation));
  MergeFlags(f, AccuracyThresholdFilter(f, o.accuracy));
  MergeFlags(f, FlyingPixelFilter(f, o.flying_pixel));
  MergeFlags(f, JumpEdgeFilter(f, s.rays, o.jump_edge));
  MergeFlags(f, WeingartenCellFilter(f, s.rays, o.weingarten));
  int raised = 0;
  for (std::size_t i = 0; i < combined.size(); ++i) {
    ASSERT_EQ((combined[i] | s.frame.flags[i]).bits(), f.flags[i].bits()) << i;
    raised += combined[i].None() ? 0 : 1;
  }
  EXPECT_TRUE(combined(40, 40).Has(Flag::kOutOfRange));
  EXPECT_TRUE(combined(30, 30).Has(Flag::kLowAmplitude));
  // The lone point at 0.7 m is alone in its cell and in front of its neighbours.
  EXPECT_TRUE(combined(70, 100).Has(Flag::kSparseCell));
  EXPECT_GT(raised, 100);  // the box outline
}

TEST(FilterSetTest, ErrorsAreReported) {
  test::Scene s = Prepared();
  s.frame.delta_l_m = Image<float>();
  EXPECT_THROW((void)ApplyFilters(s.frame, s.rays, {}), Error);  // accuracy needs ΔL
  FilterSetOptions o;
  o.accuracy_enabled = false;
  EXPECT_NO_THROW((void)ApplyFilters(s.frame, s.rays, o));
  o.jump_edge_enabled = true;
  o.jump_edge.max_angle_deg = 200.0;
  EXPECT_THROW(o.Validate(), Error);
  o.jump_edge = {};
  RayTable wrong{Image<float>(2, 2), Image<float>(2, 2), Image<float>(2, 2)};
  try {
    (void)ApplyFilters(s.frame, wrong, o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
}

}  // namespace
}  // namespace tofcam
