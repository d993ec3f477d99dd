#include "tofcam/filters/weingarten_cell_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>
#include <utility>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "test_scene.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

// n x 1 frame whose rays are all (0, 0, 1): the points are (0, 0, d).
struct Line {
  MetricFrame frame;
  RayTable rays;
};
Line MakeLine(const std::vector<float>& d) {
  const int n = static_cast<int>(d.size());
  Line l;
  l.frame.radial_distance_m = Image<float>(n, 1);
  l.frame.flags = Image<PixelFlags>(n, 1);
  for (int i = 0; i < n; ++i) l.frame.radial_distance_m[i] = d[i];
  l.rays = {Image<float>(n, 1, 0.0f), Image<float>(n, 1, 0.0f), Image<float>(n, 1, 1.0f)};
  return l;
}

// Gives pixel i of the line the ray rays[i] (one per pixel).
template <std::size_t N>
void SetRays(Line& l, const float (&rays)[N][3]) {
  for (std::size_t i = 0; i < N; ++i) {
    l.rays.x[i] = rays[i][0];
    l.rays.y[i] = rays[i][1];
    l.rays.z[i] = rays[i][2];
  }
}

TEST(WeingartenCellFilterTest, HandCountedCells) {
  // Cells of 0.1 m along z: [1.0, 1.1) holds 4 points, [2.0, 2.1) holds 2, [3.5, 3.6) holds 1.
  const Line l = MakeLine({1.01f, 1.02f, 2.05f, 1.03f, 3.55f, 1.04f, 2.06f});
  WeingartenCellOptions o;
  o.voxel_size_m = 0.1;
  o.min_points = 3;
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  const bool expected[] = {false, false, true, false, true, false, true};
  for (int i = 0; i < 7; ++i) {
    EXPECT_EQ(out[i].Has(Flag::kSparseCell), expected[i]) << i;
    EXPECT_EQ(out[i].bits() & ~static_cast<std::uint16_t>(Flag::kSparseCell), 0);
  }
}

TEST(WeingartenCellFilterTest, RejectedPointsNeitherCountNorGetFlagged) {
  Line l = MakeLine({1.01f, 1.02f, 1.03f, 1.04f, std::nanf("")});
  l.frame.flags[3] = Flag::kHighDeltaL;  // leaves 3 usable points in the cell
  WeingartenCellOptions o;
  o.min_points = 4;
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  EXPECT_TRUE(out[0].Has(Flag::kSparseCell));
  EXPECT_TRUE(out[2].Has(Flag::kSparseCell));
  EXPECT_FALSE(out[3].Has(Flag::kSparseCell));  // rejected: not judged
  EXPECT_FALSE(out[4].Has(Flag::kSparseCell));  // NaN distance: not judged
}

TEST(WeingartenCellFilterTest, NegativeCoordinatesUseFloorCells) {
  // Points at x = -0.05 and x = +0.05 lie in different cells (-1 and 0), not both in cell 0.
  Line l = MakeLine({0.05f, 0.05f});
  l.rays.x[0] = -1.0f;
  l.rays.z[0] = 0.0f;
  l.rays.x[1] = 1.0f;
  l.rays.z[1] = 0.0f;
  WeingartenCellOptions o;
  o.min_points = 2;
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  EXPECT_TRUE(out[0].Has(Flag::kSparseCell));
  EXPECT_TRUE(out[1].Has(Flag::kSparseCell));
}

TEST(WeingartenCellFilterTest, ManyDistinctCellsGrowTheTable) {
  // 40000 points 1.5 mm apart along z with 1 mm cells: every point alone in its cell, far more
  // cells than the table's first size.
  std::vector<float> d(40000);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] = 0.5f + 0.0015f * static_cast<float>(i);
  const Line l = MakeLine(d);
  WeingartenCellOptions o;
  o.voxel_size_m = 0.001;
  o.min_points = 1;
  Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  for (std::size_t i = 0; i < out.size(); ++i) ASSERT_TRUE(out[i].None()) << i;
  o.min_points = 2;
  out = WeingartenCellFilter(l.frame, l.rays, o);
  for (std::size_t i = 0; i < out.size(); ++i) ASSERT_TRUE(out[i].Has(Flag::kSparseCell)) << i;
}

