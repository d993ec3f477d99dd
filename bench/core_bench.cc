// Core benchmarks: the memory-copy floor every per-pixel stage is compared with, and the
// one-off ray-table precomputation.
#include <benchmark/benchmark.h>

#include <cstring>
#include <vector>

#include "bench_common.h"
#include "tofcam/core/camera_intrinsics.h"

namespace {

// Resolutions used across the suite: SR-2, VGA, 1 megapixel.
using tofcam::bench::Resolutions;

// Copies three 16-bit channels (what a frame carries): the floor for a pass over a frame.
void BM_MemcpyFrame(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  std::vector<std::uint16_t> src(3 * n, 1), dst(3 * n);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), src.size() * sizeof(std::uint16_t));
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations() * n));
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * 2 * src.size() * 2));
}
BENCHMARK(BM_MemcpyFrame)->Apply(Resolutions);

void BM_MakeRayTable(benchmark::State& state) {
  tofcam::CameraIntrinsics k = tofcam::CameraIntrinsics::SwissRangerSr2();
  k.width = static_cast<int>(state.range(0));
  k.height = static_cast<int>(state.range(1));
  k.cx_px = (k.width - 1) / 2.0;
  k.cy_px = (k.height - 1) / 2.0;
  k.k1 = 0.05;  // with distortion: the iterative undistortion is the cost
  for (auto _ : state) benchmark::DoNotOptimize(tofcam::MakeRayTable(k));
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}
BENCHMARK(BM_MakeRayTable)->Apply(Resolutions)->Unit(benchmark::kMillisecond);

}  // namespace
