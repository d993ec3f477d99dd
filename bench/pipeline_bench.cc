// Whole-pipeline benchmarks on simulated frames (SR-2 pavilion, moving camera, seed 7) at
// 160x124, 640x480 and 1024x1024: the paper chain of the issue-4 target (metric conversion +
// calibration + ΔL + threshold + point cloud) and Pipeline::Process, each beside a memcpy with
// the chain's minimal memory traffic. items/s = pixels/s. `tofcam bench` reports the same stages
// in one table (docs/benchmarks.md).
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <vector>

#include "bench_common.h"
#include "tofcam/pipeline/pipeline.h"
#include "tofcam/sim/simulated_camera.h"

namespace {

using tofcam::Frame;
using tofcam::MetricFrame;

// Registers, offsets and rays in; metric frame (14), ΔL (4) and cloud (26) out, bytes per pixel.
constexpr double kChainTrafficBytesPerPixel = 6 + 4 + 12 + 14 + 4 + 26;

using tofcam::bench::Resolutions;

struct Input {
  tofcam::CameraInfo info;
  tofcam::RayTable rays;
  tofcam::OffsetCalibration calibration;
  std::vector<Frame> frames;
};

Input MakeInput(int w, int h) {
  tofcam::sim::CameraModel model = tofcam::sim::ResolveCameraModel("sr2");
  tofcam::CameraIntrinsics& k = model.intrinsics;
  k.fx_px *= w / static_cast<double>(k.width);
  k.fy_px *= h / static_cast<double>(k.height);
  k.width = w;
  k.height = h;
  k.cx_px = (w - 1) / 2.0;
  k.cy_px = (h - 1) / 2.0;
  tofcam::sim::Scene scene = tofcam::sim::LoadBuiltinScene("pavilion");
  scene.camera.keys.clear();
  for (int i = 0; i <= 8; ++i) {
    tofcam::sim::Keyframe key;
    key.time_s = 4.0 * i;
    key.position_m = {0, 0, i % 2 == 0 ? 0.0 : 2.0};
    key.rotation_deg = {0, i % 2 == 0 ? -6.0 : 6.0, 0};
    scene.camera.keys.push_back(key);
  }
  tofcam::sim::SimulatorOptions so;
  so.seed = 7;
  so.threads = 2;
  so.integration_time_register = 40;
  tofcam::sim::SimulatedCamera cam(std::move(scene), model, so);
  Input in;
  in.info = cam.Info();
  in.rays = tofcam::MakeRayTable(in.info.intrinsics);
  tofcam::OffsetCalibration& c = in.calibration;
  c.camera_model = in.info.model;
  c.width = w;
  c.height = h;
  c.modulation_frequency_hz = in.info.modulation_frequency_hz;
  c.offset_m = cam.FixedPatternOffsetM();
  c.pixel_flags = tofcam::Image<tofcam::PixelFlags>(w, h);
  tofcam::DistanceCorrection g;
  g.start_m = 0.3;
  g.step_m = 0.05;
  for (int i = 0; i < 150; ++i) g.correction_m.push_back(static_cast<float>(0.03 * std::sin(i)));
  c.distance_correction = g;
  for (int i = 0; i < 4; ++i) in.frames.push_back(*cam.Grab());
  return in;
}

void SetCounters(benchmark::State& state) {
  const auto n = state.range(0) * state.range(1);
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * n);
  state.counters["ns_per_pixel"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * static_cast<double>(n),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_PaperChain(benchmark::State& state) {
  const Input in = MakeInput(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  MetricFrame m;
  tofcam::PointCloud cloud;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::ConvertToMetricInto(in.frames[i++ % in.frames.size()], {}, m);
    tofcam::ApplyCalibrationInPlace(m, in.calibration);
    tofcam::ComputeDeltaLInto(m, {}, m.delta_l_m);
    tofcam::MergeFlags(m, tofcam::AccuracyThresholdFilter(m, {}));
    tofcam::MakePointCloudInto(m, in.rays, cloud);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state);
}
BENCHMARK(BM_PaperChain)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

void RunPipeline(benchmark::State& state, bool all_filters) {
  const Input in = MakeInput(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  tofcam::PipelineOptions o;
  o.calibration = in.calibration;
  if (all_filters) {
    tofcam::FilterSetOptions& f = o.filters;
    f.range_enabled = f.amplitude_enabled = f.saturation_enabled = f.accuracy_enabled = true;
    f.flying_pixel_enabled = f.jump_edge_enabled = f.weingarten_enabled = true;
  }
  tofcam::Pipeline pipeline(o, in.info);
  tofcam::PipelineResult result;
  std::size_t i = 0;
  for (auto _ : state) {
    pipeline.Process(in.frames[i++ % in.frames.size()], result);
    benchmark::DoNotOptimize(result.cloud.x.data());
  }
  SetCounters(state);
}

void BM_PipelineDefaults(benchmark::State& state) { RunPipeline(state, false); }
BENCHMARK(BM_PipelineDefaults)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

void BM_PipelineAllFilters(benchmark::State& state) { RunPipeline(state, true); }
BENCHMARK(BM_PipelineAllFilters)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

// The floor: a memcpy whose read + write traffic equals the chain's minimal traffic.
void BM_ChainMemcpyFloor(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0) * state.range(1));
  const auto bytes = static_cast<std::size_t>(kChainTrafficBytesPerPixel / 2 * n);
  std::vector<char> src(bytes, 1), dst(bytes, 0);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), bytes);
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  SetCounters(state);
}
BENCHMARK(BM_ChainMemcpyFloor)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

// Memory bandwidth: bytes/s of a 256 MiB memcpy (reported bytes = read + write).
void BM_MemoryBandwidth(benchmark::State& state) {
  constexpr std::size_t kBytes = std::size_t{256} << 20;
  std::vector<char> src(kBytes, 1), dst(kBytes, 0);
  for (auto _ : state) {
    std::memcpy(dst.data(), src.data(), kBytes);
    benchmark::DoNotOptimize(dst.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * 2 * kBytes));
}
BENCHMARK(BM_MemoryBandwidth)->Unit(benchmark::kMillisecond);

}  // namespace
