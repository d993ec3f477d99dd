// PanCells (the pan view's single-precision cell loop, src/pan/pan_cells.h) against ExactCell,
// the double-precision definition of a point's cell: every valid point must get ExactCell's
// cell, including points placed within 1e-7 of a cell border, at the strip's edges, at the
// azimuth's branch cut and near the pan axis.
#include "pan_cells.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "tofcam/core/units.h"

namespace tofcam::internal {
namespace {

constexpr double kDeg = kPi / 180.0;

// The strip as PanView defines it (pan_view.h).
PanStrip MakeStrip(const Eigen::Vector3d& axis, double res_deg, double min_az_deg,
                   double max_az_deg, double max_el_deg) {
  const Eigen::Vector3d up = axis.normalized(), z(0, 0, 1);
  const Eigen::Vector3d forward = (z - z.dot(up) * up).normalized(), left = up.cross(forward);
  PanStrip s{};
  for (int i = 0; i < 3; ++i) {
    s.forward[i] = forward[i];
    s.left[i] = left[i];
    s.up[i] = up[i];
  }
  s.max_azimuth_rad = max_az_deg * kDeg;
  s.max_tan_elevation = std::tan(max_el_deg * kDeg);
  s.inv_resolution = 1.0 / (res_deg * kDeg);
  s.cols = static_cast<int>(std::ceil((max_az_deg - min_az_deg) / res_deg - 1e-9));
  s.rows = static_cast<int>(std::ceil(2.0 * s.max_tan_elevation * s.inv_resolution - 1e-9));
  return s;
}

struct Points {
  std::vector<float> x, y, z;
  std::vector<std::uint8_t> valid;
  void Add(const Eigen::Vector3d& p, bool ok = true) {
    x.push_back(static_cast<float>(p.x()));
    y.push_back(static_cast<float>(p.y()));
    z.push_back(static_cast<float>(p.z()));
    valid.push_back(ok ? 1 : 0);
  }
};

// The base-frame point at azimuth az, elevation tangent t and distance rho from the axis.
Eigen::Vector3d At(const PanStrip& s, double az, double t, double rho) {
  const Eigen::Vector3d f(s.forward[0], s.forward[1], s.forward[2]);
  const Eigen::Vector3d l(s.left[0], s.left[1], s.left[2]);
  const Eigen::Vector3d u(s.up[0], s.up[1], s.up[2]);
  return rho * (std::cos(az) * f + std::sin(az) * l + t * u);
}

Points TestPoints(const PanStrip& s, std::uint64_t seed) {
  Points pts;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  // Random directions over the whole sphere, 5 cm to 100 m.
  for (int i = 0; i < 20000; ++i) {
    const double az = kPi * (2 * uni(rng) - 1), el = std::asin(2 * uni(rng) - 1);
    const double r = 0.05 * std::pow(2000.0, uni(rng));
    pts.Add(At(s, az, std::tan(el), r * std::cos(el)));
  }
  // Near cell borders (including the strip's edges): col and row within 1e-7..1e-3 of an
  // integer, on either side (the rounding to float moves them a little further).
  const double offsets[] = {0.0, 1e-7, -1e-7, 1e-6, -1e-6, 1e-5, -1e-5, 1e-4, -1e-4, 1e-3, 0.5};
  std::uniform_int_distribution<int> col_of(-2, s.cols + 2), row_of(-2, s.rows + 2);
  for (int i = 0; i < 20000; ++i) {
    const double dc = offsets[i % 11], dr = offsets[(i / 11) % 11];
    const double col = col_of(rng) + dc, row = row_of(rng) + dr;
    const double az = s.max_azimuth_rad - col / s.inv_resolution;
    const double t = s.max_tan_elevation - row / s.inv_resolution;
    pts.Add(At(s, az, t, 0.2 + 30.0 * uni(rng)));
  }
  // The branch cut (az = +-pi: pf < 0, pl ~ 0) and the axis (rho ~ 1e-6).
  for (int i = 0; i < 2000; ++i) {
    const double e = (2 * uni(rng) - 1) * std::pow(10.0, -12 + 8 * uni(rng));
    pts.Add(At(s, kPi, 0.5 * (uni(rng) - 0.5), 0.5 + 5 * uni(rng)) + e * At(s, kPi / 2, 0.0, 1.0));
  }
  for (double rho : {0.0, 1e-8, 5e-7, 1e-6, 1.5e-6, 2e-6, 3e-6, 1e-5}) {
    for (double h : {1.0, -1.0, 1e-3}) {
      const Eigen::Vector3d u(s.up[0], s.up[1], s.up[2]);
      pts.Add(At(s, 0.3, 0.0, rho) + h * u);
    }
  }
  // Huge and far-out finite points; invalid points (NaN or finite) that must get no cell.
  pts.Add(At(s, 0.1, 0.1, 1e20));
  pts.Add(Eigen::Vector3d(3e38, -3e38, 3e38));
  pts.Add(Eigen::Vector3d(1e30, 1e-30, -1e30));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  pts.Add(Eigen::Vector3d(nan, 1.0, 1.0), false);
  pts.Add(At(s, 0.0, 0.0, 2.0), false);
  return pts;
}

TEST(PanCellsTest, EveryPointGetsTheExactCell) {
  struct Case {
    Eigen::Vector3d axis;
    double res_deg, min_az, max_az, max_el;
  };
  const Case cases[] = {
      {{0, 1, 0}, 0.5, -90, 90, 30},
      {{0, -1, 0}, 0.5, -90, 90, 30},
      {{0, 1, 0}, 0.01, -10, 10, 30},
      {{0, 1, 0}, 0.1, -180, 180, 45},
      {{0.2, 1, 0.1}, 2.0, -180, 180, 80},
      {{0, 1, 0}, 10.0, -10, 170, 80},
      {{-0.3, 1, 0.4}, 0.05, -60, 30, 10},
      // 0.7 deg does not divide 360: both sides of the branch cut (az = +-pi) are in the strip,
      // in cells 0 and 514.
      // (A tilted axis, so that pl = p . left is rounded in float and its sign can flip.)
      {{0, 1, 0}, 0.7, -180, 180, 30},
      {{0.3, 1, -0.2}, 0.7, -180, 180, 30},
  };
  std::uint64_t seed = 1;
  for (const Case& c : cases) {
    const PanStrip s = MakeStrip(c.axis, c.res_deg, c.min_az, c.max_az, c.max_el);
    SCOPED_TRACE(testing::Message() << "resolution " << c.res_deg << " deg, azimuth [" << c.min_az
                                    << ", " << c.max_az << "], elevation " << c.max_el);
    const Points p = TestPoints(s, seed++);
    const std::size_t n = p.x.size();
    // Both forms of the float loop (the AVX-512 one, with fused multiply-adds, where the CPU
    // has it; the portable one always), and counts that are not a multiple of 16 (a partial
    // last block).
    for (const bool portable : {false, true}) {
      for (const std::size_t count : {n, n - 5}) {
        SCOPED_TRACE(testing::Message() << (portable ? "portable" : "AVX-512 if available") << ", "
                                        << count << " points");
        const PortableFormsForTesting forms(portable);
        std::vector<std::int32_t> cell(n, 12345);
        const std::size_t rechecks =
            PanCells(count, s, p.x.data(), p.y.data(), p.z.data(), p.valid.data(), cell.data());
        int mismatches = 0, in_strip = 0;
        for (std::size_t i = 0; i < count; ++i) {
          const std::int32_t want = p.valid[i] ? ExactCell(s, p.x[i], p.y[i], p.z[i]) : kNoCell;
          in_strip += want >= 0;
          if (cell[i] != want && ++mismatches <= 5) {
            ADD_FAILURE() << "point " << i << " (" << p.x[i] << ", " << p.y[i] << ", " << p.z[i]
                          << "): cell " << cell[i] << ", exact " << want;
          }
        }
        EXPECT_EQ(mismatches, 0);
        for (std::size_t i = count; i < n; ++i) EXPECT_EQ(cell[i], 12345);  // nothing past n
        EXPECT_GT(in_strip, 1000);  // the cases exercise cells, not only "outside"
        EXPECT_GT(rechecks, 0u);    // and the double path
      }
    }
  }
}

TEST(PanCellsTest, RandomPointsAreRarelyRechecked) {
  // At the default 0.5 deg strip the float interval straddles a border for a few points in 10^4.
  const PanStrip s = MakeStrip({0, 1, 0}, 0.5, -90, 90, 30);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  Points p;
  for (int i = 0; i < 100000; ++i) {
    p.Add(At(s, kPi * (uni(rng) - 0.5), 0.6 * (uni(rng) - 0.5), 0.3 + 7 * uni(rng)));
  }
  std::vector<std::int32_t> cell(p.x.size());
  const std::size_t rechecks =
      PanCells(p.x.size(), s, p.x.data(), p.y.data(), p.z.data(), p.valid.data(), cell.data());
  EXPECT_LT(rechecks, p.x.size() / 100);
  for (std::size_t i = 0; i < p.x.size(); i += 97) {
    EXPECT_EQ(cell[i], ExactCell(s, p.x[i], p.y[i], p.z[i])) << i;
  }
}

}  // namespace
}  // namespace tofcam::internal
