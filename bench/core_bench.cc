// Core benchmarks: the memory-copy floor every per-pixel stage is compared with, and the
// one-off ray-table precomputation for the simulated cameras (bench_inputs.h).
#include <benchmark/benchmark.h>

#include "bench_common.h"
#include "tofcam/core/camera_intrinsics.h"

namespace {

using tofcam::bench::Resolutions;

// Copies three 16-bit channels (what a frame carries): the floor for a pass over a frame.
void BM_MemcpyFrame(benchmark::State& state) { tofcam::bench::CopyFloor(state, 2 * 6); }
BENCHMARK(BM_MemcpyFrame)->Apply(Resolutions);

// The simulated SR-2 model's intrinsics (with its lens distortion) at each size.
void BM_MakeRayTable(benchmark::State& state) {
  const tofcam::CameraIntrinsics k = tofcam::bench::Input(state).info.intrinsics;
  for (auto _ : state) benchmark::DoNotOptimize(tofcam::MakeRayTable(k));
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_MakeRayTable)->Apply(Resolutions)->Unit(benchmark::kMillisecond);

}  // namespace