TEST(WeingartenCellFilterTest, MatchesMapReferenceOnScene) {
  test::Scene s = test::MakeScene();
  // Sprinkle deterministic outliers so some cells are sparse.
  for (int i = 0; i < 300; ++i) {
    const int r = (i * 37) % s.frame.height(), c = (i * 91) % s.frame.width();
    s.frame.radial_distance_m(r, c) = 0.3f + 0.021f * static_cast<float>(i);
  }
  WeingartenCellOptions o;
  o.voxel_size_m = 0.1;
  o.min_points = 5;
  const Image<PixelFlags> out = WeingartenCellFilter(s.frame, s.rays, o);
  // Reference: std::map over floor(coordinate / voxel) computed in double.
  auto cell = [&](int r, int c) {
    const double d = s.frame.radial_distance_m(r, c);
    auto q = [&](float ray) { return static_cast<long>(std::floor(d * ray / o.voxel_size_m)); };
    return std::make_tuple(q(s.rays.x(r, c)), q(s.rays.y(r, c)), q(s.rays.z(r, c)));
  };
  std::map<std::tuple<long, long, long>, int> count;
  for (int r = 0; r < s.frame.height(); ++r)
    for (int c = 0; c < s.frame.width(); ++c) ++count[cell(r, c)];
  int flagged = 0, disagreements = 0;
  for (int r = 0; r < s.frame.height(); ++r) {
    for (int c = 0; c < s.frame.width(); ++c) {
      const bool want = count[cell(r, c)] < o.min_points;
      flagged += want ? 1 : 0;
      disagreements += want != out(r, c).Has(Flag::kSparseCell) ? 1 : 0;
    }
  }
  // The filter computes coordinates in float, the reference in double: a point within float
  // rounding (~1e-7 m) of a cell boundary may land in the neighbouring cell. Allow a handful.
  EXPECT_LE(disagreements, 5);
  EXPECT_GT(flagged, 200);
}

TEST(WeingartenCellFilterTest, ScatteredPointsOverAHugeBoxAreCountedToo) {
  // 1 m cells and points up to 1e5 m apart along the axes: their bounding box (2e5 x 2e5 x 1e5
  // cells) is far too big for a dense grid, so the filter counts in its hash table. Distances at
  // cell centres keep the float arithmetic exact. Cell (10, 0, 0) holds 3 points, (-100000, 0, 0)
  // 2, (0, 99999, 0) 1, (0, 0, 5) 1.
  const std::vector<float> d = {10.5f, 10.5f, 99999.5f, 10.5f, 99999.5f, 5.5f, 99999.5f};
  Line l = MakeLine(d);
  const float rays[][3] = {{1, 0, 0},  {1, 0, 0}, {-1, 0, 0}, {1, 0, 0},
                           {-1, 0, 0}, {0, 0, 1}, {0, 1, 0}};
  SetRays(l, rays);
  WeingartenCellOptions o;
  o.voxel_size_m = 1.0;
  o.min_points = 2;
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  const bool expected[] = {false, false, false, false, false, true, true};
  for (int i = 0; i < 7; ++i) EXPECT_EQ(out[i].Has(Flag::kSparseCell), expected[i]) << i;
  o.min_points = 3;
  const Image<PixelFlags> three = WeingartenCellFilter(l.frame, l.rays, o);
  const bool expected3[] = {false, false, true, false, true, true, true};
  for (int i = 0; i < 7; ++i) EXPECT_EQ(three[i].Has(Flag::kSparseCell), expected3[i]) << i;
}

