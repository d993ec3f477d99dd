// Pan-view benchmark: five simulated frames (bench_inputs.h) placed at -60°..60° assembled into
// the 180° cloud and panorama, at SR-2, VGA and 1 megapixel. items/s = input pixels/s.
#include <benchmark/benchmark.h>

#include <vector>

#include "bench_common.h"
#include "tofcam/core/units.h"
#include "tofcam/pan/pan_view.h"

namespace {

void BM_MakePanView(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::vector<tofcam::MetricFrame> frames;
  for (int i = 0; i < 5; ++i) {
    tofcam::MetricFrame f = in.ready[static_cast<std::size_t>(i) % in.ready.size()];
    f.info.pan_angle_rad = (-60.0 + 30.0 * i) * tofcam::kPi / 180.0;
    frames.push_back(std::move(f));
  }
  for (auto _ : state) {
    tofcam::PanView view = tofcam::MakePanView(frames, in.rays, {});
    benchmark::DoNotOptimize(view.panorama.data());
  }
  state.SetItemsProcessed(state.iterations() * 5 * state.range(0) * state.range(1));
}
BENCHMARK(BM_MakePanView)->Apply(tofcam::bench::Resolutions)->Unit(benchmark::kMillisecond);

}  // namespace
