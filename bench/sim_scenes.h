#pragma once
// Scenes of the simulator benchmarks, shared by sim_bench (Google Benchmark, wall time) and
// sim_profile (fixed frame count for callgrind instruction counts).

#include <string>

#include "tofcam/sim/scene.h"

namespace tofcam::bench {

// The pavilion with the robot driving back and forth at 0.5 m/s while turning at 3 deg/s: every
// frame sees a new pose, so nothing can be cached, but the motion within one exposure stays below
// the 1 cm threshold (one rendering per frame).
inline sim::Scene MovingPavilion() {
  sim::Scene s = sim::LoadBuiltinScene("pavilion");
  s.camera.keys.clear();
  for (int i = 0; i <= 250; ++i) {
    sim::Keyframe k;
    k.time_s = 4.0 * i;
    k.position_m = {0, 0, i % 2 == 0 ? 0.0 : 2.0};
    k.rotation_deg = {0, i % 2 == 0 ? -6.0 : 6.0, 0};
    s.camera.keys.push_back(k);
  }
  return s;
}

// A fast pan at 30 deg/s: the view moves about a pixel during one exposure, so the four taps are
// rendered at their own times (four renderings per frame).
inline sim::Scene PanningPavilion() {
  sim::Scene s = sim::LoadBuiltinScene("pavilion");
  sim::Keyframe a, b;
  b.time_s = 1000.0;
  b.rotation_deg = {0, 30.0 * 1000, 0};
  s.camera.keys = {a, b};
  return s;
}

}  // namespace tofcam::bench
