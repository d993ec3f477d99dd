// Scattering compensation benchmark (issue 18): CompensateScatteringInto on simulated camera
// frames (bench_inputs.h) with two lobes as the estimator finds them on the simulated SR-2 and
// three iterations, at SR-2, VGA and 1 megapixel. items/s = pixels/s.
#include <benchmark/benchmark.h>

#include "bench_common.h"
#include "tofcam/optics/scattering.h"

namespace {

void BM_CompensateScattering(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::ScatteringOptions o;
  o.lobes = {{0.0005, 8.0}, {0.0008, 48.0}};
  tofcam::Frame out;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::CompensateScatteringInto(in.camera_frames[i++ % in.camera_frames.size()], o, out);
    benchmark::DoNotOptimize(out.distance.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_CompensateScattering)
    ->Apply(tofcam::bench::Resolutions)
    ->Unit(benchmark::kMicrosecond);

}  // namespace
