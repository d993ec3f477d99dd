// False-colour benchmarks on simulated frames (bench_inputs.h) at SR-2, VGA and 1 megapixel
// beside a plain copy of the bytes (distance 4 + flags 2 in, RGB 3 out). items/s = pixels/s.
#include <benchmark/benchmark.h>

#include "bench_common.h"
#include "tofcam/color/false_color.h"

namespace {

using tofcam::Image;
using tofcam::bench::Resolutions;

void BM_CopyFloor(benchmark::State& state) { tofcam::bench::CopyFloor(state, 4 + 2 + 3); }
BENCHMARK(BM_CopyFloor)->Apply(Resolutions);

void Run(benchmark::State& state, const tofcam::FalseColorOptions& o) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::size_t i = 0;
  for (auto _ : state) {
    Image<tofcam::Rgb8> img = tofcam::FalseColor(in.ready[i++ % in.ready.size()], o);
    benchmark::DoNotOptimize(img.data());
  }
  tofcam::bench::SetPixels(state);
}

void BM_FalseColor(benchmark::State& state) { Run(state, {}); }
BENCHMARK(BM_FalseColor)->Apply(Resolutions);

void BM_FalseColorShaded(benchmark::State& state) {
  tofcam::FalseColorOptions o;
  o.amplitude_shading = true;
  Run(state, o);
}
BENCHMARK(BM_FalseColorShaded)->Apply(Resolutions);

void BM_AddLegend(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  const Image<tofcam::Rgb8> img = tofcam::FalseColor(in.ready[0], {});
  for (auto _ : state) {
    Image<tofcam::Rgb8> out = tofcam::AddLegend(img, 0.0, 7.5);
    benchmark::DoNotOptimize(out.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_AddLegend)->Apply(Resolutions);

}  // namespace
