#pragma once
// The panorama cell of a base-frame point (internal to tofcam::MakePanView; not installed).
//
// The cell is defined by a double-precision computation (ExactCell: azimuth by the branch-free
// FastAtan2, within 7e-11 rad of libm). The per-point loop runs the same geometry in single
// precision, eight points per vector, together with a bound on how far each float coordinate
// can be from the double one. Where that interval crosses a cell border, the strip's edge, the
// azimuth's branch cut or the axis, the point is marked for the double computation instead. So
// every point gets the cell ExactCell gives it, and the double path runs for a few per mille.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "../core/fast_atan2.h"

namespace tofcam::internal {

/// The strip of a pan view in double precision (PanView's definition). forward, left, up:
/// orthonormal base-frame axes (up along the pan axis); cell (row, col) = row * cols + col.
struct PanStrip {
  double forward[3], left[3], up[3];
  double max_azimuth_rad, max_tan_elevation, inv_resolution;  // inv_resolution: 1/rad
  int cols, rows;
};

/// Cell code of a point no cell holds (invalid, on the axis, outside the strip).
constexpr std::int32_t kNoCell = -1;
/// Cell code of a point whose float cell is not certain (PanCells leaves it to ExactCell).
constexpr std::int32_t kRecheckCell = -2;

/// The cell of the finite base-frame point (x, y, z), or kNoCell when it is within 1e-6 m of
/// the axis (no azimuth) or outside the strip. The definition of a point's cell.
[[gnu::always_inline]] inline std::int32_t ExactCell(const PanStrip& s, float x, float y, float z) {
  const double px = x, py = y, pz = z;
  const double pf = px * s.forward[0] + py * s.forward[1] + pz * s.forward[2];
  const double pl = px * s.left[0] + py * s.left[1] + pz * s.left[2];
  const double pu = px * s.up[0] + py * s.up[1] + pz * s.up[2];
  const double rho = std::sqrt(pf * pf + pl * pl);
  const bool off_axis = rho >= 1e-6;
  const double col = (s.max_azimuth_rad - FastAtan2(pl, pf)) * s.inv_resolution;
  const double row = (s.max_tan_elevation - pu / std::max(rho, 1e-6)) * s.inv_resolution;
  const bool in = off_axis & (col >= 0.0) & (col < s.cols) & (row >= 0.0) & (row < s.rows);
  if (!in) return kNoCell;
  return static_cast<std::int32_t>(row) * s.cols + static_cast<std::int32_t>(col);
}

/// Per point i < n: ExactCell's cell (or kNoCell) where valid[i] != 0, kNoCell where not. The
/// float loop decides most points; the rest (its kRecheckCell) get ExactCell. Points must be
/// finite where valid. Returns how many points needed ExactCell.
std::size_t PanCells(std::size_t n, const PanStrip& s, const float* x, const float* y,
                     const float* z, const std::uint8_t* valid, std::int32_t* cell);

}  // namespace tofcam::internal