TEST(WeingartenCellFilterTest, FarPointWidensTheBoundButTheOccupiedBoxIsSmall) {
  // Rays along all six axis directions and distances from 2.5 m to 199.5 m: the box bounded from
  // the distance range and the ray directions alone (400^3 cells of 1 m) is too big for a dense
  // grid, but the occupied cells span only 8 x 4 x 205. Cells: (3, 0, 0) x3, (0, -3, 0) x1,
  // (0, 0, -5) x2, (0, 0, 199) x1, (-4, 0, 0) x2.
  const std::vector<float> d = {3.5f, 2.5f, 3.5f, 4.5f, 199.5f, 3.5f, 4.5f, 3.5f, 3.5f};
  const float rays[][3] = {{1, 0, 0},  {0, -1, 0}, {1, 0, 0}, {0, 0, -1}, {0, 0, 1},
                           {-1, 0, 0}, {0, 0, -1}, {1, 0, 0}, {-1, 0, 0}};
  Line l = MakeLine(d);
  SetRays(l, rays);
  WeingartenCellOptions o;
  o.voxel_size_m = 1.0;
  o.min_points = 2;
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  const bool expected[] = {false, true, false, false, true, false, false, false, false};
  for (int i = 0; i < 9; ++i) EXPECT_EQ(out[i].Has(Flag::kSparseCell), expected[i]) << i;
}

TEST(WeingartenCellFilterTest, LongRunsOfUnusablePixelsAndOneCell) {
  // 10000 pixels: every third unusable (NaN or rejected), the rest in one cell except pixel 5000
  // alone in another. The counts must not mix the unusable pixels in, and repeated calls (the
  // count array is reused and must be left at zero) must agree.
  std::vector<float> d(10000, 2.05f);
  for (std::size_t i = 0; i < d.size(); i += 3) d[i] = std::nanf("");
  d[5000] = 3.05f;
  Line l = MakeLine(d);
  for (std::size_t i = 1; i < d.size(); i += 3) {
    if (i % 2 == 0) l.frame.flags[i] = Flag::kHighDeltaL;
  }
  WeingartenCellOptions o;
  o.min_points = 5000;  // the big cell holds 10000 - 3334 - 1666 - 1 = 4999 points: sparse
  for (int rep = 0; rep < 2; ++rep) {
    const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
    std::size_t flagged = 0;
    for (std::size_t i = 0; i < d.size(); ++i) {
      const bool usable = i % 3 != 0 && !(i % 3 == 1 && i % 2 == 0);
      EXPECT_EQ(out[i].Has(Flag::kSparseCell), usable) << i;
      flagged += out[i].Has(Flag::kSparseCell) ? 1 : 0;
    }
    EXPECT_EQ(flagged, 5000u);  // 4999 in the big cell plus pixel 5000
  }
  o.min_points = 4999;  // now the big cell is dense enough; pixel 5000 is still alone
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  for (std::size_t i = 0; i < d.size(); ++i) {
    EXPECT_EQ(out[i].Has(Flag::kSparseCell), i == 5000) << i;
  }
}

TEST(WeingartenCellFilterTest, MostlyRejectedFrameCountsOnlyItsUsablePoints) {
  // 1000 pixels, 900 already rejected (at their own distances, which must not count): of the
  // 100 usable, 60 lie in cell z = 10, 3 in z = 20 and 37 in z = 30 (0.1 m cells). With most of
  // the frame rejected the filter skips the unusable pixels instead of counting them.
  std::vector<float> d(1000, 2.05f);  // the rejected ones would fill cell z = 20
  Line l = MakeLine(d);
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (i % 10 != 0) {
      l.frame.flags[i] = Flag::kHighDeltaL;
      continue;
    }
    const std::size_t k = i / 10;  // 0..99
    l.frame.radial_distance_m[i] = k < 60 ? 1.05f : k < 63 ? 2.05f : 3.05f;
  }
  WeingartenCellOptions o;
  o.min_points = 4;
  const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
  for (std::size_t i = 0; i < d.size(); ++i) {
    const bool sparse = i % 10 == 0 && i / 10 >= 60 && i / 10 < 63;
    EXPECT_EQ(out[i].Has(Flag::kSparseCell), sparse) << i;
  }
}

