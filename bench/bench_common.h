#pragma once
// Shared by every bench/*_bench.cc: the resolutions the suite measures, the simulated inputs
// (bench_inputs.h) and the memory-copy floor a per-pixel stage is compared with.

#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "bench_inputs.h"

namespace tofcam::bench {

/// SR-2 (160x124), VGA (640x480) and 1 megapixel (1024x1024), as (width, height) arguments.
inline void Resolutions(benchmark::internal::Benchmark* b) {
  b->Args({160, 124})->Args({640, 480})->Args({1024, 1024});
}

/// The simulated input of the benchmark's (width, height) arguments.
inline const SimulatedInput& Input(const benchmark::State& state) {
  return Simulated(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
}

/// Items processed = pixels, plus an ns_per_pixel counter.
inline void SetPixels(benchmark::State& state) {
  const auto n = state.range(0) * state.range(1);
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * n);
  state.counters["ns_per_pixel"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * static_cast<double>(n),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

/// A memcpy moving `bytes_per_pixel` / 2 bytes per pixel (so its read + write traffic is
/// `bytes_per_pixel`): the floor of a stage with that minimal traffic. Items are pixels.
inline void CopyFloor(benchmark::State& state, double bytes_per_pixel) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  const auto bytes = static_cast<std::size_t>(bytes_per_pixel / 2 * static_cast<double>(n));
  std::vector<char> src(bytes, 1), dst(bytes, 0);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), bytes);
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  SetPixels(state);
}

/// Copies one float channel of state.range(0) x state.range(1) pixels: the floor for a stage that
/// reads and writes about 4 bytes per pixel. Items are pixels.
inline void CopyFloatChannel(benchmark::State& state) { CopyFloor(state, 8.0); }

}  // namespace tofcam::bench
