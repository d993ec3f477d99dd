#pragma once
// Shared by every bench/*_bench.cc: the resolutions the suite measures and the memory-copy
// floor a per-pixel stage is compared with.

#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstring>
#include <vector>

namespace tofcam::bench {

/// SR-2 (160x124), VGA (640x480) and 1 megapixel (1024x1024), as (width, height) arguments.
inline void Resolutions(benchmark::internal::Benchmark* b) {
  b->Args({160, 124})->Args({640, 480})->Args({1024, 1024});
}

/// Copies one float channel of state.range(0) x state.range(1) pixels: the floor for a stage that
/// reads and writes about 4 bytes per pixel. Items are pixels.
inline void CopyFloatChannel(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  std::vector<float> src(n, 1.0f), dst(n);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), n * sizeof(float));
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
}

}  // namespace tofcam::bench
