// ΔL per pixel (eq. 2) on simulated frames (bench_inputs.h) beside a copy of the bytes it
// touches (amplitude and intensity in, ΔL out: 12 bytes per pixel). items/s = pixels/s.
#include <benchmark/benchmark.h>

#include "bench_common.h"
#include "tofcam/accuracy/delta_l.h"

namespace {

using tofcam::bench::Resolutions;

void BM_ComputeDeltaL(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::Image<float> dl;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::ComputeDeltaLInto(in.ready[i++ % in.ready.size()], in.accuracy,
                              dl);  // reused, as in a pipeline
    benchmark::DoNotOptimize(dl.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_ComputeDeltaL)->Apply(Resolutions);

void BM_CopyDeltaLBytes(benchmark::State& state) { tofcam::bench::CopyFloor(state, 12); }
BENCHMARK(BM_CopyDeltaLBytes)->Apply(Resolutions);

}  // namespace