TEST(WeingartenCellFilterTest, CountsStayExactOverManyFrames) {
  // The dense count array is not cleared between frames: each entry carries a frame stamp, and
  // stamps are reused after 255 frames, when the array is cleared. 300 frames on one thread mix
  // near and far scenes, dense and mostly rejected frames (the dense and the sparse counting)
  // and outliers that differ per frame but repeat after 255 frames: frame 265 is frame 10 again,
  // so a count left over from frame 10 under the reused stamp would double its outliers' cells
  // (1 -> 2 points, no longer sparse). Every frame must match an exact std::map count of the
  // same float cells. Pixels 0 and 11 hold the nearest and farthest distance in every frame, so
  // the cell box (and with it each cell's place in the array) stays the same.
  CameraIntrinsics k = CameraIntrinsics::SwissRangerSr2();
  k.width = 48;
  k.height = 36;
  k.cx_px = 23.5;
  k.cy_px = 17.5;
  const test::Scene base = test::MakeScene(k);
  WeingartenCellOptions o;
  o.voxel_size_m = 0.1;
  o.min_points = 2;
  const float inv_voxel = static_cast<float>(1.0 / o.voxel_size_m);
  int total_flagged = 0;
  for (int frame = 0; frame < 300; ++frame) {
    const int phase = frame % 255;
    MetricFrame f = base.frame;
    const float scale = frame % 5 == 1 ? 2.0f : 1.0f;
    const bool mostly_rejected = frame % 3 == 1;
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      f.radial_distance_m[i] *= scale;
      if (mostly_rejected && i % 11 != 0) f.flags[i] = Flag::kHighDeltaL;
    }
    for (int j = 0; j < 20; ++j) {  // outliers, different per phase
      const std::size_t i = static_cast<std::size_t>(12 + (phase * 131 + j * 977) % (48 * 36 - 12));
      f.radial_distance_m[i] = 0.4f + 0.013f * static_cast<float>((phase * 3 + 7 * j) % 500);
    }
    f.radial_distance_m[0] = 0.3f;
    f.radial_distance_m[11] = 11.0f;
    const Image<PixelFlags> out = WeingartenCellFilter(f, base.rays, o);
    // Reference: the cells in the filter's float arithmetic, counted in a std::map.
    auto cell = [&](std::size_t i) {
      const float s = f.radial_distance_m[i] * inv_voxel;
      auto q = [&](float ray) { return static_cast<long>(std::floor(s * ray)); };
      return std::make_tuple(q(base.rays.x[i]), q(base.rays.y[i]), q(base.rays.z[i]));
    };
    std::map<std::tuple<long, long, long>, int> count;
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      if (f.flags[i].None()) ++count[cell(i)];
    }
    for (std::size_t i = 0; i < f.radial_distance_m.size(); ++i) {
      const bool want = f.flags[i].None() && count[cell(i)] < o.min_points;
      ASSERT_EQ(out[i].Has(Flag::kSparseCell), want) << "frame " << frame << " pixel " << i;
      total_flagged += want ? 1 : 0;
    }
  }
  EXPECT_GT(total_flagged, 300 * 10);  // the outliers (and the sparse frames' points) are found
}

TEST(WeingartenCellFilterTest, EveryFrameLengthCountsEachPointOnce) {
  // The counting splits the pixels into eight streams of q = 1 (mod 8) pixels with a remainder:
  // every length from 1 to 200 pixels, some unusable, must give the exact counts (a pixel counted
  // twice or not at all changes a cell of 2 or 3 points against min_points = 3).
  for (int n = 1; n <= 200; ++n) {
    const int cells = std::max(1, n / 3);  // about 3 points per cell: one more or less flips it
    auto cell = [cells](int i) { return (i * 7) % cells; };
    std::vector<float> d(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) d[i] = 0.05f + 0.1f * static_cast<float>(cell(i));
    Line l = MakeLine(d);
    for (int i = 0; i < n; i += 5) l.frame.flags[i] = Flag::kHighDeltaL;
    WeingartenCellOptions o;
    o.voxel_size_m = 0.1;
    o.min_points = 3;
    const Image<PixelFlags> out = WeingartenCellFilter(l.frame, l.rays, o);
    std::map<int, int> count;  // cell z = floor(d / 0.1) = cell(i)
    for (int i = 0; i < n; ++i) {
      if (i % 5 != 0) ++count[cell(i)];
    }
    for (int i = 0; i < n; ++i) {
      const bool want = i % 5 != 0 && count[cell(i)] < 3;
      ASSERT_EQ(out[i].Has(Flag::kSparseCell), want) << "n " << n << " pixel " << i;
    }
  }
}

