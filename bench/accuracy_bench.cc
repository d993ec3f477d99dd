// ΔL per pixel (eq. 2) beside a copy of the bytes it touches (amplitude and intensity in,
// ΔL out: 12 bytes per pixel).
#include <benchmark/benchmark.h>

#include <cstring>
#include <vector>

#include "bench_common.h"
#include "tofcam/accuracy/delta_l.h"

namespace {

using tofcam::bench::Resolutions;

void SetCounters(benchmark::State& state) {
  const auto n = state.range(0) * state.range(1);
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * n);
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * n * 12);
  state.counters["ns_per_pixel"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * static_cast<double>(n),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_ComputeDeltaL(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0)), h = static_cast<int>(state.range(1));
  tofcam::MetricFrame m;
  m.radial_distance_m = tofcam::Image<float>(w, h, 1.0f);
  m.amplitude = tofcam::Image<float>(w, h);
  m.intensity = tofcam::Image<float>(w, h);
  for (std::size_t i = 0; i < m.amplitude.size(); ++i) {
    m.amplitude[i] = static_cast<float>(i % 11 == 0 ? 0 : 500 + i % 3000);
    m.intensity[i] = static_cast<float>(4000 + i % 12000);
  }
  m.flags = tofcam::Image<tofcam::PixelFlags>(w, h);
  tofcam::Image<float> dl;
  for (auto _ : state) {
    tofcam::ComputeDeltaLInto(m, {}, dl);  // buffer reused, as in a pipeline
    benchmark::DoNotOptimize(dl.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state);
}
BENCHMARK(BM_ComputeDeltaL)->Apply(Resolutions);

void BM_CopyDeltaLBytes(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  std::vector<float> a(n, 1.0f), b(n, 2.0f), out(n);
  for (auto _ : state) {
    std::memcpy(out.data(), a.data(), n * sizeof(float));
    std::memcpy(out.data(), b.data(), n * sizeof(float));
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state);
}
BENCHMARK(BM_CopyDeltaLBytes)->Apply(Resolutions);

}  // namespace
