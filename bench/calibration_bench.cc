// Metric conversion and per-pixel calibration (eq. 1, then the distance-dependent table), each
// beside a plain copy of the bytes it reads and writes (the memory-bandwidth floor).
#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "bench_common.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace {

using tofcam::Frame;
using tofcam::Image;
using tofcam::MetricFrame;

using tofcam::bench::Resolutions;

Frame MakeFrame(int w, int h) {
  Frame f;
  f.distance = Image<std::uint16_t>(w, h);
  f.amplitude = Image<std::uint16_t>(w, h);
  f.intensity = Image<std::uint16_t>(w, h);
  for (std::size_t i = 0; i < f.distance.size(); ++i) {
    f.distance[i] = static_cast<std::uint16_t>(i * 2654435761u >> 16);
    f.amplitude[i] = static_cast<std::uint16_t>(i % 7 == 0 ? 0 : 1000 + i % 5000);
    f.intensity[i] = static_cast<std::uint16_t>(5000 + i % 9000);
  }
  return f;
}

tofcam::OffsetCalibration MakeCalibration(int w, int h, bool with_table) {
  tofcam::OffsetCalibration c;
  c.camera_model = "SR-2";
  c.width = w;
  c.height = h;
  c.offset_m = Image<float>(w, h);
  for (std::size_t i = 0; i < c.offset_m.size(); ++i) c.offset_m[i] = 0.001f * (i % 61) - 0.03f;
  if (with_table) {
    tofcam::DistanceCorrection g;
    g.start_m = 0.3;
    g.step_m = 0.05;
    for (int k = 0; k < 150; ++k) g.correction_m.push_back(0.03f * ((k % 37) / 37.0f - 0.5f));
    c.distance_correction = g;
  }
  return c;
}

void SetCounters(benchmark::State& state, std::size_t bytes) {
  const auto n = state.range(0) * state.range(1);
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * n);
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * bytes));
  state.counters["ns_per_pixel"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * static_cast<double>(n),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// Registers in: 3 x 2 bytes; out: distance, amplitude, intensity floats and flags (14 bytes).
void BM_ConvertToMetric(benchmark::State& state) {
  const Frame f = MakeFrame(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  for (auto _ : state) {
    MetricFrame m = tofcam::ConvertToMetric(f);
    benchmark::DoNotOptimize(m.radial_distance_m.data());
  }
  SetCounters(state, f.distance.size() * 20);
}
BENCHMARK(BM_ConvertToMetric)->Apply(Resolutions);

// The steady-state form a pipeline uses: buffers reused, no allocation.
void BM_ConvertToMetricInto(benchmark::State& state) {
  const Frame f = MakeFrame(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  MetricFrame m;
  for (auto _ : state) {
    tofcam::ConvertToMetricInto(f, {}, m);
    benchmark::DoNotOptimize(m.radial_distance_m.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state, f.distance.size() * 20);
}
BENCHMARK(BM_ConvertToMetricInto)->Apply(Resolutions);

void BM_CopyMetricConversionBytes(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  std::vector<char> src(6 * n, 1), dst(14 * n);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), 6 * n);
    std::memcpy(dst.data() + 6 * n, src.data(), 6 * n);
    std::memcpy(dst.data() + 12 * n, src.data(), 2 * n);
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state, n * 20);
}
BENCHMARK(BM_CopyMetricConversionBytes)->Apply(Resolutions);

// In place: reads distance, offset and flags, writes distance (14 bytes per pixel).
void BM_ApplyCalibration(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0)), h = static_cast<int>(state.range(1));
  MetricFrame m = tofcam::ConvertToMetric(MakeFrame(w, h));
  const tofcam::OffsetCalibration c = MakeCalibration(w, h, state.range(2) != 0);
  for (auto _ : state) {
    tofcam::ApplyCalibrationInPlace(m, c);
    benchmark::DoNotOptimize(m.radial_distance_m.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state, m.radial_distance_m.size() * 14);
}
BENCHMARK(BM_ApplyCalibration)
    ->ArgNames({"w", "h", "table"})
    ->Args({160, 124, 0})
    ->Args({640, 480, 0})
    ->Args({1024, 1024, 0})
    ->Args({160, 124, 1})
    ->Args({640, 480, 1})
    ->Args({1024, 1024, 1});

void BM_CopyCalibrationBytes(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  std::vector<char> src(10 * n, 1), dst(4 * n);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), 4 * n);
    std::memcpy(dst.data(), src.data() + 4 * n, 4 * n);
    std::memcpy(dst.data(), src.data() + 8 * n, 2 * n);
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state, n * 14);
}
BENCHMARK(BM_CopyCalibrationBytes)->Apply(Resolutions);

}  // namespace
