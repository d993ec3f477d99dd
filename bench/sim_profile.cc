// Fixed-work driver for instruction-count profiling of SimulatedCamera::Grab(), e.g.
//   valgrind --tool=callgrind --toggle-collect='tofcam::sim::SimulatedCamera::Grab()'
//     build/bench/sim_profile moving 20 1   (one command line)
// A fourth argument `shortcut` switches the planar shortcut on.
// Cases: moving | pan | static | generic640 | demo (the scenes of sim_bench.cc). The first frame
// is grabbed before the measured ones so one-time work (Embree BVH build) can be excluded by
// comparing runs with different frame counts. Instruction counts do not depend on machine load,
// unlike the wall times of sim_bench.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

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
  for (int i = 0; i < frames; ++i) {
    const auto f = cam.Grab();
    for (std::size_t p = 0; p < f->distance.size(); ++p) {
      mix(f->distance[p]);
      mix(f->amplitude[p]);
      mix(f->intensity[p]);
      mix(f->truth->causes[p].bits());
    }
  }
  std::printf("%s: %d frames, output hash %016llx\n", which.c_str(), frames,
              static_cast<unsigned long long>(hash));
  return 0;
}
