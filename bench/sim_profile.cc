// Fixed-work driver for instruction-count profiling of SimulatedCamera::Grab(), e.g.
//   valgrind --tool=callgrind --toggle-collect='tofcam::sim::SimulatedCamera::Grab()'
//     build/bench/sim_profile moving 20 1   (one command line)
// A fourth argument `shortcut` switches the planar shortcut on.
// Cases: moving | pan | static | generic640 | demo (the scenes of sim_bench.cc). One-time work
// (Embree BVH build, caches) happens in the first frame: compare runs with different frame
// counts to exclude it. The program also prints Grab()'s own time a frame over the frames after
// the first. Instruction counts do not depend on machine load, unlike the wall times of
// sim_bench.
#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "sim_scenes.h"
#include "tofcam/sim/simulated_camera.h"

int main(int argc, char** argv) {
  using tofcam::sim::ResolveCameraModel;
  if (argc < 3) {
    std::fprintf(
        stderr,
        "usage: sim_profile moving|pan|static|generic640|demo FRAMES [THREADS [shortcut]]\n");
    return 2;
  }
  const std::string which = argv[1];
  const int frames = std::atoi(argv[2]);
  tofcam::sim::SimulatorOptions o;
  o.threads = argc > 3 ? std::atoi(argv[3]) : 1;
  o.planar_shortcut = argc > 4 && std::string(argv[4]) == "shortcut";
  o.integration_time_register = 40;
  tofcam::sim::Scene scene;
  std::string model = "sr2";
  if (which == "moving") {
    scene = tofcam::bench::MovingPavilion();
  } else if (which == "pan") {
    scene = tofcam::bench::PanningPavilion();
  } else if (which == "static") {
    scene = tofcam::sim::LoadBuiltinScene("pavilion");
  } else if (which == "generic640") {
    scene = tofcam::bench::MovingPavilion();
    model = "generic640x480";
  } else if (which == "demo") {
    scene = tofcam::sim::LoadBuiltinScene("demo");
  } else {
    std::fprintf(stderr, "unknown case %s\n", which.c_str());
    return 2;
  }
  tofcam::sim::SimulatedCamera cam(std::move(scene), ResolveCameraModel(model), o);
  // FNV-1a over every register and the truth causes: shows whether a change altered the output.
  std::uint64_t hash = 0xCBF29CE484222325ull;
  auto mix = [&hash](std::uint64_t v) { hash = (hash ^ v) * 0x100000001B3ull; };
  // Grab()'s own wall time, without this driver's hashing: the hash is one dependent chain of
  // four multiplies a pixel, about 1.5 ms a 640x480 frame and 0.1 ms an SR-2 frame here, which
  // the whole run's time (/usr/bin/time) includes.
  std::vector<double> grab_ms;
  for (int i = 0; i < frames; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto f = cam.Grab();
    grab_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    for (std::size_t p = 0; p < f->distance.size(); ++p) {
      mix(f->distance[p]);
      mix(f->amplitude[p]);
      mix(f->intensity[p]);
      mix(f->truth->causes[p].bits());
    }
  }
  std::printf("%s: %d frames, output hash %016llx\n", which.c_str(), frames,
              static_cast<unsigned long long>(hash));
  if (frames > 1) {
    // Frames after the first (which builds the BVH and the caches).
    std::vector<double> later(grab_ms.begin() + 1, grab_ms.end());
    const double sum = std::accumulate(later.begin(), later.end(), 0.0);
    std::sort(later.begin(), later.end());
    const std::size_t n = later.size();
    const double median = n % 2 == 1 ? later[n / 2] : 0.5 * (later[n / 2 - 1] + later[n / 2]);
    std::printf("Grab(), frames 2-%d: mean %.3f ms, median %.3f ms (%.1f frames/s)\n", frames,
                sum / static_cast<double>(n), median, 1e3 * static_cast<double>(n) / sum);
  }
  return 0;
}
