// One controller update per frame (mean intensity or 8-bit histogram over the image) on
// simulated frames (bench_inputs.h). items/s = pixels/s.
#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "bench_common.h"
#include "tofcam/control/integration_time_controller.h"

namespace {

void BM_ControllerUpdate(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::ControllerOptions o;
  o.kind = static_cast<tofcam::ControllerKind>(state.range(2));
  const std::unique_ptr<tofcam::IntegrationTimeController> c = tofcam::MakeController(o);
  state.SetLabel(std::string(c->Name()));
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(c->Update(in.ready[i++ % in.ready.size()]));
  tofcam::bench::SetPixels(state);
}
void Sizes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"w", "h", "kind"});
  for (int kind = 0; kind < 3; ++kind) {
    b->Args({160, 124, kind})->Args({640, 480, kind})->Args({1024, 1024, kind});
  }
}
BENCHMARK(BM_ControllerUpdate)->Apply(Sizes);

// Floor: reading intensity and flags (6 bytes per pixel) once, as a memcpy of half of it.
void BM_CopyFloor(benchmark::State& state) { tofcam::bench::CopyFloor(state, 6); }
BENCHMARK(BM_CopyFloor)->Apply(tofcam::bench::Resolutions);

}  // namespace
