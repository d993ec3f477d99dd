#include "tofcam/filters/filter_set.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

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

TEST(FilterSetTest, EqualsChainingOnNoisyFramesWithDenseAndSparseRows) {
  // 10 cm of noise on the scene's distances and 20 % on its amplitudes, over every row or over
  // alternating bands of 7 rows: rows with many flying-pixel candidates (decided two at a time)
  // and rows with few (decided one candidate at a time, the scene's box edges) follow each
  // other. The set echoes the flying-pixel bits into the union the jump-edge filter reads; the
  // result must equal chaining the public filters. Rows and columns are the scene's (not
  // multiples of the vector width). (A row prepared again after its bits were echoed changes
  // only contrast tests next to flagged pixels; a mutation doing that was not caught here.)
  for (const bool banded : {false, true}) {
    SCOPED_TRACE(banded);
    test::Scene s = Prepared();
    std::mt19937 rng(5);
    std::normal_distribution<float> noise(0.0f, 1.0f);
    const int w = s.frame.width();
    for (std::size_t i = 0; i < s.frame.radial_distance_m.size(); ++i) {
      if (banded && (static_cast<int>(i) / w / 7) % 2 == 0) continue;
      s.frame.radial_distance_m[i] += 0.1f * noise(rng);
      s.frame.amplitude[i] *= 1.0f + 0.2f * noise(rng);
    }
    FilterSetOptions o;  // saturation and accuracy on by default
    o.flying_pixel_enabled = o.jump_edge_enabled = true;
    const Image<PixelFlags> combined = ApplyFilters(s.frame, s.rays, o);
    MetricFrame f = s.frame;
    MergeFlags(f, SaturationFilter(f, o.saturation));
    MergeFlags(f, AccuracyThresholdFilter(f, o.accuracy));
    const Image<PixelFlags> flying = FlyingPixelFilter(f, o.flying_pixel);
    MergeFlags(f, flying);
    MergeFlags(f, JumpEdgeFilter(f, s.rays, o.jump_edge));
    int flying_count = 0;
    for (std::size_t i = 0; i < combined.size(); ++i) {
      ASSERT_EQ((combined[i] | s.frame.flags[i]).bits(), f.flags[i].bits()) << i;
      flying_count += flying[i].Has(Flag::kFlyingPixel) ? 1 : 0;
    }
    // The dense regime really occurs: far more than a few per cent of pixels are flagged.
    EXPECT_GT(flying_count, static_cast<int>(combined.size() / (banded ? 40 : 20)));
  }
}

FilterSetOptions AllEnabled() {
  FilterSetOptions o;
  o.range_enabled = o.amplitude_enabled = o.saturation_enabled = o.accuracy_enabled = true;
  o.flying_pixel_enabled = o.jump_edge_enabled = o.weingarten_enabled = true;
  o.weingarten.min_points = 3;
  return o;
}

// The scene with a deterministic ripple on the distances (frame k of a sequence), so that each
// frame raises other flags.
MetricFrame Rippled(const test::Scene& s, int k) {
  MetricFrame f = s.frame;
  for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
    f.radial_distance_m[i] += 0.03f * std::sin(0.37f * static_cast<float>(i) + 1.3f * k);
  }
  f.radial_distance_m[static_cast<std::size_t>(100 + 31 * k)] = std::nanf("");
  return f;
}

TEST(FilterSetTest, PreparedSetEqualsApplyFiltersBitForBit) {
  const test::Scene s = Prepared();
  std::vector<FilterSetOptions> sets;
  sets.push_back(AllEnabled());
  sets.push_back({});  // the paper's defaults
  FilterSetOptions jump;
  jump.jump_edge_enabled = true;
  jump.jump_edge.max_angle_deg = 150.0;  // not the default: the prepared λ follow the options
  sets.push_back(jump);
  FilterSetOptions cells;
  cells.weingarten_enabled = true;
  cells.weingarten.voxel_size_m = 0.05;
  sets.push_back(cells);
  for (const FilterSetOptions& o : sets) {
    const FilterSet set(o, s.rays);
    const FilterSet copy = set;  // copies share the prepared tables
    Image<PixelFlags> reused;
    for (int k = 0; k < 4; ++k) {
      const MetricFrame f = Rippled(s, k);
      const Image<PixelFlags> want = ApplyFilters(f, s.rays, o);
      set.Process(f, reused);
      const Image<PixelFlags> fresh = copy.Process(f);
      ASSERT_TRUE(reused.SameSize(want));
      for (std::size_t i = 0; i < want.size(); ++i) {
        ASSERT_EQ(reused[i].bits(), want[i].bits()) << "frame " << k << " pixel " << i;
        ASSERT_EQ(fresh[i].bits(), want[i].bits()) << "frame " << k << " pixel " << i;
      }
    }
  }
}

