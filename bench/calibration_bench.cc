// Metric conversion and per-pixel calibration (eq. 1, then the distance-dependent table) on
// simulated frames (bench_inputs.h), each beside a plain copy of the bytes it reads and writes
// (the memory floor). items/s = pixels/s.
#include <benchmark/benchmark.h>

#include <vector>

#include "bench_common.h"
#include "tofcam/calibration/offset_calibration.h"
#include "tofcam/pipeline/metric_conversion.h"

namespace {

using tofcam::MetricFrame;
using tofcam::bench::Resolutions;

// A fresh metric frame per call (allocation and page faults included).
void BM_ConvertToMetric(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::size_t i = 0;
  for (auto _ : state) {
    MetricFrame m = tofcam::ConvertToMetric(in.camera_frames[i++ % in.camera_frames.size()]);
    benchmark::DoNotOptimize(m.radial_distance_m.data());
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_ConvertToMetric)->Apply(Resolutions);

// The steady-state form a pipeline uses: buffers reused, no allocation.
void BM_ConvertToMetricInto(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  MetricFrame m;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::ConvertToMetricInto(in.camera_frames[i++ % in.camera_frames.size()], {}, m);
    benchmark::DoNotOptimize(m.radial_distance_m.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_ConvertToMetricInto)->Apply(Resolutions);

// Registers in (3 x 2 bytes); distance, amplitude, intensity floats and flags out (14 bytes).
void BM_CopyMetricConversionBytes(benchmark::State& state) {
  tofcam::bench::CopyFloor(state, 6 + 14);
}
BENCHMARK(BM_CopyMetricConversionBytes)->Apply(Resolutions);

// In place, over and over on the same converted frames (the cost does not depend on the
// values). Argument 2: 1 = with the distance table (dense, resampled once and cached).
void BM_ApplyCalibration(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::OffsetCalibration c = in.calibration;
  if (state.range(2) == 0) c.distance_correction.reset();
  std::vector<MetricFrame> frames = in.ready;
  std::size_t i = 0;
  for (auto _ : state) {
    MetricFrame& m = frames[i++ % frames.size()];
    tofcam::ApplyCalibrationInPlace(m, c);
    benchmark::DoNotOptimize(m.radial_distance_m.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_ApplyCalibration)
    ->ArgNames({"w", "h", "table"})
    ->Args({160, 124, 0})
    ->Args({640, 480, 0})
    ->Args({1024, 1024, 0})
    ->Args({160, 124, 1})
    ->Args({640, 480, 1})
    ->Args({1024, 1024, 1});

// Reads distance, offset and flags, writes distance (14 bytes per pixel).
void BM_CopyCalibrationBytes(benchmark::State& state) { tofcam::bench::CopyFloor(state, 14); }
BENCHMARK(BM_CopyCalibrationBytes)->Apply(Resolutions);

// Resampling the 150-knot table onto the 1 mm grid: once per calibration.
void BM_ResampleDistanceTable(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Simulated(160, 124);
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        tofcam::DenseDistanceCorrection::Resample(*in.calibration.distance_correction, 7.5));
  }
}
BENCHMARK(BM_ResampleDistanceTable)->Unit(benchmark::kMicrosecond);

}  // namespace
