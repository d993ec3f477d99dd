// Point-cloud benchmarks on simulated frames (bench_inputs.h): MakePointCloud at SR-2, VGA and
// 1 megapixel beside a plain copy of the same bytes (the memory floor), plus PLY / PCD writing
// of an SR-2 cloud. items/s = pixels/s.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "bench_common.h"
#include "core/avx512_forms.h"  // internal: the portable / AVX-512 switch (src/core)
#include "tofcam/cloud/point_cloud.h"
#include "tofcam/io/cloud_io.h"

namespace {

using tofcam::bench::Resolutions;

// Floor: reads distance, 3 rays, amplitude, intensity, ΔL, flags (30 bytes); writes 6 floats and
// flags (26 bytes).
void BM_CopyFloor(benchmark::State& state) { tofcam::bench::CopyFloor(state, 30 + 26); }
BENCHMARK(BM_CopyFloor)->Apply(Resolutions);

// A fresh cloud per frame (allocation and page faults included).
void BM_MakePointCloud(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::PointCloud cloud = tofcam::MakePointCloud(in.ready[i++ % in.ready.size()], in.rays);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_MakePointCloud)->Apply(Resolutions);

// The per-frame form: the cloud's storage is reused (no allocation, no page faults).
void BM_MakePointCloudInto(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Input(state);
  tofcam::PointCloud cloud;
  std::size_t i = 0;
  for (auto _ : state) {
    tofcam::MakePointCloudInto(in.ready[i++ % in.ready.size()], in.rays, cloud);
    benchmark::DoNotOptimize(cloud.x.data());
    benchmark::ClobberMemory();
  }
  tofcam::bench::SetPixels(state);
}
BENCHMARK(BM_MakePointCloudInto)->Apply(Resolutions);

// The same with the portable forms: a cloud past kStreamCloudBytes (1 MP; 16 MiB) streamed with
// 16-byte instead of 64-byte non-temporal stores. Same values; on a CPU without AVX-512 the two
// rows run the same code.
void BM_MakePointCloudIntoPortable(benchmark::State& state) {
  const tofcam::internal::PortableFormsForTesting portable(true);
  BM_MakePointCloudInto(state);
}
BENCHMARK(BM_MakePointCloudIntoPortable)->Apply(Resolutions);

std::filesystem::path Scratch(const char* name) {
  return std::filesystem::temp_directory_path() /
         (std::string("tofcam_cloud_bench_") + std::to_string(::getpid()) + name);
}

// File writers at SR-2 size (includes fsync of the atomic write).
void BM_WritePlyBinary(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Simulated(160, 124);
  const tofcam::PointCloud cloud = tofcam::MakePointCloud(in.ready[0], in.rays);
  const auto path = Scratch(".ply");
  for (auto _ : state) tofcam::WritePly(path, cloud, tofcam::PlyFormat::kBinary, false);
  std::filesystem::remove(path);
  state.SetItemsProcessed(state.iterations() * 160 * 124);
}
BENCHMARK(BM_WritePlyBinary);

void BM_WritePcd(benchmark::State& state) {
  const tofcam::bench::SimulatedInput& in = tofcam::bench::Simulated(160, 124);
  const tofcam::PointCloud cloud = tofcam::MakePointCloud(in.ready[0], in.rays);
  const auto path = Scratch(".pcd");
  for (auto _ : state) tofcam::WritePcd(path, cloud, false);
  std::filesystem::remove(path);
  state.SetItemsProcessed(state.iterations() * 160 * 124);
}
BENCHMARK(BM_WritePcd);

}  // namespace