TEST(WeingartenCellFilterTest, Avx512AndPortableFormsFlagTheSamePixels) {
  // The scene frame with outliers (sparse cells among dense ones) cut to every width from 1 to 40
  // plus the full frame, and, at the odd width 17, to 16 heights in a row, so that the frame's
  // pixel count (the flagging runs over the whole frame) leaves every remainder mod 16 for the
  // portable tail; some pixels rejected. On an AVX-512 CPU the default form flags with a gather,
  // the portable one with table reads; both must set the same bits, and keep every bit the frame's
  // flags had.
  test::Scene s = test::MakeScene();
  for (int i = 0; i < 300; ++i) {
    const int r = (i * 37) % s.frame.height(), c = (i * 91) % s.frame.width();
    s.frame.radial_distance_m(r, c) = 0.3f + 0.021f * static_cast<float>(i);
  }
  for (int i = 0; i < 200; ++i) {
    s.frame.flags((i * 13) % s.frame.height(), (i * 29) % s.frame.width()) = Flag::kHighDeltaL;
  }
  WeingartenCellOptions o;
  o.voxel_size_m = 0.1;
  o.min_points = 5;
  std::vector<std::pair<int, int>> sizes;
  for (int w = 1; w <= 40; ++w) sizes.emplace_back(w, s.frame.height());
  for (int h = s.frame.height() - 16; h < s.frame.height(); ++h) sizes.emplace_back(17, h);
  sizes.emplace_back(s.frame.width(), s.frame.height());
  int flagged = 0;
  std::vector<bool> remainder_seen(16);
  for (const auto& [w, h] : sizes) {
    remainder_seen[static_cast<std::size_t>(w * h % 16)] = true;
    SCOPED_TRACE(testing::Message() << w << " x " << h);
    MetricFrame f;
    f.radial_distance_m = Image<float>(w, h);
    f.flags = Image<PixelFlags>(w, h);
    RayTable rays{Image<float>(w, h), Image<float>(w, h), Image<float>(w, h)};
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        f.radial_distance_m(r, c) = s.frame.radial_distance_m(r, c);
        f.flags(r, c) = s.frame.flags(r, c);
        rays.x(r, c) = s.rays.x(r, c);
        rays.y(r, c) = s.rays.y(r, c);
        rays.z(r, c) = s.rays.z(r, c);
      }
    }
    Image<PixelFlags> portable;
    {
      const internal::PortableFormsForTesting forms(true);
      portable = WeingartenCellFilter(f, rays, o);
    }
    const Image<PixelFlags> fast = WeingartenCellFilter(f, rays, o);
    for (std::size_t i = 0; i < fast.size(); ++i) {
      ASSERT_EQ(fast[i].bits(), portable[i].bits()) << "pixel " << i;
      flagged += fast[i].Has(Flag::kSparseCell);
    }
  }
  EXPECT_GT(flagged, 1000);  // the comparison is not between unflagged images
  EXPECT_EQ(std::count(remainder_seen.begin(), remainder_seen.end(), true), 16);
  if (!internal::CpuHasAvx512()) {
    GTEST_SKIP() << "no AVX-512 on this CPU: only the portable form was compared";
  }
}

TEST(WeingartenCellFilterTest, ErrorsAreReported) {
  const Line l = MakeLine({1.0f});
  WeingartenCellOptions o;
  o.voxel_size_m = 0.0;
  EXPECT_THROW(o.Validate(), Error);
  o = {};
  o.min_points = 0;
  EXPECT_THROW((void)WeingartenCellFilter(l.frame, l.rays, o), Error);
  RayTable wrong{Image<float>(2, 1), Image<float>(2, 1), Image<float>(2, 1)};
  try {
    (void)WeingartenCellFilter(l.frame, wrong, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
}

}  // namespace
}  // namespace tofcam
