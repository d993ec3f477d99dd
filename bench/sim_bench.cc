// Simulator throughput: frames per second of SimulatedCamera::Grab() (items_per_second).
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
