// Simulator throughput: frames per second of SimulatedCamera::Grab() (items_per_second). The
// second argument, where there is one, switches the planar shortcut on (1) or off (0).
#include <benchmark/benchmark.h>

#include "sim_scenes.h"
#include "tofcam/sim/simulated_camera.h"

namespace {

using tofcam::bench::MovingPavilion;
using tofcam::bench::PanningPavilion;
using tofcam::sim::CameraModel;
using tofcam::sim::LoadBuiltinScene;
using tofcam::sim::ResolveCameraModel;
using tofcam::sim::Scene;
using tofcam::sim::SimulatedCamera;
using tofcam::sim::SimulatorOptions;

void Run(benchmark::State& state, Scene scene, const CameraModel& model, int threads,
         bool shortcut = false) {
  SimulatorOptions o;
  o.threads = threads;
  o.planar_shortcut = shortcut;
  o.integration_time_register = 40;
  SimulatedCamera cam(std::move(scene), model, o);
  for (auto _ : state) {
    auto frame = cam.Grab();
    benchmark::DoNotOptimize(frame);
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_PavilionMovingCamera(benchmark::State& state) {
  Run(state, MovingPavilion(), ResolveCameraModel("sr2"), static_cast<int>(state.range(0)),
      state.range(1) != 0);
}
BENCHMARK(BM_PavilionMovingCamera)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_PavilionFastPan(benchmark::State& state) {
  Run(state, PanningPavilion(), ResolveCameraModel("sr2"), static_cast<int>(state.range(0)),
      state.range(1) != 0);
}
BENCHMARK(BM_PavilionFastPan)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_PavilionStaticCamera(benchmark::State& state) {
  Run(state, LoadBuiltinScene("pavilion"), ResolveCameraModel("sr2"),
      static_cast<int>(state.range(0)), state.range(1) != 0);
}
BENCHMARK(BM_PavilionStaticCamera)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_Generic640MovingCamera(benchmark::State& state) {
  Run(state, MovingPavilion(), ResolveCameraModel("generic640x480"),
      static_cast<int>(state.range(0)), state.range(1) != 0);
}
BENCHMARK(BM_Generic640MovingCamera)
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_DemoSequence(benchmark::State& state) {
  Run(state, LoadBuiltinScene("demo"), ResolveCameraModel("sr2"), 1, state.range(0) != 0);
}
BENCHMARK(BM_DemoSequence)->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
