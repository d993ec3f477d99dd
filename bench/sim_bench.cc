// Simulator throughput: frames per second of SimulatedCamera::Grab() (items_per_second).
#include <benchmark/benchmark.h>

#include "tofcam/sim/simulated_camera.h"

namespace {

using tofcam::sim::CameraModel;
using tofcam::sim::Keyframe;
using tofcam::sim::LoadBuiltinScene;
using tofcam::sim::ResolveCameraModel;
using tofcam::sim::Scene;
using tofcam::sim::SimulatedCamera;
using tofcam::sim::SimulatorOptions;

// The pavilion with the robot driving back and forth at 0.5 m/s while turning at 3 deg/s: every
// frame sees a new pose, so nothing can be cached, but the motion within one exposure stays below
// the 1 cm threshold (one rendering per frame).
Scene MovingPavilion() {
  Scene s = LoadBuiltinScene("pavilion");
  s.camera.keys.clear();
  for (int i = 0; i <= 250; ++i) {
    Keyframe k;
    k.time_s = 4.0 * i;
    k.position_m = {0, 0, i % 2 == 0 ? 0.0 : 2.0};
    k.rotation_deg = {0, i % 2 == 0 ? -6.0 : 6.0, 0};
    s.camera.keys.push_back(k);
  }
  return s;
}

// A fast pan at 30 deg/s: the view moves about a pixel during one exposure, so the four taps are
// rendered at their own times (four renderings per frame).
Scene PanningPavilion() {
  Scene s = LoadBuiltinScene("pavilion");
  Keyframe a, b;
  b.time_s = 1000.0;
  b.rotation_deg = {0, 30.0 * 1000, 0};
  s.camera.keys = {a, b};
  return s;
}

void Run(benchmark::State& state, Scene scene, const CameraModel& model, int threads) {
  SimulatorOptions o;
  o.threads = threads;
  o.integration_time_register = 40;
  SimulatedCamera cam(std::move(scene), model, o);
  for (auto _ : state) {
    auto frame = cam.Grab();
    benchmark::DoNotOptimize(frame);
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_PavilionMovingCamera(benchmark::State& state) {
  Run(state, MovingPavilion(), ResolveCameraModel("sr2"), static_cast<int>(state.range(0)));
}
BENCHMARK(BM_PavilionMovingCamera)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_PavilionFastPan(benchmark::State& state) {
  Run(state, PanningPavilion(), ResolveCameraModel("sr2"), static_cast<int>(state.range(0)));
}
BENCHMARK(BM_PavilionFastPan)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_PavilionStaticCamera(benchmark::State& state) {
  Run(state, LoadBuiltinScene("pavilion"), ResolveCameraModel("sr2"),
      static_cast<int>(state.range(0)));
}
BENCHMARK(BM_PavilionStaticCamera)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_Generic640MovingCamera(benchmark::State& state) {
  Run(state, MovingPavilion(), ResolveCameraModel("generic640x480"),
      static_cast<int>(state.range(0)));
}
BENCHMARK(BM_Generic640MovingCamera)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_DemoSequence(benchmark::State& state) {
  Run(state, LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), 1);
}
BENCHMARK(BM_DemoSequence)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