TEST(FilterSetTest, OneNeighbourhoodFilterAloneEqualsItsOwnFunction) {
  // With no per-pixel filter before it, a set of one neighbourhood filter reads the frame's
  // flags in place: the same flags as the filter's public function on the frame.
  const test::Scene s = Prepared();
  for (int k = 0; k < 3; ++k) {
    MetricFrame f = Rippled(s, k);
    for (std::size_t i = 0; i < f.flags.size(); i += 13) f.flags[i] = Flag::kHighDeltaL;
    FilterSetOptions o;
    o.accuracy_enabled = o.saturation_enabled = false;
    o.flying_pixel_enabled = true;
    EXPECT_EQ(FilterSet(o, s.rays).Process(f), FlyingPixelFilter(f, o.flying_pixel));
    EXPECT_EQ(ApplyFilters(f, s.rays, o), FlyingPixelFilter(f, o.flying_pixel));
    o.flying_pixel_enabled = false;
    o.jump_edge_enabled = true;
    EXPECT_EQ(FilterSet(o, s.rays).Process(f), JumpEdgeFilter(f, s.rays, o.jump_edge));
    EXPECT_EQ(ApplyFilters(f, s.rays, o), JumpEdgeFilter(f, s.rays, o.jump_edge));
    o.jump_edge_enabled = false;
    o.weingarten_enabled = true;
    o.weingarten.min_points = 3;
    EXPECT_EQ(FilterSet(o, s.rays).Process(f), WeingartenCellFilter(f, s.rays, o.weingarten));
    EXPECT_EQ(ApplyFilters(f, s.rays, o), WeingartenCellFilter(f, s.rays, o.weingarten));
  }
}

// The SR-2 with 157 x 123 pixels (no multiple of 8 or 16: the loops' vector tails run).
CameraIntrinsics OddSr2() {
  CameraIntrinsics odd = CameraIntrinsics::SwissRangerSr2();
  odd.width = 157;
  odd.height = 123;
  odd.cx_px = (157 - 1) / 2.0;
  odd.cy_px = (123 - 1) / 2.0;
  return odd;
}

// A frame for the per-pixel thresholds: the scene of an odd size (vector tails), rippled, with
// pixels at each threshold's edges and non-finite values: amplitude at the saturation limit, the
// sum of amplitude and intensity at the peak limit, NaN amplitude, intensity and ΔL, a negative
// ΔL, distances outside the range filter's limits.
MetricFrame ThresholdFrame(int k, bool with_intensity) {
  const test::Scene s = test::MakeScene(OddSr2());
  MetricFrame f = Rippled(s, k);
  const float nan = std::nanf("");
  const SaturationOptions sat;
  const std::size_t n = f.radial_distance_m.size();
  for (std::size_t i = static_cast<std::size_t>(k); i < n; i += 97) {
    switch ((i / 97) % 8) {
      case 0:
        f.amplitude[i] = static_cast<float>(sat.max_amplitude);
        break;
      case 1:  // the sum at the peak limit, each channel below its own
        f.amplitude[i] = static_cast<float>(sat.max_peak / 2);
        f.intensity[i] = static_cast<float>(sat.max_peak / 2 + 1);
        break;
      case 2:
        f.amplitude[i] = nan;
        break;
      case 3:
        f.intensity[i] = nan;
        break;
      case 4:
        f.delta_l_m[i] = nan;
        break;
      case 5:
        f.delta_l_m[i] = -0.01f;
        break;
      case 6:
        f.radial_distance_m[i] = 12.0f;
        break;
      default:
        f.amplitude[i] = 50.0f;  // below the amplitude threshold below
        break;
    }
  }
  if (!with_intensity) f.intensity = Image<float>();
  return f;
}

