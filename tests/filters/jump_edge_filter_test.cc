#include "tofcam/filters/jump_edge_filter.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>

#include "test_scene.h"
#include "tofcam/core/error.h"
#include "tofcam/core/units.h"

namespace tofcam {
namespace {

// Reference straight from tof-notes §4, in double with acos: the largest angle α over the usable
// 8-neighbours n with p·(n - p) < 0. Returns -1 when no neighbour qualifies.
double LargestAngleDeg(const MetricFrame& f, const RayTable& rays, int r, int c) {
  auto point = [&](int rr, int cc) {
    const double d = f.radial_distance_m(rr, cc);
    return Eigen::Vector3d(d * rays.x(rr, cc), d * rays.y(rr, cc), d * rays.z(rr, cc));
  };
  const Eigen::Vector3d p = point(r, c);
  double best = -1.0;
  for (int dr = -1; dr <= 1; ++dr) {
    for (int dc = -1; dc <= 1; ++dc) {
      const int rr = r + dr, cc = c + dc;
      if ((dr == 0 && dc == 0) || rr < 0 || cc < 0 || rr >= f.height() || cc >= f.width()) continue;
      if (!f.flags(rr, cc).Valid()) continue;
      const Eigen::Vector3d v = point(rr, cc) - p;
      if (p.dot(v) >= 0.0) continue;
      best = std::max(best, std::acos(p.dot(v) / (p.norm() * v.norm())) * 180.0 / kPi);
    }
  }
  return best;
}

TEST(JumpEdgeFilterTest, MatchesAcosReferenceOnPlaneAndBox) {
  test::Scene s = test::MakeScene();
  // Reject a few pixels so "ignore rejected neighbours" is exercised too.
  for (int c = 40; c < 60; ++c) s.frame.flags(62, c) = Flag::kLowAmplitude;
  JumpEdgeOptions o;
  o.max_angle_deg = 160.0;
  const Image<PixelFlags> out = JumpEdgeFilter(s.frame, s.rays, o);
  int flagged = 0, checked = 0;
  for (int r = 0; r < s.frame.height(); ++r) {
    for (int c = 0; c < s.frame.width(); ++c) {
      const bool got = out(r, c).Has(Flag::kJumpEdge);
      flagged += got ? 1 : 0;
      if (!s.frame.flags(r, c).Valid()) {
        EXPECT_FALSE(got) << "rejected pixel judged at " << r << "," << c;
        continue;
      }
      const double alpha = LargestAngleDeg(s.frame, s.rays, r, c);
      // The filter works in float; angles within 0.05° of the threshold may go either way.
      if (std::abs(alpha - o.max_angle_deg) < 0.05) continue;
      ++checked;
      EXPECT_EQ(got, alpha > o.max_angle_deg) << "pixel " << r << "," << c << " alpha " << alpha;
    }
  }
  EXPECT_GT(checked, 19000);
  // The wall pixels around the box outline are removed; the box itself and the open wall stay.
  EXPECT_GT(flagged, 100);
  EXPECT_LT(flagged, 600);
}

TEST(JumpEdgeFilterTest, RemovesFarSideOfStepOnly) {
  // Hand case: 6 x 3 image, all rays along z (a telecentric toy camera): left 3 columns at 1 m,
  // right 3 at 3 m. For a far pixel next to a near one, n - p points straight back along the
  // ray: α = 180°. For a near pixel the far neighbour lies behind it (p·(n - p) > 0).
  MetricFrame f;
  f.radial_distance_m = Image<float>(6, 3, 3.0f);
  f.flags = Image<PixelFlags>(6, 3);
  RayTable rays{Image<float>(6, 3, 0.0f), Image<float>(6, 3, 0.0f), Image<float>(6, 3, 1.0f)};
  // Spread the rays slightly so neighbours are distinct points (0.01 rad apart).
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 6; ++c) {
      const Eigen::Vector3d ray =
          Eigen::Vector3d(0.01 * (c - 2.5), 0.01 * (r - 1), 1.0).normalized();
      rays.x(r, c) = static_cast<float>(ray.x());
      rays.y(r, c) = static_cast<float>(ray.y());
      rays.z(r, c) = static_cast<float>(ray.z());
      if (c < 3) f.radial_distance_m(r, c) = 1.0f;
    }
  }
  const Image<PixelFlags> out = JumpEdgeFilter(f, rays, {});
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 6; ++c) EXPECT_EQ(out(r, c).Has(Flag::kJumpEdge), c == 3) << r << "," << c;
  }
  // With the near column rejected, nothing is in front of column 3 any more.
  for (int r = 0; r < 3; ++r) f.flags(r, 2) = Flag::kInvalid;
  const Image<PixelFlags> out2 = JumpEdgeFilter(f, rays, {});
  for (std::size_t i = 0; i < out2.size(); ++i) EXPECT_TRUE(out2[i].None()) << i;
}

TEST(JumpEdgeFilterTest, ErrorsAreReported) {
  test::Scene s = test::MakeScene();
  JumpEdgeOptions bad;
  bad.max_angle_deg = 90.0;
  EXPECT_THROW(bad.Validate(), Error);
  bad.max_angle_deg = 180.0;
  EXPECT_THROW((void)JumpEdgeFilter(s.frame, s.rays, bad), Error);
  RayTable small{Image<float>(2, 2), Image<float>(2, 2), Image<float>(2, 2)};
  try {
    (void)JumpEdgeFilter(s.frame, small, {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kMismatch);
  }
}

}  // namespace
}  // namespace tofcam
