#pragma once
// A deterministic synthetic scene for filter tests: a tilted wall plus a box face in front of it,
// computed in closed form (ray-plane intersection) on the SR-2 ray table.

#include <cmath>
#include <cstdint>

#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/frame.h"
#include "tofcam/filters/filter_set.h"

namespace tofcam::test {

struct Scene {
  RayTable rays;
  MetricFrame frame;
  Image<std::uint8_t> on_box;  // 1 where the box face is the first hit
};

// Wall: plane through (0, 0, 4) with normal (0.2, -0.1, -1) (tilted); box face: z = 1.5 for
// x in [-0.3, 0.2], y in [-0.2, 0.3]. Amplitude ~ 1/d² like the physics; intensity a constant
// background plus a signal share.
inline Scene MakeScene(const CameraIntrinsics& k = CameraIntrinsics::SwissRangerSr2()) {
  Scene s;
  s.rays = MakeRayTable(k);
  const int w = k.width, h = k.height;
  MetricFrame& f = s.frame;
  f.radial_distance_m = Image<float>(w, h);
  f.amplitude = Image<float>(w, h);
  f.intensity = Image<float>(w, h);
  f.delta_l_m = Image<float>(w, h, 0.01f);
  f.flags = Image<PixelFlags>(w, h);
  s.on_box = Image<std::uint8_t>(w, h);
  const double nx = 0.2, ny = -0.1, nz = -1.0, c = nz * 4.0;
  for (int r = 0; r < h; ++r) {
    for (int col = 0; col < w; ++col) {
      const double rx = s.rays.x(r, col), ry = s.rays.y(r, col), rz = s.rays.z(r, col);
      double d = c / (nx * rx + ny * ry + nz * rz);
      const double t_box = 1.5 / rz;
      const double bx = t_box * rx, by = t_box * ry;
      if (bx >= -0.3 && bx <= 0.2 && by >= -0.2 && by <= 0.3 && t_box < d) {
        d = t_box;
        s.on_box(r, col) = 1;
      }
      f.radial_distance_m(r, col) = static_cast<float>(d);
      f.amplitude(r, col) = static_cast<float>(20000.0 / (d * d));
      f.intensity(r, col) = static_cast<float>(5000.0 + 20000.0 / (d * d));
    }
  }
  return s;
}

// The per-pixel thresholds of subset `set` (bit 0 range, 1 amplitude, 2 saturation, 3 accuracy;
// no neighbourhood filter), the amplitude threshold at 400 so that the scene's far pixels fail it.
inline FilterSetOptions ThresholdSet(unsigned set) {
  FilterSetOptions o;
  o.range_enabled = (set & 1u) != 0;
  o.amplitude_enabled = (set & 2u) != 0;
  o.saturation_enabled = (set & 4u) != 0;
  o.accuracy_enabled = (set & 8u) != 0;
  o.amplitude.min_amplitude = 400.0;
  return o;
}

}  // namespace tofcam::test
