// One controller update per frame (mean intensity or 8-bit histogram over the image).
#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "tofcam/control/integration_time_controller.h"

namespace {

void BM_ControllerUpdate(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0)), h = static_cast<int>(state.range(1));
  tofcam::MetricFrame m;
  m.radial_distance_m = tofcam::Image<float>(w, h, 1.0f);
  m.amplitude = tofcam::Image<float>(w, h, 1000.0f);
  m.intensity = tofcam::Image<float>(w, h);
  for (std::size_t i = 0; i < m.intensity.size(); ++i) {
    m.intensity[i] = static_cast<float>(2000 + (i * 37) % 30000);
  }
  m.flags = tofcam::Image<tofcam::PixelFlags>(w, h);
  tofcam::ControllerOptions o;
  o.kind = static_cast<tofcam::ControllerKind>(state.range(2));
  const std::unique_ptr<tofcam::IntegrationTimeController> c = tofcam::MakeController(o);
  state.SetLabel(std::string(c->Name()));
  for (auto _ : state) benchmark::DoNotOptimize(c->Update(m));
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * w * h);
}
void Sizes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"w", "h", "kind"});
  for (int kind = 0; kind < 3; ++kind) b->Args({160, 124, kind})->Args({1024, 1024, kind});
}
BENCHMARK(BM_ControllerUpdate)->Apply(Sizes);

}  // namespace
