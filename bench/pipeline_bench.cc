// Whole-pipeline benchmarks on simulated frames (bench_inputs.h; registers only, as a camera
// delivers them) at 160x124, 640x480 and 1024x1024: the paper chain of the issue-4 target
// (metric conversion + calibration with the distance table + ΔL + threshold + point cloud), fused
// (PaperChain) and stage by stage, and Pipeline::Process, each beside a memcpy with the chain's
// minimal memory traffic. items/s = pixels/s. `tofcam bench` reports the same stages in one
// table (docs/benchmarks.md).
#include <benchmark/benchmark.h>

#include <cstring>
#include <vector>

#include "bench_common.h"
#include "tofcam/pipeline/paper_chain.h"
#include "tofcam/pipeline/pipeline.h"

namespace {

using tofcam::MetricFrame;
using tofcam::bench::Resolutions;

// Registers (6), offsets (4) and rays (12) in; metric frame (14), ΔL (4) and cloud (26) out,
// bytes per pixel.
constexpr double kChainTrafficBytesPerPixel = 6 + 4 + 12 + 14 + 4 + 26;

// The issue-4 target: the fused chain.
void BM_PaperChain(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::PaperChainOptions o;
  o.calibration = in.calibration;
  o.accuracy = in.accuracy;
  tofcam::PaperChain chain(o, in.info);
  MetricFrame m;
  tofcam::PointCloud cloud;
  std::size_t i = 0;
  for (auto _ : state) {
    chain.Process(in.camera_frames[i++ % in.camera_frames.size()], m, cloud);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_PaperChain)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

// The same stages called one after the other on whole frames (same results, one memory pass per
// stage).
void BM_PaperChainStageByStage(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  MetricFrame m;
  tofcam::Image<tofcam::PixelFlags> raised;
  tofcam::FilterSetOptions threshold;
  threshold.saturation_enabled = false;
  tofcam::PointCloud cloud;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::ConvertToMetricInto(in.camera_frames[i++ % in.camera_frames.size()], {}, m);
    tofcam::ApplyCalibrationInPlace(m, in.calibration);
    tofcam::ComputeDeltaLInto(m, in.accuracy, m.delta_l_m);
    tofcam::ApplyFiltersInto(m, in.rays, threshold, raised);
    tofcam::MergeFlags(m, raised);
    tofcam::MakePointCloudInto(m, in.rays, cloud);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_PaperChainStageByStage)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

void RunPipeline(benchmark::State& state, bool all_filters) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::PipelineOptions o;
  o.calibration = in.calibration;
  o.accuracy = in.accuracy;
  if (all_filters) {
    tofcam::FilterSetOptions& f = o.filters;
    f.range_enabled = f.amplitude_enabled = f.saturation_enabled = f.accuracy_enabled = true;
    f.flying_pixel_enabled = f.jump_edge_enabled = f.weingarten_enabled = true;
  }
  tofcam::Pipeline pipeline(o, in.info);
  tofcam::PipelineResult result;
  std::size_t i = 0;
  for (auto _ : state) {
    pipeline.Process(in.camera_frames[i++ % in.camera_frames.size()], result);
    benchmark::DoNotOptimize(result.cloud.x.data());
  }
  tofcam::bench::SetPixels(state);
}

void BM_PipelineDefaults(benchmark::State& state) { RunPipeline(state, false); }
BENCHMARK(BM_PipelineDefaults)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

void BM_PipelineAllFilters(benchmark::State& state) { RunPipeline(state, true); }
BENCHMARK(BM_PipelineAllFilters)->Apply(Resolutions)->Unit(benchmark::kMicrosecond);

// The floor: a memcpy whose read + write traffic equals the chain's minimal traffic.
void BM_ChainMemcpyFloor(benchmark::State& state) {
  tofcam::bench::CopyFloor(state, kChainTrafficBytesPerPixel);
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