// Each subset of the per-pixel thresholds in a set (the single ones run their own compiled
// forms, the others the form for all four): its flags are the OR of the public filters', also
// written into an output reused with every bit set (the set overwrites each pixel, it does not OR
// into what was there). With and without intensity, on an odd frame size.
TEST(FilterSetTest, EverySetOfPerPixelFiltersEqualsThePublicFilters) {
  const RayTable rays = MakeRayTable(OddSr2());
  for (const bool with_intensity : {true, false}) {
    for (int k = 0; k < 2; ++k) {
      const MetricFrame f = ThresholdFrame(k, with_intensity);
      for (unsigned set = 1; set < 16; ++set) {
        const FilterSetOptions o = test::ThresholdSet(set);
        Image<PixelFlags> want(f.width(), f.height());
        auto merge = [&want](const Image<PixelFlags>& raised) {
          for (std::size_t i = 0; i < want.size(); ++i) want[i] |= raised[i];
        };
        if (o.range_enabled) merge(RangeFilter(f, o.range));
        if (o.amplitude_enabled) merge(AmplitudeThresholdFilter(f, o.amplitude));
        if (o.saturation_enabled) merge(SaturationFilter(f, o.saturation));
        if (o.accuracy_enabled) merge(AccuracyThresholdFilter(f, o.accuracy));
        std::size_t raised = 0;
        for (std::size_t i = 0; i < want.size(); ++i) raised += want[i].None() ? 0 : 1;
        ASSERT_GT(raised, 0u) << "set " << set << ": the frame must raise some pixels";
        ASSERT_LT(raised, want.size()) << "set " << set << ": and keep some";
        EXPECT_EQ(ApplyFilters(f, rays, o), want) << "set " << set;
        Image<PixelFlags> reused(f.width(), f.height(),
                                 PixelFlags(static_cast<std::uint16_t>(0xFFFF)));
        FilterSet(o, rays).Process(f, reused);
        EXPECT_EQ(reused, want) << "set " << set << " into a reused output";
      }
    }
  }
}

TEST(FilterSetTest, ApplyFiltersNoticesOtherRaysOfTheSameSize) {
  // ApplyFilters keeps the jump test's λ per thread and must rebuild them for other rays; a
  // wider lens (another focal length, same size) changes which pixels are jump edges.
  const test::Scene s = Prepared();
  CameraIntrinsics wide = CameraIntrinsics::SwissRangerSr2();
  wide.fx_px *= 0.5;
  wide.fy_px *= 0.5;
  const RayTable wide_rays = MakeRayTable(wide);
  FilterSetOptions o;
  o.accuracy_enabled = o.saturation_enabled = false;
  o.jump_edge_enabled = true;
  o.jump_edge.max_angle_deg = 100.0;
  const Image<PixelFlags> narrow = ApplyFilters(s.frame, s.rays, o);
  const Image<PixelFlags> after = ApplyFilters(s.frame, wide_rays, o);  // right after `narrow`
  const Image<PixelFlags> want = FilterSet(o, wide_rays).Process(s.frame);
  int differ = 0;
  for (std::size_t i = 0; i < want.size(); ++i) {
    differ += narrow[i] != want[i] ? 1 : 0;
    ASSERT_EQ(after[i].bits(), want[i].bits()) << i;
  }
  EXPECT_GT(differ, 0);  // the two lenses do give other flags, so a stale λ would be seen
}

TEST(FilterSetTest, PreparedSetRefusesBadOptionsRaysAndFrames) {
  const test::Scene s = Prepared();
  FilterSetOptions bad;
  bad.weingarten_enabled = true;
  bad.weingarten.min_points = 0;
  try {
    const FilterSet set(bad, s.rays);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("min_points"), std::string::npos);
  }
  RayTable uneven = s.rays;
  uneven.z = Image<float>(3, 3);
  try {
    const FilterSet set(AllEnabled(), uneven);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
  const FilterSet set(AllEnabled(), s.rays);
  MetricFrame small;
  small.radial_distance_m = Image<float>(8, 8, 1.0f);
  small.amplitude = Image<float>(8, 8, 1000.0f);
  small.intensity = Image<float>(8, 8, 2000.0f);
  small.delta_l_m = Image<float>(8, 8, 0.01f);
  try {
    (void)set.Process(small);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
}

TEST(FilterSetTest, ConcurrentProcessCallsGiveTheSameFlags) {
  // Documented as safe from several threads (per-thread scratch, shared immutable tables).
  const test::Scene s = Prepared();
  const FilterSet set(AllEnabled(), s.rays);
  std::vector<MetricFrame> frames;
  std::vector<Image<PixelFlags>> want;
  for (int k = 0; k < 4; ++k) {
    frames.push_back(Rippled(s, k));
    want.push_back(ApplyFilters(frames.back(), s.rays, AllEnabled()));
  }
  std::vector<int> mismatches(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      Image<PixelFlags> out;
      for (int rep = 0; rep < 20; ++rep) {
        const int k = (t + rep) % 4;
        set.Process(frames[k], out);
        for (std::size_t i = 0; i < out.size(); ++i) mismatches[t] += out[i] != want[k][i];
      }
    });
  }
  for (std::thread& th : threads) th.join();
  EXPECT_EQ(mismatches, std::vector<int>(4, 0));
}

TEST(FilterSetTest, MovedFromSetRefusesToRun) {
  const test::Scene s = Prepared();
  FilterSet set(AllEnabled(), s.rays);
  const FilterSet moved = std::move(set);
  EXPECT_TRUE(moved.Process(s.frame).SameSize(s.frame.radial_distance_m));
  try {
    (void)set.Process(s.frame);  // NOLINT(bugprone-use-after-move): the point of the test
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInvalidArgument);
  }
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
